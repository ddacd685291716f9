//! `robcal predict` and `robcal compensate`: the model file that
//! `robcal calibrate --output DIR` writes, applied to a points CSV
//! (`robcal::io::points`). Output: the same rows with the predicted
//! position, or with the compensated joint command, on stdout or, all or
//! nothing, in `--output FILE`. A row that cannot be predicted or
//! compensated fails the run with its line; nothing is written.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use robcal::calibrate::{Payload, Predictor};
use robcal::io::points::{joint_column, parse_points, PointRow};
use robcal::robot::CompensateSettings;

/// `robcal predict`.
#[derive(clap::Args)]
pub struct PredictArgs {
    /// The model file (`DIR/model.json` of `robcal calibrate --output DIR`).
    #[arg(long)]
    model: PathBuf,
    /// Poses: `marker`, `load_kg`, `com_x_m..`, `<joint>_rad` per joint.
    #[arg(long)]
    poses: PathBuf,
    /// Write the CSV here (all or nothing) instead of stdout.
    #[arg(long)]
    output: Option<PathBuf>,
    /// The robot at this temperature [°C] (a model with the links' thermal
    /// expansion; default: the calibration's mean temperature, where its
    /// lengths hold).
    #[arg(long = "temperature-c", allow_negative_numbers = true)]
    temperature_c: Option<f64>,
    /// Add each pose's orientation, `rx_rad, ry_rad, rz_rad` after
    /// `x_m, y_m, z_m`: the marker's link frame turned by the identified
    /// tool frame (rotation vector, measurement frame), as a 6-D instrument
    /// measures it.
    #[arg(long)]
    orientation: bool,
}

/// `robcal compensate`.
#[derive(clap::Args)]
pub struct CompensateArgs {
    /// The model file (`DIR/model.json` of `robcal calibrate --output DIR`).
    #[arg(long)]
    model: PathBuf,
    /// Targets: `x_m, y_m, z_m` (measurement frame), `marker`, `load_kg`,
    /// `com_x_m..`, and the start `<joint>_rad` per joint (e.g. the nominal
    /// inverse kinematics of the target); optional `rx_rad, ry_rad, rz_rad`
    /// (the tip frame's orientation, rotation vector) make it a pose.
    #[arg(long)]
    targets: PathBuf,
    /// Write the CSV here (all or nothing) instead of stdout.
    #[arg(long)]
    output: Option<PathBuf>,
    /// Stop when the model puts the point within this of the target [µm].
    #[arg(long = "tolerance-um", default_value_t = 0.1, allow_negative_numbers = true, value_parser = crate::finite_positive)]
    tolerance_um: f64,
    /// Newton steps at most per target.
    #[arg(long = "max-iter", default_value_t = 20, value_parser = crate::at_least_one)]
    max_iter: usize,
    /// The robot at this temperature [°C] (a model with the links' thermal
    /// expansion; default: the calibration's mean temperature, where its
    /// lengths hold).
    #[arg(long = "temperature-c", allow_negative_numbers = true)]
    temperature_c: Option<f64>,
}

/// `robcal check`.
#[derive(clap::Args)]
pub struct CheckArgs {
    /// The model file (`DIR/model.json` of `robcal calibrate --output DIR`).
    #[arg(long)]
    model: PathBuf,
    /// The new recording: `x_m, y_m, z_m` (where the tracker saw the
    /// marker, any frame), `marker`, `load_kg`, `com_x_m..`, `<joint>_rad`
    /// per joint (the points layout of `compensate`'s targets); with
    /// --setup, a measurement CSV of that setup instead.
    #[arg(long)]
    data: PathBuf,
    /// Read --data as a measurement CSV of this setup (its units, markers
    /// and load; the calibration's own layout).
    #[arg(long)]
    setup: Option<PathBuf>,
    /// Pass at most this RMS after re-registration [mm] (default: 1.5 times
    /// the calibration's held-out RMS).
    #[arg(long = "max-rms-mm", allow_negative_numbers = true, value_parser = crate::finite_positive)]
    max_rms_mm: Option<f64>,
    /// The verdict as JSON on stdout.
    #[arg(long)]
    json: bool,
}

/// `robcal compare`.
#[derive(clap::Args)]
pub struct CompareArgs {
    /// The first model file (`A/model.json`).
    a: PathBuf,
    /// The second model file (`B/model.json`).
    b: PathBuf,
    /// Poses to compare the two robots' marker positions at (the layout of
    /// `predict`'s poses).
    #[arg(long)]
    poses: Option<PathBuf>,
    /// The comparison as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// Also write it as a self-contained HTML page here (all or nothing).
    #[arg(long)]
    html: Option<PathBuf>,
}

/// Largest model file read [bytes].
const MAX_MODEL_BYTES: u64 = 64 << 20;

/// The predictor of a model file's `predictor` section.
fn load_model(path: &Path) -> Result<Predictor, String> {
    load_model_file(path).map(|(p, _)| p)
}

/// The predictor of a model file's `predictor` section, and the file.
fn load_model_file(path: &Path) -> Result<(Predictor, serde_json::Value), String> {
    let text = robcal::io::input::read_text(path, "the model file", MAX_MODEL_BYTES)
        .map_err(|e| e.to_string())?;
    robcal::render::json::read_model(&text).map_err(|m| format!("{}: {m}", path.display()))
}

fn read_points(robot: &Predictor, path: &Path, target: bool) -> Result<Vec<PointRow>, String> {
    let text = robcal::io::input::read_text(path, "the points", robcal::io::input::MAX_DATA_BYTES)
        .map_err(|e| e.to_string())?;
    let joints: Vec<_> = robot
        .joint_names()
        .iter()
        .cloned()
        .zip(robot.chain().joints().iter().map(|j| j.kind))
        .collect();
    parse_points(&text, path, &joints, target).map_err(|e| e.to_string())
}

/// The payload warning of `rows` ([`Predictor::payload_warning`]), printed
/// once the run has succeeded (an error stays the one line on stderr).
/// Not an error: the prediction is the model's (docs/apply.md); printed
/// also with --quiet, as there is no report to hold it.
fn warn_payloads(robot: &Predictor, rows: &[PointRow], path: &Path) {
    let loads: Vec<_> = rows.iter().map(|r| (r.line, r.load_kg)).collect();
    if let Some(w) = robot.payload_warning(&loads) {
        eprintln!("robcal: warning: {}: {w}", path.display());
    }
}

/// The tool point and payload of a row.
fn tool_and_payload(
    robot: &Predictor,
    row: &PointRow,
    file: &Path,
) -> Result<(u32, Vector3<f64>, Option<Payload>, Predictor), String> {
    let (id, tool, robot) = robot.at_marker(row.marker).map_err(|e| {
        let add = if row.marker.is_none() {
            ": add a 'marker' column"
        } else {
            ""
        };
        format!("{}:{}: {e}{add}", file.display(), row.line)
    })?;
    let payload = (row.load_kg > 0.0).then(|| Payload {
        mass_kg: row.load_kg,
        com_m: Vector3::from(row.com_m.unwrap_or_default()),
    });
    Ok((id, tool, payload, robot))
}

fn header(robot: &Predictor, row: &PointRow, target: bool) -> String {
    let mut h: Vec<String> = Vec::new();
    if row.id.is_some() {
        h.push("id".into());
    }
    h.extend(["marker", "load_kg", "com_x_m", "com_y_m", "com_z_m"].map(String::from));
    if target {
        h.extend(["x_m", "y_m", "z_m"].map(String::from));
        if row.target_rotation_rad.is_some() {
            h.extend(["rx_rad", "ry_rad", "rz_rad"].map(String::from));
        }
    }
    h.extend(
        robot
            .joint_names()
            .iter()
            .zip(robot.chain().joints())
            .map(|(n, j)| joint_column(n, j.kind)),
    );
    if target {
        if row.target_rotation_rad.is_some() {
            h.push("error_urad".into());
        }
        h.extend(["error_um", "iterations"].map(String::from));
    } else {
        h.extend(["x_m", "y_m", "z_m"].map(String::from));
    }
    h.join(",")
}

fn lead(row: &PointRow, id: u32) -> String {
    let com = row.com_m.unwrap_or_default();
    let mut s = String::new();
    if let Some(i) = &row.id {
        s += &robcal::io::writer::csv_cell(i);
        s.push(',');
    }
    let _ = write!(s, "{id},{},{},{},{}", row.load_kg, com[0], com[1], com[2]);
    s
}

fn join(v: &[f64]) -> String {
    v.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(",")
}

fn emit(out: &str, output: Option<&Path>, inputs: &[&Path]) -> Result<(), String> {
    match output {
        Some(path) => {
            robcal::io::write_all_atomic(&[(path.to_path_buf(), out.as_bytes().to_vec())], inputs)
                .map_err(|e| robcal::io::atomic::about(path, &e))
        }
        None => {
            use std::io::Write as _;
            std::io::stdout()
                .write_all(out.as_bytes())
                .map_err(|e| format!("stdout: {e}"))
        }
    }
}

/// The model file's robot, at `temperature_c` when given
/// ([`Predictor::at_temperature`]).
fn load_model_at(path: &Path, temperature_c: Option<f64>) -> Result<Predictor, String> {
    let robot = load_model(path)?;
    match temperature_c {
        None => Ok(robot),
        Some(t) => robot
            .at_temperature(t)
            .map_err(|e| format!("--temperature-c: {}: {e}", path.display())),
    }
}

/// `robcal predict`.
pub fn run_predict(a: &PredictArgs) -> Result<(), String> {
    let robot = load_model_at(&a.model, a.temperature_c)?;
    let rows = read_points(&robot, &a.poses, false)?;
    let mut out = header(&robot, &rows[0], false);
    if a.orientation {
        out += ",rx_rad,ry_rad,rz_rad";
    }
    out.push('\n');
    for row in &rows {
        let (id, tool, payload, robot) = tool_and_payload(&robot, row, &a.poses)?;
        let at = |e| format!("{}:{}: cannot predict: {e}", a.poses.display(), row.line);
        let p = robot.predict(&tool, &row.q, payload.as_ref()).map_err(at)?;
        let _ = write!(
            out,
            "{},{},{}",
            lead(row, id),
            join(&row.q),
            join(p.as_slice())
        );
        if a.orientation {
            let r = robot.predict_rotation(&tool, &row.q, payload.as_ref());
            let _ = write!(out, ",{}", join(r.map_err(at)?.scaled_axis().as_slice()));
        }
        out.push('\n');
    }
    emit(&out, a.output.as_deref(), &[&a.model, &a.poses])?;
    warn_payloads(&robot, &rows, &a.poses);
    Ok(())
}

/// `robcal compensate`.
pub fn run_compensate(a: &CompensateArgs) -> Result<(), String> {
    let robot = load_model_at(&a.model, a.temperature_c)?;
    let rows = read_points(&robot, &a.targets, true)?;
    let settings = CompensateSettings {
        tolerance_m: a.tolerance_um * 1e-6,
        max_iterations: a.max_iter,
        ..CompensateSettings::new()
    };
    let mut out = header(&robot, &rows[0], true) + "\n";
    let dof = robot.dof();
    for row in &rows {
        let (id, tool, payload, robot) = tool_and_payload(&robot, row, &a.targets)?;
        let target = Vector3::from(row.target_m.unwrap_or_default());
        let c = match row.target_rotation_rad {
            None => robot.compensate(&tool, &target, &row.q, payload.as_ref(), &settings),
            Some(r) => robot.compensate_pose(
                &tool,
                &target,
                &nalgebra::UnitQuaternion::from_scaled_axis(Vector3::from(r)),
                &row.q,
                payload.as_ref(),
                &settings,
            ),
        }
        .map_err(|e| {
            format!(
                "{}:{}: cannot reach the target from the given joint values: {e}",
                a.targets.display(),
                row.line
            )
        })?;
        let (rot, err_rot) = match row.target_rotation_rad {
            Some(r) => (
                format!(",{}", join(&r)),
                format!("{:.6},", c.error_rad * 1e6),
            ),
            None => (String::new(), String::new()),
        };
        let _ = writeln!(
            out,
            "{},{}{rot},{},{err_rot}{:.6},{}",
            lead(row, id),
            join(target.as_slice()),
            join(&c.q[..dof]),
            c.error_m * 1e6,
            c.iterations
        );
    }
    emit(&out, a.output.as_deref(), &[&a.model, &a.targets])?;
    warn_payloads(&robot, &rows, &a.targets);
    Ok(())
}

/// `robcal init`.
#[derive(clap::Args)]
pub struct InitArgs {
    /// The robot's URDF.
    #[arg(long)]
    urdf: PathBuf,
    /// Base link (default: the URDF's root).
    #[arg(long)]
    base: Option<String>,
    /// Tip link, where markers and the load are given (default: the one
    /// leaf below the base).
    #[arg(long)]
    tip: Option<String>,
    /// Write the setup here (all or nothing; never over an existing file)
    /// instead of stdout. The URDF path in it is made relative to this
    /// file's directory when it can be.
    #[arg(long)]
    output: Option<PathBuf>,
}

/// `robcal init`: a commented setup for a robot.
pub fn run_init(a: &InitArgs) -> Result<(), String> {
    let robot = robcal::io::Robot::load(&a.urdf, a.base.as_deref(), a.tip.as_deref())
        .map_err(|e| e.to_string())?;
    let path = match &a.output {
        Some(out) => {
            if out.exists() {
                return Err(format!(
                    "{}: already exists; robcal init does not overwrite a setup",
                    out.display()
                ));
            }
            relative_to(&a.urdf, out.parent().unwrap_or(Path::new("")))
        }
        None => a.urdf.display().to_string(),
    };
    let text = robcal::io::template::setup_template(&path, &robot);
    emit(&text, a.output.as_deref(), &[&a.urdf])
}

/// `target` as seen from directory `dir` when both are relative (or both
/// absolute) and `dir` is a prefix of it; else `target` as given.
fn relative_to(target: &Path, dir: &Path) -> String {
    match target.strip_prefix(dir) {
        Ok(rel) if !dir.as_os_str().is_empty() => rel.display().to_string(),
        _ => match (std::path::absolute(target), std::path::absolute(dir)) {
            (Ok(t), Ok(d)) => t
                .strip_prefix(&d)
                .map_or_else(|_| t.display().to_string(), |r| r.display().to_string()),
            _ => target.display().to_string(),
        },
    }
}

/// `robcal check`: the verdict on stdout (text, or JSON with `--json`);
/// a failed check exits 1 after it, with one line on stderr.
pub fn run_check(a: &CheckArgs) -> Result<(), String> {
    use robcal::calibrate::outputs::check::CHECK_FACTOR;
    let (robot, file) = load_model_file(&a.model)?;
    // What the calibration claims for poses it did not see.
    let (own_um, which) = match (file["heldout_rms_um"].as_f64(), file["rms_um"].as_f64()) {
        (Some(h), _) => (h, "held-out RMS"),
        (None, Some(r)) => (r, "RMS"),
        (None, None) => (f64::NAN, "RMS"),
    };
    let threshold_mm = match a.max_rms_mm {
        Some(t) => t,
        None if own_um.is_finite() => CHECK_FACTOR * own_um * 1e-3,
        None => {
            return Err(format!(
                "{}: no rms_um to set the threshold from: give --max-rms-mm",
                a.model.display()
            ))
        }
    };
    let points = match &a.setup {
        Some(setup) => measured_points(&robot, setup, &a.data)?,
        None => points_of(&robot, &a.data)?,
    };
    // The calibration's σ of each joint's zero (`<joint>.offset`, mrad or
    // mm), in rad or m.
    let zero_std: Vec<f64> = robot
        .joint_names()
        .iter()
        .map(|j| {
            file["parameters"]
                .as_array()
                .and_then(|ps| ps.iter().find(|p| p["name"] == format!("{j}.offset")))
                .and_then(|p| p["std"].as_f64())
                .map_or(0.0, |s| s * 1e-3)
        })
        .collect();
    check_and_report(a, &robot, points, zero_std, threshold_mm, own_um, which)
}

/// The points of a measurement CSV of `setup` (its units, markers and
/// load): every row, a loaded one with the setup's load at `[load] com`.
fn measured_points(
    robot: &Predictor,
    setup: &Path,
    data: &Path,
) -> Result<Vec<robcal::calibrate::outputs::check::CheckPoint>, String> {
    use robcal::calibrate::outputs::check::CheckPoint;
    use robcal::calibrate::outputs::predict::Pose;
    let job = robcal::io::Job::load(setup).map_err(|e| e.to_string())?;
    if job.robot.joint_names != robot.joint_names() {
        return Err(format!(
            "{}: its robot's joints {:?} are not the model's {:?}",
            setup.display(),
            job.robot.joint_names,
            robot.joint_names()
        ));
    }
    let m = job.read_measurements(data).map_err(|e| e.to_string())?;
    if let Some(o) = m.observations.iter().find(|o| o.scalar.is_some()) {
        return Err(format!(
            "{}:{}: robcal check compares points: plane contacts and distances are not \
             checked yet",
            data.display(),
            o.line
        ));
    }
    let com = job.setup.load.map_or([0.0; 3], |l| l.com);
    Ok(m.observations
        .iter()
        .map(|o| CheckPoint {
            pose: Pose {
                line: o.line,
                marker: o.marker,
                q: o.q.to_vec(),
                payload: (o.load_kg > 0.0).then(|| Payload {
                    mass_kg: o.load_kg,
                    com_m: Vector3::from(com),
                }),
            },
            measured_m: Vector3::from(o.p_m),
        })
        .collect())
}

/// The points of a points CSV (`x_m, y_m, z_m` the measured position).
fn points_of(
    robot: &Predictor,
    data: &Path,
) -> Result<Vec<robcal::calibrate::outputs::check::CheckPoint>, String> {
    use robcal::calibrate::outputs::check::CheckPoint;
    use robcal::calibrate::outputs::predict::Pose;
    let rows = read_points(robot, data, true)?;
    let mut points = Vec::with_capacity(rows.len());
    for row in &rows {
        let (id, _, payload, _) = tool_and_payload(robot, row, data)?;
        let measured = row.target_m.ok_or_else(|| {
            format!(
                "{}:{}: no x_m, y_m, z_m: the measured position",
                data.display(),
                row.line
            )
        })?;
        points.push(CheckPoint {
            pose: Pose {
                line: row.line,
                marker: id,
                q: row.q.clone(),
                payload,
            },
            measured_m: Vector3::from(measured),
        });
    }
    Ok(points)
}

/// The check of `points` and its verdict printed (see [`run_check`]).
fn check_and_report(
    a: &CheckArgs,
    robot: &Predictor,
    points: Vec<robcal::calibrate::outputs::check::CheckPoint>,
    zero_std: Vec<f64>,
    threshold_mm: f64,
    own_um: f64,
    which: &str,
) -> Result<(), String> {
    use robcal::calibrate::outputs::check::{check, CHECK_FACTOR};
    let settings = robcal::calibrate::outputs::check::CheckSettings {
        threshold_mm,
        zero_std,
    };
    let v = check(robot, &points, &settings).map_err(|e| format!("{}: {e}", a.data.display()))?;
    let g = &v.reregistration;
    if a.json {
        let changed: Vec<serde_json::Value> = v
            .changed
            .iter()
            .map(|c| serde_json::json!({"joint": c.joint, "change": c.change, "std": c.std, "unit": c.unit}))
            .collect();
        let out = serde_json::json!({
            "pass": v.pass,
            "points": v.points,
            "rms_mm": g.rms_mm,
            "per_marker_rms_mm": g.per_marker_rms_mm,
            "as_measured_rms_mm": v.as_measured_rms_mm,
            "threshold_mm": v.threshold_mm,
            "frame": {
                "translation_mm": g.translation_mm,
                "translation_std_mm": g.translation_std_mm,
                "rotation_mrad": g.rotation_mrad,
                "rotation_std_mrad": g.rotation_std_mrad,
            },
            "changed": changed,
            "untestable": v.untestable,
        });
        println!(
            "{}",
            serde_json::to_string_pretty(&out).map_err(|e| e.to_string())?
        );
    } else {
        println!(
            "check: {} points of {}: RMS {:.4} mm after re-registration ({:.4} mm as measured; \
             the frame moved {:.3} mm and turned {:.3} mrad)",
            v.points,
            a.data.display(),
            g.rms_mm,
            v.as_measured_rms_mm,
            g.shift_mm(),
            g.turn_mrad()
        );
        let why = match a.max_rms_mm {
            Some(_) => "--max-rms-mm".to_string(),
            None => format!("{CHECK_FACTOR} x the calibration's {which}, {own_um:.1} um"),
        };
        println!(
            "check: {} at {:.4} mm ({why})",
            if v.pass { "PASS" } else { "FAIL" },
            v.threshold_mm
        );
        for c in &v.changed {
            println!(
                "check: {} moved {:.4} ± {:.4} {}",
                c.joint, c.change, c.std, c.unit
            );
        }
        if !v.untestable.is_empty() {
            println!(
                "check: not tested (the frame's re-fit absorbs them): {}",
                v.untestable.join(", ")
            );
        }
    }
    if v.pass {
        return Ok(());
    }
    let named: Vec<&str> = v.changed.iter().map(|c| c.joint.as_str()).collect();
    Err(format!(
        "check failed: RMS {:.4} mm after re-registration, above {:.4} mm{}",
        g.rms_mm,
        v.threshold_mm,
        if named.is_empty() {
            String::new()
        } else {
            format!("; moved: {}", named.join(", "))
        }
    ))
}

/// A model file's parameters (`parameters`) and effects (`effects`, as
/// `<effect> on <joint>`).
fn model_contents(
    file: &serde_json::Value,
    path: &Path,
) -> Result<(Vec<robcal::calibrate::Parameter>, Vec<String>), String> {
    let at = |m: &str| format!("{}: {m}", path.display());
    let list = file["parameters"]
        .as_array()
        .ok_or_else(|| at("no 'parameters' list"))?;
    let mut params = Vec::with_capacity(list.len());
    for p in list {
        let (Some(name), Some(value), Some(std), Some(unit)) = (
            p["name"].as_str(),
            p["value"].as_f64(),
            p["std"].as_f64(),
            p["unit"].as_str(),
        ) else {
            return Err(at("a parameter without name, value, std and unit"));
        };
        params.push(robcal::calibrate::Parameter {
            name: name.into(),
            value,
            std,
            unit: unit.into(),
            determined: p["determined"].as_bool().unwrap_or(true),
        });
    }
    let effects = file["effects"]
        .as_array()
        .map(|e| {
            e.iter()
                .map(|x| match (x["effect"].as_str(), x["joint"].as_str()) {
                    (Some(e), Some(j)) => format!("{e} on {j}"),
                    (Some(e), None) => e.to_string(),
                    _ => "?".into(),
                })
                .collect()
        })
        .unwrap_or_default();
    Ok((params, effects))
}

/// `robcal compare`: two model files side by side (text, or JSON with
/// `--json`; `--html` writes a page too).
pub fn run_compare(a: &CompareArgs) -> Result<(), String> {
    use robcal::calibrate::outputs::compare::{parameters, positions};
    use robcal::calibrate::outputs::predict::Pose;
    let (ra, fa) = load_model_file(&a.a)?;
    let (rb, fb) = load_model_file(&a.b)?;
    if ra.joint_names() != rb.joint_names() {
        return Err(format!(
            "{} and {}: not the same robot (joints {:?} and {:?})",
            a.a.display(),
            a.b.display(),
            ra.joint_names(),
            rb.joint_names()
        ));
    }
    let (pa, ea) = model_contents(&fa, &a.a)?;
    let (pb, eb) = model_contents(&fb, &a.b)?;
    let pairs = parameters(&pa, &pb);
    let only = |x: &[String], y: &[String]| -> Vec<String> {
        x.iter().filter(|e| !y.contains(e)).cloned().collect()
    };
    let (effects_a, effects_b) = (only(&ea, &eb), only(&eb, &ea));
    let pos = match &a.poses {
        None => None,
        Some(path) => {
            let rows = read_points(&ra, path, false)?;
            let mut poses = Vec::with_capacity(rows.len());
            for row in &rows {
                let (id, _, payload, _) = tool_and_payload(&ra, row, path)?;
                poses.push(Pose {
                    line: row.line,
                    marker: id,
                    q: row.q.clone(),
                    payload,
                });
            }
            Some(positions(&ra, &rb, &poses).map_err(|e| format!("{}: {e}", path.display()))?)
        }
    };
    let beyond = |z: Option<f64>| z.is_some_and(|z| z.abs() > 3.0);
    let mut text = format!(
        "compare: A = {} (RMS {:.1} um), B = {} (RMS {:.1} um)\n",
        a.a.display(),
        fa["rms_um"].as_f64().unwrap_or(f64::NAN),
        a.b.display(),
        fb["rms_um"].as_f64().unwrap_or(f64::NAN)
    );
    let w = pairs
        .iter()
        .map(|p| p.name.chars().count())
        .max()
        .unwrap_or(0)
        .max(24);
    let _ = writeln!(
        text,
        "  {:<w$} {:>12} ± {:<10} {:>12} ± {:<10} {:>9}  unit",
        "parameter", "A", "1 sd", "B", "1 sd", "(B-A)/sd"
    );
    let cell = |x: Option<(f64, f64)>| match x {
        Some((v, s)) => format!("{v:>12.4} ± {s:<10.4}"),
        None => format!("{:>12}   {:<10}", "-", ""),
    };
    for p in &pairs {
        let z = p.z();
        let _ = writeln!(
            text,
            "  {:<w$} {} {} {:>9}{} {}",
            p.name,
            cell(p.a),
            cell(p.b),
            z.map_or("-".into(), |z| format!("{z:.1}")),
            if beyond(z) { "*" } else { " " },
            p.unit
        );
    }
    let moved: Vec<&str> = pairs
        .iter()
        .filter(|p| beyond(p.z()))
        .map(|p| p.name.as_str())
        .collect();
    let _ = writeln!(
        text,
        "  * differs by more than 3 sd; {} of {}{}",
        moved.len(),
        pairs.iter().filter(|p| p.z().is_some()).count(),
        if moved.is_empty() {
            String::new()
        } else {
            format!(": {}", moved.join(", "))
        }
    );
    for (what, list) in [
        ("effects in A only", &effects_a),
        ("effects in B only", &effects_b),
    ] {
        if !list.is_empty() {
            let _ = writeln!(text, "compare: {what}: {}", list.join(", "));
        }
    }
    if let Some(p) = &pos {
        let _ = writeln!(
            text,
            "compare: positions at {} poses: RMS {:.4} mm, max {:.4} mm apart, B's frame re-fitted \
             onto A's (moved {:.3} mm, turned {:.3} mrad)",
            p.points,
            p.frame.rms_mm,
            p.max_mm,
            p.frame.shift_mm(),
            p.frame.turn_mrad()
        );
    }
    let json = serde_json::json!({
        "a": a.a.display().to_string(),
        "b": a.b.display().to_string(),
        "parameters": pairs.iter().map(|p| serde_json::json!({
            "name": p.name,
            "unit": p.unit,
            "a_value": p.a.map(|x| x.0),
            "a_std": p.a.map(|x| x.1),
            "b_value": p.b.map(|x| x.0),
            "b_std": p.b.map(|x| x.1),
            "difference_sigmas": p.z(),
        })).collect::<Vec<_>>(),
        "differ": moved,
        "effects_only_a": effects_a,
        "effects_only_b": effects_b,
        "positions": pos.as_ref().map(|p| serde_json::json!({
            "points": p.points,
            "rms_mm": p.frame.rms_mm,
            "max_mm": p.max_mm,
            "per_marker_rms_mm": p.frame.per_marker_rms_mm,
            "frame": {
                "translation_mm": p.frame.translation_mm,
                "rotation_mrad": p.frame.rotation_mrad,
            },
        })),
    });
    if let Some(path) = &a.html {
        let mut h = String::from(
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>robcal compare</title>\
             <style>body{font-family:sans-serif;max-width:70em;margin:2em auto}table{border-collapse:collapse}\
             td,th{border:1px solid #ccc;padding:0.2em 0.5em;text-align:right}td:first-child{text-align:left}\
             .beyond{background:#fde0dc}</style></head><body><h1>Two calibrations compared</h1>",
        );
        let _ = write!(
            h,
            "<p>A = <code>{}</code>, B = <code>{}</code>. A parameter whose estimates differ by \
             more than 3 σ (σ = √(σ<sub>A</sub>² + σ<sub>B</sub>²)) is marked; the base frame is \
             the tracker's placement, not judged.</p><table><tr><th>parameter</th><th>A</th>\
             <th>σ</th><th>B</th><th>σ</th><th>(B − A)/σ</th><th>unit</th></tr>",
            robcal::render::html::esc(&a.a.display().to_string()),
            robcal::render::html::esc(&a.b.display().to_string())
        );
        let num = |x: Option<f64>| x.map_or("–".to_string(), |v| format!("{v:.4}"));
        for p in &pairs {
            let z = p.z();
            let _ = write!(
                h,
                "<tr{}><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                if beyond(z) { " class=\"beyond\"" } else { "" },
                robcal::render::html::esc(&p.name),
                num(p.a.map(|x| x.0)),
                num(p.a.map(|x| x.1)),
                num(p.b.map(|x| x.0)),
                num(p.b.map(|x| x.1)),
                z.map_or("–".into(), |z| format!("{z:.1}")),
                robcal::render::html::esc(&p.unit)
            );
        }
        h.push_str("</table>");
        for (what, list) in [
            ("Effects in A only", &effects_a),
            ("Effects in B only", &effects_b),
        ] {
            if !list.is_empty() {
                let _ = write!(
                    h,
                    "<p>{what}: {}</p>",
                    robcal::render::html::esc(&list.join(", "))
                );
            }
        }
        if let Some(p) = &pos {
            let _ = write!(
                h,
                "<p>Marker positions at {} poses: RMS {:.4} mm, max {:.4} mm apart, B's frame \
                 re-fitted onto A's (moved {:.3} mm, turned {:.3} mrad).</p>",
                p.points,
                p.frame.rms_mm,
                p.max_mm,
                p.frame.shift_mm(),
                p.frame.turn_mrad()
            );
        }
        h.push_str("</body></html>\n");
        emit(&h, Some(path), &[&a.a, &a.b])?;
    }
    if a.json {
        let s = serde_json::to_string_pretty(&json).map_err(|e| e.to_string())? + "\n";
        emit(&s, None, &[])
    } else {
        emit(&text, None, &[])
    }
}
