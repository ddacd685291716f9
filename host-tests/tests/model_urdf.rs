//! The shipped `data/kr270/kr270.urdf`: parses, matches the published
//! kinematics (issue 3's table, typed into `model_common::kr270`), holds the
//! paper's configurations within its joint limits, and gives the same
//! forward kinematics as the reference when turned into a `Chain`.

use crate::model_common;

use model_common::*;
use nalgebra::{Isometry3, UnitQuaternion};
use robcal::{Chain, Joint, JointKind, LinkInertia};

fn robot() -> urdf_rs::Robot {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/kr270/kr270.urdf");
    urdf_rs::read_file(path).expect("kr270.urdf parses")
}

fn pose(p: &urdf_rs::Pose) -> Isometry3<f64> {
    Isometry3::from_parts(
        v(*p.xyz).into(),
        UnitQuaternion::from_euler_angles(p.rpy[0], p.rpy[1], p.rpy[2]),
    )
}

#[test]
fn kr270_urdf_matches_the_published_kinematics() {
    let r = robot();
    let reference = kr270();
    for (i, rj) in reference.joints.iter().enumerate() {
        let name = format!("a{}", i + 1);
        let j = r.joints.iter().find(|j| j.name == name).unwrap();
        assert_eq!(j.joint_type, urdf_rs::JointType::Revolute, "{name}");
        assert_eq!(*j.origin.xyz, rj.xyz, "{name} xyz");
        assert_eq!(*j.origin.rpy, [0.0; 3], "{name} rpy");
        assert_eq!(*j.axis.xyz, rj.axis, "{name} axis");
        assert_eq!(
            j.parent.link,
            if i == 0 {
                "base_link".to_string()
            } else {
                format!("link_{i}")
            }
        );
        assert_eq!(j.child.link, format!("link_{}", i + 1));
        // The link's (approximate) inertial is the one the tests use.
        let link = r.links.iter().find(|l| l.name == j.child.link).unwrap();
        let (m, com) = rj.link.unwrap();
        assert_eq!(link.inertial.mass.value, m);
        assert_eq!(*link.inertial.origin.xyz, com);
    }
    let flange = r.joints.iter().find(|j| j.child.link == "flange").unwrap();
    assert_eq!(flange.joint_type, urdf_rs::JointType::Fixed);
    assert_eq!(
        (*flange.origin.xyz, *flange.origin.rpy),
        ([0.0; 3], [0.0; 3])
    );
    let tool0 = r.joints.iter().find(|j| j.child.link == "tool0").unwrap();
    assert_eq!(tool0.parent.link, "flange");
    assert!((tool0.origin.rpy[1] - std::f64::consts::FRAC_PI_2).abs() < 1e-7);
    // Approximate masses: the datasheet total is about 1100 kg.
    let total: f64 = r.links.iter().map(|l| l.inertial.mass.value).sum();
    assert!((1000.0..=1150.0).contains(&total), "total mass {total} kg");
}

#[test]
fn paper_configurations_are_within_the_joint_limits() {
    let r = robot();
    for q in PAPER_Q_DEG.iter() {
        for (i, qd) in q.iter().enumerate() {
            let j = r
                .joints
                .iter()
                .find(|j| j.name == format!("a{}", i + 1))
                .unwrap();
            let x = qd.to_radians();
            assert!(
                j.limit.lower <= x && x <= j.limit.upper,
                "a{} = {qd} deg",
                i + 1
            );
        }
    }
}

#[test]
fn chain_from_the_urdf_matches_the_reference() {
    let r = robot();
    let mut chain = Chain::<f64, 6>::new();
    for i in 1..=6 {
        let j = r.joints.iter().find(|j| j.name == format!("a{i}")).unwrap();
        let mut joint = Joint::from_urdf(
            v(*j.origin.xyz),
            v(*j.origin.rpy),
            v(*j.axis.xyz),
            JointKind::Revolute,
        )
        .unwrap();
        let link = r.links.iter().find(|l| l.name == j.child.link).unwrap();
        joint.link = Some(LinkInertia {
            mass_kg: link.inertial.mass.value,
            com_m: v(*link.inertial.origin.xyz),
        });
        chain.push(joint).unwrap();
    }
    let flange = r.joints.iter().find(|j| j.child.link == "flange").unwrap();
    let tool0 = r.joints.iter().find(|j| j.child.link == "tool0").unwrap();
    chain.set_tip(pose(&flange.origin) * pose(&tool0.origin));
    let reference = kr270();
    let zero = Perturb::zero(6);
    for q in PAPER_Q_DEG.iter().map(|q| rad(q)) {
        for m in tool_markers() {
            // 1.5707963 in the file vs π/2 in the reference: 3e-8 rad on
            // a 0.36 m marker lever.
            assert_close(
                chain.marker_m(&q, &v(m)).unwrap(),
                reference.point(&q, &zero, m),
                1e-7,
                "marker",
            );
        }
    }
}
