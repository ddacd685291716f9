//! `robcal predict` and `robcal compensate` (issue 14) end to end: the
//! model file of `robcal calibrate --output DIR` on the bundled KR-270
//! (the paper's compliances with the A2 compensator table), applied.
//!
//! - `compensate` then `predict` at the compensated commands: the model
//!   puts each marker on its target (within the 0.1 µm tolerance), and the
//!   compensated command differs from the start by the deflection;
//! - a target between the compensator's calibrated A2 angles is answered
//!   (the table is interpolated);
//! - bad files: one line, exit 1, nothing written.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn robcal(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_robcal"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .output()
        .expect("run robcal")
}

fn ok(o: &Output) -> String {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8(o.stdout.clone()).expect("utf-8")
}

fn rejected(o: &Output, expect: &str) {
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains(expect), "{err} (expected '{expect}')");
    assert!(o.stdout.is_empty());
}

/// The CSV text as rows of cells, with the header.
fn table(text: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let mut lines = text.lines();
    let head = lines.next().unwrap().split(',').map(String::from).collect();
    (
        head,
        lines
            .map(|l| l.split(',').map(String::from).collect())
            .collect(),
    )
}

fn col(head: &[String], name: &str) -> usize {
    head.iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("{name} in {head:?}"))
}

/// `robcal -q predict --model MODEL --poses POSES` with `extra` arguments.
fn predict(model: &Path, poses: &Path, extra: &[&str]) -> Output {
    let args = [
        "-q",
        "predict",
        "--model",
        model.to_str().unwrap(),
        "--poses",
        poses.to_str().unwrap(),
    ];
    robcal(&[&args[..], extra].concat())
}

/// The points `x_m, y_m, z_m` of a successful `predict`, one per row.
fn points(o: &Output) -> Vec<[f64; 3]> {
    let (head, rows) = table(&ok(o));
    let xyz = ["x_m", "y_m", "z_m"].map(|c| col(&head, c));
    rows.iter()
        .map(|r| xyz.map(|k| r[k].parse::<f64>().unwrap()))
        .collect()
}

fn model(dir: &Path) -> PathBuf {
    let o = robcal(&[
        "calibrate",
        "--setup",
        "data/kr270/setup.toml",
        "--data",
        "data/kr270/measurements.csv",
        "--no-diagnose",
        "--output",
        dir.to_str().unwrap(),
    ]);
    ok(&o);
    dir.join("model.json")
}

#[test]
fn compensated_commands_put_the_markers_on_their_targets() {
    let dir = std::env::temp_dir().join(format!("robcal-apply-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let m = model(&dir);
    let m = m.to_str().unwrap();
    // Targets: the paper's first configurations' poses with A2 at its
    // calibrated angles and between them, shifted by a few mm.
    let joints = "a1_rad,a2_rad,a3_rad,a4_rad,a5_rad,a6_rad";
    let mut poses = format!("id,marker,load_kg,com_x_m,com_y_m,com_z_m,{joints}\n");
    let a2_deg = [-0.01, -20.0, -35.0, -50.0, -72.0, -90.0];
    for (i, a2) in a2_deg.iter().enumerate() {
        let q = [79.2, *a2, -5.57, 51.0, -97.52, -91.67].map(|d: f64| d.to_radians());
        let q: Vec<String> = q.iter().map(|v| v.to_string()).collect();
        let _ = writeln!(poses, "p{i},{},250,0.25,0,0.3,{}", 1 + i % 3, q.join(","));
    }
    let poses_path = dir.join("poses.csv");
    std::fs::write(&poses_path, &poses).unwrap();
    let predicted = ok(&robcal(&[
        "predict",
        "--model",
        m,
        "--poses",
        poses_path.to_str().unwrap(),
    ]));
    let (head, rows) = table(&predicted);
    assert_eq!(rows.len(), a2_deg.len());
    // The targets: 5 mm from the predicted points.
    let mut targets = format!("id,marker,load_kg,com_x_m,com_y_m,com_z_m,x_m,y_m,z_m,{joints}\n");
    for r in &rows {
        let x: Vec<f64> = ["x_m", "y_m", "z_m"]
            .iter()
            .map(|c| r[col(&head, c)].parse::<f64>().unwrap() + 0.005)
            .collect();
        let _ = writeln!(
            targets,
            "{},{},{},{},{},{},{},{},{},{}",
            r[0],
            r[1],
            r[2],
            r[3],
            r[4],
            r[5],
            x[0],
            x[1],
            x[2],
            r[6..12].join(",")
        );
    }
    let targets_path = dir.join("targets.csv");
    std::fs::write(&targets_path, &targets).unwrap();
    let out_path = dir.join("commands.csv");
    let o = robcal(&[
        "compensate",
        "--model",
        m,
        "--targets",
        targets_path.to_str().unwrap(),
        "--output",
        out_path.to_str().unwrap(),
    ]);
    ok(&o);
    let (chead, commands) = table(&std::fs::read_to_string(&out_path).unwrap());
    assert_eq!(commands.len(), rows.len());
    // Predict at the compensated commands: the markers are on the targets.
    let mut again = format!("id,marker,load_kg,com_x_m,com_y_m,com_z_m,{joints}\n");
    for c in &commands {
        assert!(c[col(&chead, "error_um")].parse::<f64>().unwrap() <= 0.1);
        let q: Vec<&str> = (1..=6)
            .map(|j| c[col(&chead, &format!("a{j}_rad"))].as_str())
            .collect();
        let _ = writeln!(again, "{},{}", c[..6].join(","), q.join(","));
    }
    let again_path = dir.join("again.csv");
    std::fs::write(&again_path, &again).unwrap();
    let reached = ok(&robcal(&[
        "predict",
        "--model",
        m,
        "--poses",
        again_path.to_str().unwrap(),
    ]));
    let (rhead, reached) = table(&reached);
    for ((t, r), c) in table(&targets).1.iter().zip(&reached).zip(&commands) {
        let d: f64 = ["x_m", "y_m", "z_m"]
            .iter()
            .enumerate()
            .map(|(k, a)| {
                r[col(&rhead, a)].parse::<f64>().unwrap() - t[6 + k].parse::<f64>().unwrap()
            })
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt();
        assert!(d <= 0.1e-6, "{}: {d} m from the target", c[0]);
        // The command moved: 5 mm of target plus the deflection undone.
        let moved: f64 = (0..6)
            .map(|j| {
                c[col(&chead, &format!("a{}_rad", j + 1))]
                    .parse::<f64>()
                    .unwrap()
                    - t[9 + j].parse::<f64>().unwrap()
            })
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt();
        assert!(moved > 1e-3, "{}: moved {moved} rad", c[0]);
    }

    // A pose target: the tip frame turned too (a rotation vector).
    let pose_path = dir.join("pose.csv");
    let lines: Vec<&str> = targets.lines().collect();
    let mut cells: Vec<String> = lines[1].split(',').map(String::from).collect();
    for (k, v) in ["0", "1.5", "0"].iter().enumerate() {
        cells.insert(9 + k, v.to_string());
    }
    let head = lines[0].replacen(",z_m,", ",z_m,rx_rad,ry_rad,rz_rad,", 1);
    std::fs::write(&pose_path, format!("{head}\n{}\n", cells.join(","))).unwrap();
    let posed = ok(&robcal(&[
        "compensate",
        "--model",
        m,
        "--targets",
        pose_path.to_str().unwrap(),
    ]));
    let (phead, prow) = table(&posed);
    assert!(prow[0][col(&phead, "error_urad")].parse::<f64>().unwrap() <= 0.1);
    assert!(prow[0][col(&phead, "error_um")].parse::<f64>().unwrap() <= 0.1);

    // Bad files: one line, exit 1, nothing written.
    let bad = dir.join("bad.csv");
    let out2 = dir.join("out2.csv");
    let compensate_bad = || {
        robcal(&[
            "compensate",
            "--model",
            m,
            "--targets",
            bad.to_str().unwrap(),
            "--output",
            out2.to_str().unwrap(),
        ])
    };
    std::fs::write(&bad, targets.replacen(",x_m,", ",x_mm,", 1)).unwrap();
    rejected(&compensate_bad(), "bad.csv:1: column 'x_mm'");
    std::fs::write(&bad, targets.replacen(",250,", ",-1,", 1)).unwrap();
    rejected(
        &compensate_bad(),
        "bad.csv:2: column 'load_kg': negative mass",
    );
    // The first target with cell `i` set to `value`.
    let rows: Vec<&str> = targets.lines().collect();
    let header: Vec<&str> = rows[0].split(',').collect();
    let with_cell = |i: usize, value: &str| {
        let mut cells: Vec<String> = rows[1].split(',').map(String::from).collect();
        cells[i] = value.into();
        std::fs::write(&bad, format!("{}\n{}\n", rows[0], cells.join(","))).unwrap();
    };
    // Values no robot has (a second reading got a point 2.5 m away for
    // 1e7 kg, and an ordinary-looking one for a joint at 1e300 rad).
    for (column, value, expect) in [
        (
            "load_kg",
            "1e7",
            "column 'load_kg': 1e7 kg is beyond 1e5 kg in magnitude",
        ),
        (
            "a2_rad",
            "1e300",
            "column 'a2_rad': 1e300 rad is beyond 1e4 rad in magnitude",
        ),
        (
            "com_z_m",
            "-2e4",
            "column 'com_z_m': -2e4 m is beyond 1e4 m in magnitude",
        ),
    ] {
        with_cell(
            header.iter().position(|h| *h == column).expect(column),
            value,
        );
        rejected(&compensate_bad(), &format!("bad.csv:2: {expect}"));
    }
    // A target 10 m away cannot be reached.
    with_cell(6, "10");
    let o = compensate_bad();
    rejected(&o, "bad.csv:2: cannot reach the target");
    assert!(!out2.exists());
    // A report JSON is not a model file.
    let report = dir.join("report.json");
    std::fs::write(&report, "{\"rms_um\": 1}").unwrap();
    let o = robcal(&[
        "predict",
        "--model",
        report.to_str().unwrap(),
        "--poses",
        poses_path.to_str().unwrap(),
    ]);
    rejected(&o, "no 'predictor' section");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A hand-edited `model.json` that robcal would read otherwise than meant
/// is an error (a second reading: a misspelt key was read as zero, a unit
/// changed to µrad read as rad, two records of one joint summed).
#[test]
fn a_model_file_edited_out_of_its_format_is_refused() {
    let dir = std::env::temp_dir().join(format!("robcal-apply-strict-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let m = model(&dir);
    let text = std::fs::read_to_string(&m).unwrap();
    let poses = "data/kr270/poses.csv";
    // The file as written reads.
    ok(&robcal(&[
        "predict",
        "--model",
        m.to_str().unwrap(),
        "--poses",
        poses,
    ]));
    let law = "\"units\":{\"backlash\":\"rad\",\"compliance\":\"rad/(N*m)\"";
    let compact: String = text.split_whitespace().collect();
    assert!(compact.contains(law), "the writer's units moved");
    let record = |c: &str| -> String {
        let i = c.find("\"joint_law\":[").unwrap() + "\"joint_law\":[".len();
        let mut depth = 0;
        for (k, ch) in c[i..].char_indices() {
            match ch {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        return c[i..=i + k].to_string();
                    }
                }
                _ => {}
            }
        }
        panic!("no joint_law record")
    };
    let first = record(&compact);
    let cases = [
        (
            compact.replacen(law, &law.replace("\"rad/(N*m)\"", "\"urad/(N*m)\""), 1),
            "joint_law of 'a2': unit of compliance 'urad/(N*m)', where robcal writes and reads 'rad/(N*m)'",
        ),
        (
            compact.replacen("\"compliance\":0.0,\"compliance_table\"", "\"complianse\":0.0,\"compliance_table\"", 1),
            "unknown field `complianse`",
        ),
        (
            compact.replacen(&first, &format!("{first},{first}"), 1),
            "joint_law of 'a2': listed twice",
        ),
    ];
    for (edited, expect) in cases {
        assert_ne!(edited, compact, "{expect}: the edit did not apply");
        let bad = dir.join("edited.json");
        std::fs::write(&bad, edited).unwrap();
        rejected(
            &robcal(&[
                "predict",
                "--model",
                bad.to_str().unwrap(),
                "--poses",
                poses,
            ]),
            expect,
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_payload_far_beyond_the_calibrations_is_predicted_with_a_warning() {
    let dir = std::env::temp_dir().join(format!("robcal-payload-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let m = model(&dir);
    let text = std::fs::read_to_string(&m).unwrap();
    assert!(
        text.contains("\"heaviest_payload_kg\": 275.8"),
        "the paper's load"
    );
    let q = "1.38,-0.5,-0.1,0.89,-1.7,-1.6";
    let head = "marker,load_kg,com_x_m,com_y_m,com_z_m,a1_rad,a2_rad,a3_rad,a4_rad,a5_rad,a6_rad";
    let predict_loads = |loads: &[&str], model: &Path| {
        let mut poses = format!("{head}\n");
        for l in loads {
            let _ = writeln!(poses, "1,{l},0.25,0,0.3,{q}");
        }
        let p = dir.join("p.csv");
        std::fs::write(&p, poses).unwrap();
        predict(model, &p, &[])
    };
    let o = predict_loads(&["0", "250", "551"], &m);
    ok(&o);
    assert!(
        o.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // 25 kg read as 25 000: the point moves, exit 0, and it is said once.
    let o = predict_loads(&["250", "25000", "600"], &m);
    let out = ok(&o);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("2 of 3 rows carry a payload more than 2 times the heaviest of the calibration (275.8 kg), up to 25000 kg (line 3)"),
        "{err}"
    );
    assert_eq!(out.lines().count(), 4);
    // A file written before the key: read, nothing to compare with.
    let old = dir.join("old.json");
    let key = text
        .find(",\n    \"heaviest_payload_kg\"")
        .expect("the key");
    let end = key + 2 + text[key + 2..].find('\n').unwrap();
    std::fs::write(&old, format!("{}{}", &text[..key], &text[end..])).unwrap();
    let o = predict_loads(&["25000"], &old);
    ok(&o);
    assert!(
        o.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let bad = dir.join("bad.json");
    std::fs::write(
        &bad,
        text.replace(
            "\"heaviest_payload_kg\": 275.8",
            "\"heaviest_payload_kg\": -1",
        ),
    )
    .unwrap();
    rejected(
        &predict_loads(&["1"], &bad),
        "heaviest_payload_kg: -1 kg is not a payload",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--temperature-c` (a model with the links' thermal expansion): a point
/// predicted at `T` is `o₁ + (1 + α (T − T_ref))(p − o₁)` of the one at the
/// reference, `o₁` the first joint's origin (the KR-270's model file, its
/// `thermal_expansion` added by hand: its calibration has no temperature);
/// a model without one, or a temperature out of range, is one line.
#[test]
fn predicted_at_a_temperature() {
    let dir = std::env::temp_dir().join(format!("robcal-thermal-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let m = model(&dir);
    let text = std::fs::read_to_string(&m).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let (alpha, reference) = (12e-6, 21.5);
    json["predictor"]["thermal_expansion"] =
        serde_json::json!({"alpha_per_k": alpha, "reference_c": reference});
    let o1: Vec<f64> = json["predictor"]["joints"][0]["origin_xyz_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let warm = dir.join("warm.json");
    std::fs::write(&warm, serde_json::to_string_pretty(&json).unwrap()).unwrap();
    let poses = dir.join("p.csv");
    std::fs::write(
        &poses,
        "marker,load_kg,com_x_m,com_y_m,com_z_m,a1_rad,a2_rad,a3_rad,a4_rad,a5_rad,a6_rad\n\
         1,0,0,0,0,1.38,-0.5,-0.1,0.89,-1.7,-1.6\n\
         1,0,0,0,0,-0.4,-1.1,0.6,0.2,1.1,0.3\n",
    )
    .unwrap();
    let predict = |model: &Path, t: Option<&str>| match t {
        Some(t) => predict(model, &poses, &["--temperature-c", t]),
        None => predict(model, &poses, &[]),
    };
    let at_ref = points(&predict(&warm, None));
    let plain = points(&predict(&m, None));
    assert_eq!(at_ref, plain, "at the reference: the file's lengths");
    for t in [35.0, -10.0] {
        let at_t = points(&predict(&warm, Some(&format!("{t}"))));
        let s = 1.0 + alpha * (t - reference);
        for (p, q) in at_ref.iter().zip(&at_t) {
            let expected: Vec<f64> = (0..3).map(|k| o1[k] + s * (p[k] - o1[k])).collect();
            let moved = (0..3).map(|k| (q[k] - p[k]).powi(2)).sum::<f64>().sqrt();
            let off = (0..3)
                .map(|k| (q[k] - expected[k]).powi(2))
                .sum::<f64>()
                .sqrt();
            // Besides: the own weight's deflection (millimetres on the
            // KR-270) grows with the lengths and the links' centres of mass
            // by the same ~4e-4, ~1 µm at −10 °C (measured 1.01 µm).
            assert!(
                off < 2e-6 && moved > 1e-4,
                "{t} degC: off {off} m, moved {moved} m"
            );
        }
    }
    rejected(
        &predict(&m, Some("30")),
        "model.json: the model has no thermal_expansion",
    );
    rejected(&predict(&warm, Some("300")), "outside [-50, 150] degC");
    json["predictor"]["thermal_expansion"]["alpha_per_k"] = serde_json::json!(0.5);
    let bad = dir.join("bad.json");
    std::fs::write(&bad, serde_json::to_string(&json).unwrap()).unwrap();
    rejected(&predict(&bad, None), "is not a thermal expansion");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A model whose links bend (`link_compliance`): under the robot's own
/// weight too when the file says so (`link_compliance_own_weight`, what a
/// calibration now writes), under the payload alone in a file written
/// before the key (its geometry absorbed the rest); a pose compensation,
/// which does not apply the bending, is refused for the former even
/// without a payload (one line, nothing written).
#[test]
fn link_bending_under_the_own_weight_is_the_files_to_say() {
    let dir = std::env::temp_dir().join(format!("robcal-bending-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let m = model(&dir);
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&m).unwrap()).unwrap();
    assert!(json["predictor"]["joints"][1]["link_mass_kg"].is_number());
    json["predictor"]["link_compliance"] =
        serde_json::json!([{"joint": "a2", "value": 2e-6, "unit": "rad/(N*m)"}]);
    let write = |name: &str, json: &serde_json::Value| {
        let p = dir.join(name);
        std::fs::write(&p, serde_json::to_string(json).unwrap()).unwrap();
        p
    };
    let old = write("old.json", &json);
    json["predictor"]["link_compliance_own_weight"] = serde_json::json!(true);
    let new = write("new.json", &json);
    let poses = dir.join("p.csv");
    std::fs::write(
        &poses,
        "marker,load_kg,com_x_m,com_y_m,com_z_m,a1_rad,a2_rad,a3_rad,a4_rad,a5_rad,a6_rad\n\
         1,0,0,0,0,1.38,-0.5,-0.1,0.89,-1.7,-1.6\n",
    )
    .unwrap();
    let predict = |model: &Path| points(&predict(model, &poses, &[]))[0];
    let (rigid, before, now) = (predict(&m), predict(&old), predict(&new));
    assert_eq!(rigid, before, "no payload: a file of before does not bend");
    let bent = (0..3)
        .map(|k| (now[k] - rigid[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    // (Measured: 55 µm.)
    assert!(bent > 1e-5, "the own weight bends a2's link by {bent} m");
    let targets = dir.join("t.csv");
    std::fs::write(
        &targets,
        "marker,load_kg,x_m,y_m,z_m,rx_rad,ry_rad,rz_rad,a1_rad,a2_rad,a3_rad,a4_rad,a5_rad,a6_rad\n\
         1,0,0.73,-2.22,0.97,0,0,0,1.38,-0.5,-0.1,0.89,-1.7,-1.6\n",
    )
    .unwrap();
    let out = dir.join("out.csv");
    let compensate = |model: &Path| {
        robcal(&[
            "-q",
            "compensate",
            "--model",
            model.to_str().unwrap(),
            "--targets",
            targets.to_str().unwrap(),
            "--output",
            out.to_str().unwrap(),
        ])
    };
    let o = compensate(&new);
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("link bending"), "{err}");
    assert!(!out.exists());
    let _ = std::fs::remove_dir_all(&dir);
}
