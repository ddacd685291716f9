//! `robcal compare`: two calibrations of one robot side by side (two
//! sessions, before and after a service): which parameters differ beyond
//! their σ, and how far apart the two robots put the markers.
//!
//! - **Parameters** by name: each one's difference `b − a` in units of
//!   `σ = √(σa² + σb²)` (the two fits' errors, independent: two
//!   recordings); a name in one model only is listed as such. The base
//!   frame's pose is the tracker's placement that day, not the robot: its
//!   difference is given but not judged.
//! - **Positions** over a set of poses: each model's prediction
//!   ([`Predictor`], every effect kept), the second's re-fitted onto the
//!   first's by a rigid transform (the two measurement frames differ as
//!   the trackers stood), and the distance left \[mm\].

use crate::calibrate::outputs::predict::{Pose, Predictor};
use crate::calibrate::outputs::validate::reregistration;
use crate::calibrate::report::{Parameter, Reregistration};
use crate::calibrate::rows::RowKind;
use crate::calibrate::settings::CalibrationError;

/// A parameter's two estimates.
#[derive(Debug, Clone, PartialEq)]
pub struct ParameterPair {
    /// Its name.
    pub name: String,
    /// Its unit.
    pub unit: String,
    /// Value and σ in the first model, if it has the parameter.
    pub a: Option<(f64, f64)>,
    /// Value and σ in the second model, if it has the parameter.
    pub b: Option<(f64, f64)>,
}

impl ParameterPair {
    /// `b − a` over `√(σa² + σb²)`, with both; `None` for a base frame's
    /// coordinate (the tracker's placement, not the robot).
    pub fn z(&self) -> Option<f64> {
        if self.name.starts_with("base.") {
            return None;
        }
        let ((va, sa), (vb, sb)) = (self.a?, self.b?);
        Some((vb - va) / sa.hypot(sb))
    }
}

/// The parameters of `a` and `b` by name: `a`'s order, then those in `b`
/// only.
pub fn parameters(a: &[Parameter], b: &[Parameter]) -> Vec<ParameterPair> {
    let pair = |p: &Parameter| (p.value, p.std);
    let mut out: Vec<ParameterPair> = a
        .iter()
        .map(|p| ParameterPair {
            name: p.name.clone(),
            unit: p.unit.clone(),
            a: Some(pair(p)),
            b: b.iter().find(|q| q.name == p.name).map(pair),
        })
        .collect();
    out.extend(
        b.iter()
            .filter(|q| !a.iter().any(|p| p.name == q.name))
            .map(|q| ParameterPair {
                name: q.name.clone(),
                unit: q.unit.clone(),
                a: None,
                b: Some(pair(q)),
            }),
    );
    out
}

/// How far apart the two robots put the markers.
#[derive(Debug, Clone, PartialEq)]
pub struct Positions {
    /// Poses compared.
    pub points: usize,
    /// RMS of the distance \[mm\], the second model's frame re-fitted onto
    /// the first's (its `rms_mm`, per marker, and the frames' difference).
    pub frame: Reregistration,
    /// Largest distance \[mm\] after it.
    pub max_mm: f64,
}

/// The two models' predictions at `poses`, the second's frame re-fitted
/// onto the first's (module docs).
///
/// # Errors
/// [`CalibrationError::Data`] for fewer than three poses, a marker either
/// model lacks, or a pose either cannot predict (its line).
pub fn positions(
    a: &Predictor,
    b: &Predictor,
    poses: &[Pose],
) -> Result<Positions, CalibrationError> {
    let data = CalibrationError::Data;
    if poses.len() < 3 {
        return Err(data(format!(
            "{} pose(s): comparing positions re-fits a frame and needs three or more",
            poses.len()
        )));
    }
    let mut points = Vec::with_capacity(poses.len());
    for p in poses {
        // The second's prediction, mapped onto the first's.
        points.push((
            RowKind::Absolute,
            p.marker,
            b.predict_pose_at(p, &p.q)?,
            a.predict_pose_at(p, &p.q)?,
        ));
    }
    let (t, frame) = reregistration(b.chain(), &points).ok_or_else(|| {
        data("the two frames could not be re-fitted (poses on a line, or not finite)".into())
    })?;
    let max_mm = points
        .iter()
        .map(|p| (p.3 - (t * nalgebra::Point3::from(p.2)).coords).norm())
        .fold(0.0, f64::max)
        * 1e3;
    Ok(Positions {
        points: poses.len(),
        frame,
        max_mm,
    })
}
