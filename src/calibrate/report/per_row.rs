//! The report's vectors per row ([`RowErrors`]) and per configuration
//! ([`ConfigNoises`]), held by column: each column is the fit's own vector
//! taken over (the residuals, the σ and weights per configuration, scaled
//! to µm in place), not a copy beside it. At 10⁶ rows a vector of
//! [`RowError`] (64 B) and one of [`ConfigNoise`] (56 B) were 120 MB made
//! while the fit's 96 MB were still there, at the end of a run that holds
//! the rows: its peak memory.

use std::sync::Arc;

use nalgebra::Vector3;

/// The noise of one configuration as the final fit saw it.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfigNoise {
    /// `config` as in the CSV.
    pub config: i64,
    /// Residual σ per axis x, y, z \[µm\] (eq. 14's σ, a point's: [`crate::calibrate::rows::noise_scale`]).
    pub sigma_um: [f64; 3],
    /// The weight per axis the fit gave its rows (eq. 14; 1 for OLS).
    pub weight: [f64; 3],
}

/// One row's error before and after calibration (the report's per-pose
/// plots and statistics).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowError {
    /// `config` as in the CSV.
    pub config: i64,
    /// Marker id.
    pub marker: u32,
    /// Whether the row is a deflection (loaded minus unloaded) rather than
    /// an absolute position.
    pub deflection: bool,
    /// The nominal robot's error \[µm\] (as [`crate::calibrate::report::Nominal`]).
    pub nominal_um: Vector3<f64>,
    /// The final model's residual \[µm\].
    pub final_um: Vector3<f64>,
}

impl RowError {
    /// Its kind as the report's notes name it: `deflection` or `position`.
    pub fn kind_name(&self) -> &'static str {
        if self.deflection {
            "deflection"
        } else {
            "position"
        }
    }
}

/// Every row's error before and after ([`RowError`]), by column.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RowErrors {
    /// `config` as in the CSV, per configuration ([`RowErrors::group`]'s;
    /// shared with the report's [`ConfigNoises`]).
    configs: Arc<[i64]>,
    /// Marker ids, per marker index ([`RowErrors::marker`]'s).
    marker_ids: Vec<u32>,
    /// Each row's configuration (index into `configs`).
    group: Vec<u32>,
    /// Each row's marker (index into `marker_ids`).
    marker: Vec<u8>,
    /// Whether each row is a deflection.
    deflection: Vec<bool>,
    /// Each row's nominal error \[µm\] (zero until set).
    nominal_um: Vec<Vector3<f64>>,
    /// Each row's final residual \[µm\].
    final_um: Vec<Vector3<f64>>,
}

impl RowErrors {
    /// The errors of rows `(group, marker, deflection)`, the final
    /// residuals `residuals` \[m\] (one per row; made µm in place), the
    /// nominal errors zero, with `configs` and `marker_ids` to name them.
    pub(crate) fn new(
        configs: Arc<[i64]>,
        marker_ids: Vec<u32>,
        rows: impl Iterator<Item = (usize, u8, bool)>,
        mut residuals: Vec<Vector3<f64>>,
    ) -> Self {
        let (lo, _) = rows.size_hint();
        let mut group = Vec::with_capacity(lo);
        let mut marker = Vec::with_capacity(lo);
        let mut deflection = Vec::with_capacity(lo);
        for (g, m, d) in rows.take(residuals.len()) {
            group.push(u32::try_from(g).unwrap_or(u32::MAX));
            marker.push(m);
            deflection.push(d);
        }
        residuals.truncate(group.len());
        for r in &mut residuals {
            *r *= 1e6;
        }
        Self {
            configs,
            marker_ids,
            nominal_um: vec![Vector3::zeros(); group.len()],
            group,
            marker,
            deflection,
            final_um: residuals,
        }
    }

    /// Sets each row's nominal error \[µm\] (one per row; the rest stay
    /// zero).
    pub(crate) fn set_nominal_um(&mut self, nominal_um: Vec<Vector3<f64>>) {
        let n = self.final_um.len();
        self.nominal_um = nominal_um;
        self.nominal_um.resize(n, Vector3::zeros());
    }

    /// Rows.
    pub fn len(&self) -> usize {
        self.final_um.len()
    }

    /// Whether there is no row.
    pub fn is_empty(&self) -> bool {
        self.final_um.is_empty()
    }

    /// Row `i`'s error.
    pub fn get(&self, i: usize) -> Option<RowError> {
        Some(RowError {
            config: usize::try_from(*self.group.get(i)?)
                .ok()
                .and_then(|g| self.configs.get(g))
                .copied()
                .unwrap_or_default(),
            marker: self
                .marker_ids
                .get(usize::from(*self.marker.get(i)?))
                .copied()
                .unwrap_or_default(),
            deflection: *self.deflection.get(i)?,
            nominal_um: *self.nominal_um.get(i)?,
            final_um: *self.final_um.get(i)?,
        })
    }

    /// Each row's error, in the rows' order.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = RowError> + '_ {
        (0..self.len()).map(|i| self.get(i).unwrap_or(ZERO_ROW))
    }

    /// Each row's final residual \[µm\].
    pub fn final_um(&self) -> &[Vector3<f64>] {
        &self.final_um
    }
}

/// (Never read: [`RowErrors::get`] is `Some` below [`RowErrors::len`].)
const ZERO_ROW: RowError = RowError {
    config: 0,
    marker: 0,
    deflection: false,
    nominal_um: Vector3::new(0.0, 0.0, 0.0),
    final_um: Vector3::new(0.0, 0.0, 0.0),
};

impl<'a> IntoIterator for &'a RowErrors {
    type Item = RowError;
    type IntoIter = Box<dyn ExactSizeIterator<Item = RowError> + 'a>;
    fn into_iter(self) -> Self::IntoIter {
        Box::new(self.iter())
    }
}

/// The noise of each configuration as the final fit saw it
/// ([`ConfigNoise`]), by column.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ConfigNoises {
    /// `config` as in the CSV.
    config: Arc<[i64]>,
    /// Residual σ per axis \[µm\].
    sigma_um: Vec<Vector3<f64>>,
    /// The weight per axis.
    weight: Vec<Vector3<f64>>,
}

impl ConfigNoises {
    /// The configurations `config` with the fit's σ per axis `sigma` \[m\]
    /// (made µm in place) and weights `weight`, as many as the shortest.
    pub(crate) fn new(
        config: Arc<[i64]>,
        mut sigma: Vec<Vector3<f64>>,
        mut weight: Vec<Vector3<f64>>,
    ) -> Self {
        let n = config.len().min(sigma.len()).min(weight.len());
        sigma.truncate(n);
        weight.truncate(n);
        for s in &mut sigma {
            *s = Vector3::new(s.x * 1e6, s.y * 1e6, s.z * 1e6);
        }
        Self {
            config,
            sigma_um: sigma,
            weight,
        }
    }

    /// Configurations.
    pub fn len(&self) -> usize {
        self.sigma_um.len()
    }

    /// Whether there is none.
    pub fn is_empty(&self) -> bool {
        self.sigma_um.is_empty()
    }

    /// Configuration `i`'s noise.
    pub fn get(&self, i: usize) -> Option<ConfigNoise> {
        Some(ConfigNoise {
            config: *self.config.get(i)?,
            sigma_um: (*self.sigma_um.get(i)?).into(),
            weight: (*self.weight.get(i)?).into(),
        })
    }

    /// Each configuration's noise, in the configurations' order.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = ConfigNoise> + '_ {
        (0..self.len()).map(|i| self.get(i).unwrap_or(ZERO_NOISE))
    }
}

/// (Never read: [`ConfigNoises::get`] is `Some` below
/// [`ConfigNoises::len`].)
const ZERO_NOISE: ConfigNoise = ConfigNoise {
    config: 0,
    sigma_um: [0.0; 3],
    weight: [0.0; 3],
};

impl<'a> IntoIterator for &'a ConfigNoises {
    type Item = ConfigNoise;
    type IntoIter = Box<dyn ExactSizeIterator<Item = ConfigNoise> + 'a>;
    fn into_iter(self) -> Self::IntoIter {
        Box::new(self.iter())
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use crate::calibrate::report::per_row::{ConfigNoise, ConfigNoises, RowError, RowErrors};

    /// Each row's error is the one a vector of [`RowError`] held, made
    /// the same way: the residual times 1e6, named by configuration and
    /// marker id (0 for a marker index with none).
    #[test]
    fn rows_and_configurations_are_read_back() {
        let res = vec![
            Vector3::new(1.5e-6, -2.0e-7, 3.3e-5),
            Vector3::new(0.1, 0.2, 0.3),
        ];
        let rows = [(1_usize, 0_u8, true), (0, 7, false)];
        let mut e = RowErrors::new(vec![10, 20].into(), vec![4], rows.into_iter(), res.clone());
        e.set_nominal_um(vec![Vector3::new(1.0, 2.0, 3.0)]);
        let want = [
            RowError {
                config: 20,
                marker: 4,
                deflection: true,
                nominal_um: Vector3::new(1.0, 2.0, 3.0),
                final_um: res[0] * 1e6,
            },
            RowError {
                config: 10,
                marker: 0,
                deflection: false,
                nominal_um: Vector3::zeros(),
                final_um: res[1] * 1e6,
            },
        ];
        assert_eq!(e.iter().collect::<Vec<_>>(), want);
        assert_eq!((e.len(), e.get(2)), (2, None));
        let s = vec![Vector3::new(1e-6, 2e-6, 3e-6)];
        let n = ConfigNoises::new(
            vec![5, 6].into(),
            s.clone(),
            vec![Vector3::new(0.5, 1.0, 2.0)],
        );
        let want = ConfigNoise {
            config: 5,
            sigma_um: [s[0].x * 1e6, s[0].y * 1e6, s[0].z * 1e6],
            weight: [0.5, 1.0, 2.0],
        };
        assert_eq!((&n).into_iter().collect::<Vec<_>>(), [want]);
    }
}
