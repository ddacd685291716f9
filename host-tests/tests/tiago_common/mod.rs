//! The TIAGo motion-capture recordings of FIGAROH (issue 7,
//! docs/tiago.md) for the host tests `tiago_*.rs` and `examples/tiago.rs`
//! (which includes this file with `#[path]`): where the data are, the
//! product's job for each of FIGAROH's models, and an independent oracle —
//! forward kinematics straight from the URDF (urdf-rs, 4 × 4 matrices) and
//! a rigid registration by SVD — that shares no code with robcal's engine.
//!
//! Every fit is `robcal::calibrate`; nothing here estimates a parameter.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Vector3};
use robcal::calibrate::{self, Method, Report, Settings};
use robcal::io::{GeometryModel, Job, MarkerModel, Measurements, Robot};

pub const TRAIN: &str = "qualisys_2021-11-30_static_postures.csv";
pub const VALID: &str = "qualisys_2021-11-26_static_postures.csv";
pub const URDF: &str = "tiago_48_schunk.urdf";
/// FIGAROH's point BL: marker 1.
pub const BL: u32 = 1;

/// The repository root (this file is `host-tests/tests/tiago_common/mod.rs`
/// or included from `examples/tiago.rs`; both know the root at compile
/// time).
pub fn repo_root() -> PathBuf {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    if here.join("data/tiago/setup.toml").exists() {
        here.to_path_buf()
    } else {
        here.parent()
            .expect("host-tests has a parent")
            .to_path_buf()
    }
}

/// `shared/datasets/tiago-mocap`: `$ROBCAL_TIAGO_DATA`, else beside the
/// repository (`X/../shared`, as in CI), else in the nearest ancestor that
/// has it (a nested git worktree); `None` when it is nowhere.
pub fn data_dir() -> Option<PathBuf> {
    if let Some(dir) = std::env::var_os("ROBCAL_TIAGO_DATA") {
        return Some(PathBuf::from(dir));
    }
    repo_root()
        .ancestors()
        .skip(1)
        .map(|a| a.join("shared/datasets/tiago-mocap"))
        .find(|d| d.join(URDF).exists())
}

/// The data directory, or `None` after saying on stderr that the test is
/// skipped and why (a plain clone without `../shared`). With
/// `ROBCAL_REQUIRE_SHARED=1` (CI) a missing directory fails the test.
pub fn data_or_skip(test: &str) -> Option<PathBuf> {
    let d = data_dir();
    if d.is_none() {
        let what = "shared/datasets/tiago-mocap";
        if std::env::var_os("ROBCAL_REQUIRE_SHARED").is_some_and(|v| v == "1") {
            panic!("{what} not found, and ROBCAL_REQUIRE_SHARED=1 (CI) requires it");
        }
        skipped_note(&format!(
            "skipped {test}: shared/datasets/tiago-mocap not found beside the repository \
             (CI has it; set ROBCAL_TIAGO_DATA to run it elsewhere)"
        ));
    }
    d
}

/// The job of `data/tiago/<setup>`, its robot read from `data`.
pub fn job(data: &Path, setup: &str) -> Job {
    let setup_path = repo_root().join("data/tiago").join(setup);
    let setup = robcal::io::Setup::load(&setup_path).expect("setup");
    let robot = Robot::load(
        data.join(URDF),
        setup.base_link.as_deref(),
        setup.tip_link.as_deref(),
    )
    .expect("robot");
    setup
        .check_robot(&robot, &setup_path)
        .expect("setup fits robot");
    Job {
        setup_path,
        setup,
        robot,
        urdf_text: None,
    }
}

/// A temporary directory unique to this process and `tag`.
pub fn temp_dir(tag: &str) -> PathBuf {
    static COUNT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = COUNT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let d = std::env::temp_dir().join(format!("robcal-tiago-{tag}-{}-{n}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A FIGAROH recording imported (`robcal::io::figaroh::import_mocap`) and
/// read back with `job`.
pub fn import(job: &Job, data: &Path, name: &str) -> Measurements {
    let dir = temp_dir("import");
    let out = dir.join(name.replace(".csv", ".contract.csv"));
    robcal::io::figaroh::import_mocap(data.join(name), &out, Some(&job.robot)).expect("import");
    let m = job.read_measurements(&out).expect("read back");
    let _ = std::fs::remove_dir_all(&dir);
    m
}

/// FIGAROH's models: the registration (base and the points), plus joint
/// offsets, plus every joint-frame error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Model {
    Registration,
    Offsets,
    Full,
}

impl Model {
    pub fn name(self) -> &'static str {
        match self {
            Model::Registration => "registration (base + points)",
            Model::Offsets => "+ joint offsets",
            Model::Full => "+ joint-frame errors (full)",
        }
    }
}

/// `job` declaring `model` and only the markers `points`.
pub fn variant(job: &Job, model: Model, points: &[u32]) -> Job {
    let mut j = job.clone();
    j.setup.markers.retain(|m| points.contains(&m.id));
    let m = &mut j.setup.model;
    m.base_frame = true;
    m.markers = MarkerModel::Identify;
    m.geometry = match model {
        Model::Registration => GeometryModel::None,
        Model::Offsets => GeometryModel::JointOffsets,
        Model::Full => GeometryModel::Full,
    };
    j
}

/// The rows of `data` of the markers `points`.
pub fn only(data: &Measurements, points: &[u32]) -> Measurements {
    let mut m = data.clone();
    m.observations.retain(|o| points.contains(&o.marker));
    m.deflections.clear();
    m
}

/// `robcal::calibrate` with unit weights (FIGAROH's), no diagnosis.
pub fn fit_ols(job: &Job, data: &Measurements) -> Report {
    let settings = Settings {
        method: Method::Ols,
        diagnose: false,
        heldout: false,
        ..Settings::default()
    };
    calibrate::calibrate(job, data, &settings, &mut |_| {}).expect("calibration")
}

/// Norm RMSE \[mm\] per marker id of the calibrated model on `data`
/// (`robcal::calibrate::validate`: nothing re-estimated), and over all.
pub fn rmse_mm(r: &Report, job: &Job, data: &Measurements) -> (BTreeMap<String, f64>, f64) {
    let v = calibrate::validate(&r.model, job, data).expect("validation");
    (v.per_marker_rms_mm, v.rms_mm)
}

// ---------------------------------------------------------------------------
// The oracle: forward kinematics from the URDF text and a rigid
// registration, independent of robcal's chain, kinematics and engine.

/// The rigid transform `(R, t)` that best maps `a` onto `b` in least
/// squares (Kabsch, by SVD).
pub fn kabsch(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> (Matrix3<f64>, Vector3<f64>) {
    let n = a.len() as f64;
    let ca = a.iter().sum::<Vector3<f64>>() / n;
    let cb = b.iter().sum::<Vector3<f64>>() / n;
    let h: Matrix3<f64> = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - ca) * (y - cb).transpose())
        .sum();
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
    let mut d = Matrix3::identity();
    if (vt.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = vt.transpose() * d * u.transpose();
    (r, cb - r * ca)
}

/// Says on the real stderr (libtest captures `eprintln!` of a passing
/// test, a direct write shows in `cargo test`'s output) why a test is
/// skipped.
pub fn skipped_note(why: &str) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr(), "{why}");
}
