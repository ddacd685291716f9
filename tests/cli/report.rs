//! `DIR/report.html` of `robcal calibrate --output DIR` (issue 19): one
//! self-contained page whose numbers are the JSON's, with every section
//! the engineer reads and a figure per plot. (CI's `.ci/report.sh` renders
//! it in headless Chromium.)

use std::path::PathBuf;
use std::process::Command;

use serde_json::Value;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Runs the naive KR-270 job (validated on its own file) with `--output`
/// and `--json`; returns the page, the JSON and the directory.
fn run(name: &str) -> (String, Value, PathBuf) {
    let dir = std::env::temp_dir().join(format!("robcal-report-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let out = Command::new(env!("CARGO_BIN_EXE_robcal"))
        .current_dir(root())
        .args([
            "calibrate",
            "--setup",
            "data/kr270/setup-naive.toml",
            "--data",
            "data/kr270/measurements.csv",
            "--validate",
            "data/kr270/measurements.csv",
            "--json",
            "-q",
            "--output",
        ])
        .arg(&dir)
        .output()
        .expect("run robcal");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let page = std::fs::read_to_string(dir.join("report.html")).expect("report.html");
    (page, v, dir)
}

#[test]
fn the_page_has_every_section_and_the_json_numbers() {
    let (page, v, dir) = run("sections");
    assert!(page.starts_with("<!DOCTYPE html>"));
    assert!(page.trim_end().ends_with("</html>"));
    for id in [
        "job",
        "summary",
        "loop",
        "parameters",
        "correlations",
        "identifiability",
        "validation",
        "warnings",
        "figures",
    ] {
        assert!(
            page.contains(&format!("<section id=\"{id}\">")),
            "section {id}"
        );
    }
    // Self-contained: no script, no external file.
    for bad in ["<script", " src=", "<link", "<img", "url("] {
        assert!(!page.contains(bad), "{bad}");
    }
    // The nominal and final errors, the step and the validation, as the
    // JSON has them.
    let f1 = |x: &Value| format!("{:.1}", x.as_f64().unwrap());
    for x in [
        &v["nominal"]["rms_um"],
        &v["nominal"]["mean_um"],
        &v["nominal"]["max_um"],
        &v["rms_um"],
        &v["heldout_rms_um"],
        &v["effects"][0]["rms_um_before"],
        &v["effects"][0]["rms_um_after"],
    ] {
        assert!(page.contains(&f1(x)), "{x}");
    }
    assert!(page.contains("compensator on a2"));
    let val = &v["validation"];
    for m in ["1", "2", "3"] {
        for key in [
            "per_marker_mean_mm",
            "per_marker_rms_mm",
            "per_marker_max_mm",
        ] {
            let x = format!("{:.4}", val[key][m].as_f64().unwrap());
            assert!(page.contains(&x), "{key} {m} {x}");
        }
    }
    // The final error per point (mean, max) is the validation's on the
    // calibration file itself (a separate prediction path, `--validate`):
    // 90 rows per marker, so the mean is the markers' mean.
    let maxes: Vec<f64> = ["1", "2", "3"]
        .iter()
        .map(|m| val["per_marker_max_mm"][m].as_f64().unwrap() * 1e3)
        .collect();
    let means: Vec<f64> = ["1", "2", "3"]
        .iter()
        .map(|m| val["per_marker_mean_mm"][m].as_f64().unwrap() * 1e3)
        .collect();
    let max = maxes.iter().copied().fold(0.0, f64::max);
    let mean = means.iter().sum::<f64>() / 3.0;
    let summary = page
        .split("after calibration (final model)")
        .nth(1)
        .expect("summary row");
    assert!(
        summary.starts_with(&format!(
            "</td><td>{:.1}</td><td>{mean:.1}</td><td>{max:.1}</td>",
            v["rms_um"].as_f64().unwrap()
        )),
        "{}",
        &summary[..80]
    );
    // Every parameter with its value, σ and 95 % interval. ν = 3·270 − 9 =
    // 801; t₀.₉₇₅(801) by the Cornish–Fisher expansion z + (z³ + z)/(4ν)
    // (independent of statrs) is 1.96292.
    let z: f64 = 1.959_964;
    let t = z + (z.powi(3) + z) / (4.0 * 801.0);
    assert!(page.contains("ν = 810 equations − 9 parameters = 801"));
    assert!(page.contains(&format!("t<sub>0.975</sub> = {t:.4}")), "{t}");
    for p in v["parameters"].as_array().unwrap() {
        let (name, x, sd) = (
            p["name"].as_str().unwrap(),
            p["value"].as_f64().unwrap(),
            p["std"].as_f64().unwrap(),
        );
        let row = page
            .split("<tr>")
            .find(|r| r.starts_with(&format!("<td>{name}</td>")))
            .unwrap_or_else(|| panic!("row of {name}"));
        // name, value, σ, [lo, hi], unit, t (4 significant digits).
        let cells: Vec<&str> = row
            .split("<td>")
            .skip(1)
            .map(|c| c.split("</td>").next().unwrap())
            .collect();
        let num = |s: &str| s.trim().parse::<f64>().unwrap_or_else(|_| panic!("{s}"));
        let close = |got: f64, want: f64| (got - want).abs() <= 6e-4 * want.abs();
        let (lo, hi) = cells[3]
            .trim_matches(|c| c == '[' || c == ']')
            .split_once(", ")
            .unwrap();
        assert!(close(num(cells[1]), x), "{row}");
        assert!(close(num(cells[2]), sd), "{row}");
        assert!(close(num(lo), x - t * sd), "{row}");
        assert!(close(num(hi), x + t * sd), "{row}");
        assert_eq!(cells[4], p["unit"].as_str().unwrap());
        assert!((num(cells[5]) - x / sd).abs() <= 0.051, "{row}");
    }
    // One inline SVG per figure, and the same figures as files beside it.
    let svgs = page.matches("<svg").count();
    let mut files: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|f| f.ends_with(".svg"))
        .collect();
    files.sort();
    assert_eq!(svgs, files.len());
    assert_eq!(
        files,
        [
            "01_compensator_a2.svg",
            "error_distribution.svg",
            "parameters_urad__N_m.svg",
            "per_pose.svg"
        ]
    );
    assert!(!page.contains("<?xml"), "no XML declaration inside HTML");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn hostile_names_are_escaped() {
    // The page quotes the data file's path; a path with markup in it is
    // text, not markup.
    let dir = std::env::temp_dir().join(format!("robcal-report-esc-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let data = dir.join("<b>x<b>&.csv");
    std::fs::copy(root().join("data/kr270/measurements.csv"), &data).unwrap();
    let out_dir = dir.join("out");
    let out = Command::new(env!("CARGO_BIN_EXE_robcal"))
        .current_dir(root())
        .args(["calibrate", "--setup", "data/kr270/setup-naive.toml", "-q"])
        .arg("--data")
        .arg(&data)
        .arg("--output")
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let page = std::fs::read_to_string(out_dir.join("report.html")).unwrap();
    assert!(page.contains("&lt;b&gt;x&lt;b&gt;&amp;.csv"));
    assert!(!page.contains("<b>x<b>"));
    let _ = std::fs::remove_dir_all(&dir);
}
