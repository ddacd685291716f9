//! The orientation of a measured pose as rows of the identification
//! problem (data contract extension: `rx, ry, rz`).
//!
//! A 6-D instrument (a laser tracker's 6-D probe, a motion-capture rigid
//! body) measures the marker's link frame's rotation `R_meas` beside its
//! point. Its row is the rotation left between the measurement and the
//! model, in the measurement frame, `y = log(R_meas R_predᵀ)` \[rad\]
//! (a rotation vector), and a parameter `x` turns the frame by
//! `∂θ/∂x · x` to first order: `R_meas ≈ Exp(Σ ∂θ/∂x x) R_pred`.
//!
//! The turn of every parameter follows from its position column: a column
//! is affine in the point it is taken at, `c(p) = v + W p`, with `W = [ω]×`
//! for a rigid motion of the frame (a joint's offset, a frame error, the
//! base, a compliance's yield, a link's bending) and `W = s I` for a
//! stretch (thermal expansion), so `ω` is read from the columns at `p`,
//! `p + eₓ` and `p + e_y` ([`crate::model::turn`], the core's rule, which
//! a device's pose rows use too:
//! [`crate::model::Layout::orientation_block`]): a stretch and a marker's
//! position do not turn the frame. One rule for every effect, present and
//! future.
//!
//! A pose's orientation rows are groups of their own in eq. 14's noise per
//! configuration and axis (a σ in rad, not in m): configuration `c`'s
//! orientation is the group after every position group
//! ([`super::Rows::configs`] lists `c` again for it).

use nalgebra::{Rotation3, Vector3};

/// The points, relative to the marker's, the columns are taken at beside
/// it for [`crate::model::turn`] \[m\] (a lever of 1 m: the differences
/// are the turn itself).
pub const PROBES: [Vector3<f64>; 2] = [Vector3::new(1.0, 0.0, 0.0), Vector3::new(0.0, 1.0, 0.0)];

/// The rotation left between a measured orientation (rotation vector
/// `measured_rad`) and the predicted `predicted`, in the measurement frame:
/// `log(R_meas R_predᵀ)` \[rad\].
pub fn residual(measured_rad: &Vector3<f64>, predicted: &Rotation3<f64>) -> Vector3<f64> {
    (Rotation3::new(*measured_rad) * predicted.transpose()).scaled_axis()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::turn;

    #[test]
    fn the_turn_of_a_rigid_motion_and_of_a_stretch() {
        let w = Vector3::new(0.3, -0.2, 0.7);
        let v = Vector3::new(1.0, 2.0, 3.0);
        let c = |p: Vector3<f64>| v + w.cross(&p) + p * 0.05;
        let p = Vector3::new(0.4, -1.1, 0.9);
        let t = turn(&c(p), &c(p + PROBES[0]), &c(p + PROBES[1]));
        assert!((t - w).norm() < 1e-12, "{t}");
    }

    #[test]
    fn the_residual_is_the_rotation_left() {
        let pred = Rotation3::new(Vector3::new(0.2, 1.0, -0.5));
        let d = Vector3::new(1e-3, -2e-3, 5e-4);
        let meas = (Rotation3::new(d) * pred).scaled_axis();
        assert!((residual(&meas, &pred) - d).norm() < 1e-12);
    }
}
