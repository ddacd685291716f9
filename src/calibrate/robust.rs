//! A robust loss: rows far out of line with the others (a tracker point
//! lost or mistaken, a line of another pose) weighted down by Huber's
//! loss on their standardised residual, so that they do not steer the
//! fit (`--robust`, [`crate::calibrate::Settings::robust`]).
//!
//! Each row `i`'s residual `rᵢ` (per axis `a`, of the last fit) is
//! standardised by a scale `sᵢₐ` that it does not move itself:
//!
//! 1. the instrument's σ of the row, when it has one (data contract 7.2),
//!    times the robust scale (3. below) of every row's residual over its
//!    instrument's σ on the axis: the instrument says how the rows'
//!    noise compares, the residuals say its level (on a real robot the
//!    model's own error may be ten times the tracker's σ: standardised by
//!    the σ alone, nearly every row would be weighted down);
//! 2. else the σ of its configuration as eq. 14 estimates it, from the
//!    *other* rows of its configuration and kind (the root mean square of
//!    their residuals on the axis), when there are at least
//!    [`crate::calibrate::Policy::robust_group_rows`] of them: the paper's
//!    premise, noise that varies over the workspace, is kept, and a row
//!    does not hide behind the σ it inflates;
//! 3. else the robust scale of the rows of its kind on that axis,
//!    `sₐ = 1.4826 · median |rₐ − median rₐ|` (the median absolute
//!    deviation: half the rows may be outliers before it moves).
//!
//! With `zᵢ = (rᵢₐ / sᵢₐ)ₐ` and `dᵢ = ‖zᵢ‖`, Huber's weight is
//!
//! ```text
//!   wᵢ = 1          when dᵢ ≤ k
//!   wᵢ = k / dᵢ     beyond,        k = Policy::huber_k (3.37, √χ²₃ at 99 %)
//! ```
//!
//! and the row enters the design times `√wᵢ` ([`Rows::set_robust`]) —
//! on top of the paper's weights per configuration and axis (eq. 14),
//! which the fit estimates from the rows as it sees them. The whole job
//! (declared fit and closed loop) is fitted again with the new weights
//! until none moves by more than [`crate::calibrate::Policy::robust_tolerance`]
//! (`crate::calibrate::run`): iteratively reweighted least squares of
//! Huber's loss, whose minimum is unique for a given model.
//!
//! The σ the report gives are the sandwich's of the weighted fit (eq. 8,
//! 11) with these weights held: the rows weighted down count for less.
//!
//! The kinds are four: absolute positions, deflections, a 6-D pose's
//! orientations (their residuals in µrad, their σ in rad: a pose's point
//! and its orientation are weighted each by its own residual, so that an
//! orientation the instrument lost does not take its good point with it),
//! and plane contacts and distances (one number each, standardised on its
//! axis alone against the one-axis threshold that keeps the same share of
//! normal rows, `k · √(χ²₁/χ²₃)` at 99 %: 2.576 for 3.37).

use nalgebra::Vector3;

use crate::calibrate::params::names::Names;
use crate::calibrate::report::{OrientationErrors, RowErrors, ScalarErrors};
use crate::calibrate::rows::{RowKind, Rows};

/// The consistency factor of the median absolute deviation for a normal
/// distribution: `1 / Φ⁻¹(3/4)`.
const MAD_NORMAL: f64 = 1.482_602_218_505_602;

/// What the robust loss needs of a row: its configuration, kind and
/// instrument's σ (taken before the rows go to the fit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowNoise {
    /// `config` as in the CSV.
    pub config: i64,
    /// Marker id.
    pub marker: u32,
    /// Its kind ([`RowNoise::kind`]).
    pub kind: NoiseKind,
    /// The instrument's σ per axis (\[m\]; an orientation's \[rad\]), when
    /// the row has one.
    pub sigma_m: Option<Vector3<f64>>,
}

/// The kinds of rows the robust loss scales apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum NoiseKind {
    /// An absolute position.
    Position = 0,
    /// A deflection (loaded minus unloaded position).
    Deflection = 1,
    /// A 6-D pose's orientation.
    Orientation = 2,
    /// A plane contact or a distance: one number, on axis 0.
    Scalar = 3,
}

impl NoiseKind {
    /// As the report's notes name it.
    pub fn name(self) -> &'static str {
        match self {
            NoiseKind::Position => "position",
            NoiseKind::Deflection => "deflection",
            NoiseKind::Orientation => "orientation",
            NoiseKind::Scalar => "contact or distance",
        }
    }

    /// The axes its residuals have: 3, or 1 for a plane contact or a
    /// distance (its number on axis 0).
    fn axes(self) -> usize {
        if self == NoiseKind::Scalar {
            1
        } else {
            3
        }
    }
}

/// The kinds, in [`NoiseKind`]'s order.
const KINDS: [NoiseKind; 4] = [
    NoiseKind::Position,
    NoiseKind::Deflection,
    NoiseKind::Orientation,
    NoiseKind::Scalar,
];

/// Huber's threshold on one axis for `k` on three: the same share of
/// normal rows kept at weight 1 (at the default `k = 3.37 = √χ²₃(0.99)`,
/// `√χ²₁(0.99) = 2.576`).
fn one_axis(k: f64) -> f64 {
    k * CHI1_99.sqrt() / CHI3_99.sqrt()
}

/// The 99 % quantiles of χ² with one and three degrees of freedom.
const CHI1_99: f64 = 6.634_896_601_021_214;
const CHI3_99: f64 = 11.344_866_730_144_373;

/// [`RowNoise`] of every row of `rows` (markers named by `names`), in row
/// order.
pub fn noise_of(rows: &Rows, names: &Names) -> Vec<RowNoise> {
    rows.rows
        .iter()
        .map(|r| RowNoise {
            config: rows.configs.get(r.group()).copied().unwrap_or_default(),
            marker: names.markers.get(usize::from(r.marker)).map_or(0, |m| m.0),
            kind: match (r.orientation, r.kind) {
                (true, _) => NoiseKind::Orientation,
                (false, RowKind::Deflection) => NoiseKind::Deflection,
                (false, RowKind::Absolute) if r.scalar().is_some() => NoiseKind::Scalar,
                (false, RowKind::Absolute) => NoiseKind::Position,
            },
            sigma_m: r.sigma(),
        })
        .collect()
}

/// The median of `v` (sorted in place); 0 when empty.
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// The robust scale per axis \[µm\] of the residuals `r` (µm) of one kind:
/// `1.4826 · MAD`.
fn scale(r: &[Vector3<f64>]) -> Vector3<f64> {
    Vector3::from_fn(|a, _| {
        let mut v: Vec<f64> = r.iter().map(|x| x[a]).collect();
        let m = median(&mut v);
        let mut dev: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
        MAD_NORMAL * median(&mut dev)
    })
}

/// The final residuals of every row (µm; an orientation's µrad), in row
/// order: the points' ([`RowErrors`]), then the plane contacts' and
/// distances' when reported apart from points (`apart`:
/// [`ScalarErrors::residuals_um`]; in data of those alone they are the
/// [`RowErrors`]), then the poses' orientations'
/// ([`OrientationErrors::residuals_urad`]).
pub fn residuals(
    errors: &RowErrors,
    apart: Option<&ScalarErrors>,
    orientation: Option<&OrientationErrors>,
) -> Vec<Vector3<f64>> {
    let numbers = apart.map_or(&[][..], |s| &s.residuals_um[..]);
    let turned = orientation.map_or(&[][..], |o| &o.residuals_urad[..]);
    errors
        .iter()
        .map(|e| e.final_um)
        .chain(numbers.iter().copied())
        .chain(turned.iter().copied())
        .collect()
}

/// Huber's weight of every row (in `(0, 1]`, row order) from the final
/// residuals `res` (µm or µrad, one per row of `noise`, the same order:
/// [`residuals`]), with threshold `k`, each standardised as the module
/// says (`group_rows`: the fewest other rows of a configuration and kind
/// whose σ standardises a row). A row whose standardised residual cannot
/// be formed (a scale of zero on an axis: a fit that reproduces the rows)
/// keeps weight 1.
pub fn huber(noise: &[RowNoise], res: &[Vector3<f64>], k: f64, group_rows: usize) -> Vec<f64> {
    let of_kind = |kind: NoiseKind| (noise.iter().zip(res)).filter(move |(n, _)| n.kind == kind);
    let scales = KINDS.map(|kind| scale(&of_kind(kind).map(|(_, r)| *r).collect::<Vec<_>>()));
    // Per kind, the robust scale of the residuals over the instrument's σ
    // (a number's on its axis alone).
    let levels = KINDS.map(|kind| {
        let z: Vec<Vector3<f64>> = of_kind(kind)
            .filter_map(|(n, r)| {
                let s = n.sigma_m? * 1e6;
                Some(Vector3::from_fn(|a, _| {
                    if a < kind.axes() {
                        r[a] / s[a]
                    } else {
                        0.0
                    }
                }))
            })
            .collect();
        scale(&z)
    });
    // Per configuration and kind: the sum of squares per axis and the rows.
    let mut sums: std::collections::HashMap<(i64, NoiseKind), (Vector3<f64>, usize)> =
        std::collections::HashMap::new();
    for (n, r) in noise.iter().zip(res) {
        let e = sums
            .entry((n.config, n.kind))
            .or_insert((Vector3::zeros(), 0));
        e.0 += r.component_mul(r);
        e.1 += 1;
    }
    noise
        .iter()
        .zip(res)
        .map(|(n, r)| {
            let s = match (n.sigma_m, sums.get(&(n.config, n.kind))) {
                (Some(s), _) => (s * 1e6).component_mul(&levels[n.kind as usize]),
                (None, Some((ss, m))) if *m > group_rows.max(1) => {
                    ((ss - r.component_mul(r)) / (m - 1) as f64).map(|v| v.max(0.0).sqrt())
                }
                _ => scales[n.kind as usize],
            };
            // A number is standardised on its axis alone, against the
            // one-axis threshold.
            let axes = n.kind.axes();
            if !s.iter().take(axes).all(|&x| x > 0.0 && x.is_finite()) {
                return 1.0;
            }
            let d = (0..axes).map(|a| (r[a] / s[a]).powi(2)).sum::<f64>().sqrt();
            let k = if axes == 1 { one_axis(k) } else { k };
            if d.is_finite() && d > k {
                (k / d).max(f64::MIN_POSITIVE)
            } else {
                1.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scale_of_normal_residuals_is_their_sigma_and_ignores_a_few_far_ones() {
        // A normal sample of σ 3: Box–Muller on a fixed lattice.
        let n = 2000;
        let mut r: Vec<Vector3<f64>> = (0..n)
            .map(|i| {
                let u1 = (i as f64 + 0.5) / n as f64;
                let u2 = ((i * 7919) % n) as f64 / n as f64;
                let rad = (-2.0 * u1.ln()).sqrt();
                let t = 2.0 * std::f64::consts::PI * u2;
                Vector3::new(
                    3.0 * rad * t.cos(),
                    3.0 * rad * t.sin(),
                    3.0 * rad * t.cos(),
                )
            })
            .collect();
        let s = scale(&r);
        for a in 0..3 {
            assert!((s[a] - 3.0).abs() < 0.15, "axis {a}: {}", s[a]);
        }
        for x in r.iter_mut().take(40) {
            *x = Vector3::repeat(5e4);
        }
        let t = scale(&r);
        for a in 0..3 {
            assert!((t[a] - 3.0).abs() < 0.3, "axis {a}: {}", t[a]);
        }
    }

    #[test]
    fn huber_weights_a_far_row_by_k_over_its_distance() {
        // ±1 µm on every axis, alternating: median 0, MAD 1 µm. The
        // instrument says 10 µm, so its level is 0.148 and every row is
        // standardised by 1.4826 µm; row 3 is 4 mm off on y.
        let configs: std::sync::Arc<[i64]> = (0..12).collect::<Vec<_>>().into();
        let mut res: Vec<Vector3<f64>> = (0..12)
            .map(|i| Vector3::repeat(if i % 2 == 0 { -1e-6 } else { 1e-6 }))
            .collect();
        res[3].y = 4e-3;
        let noise: Vec<RowNoise> = (0..12)
            .map(|config| RowNoise {
                config,
                marker: 1,
                kind: NoiseKind::Position,
                sigma_m: Some(Vector3::repeat(10e-6)),
            })
            .collect();
        let errors = RowErrors::new(configs, vec![1], (0..12).map(|i| (i, 0u8, false)), res);
        let w = huber(&noise, &residuals(&errors, None, None), 3.37, 4);
        let d: f64 = Vector3::new(1.0_f64, 4000.0, 1.0).norm() / MAD_NORMAL;
        assert!(
            (w[3] - 3.37 / d).abs() < 1e-9 * w[3],
            "{} {}",
            w[3],
            3.37 / d
        );
        assert!(w.iter().enumerate().all(|(i, &x)| i == 3 || x == 1.0));
    }
}
