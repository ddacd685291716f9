//! The data contract's JSON (§5, §7.5) and `model.json` (§7.4) as serde
//! types: `--json` prints a [`ReportJson`], `--output DIR` writes a
//! [`ModelJson`] (the same keys, the full covariance and the predictor),
//! read back by [`read_model`].
//!
//! Units are in the keys (`_um`, `_mm`) or beside the value (`unit`).
//! Non-finite numbers are written as `null` (serde_json's rule for `f64`).

use std::collections::BTreeMap;

use serde::Serialize;

use crate::calibrate::outputs::model_file::ModelFile;
use crate::calibrate::outputs::predict::Predictor;
use crate::calibrate::report::{
    EffectStep, LeftOut, NearDependent, Report, Unexplained, Validation,
};

/// `--json`: the report (contract §5).
#[derive(Serialize)]
pub struct ReportJson<'a> {
    method: &'a str,
    weights: &'a str,
    deflection_model: &'a str,
    iterations: usize,
    converged: bool,
    relinearisations: usize,
    nominal: NominalJson,
    /// The measured poses' orientations (`rx, ry, rz`; an extension):
    /// absent for points alone.
    #[serde(skip_serializing_if = "Option::is_none")]
    orientation: Option<OrientationJson<'a>>,
    /// The plane contacts and distances (`plane`, `anchor`; an
    /// extension): absent without them.
    #[serde(skip_serializing_if = "Option::is_none")]
    scalars: Option<ScalarsJson>,
    parameters: Vec<ParameterJson<'a>>,
    rms_um: f64,
    heldout_rms_um: Option<f64>,
    /// `robot.urdf` alone over the absolute rows (an extension of §7.5);
    /// absent when the URDF predicts what the model does.
    #[serde(skip_serializing_if = "Option::is_none")]
    urdf_rms_um: Option<f64>,
    effects: Vec<EffectJson<'a>>,
    unexplained: Option<UnexplainedJson<'a>>,
    validation: Option<ValidationJson<'a>>,
    warnings: &'a [String],
    /// Why the result is not a calibration (an extension of §5: the fit did
    /// not converge, or its model is worse than the nominal robot; the run
    /// exits non-zero unless `--accept-unconverged`); absent when it is one.
    #[serde(skip_serializing_if = "Option::is_none")]
    failure: Option<&'a str>,
    identifiability: Vec<LeftOutJson<'a>>,
    near_dependent: Vec<NearDependentJson<'a>>,
    /// What the run changed on its own (an extension of §5), e.g. IRLS →
    /// OLS; absent when empty.
    #[serde(skip_serializing_if = "<[String]>::is_empty")]
    notes: &'a [String],
}

/// `DIR/model.json`: the report, its covariance and the predictor.
#[derive(Serialize)]
pub struct ModelJson<'a> {
    #[serde(flatten)]
    report: ReportJson<'a>,
    covariance: CovarianceJson<'a>,
    predictor: ModelFile,
}

#[derive(Serialize)]
struct NominalJson {
    rms_um: f64,
    mean_um: f64,
    max_um: f64,
}

#[derive(Serialize)]
struct OrientationJson<'a> {
    poses: usize,
    nominal_rms_urad: f64,
    rms_urad: f64,
    mean_urad: f64,
    max_urad: f64,
    /// The parameters the points alone would leave out and the
    /// orientations determine.
    identified: &'a [String],
}

#[derive(Serialize)]
struct ScalarsJson {
    rows: usize,
    nominal_rms_um: f64,
    rms_um: f64,
    mean_um: f64,
    max_um: f64,
}

#[derive(Serialize)]
struct ParameterJson<'a> {
    name: &'a str,
    value: f64,
    std: f64,
    unit: &'a str,
    determined: bool,
}

#[derive(Serialize)]
struct EffectJson<'a> {
    effect: &'static str,
    joint: Option<&'a str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    marker: Option<u32>,
    p_value: f64,
    rms_um_before: f64,
    rms_um_after: f64,
    heldout_rms_um_before: Option<f64>,
    heldout_rms_um_after: Option<f64>,
}

#[derive(Serialize)]
struct UnexplainedJson<'a> {
    variable: &'a str,
    statistic: f64,
    p_value: f64,
}

#[derive(Serialize)]
struct ValidationJson<'a> {
    rms_mm: f64,
    per_marker_rms_mm: &'a BTreeMap<String, f64>,
    per_marker_mean_mm: &'a BTreeMap<String, f64>,
    per_marker_max_mm: &'a BTreeMap<String, f64>,
    points: usize,
    interpolated_points: usize,
    /// (An extension of §5.) Whether the errors above are those after the
    /// file's frame was re-fitted (`--reregister`).
    reregistered: bool,
    /// (An extension of §5.) The RMS as measured, in the calibration's
    /// frame.
    as_measured_rms_mm: f64,
    /// (An extension of §5.) The file's frame re-fitted with the model held
    /// fixed; absent with fewer than three absolute points.
    #[serde(skip_serializing_if = "Option::is_none")]
    reregistration: Option<ReregistrationJson<'a>>,
    /// (An extension.) The file's measured orientations against the
    /// model's, µrad; absent without `rx, ry, rz`.
    #[serde(skip_serializing_if = "Option::is_none")]
    orientation: Option<ValidationOrientationJson>,
    /// (An extension.) The file's plane contacts and distances against the
    /// calibrated model; absent without them.
    #[serde(skip_serializing_if = "Option::is_none")]
    scalars: Option<ValidationScalarsJson>,
}

#[derive(Serialize)]
struct ValidationScalarsJson {
    rows: usize,
    rms_um: f64,
    mean_um: f64,
    max_um: f64,
}

#[derive(Serialize)]
struct ValidationOrientationJson {
    poses: usize,
    rms_urad: f64,
    mean_urad: f64,
    max_urad: f64,
}

#[derive(Serialize)]
struct ReregistrationJson<'a> {
    rms_mm: f64,
    per_marker_rms_mm: &'a BTreeMap<String, f64>,
    translation_mm: [f64; 3],
    translation_std_mm: [f64; 3],
    rotation_mrad: [f64; 3],
    rotation_std_mrad: [f64; 3],
}

#[derive(Serialize)]
struct LeftOutJson<'a> {
    left_out: &'a str,
    absorbed_by: Vec<&'a str>,
    coefficients: Vec<f64>,
    coefficient_units: Vec<&'a str>,
}

#[derive(Serialize)]
struct NearDependentJson<'a> {
    name: &'a str,
    variance_inflation: f64,
    with: &'a [String],
}

#[derive(Serialize)]
struct CovarianceJson<'a> {
    parameters: Vec<&'a str>,
    unit: &'static str,
    matrix: Vec<Vec<f64>>,
}

impl<'a> ReportJson<'a> {
    /// The contract's JSON of `r`.
    pub fn of(r: &'a Report) -> Self {
        Self {
            method: r.method,
            weights: r.weights,
            deflection_model: r.deflection_model,
            iterations: r.iterations,
            converged: r.converged,
            relinearisations: r.relinearisations,
            nominal: NominalJson {
                rms_um: r.nominal.rms_um,
                mean_um: r.nominal.mean_um,
                max_um: r.nominal.max_um,
            },
            orientation: r.orientation.as_ref().map(|o| OrientationJson {
                poses: o.poses,
                nominal_rms_urad: o.nominal_rms_urad,
                rms_urad: o.rms_urad,
                mean_urad: o.mean_urad,
                max_urad: o.max_urad,
                identified: &o.identified,
            }),
            scalars: r.scalars.as_ref().map(|s| ScalarsJson {
                rows: s.rows,
                nominal_rms_um: s.nominal_rms_um,
                rms_um: s.rms_um,
                mean_um: s.mean_um,
                max_um: s.max_um,
            }),
            parameters: r
                .parameters
                .iter()
                .map(|p| ParameterJson {
                    name: &p.name,
                    value: p.value,
                    std: p.std,
                    unit: &p.unit,
                    determined: p.determined,
                })
                .collect(),
            rms_um: r.rms_um,
            heldout_rms_um: r.heldout_rms_um,
            urdf_rms_um: r.rigid.as_ref().map(|u| u.rms_um),
            effects: r.effects.iter().map(EffectJson::of).collect(),
            unexplained: r.unexplained.as_ref().map(UnexplainedJson::of),
            validation: r.validation.as_ref().map(ValidationJson::of),
            warnings: &r.warnings,
            failure: r.failure.as_deref(),
            identifiability: r.left_out.iter().map(LeftOutJson::of).collect(),
            near_dependent: r.near_dependent.iter().map(NearDependentJson::of).collect(),
            notes: &r.notes,
        }
    }
}

impl<'a> ModelJson<'a> {
    /// `model.json` of `r`, with the predictor of the calibrated robot.
    pub fn of(r: &'a Report, predictor: ModelFile) -> Self {
        let c = &r.covariance;
        Self {
            report: ReportJson::of(r),
            covariance: CovarianceJson {
                parameters: r.parameters.iter().map(|p| p.name.as_str()).collect(),
                unit: "product of the two parameters' units",
                matrix: (0..c.nrows())
                    .map(|i| (0..c.ncols()).map(|k| c[(i, k)]).collect())
                    .collect(),
            },
            predictor,
        }
    }
}

impl<'a> EffectJson<'a> {
    fn of(s: &'a EffectStep) -> Self {
        Self {
            effect: s.effect.name(),
            joint: s.joint.as_deref(),
            marker: s.marker,
            p_value: s.p_value,
            rms_um_before: s.rms_um_before,
            rms_um_after: s.rms_um_after,
            heldout_rms_um_before: s.heldout_rms_um_before,
            heldout_rms_um_after: s.heldout_rms_um_after,
        }
    }
}

impl<'a> UnexplainedJson<'a> {
    fn of(u: &'a Unexplained) -> Self {
        Self {
            variable: &u.variable,
            statistic: u.statistic,
            p_value: u.p_value,
        }
    }
}

impl<'a> ValidationJson<'a> {
    fn of(v: &'a Validation) -> Self {
        Self {
            rms_mm: v.rms_mm,
            per_marker_rms_mm: &v.per_marker_rms_mm,
            per_marker_mean_mm: &v.per_marker_mean_mm,
            per_marker_max_mm: &v.per_marker_max_mm,
            points: v.points,
            interpolated_points: v.interpolated_points,
            reregistered: v.reregistered,
            as_measured_rms_mm: v.as_measured_rms_mm,
            reregistration: v.reregistration.as_ref().map(|g| ReregistrationJson {
                rms_mm: g.rms_mm,
                per_marker_rms_mm: &g.per_marker_rms_mm,
                translation_mm: g.translation_mm,
                translation_std_mm: g.translation_std_mm,
                rotation_mrad: g.rotation_mrad,
                rotation_std_mrad: g.rotation_std_mrad,
            }),
            orientation: v.orientation.map(|o| ValidationOrientationJson {
                poses: o.poses,
                rms_urad: o.rms_urad,
                mean_urad: o.mean_urad,
                max_urad: o.max_urad,
            }),
            scalars: v.scalars.map(|s| ValidationScalarsJson {
                rows: s.rows,
                rms_um: s.rms_um,
                mean_um: s.mean_um,
                max_um: s.max_um,
            }),
        }
    }
}

impl<'a> LeftOutJson<'a> {
    fn of(l: &'a LeftOut) -> Self {
        Self {
            left_out: &l.name,
            absorbed_by: l.absorbed_by.iter().map(|a| a.name.as_str()).collect(),
            coefficients: l.absorbed_by.iter().map(|a| a.coefficient).collect(),
            coefficient_units: l.absorbed_by.iter().map(|a| a.unit.as_str()).collect(),
        }
    }
}

impl<'a> NearDependentJson<'a> {
    fn of(n: &'a NearDependent) -> Self {
        Self {
            name: &n.name,
            variance_inflation: n.inflation,
            with: &n.with,
        }
    }
}

/// The predictor of a `model.json`'s text (its `predictor` section), and
/// the whole document.
///
/// # Errors
/// Not JSON, no `predictor` section, or one that is not a predictor
/// ([`ModelFile::predictor`]): one line, without the file's name.
pub fn read_model(text: &str) -> Result<(Predictor, serde_json::Value), String> {
    let value: serde_json::Value =
        serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
    let section = value
        .get("predictor")
        .ok_or("no 'predictor' section (written by robcal calibrate --output DIR)")?;
    let file: ModelFile =
        serde_json::from_value(section.clone()).map_err(|e| format!("predictor: {e}"))?;
    let p = file.predictor().map_err(|e| format!("predictor: {e}"))?;
    Ok((p, value))
}
