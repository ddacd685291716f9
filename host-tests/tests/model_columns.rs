//! Geometric (eq. 2) and elastostatic (eq. 3) columns against central finite
//! differences of the independent 4×4 reference model (`model_common`).

use crate::model_common;

use model_common::*;
use nalgebra::{Matrix3, Vector3};
use robcal::model::{
    base_columns, compliance_columns, deflection_m, joint_frame_columns, joint_offset_columns,
    marker_columns, tool_columns,
};
use robcal::robot::{gravity_torques, joint_torques, PointLoad, Wrench};
use robcal::Chain;

/// Central-difference step. Truncation error ~h² (1e-12 relative), rounding
/// ~ε·|p|/h ≈ 1e-9 m on positions of a few metres.
const H: f64 = 1e-6;
/// Column tolerance [m per unit parameter]: rounding of the difference
/// quotient dominates (see `H`).
const TOL: f64 = 1e-8;

fn cases() -> Vec<(RefRobot, Vec<Vec<f64>>)> {
    vec![
        (kr270(), PAPER_Q_DEG.iter().map(|q| rad(q)).collect()),
        (arm7(), arm7_poses()),
    ]
}

fn fd(f: impl Fn(f64) -> Vector3<f64>) -> Vector3<f64> {
    (f(H) - f(-H)) / (2.0 * H)
}

fn geometric_case<const J: usize>(robot: &RefRobot, poses: &[Vec<f64>]) {
    let chain: Chain<f64, J> = robot.chain();
    let n = robot.joints.len();
    let zero = Perturb::zero(n);
    let marker = [0.12, -0.07, 0.2];
    for q in poses {
        let frames = chain.frames(q).unwrap();
        let p = frames.point_m(&v(marker));
        // Joint offsets.
        let mut cols = [Vector3::zeros(); J];
        joint_offset_columns(&frames, &p, &mut cols).unwrap();
        for j in 0..n {
            let r = fd(|h| {
                let mut qq = q.clone();
                qq[j] += h;
                robot.point(&qq, &zero, marker)
            });
            assert_close(cols[j], r, TOL, "joint offset");
        }
        // Joint-frame errors, right-multiplying origin_j.
        for j in 0..n {
            let six = joint_frame_columns(&frames, j, &p).unwrap();
            for (k, col) in six.iter().enumerate() {
                let r = fd(|h| {
                    let mut pert = Perturb::zero(n);
                    pert.frame[j][k] = h;
                    robot.point(q, &pert, marker)
                });
                assert_close(*col, r, TOL, "joint frame");
            }
            // The URDF parameters of the joint: xyz (parent frame) and rpy,
            // as combinations of the six frame columns.
            let ro = rpy(robot.joints[j].rpy);
            for k in 0..3 {
                let r = fd(|h| {
                    let mut rb = robot.clone();
                    rb.joints[j].xyz[k] += h;
                    rb.point(q, &zero, marker)
                });
                let pred = (0..3).map(|m| six[m] * ro[(k, m)]).sum::<Vector3<f64>>();
                assert_close(pred, r, TOL, "urdf xyz");
                let mut a = robot.joints[j].rpy;
                let mut b = a;
                a[k] += H;
                b[k] -= H;
                let omega = vee(&(ro.transpose() * (rpy(a) - rpy(b)) / (2.0 * H)));
                let r = fd(|h| {
                    let mut rb = robot.clone();
                    rb.joints[j].rpy[k] += h;
                    rb.point(q, &zero, marker)
                });
                let pred = (0..3).map(|m| six[3 + m] * omega[m]).sum::<Vector3<f64>>();
                assert_close(pred, r, TOL, "urdf rpy");
            }
        }
        // Base frame.
        let base = base_columns(&p);
        for (k, col) in base.iter().enumerate() {
            let r = fd(|h| {
                let mut pert = Perturb::zero(n);
                pert.base[k] = h;
                robot.point(q, &pert, marker)
            });
            assert_close(*col, r, TOL, "base");
        }
        // Marker position in the tip frame.
        for (k, col) in marker_columns(&frames).iter().enumerate() {
            let r = fd(|h| {
                let mut pert = Perturb::zero(n);
                pert.marker[k] = h;
                robot.point(q, &pert, marker)
            });
            assert_close(*col, r, TOL, "marker");
        }
        // Tool frame: the marker moved rigidly in the tip frame,
        // r ← Rot(w) r + t, through the reference's marker argument.
        for (k, col) in tool_columns(&frames, &p).iter().enumerate() {
            let r = fd(|h| {
                let mut d = Vector3::zeros();
                d[k % 3] = h;
                let moved = if k < 3 {
                    v(marker) + d
                } else {
                    nalgebra::Rotation3::from_scaled_axis(d) * v(marker)
                };
                robot.point(q, &zero, [moved.x, moved.y, moved.z])
            });
            assert_close(*col, r, TOL, "tool");
        }
    }
}

#[test]
fn geometric_columns_match_finite_differences() {
    let c = cases();
    geometric_case::<6>(&c[0].0, &c[0].1);
    geometric_case::<7>(&c[1].0, &c[1].1);
}

/// Reference joint torques by virtual work: `τⱼ = ∂(F·c(q))/∂qⱼ + M·ωⱼ`, with
/// `c` a point fixed to the tip and `ωⱼ` the tip's angular velocity per unit
/// `q̇ⱼ`, both by central differences of the reference model.
fn ref_torques(
    robot: &RefRobot,
    q: &[f64],
    c_tip: [f64; 3],
    f: Vector3<f64>,
    m: Vector3<f64>,
) -> Vec<f64> {
    let zero = Perturb::zero(robot.joints.len());
    (0..q.len())
        .map(|j| {
            let shifted = |h: f64| {
                let mut qq = q.to_vec();
                qq[j] += h;
                robot.frames(&qq, &zero).1
            };
            let dc = fd(|h| apply(&shifted(h), v(c_tip)));
            let ra = shifted(H).fixed_view::<3, 3>(0, 0).into_owned();
            let rb = shifted(-H).fixed_view::<3, 3>(0, 0).into_owned();
            let omega = vee(&((ra - rb) / (2.0 * H) * rb.transpose()));
            f.dot(&dc) + m.dot(&omega)
        })
        .collect()
}

fn torque_case<const J: usize>(robot: &RefRobot, poses: &[Vec<f64>]) {
    let chain: Chain<f64, J> = robot.chain();
    let n = robot.joints.len();
    let zero = Perturb::zero(n);
    let com = LOAD_COM;
    let f = Vector3::new(30.0, -20.0, -2500.0);
    let m = Vector3::new(15.0, 40.0, -25.0);
    let g = Vector3::new(0.0, 0.0, -9.80665);
    for q in poses {
        let frames = chain.frames(q).unwrap();
        let c = frames.point_m(&v(com));
        let mut tau = [0.0; J];
        let w = Wrench {
            force_n: f,
            point_m: c,
            moment_nm: m,
        };
        joint_torques(&frames, &w, &mut tau).unwrap();
        let r = ref_torques(robot, q, com, f, m);
        for j in 0..n {
            // FD of positions of ~3 m times forces of 2.5 kN: ~1e-9 · 2500.
            assert!(
                (tau[j] - r[j]).abs() < 1e-5,
                "joint {j}: {} vs {}",
                tau[j],
                r[j]
            );
        }
        // The robot's own weight: τⱼ = ∂(Σ m_l g·c_l(q))/∂qⱼ.
        let mut tg = [0.0; J];
        gravity_torques(&chain, &frames, &g, &mut tg).unwrap();
        for j in 0..n {
            let r = (fd(|h| {
                let mut qq = q.clone();
                qq[j] += h;
                let (fr, _) = robot.frames(&qq, &zero);
                let e: f64 = robot
                    .joints
                    .iter()
                    .zip(&fr)
                    .map(|(jt, t)| {
                        let (mass, c) = jt.link.unwrap();
                        mass * g.dot(&apply(t, v(c)))
                    })
                    .sum();
                Vector3::new(e, 0.0, 0.0)
            }))
            .x;
            assert!(
                (tg[j] - r).abs() < 1e-5 * (1.0 + r.abs()),
                "gravity {j}: {} vs {r}",
                tg[j]
            );
        }
    }
}

#[test]
fn joint_torques_match_virtual_work() {
    let c = cases();
    torque_case::<6>(&c[0].0, &c[0].1);
    torque_case::<7>(&c[1].0, &c[1].1);
}

fn compliance_case<const J: usize>(robot: &RefRobot, poses: &[Vec<f64>], k: &[f64]) {
    let chain: Chain<f64, J> = robot.chain();
    let n = robot.joints.len();
    let zero = Perturb::zero(n);
    // A small load (10 g): joint deflections kⱼτⱼ ≲ 1e-7, so the
    // second-order terms of the exact deflection stay below 1e-6 relative.
    let load = PointLoad {
        mass_kg: 0.01,
        com_m: v(LOAD_COM),
        gravity_mps2: Vector3::new(0.0, 0.0, -9.80665),
    };
    for q in poses {
        let frames = chain.frames(q).unwrap();
        let mut tau = [0.0; J];
        joint_torques(&frames, &load.wrench(&frames), &mut tau).unwrap();
        for marker in tool_markers() {
            let p = frames.point_m(&v(marker));
            let mut cols = [Vector3::zeros(); J];
            compliance_columns(&frames, &p, &tau[..n], &mut cols).unwrap();
            // Each column: the marker's motion per unit kⱼ when joint j
            // alone yields by kⱼτⱼ.
            for j in 0..n {
                let r = fd(|h| {
                    let mut qq = q.clone();
                    qq[j] += h * tau[j];
                    robot.point(&qq, &zero, marker)
                });
                assert_close(cols[j], r, TOL * (1.0 + tau[j].abs()), "compliance column");
            }
            // The exact deflected pose p(q + δq) − p(q), δqⱼ = kⱼτⱼ.
            let qd: Vec<f64> = q
                .iter()
                .zip(&tau)
                .zip(k)
                .map(|((q, t), k)| q + k * t)
                .collect();
            let exact = robot.point(&qd, &zero, marker) - robot.point(q, &zero, marker);
            let lin: Vector3<f64> = cols.iter().zip(k).map(|(c, k)| c * *k).sum();
            assert!(exact.norm() > 1e-9, "deflection too small to test");
            let rel = (lin - exact).norm() / exact.norm();
            assert!(rel <= 1e-6, "relative error {rel:e}");
            let dm = deflection_m(&frames, &p, &tau[..n], k).unwrap();
            assert_close(dm, lin, 1e-18, "deflection_m");
        }
    }
}

#[test]
fn compliance_columns_match_exact_deflection() {
    let c = cases();
    // Compliances of the paper's size (Table 3, rad/(N·m)).
    let k6 = [0.5e-6, 0.287e-6, 0.416e-6, 2.786e-6, 3.483e-6, 2.074e-6];
    compliance_case::<6>(&c[0].0, &c[0].1, &k6);
    // The arm's prismatic joint: 1e-6 m/N.
    let k7 = [1e-6, 1e-6, 0.8e-6, 1.5e-6, 2e-6, 3e-6, 3e-6];
    compliance_case::<7>(&c[1].0, &c[1].1, &k7);
}

#[test]
fn short_slices_are_errors() {
    let chain: Chain<f64, 6> = kr270().chain();
    let frames = chain.frames(&[0.0; 6]).unwrap();
    let mut tau = [0.0; 5];
    let w = Wrench::force(Vector3::z(), Vector3::x());
    assert!(joint_torques(&frames, &w, &mut tau).is_err());
    let mut cols = [Vector3::zeros(); 5];
    assert!(joint_offset_columns(&frames, &Vector3::x(), &mut cols).is_err());
    assert!(compliance_columns(&frames, &Vector3::x(), &[0.0; 6], &mut cols).is_err());
    assert!(joint_frame_columns(&frames, 6, &Vector3::x()).is_err());
}

/// `Param::column` is the free functions above in the parameter's reported
/// unit (`mm`, `mrad`, `urad/(N*m)`, `um/N`: SI × 1e-3 or 1e-6) on an
/// absolute sample; on a deflection the geometric parameters cancel (zero
/// columns) and the compliances act with the sample's torques.
fn param_case<const J: usize>(robot: &RefRobot, poses: &[Vec<f64>]) {
    use robcal::model::{Param, Sample};
    let chain: Chain<f64, J> = robot.chain();
    let n = robot.joints.len();
    let marker = [0.12, -0.07, 0.2];
    let g = Vector3::new(0.0, 0.0, -9.80665);
    let same = |a: Vector3<f64>, b: Vector3<f64>, what: &str| {
        assert!(
            (a - b).norm() <= 1e-15 * (1.0 + b.norm()),
            "{what}: {a:?} vs {b:?}"
        )
    };
    for q in poses {
        let frames = chain.frames(q).unwrap();
        let p = frames.point_m(&v(marker));
        let mut tau = [0.0; J];
        gravity_torques(&chain, &frames, &g, &mut tau).unwrap();
        let abs = Sample::absolute(&frames, p, 2, &tau[..n]);
        let def = Sample::deflection(&frames, p, 2, &tau[..n], None);
        let mut offsets = [Vector3::zeros(); J];
        joint_offset_columns(&frames, &p, &mut offsets).unwrap();
        let mut compliances = [Vector3::zeros(); J];
        compliance_columns(&frames, &p, &tau[..n], &mut compliances).unwrap();
        for j in 0..n {
            let joint = j as u8;
            let off = Param::JointOffset { joint };
            same(off.column(&abs).unwrap(), offsets[j] * 1e-3, "offset");
            same(
                off.column(&def).unwrap(),
                Vector3::zeros(),
                "offset, deflection",
            );
            let k = Param::Compliance { joint };
            same(k.column(&abs).unwrap(), compliances[j] * 1e-6, "compliance");
            same(
                k.column(&def).unwrap(),
                compliances[j] * 1e-6,
                "compliance, deflection",
            );
            let six = joint_frame_columns(&frames, j, &p).unwrap();
            for (a, col) in six.iter().enumerate() {
                let fr = Param::JointFrame {
                    joint,
                    axis: a as u8,
                };
                same(fr.column(&abs).unwrap(), col * 1e-3, "joint frame");
                same(
                    fr.column(&def).unwrap(),
                    Vector3::zeros(),
                    "joint frame, deflection",
                );
            }
        }
        for (a, col) in base_columns(&p).iter().enumerate() {
            let b = Param::Base { axis: a as u8 };
            same(b.column(&abs).unwrap(), col * 1e-3, "base");
        }
        for (a, col) in marker_columns(&frames).iter().enumerate() {
            let own = Param::Marker {
                marker: 2,
                axis: a as u8,
            };
            same(own.column(&abs).unwrap(), col * 1e-3, "marker");
            let other = Param::Marker {
                marker: 0,
                axis: a as u8,
            };
            same(
                other.column(&abs).unwrap(),
                Vector3::zeros(),
                "another marker",
            );
        }
        // A joint the chain does not have, an axis out of range.
        assert!(Param::JointOffset { joint: n as u8 }.column(&abs).is_err());
        assert!(Param::Base { axis: 6 }.column(&abs).is_err());
    }
}

#[test]
fn param_columns_are_the_free_functions_in_reported_units() {
    let c = cases();
    param_case::<6>(&c[0].0, &c[0].1);
    param_case::<7>(&c[1].0, &c[1].1);
}

/// The gravity compliance's column (`Param::GravityCompliance`, mrad) is the
/// finite difference of the reference model's marker when joint `j` turns by
/// `x` times the gravity direction's component on its basis, both computed
/// here from the reference frames: `gₐ = (Rⱼᵀĝ)·a`, `a` the joint's x axis
/// made perpendicular to its axis `ẑ` (its y axis when `|ẑ·x| ≥ 0.9`),
/// `b = ẑ × a`. Zero on a deflection and without a gravity direction.
fn gravity_case<const J: usize>(robot: &RefRobot, poses: &[Vec<f64>]) {
    use robcal::model::{Param, Sample};
    let chain: Chain<f64, J> = robot.chain();
    let n = robot.joints.len();
    let zero = Perturb::zero(n);
    let marker = [0.12, -0.07, 0.2];
    let g = Vector3::new(0.0, 0.0, -1.0);
    for q in poses {
        let frames = chain.frames(q).unwrap();
        let p = frames.point_m(&v(marker));
        let tau = [0.0; J];
        let mut abs = Sample::absolute(&frames, p, 0, &tau[..n]);
        abs.gravity = g;
        let mut def = Sample::deflection(&frames, p, 0, &tau[..n], None);
        def.gravity = g;
        let (reference, _) = robot.frames(q, &zero);
        for (j, joint) in robot.joints.iter().enumerate() {
            if joint.prismatic {
                continue;
            }
            let r: Matrix3<f64> = reference[j].fixed_view::<3, 3>(0, 0).into_owned();
            let z = v(joint.axis) / v(joint.axis).norm();
            let seed = if z.x.abs() < 0.9 {
                Vector3::x()
            } else {
                Vector3::y()
            };
            let a = (seed - z * z.dot(&seed)).normalize();
            let local = r.transpose() * g;
            for (b, e) in [(false, a), (true, z.cross(&a))] {
                let gc = local.dot(&e);
                let want = fd(|h| {
                    let mut qh = q.clone();
                    qh[j] += h * gc;
                    robot.point(&qh, &zero, marker)
                }) * 1e-3;
                let param = Param::GravityCompliance { joint: j as u8, b };
                let got = param.column(&abs).unwrap();
                assert!((got - want).norm() < TOL * 1e-3, "{param}: {got} vs {want}");
                assert_eq!(param.column(&def).unwrap(), Vector3::zeros());
            }
        }
        let mut no_g = Sample::absolute(&frames, p, 0, &tau[..n]);
        no_g.gravity = Vector3::zeros();
        let param = Param::GravityCompliance { joint: 1, b: false };
        assert_eq!(param.column(&no_g).unwrap(), Vector3::zeros());
    }
}

#[test]
fn gravity_compliance_columns_match_finite_differences() {
    let c = cases();
    gravity_case::<6>(&c[0].0, &c[0].1);
    gravity_case::<7>(&c[1].0, &c[1].1);
}
