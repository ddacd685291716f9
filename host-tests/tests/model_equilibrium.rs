//! `robcal::robot::equilibrium`: the deflected pose of a loaded chain whose
//! joints yield, its torque Jacobian and its sensitivity — against central
//! differences and against the independent 4×4 reference of `model_common`.

use crate::model_common;

use model_common::*;
use nalgebra::Vector3;
use robcal::robot::{equilibrium, EquilibriumSettings, JointLaw, Loading, PointLoad};
use robcal::Chain;

/// A linear law `δⱼ = kⱼ τⱼ + eⱼ`.
struct Springs {
    k: Vec<f64>,
    e: Vec<f64>,
}

impl JointLaw<f64> for Springs {
    fn deflection(&self, j: usize, tau: f64) -> (f64, f64) {
        (self.k[j] * tau + self.e[j], self.k[j])
    }
}

const SETTINGS: EquilibriumSettings<f64> = EquilibriumSettings {
    tolerance: 1e-14,
    max_iterations: 50,
};

fn loading(mass_kg: f64, own: bool) -> Loading<f64> {
    Loading {
        load: Some(PointLoad {
            mass_kg,
            com_m: v(LOAD_COM),
            gravity_mps2: Vector3::new(0.0, 0.0, -9.80665),
        }),
        own_weight_mps2: own.then_some(Vector3::new(0.0, 0.0, -9.80665)),
    }
}

/// Joint torques of `loading` at `q` with the independent reference
/// frames: `τⱼ = zⱼ·((c − oⱼ) × F)` for every point force, revolute joints
/// (the KR-270 has no prismatic joint).
fn reference_torques(robot: &RefRobot, q: &[f64], l: &Loading<f64>) -> Vec<f64> {
    let (frames, tip) = robot.frames(q, &Perturb::zero(q.len()));
    let g = Vector3::new(0.0, 0.0, -9.80665);
    let mut forces: Vec<(Vector3<f64>, Vector3<f64>, usize)> = Vec::new();
    if let Some(load) = l.load {
        forces.push((
            load.gravity_mps2 * load.mass_kg,
            apply(&tip, load.com_m),
            q.len() - 1,
        ));
    }
    if l.own_weight_mps2.is_some() {
        for (j, joint) in robot.joints.iter().enumerate() {
            if let Some((m, c)) = joint.link {
                forces.push((g * m, apply(&frames[j], v(c)), j));
            }
        }
    }
    (0..q.len())
        .map(|j| {
            let o = frames[j].fixed_view::<3, 1>(0, 3).into_owned();
            let axis = v(robot.joints[j].axis) / v(robot.joints[j].axis).norm();
            let z = frames[j].fixed_view::<3, 3>(0, 0) * axis;
            forces
                .iter()
                .filter(|f| f.2 >= j)
                .map(|(f, c, _)| z.dot(&(c - o).cross(f)))
                .sum()
        })
        .collect()
}

/// The paper's compliances, a1 rigid \[rad/(N·m)\], 100× softer than the
/// KR-270's so that the non-linearity is large.
fn soft_kr270_law() -> Springs {
    Springs {
        k: [0.0, 0.29, 0.42, 2.8, 3.5, 2.1]
            .iter()
            .map(|k| k * 1e-4)
            .collect(),
        e: vec![0.0; 6],
    }
}

#[test]
fn torque_jacobian_is_the_derivative_of_the_torques() {
    for (robot, poses, n) in [
        (
            kr270(),
            PAPER_Q_DEG.iter().map(|q| rad(q)).collect::<Vec<_>>(),
            6,
        ),
        (arm7(), arm7_poses(), 7),
    ] {
        let chain: Chain<f64, 8> = robot.chain();
        for own in [false, true] {
            let l = loading(265.0, own);
            for q in &poses {
                let t = l
                    .torque_jacobian(&chain, &chain.frames(q).unwrap())
                    .unwrap();
                let h = 1e-6;
                for i in 0..n {
                    let mut qp = q.clone();
                    let mut qm = q.clone();
                    qp[i] += h;
                    qm[i] -= h;
                    let (mut tp, mut tm) = ([0.0; 8], [0.0; 8]);
                    l.torques(&chain, &chain.frames(&qp).unwrap(), &mut tp)
                        .unwrap();
                    l.torques(&chain, &chain.frames(&qm).unwrap(), &mut tm)
                        .unwrap();
                    let scale = tp.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
                    for j in 0..n {
                        let fd = (tp[j] - tm[j]) / (2.0 * h);
                        assert!(
                            (t[(j, i)] - fd).abs() <= 1e-6 * scale,
                            "∂τ{j}/∂θ{i}: {} vs central difference {fd} (own weight {own})",
                            t[(j, i)]
                        );
                    }
                }
                // Nothing past the dof.
                assert!((n..8).all(|i| (0..8).all(|j| t[(j, i)] == 0.0 && t[(i, j)] == 0.0)));
            }
        }
    }
}

#[test]
fn equilibrium_satisfies_the_law_at_the_deflected_pose() {
    let robot = kr270();
    let chain: Chain<f64, 6> = robot.chain();
    let law = soft_kr270_law();
    for own in [false, true] {
        let l = loading(270.0, own);
        for q in PAPER_Q_DEG.iter().map(|q| rad(q)) {
            let eq = equilibrium(&chain, &q, &q, &l, &law, &SETTINGS).unwrap();
            let theta = eq.frames.q().to_vec();
            // The torques of the independent reference at θ, not robcal's.
            let tau = reference_torques(&robot, &theta, &l);
            for j in 0..6 {
                let want = q[j] + law.k[j] * tau[j];
                assert!(
                    (theta[j] - want).abs() < 1e-13,
                    "joint {j}: θ = {} but q + kτ(θ) = {want}",
                    theta[j]
                );
                assert!((eq.tau[j] - tau[j]).abs() < 1e-9 * tau[j].abs().max(1.0));
                assert_eq!(eq.deflection[j], theta[j] - q[j]);
            }
            // 100× the KR-270's compliances: still a few Newton steps.
            assert!(eq.iterations <= 6, "{} Newton steps", eq.iterations);
            // The deflection is not the first-order one: the torques at θ
            // differ from those at q.
            let tau_q = reference_torques(&robot, &q, &l);
            assert!((0..6).any(|j| (tau[j] - tau_q[j]).abs() > 1e-3 * tau_q[j].abs()));
        }
    }
}

#[test]
fn sensitivity_and_twist_columns_are_derivatives_of_the_equilibrium() {
    let robot = kr270();
    let chain: Chain<f64, 6> = robot.chain();
    let marker = v(tool_markers()[1]);
    let l = loading(260.0, true);
    for q in PAPER_Q_DEG.iter().map(|q| rad(q)).step_by(4) {
        let law = soft_kr270_law();
        let eq = equilibrium(&chain, &q, &q, &l, &law, &SETTINGS).unwrap();
        let p0 = eq.frames.point_m(&marker);
        let h = 1e-7;
        for j in 0..6 {
            let shifted = |e: f64| {
                let mut law = soft_kr270_law();
                law.e[j] = e;
                equilibrium(&chain, &q, &q, &l, &law, &SETTINGS).unwrap()
            };
            let (a, b) = (shifted(h), shifted(-h));
            for i in 0..6 {
                let fd = (a.frames.q()[i] - b.frames.q()[i]) / (2.0 * h);
                assert!(
                    (eq.sensitivity[(i, j)] - fd).abs() < 1e-6,
                    "M[{i},{j}] = {} vs {fd}",
                    eq.sensitivity[(i, j)]
                );
            }
            let fd = (a.frames.point_m(&marker) - b.frames.point_m(&marker)) / (2.0 * h);
            assert_close(eq.twist_column(j, &p0).unwrap(), fd, 1e-6, "twist column");
        }
    }
}

#[test]
fn a_rigid_law_is_the_commanded_pose() {
    let chain: Chain<f64, 6> = kr270().chain();
    let law = Springs {
        k: vec![0.0; 6],
        e: vec![0.0; 6],
    };
    let q = rad(&PAPER_Q_DEG[3]);
    let eq = equilibrium(&chain, &q, &q, &loading(250.0, true), &law, &SETTINGS).unwrap();
    assert_eq!(eq.frames.q(), &q[..]);
    assert_eq!(eq.iterations, 0);
    assert_eq!(eq.sensitivity, nalgebra::SMatrix::<f64, 6, 6>::identity());
    // A wrong-length guess is an error, not a panic.
    assert!(equilibrium(&chain, &q, &q[..5], &loading(1.0, false), &law, &SETTINGS).is_err());
}
