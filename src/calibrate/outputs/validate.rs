//! `--validate`: the calibrated model on another measurement file of the
//! same job, nothing re-estimated.
//!
//! Every point is predicted by [`Predictor`], the code path of
//! compensation: an absolute position is the marker at the robot's
//! equilibrium under its own weight; a deflection is the marker under the
//! load (the setup's `[load] com`, plus the fitted `load_com` shift when
//! the model has one) minus the marker without it, the own weight left out
//! of both as the calibration's deflection rows leave it out
//! ([`Predictor::predict_deflection`]). The drift of the
//! measurement system is a property of the calibration session and is not
//! carried over to another file. A model with the links' thermal
//! expansion predicts an absolute point at the temperature the file gives
//! it ([`Predictor::at_temperature`]); a deflection at the reference (its
//! loaded and unloaded points are measured moments apart: the
//! temperature's change between them is not carried over). A 6-D pose's
//! orientation is validated apart, in µrad
//! ([`crate::calibrate::report::OrientationValidation`]): the frame
//! [`Predictor::predict_marker_rotation`] predicts against the measured
//! one, as measured. A plane contact's or a distance's number is
//! validated apart too, in µm
//! ([`crate::calibrate::report::ScalarValidation`]): the measured number
//! against the one of the model's point (in a file of those alone they are
//! the validation's errors, and nothing is re-registered).
//!
//! **Re-registration.** A file measured with the tracker set up elsewhere
//! differs from the calibration's frame by a rigid transform, which moves
//! every point. With three absolute points or more, the file's frame is
//! re-fitted with the calibrated model held fixed — every effect kept,
//! only the transform fitted, as the calibration registers its base
//! ([`Geometry::register`], unweighted) — and the error after it is
//! reported beside the error as measured
//! ([`crate::calibrate::report::Reregistration`]; deflections turned by
//! its rotation). [`validate_with`] and `--reregister` make it the
//! headline; without it, a file that fits [`Policy::reregistration_gain`]
//! times better re-registered is a warning
//! ([`crate::calibrate::report::plausibility::check_validation`]).
//!
//! [`Policy::reregistration_gain`]: crate::calibrate::settings::Policy::reregistration_gain

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Matrix3, Point3, Vector3};

use crate::calibrate::effects::declared::needs_absolute;
use crate::calibrate::fit::residuals::rms_um;
use crate::calibrate::outputs::predict::{Payload, Predictor};
use crate::calibrate::params::geometry::{Geometry, J};
use crate::calibrate::report::calibrated::CalibratedModel;
use crate::calibrate::report::{
    Nominal, OrientationValidation, Reregistration, ScalarValidation, Validation,
};
use crate::calibrate::rows::{RowKind, Rows};
use crate::calibrate::settings::CalibrationError;
use crate::error::Error;
use crate::io::{job::Job, measurements::Measurements};
use crate::robot::Chain;

/// Evaluates `model` on `data` (rows of the kinds the calibration used,
/// predicted by [`Predictor`]): the norm RMSE of each marker's position
/// error \[mm\], as measured; the re-registration beside it (see the
/// module docs).
///
/// A joint with a compensator table at an angle the calibration did not
/// measure gets the table's linear interpolation (held at its ends), and
/// the point is counted in [`Validation::interpolated_points`].
///
/// # Errors
/// [`CalibrationError::Data`] when the file has no row of the kinds the
/// calibration used; [`CalibrationError::NoEquilibrium`] at a row where
/// the loaded robot has no equilibrium under the calibrated joint law.
pub fn validate(
    model: &CalibratedModel,
    job: &Job,
    data: &Measurements,
) -> Result<Validation, CalibrationError> {
    validate_with(model, job, data, false)
}

/// [`validate`], its errors those after the file's measurement frame is
/// re-fitted when `reregister` (and the file has three absolute points or
/// more: else as measured, [`Validation::reregistered`] false).
///
/// # Errors
/// As [`validate`].
pub fn validate_with(
    model: &CalibratedModel,
    job: &Job,
    data: &Measurements,
    reregister: bool,
) -> Result<Validation, CalibrationError> {
    let mut names = model.names.clone();
    let mut rows = Rows::new(job, data, needs_absolute(job), &mut names, &model.policy)?;
    // The points; a pose's orientation apart (module `rows::orientation`),
    // and a plane contact or a distance (module `rows::scalar`), when the
    // calibration took absolute rows.
    let poses: Vec<_> = (rows.rows.iter())
        .filter(|r| r.orientation && model.kinds.absolute)
        .map(|r| (usize::from(r.marker), r.q.clone(), r.measured, r.line()))
        .collect();
    let numbers: Vec<_> = (rows.rows.iter())
        .filter(|_| model.kinds.absolute)
        .filter_map(|r| {
            let s = r.scalar().copied()?;
            Some((s, r.marker, r.q.clone(), r.line(), r.dtemp_k()))
        })
        .collect();
    rows.rows.retain(|r| match r.kind {
        RowKind::Deflection => model.kinds.deflections,
        RowKind::Absolute => model.kinds.absolute && !r.orientation && r.scalar().is_none(),
    });
    // A compensator table answers between its calibrated angles by linear
    // interpolation (Linearisation::compliance_at); count those points.
    let interpolated_points = rows
        .rows
        .iter()
        .filter(|r| !model.linearisation.interpolated(&r.q).is_empty())
        .count();
    let robot = Predictor::new(model, job);
    let payload_com = rows.com + robot.load_com_shift_m();
    // With a thermal expansion, the robot at the temperature of an
    // absolute row `dtemp_k` over the reference (none: `robot` itself).
    let warm = |dtemp_k: Option<f64>| match (
        robot.thermal_expansion(),
        &rows.temperature_ref_c,
        dtemp_k,
    ) {
        (Some(_), Some((_, mean)), Some(dt)) => robot.at_temperature(mean + dt).map(Some),
        _ => Ok(None),
    };
    let mut all = Vec::new();
    let mut per: BTreeMap<u32, Vec<Vector3<f64>>> = BTreeMap::new();
    // Each point: its kind, marker id, prediction and measurement [m].
    let mut points = Vec::new();
    for row in &rows.rows {
        let at = |e: Error| {
            CalibrationError::NoEquilibrium(format!(
                "{}:{}: the calibrated model cannot predict this point ({e})",
                data.file.display(),
                row.line()
            ))
        };
        let m = usize::from(row.marker);
        let predicted = match row.kind {
            RowKind::Absolute => warm(row.dtemp_k())?
                .as_ref()
                .unwrap_or(&robot)
                .predict_marker(m, &row.q, None),
            RowKind::Deflection => {
                let payload = Payload {
                    mass_kg: row.load_kg(),
                    com_m: payload_com,
                };
                robot.predict_marker_deflection(m, &row.q, &payload)
            }
        }
        .map_err(at)?;
        let r = row.measured - predicted;
        all.push(r);
        per.entry(names.marker_id(row.marker)).or_default().push(r);
        points.push((
            row.kind,
            names.marker_id(row.marker),
            predicted,
            row.measured,
        ));
    }
    // Each plane contact's or distance's number left [m, on axis 0]: the
    // measured against the model's point's, as measured.
    let left = (numbers.iter())
        .map(|(s, marker, q, line, dtemp_k)| {
            let p = (warm(*dtemp_k)?.as_ref().unwrap_or(&robot))
                .predict_marker(usize::from(*marker), q, None)
                .map_err(|e| {
                    CalibrationError::NoEquilibrium(format!(
                        "{}:{line}: the calibrated model cannot predict this point ({e})",
                        data.file.display(),
                    ))
                })?;
            Ok((*marker, Vector3::new(s.value_m() - s.of(&p), 0.0, 0.0)))
        })
        .collect::<Result<Vec<_>, CalibrationError>>()?;
    let scalars = (!left.is_empty()).then(|| {
        let n = Nominal::of(&left.iter().map(|l| l.1).collect::<Vec<_>>());
        ScalarValidation {
            rows: left.len(),
            rms_um: n.rms_um,
            mean_um: n.mean_um,
            max_um: n.max_um,
        }
    });
    // In a file of those alone, they are the errors.
    if all.is_empty() {
        for (marker, r) in &left {
            all.push(*r);
            per.entry(names.marker_id(*marker)).or_default().push(*r);
        }
    }
    if all.is_empty() {
        return Err(CalibrationError::Data(format!(
            "{}: no point to validate on (no row of the kinds the calibration used: {})",
            data.file.display(),
            match (model.kinds.deflections, model.kinds.absolute) {
                (true, true) => "deflections and absolute positions",
                (true, false) => "deflections, i.e. loaded rows with their unloaded rows",
                _ => "absolute positions",
            }
        )));
    }
    // Each pose's rotation left [rad]: the measured frame against the
    // model's, as measured.
    let turned = (poses.iter())
        .map(|(m, q, measured, line)| {
            let predicted = robot.predict_marker_rotation(*m, q).map_err(|e| {
                CalibrationError::NoEquilibrium(format!(
                    "{}:{line}: the calibrated model cannot predict this orientation ({e})",
                    data.file.display(),
                ))
            })?;
            Ok(crate::calibrate::rows::orientation::residual(
                measured, &predicted,
            ))
        })
        .collect::<Result<Vec<_>, CalibrationError>>()?;
    // The statistics of the points' errors, of rad as of m (×1e6: µrad).
    let orientation = (!turned.is_empty()).then(|| {
        let n = Nominal::of(&turned);
        OrientationValidation {
            poses: turned.len(),
            rms_urad: n.rms_um,
            mean_urad: n.mean_um,
            max_urad: n.max_um,
        }
    });
    let (rms_mm, per_marker_rms_mm, per_marker_mean_mm, per_marker_max_mm) = summary(&all, &per);
    let reregistration = reregistration(&job.robot.chain, &points).map(|(_, g)| g);
    let mut v = Validation {
        rms_mm,
        per_marker_rms_mm,
        per_marker_mean_mm,
        per_marker_max_mm,
        points: all.len(),
        interpolated_points,
        as_measured_rms_mm: rms_mm,
        reregistration,
        reregistered: false,
        orientation,
        scalars,
    };
    if let (true, Some(g)) = (reregister, &v.reregistration) {
        v.rms_mm = g.rms_mm;
        v.per_marker_rms_mm = g.per_marker_rms_mm.clone();
        v.per_marker_mean_mm = g.per_marker_mean_mm.clone();
        v.per_marker_max_mm = g.per_marker_max_mm.clone();
        v.reregistered = true;
    }
    Ok(v)
}

/// RMS \[mm\] of `all`; per marker id of `per`: RMS, mean and largest
/// norm \[mm\].
type Summary = (
    f64,
    BTreeMap<String, f64>,
    BTreeMap<String, f64>,
    BTreeMap<String, f64>,
);

fn summary(all: &[Vector3<f64>], per: &BTreeMap<u32, Vec<Vector3<f64>>>) -> Summary {
    let per_marker = |f: &dyn Fn(&[Vector3<f64>]) -> f64| -> BTreeMap<String, f64> {
        per.iter().map(|(m, v)| (m.to_string(), f(v))).collect()
    };
    (
        rms_um(all) * 1e-3,
        per_marker(&|v| rms_um(v) * 1e-3),
        per_marker(&|v| v.iter().map(|r| r.norm()).sum::<f64>() / v.len() as f64 * 1e3),
        per_marker(&|v| v.iter().map(|r| r.norm()).fold(0.0, f64::max) * 1e3),
    )
}

/// The file's measurement frame re-fitted (module docs) from `points`
/// (kind, marker id, predicted, measured \[m\]) of a robot whose chain is
/// `chain`: the transform from the calibration's frame to the file's, and
/// what it leaves. `None` with fewer than three absolute points, or when
/// the fit leaves no residual degree of freedom or is not finite.
pub(crate) fn reregistration(
    chain: &Chain<f64, J>,
    points: &[(RowKind, u32, Vector3<f64>, Vector3<f64>)],
) -> Option<(Isometry3<f64>, Reregistration)> {
    let (predicted, measured): (Vec<_>, Vec<_>) = points
        .iter()
        .filter(|p| p.0 == RowKind::Absolute)
        .map(|p| (p.2, p.3))
        .unzip();
    let n = predicted.len();
    if n < 3 {
        return None;
    }
    let mut g = Geometry::nominal(chain, &[]);
    g.register(&predicted, &measured);
    let t = g.base;
    let mut all = Vec::new();
    let mut per: BTreeMap<u32, Vec<Vector3<f64>>> = BTreeMap::new();
    let mut square = 0.0;
    for &(kind, id, p, m) in points {
        let r = match kind {
            RowKind::Absolute => m - (t * Point3::from(p)).coords,
            RowKind::Deflection => m - t.rotation * p,
        };
        if kind == RowKind::Absolute {
            square += r.norm_squared();
        }
        all.push(r);
        per.entry(id).or_default().push(r);
    }
    let (rms_mm, per_marker_rms_mm, per_marker_mean_mm, per_marker_max_mm) = summary(&all, &per);
    // The transform's σ about the predicted points' centroid `c`: the
    // translation `s/√n` per axis, the rotation `s² (Σ [q]ₓᵀ[q]ₓ)⁻¹`, `q`
    // the points about `c` turned into the file's frame.
    let dof = 3 * n - 6;
    if dof == 0 {
        return None;
    }
    let s2 = square / dof as f64;
    let c = predicted.iter().sum::<Vector3<f64>>() / n as f64;
    let mut m = Matrix3::zeros();
    for p in &predicted {
        let q = t.rotation * (p - c);
        m += Matrix3::identity() * q.norm_squared() - q * q.transpose();
    }
    let cov_r = m.try_inverse()? * s2;
    let moved = (t * Point3::from(c)).coords - c;
    let turn = t.rotation.scaled_axis();
    let g = Reregistration {
        rms_mm,
        per_marker_rms_mm,
        per_marker_mean_mm,
        per_marker_max_mm,
        translation_mm: [moved.x * 1e3, moved.y * 1e3, moved.z * 1e3],
        rotation_mrad: [turn.x * 1e3, turn.y * 1e3, turn.z * 1e3],
        translation_std_mm: [(s2 / n as f64).sqrt() * 1e3; 3],
        rotation_std_mrad: [0, 1, 2].map(|k| cov_r[(k, k)].max(0.0).sqrt() * 1e3),
    };
    let finite = g.rms_mm.is_finite()
        && g.translation_mm
            .iter()
            .chain(&g.rotation_mrad)
            .all(|v| v.is_finite());
    finite.then_some((t, g))
}
