//! How far the nominal model moves the markers across the configurations:
//! the spread the scale check compares ([`spread`]) and the rules on
//! poses that barely move the markers, overall, off a line or off a plane
//! ([`barely_moved`]).
//!
//! The rules are about the same thing: where the nominal robot's points
//! barely move in some direction, the data excite the geometry there only
//! by its errors. A parameter whose column is zero or dependent at the
//! nominal robot may then move the true robot's points, and the reduced
//! model cannot follow. Points on a line are the sharpest case for the
//! base frame: a rigid registration onto collinear points leaves the
//! rotation about the line undetermined. Points in a plane determine the
//! base, but not what tilts the joints out of it: a random chain of the
//! property tests (seed 5517115213884886855, two parallel joints and a
//! marker on the third joint's axis; its nominal points in a plane, the
//! measured ones off it by the robot's errors) ended "converged" at 85.8 µm
//! against 32 µm of noise, with 14 of 21 parameters left out and no
//! warning.

use nalgebra::{Matrix3, Vector3};

use crate::calibrate::settings::Policy;

/// RMS spread about the centroid of `v` \[m\].
pub(super) fn spread(v: impl Iterator<Item = Vector3<f64>> + Clone) -> f64 {
    let n = v.clone().count().max(1) as f64;
    let c = v.clone().sum::<Vector3<f64>>() / n;
    (v.map(|p| (p - c).norm_squared()).sum::<f64>() / n).sqrt()
}

/// The RMS spreads \[m\] of `v` along its three principal directions
/// (square roots of the eigenvalues of the points' covariance about their
/// centroid), largest first.
pub(super) fn principal(v: impl Iterator<Item = Vector3<f64>> + Clone) -> [f64; 3] {
    let n = v.clone().count().max(1) as f64;
    let c = v.clone().sum::<Vector3<f64>>() / n;
    let cov: Matrix3<f64> = v
        .map(|p| (p - c) * (p - c).transpose())
        .sum::<Matrix3<f64>>()
        / n;
    let mut e: [f64; 3] = cov.symmetric_eigenvalues().into();
    e.sort_by(|a, b| b.total_cmp(a));
    e.map(|l| l.max(0.0).sqrt())
}

/// The warning on the nominal model's predicted points `predicted`
/// (unloaded rows) of the file `file`, if any: spread overall less than
/// [`Policy::min_spread_m`]; or within it of a line (the second principal
/// spread), or of a plane (the third), while beyond it along them.
pub(super) fn barely_moved(
    file: &std::path::Path,
    predicted: impl Iterator<Item = Vector3<f64>> + Clone,
    policy: &Policy,
) -> Option<String> {
    let overall = spread(predicted.clone());
    if overall < policy.min_spread_m {
        return Some(format!(
            "{}: the nominal model moves the markers over only {:.3} mm across the \
             configurations: the poses barely move them, and what is left out as dependent \
             at the nominal robot may matter at the true one",
            file.display(),
            overall * 1e3
        ));
    }
    let [first, second, third] = principal(predicted);
    if second < policy.min_spread_m {
        return Some(format!(
            "{}: the nominal model moves the markers along a line only ({:.1} mm along it, \
             {:.3} mm off it, RMS across the configurations): the poses barely move them off \
             the line, a rotation about it is not determined at the nominal robot, and what \
             is left out as dependent there may matter at the true one; measure poses that \
             move the markers off the line (another joint, or a marker off the last axis)",
            file.display(),
            first * 1e3,
            second * 1e3
        ));
    }
    (third < policy.min_spread_m).then(|| {
        format!(
            "{}: the nominal model moves the markers in a plane only ({:.1} and {:.1} mm \
             across it, {:.3} mm off it, RMS across the configurations): the poses barely \
             move them off the plane, and what is left out as dependent at the nominal robot \
             (a tilt of the joints out of the plane) may matter at the true one, whose joints \
             need not be parallel; measure poses that move the markers off the plane",
            file.display(),
            first * 1e3,
            second * 1e3,
            third * 1e3
        )
    })
}

#[cfg(test)]
mod tests {
    use crate::calibrate::report::plausibility::spread::*;

    fn points(f: impl Fn(f64) -> Vector3<f64>) -> Vec<Vector3<f64>> {
        (0..26).map(|i| f(i as f64 / 25.0 - 0.5)).collect()
    }

    /// Spread overall, along a line, off it: the principal spreads of
    /// points on a line and on a circle, against their formulas.
    #[test]
    fn the_principal_spreads_are_those_of_the_points() {
        let line = points(|t| Vector3::new(0.3, -0.2, 1.0) * t + Vector3::new(2.0, 1.0, -3.0));
        let [a, b, c] = principal(line.iter().copied());
        // t evenly over [-0.5, 0.5] at N points: variance (N + 1) / (12 (N − 1)).
        let n = line.len() as f64;
        let rms_t = ((n + 1.0) / (12.0 * (n - 1.0))).sqrt();
        let expect: f64 = Vector3::new(0.3, -0.2, 1.0).norm() * rms_t;
        assert!((a - expect).abs() < 1e-12, "{a} {expect}");
        assert!(b < 1e-7 && c < 1e-7, "{b} {c}");
        assert!((spread(line.iter().copied()) - a).abs() < 1e-12);
        // A circle of radius 0.2 m in a tilted plane: two spreads of
        // 0.2/√2, none off the plane.
        let circle: Vec<Vector3<f64>> = (0..64)
            .map(|k| {
                let t = k as f64 * core::f64::consts::TAU / 64.0;
                let (u, v) = (Vector3::new(1.0, 1.0, 0.0).normalize(), Vector3::z());
                (u * t.cos() + v * t.sin()) * 0.2
            })
            .collect();
        let [a, b, c] = principal(circle.iter().copied());
        let r = 0.2 / 2f64.sqrt();
        assert!(
            (a - r).abs() < 1e-12 && (b - r).abs() < 1e-12 && c < 1e-7,
            "{a} {b} {c}"
        );
    }

    /// A random chain of the property tests (seed 1202820159449195811 of
    /// `host-tests/tests/identifiability.rs`) whose marker sits on its last
    /// joint's axis behind a prismatic joint: its points lie on a line
    /// at the nominal robot (158.4 mm along it) and the fit ended at
    /// 470.6 µm against 33 µm of noise with no warning. Points on a line
    /// or in a plane are a warning; moved off them by more than the bound,
    /// they are not.
    #[test]
    fn points_on_a_line_or_in_a_plane_are_a_warning() {
        let policy = Policy::default();
        let file = std::path::Path::new("arm.csv");
        let dir = Vector3::new(0.1, 0.9, -0.2).normalize();
        let line = points(|t| dir * (0.55 * t) + Vector3::new(0.0, -0.9, -2.9));
        let w = barely_moved(file, line.iter().copied(), &policy).expect("a warning");
        assert!(
            w.starts_with("arm.csv: the nominal model moves the markers along a line only"),
            "{w}"
        );
        assert!(w.contains("barely move"), "{w}");
        assert!(w.contains("0.000 mm off it"), "{w}");
        // Off the line by 5 mm RMS (a circle of radius 7.07 mm about it):
        // still a line; by 20 mm not.
        let normal = dir.cross(&Vector3::z()).normalize();
        let binormal = dir.cross(&normal);
        let around = |radius: f64| {
            line.iter()
                .enumerate()
                .map(|(k, p)| {
                    let t = k as f64 * core::f64::consts::TAU / 4.0;
                    p + (normal * t.cos() + binormal * t.sin()) * radius
                })
                .collect::<Vec<_>>()
        };
        let w = barely_moved(file, around(5e-3 * 2f64.sqrt()).iter().copied(), &policy)
            .expect("a warning");
        assert!(w.contains("along a line only"), "{w}");
        assert!(barely_moved(file, around(20e-3 * 2f64.sqrt()).iter().copied(), &policy).is_none());
        // Points in a plane: their own warning; lifted off it by 20 mm RMS
        // (alternately above and below), none.
        let plane: Vec<Vector3<f64>> = (0..36)
            .map(|k| Vector3::new((k % 6) as f64 * 0.1, (k / 6) as f64 * 0.1, 1.0))
            .collect();
        let w = barely_moved(file, plane.iter().copied(), &policy).expect("a warning");
        assert!(
            w.contains("in a plane only") && w.contains("0.000 mm off it"),
            "{w}"
        );
        assert!(w.contains("barely move"), "{w}");
        let lifted: Vec<Vector3<f64>> = plane
            .iter()
            .enumerate()
            .map(|(k, p)| p + Vector3::z() * if (k + k / 6) % 2 == 0 { 0.02 } else { -0.02 })
            .collect();
        assert!(barely_moved(file, lifted.iter().copied(), &policy).is_none());
        // Overall under the bound: the first rule, its message unchanged.
        let still = points(|t| dir * (1e-3 * t));
        let w = barely_moved(file, still.iter().copied(), &policy).expect("a warning");
        assert!(w.contains("moves the markers over only"), "{w}");
    }
}
