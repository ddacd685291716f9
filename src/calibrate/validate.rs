//! `--validate`: the calibrated model on another measurement file of the
//! same job, nothing re-estimated.

use std::collections::BTreeMap;

use nalgebra::Vector3;

use super::calibrated::CalibratedModel;
use super::declared::needs_absolute;
use super::design::Design;
use super::report::Validation;
use super::residuals::rms_um;
use super::rows::{RowKind, Rows};
use super::settings::CalibrationError;
use crate::io::{Job, Measurements};
use crate::model::{in_some_bin, Param};

/// Evaluates `model` on `data` (rows of the kinds the calibration used,
/// predicted by the calibrated geometry and the estimate): the norm RMSE of
/// each marker's position error \[mm\].
///
/// # Errors
/// [`CalibrationError::Data`] when a row cannot be predicted (an angle
/// outside every compensator bin of the calibration).
pub fn validate(
    model: &CalibratedModel,
    job: &Job,
    data: &Measurements,
) -> Result<Validation, CalibrationError> {
    let mut names = model.names.clone();
    let mut rows = Rows::new(job, data, needs_absolute(job), &mut names, &model.policy)?;
    rows.relinearise(&model.geometry, &model.linearisation)?;
    rows.rows.retain(|r| match r.kind {
        RowKind::Deflection => model.kinds.deflections,
        RowKind::Absolute => model.kinds.absolute,
    });
    for row in &rows.rows {
        for p in &model.params {
            if let Param::ComplianceAt { joint, .. } = *p {
                let j = usize::from(joint);
                if !in_some_bin(&model.params, joint, row.q[j]) {
                    return Err(CalibrationError::Data(format!(
                        "{}:{}: joint '{}' is at an angle the calibration has no compliance for",
                        data.file.display(),
                        row.line,
                        names.joints[j]
                    )));
                }
            }
        }
    }
    let d = Design::new(
        &rows.rows,
        &model.params,
        &model.linearisation,
        &model.names,
        rows.configs.len(),
    )
    .map_err(|e| CalibrationError::Core("columns", e))?;
    let cols: Vec<usize> = (0..model.params.len()).collect();
    let mut all = Vec::new();
    let mut per: BTreeMap<u32, Vec<Vector3<f64>>> = BTreeMap::new();
    for i in 0..d.rows() {
        let r = d.residual(&cols, &model.x, i);
        all.push(r);
        per.entry(names.marker_id(rows.rows[i].marker))
            .or_default()
            .push(r);
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
    })
}
