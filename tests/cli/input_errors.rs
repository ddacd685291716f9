//! The input errors a calibration engineer makes, through `robcal calibrate`
//! (issue 8): each one is either rejected with a one-line message naming the
//! file, line and column, or accepted with a `robcal: warning:` on stderr
//! when the numbers only look suspicious (wrong units). Built from the
//! KR-270 job (`data/kr270`), each case changing one thing.

use crate::common::Scratch;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

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

/// A fresh directory with a copy of the KR-270 setup (its `[units]` and
/// `[model]` replaced by `units`/`model` when given, robot path absolute).
fn job(name: &str, units: Option<&str>, model: Option<&str>) -> (Scratch, PathBuf) {
    let dir = Scratch::new(&format!("robcal-input-{name}"));
    let text = std::fs::read_to_string(root().join("data/kr270/setup.toml")).unwrap();
    let urdf = root().join("data/kr270/kr270.urdf");
    let mut text = text.replace(
        "robot = \"kr270.urdf\"",
        &format!("robot = {:?}", urdf.to_str().unwrap()),
    );
    if let Some(u) = units {
        text = text.replace("angle = \"deg\"\nlength = \"mm\"", u);
    }
    if let Some(m) = model {
        let at = text.find("[model]").unwrap();
        text = format!("{}{m}", &text[..at]);
    }
    let setup = dir.join("setup.toml");
    std::fs::write(&setup, text).unwrap();
    (dir, setup)
}

/// The KR-270 measurements, each data row passed through `edit(line, cells)`
/// (line 1-based as in the file; returning `None` drops the row).
fn csv(dir: &Path, edit: impl Fn(usize, Vec<String>) -> Option<Vec<String>>) -> PathBuf {
    let text = std::fs::read_to_string(root().join("data/kr270/measurements.csv")).unwrap();
    let mut lines = text.lines();
    let mut out = String::from(lines.next().unwrap());
    out.push('\n');
    for (i, l) in lines.enumerate() {
        let cells: Vec<String> = l.split(',').map(str::to_owned).collect();
        if let Some(c) = edit(i + 2, cells) {
            out.push_str(&c.join(","));
            out.push('\n');
        }
    }
    let path = dir.join("data.csv");
    std::fs::write(&path, out).unwrap();
    path
}

fn run(setup: &Path, data: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "calibrate",
        "--setup",
        setup.to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
    ];
    args.extend(extra);
    robcal(&args)
}

fn rejected(out: &Output) -> String {
    let err = String::from_utf8(out.stderr.clone()).unwrap();
    assert!(!out.status.success(), "accepted: {err}");
    assert!(out.stdout.is_empty());
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.starts_with("robcal: error: "), "{err}");
    err
}

const COL_X: usize = 10;

#[test]
fn degrees_read_as_radians_is_an_error_naming_the_cell() {
    let (dir, setup) = job("deg-as-rad", Some("angle = \"rad\"\nlength = \"mm\""), None);
    let data = csv(&dir, |_, c| Some(c));
    let err = rejected(&run(&setup, &data, &[]));
    assert!(
        err.contains("data.csv:2: column 'a1': 79.2 rad is beyond ±2π")
            && err.contains("is the column in degrees?"),
        "{err}"
    );
}

#[test]
fn radians_read_as_degrees_warns_on_stderr() {
    let (dir, setup) = job("rad-as-deg", None, None);
    let data = csv(&dir, |_, mut c| {
        for v in &mut c[4..10] {
            *v = format!("{}", v.parse::<f64>().unwrap().to_radians());
        }
        Some(c)
    });
    let out = run(&setup, &data, &["--no-diagnose", "--json"]);
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(
        err.lines().any(|l| l.starts_with("robcal: warning: ")
            && l.contains("data.csv: every revolute joint value is within ±π")
            && l.contains("are the joint columns in radians?")),
        "{err}"
    );
}

#[test]
fn millimetres_read_as_metres_is_an_error_naming_the_cell() {
    let (dir, setup) = job("mm-as-m", Some("angle = \"deg\"\nlength = \"m\""), None);
    let data = csv(&dir, |_, c| Some(c));
    let err = rejected(&run(&setup, &data, &[]));
    assert!(
        err.contains("data.csv:2: column 'x': ") && err.contains("is the column in millimetres?"),
        "{err}"
    );
}

#[test]
fn metres_read_as_millimetres_warns_on_stderr() {
    let (dir, setup) = job("m-as-mm", None, None);
    let data = csv(&dir, |_, mut c| {
        for v in &mut c[COL_X..COL_X + 3] {
            *v = format!("{}", v.parse::<f64>().unwrap() / 1000.0);
        }
        Some(c)
    });
    let out = run(&setup, &data, &["--no-diagnose", "--json"]);
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(
        err.lines().any(|l| l.starts_with("robcal: warning: ")
            && l.contains("every x, y, z is within ±10")
            && l.contains("are the positions in metres?")),
        "{err}"
    );
}

#[test]
fn unknown_joint_column_lists_the_chain_joints() {
    let (dir, setup) = job("unknown-joint", None, None);
    let data = csv(&dir, |_, c| Some(c));
    let text = std::fs::read_to_string(&data)
        .unwrap()
        .replacen("a3", "A3", 1);
    std::fs::write(&data, text).unwrap();
    let err = rejected(&run(&setup, &data, &[]));
    assert!(
        err.contains("data.csv:1: column 'A3': neither a fixed column nor a movable joint")
            && err.contains("(joints: a1, a2, a3, a4, a5, a6)"),
        "{err}"
    );
}

#[test]
fn unknown_marker_names_line_and_column() {
    let (dir, setup) = job("unknown-marker", None, None);
    let data = csv(&dir, |line, mut c| {
        if line == 7 {
            c[2] = "4".into();
        }
        Some(c)
    });
    let err = rejected(&run(&setup, &data, &[]));
    assert!(
        err.contains("data.csv:7: column 'marker': marker 4 is not declared in the setup"),
        "{err}"
    );
}

#[test]
fn unpaired_loaded_row_names_its_line() {
    let (dir, setup) = job("unpaired", None, None);
    // Line 2 is the unloaded row of line 3.
    let data = csv(&dir, |line, c| (line != 2).then_some(c));
    let err = rejected(&run(&setup, &data, &[]));
    assert!(
        err.contains("data.csv:2: column 'load_kg': loaded row (config 1, rep 1, marker 1) has no unloaded row"),
        "{err}"
    );
}

#[test]
fn non_finite_value_names_line_and_column() {
    for bad in ["nan", "inf", "-Infinity", "1e999"] {
        let (dir, setup) = job("non-finite", None, None);
        let data = csv(&dir, |line, mut c| {
            if line == 5 {
                c[COL_X + 1] = bad.into();
            }
            Some(c)
        });
        let err = rejected(&run(&setup, &data, &[]));
        assert!(
            err.contains(&format!("data.csv:5: column 'y': non-finite value '{bad}'")),
            "{err}"
        );
    }
}

#[test]
fn too_few_configurations_for_the_declared_model() {
    // One configuration seen by one marker: 3 equations per repetition, so
    // at most 3 of the 5 declared compliances can be identified. This used
    // to succeed with k_a5 and k_a6 silently missing from the JSON.
    let (dir, setup) = job("few-configs", None, None);
    let data = csv(&dir, |_, c| (c[0] == "1" && c[2] == "1").then_some(c));
    let err = rejected(&run(&setup, &data, &["--json"]));
    assert!(
        err.contains("data.csv: too few configurations for the declared model: k_a5, k_a6 cannot be identified from 1 configuration(s)"),
        "{err}"
    );
    assert!(err.contains("measure more configurations"), "{err}");
}

#[test]
fn two_configurations_are_enough_for_the_paper_model() {
    // Two configurations seen by three markers identify the paper's model
    // (five compliances here: both configurations have a2 at -0.01 deg, so
    // a2's split has one bin); the fit runs, and the held-out RMS shows how
    // badly two configurations predict.
    let (dir, setup) = job("two-configs", None, None);
    let data = csv(&dir, |_, c| {
        (c[0].parse::<i64>().unwrap() <= 2).then_some(c)
    });
    let out = run(&setup, &data, &["--json", "--no-diagnose"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

// Plausibility (issue 13, `robcal::calibrate::report::plausibility`): each wrong
// answer that once left with exit 0 is an error or a reported warning.

/// A run that failed after the calibration began: progress lines, then
/// the one error line last; nothing on stdout.
fn failed(out: &Output) -> String {
    let err = String::from_utf8(out.stderr.clone()).unwrap();
    assert!(!out.status.success(), "accepted: {err}");
    assert!(out.stdout.is_empty());
    let last = err.lines().last().unwrap_or_default().to_owned();
    assert!(last.starts_with("robcal: error: "), "{err}");
    last
}

/// The KR-270 data as shipped.
fn shipped(dir: &Path) -> PathBuf {
    csv(dir, |_, c| Some(c))
}

fn json(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn a_compliance_without_loaded_rows_is_an_error_naming_it() {
    let (dir, setup) = job("no-load", None, None);
    let data = csv(&dir, |_, c| (c[3] == "0").then_some(c));
    let err = rejected(&run(&setup, &data, &["--no-diagnose"]));
    assert!(
        err.contains("k_a6 declared, but no row puts a torque"),
        "{err}"
    );
}

#[test]
fn a_load_centre_of_mass_on_a_joint_axis_is_an_error_naming_the_compliance() {
    let (dir, setup) = job("com-on-axis", None, None);
    let text = std::fs::read_to_string(&setup).unwrap();
    std::fs::write(
        &setup,
        text.replace("com = [0.25, 0.0, 0.30]", "com = [0.0, 0.0, 0.30]"),
    )
    .unwrap();
    let err = rejected(&run(&setup, &shipped(&dir), &["--no-diagnose"]));
    assert!(
        err.contains("k_a6 declared, but no row puts a torque"),
        "{err}"
    );
}

#[test]
fn a_negative_compliance_beyond_three_sigma_is_an_error() {
    // The centre of mass on the wrong side of the flange: k_a6 comes out
    // −2.4 ± 0.07 µrad/(N·m) (once reported with exit 0).
    let (dir, setup) = job("negative", None, None);
    let text = std::fs::read_to_string(&setup).unwrap();
    std::fs::write(
        &setup,
        text.replace("com = [0.25, 0.0, 0.30]", "com = [-0.25, 0.0, 0.30]"),
    )
    .unwrap();
    let err = failed(&run(&setup, &shipped(&dir), &["--no-diagnose"]));
    assert!(
        err.contains("k_a6 = -") && err.contains("is negative by") && err.contains("[load] com"),
        "{err}"
    );
}

#[test]
fn one_joint_column_in_radians_is_an_error_naming_the_column() {
    let (dir, setup) = job("a3-rad", None, None);
    let data = csv(&dir, |_, mut c| {
        c[6] = format!("{}", c[6].parse::<f64>().unwrap().to_radians());
        Some(c)
    });
    let err = rejected(&run(&setup, &data, &[]));
    assert!(
        err.contains("column 'a3': its values fit rad far better"),
        "{err}"
    );
}

#[test]
fn positions_in_centimetres_are_an_error() {
    let (dir, setup) = job("cm", None, None);
    let data = csv(&dir, |_, mut c| {
        for v in &mut c[COL_X..COL_X + 3] {
            *v = format!("{}", v.parse::<f64>().unwrap() / 10.0);
        }
        Some(c)
    });
    let err = rejected(&run(&setup, &data, &[]));
    assert!(
        err.contains("spread 0.100 times as far") && err.contains("another unit"),
        "{err}"
    );
}

#[test]
fn validation_with_no_point_is_an_error() {
    let (dir, setup) = job("validate-none", None, None);
    let data = shipped(&dir);
    let unloaded = dir.join("unloaded.csv");
    let text = std::fs::read_to_string(&data).unwrap();
    let keep: Vec<&str> = text
        .lines()
        .enumerate()
        .filter(|(i, l)| *i == 0 || l.split(',').nth(3) == Some("0"))
        .map(|(_, l)| l)
        .collect();
    std::fs::write(&unloaded, keep.join("\n") + "\n").unwrap();
    let unloaded = unloaded.to_str().unwrap();
    let err = failed(&run(
        &setup,
        &data,
        &["--no-diagnose", "--validate", unloaded],
    ));
    assert!(
        err.contains("unloaded.csv: no point to validate on"),
        "{err}"
    );
}

#[test]
fn validation_reports_points_mean_and_max() {
    let (dir, setup) = job("validate-keys", None, None);
    let data = shipped(&dir);
    let v = json(&run(
        &setup,
        &data,
        &[
            "--no-diagnose",
            "--json",
            "--validate",
            data.to_str().unwrap(),
        ],
    ));
    let val = &v["validation"];
    assert_eq!(val["points"], 270);
    for m in ["1", "2", "3"] {
        let (mean, max, rms) = (
            val["per_marker_mean_mm"][m].as_f64().unwrap(),
            val["per_marker_max_mm"][m].as_f64().unwrap(),
            val["per_marker_rms_mm"][m].as_f64().unwrap(),
        );
        assert!(
            0.0 < mean && mean <= rms && rms <= max,
            "{mean} {rms} {max}"
        );
    }
}

/// A fit that did not converge is not a calibration (issue 58): its report
/// is written, marked (`failure`), and the run exits 1, unless the user
/// accepts it (`--accept-unconverged`: exit 0, the same report).
#[test]
fn a_fit_stopped_at_max_iter_says_so() {
    let (dir, setup) = job("max-iter", None, None);
    let data = shipped(&dir);
    let args = ["--no-diagnose", "--json", "--max-iter", "1"];
    let refused = run(&setup, &data, &args);
    assert_eq!(refused.status.code(), Some(1));
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(err.contains("not a calibration"), "{err}");
    let marked: serde_json::Value = serde_json::from_slice(&refused.stdout).unwrap();
    assert!(
        (marked["failure"].as_str()).is_some_and(|f| f.contains("did not converge")),
        "{marked}"
    );
    let mut accepting = args.to_vec();
    accepting.push("--accept-unconverged");
    let v = json(&run(&setup, &data, &accepting));
    assert_eq!(v, marked);
    assert_eq!(v["converged"], false);
    let w = v["warnings"].as_array().unwrap();
    assert!(
        w.iter()
            .any(|w| w.as_str().unwrap().contains("did not converge")),
        "{w:?}"
    );
    let v = json(&run(&setup, &data, &["--no-diagnose", "--json"]));
    assert_eq!(v["converged"], true);
    assert_eq!(v["warnings"], serde_json::json!([]));
    assert!(v.get("failure").is_none(), "{v}");
}

#[test]
fn absurd_numbers_name_the_value_and_where() {
    let (dir, setup) = job("absurd-load", None, None);
    let data = csv(&dir, |line, mut c| {
        if line == 3 {
            c[3] = "1e308".into();
        }
        Some(c)
    });
    let err = rejected(&run(&setup, &data, &[]));
    assert!(
        err.contains("data.csv:3: column 'load_kg': load 1e308 kg is more than"),
        "{err}"
    );
    let data = csv(&dir, |line, mut c| {
        if line == 2 {
            c[COL_X] = "1e300".into();
        }
        Some(c)
    });
    let err = rejected(&run(&setup, &data, &[]));
    assert!(
        err.contains("data.csv:2: column 'x': 1e297 m is more than"),
        "{err}"
    );
    let text = std::fs::read_to_string(&setup).unwrap();
    for (from, to, says) in [
        (
            "gravity = [0.0, 0.0, -9.80665]",
            "gravity = [0.0, 0.0, 0.0]",
            "setup.toml: load.gravity: [0.0, 0.0, 0.0] m/s² has norm 0",
        ),
        (
            "xyz = [0.0, 0.30, 0.20]",
            "xyz = [1e300, 0.30, 0.20]",
            "setup.toml: marker[0].xyz: [1e300, 0.3, 0.2] m is more than 100 m",
        ),
    ] {
        std::fs::write(&setup, text.replace(from, to)).unwrap();
        let err = rejected(&run(&setup, &shipped(&dir), &[]));
        assert!(err.contains(says), "{err}");
    }
}

#[test]
fn a_missing_or_bad_argument_is_a_usage_error_named_on_its_one_line() {
    for (args, expect) in [
        (
            &["calibrate", "--setup", "s.toml"][..],
            "not provided: --data <DATA>",
        ),
        (
            &[][..],
            "a command is needed: calibrate, import, predict, compensate, check, compare, plan, init",
        ),
        (&["import"][..], "a command is needed: figaroh-mocap, poses"),
        (
            &["calibrate", "--setup", "s", "--data", "d", "--lambda", "-1"][..],
            "'--lambda <LAMBDA>': must be a finite number >= 0",
        ),
        (
            &[
                "calibrate",
                "--setup",
                "s",
                "--data",
                "d",
                "--max-iter",
                "0",
            ][..],
            "must be a whole number from 1 to",
        ),
        (
            &[
                "compensate",
                "--model",
                "m",
                "--targets",
                "t",
                "--tolerance-um",
                "nan",
            ][..],
            "must be a finite number > 0",
        ),
    ] {
        let out = robcal(args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.starts_with("robcal: ") && err.contains(expect), "{err}");
    }
}

#[test]
fn a_load_on_the_joint_axis_is_named_as_such_not_as_no_load() {
    let (dir, setup) = job("axis-load", None, None);
    let text = std::fs::read_to_string(&setup).unwrap();
    std::fs::write(&setup, text.replace("com = [0.25, 0.0, 0.30]\n", "")).unwrap();
    let data = csv(&dir, |_, cells| Some(cells));
    let err = rejected(&run(&setup, &data, &[]));
    assert!(
        err.contains("k_a6 declared, but no row puts a torque")
            && err.contains(
                "loaded rows, but their load acts through the joint's axis: check [load] com"
            ),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn several_loads_against_one_unloaded_point_are_warned_about() {
    let (dir, setup) = job("shared-unloaded", None, None);
    // Every loaded row once more at half the load (positions kept: the
    // warning is about the pairing, not the values).
    let text = std::fs::read_to_string(root().join("data/kr270/measurements.csv")).unwrap();
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        out.push_str(line);
        out.push('\n');
        let cells: Vec<&str> = line.split(',').collect();
        if i > 0 && cells[3] != "0" {
            let half = cells[3].parse::<f64>().unwrap() / 2.0;
            let mut copy: Vec<String> = cells.iter().map(|c| c.to_string()).collect();
            copy[3] = half.to_string();
            out.push_str(&copy.join(","));
            out.push('\n');
        }
    }
    let data = dir.join("data.csv");
    std::fs::write(&data, out).unwrap();
    let run = run(
        &setup,
        &data,
        &["--no-diagnose", "--json", "--method", "ols"],
    );
    let err = String::from_utf8(run.stderr).unwrap();
    assert!(
        err.lines().any(|l| l.starts_with("robcal: warning: ")
            && l.contains("data.csv:2: 270 unloaded row(s) are each the reference of several loaded rows (first: line 2, for lines 3 and 4)")
            && l.contains("sigma of the compliances are understated")),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
