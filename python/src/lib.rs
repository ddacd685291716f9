//! `robcal._robcal`: robcal's one engine behind a Python module (PyO3).
//!
//! Nothing here calibrates, predicts or writes a report of its own: each
//! call is the library's (`robcal::io::Job`, `robcal::calibrate`,
//! `robcal::render`, `robcal::calibrate::Predictor`), with the GIL released
//! while it runs. The pure-Python package around it (`python/robcal/`)
//! turns numpy arrays and DataFrames into what these take: arrays of
//! `f64` as their native-endian bytes, row-major; columns of a
//! measurement table as text cells or `f64` bytes.
//!
//! Errors are Python exceptions carrying the command's one-line message:
//! [`InputError`] (a file or table, with its line and column where there
//! is one), [`CalibrationError`] (the engine's), both an [`Error`].

#![forbid(unsafe_code)]

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;

use nalgebra::{UnitQuaternion, Vector3};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use robcal::calibrate::{self, DeflectionModel, Method, Payload, Predictor, Report, Settings};
use robcal::io::points::MAX_JOINT_RAD;
use robcal::io::units::{MAX_LOAD_KG, MAX_POSITION_M};
use robcal::render::files::{self, OutputFiles};
use robcal::render::html::JobInfo;
use robcal::robot::CompensateSettings;

create_exception!(
    _robcal,
    Error,
    PyException,
    "Every error robcal raises: the command's one-line message."
);
create_exception!(
    _robcal,
    InputError,
    Error,
    "A file or table robcal cannot read: the message names it, and the line and column where there is one."
);
create_exception!(
    _robcal,
    CalibrationError,
    Error,
    "The engine's: data that cannot be calibrated, a point that cannot be predicted or reached."
);

/// A message on one line, its quotes and length cut as the command's
/// (`robcal: error: …`).
fn one_line(e: impl std::fmt::Display) -> String {
    robcal::io::input::shorten(&e.to_string().replace(['\n', '\r'], " "))
}

fn input_error(e: impl std::fmt::Display) -> PyErr {
    InputError::new_err(one_line(e))
}

fn calibration_error(e: impl std::fmt::Display) -> PyErr {
    CalibrationError::new_err(one_line(e))
}

fn error(e: impl std::fmt::Display) -> PyErr {
    Error::new_err(one_line(e))
}

/// A count of at least one.
fn count(v: i64, what: &str) -> PyResult<usize> {
    usize::try_from(v)
        .ok()
        .filter(|&n| n >= 1)
        .ok_or_else(|| PyValueError::new_err(format!("{what} = {v}: expected at least 1")))
}

/// A marker id (0 to 2³² − 1).
fn marker_id(v: Option<i64>) -> PyResult<Option<u32>> {
    v.map(|m| {
        u32::try_from(m).map_err(|_| {
            PyValueError::new_err(format!(
                "marker = {m}: not a marker id (integer 0 to 4294967295)"
            ))
        })
    })
    .transpose()
}

/// `bytes` of native-endian `f64`s.
fn floats(b: &[u8], what: &str) -> PyResult<Vec<f64>> {
    if !b.len().is_multiple_of(8) {
        return Err(PyValueError::new_err(format!(
            "{what}: {} bytes are not a whole number of float64",
            b.len()
        )));
    }
    Ok(b.chunks_exact(8)
        .map(|c| f64::from_ne_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
        .collect())
}

fn to_bytes<'py>(py: Python<'py>, v: &[f64]) -> Bound<'py, PyBytes> {
    let mut b = Vec::with_capacity(8 * v.len());
    for x in v {
        b.extend_from_slice(&x.to_ne_bytes());
    }
    PyBytes::new(py, &b)
}

/// A calibration job: the setup and the robot it names.
#[pyclass(frozen, module = "robcal._robcal")]
struct Job {
    inner: Arc<robcal::io::Job>,
}

/// A measurement file (or table) read for a job.
#[pyclass(frozen, module = "robcal._robcal")]
struct Measurements {
    inner: Arc<robcal::io::Measurements>,
}

/// `ROBCAL_MAX_HELD_DESIGN_ROWS`, as the command reads it.
fn max_held_design_rows() -> PyResult<usize> {
    match std::env::var("ROBCAL_MAX_HELD_DESIGN_ROWS") {
        Err(std::env::VarError::NotPresent) => {
            Ok(calibrate::Policy::default().max_held_design_rows)
        }
        Ok(v) => v.trim().parse().map_err(|_| {
            error(format!(
                "ROBCAL_MAX_HELD_DESIGN_ROWS={v:?}: expected a number of rows"
            ))
        }),
        Err(e) => Err(error(format!("ROBCAL_MAX_HELD_DESIGN_ROWS: {e}"))),
    }
}

#[pymethods]
impl Job {
    /// Reads the setup file and the URDF it names.
    #[staticmethod]
    fn load(py: Python<'_>, setup_path: PathBuf) -> PyResult<Self> {
        let job = py
            .detach(|| robcal::io::Job::load(&setup_path))
            .map_err(input_error)?;
        Ok(Self {
            inner: Arc::new(job),
        })
    }

    /// A job from text: the setup's TOML and the URDF; the names stand for
    /// them in errors.
    #[staticmethod]
    #[pyo3(signature = (setup_toml, urdf, setup_name = "setup.toml", urdf_name = "robot.urdf"))]
    fn parse(setup_toml: &str, urdf: &str, setup_name: &str, urdf_name: &str) -> PyResult<Self> {
        let job =
            robcal::io::Job::parse(setup_toml, setup_name, urdf, urdf_name).map_err(input_error)?;
        Ok(Self {
            inner: Arc::new(job),
        })
    }

    /// The robot's name (the URDF's).
    #[getter]
    fn robot_name(&self) -> String {
        self.inner.robot.name.clone()
    }

    /// The movable joints' names, chain order: the measurement table's
    /// joint columns.
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.inner.robot.joint_names.clone()
    }

    /// Whether each joint is angular (revolute): its column is in the
    /// setup's angle unit, else in its length unit.
    #[getter]
    fn joint_is_angular(&self) -> Vec<bool> {
        self.inner
            .robot
            .chain
            .joints()
            .iter()
            .map(|j| j.kind == robcal::JointKind::Revolute)
            .collect()
    }

    /// The setup's units: `(angle, length)`, e.g. `("deg", "mm")`.
    #[getter]
    fn units(&self) -> (String, String) {
        let u = self.inner.setup.units;
        let angle = match u.angle {
            robcal::io::units::AngleUnit::Deg => "deg",
            robcal::io::units::AngleUnit::Rad => "rad",
        };
        let length = match u.length {
            robcal::io::units::LengthUnit::Mm => "mm",
            robcal::io::units::LengthUnit::M => "m",
        };
        (angle.to_string(), length.to_string())
    }

    /// The setup's marker ids.
    #[getter]
    fn markers(&self) -> Vec<u32> {
        self.inner.setup.markers.iter().map(|m| m.id).collect()
    }

    /// The setup as TOML text.
    fn setup_toml(&self) -> String {
        self.inner.setup.to_toml()
    }

    /// Reads a measurement CSV of this job (at most `max_bytes`).
    #[pyo3(signature = (path, max_bytes = 1 << 30))]
    fn read_measurements(
        &self,
        py: Python<'_>,
        path: PathBuf,
        max_bytes: u64,
    ) -> PyResult<Measurements> {
        let m = py
            .detach(|| self.inner.read_measurements_limited(&path, max_bytes))
            .map_err(input_error)?;
        Ok(Measurements { inner: Arc::new(m) })
    }

    /// Reads measurement CSV text of this job; `name` stands for it in
    /// errors.
    #[pyo3(signature = (text, name = "<measurements>"))]
    fn parse_measurements(
        &self,
        py: Python<'_>,
        text: &[u8],
        name: &str,
    ) -> PyResult<Measurements> {
        let job = &self.inner;
        let m = py
            .detach(|| robcal::io::parse_measurements(text, name, &job.robot, &job.setup))
            .map_err(input_error)?;
        Ok(Measurements { inner: Arc::new(m) })
    }

    /// A measurement table of this job from columns: `(header, cells)`
    /// pairs, each column either a list of text cells or the bytes of its
    /// `f64` values, all of `rows` rows. The table is read as the CSV it
    /// writes (the one reader, its checks and messages; line `k` is row
    /// `k − 2`); `name` stands for it in errors.
    #[pyo3(signature = (columns, rows, name = "<table>"))]
    fn table_measurements(
        &self,
        py: Python<'_>,
        columns: Vec<(String, Bound<'_, PyAny>)>,
        rows: usize,
        name: &str,
    ) -> PyResult<Measurements> {
        enum Cells {
            Text(Vec<String>),
            Floats(Vec<f64>),
        }
        if columns.is_empty() && rows > 0 {
            return Err(PyValueError::new_err(
                "a measurement table needs its columns (config, marker, the joints, x, y, z, …)",
            ));
        }
        let mut cols = Vec::with_capacity(columns.len());
        for (header, cells) in &columns {
            let c = if let Ok(b) = cells.cast::<PyBytes>() {
                Cells::Floats(floats(b.as_bytes(), header)?)
            } else {
                Cells::Text(cells.extract::<Vec<String>>().map_err(|_| {
                    pyo3::exceptions::PyTypeError::new_err(format!(
                        "column {header:?}: expected float64 bytes or a list of str"
                    ))
                })?)
            };
            let n = match &c {
                Cells::Text(v) => v.len(),
                Cells::Floats(v) => v.len(),
            };
            if n != rows {
                return Err(PyValueError::new_err(format!(
                    "column {header:?} has {n} values, the table {rows} rows"
                )));
            }
            cols.push(c);
        }
        let job = &self.inner;
        let headers: Vec<String> = columns
            .iter()
            .map(|c| robcal::io::writer::csv_cell(&c.0))
            .collect();
        let m = py.detach(|| {
            // Every row was given (checked above): about 16 bytes a cell.
            let mut text = String::with_capacity(rows.saturating_mul(16 * cols.len()).min(1 << 30));
            text.push_str(&headers.join(","));
            text.push('\n');
            for r in 0..rows {
                for (k, c) in cols.iter().enumerate() {
                    if k > 0 {
                        text.push(',');
                    }
                    match c {
                        Cells::Text(v) => text.push_str(&robcal::io::writer::csv_cell(&v[r])),
                        // A NaN is pandas' missing value: an empty cell (a
                        // point's empty plane cells, a pose's empty
                        // orientation). Else Rust's shortest representation:
                        // the same f64 read back.
                        Cells::Floats(v) if v[r].is_nan() => {}
                        Cells::Floats(v) => {
                            let _ = write!(text, "{}", v[r]);
                        }
                    }
                }
                text.push('\n');
            }
            robcal::io::parse_measurements(text.as_bytes(), name, &job.robot, &job.setup)
        });
        Ok(Measurements {
            inner: Arc::new(m.map_err(input_error)?),
        })
    }

    /// Calibrates `data` (the command's `robcal calibrate`, the same
    /// settings by the same names); `validate`: evaluate the result on
    /// another file, `reregister` its frame re-fitted. The GIL is released
    /// while it runs.
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (data, *, method = "irls", lambda_ = None, max_iter = 100, diagnose = true,
        linear = false, leave_out_outliers = false, robust = false, validate = None, reregister = false))]
    fn calibrate(
        &self,
        py: Python<'_>,
        data: &Measurements,
        method: &str,
        lambda_: Option<f64>,
        max_iter: i64,
        diagnose: bool,
        linear: bool,
        leave_out_outliers: bool,
        robust: bool,
        validate: Option<PyRef<'_, Measurements>>,
        reregister: bool,
    ) -> PyResult<Calibration> {
        let method = match method {
            "irls" => Method::Irls,
            "wls" => Method::Wls,
            "ols" => Method::Ols,
            m => {
                return Err(PyValueError::new_err(format!(
                    "method {m:?}: expected 'irls', 'wls' or 'ols'"
                )))
            }
        };
        if let Some(l) = lambda_ {
            if !(l.is_finite() && l >= 0.0) {
                return Err(PyValueError::new_err(format!(
                    "lambda_ = {l}: expected a finite number >= 0"
                )));
            }
        }
        let max_iter = count(max_iter, "max_iter")?;
        if reregister && validate.is_none() {
            return Err(PyValueError::new_err("reregister needs validate"));
        }
        let settings = Settings {
            method,
            lambda: lambda_,
            max_iterations: max_iter,
            diagnose,
            deflection_model: if linear {
                DeflectionModel::Linear
            } else {
                DeflectionModel::Exact
            },
            leave_out_outliers,
            robust,
            policy: calibrate::Policy {
                max_held_design_rows: max_held_design_rows()?,
                ..Default::default()
            },
            ..Settings::default()
        };
        let job = Arc::clone(&self.inner);
        let m = Arc::clone(&data.inner);
        let v = validate.as_ref().map(|v| Arc::clone(&v.inner));
        let report = py.detach(|| {
            let mut report = calibrate::calibrate(&job, &m, &settings, &mut |_| {})
                .map_err(|e| e.to_string())?;
            if let Some(v) = &v {
                let v = calibrate::validate_with(&report.model, &job, v, reregister)
                    .map_err(|e| e.to_string())?;
                report.set_validation(v);
            }
            Ok::<_, String>(report)
        });
        let report = report.map_err(calibration_error)?;
        Ok(Calibration {
            lambda: lambda_.unwrap_or(self.inner.setup.noise.lambda),
            job: Arc::clone(&self.inner),
            data: data.inner.file.clone(),
            validate: v.map(|v| v.file.clone()),
            report,
        })
    }
}

#[pymethods]
impl Measurements {
    /// The file (or the name a table was given).
    #[getter]
    fn file(&self) -> String {
        self.inner.file.display().to_string()
    }

    /// The reader's warnings, one line each.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.inner.warnings.iter().map(|w| w.to_string()).collect()
    }

    /// The measured points (rows of the file).
    fn __len__(&self) -> usize {
        self.inner.observations.len()
    }
}

/// A calibration's result: the report, and the calibrated robot.
#[pyclass(frozen, module = "robcal._robcal")]
struct Calibration {
    report: Report,
    job: Arc<robcal::io::Job>,
    data: PathBuf,
    validate: Option<PathBuf>,
    lambda: f64,
}

impl Calibration {
    fn files(&self, keep_nominal_markers: bool) -> Result<OutputFiles, String> {
        let info = JobInfo {
            job: &self.job,
            data: &self.data,
            validate: self.validate.as_deref(),
            lambda: self.lambda,
        };
        OutputFiles::of(
            &self.report,
            &info,
            calibrate::export::UrdfOptions {
                keep_nominal_markers,
            },
        )
    }
}

#[pymethods]
impl Calibration {
    /// The contract's JSON (`robcal calibrate --json`), the same text.
    fn json(&self) -> PyResult<String> {
        files::report_json(&self.report).map_err(error)
    }

    /// The text report (`robcal calibrate` without `--json`).
    fn text(&self) -> String {
        self.report.to_string()
    }

    fn __str__(&self) -> String {
        self.report.to_string()
    }

    /// Why the result is not a calibration (the command exits 1), or None.
    #[getter]
    fn failure(&self) -> Option<String> {
        self.report.failure.clone()
    }

    /// The parameters: `(name, value, std, unit, determined)` each, in the
    /// reported units.
    #[getter]
    fn parameters(&self) -> Vec<(String, f64, f64, String, bool)> {
        self.report
            .parameters
            .iter()
            .map(|p| (p.name.clone(), p.value, p.std, p.unit.clone(), p.determined))
            .collect()
    }

    /// The parameters' covariance (eq. 8, 11), row-major `f64` bytes, in the
    /// product of the two parameters' units.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        let c = &self.report.covariance;
        let v: Vec<f64> = (0..c.nrows())
            .flat_map(|i| (0..c.ncols()).map(move |k| c[(i, k)]))
            .collect();
        to_bytes(py, &v)
    }

    /// `robcal calibrate --output DIR`'s files, by file name, as text.
    #[pyo3(signature = (keep_nominal_markers = false))]
    fn output_files<'py>(
        &self,
        py: Python<'py>,
        keep_nominal_markers: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let f = py
            .detach(|| self.files(keep_nominal_markers))
            .map_err(error)?;
        let d = PyDict::new(py);
        d.set_item("robot.urdf", f.urdf)?;
        d.set_item("model.json", f.model_json)?;
        d.set_item("report.html", f.report_html)?;
        for g in f.figures {
            d.set_item(g.file, g.svg)?;
        }
        Ok(d)
    }

    /// Writes `--output DIR`'s files into `dir` (made when missing), all or
    /// nothing.
    #[pyo3(signature = (dir, keep_nominal_markers = false))]
    fn write(&self, py: Python<'_>, dir: PathBuf, keep_nominal_markers: bool) -> PyResult<()> {
        py.detach(|| {
            let f = self.files(keep_nominal_markers)?;
            let robot = self.job.setup.robot_path(&self.job.setup_path);
            let mut inputs = vec![self.data.as_path(), self.job.setup_path.as_path()];
            if self.job.urdf_text.is_none() {
                inputs.push(robot.as_path());
            }
            inputs.extend(self.validate.as_deref());
            robcal::io::atomic::write_dirs(vec![(&dir, f.into_files(&dir))], &inputs)
        })
        .map_err(error)
    }

    /// The calibrated robot (the predictor `model.json` holds).
    fn model(&self) -> Model {
        Model {
            inner: Predictor::new(&self.report.model, &self.job),
        }
    }
}

/// A calibrated robot: predicts where a marker settles, and the joint
/// command that reaches a target.
#[pyclass(frozen, module = "robcal._robcal")]
struct Model {
    inner: Predictor,
}

/// The largest model file read \[bytes\] (the command's).
const MAX_MODEL_BYTES: u64 = 64 << 20;

/// A number as written in a message: short, with an exponent when large.
fn short(x: f64) -> String {
    if x.is_finite() && x.abs() >= 1e6 {
        format!("{x:e}")
    } else {
        x.to_string()
    }
}

/// Checks that every value of `v` is finite and within `±max`.
fn within(v: &[f64], max: f64, what: &str, unit: &str) -> PyResult<()> {
    match v.iter().position(|x| !(x.is_finite() && x.abs() <= max)) {
        None => Ok(()),
        Some(i) => Err(PyValueError::new_err(format!(
            "{what}: value {i} is {}: expected a finite value within ±{max} {unit}",
            short(v[i])
        ))),
    }
}

impl Model {
    /// The joint values' bounds and units, chain order.
    fn check_q(&self, q: &[f64], what: &str) -> PyResult<()> {
        let dof = self.inner.dof();
        for (k, j) in self.inner.chain().joints().iter().enumerate() {
            let col: Vec<f64> = q.iter().skip(k).step_by(dof).copied().collect();
            let (max, unit) = match j.kind {
                robcal::JointKind::Revolute => (MAX_JOINT_RAD, "rad"),
                robcal::JointKind::Prismatic => (MAX_POSITION_M, "m"),
            };
            within(&col, max, &format!("{what} column {k}"), unit)?;
        }
        Ok(())
    }

    /// The payloads of `n` rows: `load_kg` one or `n` masses, `com_m`
    /// three or `3n` coordinates; none where the mass is 0.
    fn payloads(&self, n: usize, load_kg: &[f64], com_m: &[f64]) -> PyResult<Vec<Option<Payload>>> {
        within(load_kg, MAX_LOAD_KG, "load_kg", "kg")?;
        if let Some(i) = load_kg.iter().position(|&m| m < 0.0) {
            return Err(PyValueError::new_err(format!(
                "load_kg: value {i} is {}: a mass is >= 0",
                load_kg[i]
            )));
        }
        within(com_m, MAX_POSITION_M, "com_m", "m")?;
        if !(load_kg.len() == 1 || load_kg.len() == n) {
            return Err(PyValueError::new_err(format!(
                "load_kg: {} values for {n} rows",
                load_kg.len()
            )));
        }
        if !(com_m.len() == 3 || com_m.len() == 3 * n) {
            return Err(PyValueError::new_err(format!(
                "com_m: {} values for {n} rows: expected 3 or {}",
                com_m.len(),
                3 * n
            )));
        }
        Ok((0..n)
            .map(|r| {
                let m = load_kg[if load_kg.len() == 1 { 0 } else { r }];
                let c = if com_m.len() == 3 { 0 } else { 3 * r };
                (m > 0.0).then(|| Payload {
                    mass_kg: m,
                    com_m: Vector3::new(com_m[c], com_m[c + 1], com_m[c + 2]),
                })
            })
            .collect())
    }

    fn rows(&self, q: &[f64]) -> PyResult<usize> {
        let dof = self.inner.dof();
        if q.is_empty() || !q.len().is_multiple_of(dof) {
            return Err(PyValueError::new_err(format!(
                "q: {} values are not rows of {dof} joints",
                q.len()
            )));
        }
        Ok(q.len() / dof)
    }
}

#[pymethods]
impl Model {
    /// Reads a model file (`DIR/model.json`).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let text = robcal::io::input::read_text(&path, "the model file", MAX_MODEL_BYTES)
            .map_err(input_error)?;
        Self::from_json(&text, &path.display().to_string())
    }

    /// A model from `model.json`'s text; `name` stands for it in errors.
    #[staticmethod]
    #[pyo3(signature = (text, name = "<model.json>"))]
    fn from_json(text: &str, name: &str) -> PyResult<Self> {
        let (inner, _) = robcal::render::json::read_model(text)
            .map_err(|m| input_error(format!("{name}: {m}")))?;
        Ok(Self { inner })
    }

    /// The movable joints' names, chain order.
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.inner.joint_names().to_vec()
    }

    /// Whether each joint is angular (rad), else prismatic (m).
    #[getter]
    fn joint_is_angular(&self) -> Vec<bool> {
        self.inner
            .chain()
            .joints()
            .iter()
            .map(|j| j.kind == robcal::JointKind::Revolute)
            .collect()
    }

    /// The links' thermal expansion: `(α [1/K], the temperature [°C] the
    /// lengths hold at)`, or `None`.
    #[getter]
    fn thermal_expansion(&self) -> Option<(f64, f64)> {
        self.inner.thermal_expansion()
    }

    /// The robot at `temp_c` \[°C\] (`robcal predict --temperature-c`).
    fn at_temperature(&self, temp_c: f64) -> PyResult<Self> {
        let inner = self
            .inner
            .at_temperature(temp_c)
            .map_err(calibration_error)?;
        Ok(Self { inner })
    }

    /// The markers: `(id, [x, y, z])` \[m, tip frame\] each, calibrated.
    #[getter]
    fn markers(&self) -> Vec<(u32, [f64; 3])> {
        self.inner.markers().map(|(i, p)| (i, p.into())).collect()
    }

    /// Where the marker settles \[m, measurement frame\] for each row of
    /// joint values `q` (`f64` bytes, rows of `dof`, rad or m) with the
    /// payload `load_kg` (kg; one or one per row) at `com_m` (m, tip frame;
    /// one or one per row): `f64` bytes, three per row. With `orientation`,
    /// the orientation a 6-D instrument measures there instead: the tip
    /// frame turned by the identified tool frame, at the robot's
    /// equilibrium, as a rotation vector \[rad, measurement frame\]
    /// (`robcal predict --orientation`'s `rx_rad, ry_rad, rz_rad`).
    /// Releases the GIL.
    #[pyo3(signature = (q, load_kg, com_m, marker = None, orientation = false))]
    fn predict<'py>(
        &self,
        py: Python<'py>,
        q: &[u8],
        load_kg: Vec<f64>,
        com_m: Vec<f64>,
        marker: Option<i64>,
        orientation: bool,
    ) -> PyResult<Bound<'py, PyBytes>> {
        let marker = marker_id(marker)?;
        let q = floats(q, "q")?;
        let n = self.rows(&q)?;
        self.check_q(&q, "q")?;
        let payloads = self.payloads(n, &load_kg, &com_m)?;
        let (_, tool, robot) = self.inner.at_marker(marker).map_err(calibration_error)?;
        let dof = robot.dof();
        let out = py.detach(|| {
            let mut out = Vec::with_capacity(3 * n);
            for (r, payload) in payloads.iter().enumerate() {
                let (q, payload) = (&q[r * dof..(r + 1) * dof], payload.as_ref());
                let p = if orientation {
                    robot
                        .predict_rotation(&tool, q, payload)
                        .map(|r| r.scaled_axis())
                } else {
                    robot.predict(&tool, q, payload)
                };
                out.extend_from_slice(
                    p.map_err(|e| format!("row {r}: cannot predict: {e}"))?
                        .as_slice(),
                );
            }
            Ok::<_, String>(out)
        });
        Ok(to_bytes(py, &out.map_err(calibration_error)?))
    }

    /// The joint commands whose loaded, deflected robot puts the marker on
    /// each target \[m, measurement frame; `f64` bytes, three per row\],
    /// Newton from `q_start` (rows of `dof`); with `rotation_rad` (three
    /// per row, a rotation vector of the tip frame) a pose. Returns the
    /// commands' bytes, the error left per row \[µm\], the orientation's
    /// \[µrad\] (or None) and Newton's steps. Releases the GIL.
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    #[pyo3(signature = (targets_m, q_start, load_kg, com_m, marker = None, rotation_rad = None,
        tolerance_um = 0.1, max_iter = 20))]
    fn compensate<'py>(
        &self,
        py: Python<'py>,
        targets_m: &[u8],
        q_start: &[u8],
        load_kg: Vec<f64>,
        com_m: Vec<f64>,
        marker: Option<i64>,
        rotation_rad: Option<&[u8]>,
        tolerance_um: f64,
        max_iter: i64,
    ) -> PyResult<(Bound<'py, PyBytes>, Vec<f64>, Option<Vec<f64>>, Vec<usize>)> {
        let q = floats(q_start, "q_start")?;
        let n = self.rows(&q)?;
        self.check_q(&q, "q_start")?;
        let t = floats(targets_m, "targets_m")?;
        if t.len() != 3 * n {
            return Err(PyValueError::new_err(format!(
                "targets_m: {} values for {n} rows: expected {}",
                t.len(),
                3 * n
            )));
        }
        within(&t, MAX_POSITION_M, "targets_m", "m")?;
        let rot = rotation_rad
            .map(|r| floats(r, "rotation_rad"))
            .transpose()?;
        if let Some(r) = &rot {
            if r.len() != 3 * n {
                return Err(PyValueError::new_err(format!(
                    "rotation_rad: {} values for {n} rows: expected {}",
                    r.len(),
                    3 * n
                )));
            }
            within(r, MAX_JOINT_RAD, "rotation_rad", "rad")?;
        }
        if !(tolerance_um.is_finite() && tolerance_um > 0.0) {
            return Err(PyValueError::new_err(format!(
                "tolerance_um = {tolerance_um}: expected a finite number > 0"
            )));
        }
        let max_iter = count(max_iter, "max_iter")?;
        let marker = marker_id(marker)?;
        let payloads = self.payloads(n, &load_kg, &com_m)?;
        let (_, tool, robot) = self.inner.at_marker(marker).map_err(calibration_error)?;
        let settings = CompensateSettings {
            tolerance_m: tolerance_um * 1e-6,
            max_iterations: max_iter,
            ..CompensateSettings::new()
        };
        let dof = robot.dof();
        let out = py.detach(|| {
            let mut qs = Vec::with_capacity(n * dof);
            let (mut err, mut err_rot, mut its) = (Vec::new(), Vec::new(), Vec::new());
            for (r, payload) in payloads.iter().enumerate() {
                let target = Vector3::new(t[3 * r], t[3 * r + 1], t[3 * r + 2]);
                let start = &q[r * dof..(r + 1) * dof];
                let c = match &rot {
                    None => robot.compensate(&tool, &target, start, payload.as_ref(), &settings),
                    Some(v) => robot.compensate_pose(
                        &tool,
                        &target,
                        &UnitQuaternion::from_scaled_axis(Vector3::new(
                            v[3 * r],
                            v[3 * r + 1],
                            v[3 * r + 2],
                        )),
                        start,
                        payload.as_ref(),
                        &settings,
                    ),
                }
                .map_err(|e| {
                    format!("row {r}: cannot reach the target from the given joint values: {e}")
                })?;
                qs.extend_from_slice(&c.q[..dof]);
                err.push(c.error_m * 1e6);
                err_rot.push(c.error_rad * 1e6);
                its.push(c.iterations);
            }
            Ok::<_, String>((qs, err, err_rot, its))
        });
        let (qs, err, err_rot, its) = out.map_err(calibration_error)?;
        Ok((to_bytes(py, &qs), err, rot.map(|_| err_rot), its))
    }

    /// The payload warning of these masses \[kg\] (heavier than the
    /// calibration's, or one the model cannot feel), or None.
    fn payload_warning(&self, load_kg: Vec<f64>) -> Option<String> {
        let loads: Vec<(usize, f64)> = load_kg.into_iter().enumerate().collect();
        self.inner.payload_warning(&loads)
    }
}

/// What a selection of poses predicts ([`robcal::calibrate::plan::Scores`]),
/// by the command's JSON keys.
fn scores<'py>(
    py: Python<'py>,
    s: &robcal::calibrate::plan::Scores,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("log_det", s.log_det)?;
    d.set_item("trace_scaled", s.trace)?;
    d.set_item("min_eigenvalue_scaled", s.min_eigen)?;
    d.set_item("condition", s.condition)?;
    d.set_item("predicted_rms_um", s.predicted_um)?;
    d.set_item("std", s.std.clone())?;
    Ok(d)
}

/// A plan: the configurations to measure and what they predict.
#[pyclass(frozen, module = "robcal._robcal")]
struct Plan {
    /// The chosen configurations' joint values, row-major.
    q: Vec<f64>,
    load_kg: Vec<f64>,
    csv: String,
    criterion: &'static str,
    candidates: usize,
    exchanges: usize,
    params: Vec<String>,
    units: Vec<String>,
    left_out: Vec<String>,
    notes: Vec<String>,
    planned: robcal::calibrate::plan::Scores,
    random: Option<robcal::calibrate::plan::Scores>,
}

#[pymethods]
impl Plan {
    /// The chosen configurations' joint values \[rad or m\], `f64` bytes,
    /// rows of the robot's joints in the order chosen.
    #[getter]
    fn q<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        to_bytes(py, &self.q)
    }

    /// Their payload masses \[kg\].
    #[getter]
    fn load_kg(&self) -> Vec<f64> {
        self.load_kg.clone()
    }

    /// The points CSV `robcal plan --output` writes, the same text.
    fn csv(&self) -> String {
        self.csv.clone()
    }

    /// The criterion (`d`, `a`, `i`, `e`, `condition`), the candidates
    /// chosen from, the greedy steps and exchanges made.
    #[getter]
    fn summary(&self) -> (&'static str, usize, usize) {
        (self.criterion, self.candidates, self.exchanges)
    }

    /// The parameters planned for and their units; those no candidate
    /// determines; what the plan assumed.
    #[getter]
    fn parameters(&self) -> (Vec<String>, Vec<String>, Vec<String>, Vec<String>) {
        (
            self.params.clone(),
            self.units.clone(),
            self.left_out.clone(),
            self.notes.clone(),
        )
    }

    /// What the plan predicts, and as many random candidates as drawn
    /// (None for a pool of the user's).
    fn scores<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyDict>, Option<Bound<'py, PyDict>>)> {
        let random = self.random.as_ref().map(|r| scores(py, r)).transpose()?;
        Ok((scores(py, &self.planned)?, random))
    }
}

/// `robcal plan`: the `poses` configurations of a pool of candidates that
/// determine the job's declared model best; the candidates drawn within
/// the joint limits (`limits` tighter, `(name, lo, hi)`), each with every
/// mass of `load_kg`, or `pool_q` (rows of joint values, `f64` bytes) with
/// `pool_load_kg`. The command's settings and checks. Releases the GIL.
#[allow(clippy::too_many_arguments)]
#[pyfunction]
#[pyo3(signature = (job, poses, *, candidates = 1000, pool_q = None, pool_load_kg = None,
    pool_path = None, criterion = "d", seed = 0x706c_616e, load_kg = Vec::new(),
    limits = Vec::new(), exchange_passes = 10, orientation_urad = None))]
fn plan(
    py: Python<'_>,
    job: &Job,
    poses: i64,
    candidates: i64,
    pool_q: Option<&[u8]>,
    pool_load_kg: Option<Vec<f64>>,
    pool_path: Option<PathBuf>,
    criterion: &str,
    seed: u64,
    load_kg: Vec<f64>,
    limits: Vec<(String, f64, f64)>,
    exchange_passes: i64,
    orientation_urad: Option<f64>,
) -> PyResult<Plan> {
    use robcal::calibrate::plan::{self as p, Candidate, Criterion, PlanSettings};
    let range = |v: i64, lo: i64, hi: i64, what: &str| {
        usize::try_from(v)
            .ok()
            .filter(|_| (lo..=hi).contains(&v))
            .ok_or_else(|| PyValueError::new_err(format!("{what} = {v}: expected {lo} to {hi}")))
    };
    let poses = range(poses, 1, 100_000, "poses")?;
    let candidates = range(candidates, 1, p::MAX_CANDIDATES as i64, "candidates")?;
    let exchange_passes = range(exchange_passes, 0, 100, "exchange_passes")?;
    if let Some(s) = orientation_urad.filter(|s| !(s.is_finite() && *s > 0.0)) {
        return Err(PyValueError::new_err(format!(
            "orientation_urad = {}: a number above 0",
            short(s)
        )));
    }
    let criterion = match criterion {
        "d" => Criterion::D,
        "a" => Criterion::A,
        "i" => Criterion::I,
        "e" => Criterion::E,
        "condition" => Criterion::Condition,
        c => {
            return Err(PyValueError::new_err(format!(
                "criterion {c:?}: expected 'd', 'a', 'i', 'e' or 'condition'"
            )))
        }
    };
    let max = MAX_LOAD_KG;
    for m in load_kg.iter().chain(pool_load_kg.iter().flatten()) {
        if !(m.is_finite() && (0.0..=max).contains(m)) {
            return Err(PyValueError::new_err(format!(
                "load_kg: {}: a mass from 0 to {max} kg",
                short(*m)
            )));
        }
    }
    for (name, lo, hi) in &limits {
        within(
            &[*lo, *hi],
            MAX_JOINT_RAD.max(MAX_POSITION_M),
            &format!("limits {name:?}"),
            "rad or m",
        )?;
    }
    let settings = PlanSettings {
        poses,
        candidates,
        criterion,
        seed,
        loads_kg: load_kg,
        limits,
        exchange_passes,
        orientation_sigma_urad: orientation_urad,
    };
    let job = Arc::clone(&job.inner);
    let dof = job.robot.dof();
    let pool_candidates = match (pool_q, pool_path) {
        (Some(_), Some(_)) => {
            return Err(PyValueError::new_err(
                "a pool of rows or a pool file, not both",
            ))
        }
        (None, Some(path)) => Some(p::read_pool(&job, &path).map_err(input_error)?),
        (None, None) => None,
        (Some(b), None) => {
            let q = floats(b, "pool_q")?;
            if q.is_empty() || !q.len().is_multiple_of(dof) {
                return Err(PyValueError::new_err(format!(
                    "pool_q: {} values are not rows of {dof} joints",
                    q.len()
                )));
            }
            let n = q.len() / dof;
            within(&q, MAX_JOINT_RAD.max(MAX_POSITION_M), "pool_q", "rad or m")?;
            let loads = pool_load_kg.unwrap_or_else(|| vec![0.0]);
            if !(loads.len() == 1 || loads.len() == n) {
                return Err(PyValueError::new_err(format!(
                    "pool_load_kg: {} values for {n} rows",
                    loads.len()
                )));
            }
            Some(
                (0..n)
                    .map(|r| Candidate {
                        q: q[r * dof..(r + 1) * dof].to_vec(),
                        load_kg: loads[if loads.len() == 1 { 0 } else { r }],
                    })
                    .collect::<Vec<_>>(),
            )
        }
    };
    let out = py.detach(|| {
        let policy = calibrate::Policy::default();
        let (pool, planned, baseline) =
            p::make(&job, &settings, pool_candidates, &policy).map_err(|e| e.to_string())?;
        let csv = p::points_csv(&job, &pool, &planned.chosen);
        let q = planned
            .chosen
            .iter()
            .flat_map(|&c| pool.candidates[c].q.iter().copied())
            .collect();
        let load_kg = planned
            .chosen
            .iter()
            .map(|&c| pool.candidates[c].load_kg)
            .collect();
        Ok::<_, String>(Plan {
            q,
            load_kg,
            csv,
            criterion: planned.criterion.name(),
            candidates: pool.candidates.len(),
            exchanges: planned.exchanges,
            params: pool.params.clone(),
            units: pool.units.clone(),
            left_out: pool.left_out.clone(),
            notes: pool.notes.clone(),
            planned: planned.scores,
            random: baseline,
        })
    });
    out.map_err(calibration_error)
}

/// `robcal import figaroh-mocap`: a FIGAROH mocap CSV into the contract
/// CSV at `output` (rad, m), joints in `job`'s chain order when given;
/// `output` untouched on error. Returns `(postures, rows)`.
#[pyfunction]
#[pyo3(signature = (input, output, job = None))]
fn import_figaroh_mocap(
    py: Python<'_>,
    input: PathBuf,
    output: PathBuf,
    job: Option<PyRef<'_, Job>>,
) -> PyResult<(usize, usize)> {
    let job = job.map(|j| Arc::clone(&j.inner));
    let r = py
        .detach(|| {
            robcal::io::figaroh::import_mocap(&input, &output, job.as_ref().map(|j| &j.robot))
        })
        .map_err(input_error)?;
    Ok((r.postures, r.rows))
}

/// `robcal import poses`: the real data sets' wide pose CSV (and 6-D
/// exports: quaternion or Euler columns per marker) into the contract CSV
/// at `output` (rad, m), only the rows of `split` when given; `euler`
/// names the Euler columns' convention (`"fixed-xyz"`, `"moving-xyz"`, …);
/// `output` untouched on error. Returns `(poses, rows, warnings)`.
#[pyfunction]
#[pyo3(signature = (input, output, split = None, euler = None))]
fn import_poses(
    py: Python<'_>,
    input: PathBuf,
    output: PathBuf,
    split: Option<String>,
    euler: Option<String>,
) -> PyResult<(usize, usize, Vec<String>)> {
    let euler = euler
        .map(|e| e.parse::<robcal::io::poses::Euler>())
        .transpose()
        .map_err(pyo3::exceptions::PyValueError::new_err)?;
    let options = robcal::io::poses::ImportOptions { split, euler };
    let r = py
        .detach(|| robcal::io::poses::import_poses(&input, &output, &options))
        .map_err(input_error)?;
    Ok((r.poses, r.rows, r.warnings))
}

/// The native module.
#[pymodule]
fn _robcal(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("Error", py.get_type::<Error>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("CalibrationError", py.get_type::<CalibrationError>())?;
    m.add_class::<Job>()?;
    m.add_class::<Measurements>()?;
    m.add_class::<Calibration>()?;
    m.add_class::<Model>()?;
    m.add_class::<Plan>()?;
    m.add_function(wrap_pyfunction!(plan, m)?)?;
    m.add_function(wrap_pyfunction!(import_figaroh_mocap, m)?)?;
    m.add_function(wrap_pyfunction!(import_poses, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
