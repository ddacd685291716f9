//! Forward kinematics of `robcal::Chain` against the independent 4×4
//! reference of `model_common`, on the KR-270 and a 7-joint arm with a
//! prismatic joint.

use crate::model_common;

use model_common::*;
use nalgebra::Vector3;
use robcal::{Chain, Error, JointKind};

// Both models are exact; differences are rounding of ~10 products of unit
// rotations times lengths of a few metres.
const TOL_M: f64 = 1e-12;

fn check_robot<const J: usize>(robot: &RefRobot, poses: &[Vec<f64>]) {
    let chain: Chain<f64, J> = robot.chain();
    let zero = Perturb::zero(robot.joints.len());
    for q in poses {
        let frames = chain.frames(q).unwrap();
        let (ref_frames, ref_tip) = robot.frames(q, &zero);
        for (j, (jf, rf)) in frames.joints().iter().zip(&ref_frames).enumerate() {
            // Origin o_j and axis z_j of the moved frame.
            let o = rf.fixed_view::<3, 1>(0, 3).into_owned();
            let axis = v(robot.joints[j].axis);
            let z = rf.fixed_view::<3, 3>(0, 0) * axis / axis.norm();
            assert_close(jf.origin_m(), o, TOL_M, "joint origin");
            assert_close(jf.axis.into_inner(), z, TOL_M, "joint axis");
            // The whole frame.
            let m = jf.frame.to_homogeneous();
            assert!((m - rf).norm() < TOL_M, "frame {j}");
        }
        assert!((frames.tip().to_homogeneous() - ref_tip).norm() < TOL_M);
        assert!((chain.tip_pose(q).unwrap().to_homogeneous() - ref_tip).norm() < TOL_M);
        let m = [0.1, -0.2, 0.3];
        assert_close(
            chain.marker_m(q, &v(m)).unwrap(),
            robot.point(q, &zero, m),
            TOL_M,
            "marker",
        );
        assert_eq!(frames.q(), &q[..]);
        // In place: the same frames, into a buffer that held another pose.
        let mut into = chain.frames(&vec![0.3; q.len()]).unwrap();
        chain.frames_into(q, &mut into).unwrap();
        assert_eq!(into, frames);
    }
}

#[test]
fn kr270_matches_reference_on_the_paper_configurations() {
    let poses: Vec<_> = PAPER_Q_DEG.iter().map(|q| rad(q)).collect();
    check_robot::<6>(&kr270(), &poses);
}

#[test]
fn arm7_with_prismatic_joint_matches_reference() {
    let robot = arm7();
    let chain: Chain<f64, 7> = robot.chain();
    assert_eq!(chain.joints()[1].kind, JointKind::Prismatic);
    check_robot::<7>(&robot, &arm7_poses());
}

#[test]
fn kr270_a2_minus_90_deg_is_upper_arm_vertical() {
    let chain: Chain<f64, 6> = kr270().chain();
    let q = rad(&[0.0, -90.0, 0.0, 0.0, 0.0, 0.0]);
    let f = chain.frames(&q).unwrap();
    let upper_arm = f.joints()[2].origin_m() - f.joints()[1].origin_m();
    // a2 at (0.350, 0, 0.675); a3 1.150 m straight above it.
    assert_close(upper_arm, Vector3::new(0.0, 0.0, 1.150), 1e-12, "upper arm");
    // At all zeros the arm points along +x: flange at x = 0.35+1.15+1.2+0.24.
    let f0 = chain.frames(&[0.0; 6]).unwrap();
    assert_close(
        f0.tip().translation.vector,
        Vector3::new(2.94, 0.0, 0.675 - 0.041),
        1e-12,
        "flange at zero",
    );
    // tool0's z axis is the flange normal (+x of the base at zero).
    let z_tool = f0.tip().rotation * Vector3::z();
    assert_close(z_tool, Vector3::x(), 1e-7, "tool0 z");
}

#[test]
fn wrong_length_or_non_finite_q_is_an_error() {
    let chain: Chain<f64, 6> = kr270().chain();
    assert!(matches!(
        chain.frames(&[0.0; 5]),
        Err(Error::Mismatch { .. })
    ));
    assert!(matches!(
        chain.frames(&[0.0; 7]),
        Err(Error::Mismatch { .. })
    ));
    let mut q = [0.0; 6];
    q[3] = f64::NAN;
    assert!(matches!(chain.frames(&q), Err(Error::NonFinite { .. })));
    // In place, a rejected pose leaves the buffer as it was.
    let before = chain.frames(&[0.2; 6]).unwrap();
    let mut into = before.clone();
    assert!(chain.frames_into(&q, &mut into).is_err());
    assert!(chain.frames_into(&[0.0; 5], &mut into).is_err());
    assert_eq!(into, before);
    assert!(matches!(
        chain.frames(&[0.0; 6]).unwrap().joint(6),
        Err(Error::OutOfRange { .. })
    ));
}

#[test]
fn f32_chain_agrees_with_f64() {
    let robot = kr270();
    let c64: Chain<f64, 6> = robot.chain();
    let mut c32 = Chain::<f32, 6>::new();
    for j in c64.joints() {
        let jj = robcal::Joint::from_urdf(
            j.origin.translation.vector.cast::<f32>(),
            Vector3::zeros(),
            j.axis.into_inner().cast::<f32>(),
            j.kind,
        )
        .unwrap();
        c32.push(jj).unwrap();
    }
    c32.set_tip(c64.tip().cast::<f32>());
    for q in PAPER_Q_DEG.iter().map(|q| rad(q)) {
        let q32: Vec<f32> = q.iter().map(|&x| x as f32).collect();
        let p64 = c64.marker_m(&q, &Vector3::new(0.25, 0.0, 0.3)).unwrap();
        let p32 = c32.marker_m(&q32, &Vector3::new(0.25, 0.0, 0.3)).unwrap();
        // f32: ~1e-7 relative per operation on lengths of ~3 m.
        assert!((p32.cast::<f64>() - p64).norm() < 1e-5);
    }
}
