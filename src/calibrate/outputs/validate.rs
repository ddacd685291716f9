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
//! carried over to another file.

use std::collections::BTreeMap;

use nalgebra::Vector3;

use crate::calibrate::effects::declared::needs_absolute;
use crate::calibrate::fit::residuals::rms_um;
use crate::calibrate::outputs::predict::{Payload, Predictor};
use crate::calibrate::report::calibrated::CalibratedModel;
use crate::calibrate::report::Validation;
use crate::calibrate::rows::{RowKind, Rows};
use crate::calibrate::settings::CalibrationError;
use crate::error::Error;
use crate::io::{job::Job, measurements::Measurements};

/// Evaluates `model` on `data` (rows of the kinds the calibration used,
/// predicted by [`Predictor`]): the norm RMSE of each marker's position
/// error \[mm\].
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
    let mut names = model.names.clone();
    let mut rows = Rows::new(job, data, needs_absolute(job), &mut names, &model.policy)?;
    rows.rows.retain(|r| match r.kind {
        RowKind::Deflection => model.kinds.deflections,
        RowKind::Absolute => model.kinds.absolute,
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
    let mut all = Vec::new();
    let mut per: BTreeMap<u32, Vec<Vector3<f64>>> = BTreeMap::new();
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
            RowKind::Absolute => robot.predict_marker(m, &row.q, None),
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
    let per_marker = |f: &dyn Fn(&[Vector3<f64>]) -> f64| -> BTreeMap<String, f64> {
        per.iter().map(|(m, v)| (m.to_string(), f(v))).collect()
    };
    Ok(Validation {
        rms_mm: rms_um(&all) * 1e-3,
        per_marker_rms_mm: per_marker(&|v| rms_um(v) * 1e-3),
        per_marker_mean_mm: per_marker(&|v| {
            v.iter().map(|r| r.norm()).sum::<f64>() / v.len() as f64 * 1e3
        }),
        per_marker_max_mm: per_marker(&|v| v.iter().map(|r| r.norm()).fold(0.0, f64::max) * 1e3),
        points: all.len(),
        interpolated_points,
    })
}
