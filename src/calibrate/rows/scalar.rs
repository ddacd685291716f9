//! A plane contact or a distance as a row of the identification problem
//! (issue 53; data contract extension: CSV `plane`, `anchor`, `distance`).
//!
//! Without a tracker, a touch probe, a ballbar or a draw-wire sensor
//! measures one number about the marker's point `p`: its signed distance
//! from a plane fixed in the measurement frame, `s = n · p − d` (unit
//! normal `n`), or its distance from an anchor point `c` fixed there,
//! `s = |p − c|`. Its row is one equation: the measured number minus the
//! predicted, `y = s_meas − s(p)` \[m\], and each parameter's column is the
//! position column projected on the gradient `u = ∂s/∂p` (`n`, or the unit
//! vector from `c` to `p`): `uᵀ ∂p/∂x`. So every parameter and effect of
//! the model acts on it as on a point.
//!
//! The row keeps the engine's three-axis layout with its number on axis 0
//! and zeros on the other two, which are no equations: the rows are groups
//! of their own ([`super::Rows::scalar_range`]), and the design weighs
//! their second and third axes 0 in every sum and counts no rows there in
//! eq. 14's σ ([`crate::calibrate::design::Design::live`]).
//!
//! The plane and the anchor are given in the setup, in the measurement
//! frame: alone, the measurement frame is theirs, and the base frame
//! (`base_frame = true`) says where the robot stands relative to them.
//! What the numbers cannot tell (a plane says nothing of a shift along it
//! or a turn about its normal; one anchor nothing of a turn about it) the
//! independence test leaves out, and the report names.

use nalgebra::Vector3;

pub use crate::io::measurements::Scalar;

/// Which axes of such a row are equations: its number's, axis 0.
pub const LIVE: [f64; 3] = [1.0, 0.0, 0.0];

impl Scalar {
    /// The number predicted for the point `p_m` \[m, measurement frame\]:
    /// `n · p − d`, or `|p − c|`.
    pub fn of(&self, p_m: &Vector3<f64>) -> f64 {
        match *self {
            Scalar::Plane {
                normal, offset_m, ..
            } => Vector3::from(normal).dot(p_m) - offset_m,
            Scalar::Distance { anchor_m, .. } => (p_m - Vector3::from(anchor_m)).norm(),
        }
    }

    /// Its gradient `u = ∂s/∂p` at `p_m`: the plane's normal, or the unit
    /// vector from the anchor to the point (zero at the anchor).
    pub fn gradient(&self, p_m: &Vector3<f64>) -> Vector3<f64> {
        match *self {
            Scalar::Plane { normal, .. } => Vector3::from(normal),
            Scalar::Distance { anchor_m, .. } => (p_m - Vector3::from(anchor_m))
                .try_normalize(0.0)
                .unwrap_or_else(Vector3::zeros),
        }
    }

    /// The row's left-hand side at the point `p_m`, on axis 0: the
    /// measured number minus the predicted, plus the projection of the
    /// point's linearised joint-law part `linear` \[m\] (zero for the
    /// first-order model).
    pub fn lhs(&self, p_m: &Vector3<f64>, linear: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(
            self.value_m() - self.of(p_m) + self.gradient(p_m).dot(linear),
            0.0,
            0.0,
        )
    }

    /// A position column `column` at the point `p_m` as the row's: its
    /// projection on the gradient, on axis 0.
    pub fn column(&self, p_m: &Vector3<f64>, column: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(self.gradient(p_m).dot(column), 0.0, 0.0)
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::Scalar;

    /// The row's column is the derivative of the number: central
    /// differences of `s(p + t v)` along the column `v`.
    #[test]
    fn the_column_is_the_derivative_of_the_number() {
        let p = Vector3::new(0.3, -0.2, 0.9);
        let v = Vector3::new(0.2, 0.7, -0.4);
        let n = Vector3::new(1.0, 2.0, 2.0) / 3.0;
        for s in [
            Scalar::Plane {
                id: 1,
                normal: n.into(),
                offset_m: 0.25,
                value_m: 0.0,
            },
            Scalar::Distance {
                id: 1,
                anchor_m: [0.1, 0.4, -0.3],
                value_m: 1.0,
            },
        ] {
            let h = 1e-6;
            let fd = (s.of(&(p + v * h)) - s.of(&(p - v * h))) / (2.0 * h);
            let col = s.column(&p, &v);
            assert!((col.x - fd).abs() < 1e-9, "{s:?}: {} vs {fd}", col.x);
            assert_eq!((col.y, col.z), (0.0, 0.0));
        }
        // The plane's number: n · p − d.
        let plane = Scalar::Plane {
            id: 1,
            normal: n.into(),
            offset_m: 0.25,
            value_m: 0.01,
        };
        let want = n.dot(&p) - 0.25;
        assert!((plane.of(&p) - want).abs() < 1e-15);
        assert!((plane.lhs(&p, &Vector3::zeros()).x - (0.01 - want)).abs() < 1e-15);
    }
}
