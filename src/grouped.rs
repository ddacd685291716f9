//! Grouped sufficient statistics: everything the iterative reweighting of
//! section 5 needs, without keeping the raw measurements.
//!
//! The paper estimates the noise σ per robot configuration (a *group*) and
//! per axis (x, y, z) from the residuals of the previous fit, turns it into
//! weights (eq. 14) and fits again. Within one group and axis `(g, a)` every
//! row shares one weight, so the unweighted moments
//!
//! - `S = Σ b bᵀ` (N × N, symmetric), `u = Σ b y`, `yy = Σ y²`, `n`
//!
//! are sufficient. From them, exactly (up to rounding):
//!
//! - the residual sum of squares for any `X`: `yy − 2 Xᵀu + Xᵀ S X`, hence σ
//!   per group and axis;
//! - the re-weighted statistics `Λ = Σ w²_ga S_ga`, `η = Σ w²_ga u_ga`;
//! - the sandwich middle term `M = Σ w⁴_ga σ²_ga S_ga` (eq. 11).
//!
//! Memory is `G · 3 · (N² + N + 2)` scalars, fixed: it grows with the number
//! of configurations, never with the number of measurements.
//!
//! The residual sum of squares is a difference of large terms; it keeps its
//! accuracy while `yy` is within a few orders of magnitude of the residuals'
//! sum of squares. Feed `Δp` as deviations from a nominal model (deflections,
//! or measured − nominal positions), not as raw absolute coordinates.

use nalgebra::{RealField, SMatrix, SVector, Vector3};

use crate::accumulator::{symmetric, Accumulator};
use crate::Error;

/// Moments of the rows of one group and one axis.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AxisMoments<T: RealField + Copy, const N: usize> {
    /// `S = Σ b bᵀ`, upper triangle.
    pub s_upper: SMatrix<T, N, N>,
    /// `u = Σ b y`.
    pub u: SVector<T, N>,
    /// `Σ y²`.
    pub yy: T,
    /// Rows.
    pub n: usize,
}

impl<T: RealField + Copy, const N: usize> AxisMoments<T, N> {
    fn new() -> Self {
        Self {
            s_upper: SMatrix::zeros(),
            u: SVector::zeros(),
            yy: T::zero(),
            n: 0,
        }
    }

    /// Residual sum of squares `Σ (y − bᵀX)² = yy − 2Xᵀu + XᵀSX`, clamped at 0.
    pub fn rss(&self, x: &SVector<T, N>) -> T {
        let s = symmetric(&self.s_upper);
        let two = T::one() + T::one();
        (self.yy - two * x.dot(&self.u) + (s * x).dot(x)).max(T::zero())
    }
}

/// The moments of one group (robot configuration), per axis x, y, z.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GroupMoments<T: RealField + Copy, const N: usize> {
    /// The group's id (e.g. the configuration number of the CSV).
    pub id: i32,
    /// Moments per axis: x, y, z.
    pub axes: [AxisMoments<T, N>; 3],
}

/// Grouped sufficient statistics for at most `G` groups. See the
/// [module docs](self).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GroupedStats<T: RealField + Copy, const N: usize, const G: usize> {
    groups: heapless::Vec<GroupMoments<T, N>, G>,
}

impl<T: RealField + Copy, const N: usize, const G: usize> Default for GroupedStats<T, N, G> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: RealField + Copy, const N: usize, const G: usize> GroupedStats<T, N, G> {
    /// No groups yet.
    pub const fn new() -> Self {
        Self {
            groups: heapless::Vec::new(),
        }
    }

    /// The groups, in the order they first appeared.
    pub fn groups(&self) -> &[GroupMoments<T, N>] {
        &self.groups
    }

    /// Total number of rows.
    pub fn equations(&self) -> usize {
        self.groups
            .iter()
            .map(|g| g.axes.iter().map(|a| a.n).sum::<usize>())
            .sum()
    }

    /// Adds one measurement of group `id`: rows `b` (x, y, z) and `Δp` \[m\].
    /// Weights are not given here: they are chosen later, per group and axis.
    ///
    /// # Errors
    /// [`Error::NonFinite`] for a non-finite value or an overflowing sum,
    /// [`Error::CapacityExceeded`] when `id` is new and `G` groups exist
    /// already. The statistics are unchanged on error.
    pub fn update(&mut self, id: i32, b: &SMatrix<T, 3, N>, dp: &Vector3<T>) -> Result<(), Error> {
        if !b.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite { what: "row" });
        }
        if !dp.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite { what: "dp" });
        }
        let index = match self.groups.iter().position(|g| g.id == id) {
            Some(i) => i,
            None => {
                if self.groups.is_full() {
                    return Err(Error::CapacityExceeded {
                        what: "groups",
                        capacity: G,
                    });
                }
                self.groups.len()
            }
        };
        // Overflow guard on the new diagonals (they bound the off-diagonals).
        let empty = AxisMoments::new();
        for a in 0..3 {
            let row = b.row(a);
            let ax = self.groups.get(index).map_or(&empty, |g| &g.axes[a]);
            if !(ax.yy + dp[a] * dp[a]).is_finite() {
                return Err(Error::NonFinite { what: "overflow" });
            }
            for i in 0..N {
                let d = ax.s_upper[(i, i)] + row[i] * row[i];
                let e = ax.u[i] + row[i] * dp[a];
                if !(d.is_finite() && e.is_finite()) {
                    return Err(Error::NonFinite { what: "overflow" });
                }
            }
        }
        if index == self.groups.len() {
            let fresh = GroupMoments {
                id,
                axes: [AxisMoments::new(); 3],
            };
            // Cannot fail: checked `is_full` above.
            self.groups
                .push(fresh)
                .map_err(|_| Error::CapacityExceeded {
                    what: "groups",
                    capacity: G,
                })?;
        }
        let g = &mut self.groups[index];
        for (a, ax) in g.axes.iter_mut().enumerate() {
            let row: SVector<T, N> = b.row(a).transpose();
            for j in 0..N {
                for i in 0..=j {
                    ax.s_upper[(i, j)] += row[i] * row[j];
                }
            }
            ax.u += row * dp[a];
            ax.yy += dp[a] * dp[a];
            ax.n += 1;
        }
        Ok(())
    }

    /// σ per group and axis of the residuals of `x`:
    /// `σ²_ga = RSS_ga / n_ga · m / (m − p)`, where `m` is the total number of
    /// rows and `p` the number of estimated parameters (a global
    /// degrees-of-freedom correction, so that σ² is unbiased on average).
    /// In the unit of `Δp`. One entry per group, in [`Self::groups`] order.
    #[must_use]
    pub fn residual_sigma(
        &self,
        x: &SVector<T, N>,
        parameters: usize,
    ) -> heapless::Vec<Vector3<T>, G> {
        let m = self.equations();
        let correction = if m > parameters {
            nalgebra::convert::<f64, T>(m as f64 / (m - parameters) as f64)
        } else {
            T::one()
        };
        let mut out = heapless::Vec::new();
        for g in &self.groups {
            let s = Vector3::from_fn(|a, _| {
                let ax = &g.axes[a];
                if ax.n == 0 {
                    return T::zero();
                }
                let n = nalgebra::convert::<f64, T>(ax.n as f64);
                (ax.rss(x) / n * correction).sqrt()
            });
            // Same length as `groups`: cannot overflow.
            let _ = out.push(s);
        }
        out
    }

    /// The weighted statistics: every row of group `g`, axis `a` carries the
    /// weight `weights[g][a]`; with `sigma`, the sandwich middle term
    /// `M = Σ w⁴ σ² S` is accumulated too.
    ///
    /// # Errors
    /// [`Error::Mismatch`] when `weights` (or `sigma`) does not have one
    /// entry per group; [`Error::NonFinite`] / [`Error::NotPositive`] for bad
    /// weights.
    pub fn weighted(
        &self,
        weights: &[Vector3<T>],
        sigma: Option<&[Vector3<T>]>,
    ) -> Result<Accumulator<T, N>, Error> {
        if weights.len() != self.groups.len() || sigma.is_some_and(|s| s.len() != self.groups.len())
        {
            return Err(Error::Mismatch {
                what: "one weight (and sigma) per group",
            });
        }
        let mut acc = Accumulator::new();
        for (gi, g) in self.groups.iter().enumerate() {
            for (a, ax) in g.axes.iter().enumerate() {
                let s = sigma.map(|s| s[gi][a]);
                acc.add_moments(&ax.s_upper, &ax.u, ax.yy, ax.n, weights[gi][a], s)?;
            }
        }
        Ok(acc)
    }
}
