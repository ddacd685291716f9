//! `robcal calibrate` end to end, through the data contract (§4, §5): the
//! KR-270 naive-model demonstration, the JSON schema, `--validate`,
//! `--plots`, and bad input (file, line, column; non-zero exit; nothing
//! written).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

use crate::round_trip;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn robcal(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_robcal"))
        .current_dir(root())
        .args(args)
        .output()
        .expect("run robcal")
}

const NAIVE: [&str; 5] = [
    "calibrate",
    "--setup",
    "data/kr270/setup-naive.toml",
    "--data",
    "data/kr270/measurements.csv",
];

fn json(out: &Output) -> Value {
    assert!(
        out.status.success(),
        "robcal failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("stdout is JSON")
}

fn keys(v: &Value) -> Vec<&str> {
    let mut k: Vec<&str> = v.as_object().unwrap().keys().map(|s| s.as_str()).collect();
    k.sort_unstable();
    k
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("robcal-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn kr270_naive_model_traces_the_compensator() {
    let mut args = NAIVE.to_vec();
    args.push("--json");
    let v = json(&robcal(&args));
    assert_eq!(
        keys(&v),
        [
            "converged",
            "deflection_model",
            "effects",
            "heldout_rms_um",
            "identifiability",
            "iterations",
            "method",
            "near_dependent",
            "nominal",
            "parameters",
            "relinearisations",
            "rms_um",
            "unexplained",
            "validation",
            "warnings",
            "weights"
        ]
    );
    // No instrument σ in these data: the paper's estimated σ.
    assert_eq!(v["weights"], "estimated");
    // The nominal error (data contract 7.5) of a deflection-only job is the
    // measured deflections themselves: computed here from the CSV.
    let csv = std::fs::read_to_string(root().join("data/kr270/measurements.csv")).unwrap();
    let mut unloaded = std::collections::BTreeMap::new();
    let mut norms = Vec::new();
    for line in csv.lines().skip(1) {
        let c: Vec<&str> = line.split(',').collect();
        let key = (c[0].to_string(), c[1].to_string(), c[2].to_string());
        let p: Vec<f64> = c[10..13].iter().map(|x| x.parse().unwrap()).collect();
        if c[3] == "0" {
            unloaded.insert(key, p);
        } else {
            let u = &unloaded[&key];
            let d2: f64 = (0..3).map(|a| (p[a] - u[a]).powi(2)).sum();
            norms.push(d2.sqrt() * 1e3); // mm -> um
        }
    }
    let n = norms.len() as f64;
    let rms = (norms.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    let mean = norms.iter().sum::<f64>() / n;
    let max = norms.iter().copied().fold(0.0, f64::max);
    let nominal = &v["nominal"];
    for (key, want) in [("rms_um", rms), ("mean_um", mean), ("max_um", max)] {
        let got = nominal[key].as_f64().unwrap();
        assert!(
            (got - want).abs() < 1e-6 * want,
            "nominal {key}: {got} vs {want}"
        );
    }
    assert_eq!(v["method"], "irls");
    assert_eq!(v["deflection_model"], "exact");
    assert!(v["iterations"].as_u64().unwrap() >= 1);
    assert!(v["validation"].is_null());
    assert!(v["unexplained"].is_null(), "{}", v["unexplained"]);

    // The diagnosis adds exactly the compensator on a2 (the paper's k21…k25).
    let effects = v["effects"].as_array().unwrap();
    assert_eq!(effects.len(), 1, "{effects:?}");
    let e = &effects[0];
    assert_eq!(
        keys(e),
        [
            "effect",
            "heldout_rms_um_after",
            "heldout_rms_um_before",
            "joint",
            "p_value",
            "rms_um_after",
            "rms_um_before"
        ]
    );
    assert_eq!(e["effect"], "compensator");
    assert_eq!(e["joint"], "a2");
    assert!(e["p_value"].as_f64().unwrap() < 1e-20);
    let (before, after) = (
        e["rms_um_before"].as_f64().unwrap(),
        e["rms_um_after"].as_f64().unwrap(),
    );
    let (hb, ha) = (
        e["heldout_rms_um_before"].as_f64().unwrap(),
        e["heldout_rms_um_after"].as_f64().unwrap(),
    );
    // Reference run: 262.1 -> 123.2 µm, held out 265.7 -> 124.3 µm.
    assert!(before > 1.8 * after, "{before} -> {after}");
    assert!(hb > 1.8 * ha, "{hb} -> {ha}");
    assert_eq!(v["rms_um"].as_f64().unwrap(), after);
    assert_eq!(v["heldout_rms_um"].as_f64().unwrap(), ha);

    // Parameters: k_a2@<angle as written in the CSV> and k_a3..k_a6.
    let params = v["parameters"].as_array().unwrap();
    let names: Vec<&str> = params.iter().map(|p| p["name"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [
            "k_a2@-0.01",
            "k_a2@-25.24",
            "k_a2@-56.9",
            "k_a2@-99.85",
            "k_a2@-140",
            "k_a3",
            "k_a4",
            "k_a5",
            "k_a6"
        ]
    );
    // Table 3 (WLS) of the paper, which generated the data: the estimates
    // lie within 4σ of it.
    let truth = [
        0.287, 0.277, 0.302, 0.293, 0.246, 0.416, 2.786, 3.483, 2.074,
    ];
    for (p, t) in params.iter().zip(truth) {
        assert_eq!(p["unit"], "urad/(N*m)");
        assert_eq!(keys(p), ["determined", "name", "std", "unit", "value"]);
        assert_eq!(p["determined"], true);
        let (x, s) = (p["value"].as_f64().unwrap(), p["std"].as_f64().unwrap());
        assert!(
            s > 0.0 && (x - t).abs() < 4.0 * s + 0.01 * t,
            "{p}: truth {t}"
        );
    }
}

#[test]
fn paper_model_needs_no_effect() {
    let v = json(&robcal(&[
        "calibrate",
        "--setup",
        "data/kr270/setup.toml",
        "--data",
        "data/kr270/measurements.csv",
        "--json",
    ]));
    assert_eq!(v["effects"].as_array().unwrap().len(), 0);
    assert!(v["unexplained"].is_null());
}

/// The README's pose command: the KR-270's 6-D poses (generated with
/// joint zeros and a tool frame off; `generate_kr270_poses` prints the
/// truth). The orientations are reported apart in µrad; the tool's
/// rotation is identified, the last joint's zero left out as the same
/// turn; the estimates are the truth's within 3 σ.
#[test]
fn six_d_poses_identify_the_tool_frame() {
    let dir = temp_dir("six-d");
    let v = json(&robcal(&[
        "calibrate",
        "--setup",
        "data/kr270/setup-6d.toml",
        "--data",
        "data/kr270/poses-6d.csv",
        "--json",
        "--output",
        dir.to_str().unwrap(),
    ]));
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(
        html.contains("orientation of 40 poses"),
        "no orientation in the report"
    );
    // `robcal predict` from model.json alone: each pose's frame within the
    // instrument's noise of the measured one, as the report's RMS says.
    let data = std::fs::read_to_string("data/kr270/poses-6d.csv").unwrap();
    let mut poses = String::from("marker,a1_rad,a2_rad,a3_rad,a4_rad,a5_rad,a6_rad\n");
    let mut measured = Vec::new();
    for line in data.lines().skip(1) {
        let c: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
        let q: Vec<String> = c[1..7].iter().map(f64::to_string).collect();
        poses += &format!("1,{}\n", q.join(","));
        measured.push(nalgebra::Vector3::new(c[13], c[14], c[15]));
    }
    let poses_csv = dir.join("poses.csv");
    std::fs::write(&poses_csv, poses).unwrap();
    let model = dir.join("model.json");
    let out = robcal(&[
        "predict",
        "--model",
        model.to_str().unwrap(),
        "--poses",
        poses_csv.to_str().unwrap(),
        "--orientation",
    ]);
    let text = String::from_utf8(out.stdout).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let rx = header.iter().position(|h| *h == "rx_rad").expect("rx_rad");
    let mut sq = 0.0;
    for (line, m) in text.lines().skip(1).zip(&measured) {
        let c: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
        let predicted =
            nalgebra::Rotation3::new(nalgebra::Vector3::new(c[rx], c[rx + 1], c[rx + 2]));
        let left = nalgebra::Rotation3::new(*m) * predicted.transpose();
        sq += left.angle().powi(2);
    }
    let predicted_rms_urad = (sq / measured.len() as f64).sqrt() * 1e6;
    let _ = std::fs::remove_dir_all(&dir);
    let o = &v["orientation"];
    let reported = o["rms_urad"].as_f64().unwrap();
    assert!(
        (predicted_rms_urad / reported - 1.0).abs() < 0.01,
        "predict {predicted_rms_urad} urad, reported {reported} urad"
    );
    assert_eq!(o["poses"], 40);
    let rms = o["rms_urad"].as_f64().unwrap();
    assert!(rms > 30.0 && rms < 70.0, "{o}");
    assert!(o["nominal_rms_urad"].as_f64().unwrap() > 1000.0, "{o}");
    let rms_um = v["rms_um"].as_f64().unwrap();
    assert!(rms_um > 20.0 && rms_um < 45.0, "{rms_um}");
    // The truth the generator printed (mm, mrad).
    let truth = [
        ("tool.tx", -0.018_240),
        ("tool.ty", -0.195_489),
        ("tool.tz", -0.164_791),
        ("tool.rx", -0.420_399),
        ("tool.ry", 0.234_550),
        ("tool.rz", 0.078_653),
        ("a1.offset", -0.577_869),
        ("a2.offset", 0.655_072),
        ("a3.offset", 0.467_787),
        ("a4.offset", 0.491_897),
        ("a5.offset", 0.711_491),
    ];
    let params = v["parameters"].as_array().unwrap();
    assert_eq!(params.len(), truth.len(), "{params:?}");
    for (name, t) in truth {
        let p = params
            .iter()
            .find(|p| p["name"] == name)
            .unwrap_or_else(|| panic!("{name}"));
        let z = (p["value"].as_f64().unwrap() - t) / p["std"].as_f64().unwrap();
        assert!(z.abs() < 3.0, "{name}: {p}");
    }
    assert!(
        v["identifiability"].to_string().contains("a6.offset"),
        "{}",
        v["identifiability"]
    );
}

/// The README's command without a tracker: the KR-270's probe touching
/// the floor and two walls of a corner (generated with joint zeros off and
/// the base 2.7 mm and 0.6 mrad off its nominal place;
/// `generate_kr270_contacts` prints the truth). The contacts' errors are
/// reported (`scalars`, one equation a contact); the estimates are the
/// truth's within 3 σ, the first joint's zero left out as the base's turn
/// (its truth 0); the outputs are written.
#[test]
fn plane_contacts_identify_the_base_and_the_joint_zeros() {
    let dir = temp_dir("contacts");
    let v = json(&robcal(&[
        "calibrate",
        "--setup",
        "data/kr270/setup-contacts.toml",
        "--data",
        "data/kr270/contacts.csv",
        "--json",
        "--output",
        dir.to_str().unwrap(),
    ]));
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(html.contains("(60 equations)"), "equations in the report");
    assert!(dir.join("robot.urdf").exists() && dir.join("model.json").exists());
    let _ = std::fs::remove_dir_all(&dir);
    let s = &v["scalars"];
    assert_eq!(s["rows"], 60);
    let rms = s["rms_um"].as_f64().unwrap();
    assert!(rms > 5.0 && rms < 15.0, "{s}");
    assert_eq!(v["rms_um"], s["rms_um"], "no points: the contacts' RMS");
    let heldout = v["heldout_rms_um"].as_f64().unwrap();
    assert!(heldout > rms && heldout < 2.0 * rms, "{heldout}");
    // The truth the generator printed (mm, mrad).
    let truth = [
        ("base.tx", 2.0),
        ("base.ty", -1.5),
        ("base.tz", 0.8),
        ("base.rx", 0.3),
        ("base.ry", -0.2),
        ("base.rz", 0.5),
        ("a2.offset", -0.136_201),
        ("a3.offset", 0.599_677),
        ("a4.offset", -0.915_232),
        ("a5.offset", 0.567_333),
        ("a6.offset", 0.0),
    ];
    let params = v["parameters"].as_array().unwrap();
    assert_eq!(params.len(), truth.len(), "{params:?}");
    for (name, t) in truth {
        let p = params
            .iter()
            .find(|p| p["name"] == name)
            .unwrap_or_else(|| panic!("{name}"));
        let z = (p["value"].as_f64().unwrap() - t) / p["std"].as_f64().unwrap();
        assert!(z.abs() < 3.0, "{name}: {p}");
    }
    assert!(
        v["identifiability"].to_string().contains("a1.offset"),
        "{}",
        v["identifiability"]
    );
}

#[test]
fn no_diagnose_ols_fits_the_declared_model_only() {
    let mut args = NAIVE.to_vec();
    args.extend(["--no-diagnose", "--method", "ols", "--json"]);
    let v = json(&robcal(&args));
    assert_eq!(v["method"], "ols");
    assert_eq!(v["iterations"], 0);
    assert_eq!(v["effects"].as_array().unwrap().len(), 0);
    let names: Vec<&str> = v["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["k_a2", "k_a3", "k_a4", "k_a5", "k_a6"]);
}

#[test]
fn validate_reports_per_marker_rmse() {
    let mut args = NAIVE.to_vec();
    args.extend(["--validate", "data/kr270/measurements.csv", "--json"]);
    let v = json(&robcal(&args));
    let val = &v["validation"];
    // (KR-270's deflections alone: no frame to re-fit, no
    // `reregistration`.)
    assert_eq!(
        keys(val),
        [
            "as_measured_rms_mm",
            "interpolated_points",
            "per_marker_max_mm",
            "per_marker_mean_mm",
            "per_marker_rms_mm",
            "points",
            "reregistered",
            "rms_mm"
        ]
    );
    assert_eq!(val["reregistered"], false);
    assert_eq!(val["as_measured_rms_mm"], val["rms_mm"]);
    assert_eq!(keys(&val["per_marker_rms_mm"]), ["1", "2", "3"]);
    // The calibration file itself: the validation RMS is the fit's RMS.
    let rms_mm = val["rms_mm"].as_f64().unwrap();
    assert!((rms_mm * 1e3 - v["rms_um"].as_f64().unwrap()).abs() < 1e-6);
}

#[test]
fn human_report_shows_the_errors_before_and_after() {
    let out = robcal(&NAIVE);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("added compensator on a2"), "{text}");
    assert!(text.contains("RMS 261.8 -> 122.6 um"), "{text}");
    assert!(text.contains("held-out RMS"), "{text}");
    assert!(
        text.contains("error per point after calibration: mean 104.5 um, max 342.9 um"),
        "{text}"
    );
    // The nominal error, and what ± means, say themselves.
    assert!(
        text.contains("nominal (before calibration): RMS 6318.3 um"),
        "{text}"
    );
    let head = text
        .lines()
        .find(|l| l.contains("value ± 1 sd"))
        .expect("a labelled table");
    let row = text
        .lines()
        .find(|l| l.starts_with("  k_a2@-0.01") && l.contains('±'))
        .unwrap();
    assert_eq!(head.find('±'), row.find('±'), "aligned:\n{head}\n{row}");
    // t = value / σ, right-aligned under its header.
    let t_end = head.find(" t ").unwrap() + 2;
    let t: f64 = row[..t_end].rsplit(' ').next().unwrap().parse().unwrap();
    let cells: Vec<f64> = row
        .split_whitespace()
        .filter_map(|c| c.parse().ok())
        .collect();
    // (σ is printed to 4 decimals: 0.0006 for 0.000627.)
    assert!((t / (cells[0] / cells[1]) - 1.0).abs() < 0.1, "{row}");
    assert!(t > 100.0, "{row}");
}

/// The names of the files in `dir`, sorted.
fn files_in(dir: &Path) -> Vec<String> {
    let mut files: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    files.sort();
    files
}

#[test]
fn plots_are_svg_and_complete() {
    let dir = temp_dir("plots");
    let mut args = NAIVE.to_vec();
    let d = dir.to_str().unwrap().to_string();
    args.extend(["--plots", &d, "--json"]);
    json(&robcal(&args));
    let files = files_in(&dir);
    assert_eq!(
        files,
        [
            "01_compensator_a2.svg",
            "error_distribution.svg",
            "parameters_urad__N_m.svg",
            "per_pose.svg"
        ]
    );
    for (file, axis) in [
        ("01_compensator_a2.svg", "q_a2 [deg]"),
        ("per_pose.svg", "error per pose, RMS [µm] (log)"),
        ("error_distribution.svg", "error per point, |Δp| [µm] (log)"),
        ("parameters_urad__N_m.svg", "value [urad/(N*m)]"),
    ] {
        let svg = std::fs::read_to_string(dir.join(file)).unwrap();
        assert!(svg.trim_start().starts_with("<svg"), "{}", &svg[..80]);
        assert!(svg.trim_end().ends_with("</svg>"));
        // Units on the axes; the Okabe–Ito palette, no pure red or green.
        assert!(svg.contains(axis), "{file}");
        assert!(
            !svg.contains("#FF0000") && !svg.contains("#00FF00"),
            "{file}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn plots_and_output_are_written_together_or_not_at_all() {
    let dir = temp_dir("together");
    std::fs::create_dir_all(&dir).unwrap();
    let (plots, file) = (dir.join("plots"), dir.join("a-file"));
    std::fs::write(&file, "kept").unwrap();
    let mut args = NAIVE.to_vec();
    let (p, f) = (plots.to_str().unwrap(), file.to_str().unwrap());
    args.extend(["--plots", p, "--output", f]);
    assert_rejected(
        &robcal(&args),
        "a-file: exists and is not a directory",
        &plots,
    );
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "kept");
    // Below a file: refused before the fit too.
    let below = file.join("sub");
    let mut args = NAIVE.to_vec();
    args.extend(["--output", below.to_str().unwrap()]);
    assert_rejected(
        &robcal(&args),
        "a-file exists and is not a directory",
        &plots,
    );
    // One directory for both, named two ways: each figure once, every file
    // there.
    let dotted = dir.join(".").join("plots");
    let mut args = NAIVE.to_vec();
    args.extend(["--plots", p, "--output", dotted.to_str().unwrap(), "--json"]);
    json(&robcal(&args));
    let files = files_in(&plots);
    assert_eq!(files.len(), 7, "{files:?}");
    assert!(files.contains(&"report.html".to_string()), "{files:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

fn assert_rejected(out: &Output, expect: &str, plots: &Path) {
    assert!(!out.status.success());
    assert!(
        out.stdout.is_empty(),
        "stdout: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    let err = String::from_utf8(out.stderr.clone()).unwrap();
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains(expect), "{err}");
    assert!(!plots.exists(), "nothing may be written on error");
}

#[test]
fn bad_input_names_file_line_column_and_writes_nothing() {
    let dir = temp_dir("bad");
    let d = dir.to_str().unwrap().to_string();
    let bad = "host-tests/tests/fixtures/loop/kr270_bad.csv";
    let out = robcal(&[
        "calibrate",
        "--setup",
        "data/kr270/setup-naive.toml",
        "--data",
        bad,
        "--plots",
        &d,
        "--json",
    ]);
    assert_rejected(
        &out,
        "kr270_bad.csv:5: column 'a2': 'abc' is not a number",
        &dir,
    );

    // A bad validation file is rejected before anything runs or is written.
    let out = robcal(&[
        "calibrate",
        "--setup",
        "data/kr270/setup-naive.toml",
        "--data",
        "data/kr270/measurements.csv",
        "--validate",
        bad,
        "--plots",
        &d,
    ]);
    assert_rejected(&out, "kr270_bad.csv:5: column 'a2'", &dir);

    let out = robcal(&[
        "calibrate",
        "--setup",
        "no/such/setup.toml",
        "--data",
        "data/kr270/measurements.csv",
    ]);
    assert_rejected(&out, "no/such/setup.toml", &dir);

    let mut args = NAIVE.to_vec();
    args.extend(["--lambda", "-1"]);
    assert_rejected(&robcal(&args), "--lambda", &dir);
}

#[test]
fn unknown_method_is_a_usage_error() {
    let mut args = NAIVE.to_vec();
    args.extend(["--method", "magic"]);
    let out = robcal(&args);
    assert!(!out.status.success());
    assert!(out.stdout.is_empty());
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("magic"), "{err}");
}

#[test]
fn wls_one_step_also_finds_the_compensator() {
    let mut args = NAIVE.to_vec();
    args.extend([
        "--method",
        "wls",
        "--lambda",
        "1",
        "--max-iter",
        "3",
        "--json",
    ]);
    let v = json(&robcal(&args));
    assert_eq!(v["method"], "wls");
    assert_eq!(v["iterations"], 1);
    let effects = v["effects"].as_array().unwrap();
    assert_eq!(effects.len(), 1, "{effects:?}");
    assert_eq!(effects[0]["effect"], "compensator");
    assert_eq!(effects[0]["joint"], "a2");
}

/// `--output DIR` (data contract 7.4): the calibrated URDF and model.json,
/// all or nothing.
#[test]
fn output_dir_holds_the_calibrated_urdf_and_the_model_all_or_nothing() {
    let dir = std::env::temp_dir().join(format!("robcal-output-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let run = |out: &std::path::Path| {
        std::process::Command::new(env!("CARGO_BIN_EXE_robcal"))
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args([
                "calibrate",
                "--setup",
                "data/kr270/setup.toml",
                "--data",
                "data/kr270/measurements.csv",
                "--no-diagnose",
                "--output",
                out.to_str().unwrap(),
            ])
            .output()
            .expect("run robcal")
    };
    let o = run(&dir);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let urdf = std::fs::read_to_string(dir.join("robot.urdf")).expect("robot.urdf");
    let robot = urdf_rs::read_from_string(&urdf).expect("the calibrated URDF parses");
    for link in ["measurement_frame", "marker_1", "marker_2", "marker_3"] {
        assert!(robot.links.iter().any(|l| l.name == link), "{link}");
    }
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("model.json")).unwrap()).unwrap();
    let n = model["parameters"].as_array().unwrap().len();
    let c = &model["covariance"];
    assert_eq!(c["parameters"].as_array().unwrap().len(), n);
    assert_eq!(c["matrix"].as_array().unwrap().len(), n);
    assert!(c["matrix"][0][0].as_f64().unwrap() > 0.0);

    // A directory where robot.urdf goes: nothing is written.
    let blocked = dir.join("blocked");
    std::fs::create_dir_all(blocked.join("robot.urdf")).unwrap();
    let o = run(&blocked);
    assert_eq!(o.status.code(), Some(1));
    assert!(!blocked.join("model.json").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `-q` leaves stderr empty on success; `-v` times each progress line.
#[test]
fn quiet_and_verbose() {
    let mut args = NAIVE.to_vec();
    args.push("-q");
    let o = robcal(&args);
    assert!(o.status.success());
    assert!(
        o.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let mut args = NAIVE.to_vec();
    args.push("--verbose");
    let o = robcal(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.lines().count() >= 1 && err.lines().all(|l| l.contains(" s] ")),
        "{err}"
    );
}

/// A measurement error in one row is named by the outlier rule
/// (`calibrate::plausibility`): a loaded point of KR-270 moved by 3 mm
/// (the deflections' median residual is ~90 µm, their largest 343 µm),
/// where the clean file gives no such warning.
#[test]
fn a_point_off_by_millimetres_is_named_as_a_likely_measurement_error() {
    let run = |data: &str| {
        json(&robcal(&[
            "calibrate",
            "--setup",
            "data/kr270/setup.toml",
            "--data",
            data,
            "--no-diagnose",
            "--json",
        ]))
    };
    let named = |v: &Value| -> Vec<String> {
        v["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .map(|w| w.as_str().unwrap().to_string())
            .filter(|w| w.contains("times the median row's"))
            .collect()
    };
    assert!(named(&run("data/kr270/measurements.csv")).is_empty());
    let text = std::fs::read_to_string(root().join("data/kr270/measurements.csv")).unwrap();
    let mut moved = 0;
    let lines: Vec<String> = text
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            // config 7, repetition 2, marker 1, loaded: x + 3 mm.
            if f[..3] == ["7", "2", "1"] && f[3] != "0" {
                moved += 1;
                let x: f64 = f[10].parse().unwrap();
                let mut g: Vec<String> = f.iter().map(|s| s.to_string()).collect();
                g[10] = format!("{}", x + 3.0);
                return g.join(",");
            }
            l.to_string()
        })
        .collect();
    assert_eq!(moved, 1);
    let dir = temp_dir("outlier");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("measurements.csv");
    std::fs::write(&file, lines.join("\n") + "\n").unwrap();
    let w = named(&run(file.to_str().unwrap()));
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].starts_with("1 of 270 deflection rows has a residual above 20 times"),
        "{}",
        w[0]
    );
    assert!(w[0].contains(": config 7 marker 1 "), "{}", w[0]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn designs_not_held_give_the_same_report_and_a_bad_value_is_refused() {
    // `ROBCAL_MAX_HELD_DESIGN_ROWS=0`: no design holds its columns (each
    // pass computes them again from the rows); the report is the same
    // bytes. A value that is not a number is a one-line error.
    let mut args = NAIVE.to_vec();
    args.push("--json");
    let run = |value: Option<&str>| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_robcal"));
        c.current_dir(root()).args(&args);
        match value {
            Some(v) => c.env("ROBCAL_MAX_HELD_DESIGN_ROWS", v),
            None => c.env_remove("ROBCAL_MAX_HELD_DESIGN_ROWS"),
        };
        c.output().expect("run robcal")
    };
    let held = run(None);
    let computed = run(Some("0"));
    assert!(held.status.success() && computed.status.success());
    assert_eq!(held.stdout, computed.stdout);
    let bad = run(Some("lots"));
    assert_eq!(bad.status.code(), Some(1));
    let err = String::from_utf8_lossy(&bad.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("ROBCAL_MAX_HELD_DESIGN_ROWS"), "{err}");
    assert!(bad.stdout.is_empty());
}

/// robcal's own `robot.urdf` as the next calibration's nominal robot
/// (issue 59): its measurement frame and markers are placed again, not
/// refused, and the second run changes nothing beyond its σ.
#[test]
fn kr270_recalibrates_from_its_own_output() {
    let d = temp_dir("round-trip");
    std::fs::create_dir_all(&d).unwrap();
    std::fs::copy(root().join("data/kr270/setup.toml"), d.join("setup.toml")).unwrap();
    let urdf = root().join("data/kr270/kr270.urdf");
    let data = root().join("data/kr270/measurements.csv");
    round_trip::assert_round_trip(
        &d,
        round_trip::Trip {
            setup: "setup.toml",
            robot: urdf.to_str().unwrap(),
            args: &["--data", data.to_str().unwrap(), "--no-diagnose"],
            markers_from_first: false,
            origin_tolerance: 1e-9,
        },
    );
    let _ = std::fs::remove_dir_all(&d);
}
