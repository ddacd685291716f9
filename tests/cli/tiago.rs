//! `robcal import figaroh-mocap` and `robcal calibrate --validate` on the
//! TIAGo motion-capture recordings of `shared/datasets/tiago-mocap` (issue 7,
//! docs/tiago.md): the command of the issue runs and reports
//! `validation.per_marker_rms_mm` with marker 1 = point BL.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

use crate::round_trip;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `shared/datasets/tiago-mocap` beside the repository (CI), else in the
/// nearest ancestor that has it (a nested git worktree).
fn data_dir() -> PathBuf {
    find_data().expect("shared/datasets/tiago-mocap beside the repository")
}

fn find_data() -> Option<PathBuf> {
    root()
        .ancestors()
        .skip(1)
        .map(|a| a.join("shared/datasets/tiago-mocap"))
        .find(|d| d.join("tiago_48_schunk.urdf").exists())
}

/// Whether `test` is skipped: the data are not there (a plain clone; it
/// says so on stderr). With `ROBCAL_REQUIRE_SHARED=1` (CI) that is a
/// failure instead.
fn skip(test: &str) -> bool {
    if find_data().is_some() {
        return false;
    }
    let what = "shared/datasets/tiago-mocap";
    if std::env::var_os("ROBCAL_REQUIRE_SHARED").is_some_and(|v| v == "1") {
        panic!("{what} not found, and ROBCAL_REQUIRE_SHARED=1 (CI) requires it");
    }
    skipped_note(&format!(
        "skipped {test}: {what} not found beside the repository (CI has it)"
    ));
    true
}

fn robcal(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_robcal"))
        .current_dir(root())
        .args(args)
        .output()
        .expect("run robcal")
}

fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "robcal failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `data/tiago/setup.toml` itself when `shared/` is beside the repository;
/// else a copy naming the URDF found by [`data_dir`].
fn setup(dir: &Path) -> PathBuf {
    setup_named(dir, "setup.toml")
}

/// [`setup`] for another setup file of `data/tiago`.
fn setup_named(dir: &Path, name: &str) -> PathBuf {
    let shipped = root().join("data/tiago").join(name);
    if root().join("../shared/datasets/tiago-mocap").exists() {
        return shipped;
    }
    let text = std::fs::read_to_string(&shipped).unwrap();
    let urdf = data_dir().join("tiago_48_schunk.urdf");
    let text = text.replace(
        "../../../shared/datasets/tiago-mocap/tiago_48_schunk.urdf",
        &urdf.to_string_lossy(),
    );
    let copy = dir.join(name);
    std::fs::write(&copy, text).unwrap();
    copy
}

/// `robcal import figaroh-mocap` of the recording of `day` into
/// `dir/<day>.csv`.
fn import(dir: &Path, day: &str) -> PathBuf {
    let input = data_dir().join(format!("qualisys_{day}_static_postures.csv"));
    let out = dir.join(format!("{day}.csv"));
    ok(&robcal(&[
        "import",
        "figaroh-mocap",
        input.to_str().unwrap(),
        out.to_str().unwrap(),
    ]));
    out
}

#[test]
fn import_then_calibrate_with_validation() {
    if skip("import_then_calibrate_with_validation") {
        return;
    }
    let dir = std::env::temp_dir().join(format!("robcal-cli-tiago-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (train, held) = (import(&dir, "2021-11-30"), import(&dir, "2021-11-26"));
    for (out, postures) in [(&train, 37), (&held, 62)] {
        let text = std::fs::read_to_string(out).unwrap();
        assert_eq!(text.lines().count(), 1 + 4 * postures);
    }
    // A missing input: one line on stderr, non-zero exit, nothing written.
    let missing = dir.join("missing.csv");
    let o = robcal(&[
        "import",
        "figaroh-mocap",
        missing.to_str().unwrap(),
        dir.join("never.csv").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert_eq!(String::from_utf8_lossy(&o.stderr).lines().count(), 1);
    assert!(!dir.join("never.csv").exists());

    let setup = setup(&dir);
    let o = robcal(&[
        "calibrate",
        "--setup",
        setup.to_str().unwrap(),
        "--data",
        train.to_str().unwrap(),
        "--validate",
        held.to_str().unwrap(),
        "--json",
    ]);
    ok(&o);
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    let per = &v["validation"]["per_marker_rms_mm"];
    let bl = per["1"]
        .as_f64()
        .expect("marker 1 (BL) in per_marker_rms_mm");
    for k in ["2", "3", "4"] {
        assert!(per[k].as_f64().is_some(), "marker {k}");
    }
    // The CLI's declared model (full geometry, four points, IRLS) plus what
    // its diagnosis adds: 3.51 mm on BL when written (docs/tiago.md); a
    // threshold with room for changes to the loop's defaults, well below
    // the registration-only 4.9 mm.
    assert!(bl < 4.0, "BL validation {bl} mm");
    let _ = std::fs::remove_dir_all(&dir);
}

/// One point per posture (marker 1 only): no configuration has two rows to
/// estimate its σ from, so IRLS falls back to OLS and the report says so.
#[test]
fn one_marker_per_configuration_falls_back_to_ols() {
    if skip("one_marker_per_configuration_falls_back_to_ols") {
        return;
    }
    let dir = std::env::temp_dir().join(format!("robcal-cli-tiago-ols-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let all = import(&dir, "2021-11-30");
    let text = std::fs::read_to_string(&all).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let col = header.split(',').position(|c| c == "marker").unwrap();
    let mut one = format!("{header}\n");
    for l in lines.filter(|l| l.split(',').nth(col) == Some("1")) {
        one.push_str(l);
        one.push('\n');
    }
    let bl = dir.join("bl.csv");
    std::fs::write(&bl, one).unwrap();
    let setup = setup(&dir);
    let o = robcal(&[
        "calibrate",
        "--setup",
        setup.to_str().unwrap(),
        "--data",
        bl.to_str().unwrap(),
        "--no-diagnose",
        "--json",
    ]);
    ok(&o);
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["method"], "ols");
    let notes = v["notes"].as_array().expect("notes");
    assert!(notes[0].as_str().unwrap().contains("OLS"), "{notes:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `geometry = "select"` (data/tiago/setup-select.toml): the declared model
/// is the registration only (base frame, the four points); the joint
/// geometry is left to the loop's candidates.
#[test]
fn select_declares_the_registration_only() {
    if skip("select_declares_the_registration_only") {
        return;
    }
    let dir = std::env::temp_dir().join(format!("robcal-cli-tiago-sel-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let train = import(&dir, "2021-11-30");
    let setup = setup_named(&dir, "setup-select.toml");
    let o = robcal(&[
        "calibrate",
        "--setup",
        setup.to_str().unwrap(),
        "--data",
        train.to_str().unwrap(),
        "--no-diagnose",
        "--json",
    ]);
    ok(&o);
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    let names: Vec<&str> = v["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert!(!names.is_empty());
    assert!(
        names
            .iter()
            .all(|n| n.starts_with("base.") || n.starts_with("marker")),
        "{names:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// robcal's own `robot.urdf` of TIAGo (`geometry = "full"`) as the next
/// calibration's nominal robot (issue 59). The calibrated axes turn the
/// nominal robot's exact dependencies into near ones: the second run must
/// keep the set the first one kept, not a near-null one (σ of 300 m and no
/// convergence before the independence test met its criterion as stated,
/// `robcal::estimate::rank`).
///
/// From the setup's nominal markers (14 mm from the calibrated ones) the
/// second fit ends elsewhere in a valley where the fit is flat to 1e-10 of
/// its RMS: joint origins differ by up to 1.6e-7 m (1.3e-4 σ), whatever
/// Gauss–Newton's step tolerance (1e-6 or 1e-10 mm: the same 1.74e-8 m of
/// the base). Started at the first run's markers, it ends where the first
/// did, to 1e-9 m.
#[test]
fn tiago_recalibrates_from_its_own_output() {
    if skip("tiago_recalibrates_from_its_own_output") {
        return;
    }
    let dir = std::env::temp_dir().join(format!("robcal-cli-tiago-rt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let train = import(&dir, "2021-11-30");
    std::fs::copy(root().join("data/tiago/setup.toml"), dir.join("setup.toml")).unwrap();
    let urdf = data_dir().join("tiago_48_schunk.urdf");
    let args = ["--data", train.to_str().unwrap(), "--no-diagnose"];
    for (markers_from_first, origin_tolerance) in [(false, 1e-6), (true, 1e-9)] {
        round_trip::assert_round_trip(
            &dir,
            round_trip::Trip {
                setup: "setup.toml",
                robot: urdf.to_str().unwrap(),
                args: &args,
                markers_from_first,
                origin_tolerance,
            },
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Estimates within 2 σ of 0 (issue 59) are flagged wherever the
/// parameters are: `determined: false` in the JSON, `*` in the text
/// table (with its footnote), "within 2σ of 0" in the page's table; and
/// named in one warning.
#[test]
fn undetermined_estimates_are_flagged_in_every_output() {
    if skip("undetermined_estimates_are_flagged_in_every_output") {
        return;
    }
    let dir = std::env::temp_dir().join(format!("robcal-cli-tiago-flag-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let train = import(&dir, "2021-11-30");
    let setup = setup_named(&dir, "setup-select.toml");
    let out = dir.join("out");
    let args = |json: bool| {
        let mut a = vec![
            "calibrate".to_string(),
            "-q".into(),
            "--setup".into(),
            setup.to_string_lossy().into_owned(),
            "--data".into(),
            train.to_string_lossy().into_owned(),
            "--method".into(),
            "ols".into(),
        ];
        if json {
            a.extend([
                "--json".into(),
                "--output".into(),
                out.to_string_lossy().into_owned(),
            ]);
        }
        a
    };
    let o = robcal(&args(true).iter().map(String::as_str).collect::<Vec<_>>());
    ok(&o);
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    let flagged: Vec<&str> = v["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["determined"] == false)
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert!(!flagged.is_empty());
    let text = robcal(&args(false).iter().map(String::as_str).collect::<Vec<_>>());
    ok(&text);
    let text = String::from_utf8_lossy(&text.stdout);
    for name in &flagged {
        let line = text
            .lines()
            .rfind(|l| l.trim_start().starts_with(&format!("{name} ")) && l.contains(" ± "))
            .unwrap_or_else(|| panic!("{name} not in the table"));
        assert!(line.contains("* "), "{line}");
    }
    assert!(text.contains("* within 2 sd of 0"), "{text}");
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert_eq!(
        page.matches("<td>within 2σ of 0</td>").count(),
        flagged.len()
    );
    let named = warnings(&v)
        .iter()
        .filter(|w| w.contains("within 2 sigma of 0"))
        .map(|w| {
            flagged
                .iter()
                .filter(|n| w.contains(&format!("{n} = ")))
                .count()
        })
        .sum::<usize>();
    assert_eq!(named, flagged.len(), "{:?}", warnings(&v));
    let _ = std::fs::remove_dir_all(&dir);
}

/// The report's `warnings`.
fn warnings(v: &Value) -> Vec<&str> {
    v["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(Value::as_str)
        .collect()
}

/// `calibrate --method ols --json` of `setup` on `data` (and `--validate`).
fn calibrate_ols(setup: &Path, data: &Path, validate: Option<&Path>) -> Value {
    let mut args = vec![
        "calibrate",
        "--setup",
        setup.to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
        "--method",
        "ols",
        "--json",
    ];
    if let Some(v) = validate {
        args.extend(["--validate", v.to_str().unwrap()]);
    }
    let o = robcal(&args);
    ok(&o);
    serde_json::from_slice(&o.stdout).unwrap()
}

fn effects(v: &Value) -> Vec<String> {
    v["effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            format!(
                "{} {}",
                e["effect"].as_str().unwrap(),
                e["joint"].as_str().unwrap_or("")
            )
        })
        .collect()
}

/// The protocol of docs/tiago.md ("The CLI, second session"), fixed on the
/// training data and committed before its one validation run; these pins
/// are that run's numbers (deterministic: OLS, no random input), so a change
/// of the loop shows here and must be explained there.
///
/// - Registration only (base + four points, Gauss–Newton): 4.09 mm on
///   training, the number of the independent core implementation
///   (`host-tests/tests/tiago_common`, docs/tiago.md's table).
/// - The chosen model (lowest training leave-one-out RMS:
///   `setup-select.toml`, OLS; the IRLS runs' 3.38 and 3.75 mm are pinned in
///   the docs only, they take a minute each in the test profile) predicts
///   the other day's BL at 3.31 mm: better than registration (4.87) and
///   offsets (4.23), not better than FIGAROH's full model (3.07).
/// - Days swapped (fit and choose on 2021-11-26): BL 2.37 mm on 2021-11-30.
/// - Rerun with the exact deflection model (issue 13; docs/tiago.md): the
///   same choice and effects, leave-one-out 2.352 / 2.597 mm (were 2.349 /
///   2.501 with eq. 3), BL 3.310 mm; days swapped 2.413 mm.
/// - Rerun with the links' bending under the robot's own weight (issue
///   56; docs/tiago.md): the same choice, leave-one-out 2.218 / 2.343 mm,
///   BL 3.017 mm (FIGAROH's full model: 3.07); days swapped, of the OLS
///   runs `setup.toml`'s is chosen now, BL 2.161 mm.
#[test]
fn protocol_pins_the_validation_run() {
    if skip("protocol_pins_the_validation_run") {
        return;
    }
    let dir = std::env::temp_dir().join(format!("robcal-cli-tiago-proto-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (d30, d26) = (import(&dir, "2021-11-30"), import(&dir, "2021-11-26"));
    let select = setup_named(&dir, "setup-select.toml");
    let full = setup(&dir);
    let near = |a: f64, b: f64| (a - b).abs() < 0.005;

    let o = robcal(&[
        "calibrate",
        "--setup",
        select.to_str().unwrap(),
        "--data",
        d30.to_str().unwrap(),
        "--method",
        "ols",
        "--no-diagnose",
        "--json",
    ]);
    ok(&o);
    let reg: Value = serde_json::from_slice(&o.stdout).unwrap();
    let reg_mm = reg["rms_um"].as_f64().unwrap() / 1e3;
    assert!(near(reg_mm, 4.09), "registration {reg_mm} mm");

    // Choice on training: select-OLS has the lower leave-one-out RMS.
    let chosen = calibrate_ols(&select, &d30, Some(&d26));
    let other = calibrate_ols(&full, &d30, None);
    let loo = |v: &Value| v["heldout_rms_um"].as_f64().unwrap() / 1e3;
    // 2.352 / 2.383 before the links' bending under the robot's own
    // weight (issue 56; docs/tiago.md).
    assert!(near(loo(&chosen), 2.218), "{}", loo(&chosen));
    assert!(near(loo(&other), 2.343), "{}", loo(&other));
    assert!(loo(&chosen) < loo(&other));
    // The estimates within 2 σ of 0 are said, in one warning, by the rule
    // of `plausibility::determined`.
    let warned = warnings(&chosen);
    assert_eq!(warned.len(), 1, "{warned:?}");
    assert!(
        warned[0].starts_with("4 estimates are within 2 sigma of 0")
            && warned[0].contains("arm_6_joint.tz = -1.2222 ± 0.6514 mm"),
        "{warned:?}"
    );
    let flagged = chosen["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["determined"] == false)
        .count();
    assert_eq!(flagged, 4);
    assert_eq!(
        effects(&chosen),
        [
            "geometry arm_6_joint",
            "joint_compliance arm_6_joint",
            "link_compliance arm_1_joint",
            "geometry arm_1_joint",
            "gear_cyclic arm_1_joint"
        ]
    );
    let bl = chosen["validation"]["per_marker_rms_mm"]["1"]
        .as_f64()
        .unwrap();
    assert!(near(bl, 3.017), "BL validation {bl} mm");
    assert!(bl < 3.07, "better than FIGAROH's full model");

    // Days swapped: of the OLS runs, `setup.toml`'s has the lower
    // leave-one-out RMS (the protocol's choice over all four runs is
    // `setup.toml` with IRLS, 2.278 mm, BL 2.207 mm: docs/tiago.md; IRLS
    // takes a minute here).
    let rev = calibrate_ols(&select, &d26, Some(&d30));
    let rev_other = calibrate_ols(&full, &d26, Some(&d30));
    assert!(near(loo(&rev), 2.436), "{}", loo(&rev));
    assert!(near(loo(&rev_other), 2.383), "{}", loo(&rev_other));
    let bl = |v: &Value| v["validation"]["per_marker_rms_mm"]["1"].as_f64().unwrap();
    assert!(
        near(bl(&rev), 2.341),
        "BL validation, days swapped: {} mm",
        bl(&rev)
    );
    assert!(
        near(bl(&rev_other), 2.161),
        "BL validation, days swapped: {} mm",
        bl(&rev_other)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Says on the real stderr (libtest captures `eprintln!` of a passing
/// test, a direct write shows in `cargo test`'s output) why a test is
/// skipped.
fn skipped_note(why: &str) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr(), "{why}");
}
