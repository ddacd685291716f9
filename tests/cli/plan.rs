//! `robcal plan` (issue 54) on the bundled KR-270: the paper's compliances
//! planned from 1 000 random candidates under a 250 kg payload.
//!
//! - the plan determines the compliances better than as many random
//!   candidates, by its own prediction (the measured comparison against a
//!   generator that shares no code with robcal is
//!   `host-tests/tests/plan.rs`);
//! - the written configurations are the points CSV, within the limits, the
//!   same bytes on every run, and read back as a pool;
//! - the core's next best pose (`estimate::plan::next_best`, the
//!   controller's step) is the host's first choice;
//! - what cannot be planned is one line and exit 1, nothing written.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

fn robcal(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_robcal"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .output()
        .expect("run robcal")
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("robcal-plan-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn plan(out: &Path, extra: &[&str]) -> Value {
    let out = out.to_str().unwrap();
    let mut args = vec![
        "plan",
        "--setup",
        "data/kr270/setup.toml",
        "--poses",
        "15",
        "--load-kg",
        "250",
        "--output",
        out,
        "--json",
    ];
    args.extend_from_slice(extra);
    let o = robcal(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).expect("JSON")
}

#[test]
fn a_plan_of_the_kr270_determines_its_compliances_better_than_random_poses() {
    let d = dir("kr270");
    let v = plan(&d.join("plan.csv"), &[]);
    let names: Vec<&str> = (v["parameters"].as_array().unwrap().iter())
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["k_a2", "k_a3", "k_a4", "k_a5", "k_a6"], "{v}");
    assert!(v["left_out"].as_array().unwrap().is_empty());
    assert!(v["notes"][0]
        .as_str()
        .unwrap()
        .contains("compliance_by_angle"));
    // Every compliance better determined, the trace of the scaled
    // covariance less than half, the predicted error lower.
    for p in v["parameters"].as_array().unwrap() {
        assert!(
            p["std"].as_f64().unwrap() < p["std_random"].as_f64().unwrap(),
            "{p}"
        );
    }
    let (planned, random) = (&v["plan"], &v["random"]);
    let t = |s: &Value| s["trace_scaled"].as_f64().unwrap();
    assert!(t(planned) < 0.5 * t(random), "{planned} {random}");
    let e = |s: &Value| s["predicted_rms_um"].as_f64().unwrap();
    assert!(e(planned) < e(random), "{planned} {random}");

    // The configurations: the points CSV, 250 kg, within the URDF's limits.
    let csv = std::fs::read_to_string(d.join("plan.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("id,load_kg,com_x_m,com_y_m,com_z_m,a1_rad,a2_rad,a3_rad,a4_rad,a5_rad,a6_rad")
    );
    let urdf = std::fs::read_to_string("data/kr270/kr270.urdf").unwrap();
    let limits: Vec<(f64, f64)> = urdf
        .split("<limit")
        .skip(1)
        .map(|l| {
            let attr = |k: &str| -> f64 {
                let s = &l[l.find(&format!("{k}=\"")).unwrap() + k.len() + 2..];
                s[..s.find('"').unwrap()].parse().unwrap()
            };
            (attr("lower"), attr("upper"))
        })
        .collect();
    assert_eq!(limits.len(), 6);
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), 15);
    for (k, r) in rows.iter().enumerate() {
        let cells: Vec<&str> = r.split(',').collect();
        assert_eq!(cells[0], format!("plan{}", k + 1));
        assert_eq!(cells[1..5], ["250", "0.25", "0.0", "0.3"]);
        for (j, c) in cells[5..].iter().enumerate() {
            let q: f64 = c.parse().unwrap();
            assert!((limits[j].0..=limits[j].1).contains(&q), "{r}");
        }
    }
    // The same bytes again; and the plan as a pool of its own, all of it
    // chosen.
    plan(&d.join("again.csv"), &[]);
    assert_eq!(csv, std::fs::read_to_string(d.join("again.csv")).unwrap());
    let pool = d.join("plan.csv");
    let w = plan(
        &d.join("from-pool.csv"),
        &["--pool", pool.to_str().unwrap()],
    );
    assert_eq!(w["candidates"], 15);
    assert!(w["random"].is_null());
    let mut a: Vec<&str> = csv
        .lines()
        .skip(1)
        .map(|l| l.split_once(',').unwrap().1)
        .collect();
    let from = std::fs::read_to_string(d.join("from-pool.csv")).unwrap();
    let mut b: Vec<&str> = from
        .lines()
        .skip(1)
        .map(|l| l.split_once(',').unwrap().1)
        .collect();
    a.sort_unstable();
    b.sort_unstable();
    assert_eq!(a, b);
    let _ = std::fs::remove_dir_all(&d);
}

/// The controller's step — the core's `next_best` over the candidates'
/// blocks from an empty accumulator and the first prior — is the host's
/// first greedy choice.
#[test]
fn the_cores_next_best_pose_is_the_hosts_first_choice() {
    use robcal::calibrate::plan::{choose, pool, random_candidates, Criterion, PlanSettings};
    let job =
        robcal::io::Job::load(Path::new(env!("CARGO_MANIFEST_DIR")).join("data/kr270/setup.toml"))
            .unwrap();
    let s = PlanSettings {
        candidates: 300,
        loads_kg: vec![250.0],
        ..PlanSettings::default()
    };
    let p = pool(
        &job,
        random_candidates(&job, &s).unwrap(),
        None,
        &Default::default(),
    )
    .unwrap();
    let host = choose(&p, 1, Criterion::D, 0).unwrap();
    let n = p.parameters();
    let table: Vec<&[robcal::estimate::Block<f64, nalgebra::Dyn>]> =
        (0..p.candidates.len()).map(|c| p.blocks(c)).collect();
    let device = robcal::estimate::plan::next_best(
        &nalgebra::DMatrix::zeros(n, n),
        &p.prior(),
        &vec![true; n],
        &table,
        &vec![false; table.len()],
    )
    .unwrap()
    .unwrap();
    assert_eq!(host.chosen, vec![device.0]);
}

#[test]
fn what_cannot_be_planned_is_one_line_and_nothing_written() {
    let d = dir("refuse");
    let out = d.join("plan.csv");
    let o = out.to_str().unwrap();
    // (Exit 2: an argument out of range, as clap says it.)
    let cases: [(&[&str], i32, &str); 7] = [
        (&["--poses", "5"], 1, "--load-kg"),
        (
            &["--poses", "50", "--candidates", "20", "--load-kg", "250"],
            1,
            "50 poses to choose from 20 candidates",
        ),
        (
            &["--poses", "5", "--load-kg", "250", "--limit", "a9=0:1"],
            1,
            "unknown joint 'a9'",
        ),
        (
            &["--poses", "5", "--load-kg", "250", "--limit", "a2=-9:9"],
            1,
            "--limit a2=-9:9",
        ),
        (&["--poses", "5", "--load-kg", "-3"], 2, "a mass from 0"),
        (&["--poses", "5", "--candidates", "100001"], 2, "100001"),
        (
            &[
                "--poses",
                "5",
                "--load-kg",
                "250",
                "--orientation-urad",
                "0",
            ],
            2,
            "a number above 0",
        ),
    ];
    for (args, code, expect) in cases {
        let mut all = vec!["plan", "--setup", "data/kr270/setup.toml"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["--output", o]);
        let r = robcal(&all);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(code), "{args:?}: {err}");
        if code == 1 {
            assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        }
        assert!(err.contains(expect), "{err} (expected '{expect}')");
        assert!(!out.exists(), "{args:?} wrote {o}");
    }
    // A pool that is not one: its line and column, nothing written.
    let pool = d.join("pool.csv");
    std::fs::write(
        &pool,
        "load_kg,a1_rad,a2_rad,a3_rad,a4_rad,a5_rad,a6_rad\n250,0,0,0,0,nan,0\n",
    )
    .unwrap();
    let r = robcal(&[
        "plan",
        "--setup",
        "data/kr270/setup.toml",
        "--poses",
        "1",
        "--pool",
        pool.to_str().unwrap(),
        "--output",
        o,
    ]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(1), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("pool.csv:2"), "{err}");
    assert!(!out.exists());
    let _ = std::fs::remove_dir_all(&d);
}

/// Compliances and the full geometry together: a loaded candidate gives
/// six blocks (three markers' positions and deflections), more than the
/// core's gain takes at once; the host plans it the same way, and better
/// than random poses.
#[test]
fn positions_and_deflections_together_are_planned() {
    let d = dir("mixed");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let setup = std::fs::read_to_string(root.join("data/kr270/setup.toml"))
        .unwrap()
        .replace("geometry = \"none\"", "geometry = \"full\"")
        .replace(
            "robot = \"kr270.urdf\"",
            &format!("robot = {:?}", root.join("data/kr270/kr270.urdf")),
        );
    std::fs::write(d.join("setup.toml"), setup).unwrap();
    let o = robcal(&[
        "plan",
        "--setup",
        d.join("setup.toml").to_str().unwrap(),
        "--poses",
        "30",
        "--load-kg",
        "250",
        "--load-kg",
        "0",
        "--output",
        d.join("plan.csv").to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    let names: Vec<&str> = (v["parameters"].as_array().unwrap().iter())
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert!(
        names.contains(&"k_a3") && names.iter().any(|n| n.ends_with(".tx")),
        "{names:?}"
    );
    let t = |s: &Value| s["trace_scaled"].as_f64().unwrap();
    assert!(t(&v["plan"]) < t(&v["random"]), "{v}");
    let _ = std::fs::remove_dir_all(&d);
}

/// A 6-D instrument (`--orientation-urad`): on the KR-270 pose job the
/// tool frame's rotation, which the points of one probe leave out, is
/// planned for with the orientations.
#[test]
fn a_plan_for_a_6d_instrument_determines_the_tool_rotation() {
    let d = dir("six-d");
    let out = d.join("plan.csv");
    let run = |extra: &[&str]| -> Value {
        let mut args = vec![
            "plan",
            "--setup",
            "data/kr270/setup-6d.toml",
            "--poses",
            "8",
            "--candidates",
            "300",
            "--output",
            out.to_str().unwrap(),
            "--json",
        ];
        args.extend_from_slice(extra);
        let o = robcal(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).expect("JSON")
    };
    let names = |v: &Value, key: &str| -> Vec<String> {
        let list = v[key].as_array().expect(key);
        list.iter()
            .map(|p| p.get("name").unwrap_or(p).as_str().unwrap().to_string())
            .collect()
    };
    let points = run(&[]);
    let poses = run(&["--orientation-urad", "30"]);
    let (left, planned) = (names(&points, "left_out"), names(&poses, "parameters"));
    let turns: Vec<&String> = left.iter().filter(|p| p.starts_with("tool.r")).collect();
    assert!(!turns.is_empty(), "points leave out {left:?}");
    assert!(turns.iter().all(|p| planned.contains(p)), "{planned:?}");
    let _ = std::fs::remove_dir_all(&d);
}
