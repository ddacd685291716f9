//! The declared parameters left out at the nominal robot, tested again at
//! the fitted one.
//!
//! Which declared parameters the data identify is decided at the nominal
//! robot ([`crate::calibrate::engine::Engine::left_out`]): its dependences are mostly
//! structural (a1's offset is the base's turn about z) and hold at every
//! geometry. Some hold only at the nominal one: a marker exactly on a
//! joint's axis there makes that joint's turn and a tilt of the base move
//! it alike, while the real marker, a little off the axis, tells them
//! apart. Left out, such a parameter leaves its whole effect in the
//! residuals (a property test found 365 µm of RMS against 33 µm of noise,
//! with no warning). The same holds for a parameter that a Gauss–Newton
//! step made dependent on the way (`first_fit`: 60 µm against
//! 33 µm on another random chain, seed 14554966693631364839). So each
//! parameter left out at the nominal robot or on the way is carried,
//! unfitted, in the declared fit's designs ([`Engine::fit_carrying`]), and
//! at the fitted geometry:
//!
//! 1. those the one independence test ([`crate::estimate::rank`]) finds
//!    independent of the fitted ones there are the candidates;
//! 2. forward selection, one parameter at a time: each candidate's nested
//!    F test ([`crate::estimate::nested_test`], the fit's weights) against
//!    the model and the parameters already chosen; the most significant is
//!    chosen when `p · (candidates tested) <` [`crate::calibrate::settings::Policy::alpha`]
//!    (Bonferroni, as for the effects), until none is. A parameter that only
//!    rides along with a significant one is not chosen;
//! 3. the declared model is fitted again with the chosen ones, in the
//!    model's order ([`crate::calibrate::effects::declared`]: the base before the joints, which
//!    decides what a dependence leaves out). The report's notes name those
//!    that the new fit keeps; one that it leaves out again is reported left
//!    out, with what absorbs it there. If none is kept, if the new fit
//!    realises less than [`crate::calibrate::settings::Policy::min_realised`] of the drop in the
//!    residual sum of squares the tests predict (they are made at the first
//!    fit's linearisation, and a poor first-order picture can promise what
//!    the new fit does not find: a random chain, seed 2155227116266218952,
//!    promised 94 %, and the new fit's RMS was 128.27 µm against 128.27),
//!    or if it fails, the first
//!    fit stands (a failure is a warning: the declared model lacks a
//!    parameter the data ask for).
//!
//! The test keeps a dependence that the fitted geometry breaks only by
//! rounding (DLR Justin's `left_0.tx` and `left_0.ty`: independent at the
//! fitted geometry, F = 0.28 on (2, 1722) together) from fitting noise.
//! One round: a parameter that becomes independent only after the chosen
//! ones moved the geometry again stays left out.

use crate::calibrate::engine::{Engine, Fitted};
use crate::calibrate::fit::{self, Method};
use crate::calibrate::params::names::Names;
use crate::calibrate::report::LeftOut;
use crate::calibrate::settings::CalibrationError;
use crate::error::Error;
use crate::estimate::{Accumulator, NestedTest};
use crate::model::Param;
use nalgebra::Dyn;

/// The declared model fitted. A parameter that a Gauss–Newton step makes
/// dependent on the others (at the geometry the step reached) is left out
/// with the parameters that absorb it there, and the fit goes on from there
/// without it; a declared compliance that becomes dependent is an error, as
/// at the nominal robot. `carried` and what is returned beside the fit as
/// in [`Engine::fit_carrying`]; a parameter left out on the way is carried
/// from there on (added to `carried`), to be tested again at the fitted
/// geometry (the rest of this module).
///
/// # Errors
/// [`CalibrationError::Data`] when a compliance or every parameter is
/// left out; as [`Engine::fit`].
pub(in crate::calibrate) fn first_fit(
    e: &mut Engine<'_>,
    mut params: Vec<Param>,
    left_out: &mut Vec<LeftOut>,
    carried: &mut Vec<Param>,
) -> Result<(Fitted, Option<Accumulator<f64, Dyn>>), CalibrationError> {
    loop {
        match e.fit_carrying(&params, carried) {
            Err(CalibrationError::Dependent(_)) => {}
            // The solver's refusal, by name (a candidate's is its rejection,
            // `crate::calibrate::diagnosis::trial`); of a weighted fit, with the unweighted one
            // offered (the independence test passed the unweighted columns).
            Err(CalibrationError::Core("fit", err)) => {
                return Err(match CalibrationError::of_fit(err, &params, &e.names) {
                    CalibrationError::Data(why) if e.fit_settings.method != Method::Ols => {
                        CalibrationError::Data(format!(
                            "{why}, or fit without weights (--method ols)"
                        ))
                    }
                    other => other,
                })
            }
            other => return other,
        }
        let now = e.left_out(&params)?;
        let out: Vec<Param> = params
            .iter()
            .filter(|p| now.iter().any(|l| l.name == e.names.name(p)))
            .copied()
            .collect();
        if let Some(p) = out.iter().find(|p| p.is_compliance()) {
            return Err(CalibrationError::Data(format!(
                "{} cannot be identified: at the fitted geometry its column is a \
                 combination of the other parameters'; measure more configurations, or \
                 remove it from [model]",
                e.names.name(p)
            )));
        }
        if out.is_empty() {
            return Err(CalibrationError::Data(
                "the declared model could not be fitted: a parameter became dependent on \
                 the others during the fit"
                    .into(),
            ));
        }
        for l in now {
            (e.progress)(&format!(
                "{} left out: dependent on the others at the fitted geometry",
                l.name
            ));
            left_out.push(l);
        }
        params.retain(|p| !out.contains(p));
        carried.extend_from_slice(&out);
        if params.is_empty() {
            return Err(CalibrationError::Data(
                "the declared model has no parameter these data can identify".into(),
            ));
        }
    }
}

/// `first`, the declared fit that carried `carried`
/// ([`Engine::fit_carrying`]; `info` its unit-weight sums with OLS), or the
/// fit with those of `carried` that the rule of the module re-adds (taken
/// off `left_out`, with a note in `notes`; a failed fit with them is a
/// warning in `warnings`). `order` is the declared model's order.
///
/// # Errors
/// As [`Engine::design`] and [`fit::test`];
/// [`CalibrationError::Cancelled`] from the new fit.
#[allow(clippy::too_many_arguments)]
pub fn revive(
    e: &mut Engine<'_>,
    first: Fitted,
    info: Option<Accumulator<f64, nalgebra::Dyn>>,
    carried: &[Param],
    order: &[Param],
    left_out: &mut Vec<LeftOut>,
    notes: &mut Vec<String>,
    warnings: &mut Vec<String>,
) -> Result<Fitted, CalibrationError> {
    if carried.is_empty() {
        return Ok(first);
    }
    let all: Vec<Param> = first.params.iter().chain(carried).copied().collect();
    let chosen = choose(e, &first, &all, info.as_ref())?;
    if chosen.is_empty() {
        e.drop_carried(&first.params);
        return Ok(first);
    }
    let revived: Vec<Param> = chosen.iter().map(|(c, _)| all[*c]).collect();
    let params: Vec<Param> = order
        .iter()
        .filter(|p| first.params.contains(p) || revived.contains(p))
        .copied()
        .collect();
    let tests = |n: &Names, of: &[Param]| -> Vec<String> {
        chosen
            .iter()
            .filter(|(c, _)| of.contains(&all[*c]))
            .map(|(c, t)| {
                format!(
                    "{}: F = {:.1} on ({}, {}), p = {:.1e}",
                    n.name(&all[*c]),
                    t.f,
                    t.dof_num,
                    t.dof_den,
                    t.p_value
                )
            })
            .collect()
    };
    let mut now = left_out.clone();
    let revived_names = names(&e.names, &revived);
    now.retain(|l| !revived_names.contains(&l.name));
    let refit = first_fit(e, params, &mut now, &mut Vec::new()).map(|(f, _)| f);
    if let Err(CalibrationError::Cancelled) = refit {
        return Err(CalibrationError::Cancelled);
    }
    // The tests are at the first fit's linearisation: a new fit that does
    // not realise a good share of the drop they predict did not find what
    // they promised (a poor first-order picture), and the first fit
    // stands, with its warnings.
    let predicted = chosen.iter().map(|(_, t)| t.delta_rss).sum::<f64>()
        / chosen[0].1.rss_before.max(f64::MIN_POSITIVE);
    // (With rows of both kinds or a robust loss's weights, on the design's
    // scale: the residuals by `Rows::noise_scale`, as the tests summed
    // them.)
    let scaled_rss = |f: &Fitted| -> f64 {
        (e.rows.rows.iter().zip(&f.residuals))
            .map(|(row, r)| (r * e.rows.noise_scale(row)).norm_squared())
            .sum()
    };
    let realised = |f: &Fitted| {
        if e.rows.scaled() {
            1.0 - scaled_rss(f) / scaled_rss(&first).max(f64::MIN_POSITIVE)
        } else {
            1.0 - (f.rms_um / first.rms_um).powi(2)
        }
    };
    let kept: Vec<Param> = match &refit {
        Ok(f) if realised(f) >= e.policy.min_realised * predicted => revived
            .iter()
            .filter(|p| f.params.contains(p))
            .copied()
            .collect(),
        _ => Vec::new(),
    };
    match refit {
        Ok(f) if !kept.is_empty() => {
            let note = format!(
                "{} re-added: left out as dependent on the others at the nominal robot or \
                 on the way, independent at the fitted geometry, where each is significant \
                 given the model and those before it ({}; Bonferroni over the candidates, \
                 alpha {})",
                names(&e.names, &kept).join(", "),
                tests(&e.names, &kept).join("; "),
                e.policy.alpha
            );
            (e.progress)(&note);
            notes.push(note);
            *left_out = now;
            Ok(f)
        }
        other => {
            if let Err(err) = other {
                warnings.push(format!(
                    "{} left out on the way tested significant at the fitted geometry \
                     ({}), but the fit with them failed ({err}): the declared model is \
                     reported without them",
                    revived_names.join(", "),
                    tests(&e.names, &revived).join("; ")
                ));
            }
            // The first fit stands (a re-added parameter left out again:
            // as if it had not been re-added).
            e.restore(&first)?;
            Ok(first)
        }
    }
}

/// The names of `ps`.
fn names(n: &Names, ps: &[Param]) -> Vec<String> {
    ps.iter().map(|p| n.name(p)).collect()
}

/// The carried columns (after the first `first.params.len()` of `all`)
/// chosen by the forward selection of the module, in the order chosen,
/// each with its test.
fn choose(
    e: &Engine<'_>,
    first: &Fitted,
    all: &[Param],
    info: Option<&Accumulator<f64, nalgebra::Dyn>>,
) -> Result<Vec<(usize, NestedTest)>, CalibrationError> {
    let n = first.params.len();
    // The fit's last design: its parameters, then the carried ones.
    let d = e.design(all)?;
    let mut model: Vec<usize> = (0..n).collect();
    let extra: Vec<usize> = (n..all.len()).collect();
    let mut left = match info {
        // The same test on the same sums (`Design::independent`'s are the
        // unit-weight sums of these columns in this order).
        Some(acc) => match d.identifiability_of(&(0..all.len()).collect::<Vec<_>>(), acc) {
            Some(rank) => extra.iter().copied().filter(|&c| rank.kept[c]).collect(),
            None => Vec::new(),
        },
        None => d.independent(&model, &extra),
    };
    let mut chosen: Vec<(usize, NestedTest)> = Vec::new();
    while !left.is_empty() {
        let mut best: Option<(usize, NestedTest)> = None;
        for &c in &left {
            let t = match info {
                // OLS: the fit's weights are one, and these are its sums.
                Some(acc) => {
                    let cols: Vec<usize> = model.iter().copied().chain([c]).collect();
                    fit::test_sums(&fit::columns_of(acc, &cols), model.len())
                }
                None => fit::test(&d, &model, &[c], &first.fit.weights),
            };
            match t {
                Ok(t) if best.as_ref().is_none_or(|b| t.p_value < b.1.p_value) => {
                    best = Some((c, t));
                }
                Ok(_) | Err(Error::NotIdentifiable { .. } | Error::TooFewEquations { .. }) => {}
                Err(err) => return Err(CalibrationError::Core("left-out test", err)),
            }
        }
        let tried = left.len() as f64;
        match best {
            Some((c, t)) if t.p_value * tried < e.policy.alpha => {
                model.push(c);
                left.retain(|&l| l != c);
                chosen.push((c, t));
            }
            _ => break,
        }
    }
    Ok(chosen)
}
