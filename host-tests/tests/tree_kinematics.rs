//! A tree (`Chain::push_child`, data contract 7.1) against serial chains:
//! a Y-shaped robot whose two branches share their first two joints. Each
//! branch built on its own as a serial chain is the reference for the
//! tree's frames at that branch's end; the tree's gravity torques must be
//! the derivative of its potential energy (both branches' links weigh on
//! the shared joints), and the torque Jacobian the derivative of the
//! torques.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use robcal::robot::{gravity_torques, End, Loading};
use robcal::{Chain, Joint, JointKind, LinkInertia};

fn joint(xyz: [f64; 3], rpy: [f64; 3], axis: [f64; 3], mass_kg: f64) -> Joint<f64> {
    let mut j = Joint::from_urdf(
        Vector3::from(xyz),
        Vector3::from(rpy),
        Vector3::from(axis),
        JointKind::Revolute,
    )
    .unwrap();
    j.link = Some(LinkInertia {
        mass_kg,
        com_m: Vector3::new(0.1, 0.02, -0.03),
    });
    j
}

/// Shared: 0, 1. Branch a: 2, 3. Branch b: 4, 5.
fn parts() -> [Joint<f64>; 6] {
    [
        joint([0.0, 0.0, 0.3], [0.0; 3], [0.0, 0.0, 1.0], 5.0),
        joint([0.0, 0.0, 0.2], [0.0; 3], [0.0, 1.0, 0.0], 4.0),
        joint([0.0, 0.15, 0.4], [0.1, 0.0, 0.0], [0.0, 1.0, 0.0], 3.0),
        joint([0.35, 0.0, 0.0], [0.0; 3], [1.0, 0.0, 0.0], 2.0),
        joint([0.0, -0.15, 0.4], [-0.1, 0.0, 0.0], [0.0, 1.0, 0.0], 3.5),
        joint([0.3, 0.0, 0.05], [0.0; 3], [0.0, 0.0, 1.0], 1.5),
    ]
}

fn tip(x: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(x, 0.02, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.2, 0.0),
    )
}

/// The tree, its tip on branch a; and the end of branch b.
fn tree() -> (Chain<f64, 8>, End<f64>) {
    let [s0, s1, a0, a1, b0, b1] = parts();
    let mut c = Chain::<f64, 8>::new();
    c.push(s0).unwrap();
    c.push(s1).unwrap();
    c.push(a0).unwrap();
    c.push(a1).unwrap();
    c.set_tip(tip(0.1));
    let b = c.push_child(b0, Some(1)).unwrap();
    let b = c.push_child(b1, Some(b)).unwrap();
    (
        c,
        End {
            joint: Some(b),
            origin: tip(0.12),
        },
    )
}

/// Branch `a` (`true`) or `b` as a serial chain of its own.
fn serial(a: bool) -> Chain<f64, 8> {
    let p = parts();
    let mut c = Chain::<f64, 8>::new();
    let idx: [usize; 4] = if a { [0, 1, 2, 3] } else { [0, 1, 4, 5] };
    for i in idx {
        c.push(p[i]).unwrap();
    }
    c.set_tip(tip(if a { 0.1 } else { 0.12 }));
    c
}

const Q: [[f64; 6]; 3] = [
    [0.3, -0.5, 0.8, 1.1, -0.4, 0.9],
    [-1.2, 0.7, -0.3, 0.2, 1.3, -0.6],
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
];

#[test]
fn each_end_of_the_tree_is_its_branch_as_a_serial_chain() {
    let (tree, b_end) = tree();
    assert!(!tree.is_serial());
    assert_eq!(tree.parent(4), Some(1));
    assert_eq!(tree.path(Some(5)).collect::<Vec<_>>(), [5, 4, 1, 0]);
    let tree_b = tree.with_tip(&b_end).unwrap();
    let (sa, sb) = (serial(true), serial(false));
    for q in Q {
        let qa = [q[0], q[1], q[2], q[3]];
        let qb = [q[0], q[1], q[4], q[5]];
        let (ta, tb) = (tree.frames(&q).unwrap(), tree_b.frames(&q).unwrap());
        let (fa, fb) = (sa.frames(&qa).unwrap(), sb.frames(&qb).unwrap());
        let close = |x: &Isometry3<f64>, y: &Isometry3<f64>| {
            (x.to_homogeneous() - y.to_homogeneous()).norm() < 1e-14
        };
        assert!(close(ta.tip(), fa.tip()));
        assert!(close(tb.tip(), fb.tip()));
        // The joints that carry each end, and only those.
        let carries = |f: &robcal::robot::Frames<f64, 8>| -> Vec<bool> {
            f.joints().iter().map(|j| j.carries).collect()
        };
        assert_eq!(carries(&ta), [true, true, true, true, false, false]);
        assert_eq!(carries(&tb), [true, true, false, false, true, true]);
        // A joint off the branch does not move a point on its end.
        let p = tb.point_m(&Vector3::new(0.01, 0.02, 0.03));
        assert_eq!(tb.joints()[2].twist_column(&p), Vector3::zeros());
        assert_eq!(
            robcal::model::joint_frame_columns(&tb, 3, &p).unwrap(),
            [Vector3::zeros(); 6]
        );
        for (j, r) in [(0, 0), (1, 1), (4, 2), (5, 3)] {
            let d = tb.joints()[j].twist_column(&p) - fb.joints()[r].twist_column(&p);
            assert!(d.norm() < 1e-14, "joint {j}");
        }
    }
}

/// Potential energy `−Σ m g·c` \[J\] of every link of the tree at `q`.
fn energy(tree: &Chain<f64, 8>, q: &[f64], g: &Vector3<f64>) -> f64 {
    let f = tree.frames(q).unwrap();
    tree.joints()
        .iter()
        .zip(f.joints())
        .map(|(j, jf)| {
            let l = j.link.unwrap();
            let c = jf.frame.transform_point(&l.com_m.into()).coords;
            -l.mass_kg * g.dot(&c)
        })
        .sum()
}

#[test]
fn the_trees_gravity_torques_are_the_derivative_of_its_energy() {
    let (tree, _) = tree();
    let g = Vector3::new(0.3, -0.2, -9.8);
    for q in Q {
        let f = tree.frames(&q).unwrap();
        let mut tau = [0.0; 8];
        gravity_torques(&tree, &f, &g, &mut tau).unwrap();
        for j in 0..6 {
            // τ = −∂V/∂q (the torque the joint must hold is its opposite;
            // robcal's sign: the torque gravity applies about the axis).
            let h = 1e-6;
            let (mut qp, mut qm) = (q, q);
            qp[j] += h;
            qm[j] -= h;
            let dv = (energy(&tree, &qp, &g) - energy(&tree, &qm, &g)) / (2.0 * h);
            assert!(
                (tau[j] + dv).abs() < 1e-6,
                "joint {j}: {} vs {}",
                tau[j],
                -dv
            );
        }
    }
}

#[test]
fn the_trees_torque_jacobian_is_the_derivative_of_its_torques() {
    let (tree, b_end) = tree();
    let tree_b = tree.with_tip(&b_end).unwrap();
    let loading = Loading {
        load: Some(robcal::robot::PointLoad {
            mass_kg: 2.0,
            com_m: Vector3::new(0.05, 0.0, 0.1),
            gravity_mps2: Vector3::new(0.0, 0.0, -9.81),
        }),
        own_weight_mps2: Some(Vector3::new(0.0, 0.0, -9.81)),
    };
    // The load hangs from each end in turn.
    for chain in [&tree, &tree_b] {
        for q in Q {
            let t = loading
                .torque_jacobian(chain, &chain.frames(&q).unwrap())
                .unwrap();
            for i in 0..6 {
                let h = 1e-6;
                let (mut qp, mut qm) = (q, q);
                qp[i] += h;
                qm[i] -= h;
                let (mut tp, mut tm) = ([0.0; 8], [0.0; 8]);
                loading
                    .torques(chain, &chain.frames(&qp).unwrap(), &mut tp)
                    .unwrap();
                loading
                    .torques(chain, &chain.frames(&qm).unwrap(), &mut tm)
                    .unwrap();
                for j in 0..6 {
                    let fd = (tp[j] - tm[j]) / (2.0 * h);
                    assert!(
                        (t[(j, i)] - fd).abs() < 1e-5,
                        "dtau{j}/dq{i}: {} vs {fd}",
                        t[(j, i)]
                    );
                }
            }
        }
    }
}
