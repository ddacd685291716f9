//! robcal's own output as the next calibration's input (issue 59): a job
//! calibrated with `--output o1`, then the same job with
//! `robot = "o1/robot.urdf"` and `--output o2`. The second run starts at
//! the first one's answer, on the same data: its geometric changes are
//! within their σ of zero, every other estimate within the first's σ of
//! the first's, and its `robot.urdf` is the first one's to a tolerance
//! (1e-9 m and rad where the second run starts where the first ended).

use std::path::Path;
use std::process::Command;

use nalgebra::{Rotation3, Vector3};
use serde_json::Value;

/// Runs `robcal calibrate --setup <setup> --json --output <out> <args>` in
/// `dir`, the setup's `robot` line replaced by `robot` and, with
/// `markers`, each `[[marker]]`'s `xyz` line by the `xyz_m` of its id in
/// that `model.json` (the calibrated markers); its JSON.
fn calibrate(
    dir: &Path,
    setup: &str,
    robot: &str,
    markers: Option<&Value>,
    out: &str,
    args: &[&str],
) -> Value {
    let text = std::fs::read_to_string(dir.join(setup)).unwrap();
    let calibrated = |id: &str| -> Option<String> {
        let list = markers?["predictor"]["markers"].as_array()?;
        let m = list
            .iter()
            .find(|m| m["id"].as_u64().map(|v| v.to_string()) == Some(id.to_owned()))?;
        Some(format!("xyz = {}", m["xyz_m"]))
    };
    let mut id = String::new();
    let text: String = text
        .lines()
        .map(|l| {
            if let Some(v) = l.strip_prefix("id = ") {
                id = v.trim().to_owned();
            }
            if l.starts_with("robot = ") {
                format!("robot = {robot:?}")
            } else if l.starts_with("xyz = ") {
                calibrated(&id).unwrap_or_else(|| l.to_owned())
            } else {
                l.to_owned()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    let name = format!("{out}.toml");
    std::fs::write(dir.join(&name), text).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_robcal"))
        .current_dir(dir)
        .args([
            "calibrate",
            "-q",
            "--setup",
            &name,
            "--json",
            "--output",
            out,
        ])
        .args(args)
        .output()
        .expect("run robcal");
    assert!(
        o.status.success(),
        "{out}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("JSON on stdout")
}

/// The angle of `r` (rad), accurate near zero: `‖R − Rᵀ‖_F / (2√2)` is
/// `sin θ` (`Rotation3::angle`'s `acos` loses half the digits there, 2e-8
/// rad for equal rotations).
fn angle(r: &Rotation3<f64>) -> f64 {
    let m = r.matrix();
    (m - m.transpose()).norm() / (2.0 * std::f64::consts::SQRT_2)
}

fn pose(p: &urdf_rs::Pose) -> (Vector3<f64>, Rotation3<f64>) {
    (
        Vector3::from(p.xyz.0),
        Rotation3::from_euler_angles(p.rpy[0], p.rpy[1], p.rpy[2]),
    )
}

/// How the second run is set up, and how close its `robot.urdf` must be.
#[derive(Debug, Clone, Copy)]
pub struct Trip<'a> {
    /// The setup file in the directory.
    pub setup: &'a str,
    /// The first run's nominal robot (relative to the directory).
    pub robot: &'a str,
    /// Extra arguments of both runs.
    pub args: &'a [&'a str],
    /// The second run's markers start at the first run's calibrated ones
    /// (its `model.json`), not at the setup's nominal ones: it then starts
    /// where the first ended.
    pub markers_from_first: bool,
    /// Largest difference of a joint origin between the two `robot.urdf`
    /// (m, and rad).
    pub origin_tolerance: f64,
}

/// The round trip `trip` in `dir`; asserts the above.
pub fn assert_round_trip(dir: &Path, trip: Trip<'_>) {
    let Trip {
        setup,
        robot,
        args,
        markers_from_first,
        origin_tolerance,
    } = trip;
    let first = calibrate(dir, setup, robot, None, "o1", args);
    let model: Option<Value> = markers_from_first.then(|| {
        let text = std::fs::read_to_string(dir.join("o1/model.json")).unwrap();
        serde_json::from_str(&text).unwrap()
    });
    let second = calibrate(dir, setup, "o1/robot.urdf", model.as_ref(), "o2", args);
    let params = |v: &Value| -> Vec<(String, f64, f64)> {
        v["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| {
                (
                    p["name"].as_str().unwrap().to_owned(),
                    p["value"].as_f64().unwrap(),
                    p["std"].as_f64().unwrap(),
                )
            })
            .collect()
    };
    let (one, two) = (params(&first), params(&second));
    assert!(!two.is_empty());
    for (name, v2, sd2) in &two {
        // A joint's geometry is a change from the nominal robot, which is now
        // the first calibration's: zero within its σ; so is a marker's
        // when it starts at the first calibration's.
        let joint_geometry = !name.starts_with("base.")
            && !name.starts_with("marker")
            && [".offset", ".tx", ".ty", ".tz", ".rx", ".ry", ".rz"]
                .iter()
                .any(|s| name.ends_with(s));
        let change = joint_geometry || (markers_from_first && name.starts_with("marker"));
        if change {
            assert!(
                v2.abs() <= *sd2,
                "{name}: {v2} ± {sd2} after the round trip"
            );
        } else {
            let (_, v1, sd1) = one
                .iter()
                .find(|p| &p.0 == name)
                .unwrap_or_else(|| panic!("{name} only in the second run"));
            assert!((v2 - v1).abs() <= *sd1, "{name}: {v1} ± {sd1}, then {v2}");
        }
    }
    let read = |d: &str| {
        let text = std::fs::read_to_string(dir.join(d).join("robot.urdf")).unwrap();
        urdf_rs::read_from_string(&text).expect("robot.urdf parses")
    };
    let (u1, u2) = (read("o1"), read("o2"));
    let mut links1: Vec<&str> = u1.links.iter().map(|l| l.name.as_str()).collect();
    let mut links2: Vec<&str> = u2.links.iter().map(|l| l.name.as_str()).collect();
    links1.sort_unstable();
    links2.sort_unstable();
    assert_eq!(links1, links2, "the same links, none added");
    assert_eq!(u1.joints.len(), u2.joints.len());
    for j1 in &u1.joints {
        let j2 = u2
            .joints
            .iter()
            .find(|j| j.name == j1.name)
            .unwrap_or_else(|| panic!("joint {} missing after the round trip", j1.name));
        let ((t1, r1), (t2, r2)) = (pose(&j1.origin), pose(&j2.origin));
        let dt = (t1 - t2).norm();
        let dr = angle(&(r1.inverse() * r2));
        assert!(
            dt <= origin_tolerance && dr <= origin_tolerance,
            "joint {}: {dt} m, {dr} rad",
            j1.name
        );
    }
}
