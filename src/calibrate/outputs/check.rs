//! `robcal check`: a calibrated robot (its `model.json`) against a new
//! recording, months later — is it still within its calibration, and if
//! not, which joint's zero moved?
//!
//! 1. **Re-registered error.** Every point is predicted by the model as
//!    written ([`Predictor`], every effect of `model.json` kept); the new
//!    file's measurement frame (the tracker set up anywhere) is re-fitted
//!    with the model held fixed, as `--validate --reregister` does
//!    ([`crate::calibrate::outputs::validate`]), and the error left is the
//!    robot's.
//! 2. **Verdict.** It passes when that RMS is at most a threshold — the
//!    user's, or [`CHECK_FACTOR`] times the calibration's own held-out
//!    RMS (its RMS on the training rows when it has none): what the
//!    calibration claims for poses it did not see — and no joint's zero
//!    moved (3.).
//! 3. **What changed.** The joints' zeros and the frame are fitted to the
//!    recording by Gauss–Newton from the model as written (each step a
//!    least-squares fit to the re-registered residuals on the model's own
//!    columns, by central differences of its predictions; the one
//!    independence test [`crate::estimate::rank`] leaves out what the
//!    frame absorbs, e.g. a first joint's turn about a vertical axis). A
//!    joint whose zero moved beyond [`CHANGE_SIGMAS`] of its σ — the
//!    check's (`s² (BᵀB)⁻¹`) and the calibration's own of that zero, in
//!    quadrature (an unchanged robot differs from its calibration by the
//!    calibration's error) — is named, and fails the check too.
//!
//! Units: points \[m\] in, errors \[mm\] out; a joint's change in mrad
//! (revolute) or mm (prismatic).

use nalgebra::{DMatrix, DVector, Point3, Vector3};

use crate::calibrate::outputs::predict::{Pose, Predictor};
use crate::calibrate::outputs::validate::reregistration;
use crate::calibrate::report::Reregistration;
use crate::calibrate::rows::RowKind;
use crate::calibrate::settings::CalibrationError;
use crate::estimate::{identifiability, IdentifiabilitySettings};
use crate::robot::JointKind;

/// The default threshold is this many times the calibration's held-out
/// RMS: a new recording of the unchanged robot, re-registered, misses by
/// about that RMS (its sampling spread is a few per cent at 80 points).
/// 1.5.
pub const CHECK_FACTOR: f64 = 1.5;

/// A joint whose zero moved beyond this many of its σ is named, and fails
/// the check: 4 (two-sided 6e-5 a joint: a 7-joint robot unchanged is
/// failed by chance in 4e-4 of its checks). 4.
pub const CHANGE_SIGMAS: f64 = 4.0;

/// Central-difference step of a joint's column \[rad or m\].
const STEP: f64 = 1e-6;

/// What [`check`] judges by.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckSettings {
    /// The re-registered RMS it passes at \[mm\].
    pub threshold_mm: f64,
    /// The calibration's σ of each joint's zero \[rad or m\], chain order
    /// (its `<joint>.offset`'s; 0 for a joint it did not identify, or past
    /// the list): a change is judged against it and the check's own, in
    /// quadrature.
    pub zero_std: Vec<f64>,
}

/// One measured point of the new recording.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckPoint {
    /// The marker and its command.
    pub pose: Pose,
    /// Where the tracker saw the marker \[m, the file's frame\].
    pub measured_m: Vector3<f64>,
}

/// A joint whose zero moved beyond [`CHANGE_SIGMAS`] of its σ.
#[derive(Debug, Clone, PartialEq)]
pub struct JointChange {
    /// Its name.
    pub joint: String,
    /// The change of its zero (`mrad` or `mm`).
    pub change: f64,
    /// One σ of it: the check's and the calibration's, in quadrature.
    pub std: f64,
    /// `mrad` (revolute) or `mm` (prismatic).
    pub unit: &'static str,
}

/// The recheck's answer.
#[derive(Debug, Clone, PartialEq)]
pub struct Verdict {
    /// Points checked.
    pub points: usize,
    /// RMS as measured, in the calibration's frame \[mm\].
    pub as_measured_rms_mm: f64,
    /// The file's frame re-fitted, and the error left (its `rms_mm`).
    pub reregistration: Reregistration,
    /// The RMS it passes at \[mm\].
    pub threshold_mm: f64,
    /// Whether the re-registered RMS is at most the threshold and no
    /// joint's zero moved.
    pub pass: bool,
    /// The joints whose zero moved beyond [`CHANGE_SIGMAS`] σ, largest
    /// first by `|change| / σ`.
    pub changed: Vec<JointChange>,
    /// Joints whose change the frame's re-fit absorbs: not tested.
    pub untestable: Vec<String>,
}

/// Checks `robot` against `points` by `settings` (see the module docs).
///
/// # Errors
/// [`CalibrationError::Data`] for fewer than three points, a marker the
/// model does not have, or a point the model cannot predict (its line).
pub fn check(
    robot: &Predictor,
    points: &[CheckPoint],
    settings: &CheckSettings,
) -> Result<Verdict, CalibrationError> {
    let threshold_mm = settings.threshold_mm;
    if points.len() < 3 {
        return Err(CalibrationError::Data(format!(
            "{} point(s): a check re-fits the measurement frame and needs three or more",
            points.len()
        )));
    }
    let dof = robot.dof();
    // The model as written: the verdict's error.
    let first = step(robot, points, &vec![0.0; dof])?;
    // The joints' zeros by Gauss–Newton from there (each step a fit of
    // the zeros and the frame to the re-registered residuals at the zeros
    // so far), at most `MAX_STEPS` steps.
    let mut zeros = vec![0.0; dof];
    let mut last = None;
    for _ in 0..MAX_STEPS {
        let s = if last.is_none() {
            first.clone()
        } else {
            step(robot, points, &zeros)?
        };
        let Some(fit) = s.fit.clone() else { break };
        let mut largest: f64 = 0.0;
        for (&k, (&x, &sd)) in fit.kept.iter().zip(fit.x.iter().zip(&fit.std)) {
            if let Some(j) = k.checked_sub(6) {
                zeros[j] += x;
                largest = largest.max(x.abs() / sd.max(f64::MIN_POSITIVE));
            }
        }
        last = Some(fit);
        if largest < 1e-3 {
            break;
        }
    }
    let names = robot.joint_names();
    let kinds: Vec<JointKind> = robot.chain().joints().iter().map(|j| j.kind).collect();
    let (mut changed, untestable) = match &last {
        Some(fit) => (
            fit.kept
                .iter()
                .zip(&fit.std)
                .filter_map(|(&k, &sd)| Some((k.checked_sub(6)?, sd)))
                // The calibration's own error of the zero counts too: the
                // same robot, unchanged, differs from its calibration by
                // it (the check's σ and the calibration's, in quadrature).
                .map(|(j, sd)| {
                    let cal = settings.zero_std.get(j).copied().unwrap_or(0.0);
                    (j, sd.hypot(if cal.is_finite() { cal } else { 0.0 }))
                })
                .filter(|&(j, sd)| zeros[j].abs() > CHANGE_SIGMAS * sd)
                .map(|(j, sd)| JointChange {
                    joint: names[j].clone(),
                    change: zeros[j] * 1e3,
                    std: sd * 1e3,
                    unit: match kinds[j] {
                        JointKind::Revolute => "mrad",
                        JointKind::Prismatic => "mm",
                    },
                })
                .collect::<Vec<_>>(),
            (0..dof)
                .filter(|j| !fit.kept.contains(&(6 + j)))
                .map(|j| names[j].clone())
                .collect(),
        ),
        None => (Vec::new(), Vec::new()),
    };
    changed.sort_by(|a, b| {
        (b.change / b.std)
            .abs()
            .total_cmp(&(a.change / a.std).abs())
    });
    let reg = first.reregistration;
    Ok(Verdict {
        points: points.len(),
        as_measured_rms_mm: first.as_measured_rms_mm,
        pass: reg.rms_mm <= threshold_mm && changed.is_empty(),
        reregistration: reg,
        threshold_mm,
        changed,
        untestable,
    })
}

/// Gauss–Newton steps of the joints' zeros at most.
const MAX_STEPS: usize = 5;

/// One step of [`check`] at the joints' zeros moved by `zeros` \[rad or
/// m\]: the re-registration there and the least-squares step of the zeros
/// and the frame.
#[derive(Debug, Clone)]
struct Step {
    as_measured_rms_mm: f64,
    reregistration: Reregistration,
    fit: Option<Fit>,
}

/// A least-squares step: the kept columns (the frame's six, then the
/// joints), the step and each one's σ (`s² (BᵀB)⁻¹`).
#[derive(Debug, Clone)]
struct Fit {
    kept: Vec<usize>,
    x: Vec<f64>,
    std: Vec<f64>,
}

fn step(robot: &Predictor, points: &[CheckPoint], zeros: &[f64]) -> Result<Step, CalibrationError> {
    let data = CalibrationError::Data;
    // Each point's prediction, and the model's columns of every joint's
    // zero there (central differences of the same prediction).
    let dof = robot.dof();
    let mut predicted = Vec::with_capacity(points.len());
    let mut columns = Vec::with_capacity(points.len());
    for p in points {
        let q: Vec<f64> = p.pose.q.iter().zip(zeros).map(|(q, z)| q + z).collect();
        let predict = |q: &[f64]| robot.predict_pose_at(&p.pose, q);
        predicted.push(predict(&q)?);
        let mut cols = Vec::with_capacity(dof);
        for j in 0..dof {
            let (mut up, mut down) = (q.clone(), q.clone());
            up[j] += STEP;
            down[j] -= STEP;
            cols.push((predict(&up)? - predict(&down)?) / (2.0 * STEP));
        }
        columns.push(cols);
    }
    let pts: Vec<_> = points
        .iter()
        .zip(&predicted)
        .map(|(p, &q)| (RowKind::Absolute, p.pose.marker, q, p.measured_m))
        .collect();
    let (t, reg) = reregistration(robot.chain(), &pts).ok_or_else(|| {
        data(
            "the measurement frame could not be re-fitted (points on a line, or not finite)".into(),
        )
    })?;
    let as_measured: Vec<Vector3<f64>> = pts.iter().map(|p| p.3 - p.2).collect();
    // The joints' zeros and the frame, fitted to the re-registered
    // residuals: columns in the file's frame, the frame's turn about the
    // predicted points' centroid.
    let moved: Vec<Vector3<f64>> = predicted
        .iter()
        .map(|p| (t * Point3::from(*p)).coords)
        .collect();
    let c = moved.iter().sum::<Vector3<f64>>() / moved.len() as f64;
    let n = dof + 6;
    let rows = 3 * points.len();
    let mut b = DMatrix::<f64>::zeros(rows, n);
    let mut y = DVector::<f64>::zeros(rows);
    for (i, p) in points.iter().enumerate() {
        let r = p.measured_m - moved[i];
        let arm = moved[i] - c;
        for a in 0..3 {
            y[3 * i + a] = r[a];
        }
        // The frame first: a joint the frame's move absorbs is the one
        // left out (layout order), not a component of the frame.
        for k in 0..3 {
            b[(3 * i + k, k)] = 1.0;
            let turn = Vector3::ith(k, 1.0).cross(&arm);
            for a in 0..3 {
                b[(3 * i + a, 3 + k)] = turn[a];
            }
        }
        for (j, col) in columns[i].iter().enumerate() {
            let col = t.rotation * col;
            for a in 0..3 {
                b[(3 * i + a, 6 + j)] = col[a];
            }
        }
    }
    let lambda = b.transpose() * &b;
    let eta = b.transpose() * &y;
    let fit = identifiability(&lambda, &vec![true; n], &IdentifiabilitySettings::default())
        .ok()
        .and_then(|rank| {
            let kept: Vec<usize> = (0..n).filter(|&k| rank.kept[k]).collect();
            solve(&lambda, &eta, &y, kept, rows)
        });
    Ok(Step {
        as_measured_rms_mm: rms_mm(&as_measured),
        reregistration: reg,
        fit,
    })
}

/// The least-squares step on the columns `kept` (`Λ_KK x = η_K`), each
/// one's σ from `s² (Λ_KK⁻¹)ᵢᵢ`, `s²` the residual variance over
/// `rows − kept` degrees of freedom.
fn solve(
    lambda: &DMatrix<f64>,
    eta: &DVector<f64>,
    y: &DVector<f64>,
    kept: Vec<usize>,
    rows: usize,
) -> Option<Fit> {
    let k = kept.len();
    if k == 0 || rows <= k {
        return None;
    }
    let l = DMatrix::from_fn(k, k, |a, b| lambda[(kept[a], kept[b])]);
    let e = DVector::from_fn(k, |a, _| eta[kept[a]]);
    let ch = l.cholesky()?;
    let x = ch.solve(&e);
    let inverse = ch.inverse();
    let s2 = ((y.norm_squared() - x.dot(&e)) / (rows - k) as f64).max(0.0);
    let std = (0..k).map(|a| (s2 * inverse[(a, a)]).sqrt()).collect();
    Some(Fit {
        kept,
        x: x.iter().copied().collect(),
        std,
    })
}

/// RMS of the norms of `r` \[m\] in mm.
fn rms_mm(r: &[Vector3<f64>]) -> f64 {
    (r.iter().map(|v| v.norm_squared()).sum::<f64>() / r.len().max(1) as f64).sqrt() * 1e3
}
