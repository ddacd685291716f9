//! The noise scale of a row: eq. 14's σ per configuration and axis is a
//! measured point's, and a deflection (the difference of two points) has
//! `√2` times it. When the rows mix both kinds the design holds every
//! deflection scaled by `1/√2` ([`noise_scale`]) and the residuals are
//! reported in metres again ([`Rows::unscaled`]).
//!
//! A robust loss ([`crate::calibrate::robust`]) scales a row further, by
//! `√w` of its weight `w` ([`row_scale`]): the same as weighting it by `w`
//! in every sum of squares, while eq. 14's σ of its configuration stays
//! estimated from the rows as the fit sees them and the instrument's σ of
//! its configuration stays the instrument's.

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

/// The factor `row` enters the design with (`y` and columns): its kind's
/// [`noise_scale`] times its robust loss's `√w` ([`Row::robust`]).
pub fn row_scale(mixed: bool, row: &Row) -> f64 {
    let s = noise_scale(mixed, row.kind);
    match row.extra.as_ref().and_then(|e| e.robust) {
        Some(r) => s * r,
        None => s,
    }
}

/// A row's left-hand side `y` ([`Rows::y`]) as the design holds it: times
/// [`row_scale`] (not multiplied where the scale is 1): the same values
/// wherever a pass needs them ([`crate::calibrate::design::Design`]).
pub fn scaled_y(mixed: bool, row: &Row, y: Vector3<f64>) -> Vector3<f64> {
    let s = row_scale(mixed, row);
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

    /// Whether any row enters the design scaled ([`row_scale`] other
    /// than 1): rows of both kinds, or a robust loss's weights.
    pub fn scaled(&self) -> bool {
        self.mixed() || self.rows.iter().any(|r| r.robust() != 1.0)
    }

    /// [`row_scale`] of `row`: the factor it enters the design with;
    /// residuals are reported unscaled ([`Rows::unscaled`]).
    pub fn noise_scale(&self, row: &Row) -> f64 {
        row_scale(self.mixed(), row)
    }

    /// Sets each row's robust factor `√w` ([`Row::robust`]) from `scales`,
    /// one per row in row order; a factor of 1 is none.
    ///
    /// # Errors
    /// When `scales` is not one per row, or a factor is not in `(0, 1]`.
    pub fn set_robust(&mut self, scales: &[f64]) -> Result<(), crate::error::Error> {
        if scales.len() != self.rows.len() || !scales.iter().all(|&s| s > 0.0 && s <= 1.0) {
            return Err(crate::error::Error::Mismatch {
                what: "robust factors: one per row, each in (0, 1]",
            });
        }
        for (row, &s) in self.rows.iter_mut().zip(scales) {
            if s == 1.0 {
                if let Some(e) = &mut row.extra {
                    e.robust = None;
                }
            } else {
                row.extra_mut().robust = Some(s);
            }
        }
        Ok(())
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
