//! FIGAROH mocap importer (`robcal::io::figaroh`) on the TIAGo recordings of
//! `shared/datasets/tiago-mocap`, and the shipped setup `data/tiago/setup.toml`.

use crate::tiago_common;
use tiago_common::*;

use std::path::Path;

use robcal::io::figaroh::{import_mocap, read_mocap};
use robcal::io::{ErrorKind, Setup};

/// Movable joints of FIGAROH's chain, base to hand.
const JOINT_NAMES: [&str; 8] = [
    "torso_lift_joint",
    "arm_1_joint",
    "arm_2_joint",
    "arm_3_joint",
    "arm_4_joint",
    "arm_5_joint",
    "arm_6_joint",
    "arm_7_joint",
];

/// The FIGAROH file split by hand (an independent reader): header, rows.
fn raw(data: &Path, name: &str) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(data.join(name)).unwrap();
    let mut lines = text.lines();
    let header = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_owned)
        .collect();
    let rows = lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

#[test]
fn round_trip_is_exact() {
    let Some(data) = data_or_skip("round_trip_is_exact") else {
        return;
    };
    let job = job(&data, "setup.toml");
    let dir = temp_dir("import");
    for (name, postures, shipped) in [(TRAIN, 37, true), (VALID, 62, false)] {
        let (header, rows) = raw(&data, name);
        assert_eq!(header.contains(&"shipped_row".to_string()), shipped);
        let col = |n: &str| header.iter().position(|h| h == n).unwrap();
        let obs = import(&job, &data, name).observations;
        assert_eq!(obs.len(), 4 * postures);
        assert_eq!(rows.len(), postures);
        for o in &obs {
            let row = &rows[o.config as usize - 1];
            assert_eq!((o.rep, o.load_kg), (1, 0.0));
            let k = o.marker;
            assert!((1..=4).contains(&k));
            for (a, axis) in ["x", "y", "z"].iter().enumerate() {
                assert_eq!(
                    o.p_m[a].to_bits(),
                    row[col(&format!("{axis}{k}"))].to_bits()
                );
            }
            for (j, n) in JOINT_NAMES.iter().enumerate() {
                assert_eq!(o.q[j].to_bits(), row[col(n)].to_bits(), "{n}");
            }
            let t = 0.5 * (row[col("t_start_robot")] + row[col("t_end_robot")]);
            assert_eq!(o.t_s.unwrap().to_bits(), t.to_bits());
        }
        // Without a robot: the same rows (FIGAROH's joint order is the chain's).
        let plain = dir.join("plain.csv");
        let n = import_mocap(data.join(name), &plain, None).unwrap();
        assert_eq!(
            (n.postures, n.rows, n.has_time),
            (postures, 4 * postures, true)
        );
        let back = job.read_measurements(&plain).unwrap().observations;
        let strip = |v: &[robcal::io::Observation]| {
            v.iter()
                .map(|o| (o.config, o.marker, o.q.clone(), o.p_m, o.t_s))
                .collect::<Vec<_>>()
        };
        assert_eq!(strip(&back), strip(&obs));
    }
    let m = read_mocap(data.join(TRAIN)).unwrap();
    assert_eq!(m.joint_names, JOINT_NAMES);
    assert_eq!(m.postures[35].shipped_row, Some(33.0));
    assert_eq!(m.postures[36].shipped_row, Some(-1.0));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn rejected_input_names_file_line_column_and_writes_nothing() {
    let Some(data) = data_or_skip("rejected_input_names_file_line_column_and_writes_nothing")
    else {
        return;
    };
    let dir = temp_dir("import-bad");
    let text = std::fs::read_to_string(data.join(TRAIN)).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    // Line 5 (4th posture): arm_3_joint is column 16.
    let mut cells: Vec<&str> = lines[4].split(',').collect();
    cells[15] = "0.1.2";
    lines[4] = cells.join(",");
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, lines.join("\n")).unwrap();
    let out = dir.join("out.csv");
    let e = import_mocap(&bad, &out, None).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Syntax);
    assert_eq!(
        e.to_string(),
        format!(
            "{}:5: column 'arm_3_joint': '0.1.2' is not a number",
            bad.display()
        )
    );
    assert!(!out.exists());
    // A chain whose joints are not the file's.
    let job = job(&data, "setup.toml");
    let renamed = text.replacen("arm_7_joint", "wrist_joint", 1);
    std::fs::write(&bad, renamed).unwrap();
    let e = import_mocap(&bad, &out, Some(&job.robot)).unwrap_err();
    assert_eq!(e.kind, ErrorKind::MissingColumn);
    assert!(e.to_string().contains("arm_7_joint"), "{e}");
    assert!(!out.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn setup_names_the_shared_urdf_and_figaroh_chain() {
    let Some(data) = data_or_skip("setup_names_the_shared_urdf_and_figaroh_chain") else {
        return;
    };
    let job = job(&data, "setup.toml");
    assert_eq!(
        job.setup.robot,
        std::path::Path::new("../../../shared/datasets/tiago-mocap/tiago_48_schunk.urdf")
    );
    // In CI the repository sits beside `shared/`: the path resolves. (In a
    // nested worktree it cannot; `job()` then reads the URDF it finds.)
    if repo_root()
        .parent()
        .unwrap()
        .join("shared/datasets/tiago-mocap")
        .exists()
    {
        let p = job.setup.robot_path(&job.setup_path);
        assert_eq!(
            p.canonicalize().ok(),
            data.join(URDF).canonicalize().ok(),
            "the setup names the shared URDF"
        );
        robcal::io::Job::load(&job.setup_path).unwrap();
    }
    assert_eq!(job.robot.joint_names, JOINT_NAMES);
    assert_eq!(
        job.robot.chain.joints()[0].kind,
        robcal::JointKind::Prismatic
    );
    assert_eq!(job.setup.markers.len(), 4);
    assert!(job.setup.model.base_frame);
    let text = std::fs::read_to_string(&job.setup_path).unwrap();
    Setup::parse(&text, "setup.toml").unwrap();
}
