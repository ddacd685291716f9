//! Plausibility, stated once: what `robcal calibrate` refuses and what it
//! reports. No implausible result leaves with exit 0 unannounced.
//!
//! **The rule.** A finding that makes the result wrong whatever the user
//! meant is an *error* (the run stops, exit 1, one line naming the file,
//! column or parameter). A finding that may be right but needs a look is a
//! *warning*: printed in the report (`warning: …`) and in the JSON's
//! `warnings` list. The thresholds are [`Policy`] fields.
//!
//! | finding | when | outcome |
//! |---|---|---|
//! | no residual to estimate the noise from | the rows' equations (3 a row) no more than the declared model's identifiable parameters (`calibrate`) | error |
//! | compliance (any joint-law parameter) with no torque at its joint | declared, `max |τⱼ| <` [`Policy::min_torque_nm`] over the rows | error |
//! | positions on another scale than the robot | spread of the measured unloaded points over that of the nominal model's prediction beyond [`Policy::max_scale_ratio`] either way | error |
//! | … | beyond [`Policy::warn_scale_ratio`] | warning |
//! | poses that barely move the markers | spread of the nominal model's predicted unloaded points below [`Policy::min_spread_m`] (then no scale or unit check) | warning |
//! | poses that barely move the markers off a line, or off a plane | the second principal spread of the same points (RMS off their best line), or the third (off their best plane), below [`Policy::min_spread_m`]: a rigid registration onto points on a line leaves the rotation about it undetermined, and a parameter whose column is zero or dependent at the nominal robot (a marker on the last joint's axis, a tilt of parallel joints) may move the true robot's points (`spread::barely_moved`) | warning |
//! | one joint column in the other angle unit | the nominal model registers onto the measured points [`Policy::unit_fit_ratio`] times better with that column converted (deg ↔ rad) | error |
//! | negative compliance or backlash in the final model | more than [`Policy::negative_sigmas`] σ below 0 | error |
//! | … | within [`Policy::negative_sigmas`] σ | warning (consistent with 0) |
//! | a declared compliance (any joint-law term that follows the torque) the data do not determine | its final estimate ≥ 0 and within [`Policy::determined_sigmas`] σ of 0 (`determined`) | warning (a prediction applies it under any load) |
//! | an effect the loop added that the later ones took over | every parameter it added within [`Policy::determined_sigmas`] σ of 0 in the final model | warning |
//! | any other estimate the data do not tell from the nominal robot's value (a joint's offset or frame, a marker, a declared effect; not the base frame's pose) | within [`Policy::determined_sigmas`] σ of 0 in the final model ([`crate::calibrate::report::Parameter::determined`]) | one warning naming them all, and `*` in the parameter table (`determined: false` in the JSON) |
//! | a declared geometric parameter left out that other poses would identify (the data's dependence, not the model's: its nominal value unchecked) | kept on [`Policy::varied_poses`] configurations drawn within the joint limits (`calibrate::varied`, which words the warning: added by `calibrate::run`) | warning naming it, by how many mm per unit its error shows at those poses, and the joints the data hold still |
//! | a declared parameter left out, absorbed far from one-to-one | a kept parameter of the same unit absorbs it with a coefficient beyond [`Policy::max_absorption`] in magnitude | warning (the reduced model is exact only to first order) |
//! | an effect's size past the bound it was admitted under, in the final model | a gear cyclic error above [`Policy::max_cyclic_mrad`], a gravity compliance above [`Policy::max_gravity_deflection_mrad`], a drift above [`Policy::max_drift_mm_per_h`] ([`crate::calibrate::effects::inadmissible`]: the loop checks them when it adds the effect; later steps refit them) | warning |
//! | the fit did not converge | IRLS at `--max-iter`, or Gauss–Newton at [`Policy::max_steps`] or back at its best model ([`Policy::max_cost_increase`]) | warning, `converged: false`, and not a calibration ([`failure`]: the report written, exit 1 unless `--accept-unconverged`) |
//! | the calibrated model fits worse than the nominal robot | the final residuals' root sum of squares, weighted by the fit's weights (eq. 14; unit for OLS), above the nominal robot's (base registered) with the same weights by more than [`Policy::worse_than_nominal`]: the declared model holds the nominal robot (every parameter zero), so Gauss–Newton ended at a wrong stationary point. (The unweighted RMS of a weighted fit may legitimately end above the nominal robot's: the fit minimises the weighted sum) | warning, and not a calibration ([`failure`]) |
//! | a row far out of line with the others (a measurement error: a tracker point lost or mistaken, a line of another pose) | its final residual's norm above [`Policy::outlier_ratio`] times the median row's of its kind (positions, deflections) and above [`Policy::outlier_floor_um`], among at least [`Policy::outlier_min_rows`] rows of the kind | warning naming the largest five by configuration and marker; with `Settings::leave_out_outliers` (`--leave-out-outliers`) they are left out and the job fitted again, once ([`outlying`]); with `Settings::robust` (`--robust`) every row is weighted by Huber's loss first ([`crate::calibrate::robust`]) |
//! | `robot.urdf` predicts the measured points worse than the nominal robot | the RMS over the absolute rows of what it holds (the geometric parameters refitted as a rigid robot when the model has parameters a URDF cannot hold, `export::rigid_urdf`; the model's own geometry when that refit fails) above the nominal robot's by more than [`Policy::worse_than_nominal`] | warning |
//! | validation with no point | `--validate` | error ([`crate::calibrate::outputs::validate`](mod@crate::calibrate::outputs::validate)) |
//! | a validation file measured in another frame (the tracker set up elsewhere) | its RMS as measured above [`Policy::reregistration_gain`] times that after its frame is re-fitted with the model held fixed, the frame moved beyond [`Policy::frame_sigmas`] σ, and the re-registration not asked for ([`check_validation`]) | warning naming the frame's move and `--reregister` |
//!
//! The scale and unit checks read at most [`Policy::unit_check_points`]
//! unloaded points, evenly spaced in file order.
//!
//! Candidates of the diagnosis with an implausible estimate are rejected
//! there ([`crate::calibrate::effects::inadmissible`]) and named in `notes`; input
//! files are checked by their readers ([`crate::io`]).

use nalgebra::Vector3;

mod determined;
mod spread;
use spread::spread;

use crate::calibrate::params::geometry::Geometry;
use crate::calibrate::params::names::Names;
use crate::calibrate::report::{Report, RowError, Validation};
use crate::calibrate::rows::{RowKind, Rows};
use crate::calibrate::settings::{CalibrationError, Policy};
use crate::io::{
    job::Job, measurements::Measurements, measurements::Observation, units::AngleUnit,
};

use crate::model::Param;

/// The joint a joint-law parameter acts through (compliances, their bins,
/// nonlinear stiffness, backlash, link compliance).
fn loaded_joint(p: &Param) -> Option<u8> {
    match *p {
        Param::Compliance { joint }
        | Param::ComplianceAt { joint, .. }
        | Param::NonlinearStiffness { joint }
        | Param::Backlash { joint }
        | Param::LinkCompliance { joint } => Some(joint),
        _ => None,
    }
}

/// Whether `p` is a term of the joint law that follows the joint's torque
/// (a compliance, a compensator's bin, nonlinear stiffness, backlash, a
/// link's bending): one that needs a load to be identified, and that a
/// payload changes.
pub(crate) fn follows_torque(p: &Param) -> bool {
    loaded_joint(p).is_some()
}

/// A compliance or backlash: physical only at or above zero (the negative
/// rule of [`check_result`]).
fn sign_bound(p: &Param) -> bool {
    matches!(
        p,
        Param::Compliance { .. } | Param::ComplianceAt { .. } | Param::Backlash { .. }
    )
}

/// A declared joint-law parameter needs a torque at its joint: a load on
/// some row, or the robot's own weight on an absolute row.
///
/// # Errors
/// [`CalibrationError::Data`] naming the parameters without torque.
pub fn check_torques(
    model: &[Param],
    rows: &Rows,
    names: &Names,
    policy: &Policy,
    file: &std::path::Path,
) -> Result<(), CalibrationError> {
    let unloaded: Vec<String> = model
        .iter()
        .filter(|p| {
            loaded_joint(p).is_some_and(|j| {
                let j = usize::from(j);
                rows.rows
                    .iter()
                    .map(|r| r.tau().get(j).map_or(0.0, |t| t.abs()))
                    .fold(0.0, f64::max)
                    < policy.min_torque_nm
            })
        })
        .map(|p| names.name(p))
        .collect();
    if unloaded.is_empty() {
        return Ok(());
    }
    let loaded = rows.rows.iter().filter(|r| r.load_kg() > 0.0).count();
    let why = if loaded > 0 {
        format!(
            "{loaded} loaded rows, but their load acts through the joint's axis: \
             check [load] com, the load's centre of mass in tip_link"
        )
    } else {
        "no loaded row, and no own weight acting on it".to_string()
    };
    Err(CalibrationError::Data(format!(
        "{}: {} declared, but no row puts a torque of {} N*m or more on the joint \
         ({why}): a compliance cannot be identified without load; measure loaded \
         rows, or remove it from [model]",
        file.display(),
        unloaded.join(", "),
        policy.min_torque_nm
    )))
}

/// Nominal predictions \[m\] of the observations `checked`, paired with
/// the measured points; joint `convert` (if any) with its values scaled by
/// `s`.
fn pairs(
    job: &Job,
    checked: &[&Observation],
    convert: Option<(usize, f64)>,
) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    let markers = &job.setup.markers;
    // One chain per link markers are on (a tree: data contract 7.1).
    let chains = job.robot.chains();
    checked
        .iter()
        .filter_map(|o| {
            let m = markers.iter().find(|m| m.id == o.marker)?;
            let mut q = o.q.clone();
            if let Some((j, s)) = convert {
                q[j] *= s;
            }
            let k = job.robot.end_index(m.link.as_deref())?;
            let f = chains.get(k)?.frames(&q).ok()?;
            Some((f.point_m(&Vector3::from(m.xyz)), Vector3::from(o.p_m)))
        })
        .collect()
}

/// RMS \[m\] of the nominal prediction registered (rigidly) onto the
/// measured points.
fn registered_rms(job: &Job, pairs: &[(Vector3<f64>, Vector3<f64>)]) -> f64 {
    let (pred, meas): (Vec<_>, Vec<_>) = pairs.iter().copied().unzip();
    let mut g = Geometry::nominal(&job.robot.chain, &[]);
    g.register(&pred, &meas);
    let n = pairs.len().max(1) as f64;
    (pairs
        .iter()
        .map(|(p, m)| {
            (g.base * nalgebra::Point3::from(*p) - nalgebra::Point3::from(*m)).norm_squared()
        })
        .sum::<f64>()
        / n)
        .sqrt()
}

/// The scale of the positions and the unit of each angle column against
/// the nominal robot (unloaded rows, at most [`Policy::unit_check_points`]
/// of them; needs 4 points spread over [`Policy::min_spread_m`]).
///
/// # Errors
/// [`CalibrationError::Data`] for a scale beyond
/// [`Policy::max_scale_ratio`] or a joint column that fits the other
/// angle unit [`Policy::unit_fit_ratio`] times better.
pub fn check_units(
    job: &Job,
    data: &Measurements,
    policy: &Policy,
) -> Result<Vec<String>, CalibrationError> {
    let mut warnings = Vec::new();
    let cap = policy.unit_check_points.max(1);
    // The points (a plane contact or a distance has none).
    let points = || data.unloaded().filter(|o| o.scalar.is_none());
    let stride = points().count().div_ceil(cap);
    // Every `stride`-th unloaded observation, picked once (each pass over
    // a million observations was ~30 ms, and there is one per joint).
    let checked: Vec<&Observation> = points().step_by(stride.max(1)).collect();
    let base = pairs(job, &checked, None);
    let predicted = spread(base.iter().map(|p| p.0));
    if base.len() < 4 {
        return Ok(warnings);
    }
    // A pivot (every point measured at one place, the robot's predicted
    // ones within `min_spread_m` of one another): points that barely move
    // are what it is, and there is no spread to compare.
    if spread(base.iter().map(|p| p.1)) < crate::calibrate::params::geometry::PIVOT_M
        && predicted < policy.min_spread_m
    {
        return Ok(warnings);
    }
    warnings.extend(spread::barely_moved(
        &data.file,
        base.iter().map(|p| p.0),
        policy,
    ));
    if predicted < policy.min_spread_m {
        return Ok(warnings);
    }
    let measured = spread(base.iter().map(|p| p.1));
    let ratio = measured / predicted;
    let file = data.file.display();
    let length = match job.setup.units.length {
        crate::io::units::LengthUnit::Mm => "mm",
        crate::io::units::LengthUnit::M => "m",
    };
    if !(ratio < policy.max_scale_ratio && ratio > 1.0 / policy.max_scale_ratio) {
        return Err(CalibrationError::Data(format!(
            "{file}: the measured positions spread {ratio:.3} times as far as the robot's \
             nominal model predicts ({:.1} vs {:.1} mm): are x, y, z in another unit than \
             [units] length = \"{length}\"?",
            measured * 1e3,
            predicted * 1e3
        )));
    }
    if !(ratio < policy.warn_scale_ratio && ratio > 1.0 / policy.warn_scale_ratio) {
        warnings.push(format!(
            "{file}: the measured positions spread {ratio:.3} times as far as the nominal \
             model predicts (markers' xyz, or the unit of x, y, z?)"
        ));
    }
    let declared = registered_rms(job, &base);
    let (factor, other) = match job.setup.units.angle {
        AngleUnit::Deg => (180.0 / core::f64::consts::PI, "rad"),
        AngleUnit::Rad => (core::f64::consts::PI / 180.0, "deg"),
    };
    // Each revolute joint's column read in the other unit, on worker
    // threads (each a forward kinematics of every checked point and a
    // registration); the first joint in order that fits better is the error.
    let revolute: Vec<usize> = (job.robot.chain.joints().iter().enumerate())
        .filter(|(_, jt)| jt.kind == crate::robot::JointKind::Revolute)
        .map(|(j, _)| j)
        .collect();
    let threads = crate::parallel::threads();
    let alts = crate::parallel::map(revolute.len(), threads, |k| {
        registered_rms(job, &pairs(job, &checked, Some((revolute[k], factor))))
    });
    for (&j, alt) in revolute.iter().zip(alts) {
        if alt * policy.unit_fit_ratio < declared {
            return Err(CalibrationError::Data(format!(
                "{file}: column '{}': its values fit {other} far better than the declared \
                 [units] angle (the nominal model registers with RMS {:.1} mm read as \
                 {other}, {:.1} mm as declared)",
                job.robot.joint_names[j],
                alt * 1e3,
                declared * 1e3
            )));
        }
    }
    Ok(warnings)
}

/// The final model's findings: negative compliances and backlash
/// ([`Policy::negative_sigmas`]), effects past the bound they were
/// admitted under, and a fit that did not converge.
///
/// # Errors
/// [`CalibrationError::Data`] for a compliance or backlash below zero by
/// more than [`Policy::negative_sigmas`] σ.
pub fn check_result(report: &Report, policy: &Policy) -> Result<Vec<String>, CalibrationError> {
    let mut warnings = Vec::new();
    for (p, par) in report.model.params.iter().zip(&report.parameters) {
        if !sign_bound(p) || par.value >= 0.0 {
            continue;
        }
        let z = -par.value / par.std;
        let what = format!(
            "{} = {:.4} ± {:.4} {} is negative",
            par.name, par.value, par.std, par.unit
        );
        if z > policy.negative_sigmas || !z.is_finite() {
            return Err(CalibrationError::Data(format!(
                "{what} by {z:.1} sigma: not a physical joint; is the setup's [load] com \
                 right (a centre of mass wrong, or on the joint's axis), are there enough \
                 loaded configurations?"
            )));
        }
        warnings.push(format!(
            "{what}, within {} sigma of 0",
            policy.negative_sigmas
        ));
    }
    for l in &report.left_out {
        let far = l.absorbed_by.iter().find(|a| {
            let mut u = a.unit.split('/');
            u.next() == u.next() && a.coefficient.abs() > policy.max_absorption
        });
        if let Some(a) = far {
            warnings.push(format!(
                "{} is left out and absorbed by {} with a coefficient of {:.1} {}: the kept \
                 parameters reproduce it only to first order; declare fewer parameters \
                 if the residuals exceed the noise",
                l.name, a.name, a.coefficient, a.unit
            ));
        }
    }
    // The bounds an effect was admitted under, on the final estimate.
    let m = &report.model;
    // (A mass as the mass it is, not as its last step.)
    let x: Vec<f64> = (m.params.iter().zip(&m.x))
        .map(|(p, &v)| match p {
            Param::LinkMass { .. } => m.geometry.value(p, v),
            _ => v,
        })
        .collect();
    for p in &m.params {
        let bounded = matches!(
            p,
            Param::GearCyclic { .. }
                | Param::GravityCompliance { .. }
                | Param::Drift { .. }
                | Param::LinkMass { .. }
                | Param::ThermalExpansion
        );
        if let Some(why) = bounded
            .then(|| {
                crate::calibrate::effects::inadmissible(&m.names, policy, &m.params, &x, &[*p])
            })
            .flatten()
        {
            warnings.push(format!(
                "{why} in the final model: within the bound when the loop added it, moved \
                 past it by the later steps; more likely another error absorbed than the effect"
            ));
        }
    }
    if !report.converged {
        warnings.push(format!(
            "the fit did not converge ({} reweighting iterations, {} Gauss-Newton \
             relinearisations): the estimate and its sigma are those of the last step",
            report.iterations, report.relinearisations
        ));
    }
    warnings.extend(determined::undetermined(report, policy));
    warnings.extend(worse_than_nominal(report, policy.worse_than_nominal));
    warnings.extend(outliers(&report.row_errors, policy));
    warnings.extend(urdf_worse(report, policy.worse_than_nominal));
    Ok(warnings)
}

/// The rule for a validation measured in another frame (module docs):
/// the warning, if it applies.
pub fn check_validation(v: &Validation, policy: &Policy) -> Option<String> {
    let g = v.reregistration.as_ref()?;
    // (NaN compares false: no warning on a number that is not one.)
    let far = v.as_measured_rms_mm > policy.reregistration_gain * g.rms_mm;
    if v.reregistered || !far || !g.moved(policy.frame_sigmas) {
        return None;
    }
    Some(format!(
        "validation: RMS {:.4} mm as measured, {:.4} mm once the file's measurement frame is \
         re-fitted with the calibrated model held fixed (it moved {:.3} mm and turned {:.3} \
         mrad): the file was most likely measured with the tracker set up elsewhere; \
         --reregister reports the error after re-registration",
        v.as_measured_rms_mm,
        g.rms_mm,
        g.shift_mm(),
        g.turn_mrad()
    ))
}

/// Why the result of a run is not a calibration, if it is not one: the
/// fit did not converge (IRLS at `--max-iter`, Gauss–Newton at
/// [`Policy::max_steps`] or with no step that lowers the cost,
/// [`Policy::max_cost_increase`]), or the final model fits its own rows
/// worse than the nominal robot by [`Policy::worse_than_nominal`] (weighted
/// by the fit's weights, or, for the RMS the report gives, unweighted).
/// The first two are
/// also warnings; `robcal calibrate` exits non-zero on any unless the user
/// accepts the result (`--accept-unconverged`).
pub fn failure(report: &Report, policy: &Policy) -> Option<String> {
    if !report.converged {
        return Some(format!(
            "the fit did not converge ({} reweighting iterations, {} Gauss-Newton \
             relinearisations); the model is the last one whose fit did not get worse, and its \
             errors are its own",
            report.iterations, report.relinearisations
        ));
    }
    // The weighted sums first (the fit's own criterion), then the error a
    // user reads: a weighted fit's may end above the nominal robot's, and
    // a model that predicts its own data worse than the robot did before
    // is not a calibration either.
    worse_than_nominal(report, policy.worse_than_nominal).or_else(|| {
        (report.rms_um > report.nominal.rms_um * (1.0 + policy.worse_than_nominal)).then(|| {
            format!(
                "the model predicts its own data worse than the nominal robot (RMS {:.1} um \
                 against {:.1} um): the declared model lacks what the data hold, and the \
                 weights of the fit traded the errors of some configurations for others'",
                report.rms_um, report.nominal.rms_um
            )
        })
    })
}

/// RMS \[µm\] of the nominal robot and of the final model over the
/// absolute rows ([`Report::row_errors`]).
fn absolute_rms_um(report: &Report) -> (f64, f64) {
    let (mut n, mut nominal, mut fitted) = (0_usize, 0.0, 0.0);
    for r in report.row_errors.iter().filter(|r| !r.deflection) {
        n += 1;
        nominal += r.nominal_um.norm_squared();
        fitted += r.final_um.norm_squared();
    }
    let n = n.max(1) as f64;
    ((nominal / n).sqrt(), (fitted / n).sqrt())
}

/// The warning when `robot.urdf` ([`Report::rigid`]) predicts the
/// absolute rows worse than the nominal robot by more than the share
/// `margin`: a rigid refit that ended at a wrong stationary point, or, when
/// that refit could not be made, the model's own geometry, which the
/// parameters only `model.json` holds absorbed in part.
fn urdf_worse(report: &Report, margin: f64) -> Option<String> {
    let rigid = report.rigid.as_ref()?;
    let (nominal, fitted) = absolute_rms_um(report);
    if rigid.rms_um <= nominal * (1.0 + margin) {
        return None;
    }
    let what = if rigid.refit.is_some() {
        "its geometric parameters refitted as a rigid robot ended at a wrong stationary point"
    } else {
        "the rigid refit of its geometric parameters failed, and it holds the model's own \
         geometry, part of which the parameters only model.json holds absorbed"
    };
    Some(format!(
        "robot.urdf predicts the measured points worse than the nominal robot (RMS {:.1} um \
         against {nominal:.1} um over the absolute rows; the whole model {fitted:.1} um): \
         {what}; a controller that loads only the URDF needs a geometric calibration (a \
         geometric [model] with --no-diagnose)",
        rigid.rms_um
    ))
}

/// Rows listed by name in [`outliers`]' warning, at most (the largest).
const OUTLIERS_LISTED: usize = 5;

/// The warning when some rows' final residuals are far out of line with
/// the others': a norm above [`Policy::outlier_ratio`] times the median
/// row's of the same kind (absolute positions and deflections apart) and
/// above [`Policy::outlier_floor_um`], among at least
/// [`Policy::outlier_min_rows`] rows of the kind. The largest
/// [`OUTLIERS_LISTED`] are named by configuration and marker.
fn outliers<R: std::borrow::Borrow<RowError>>(
    rows: impl IntoIterator<Item = R> + Copy,
    policy: &Policy,
) -> Option<String> {
    let mut parts = Vec::new();
    for deflection in [false, true] {
        let Some((count, median, far)) = far_of_kind(rows, deflection, policy) else {
            continue;
        };
        let kind = if deflection { "deflection" } else { "position" };
        let named: Vec<String> = far
            .iter()
            .take(OUTLIERS_LISTED)
            .map(|(n, r)| format!("config {} marker {} {n:.1} um", r.config, r.marker))
            .collect();
        let more = if far.len() > OUTLIERS_LISTED {
            ", ..."
        } else {
            ""
        };
        let verb = if far.len() == 1 { "has" } else { "have" };
        parts.push(format!(
            "{} of {} {kind} rows {verb} a residual above {} times the median row's \
             ({median:.1} um): {}{more}",
            far.len(),
            count,
            policy.outlier_ratio,
            named.join(", ")
        ));
    }
    (!parts.is_empty()).then(|| {
        format!(
            "{}; a measurement error there (a tracker point lost or mistaken, a line of \
             another pose) moves the whole fit: check those rows",
            parts.join("; ")
        )
    })
}

/// What the outlier rule finds among the rows of one kind: how many rows
/// of the kind, their median norm \[µm\], and the far ones with their
/// norms, largest first.
type Far = (usize, f64, Vec<(f64, RowError)>);

/// The rows of one kind (`deflection` or absolute positions) the outlier
/// rule names ([`Far`]); `None` when there is none, or too few rows of the
/// kind.
fn far_of_kind<R: std::borrow::Borrow<RowError>>(
    rows: impl IntoIterator<Item = R> + Copy,
    deflection: bool,
    policy: &Policy,
) -> Option<Far> {
    let of_kind = || {
        (rows.into_iter())
            .map(|r| *r.borrow())
            .filter(move |r| r.deflection == deflection)
    };
    // The norms alone (8 MB at 10⁶ rows), for the median: the middle
    // one, the upper of the two middle ones for an even count.
    let mut v: Vec<f64> = of_kind().map(|r| r.final_um.norm()).collect();
    let count = v.len();
    if count < policy.outlier_min_rows.max(1) {
        return None;
    }
    let median = *v.select_nth_unstable_by(count / 2, f64::total_cmp).1;
    drop(v);
    let bound = (policy.outlier_ratio * median).max(policy.outlier_floor_um);
    let mut far: Vec<(f64, RowError)> = of_kind()
        .map(|r| (r.final_um.norm(), r))
        .filter(|(n, _)| *n > bound || n.is_nan())
        .collect();
    far.sort_by(|a, b| b.0.total_cmp(&a.0));
    (!far.is_empty()).then_some((count, median, far))
}

/// Every row the outlier rule names (module docs), both kinds, largest
/// first within each: what `Settings::leave_out_outliers` leaves out.
pub fn outlying(report: &Report, policy: &Policy) -> Vec<RowError> {
    [false, true]
        .into_iter()
        .filter_map(|deflection| far_of_kind(&report.row_errors, deflection, policy))
        .flat_map(|(_, _, far)| far.into_iter().map(|(_, r)| r))
        .collect()
}

/// The warning when the calibrated model fits the rows worse than the
/// nominal robot by more than the share `margin`, with the weights of the
/// fit per configuration and axis ([`Report::noise`]; for OLS the RMS
/// themselves, without a pass over the rows): every
/// parameter zero is the nominal robot, so the fit ends at least as close
/// in its own (weighted) sum of squares, unless Gauss–Newton stopped at
/// another stationary point.
fn worse_than_nominal(report: &Report, margin: f64) -> Option<String> {
    // With rows of both kinds the fit's sum has the deflections' residuals
    // over `√2` (`Rows::noise_scale`): summed here the same way.
    let kinds = |d: bool| report.row_errors.iter().any(|r| r.deflection == d);
    let mixed = kinds(true) && kinds(false);
    if report.method == "ols" && !mixed {
        return worse_message(report.rms_um, report.nominal.rms_um, None, margin);
    }
    let weights: std::collections::HashMap<i64, [f64; 3]> =
        report.noise.iter().map(|n| (n.config, n.weight)).collect();
    let (mut fitted, mut nominal) = (0.0, 0.0);
    for r in &report.row_errors {
        let kind = if r.deflection {
            RowKind::Deflection
        } else {
            RowKind::Absolute
        };
        let s = crate::calibrate::rows::noise_scale(mixed, kind);
        let w = weights
            .get(&r.config)
            .copied()
            .unwrap_or([1.0; 3])
            .map(|w| w * s);
        for a in 0..3 {
            fitted += (w[a] * r.final_um[a]).powi(2);
            nominal += (w[a] * r.nominal_um[a]).powi(2);
        }
    }
    let rows = report.row_errors.len().max(1) as f64;
    let weighted = ((fitted / rows).sqrt(), (nominal / rows).sqrt());
    worse_message(report.rms_um, report.nominal.rms_um, Some(weighted), margin)
}

/// [`worse_than_nominal`]'s rule on the RMS `rms_um` and the nominal
/// robot's `nominal_um` \[µm\], or on their weighted counterparts when the
/// fit was weighted.
fn worse_message(
    rms_um: f64,
    nominal_um: f64,
    weighted: Option<(f64, f64)>,
    margin: f64,
) -> Option<String> {
    let (fitted, nominal) = weighted.unwrap_or((rms_um, nominal_um));
    (fitted > nominal * (1.0 + margin)).then(|| {
        let by_weight = weighted.map_or(String::new(), |(f, n)| {
            format!("; with the weights of the fit {f:.1} um against {n:.1} um")
        });
        format!(
            "the calibrated model fits the measurements worse than the nominal robot \
             (RMS {rms_um:.1} um against {nominal_um:.1} um{by_weight}): Gauss-Newton \
             ended at a wrong stationary point; check the setup (markers, base frame, \
             units) or declare fewer parameters"
        )
    })
}

#[cfg(test)]
mod tests {
    use crate::calibrate::report::plausibility::*;

    /// A fit that ended worse than the nominal robot is a warning (a random
    /// chain once ended, "converged", at 12 432 µm against the nominal
    /// robot's 803 µm); one that improved on it is not.
    #[test]
    fn a_fit_worse_than_the_nominal_robot_is_a_warning() {
        let w = worse_message(12432.4, 803.1, None, 0.01).expect("a warning");
        assert!(w.contains("RMS 12432.4 um against 803.1 um"), "{w}");
        assert!(worse_message(33.2, 803.1, None, 0.01).is_none());
        assert!(worse_message(803.1, 803.1, None, 0.01).is_none());
        // A base-only model ends at the nominal robot up to rounding (a
        // second reading found 42.40671294559378 against …377 warned).
        assert!(worse_message(42.40671294559378, 42.40671294559377, None, 0.01).is_none());
        assert!(worse_message(812.0, 803.1, None, 0.01).is_some());
        // A weighted fit is judged on its weighted sums: its unweighted
        // RMS may end above the nominal robot's (IRLS 693.7 µm against
        // 663.3 in a random chain, where OLS reached 657.9).
        assert!(worse_message(693.7, 663.3, Some((50.1, 52.4)), 0.01).is_none());
        let w = worse_message(693.7, 663.3, Some((60.0, 52.4)), 0.01).expect("a warning");
        assert!(
            w.contains("with the weights of the fit 60.0 um against 52.4 um"),
            "{w}"
        );
    }

    fn row(config: i64, deflection: bool, um: f64) -> RowError {
        RowError {
            config,
            marker: 1,
            deflection,
            nominal_um: Vector3::zeros(),
            final_um: Vector3::new(um, 0.0, 0.0),
        }
    }

    /// The outlier rule: above 20 times the median row's norm of its kind
    /// and above 1 µm, among at least 10 rows; the largest five named.
    #[test]
    fn rows_far_out_of_line_with_the_others_are_named() {
        let policy = Policy::default();
        // 20 rows of 10..29 µm: the median (the 11th smallest) is 20 µm.
        let mut rows: Vec<RowError> = (0..20).map(|i| row(i, false, 10.0 + i as f64)).collect();
        assert!(outliers(&rows, &policy).is_none());
        // 22 rows: the median is now 21 µm, the bound 420 µm (a norm: the
        // sign of an axis does not matter).
        rows.push(row(100, false, 421.0));
        rows.push(row(101, false, -419.0));
        let w = outliers(&rows, &policy).expect("a warning");
        assert!(
            w.starts_with("1 of 22 position rows has a residual above 20 times the median row's (21.0 um): config 100 marker 1 421.0 um;"),
            "{w}"
        );
        // Deflections are judged apart: their own median, their own count.
        let mut both = rows.clone();
        both.extend((0..10).map(|i| row(200 + i, true, 1000.0 + i as f64)));
        let w = outliers(&both, &policy).expect("a warning");
        assert!(w.contains("1 of 22 position rows has"), "{w}");
        assert!(!w.contains("deflection rows"), "{w}");
        // 28 rows, median 24 µm: six far rows, the five largest named,
        // then "..."; 421 µm is no longer far.
        rows.extend((0..6).map(|i| row(300 + i, false, 1000.0 + i as f64)));
        let w = outliers(&rows, &policy).expect("a warning");
        assert!(w.starts_with("6 of 28 position rows have"), "{w}");
        assert!(
            w.contains("config 305 marker 1 1005.0 um, config 304"),
            "{w}"
        );
        assert!(w.contains("config 301 marker 1 1001.0 um, ...;"), "{w}");
        assert!(!w.contains("config 100 "), "{w}");
        // Fewer than ten rows of a kind: no median to judge by.
        let few: Vec<RowError> = rows[..9]
            .iter()
            .copied()
            .chain([row(9, false, 1e6)])
            .collect();
        assert!(outliers(&few[1..], &policy).is_none());
        assert!(outliers(&few, &policy).is_some());
        // Rounding is not an outlier: nothing below 1 µm.
        let exact: Vec<RowError> = (0..20)
            .map(|i| row(i, false, 1e-9))
            .chain([row(20, false, 0.5)])
            .collect();
        assert!(outliers(&exact, &policy).is_none());
    }
}
