//! The noise scale of a row: eq. 14's σ per configuration and axis is a
//! measured point's, and a deflection (the difference of two points) has
//! `√2` times it. When the rows mix both kinds the design holds every
//! deflection scaled by `1/√2` ([`noise_scale`]) and the residuals are
//! reported in metres again ([`Rows::unscaled`]).

use nalgebra::Vector3;

use crate::calibrate::rows::{Row, RowKind, Rows};

/// The factor a row of `kind` enters the design with (`y`, columns,
/// instrument σ) when the rows mix both kinds (`mixed`): `1/√2` for a
/// deflection (two points' noise), else 1, so that eq. 14's σ per
/// configuration and axis is one point's (`docs/numerics.md` §7).
pub fn noise_scale(mixed: bool, kind: RowKind) -> f64 {
    if mixed && kind == RowKind::Deflection {
        std::f64::consts::FRAC_1_SQRT_2
    } else {
        1.0
    }
}

/// A row's left-hand side `y` ([`Rows::y`]) as the design holds it: times
/// [`noise_scale`] (not multiplied where the scale is 1): the same values
/// wherever a pass needs them ([`crate::calibrate::design::Design`]).
pub fn scaled_y(mixed: bool, row: &Row, y: Vector3<f64>) -> Vector3<f64> {
    let s = noise_scale(mixed, row.kind);
    if s == 1.0 {
        y
    } else {
        y * s
    }
}

impl Rows {
    /// Whether the rows are of both kinds (deflections and absolute).
    pub fn mixed(&self) -> bool {
        self.kinds.absolute && self.kinds.deflections
    }

    /// [`noise_scale`] of `row`; residuals are reported unscaled
    /// ([`Rows::unscaled`]).
    pub fn noise_scale(&self, row: &Row) -> f64 {
        noise_scale(self.mixed(), row.kind)
    }

    /// Row `i`'s residual `r` from the design (scaled by
    /// [`Rows::noise_scale`]) in metres again.
    pub fn unscaled(&self, i: usize, r: Vector3<f64>) -> Vector3<f64> {
        match self.rows.get(i).map(|row| self.noise_scale(row)) {
            Some(s) if s != 1.0 => r / s,
            _ => r,
        }
    }
}
