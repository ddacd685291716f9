//! URDF → chain (`robcal::io::urdf`): a hand-written fixture with every
//! folding case, the real TIAGo URDF, and the error paths.

// The TIAGo numbers are copied as the URDF writes them (1.57079632679, not
// FRAC_PI_2): the test checks the file's transforms, not ideal ones.
#![allow(clippy::approx_constant)]

use std::path::{Path, PathBuf};

use approx::assert_relative_eq;
use nalgebra::{Matrix3, Matrix4, Rotation3, Vector3};
use robcal::io::{ErrorKind, Robot, UrdfJointKind, MAX_JOINTS};
use robcal::JointKind;

const HALF_PI: f64 = std::f64::consts::FRAC_PI_2;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// `shared/datasets/tiago-mocap/tiago_48_schunk.urdf`, found from the
/// manifest dir upward (`../../shared` in a checkout of main, one level more
/// in a worktree). Never copied into the repository (CC BY-NC-ND).
/// `None` on a plain clone (the test says it is skipped), a failure with
/// `ROBCAL_REQUIRE_SHARED=1` (CI).
fn tiago_urdf(test: &str) -> Option<PathBuf> {
    let found = Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .map(|d| d.join("shared/datasets/tiago-mocap/tiago_48_schunk.urdf"))
        .find(|p| p.is_file());
    if found.is_none() {
        let what = "shared/datasets/tiago-mocap/tiago_48_schunk.urdf";
        if std::env::var_os("ROBCAL_REQUIRE_SHARED").is_some_and(|v| v == "1") {
            panic!("{what} not found, and ROBCAL_REQUIRE_SHARED=1 (CI) requires it");
        }
        skipped_note(&format!(
            "skipped {test}: {what} not found above the repository (CI has it)"
        ));
    }
    found
}

/// URDF `rpy` written out by hand: `R = Rz(y)·Ry(p)·Rx(r)` (fixed X-Y-Z).
fn rpy_matrix(r: f64, p: f64, y: f64) -> Matrix3<f64> {
    let (sr, cr) = r.sin_cos();
    let (sp, cp) = p.sin_cos();
    let (sy, cy) = y.sin_cos();
    let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, cr, -sr, 0.0, sr, cr);
    let ry = Matrix3::new(cp, 0.0, sp, 0.0, 1.0, 0.0, -sp, 0.0, cp);
    let rz = Matrix3::new(cy, -sy, 0.0, sy, cy, 0.0, 0.0, 0.0, 1.0);
    rz * ry * rx
}

fn homogeneous(xyz: [f64; 3], rpy: [f64; 3]) -> Matrix4<f64> {
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&rpy_matrix(rpy[0], rpy[1], rpy[2]));
    m.fixed_view_mut::<3, 1>(0, 3)
        .copy_from(&Vector3::from(xyz));
    m
}

#[test]
fn small_fixture_folds_fixed_joints_and_sums_link_masses() {
    let robot = Robot::load(fixture("io_small.urdf"), Some("world"), Some("flange")).unwrap();
    assert_eq!(robot.name, "small");
    assert_eq!(robot.joint_names, ["j1", "j2", "j3"]);
    assert_eq!(
        robot.joint_kinds,
        [
            UrdfJointKind::Revolute,
            UrdfJointKind::Continuous,
            UrdfJointKind::Prismatic
        ]
    );
    let kinds: Vec<JointKind> = robot.chain.joints().iter().map(|j| j.kind).collect();
    assert_eq!(
        kinds,
        [
            JointKind::Revolute,
            JointKind::Revolute,
            JointKind::Prismatic
        ]
    );
    assert_eq!(
        robot.limits[0].map(|l| (l.lower, l.upper)),
        Some((-2.5, 2.5))
    );
    assert_eq!(robot.limits[1], None, "continuous: no limits");
    assert_eq!(
        robot.limits[2].map(|l| (l.lower, l.upper)),
        Some((0.0, 0.3))
    );

    let j = robot.chain.joints();
    // Tolerances: a few ulps of the transform products (values ~1).
    let tol = 1e-14;
    // j1: mount (fixed, before it) ∘ j1 origin.
    let expect =
        homogeneous([1.0, 2.0, 0.0], [0.0, 0.0, HALF_PI]) * homogeneous([0.0, 0.0, 0.4], [0.0; 3]);
    assert_relative_eq!(j[0].origin.to_homogeneous(), expect, epsilon = tol);
    // j2: elbow_offset (fixed, mid-chain) ∘ j2 origin = (0,0,0.5), Rx(π/2).
    let expect =
        homogeneous([0.0, 0.0, 0.3], [HALF_PI, 0.0, 0.0]) * homogeneous([0.0, 0.2, 0.0], [0.0; 3]);
    assert_relative_eq!(j[1].origin.to_homogeneous(), expect, epsilon = tol);
    assert_relative_eq!(
        j[1].origin.translation.vector,
        Vector3::new(0.0, 0.0, 0.5),
        epsilon = tol
    );
    assert_relative_eq!(j[1].axis.into_inner(), Vector3::y(), epsilon = tol);
    assert_relative_eq!(
        j[2].origin.to_homogeneous(),
        homogeneous([0.0, 0.0, 0.5], [0.0; 3]),
        epsilon = tol
    );
    // tip: the tool flange.
    assert_relative_eq!(
        robot.chain.tip().to_homogeneous(),
        homogeneous([0.1, 0.0, 0.0], [0.0, HALF_PI, 0.0]),
        epsilon = tol
    );

    // j1 carries l1 (2 kg at (0,0,0.1)), l1b fixed to it (1 kg at (0.1,0,0)
    // in a frame at (0,0,0.3) turned about x: (0.1,0,0.3)) and the side
    // branch sensor (0.5 kg at (0.2,0.05,0)); the base's 10 kg are nobody's.
    let l = j[0].link.unwrap();
    assert_relative_eq!(l.mass_kg, 3.5, epsilon = 1e-15);
    let com = (Vector3::new(0.0, 0.0, 0.1) * 2.0
        + Vector3::new(0.1, 0.0, 0.3)
        + Vector3::new(0.2, 0.05, 0.0) * 0.5)
        / 3.5;
    assert_relative_eq!(l.com_m, com, epsilon = 1e-15);
    let l = j[1].link.unwrap();
    assert_eq!(l.mass_kg, 1.5);
    assert_relative_eq!(l.com_m, Vector3::new(0.0, 0.0, 0.2), epsilon = 1e-15);
    // j3 carries l3 and the flange beyond the tip frame's own link (0.2 kg at
    // (0,0,0.01) in a frame at (0.1,0,0) turned about y: (0.11,0,0)).
    let l = j[2].link.unwrap();
    assert_relative_eq!(l.mass_kg, 1.0, epsilon = 1e-15);
    assert_relative_eq!(l.com_m, Vector3::new(0.062, 0.0, 0.0), epsilon = 1e-15);

    // The flap hangs from the sensor through a movable joint: left out, listed.
    assert_eq!(robot.off_chain.len(), 1);
    let b = &robot.off_chain[0];
    assert_eq!(
        (b.joint.as_str(), b.parent_link.as_str(), b.chain_joint),
        ("flap_joint", "sensor", 0)
    );
    assert_eq!(b.mass_kg, 2.0);
}

#[test]
fn small_fixture_defaults_and_mid_chain_tip() {
    // Root link is `world`; the tree below branches (flap), so no default tip.
    let e = Robot::load(fixture("io_small.urdf"), None, None).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Robot);
    assert!(e.message.contains("set tip_link"), "{e}");
    let robot = Robot::load(fixture("io_small.urdf"), None, Some("l2")).unwrap();
    assert_eq!(robot.base_link, "world");
    assert_eq!(robot.joint_names, ["j1", "j2"]);
    // j3 is beyond the tip: its body is left out of j2's and listed.
    assert_eq!(robot.chain.joints()[1].link.unwrap().mass_kg, 1.5);
    let names: Vec<&str> = robot.off_chain.iter().map(|b| b.joint.as_str()).collect();
    assert_eq!(names, ["flap_joint", "j3"]);
    assert_relative_eq!(robot.off_chain[1].mass_kg, 1.0, epsilon = 1e-15);
    // Base mid-chain: the fixed joint before j2 is folded into it.
    let robot = Robot::load(fixture("io_small.urdf"), Some("l1"), Some("l2")).unwrap();
    assert_eq!(robot.joint_names, ["j2"]);
    assert_relative_eq!(
        robot.chain.joints()[0].origin.translation.vector,
        Vector3::new(0.0, 0.0, 0.5),
        epsilon = 1e-15
    );
}

#[test]
fn tiago_torso_and_arm() {
    let Some(path) = tiago_urdf("tiago_torso_and_arm") else {
        return;
    };
    let robot = Robot::load(&path, Some("base_footprint"), Some("arm_7_link")).unwrap();
    let names: Vec<String> = std::iter::once("torso_lift_joint".to_owned())
        .chain((1..=7).map(|i| format!("arm_{i}_joint")))
        .collect();
    assert_eq!(robot.joint_names, names);
    assert_eq!(robot.dof(), 8);
    assert_eq!(robot.joint_kinds[0], UrdfJointKind::Prismatic);
    assert!(robot.joint_kinds[1..]
        .iter()
        .all(|&k| k == UrdfJointKind::Revolute));
    assert_eq!(
        robot.limits[0].map(|l| (l.lower, l.upper)),
        Some((0.0, 0.35))
    );
    assert_eq!(
        robot.limits[1].map(|l| (l.lower, l.upper)),
        Some((0.0, 2.74889357189))
    );

    // base_footprint_joint (0,0,0.0985) and torso_fixed_joint (-0.062,0,0.193),
    // both without rotation, folded into torso_lift_joint (0,0,0.597).
    let torso = &robot.chain.joints()[0];
    assert_relative_eq!(
        torso.origin.translation.vector,
        Vector3::new(-0.062, 0.0, 0.0985 + 0.193 + 0.597),
        epsilon = 1e-15
    );
    assert_relative_eq!(torso.origin.rotation.angle(), 0.0);
    assert_relative_eq!(torso.axis.into_inner(), Vector3::z());
    // arm_1 has no fixed joint before it: its origin is the URDF's.
    assert_relative_eq!(
        robot.chain.joints()[1].origin.to_homogeneous(),
        homogeneous([0.15505, 0.014, -0.151], [0.0, 0.0, -1.57079632679]),
        epsilon = 1e-15
    );
    assert_eq!(*robot.chain.tip(), nalgebra::Isometry3::identity());

    // Masses (URDF <mass> values). Torso: torso_lift_link alone; the head
    // hangs from it through head_1_joint and is listed, not included.
    assert_eq!(torso.link.unwrap().mass_kg, 6.93198);
    assert_relative_eq!(
        torso.link.unwrap().com_m,
        Vector3::new(0.04361, -0.00116, -0.17334)
    );
    // arm_7: arm_7_link + arm_tool_link + wrist_ft_link + wrist_ft_tool_link
    // + gripper_tool_link + gripper_link + gripper_grasping_frame, all fixed.
    let hand = 0.234252 + 0.1 + 0.1 + 0.1 + 0.0001 + 0.63871 + 0.0001;
    assert_relative_eq!(
        robot.chain.joints()[7].link.unwrap().mass_kg,
        hand,
        epsilon = 1e-12
    );
    let arm = [1.563428, 1.800397, 2.343502, 1.432697, 1.655819, 0.370063];
    for (i, m) in arm.iter().enumerate() {
        assert_eq!(
            robot.chain.joints()[i + 1].link.unwrap().mass_kg,
            *m,
            "arm_{}",
            i + 1
        );
    }
    let off: Vec<(&str, usize)> = robot
        .off_chain
        .iter()
        .map(|b| (b.joint.as_str(), b.chain_joint))
        .collect();
    assert_eq!(
        off,
        [
            ("head_1_joint", 0),
            ("gripper_finger_joint", 7),
            ("gripper_right_finger_joint", 7)
        ]
    );
    // head_1 + head_2 + xtion and its six frames (0.001 each).
    let head = 0.6222 + 0.66123 + 0.2197 + 6.0 * 0.001;
    assert_relative_eq!(robot.off_chain[0].mass_kg, head, epsilon = 1e-12);
    // finger + fingertip.
    assert_relative_eq!(
        robot.off_chain[1].mass_kg,
        0.06286 + 0.000001,
        epsilon = 1e-15
    );
}

#[test]
fn tiago_tip_folds_the_fixed_tool_chain() {
    let Some(path) = tiago_urdf("tiago_tip_folds_the_fixed_tool_chain") else {
        return;
    };
    let robot = Robot::load(&path, None, Some("gripper_tool_link")).unwrap();
    assert_eq!(robot.base_link, "base_footprint", "the one root link");
    assert_eq!(robot.dof(), 8);
    // arm_tool_joint · wrist_ft_joint · wrist_tool_joint · gripper_tool_joint,
    // numbers from the URDF.
    let expect = homogeneous(
        [0.0, 0.0, 0.046],
        [1.57079632679, -1.57079632679, 3.14159265359],
    ) * homogeneous([0.00785, 0.0, 0.0], [1.57079632679, 0.0, 1.57079632679])
        * homogeneous([0.0, 0.0, 0.012725], [-1.57079632679, -1.57079632679, 0.0])
        * homogeneous(
            [0.01, 0.0, 0.0],
            [1.57079632679, 1.57079632679, -1.57079632679],
        );
    assert_relative_eq!(robot.chain.tip().to_homogeneous(), expect, epsilon = 1e-14);
    // The same bodies load arm_7 whatever the tip frame.
    let hand = 0.234252 + 0.1 + 0.1 + 0.1 + 0.0001 + 0.63871 + 0.0001;
    assert_relative_eq!(
        robot.chain.joints()[7].link.unwrap().mass_kg,
        hand,
        epsilon = 1e-12
    );
    let r = Rotation3::from_matrix_unchecked(expect.fixed_view::<3, 3>(0, 0).into_owned());
    assert_relative_eq!(r.matrix().determinant(), 1.0, epsilon = 1e-12);
}

#[test]
fn tiago_errors_name_the_file_and_line() {
    let Some(path) = tiago_urdf("tiago_errors_name_the_file_and_line") else {
        return;
    };
    let text = std::fs::read_to_string(&path).unwrap();
    let line_of = |needle: &str| text.lines().position(|l| l.contains(needle)).unwrap() + 1;

    let e = Robot::load(&path, Some("base_footprint"), Some("hand_link")).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Robot);
    assert_eq!(e.file, path);
    assert!(
        e.to_string().starts_with(&format!(
            "{}: tip_link 'hand_link' is not a link",
            path.display()
        )),
        "{e}"
    );

    let e = Robot::load(&path, Some("arm_1_link"), Some("head_2_link")).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Robot);
    assert!(e.message.contains("no path"), "{e}");

    // The right finger is a mimic joint: not a chain joint.
    let e = Robot::load(
        &path,
        Some("torso_lift_link"),
        Some("gripper_right_finger_link"),
    )
    .unwrap_err();
    assert_eq!(e.kind, ErrorKind::Robot);
    assert_eq!(
        e.line,
        Some(line_of(r#"<joint name="gripper_right_finger_joint" type"#))
    );
    assert!(e.message.contains("mimic"), "{e}");
}

fn parse(urdf: &str, base: &str, tip: &str) -> Result<Robot, robcal::io::InputError> {
    Robot::parse(urdf, "inline.urdf", Some(base), Some(tip))
}

const LINKS: &str = r#"<link name="a"/><link name="b"/><link name="c"/>"#;

#[test]
fn malformed_urdfs_are_errors() {
    let joint = |name: &str, kind: &str, extra: &str, parent: &str, child: &str| {
        format!(
            "<joint name=\"{name}\" type=\"{kind}\"><parent link=\"{parent}\"/>\
             <child link=\"{child}\"/>{extra}</joint>"
        )
    };
    let robot = |joints: &str| format!("<robot name=\"r\">\n{LINKS}\n{joints}\n</robot>");

    let e = parse("<robot name=\"r\"><link></robot>", "a", "b").unwrap_err();
    assert_eq!(e.kind, ErrorKind::Syntax);
    assert_eq!(e.file, Path::new("inline.urdf"));

    let planar = robot(&joint("p", "planar", "", "a", "b"));
    let e = parse(&planar, "a", "b").unwrap_err();
    assert_eq!(e.kind, ErrorKind::Robot);
    assert_eq!(e.line, Some(3));
    assert_eq!(
        e.to_string(),
        "inline.urdf:3: joint 'p': planar joints are not supported on the chain"
    );
    let floating = robot(&joint("f", "floating", "", "a", "b"));
    assert!(parse(&floating, "a", "b")
        .unwrap_err()
        .message
        .contains("floating"));

    let zero = robot(&joint("z", "revolute", r#"<axis xyz="0 0 0"/>"#, "a", "b"));
    let e = parse(&zero, "a", "b").unwrap_err();
    assert_eq!(
        (e.kind, e.message.as_str()),
        (ErrorKind::Robot, "joint 'z': zero axis")
    );

    let nan = robot(&joint(
        "n",
        "continuous",
        r#"<origin xyz="0 NaN 0"/>"#,
        "a",
        "b",
    ));
    let e = parse(&nan, "a", "b").unwrap_err();
    assert_eq!(e.kind, ErrorKind::NonFinite);
    assert!(e.message.starts_with("joint 'n': origin"), "{e}");

    let far = robot(&joint(
        "f",
        "continuous",
        r#"<origin xyz="0 1e308 0"/>"#,
        "a",
        "b",
    ));
    let e = parse(&far, "a", "b").unwrap_err();
    assert_eq!(e.kind, ErrorKind::InvalidValue);
    assert!(e.message.contains("beyond 1e4 m, not a robot's"), "{e}");

    let dangling = robot(&joint("d", "fixed", "", "a", "nowhere"));
    let e = parse(&dangling, "a", "b").unwrap_err();
    assert!(
        e.message.contains("child link 'nowhere' is not defined"),
        "{e}"
    );

    let two_parents = robot(
        &(joint("j1", "continuous", "", "a", "c") + &joint("j2", "continuous", "", "b", "c")),
    );
    let e = parse(&two_parents, "a", "c").unwrap_err();
    assert!(e.message.contains("already the child of joint 'j1'"), "{e}");

    let fixed_only = robot(&joint("f", "fixed", "", "a", "b"));
    let e = parse(&fixed_only, "a", "b").unwrap_err();
    assert!(e.message.contains("no movable joint"), "{e}");

    let e = parse(&fixed_only, "a", "zz").unwrap_err();
    assert_eq!(e.message, "tip_link 'zz' is not a link of robot 'r'");

    let heavy = "<robot name=\"r\"><link name=\"a\"/><link name=\"b\"><inertial><mass value=\"-1\"/>\
        <inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial></link>\
        <joint name=\"j\" type=\"continuous\"><parent link=\"a\"/><child link=\"b\"/></joint></robot>";
    let e = parse(heavy, "a", "b").unwrap_err();
    assert_eq!(e.kind, ErrorKind::InvalidValue);
    assert!(e.message.contains("link 'b': negative mass"), "{e}");
}

#[test]
fn too_many_joints() {
    let mut urdf = String::from("<robot name=\"long\">\n<link name=\"l0\"/>\n");
    for i in 1..=MAX_JOINTS + 1 {
        urdf += &format!(
            "<link name=\"l{i}\"/>\n<joint name=\"j{i}\" type=\"continuous\">\
             <parent link=\"l{}\"/><child link=\"l{i}\"/></joint>\n",
            i - 1
        );
    }
    urdf += "</robot>";
    let ok = parse(&urdf, "l0", &format!("l{MAX_JOINTS}")).unwrap();
    assert_eq!(ok.dof(), MAX_JOINTS);
    assert!(
        ok.chain.joints().iter().all(|j| j.link.is_none()),
        "massless links: no inertia"
    );
    let e = parse(&urdf, "l0", &format!("l{}", MAX_JOINTS + 1)).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Robot);
    assert!(
        e.message
            .contains(&format!("more than {MAX_JOINTS} movable joints")),
        "{e}"
    );
}

/// Says on the real stderr (libtest captures `eprintln!` of a passing
/// test, a direct write shows in `cargo test`'s output) why a test is
/// skipped.
fn skipped_note(why: &str) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr(), "{why}");
}
