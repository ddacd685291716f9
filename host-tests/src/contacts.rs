//! Plane contacts and distances (issue 53): a true robot whose joint zeros
//! are off, its probe touching planes fixed in the world (a touch probe), or
//! its distance from an anchor read by a draw-wire sensor. Nothing here
//! calls robcal's kinematics, columns or engine: the forward kinematics is
//! [`super::exact::Fk`] (urdf-rs, 4 × 4 matrices), a contact found by
//! Newton's method on one joint.

use nalgebra::{Matrix3, Rotation3, Vector3};
use robcal_paper::rng::SplitMix64;

use super::poses::{Arm, Truth};

/// What a row measures: a contact with a plane `n · p = d` (unit `n`), or
/// the distance from an anchor.
#[derive(Debug, Clone, Copy)]
pub enum Target {
    /// A plane, id, unit normal and offset \[m\] (`n · p = d`).
    Plane(u32, Vector3<f64>, f64),
    /// An anchor, id and position \[m\].
    Anchor(u32, Vector3<f64>),
}

/// The true probe's point at commanded joint values `q` \[m, the robot's
/// base frame\].
pub fn point(arm: &Arm, truth: &Truth, q: &[f64]) -> Vector3<f64> {
    let theta: Vec<f64> = q.iter().zip(&truth.offsets).map(|(q, o)| q + o).collect();
    let pose = arm.fk.pose(&theta);
    let r = Rotation3::from_matrix_unchecked(Matrix3::from(pose.tip.fixed_view::<3, 3>(0, 0)));
    let p = pose.tip.fixed_view::<3, 1>(0, 3).into_owned();
    p + r * (truth.tool_t + Rotation3::new(truth.tool_r) * arm.marker_m)
}

/// Joint values drawn within `arm`'s ranges \[rad\].
fn draw(arm: &Arm, rng: &mut SplitMix64) -> Vec<f64> {
    arm.ranges
        .iter()
        .map(|&(lo, hi)| rng.range(lo, hi))
        .collect()
}

/// `n` rows of the true robot as a measurement CSV (units m and rad): each
/// a random pose, the targets in turn. A plane's row is a contact: the
/// commanded pose moved by Newton's method on the joint that moves the
/// probe most along the normal until the true point is `ε ~ N(0, σ)` off
/// the plane, written as distance 0 (a contact); an anchor's the true
/// distance plus `N(0, σ)`. `sd` is `sigma_m` on every row.
pub fn csv(
    arm: &Arm,
    truth: &Truth,
    targets: &[Target],
    sigma_m: f64,
    n: usize,
    rng: &mut SplitMix64,
) -> String {
    let mut out = format!("config,{},plane,anchor,distance,sd\n", arm.joints.join(","));
    let mut row = 0;
    while row < n {
        let mut q = draw(arm, rng);
        let target = targets[row % targets.len()];
        let cells = match target {
            Target::Plane(id, normal, d) => {
                let eps = rng.normal() * sigma_m;
                let f = |q: &[f64]| normal.dot(&point(arm, truth, q)) - d - eps;
                // The joint that moves the probe most along the normal.
                let h = 1e-6;
                let slope = |q: &[f64], j: usize| {
                    let (mut a, mut b) = (q.to_vec(), q.to_vec());
                    a[j] += h;
                    b[j] -= h;
                    (f(&a) - f(&b)) / (2.0 * h)
                };
                let j = (0..q.len())
                    .max_by(|&a, &b| slope(&q, a).abs().total_cmp(&slope(&q, b).abs()))
                    .unwrap_or(0);
                let mut ok = false;
                for _ in 0..50 {
                    let v = f(&q);
                    if v.abs() < 1e-13 {
                        ok = true;
                        break;
                    }
                    let s = slope(&q, j);
                    if s.abs() < 1e-3 {
                        break;
                    }
                    q[j] -= (v / s).clamp(-0.3, 0.3);
                }
                let (lo, hi) = arm.ranges[j];
                if !ok || q[j] < lo || q[j] > hi {
                    continue;
                }
                format!("{id},,0,{sigma_m}")
            }
            Target::Anchor(id, c) => {
                let d = (point(arm, truth, &q) - c).norm() + rng.normal() * sigma_m;
                format!(",{id},{d:.12},{sigma_m}")
            }
        };
        let qs: Vec<String> = q.iter().map(|v| format!("{v:.12}")).collect();
        out += &format!("{},{},{cells}\n", row + 1, qs.join(","));
        row += 1;
    }
    out
}

/// `n` rows of the true robot held at a pivot `c` \[m, the robot's base
/// frame\] (a ball in a fixed cup): each a random pose moved by Newton's
/// method on the first three joints until the true point is
/// `c + N(0, σ)` per axis, written as the point `c` (units m and rad).
pub fn pivot_csv(
    arm: &Arm,
    truth: &Truth,
    c: Vector3<f64>,
    sigma_m: f64,
    n: usize,
    rng: &mut SplitMix64,
) -> String {
    let mut out = format!("config,{},x,y,z\n", arm.joints.join(","));
    let mut row = 0;
    while row < n {
        let mut q = draw(arm, rng);
        let target = c + Vector3::from_fn(|_, _| rng.normal() * sigma_m);
        let mut ok = false;
        for _ in 0..100 {
            let e = point(arm, truth, &q) - target;
            if e.norm() < 1e-13 {
                ok = true;
                break;
            }
            let h = 1e-6;
            let jac = nalgebra::Matrix3::from_fn(|a, j| {
                let (mut u, mut d) = (q.clone(), q.clone());
                u[j] += h;
                d[j] -= h;
                (point(arm, truth, &u)[a] - point(arm, truth, &d)[a]) / (2.0 * h)
            });
            let Some(step) = jac.try_inverse().map(|inv| inv * e) else {
                break;
            };
            let scale = (0.3 / step.amax()).min(1.0);
            for (qj, s) in q.iter_mut().zip(step.iter()) {
                *qj -= s * scale;
            }
        }
        let inside = (0..3).all(|j| arm.ranges[j].0 <= q[j] && q[j] <= arm.ranges[j].1);
        if !ok || !inside {
            continue;
        }
        let qs: Vec<String> = q.iter().map(|v| format!("{v:.12}")).collect();
        out += &format!("{},{},{},{},{}\n", row + 1, qs.join(","), c.x, c.y, c.z);
        row += 1;
    }
    out
}
