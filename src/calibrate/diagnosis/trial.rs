//! The trial of candidate effects in the closed loop ([`crate::calibrate::diagnosis`]):
//! the model with a candidate added, fitted by Gauss–Newton from the
//! current model's state ([`Engine::fit`]), its estimate checked against
//! the plausibility rules ([`inadmissible`]).
//!
//! Every trial starts from the same state, the current model's rows bit for
//! bit: after a trial on the engine itself, [`Engine::restore_from`] puts
//! the rows' equilibria back where they started. The trials are therefore
//! independent of one another and of their order, and several can run side
//! by side with the answers of the serial loop ([`crate::parallel`]): when
//! more than one candidate is eligible and the rows are too few for threads
//! inside one relinearisation (at most [`crate::parallel::for_rows`]' one
//! thread), the candidates are fitted on copies of the engine's state on
//! worker threads, in order, up to the first whose estimate is admissible;
//! the engine takes over that one's state. A trial after an admissible one
//! stops at its next Gauss–Newton step ([`Engine::cancel`]): it would be
//! dropped.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use nalgebra::Dyn;

use crate::calibrate::design::Design;
use crate::calibrate::effects::{inadmissible, Candidate};
use crate::calibrate::engine::{Engine, Fitted, LastDesign};
use crate::calibrate::fit::{columns_of, information, FitSettings};
use crate::calibrate::params::geometry::Geometry;
use crate::calibrate::params::linearisation::Linearisation;
use crate::calibrate::params::names::Names;
use crate::calibrate::rows::Rows;
use crate::calibrate::settings::{CalibrationError, Policy};
use crate::error::Error;
use crate::estimate::Accumulator;
use crate::model::Param;
use crate::parallel;

/// What the trial of one candidate found.
pub enum Outcome {
    /// Not added, and why (the report's note).
    Rejected(String),
    /// Fitted, its estimate admissible: the engine is at its state.
    Admissible(Box<Fitted>),
}

/// The outcomes of `cands` tried in order from the current model's state
/// (`current`, with its rows' equilibria `start`: [`Rows::start_points`]),
/// up to and including the first admissible one (all of them when none
/// is). After it the engine is at the admissible one's state, or at
/// `current`'s when all were rejected.
///
/// # Errors
/// A trial's error that is not a rejection (the run's error), as
/// [`Engine::fit`]; as [`Engine::restore_from`].
pub fn first_admissible(
    e: &mut Engine<'_>,
    current: &Fitted,
    start: &[Vec<f64>],
    cands: &[&Candidate],
) -> Result<Vec<Outcome>, CalibrationError> {
    let threads = if parallel::for_rows(e.rows.rows.len()) == 1 {
        parallel::threads().min(cands.len())
    } else {
        1
    };
    if threads <= 1 {
        let mut out = Vec::new();
        for c in cands {
            match one(e, &current.params, c)? {
                Outcome::Rejected(why) => {
                    e.restore_from(current, start)?;
                    out.push(Outcome::Rejected(why));
                }
                admissible => {
                    out.push(admissible);
                    break;
                }
            }
        }
        return Ok(out);
    }
    let seed = Seed {
        rows: &e.rows,
        names: &e.names,
        geometry: &e.geometry,
        lin: &e.lin,
        fit_settings: e.fit_settings,
        policy: e.policy,
        heldout: e.heldout,
    };
    // The first admissible index so far: a trial after it is abandoned at
    // its next Gauss–Newton step (its result would be dropped anyway).
    let first = AtomicUsize::new(usize::MAX);
    let tried = parallel::map_until(
        cands.len(),
        threads,
        |i| {
            let cancel = || first.load(Ordering::Relaxed) < i;
            let r = seed.try_one(&current.params, cands[i], &cancel);
            if matches!(r, Ok((Outcome::Admissible(_), _))) {
                first.fetch_min(i, Ordering::Relaxed);
            }
            r
        },
        |r| !matches!(r, Ok((Outcome::Rejected(_), _))),
    );
    let mut out = Vec::with_capacity(tried.len());
    for t in tried {
        let (outcome, state) = t?;
        if let Outcome::Admissible(_) = outcome {
            e.rows = state.rows;
            e.geometry = state.geometry;
            e.lin = state.lin;
            e.last_design = state.last_design;
        }
        out.push(outcome);
    }
    Ok(out)
}

/// The engine's state, shared by the worker threads that fit candidates.
struct Seed<'s> {
    rows: &'s Rows,
    names: &'s Names,
    geometry: &'s Geometry,
    lin: &'s Linearisation,
    fit_settings: FitSettings,
    policy: Policy,
    heldout: bool,
}

/// The state a trial on a copy of the engine ends at.
struct State {
    rows: std::sync::Arc<Rows>,
    geometry: Geometry,
    lin: Linearisation,
    last_design: Mutex<Option<LastDesign>>,
}

impl Seed<'_> {
    /// [`one`] on a copy of the engine (no progress messages: a trial
    /// makes none).
    fn try_one(
        &self,
        params: &[Param],
        c: &Candidate,
        cancel: &(dyn Fn() -> bool + Sync),
    ) -> Result<(Outcome, State), CalibrationError> {
        let mut quiet = |_: &str| {};
        let mut e = Engine {
            cancel: Some(cancel),
            rows: std::sync::Arc::new(self.rows.clone()),
            names: self.names.clone(),
            geometry: self.geometry.clone(),
            lin: self.lin.clone(),
            fit_settings: self.fit_settings,
            policy: self.policy,
            heldout: self.heldout,
            progress: &mut quiet,
            last_design: Mutex::new(None),
        };
        let outcome = one(&mut e, params, c)?;
        Ok((
            outcome,
            State {
                rows: e.rows,
                geometry: e.geometry,
                lin: e.lin,
                last_design: e.last_design,
            },
        ))
    }
}

/// The trial of `c` on the model `params`: the model with it fitted, and
/// the verdict on its estimate. A candidate whose fit cannot be made is
/// rejected, never the run: no equilibrium under its estimate, or a column
/// the estimator finds dependent on the others.
fn one(e: &mut Engine<'_>, params: &[Param], c: &Candidate) -> Result<Outcome, CalibrationError> {
    let new_params = extended(e, params, c)?;
    let next = match e.fit(&new_params) {
        Ok(next) => next,
        Err(CalibrationError::NoEquilibrium(why)) => {
            return Ok(Outcome::Rejected(format!(
                "rejected: with its estimate the robot has no equilibrium ({why})"
            )))
        }
        Err(CalibrationError::Dependent(_)) => {
            return Ok(Outcome::Rejected(
                "rejected: at its fitted geometry a column is a combination of the others"
                    .to_string(),
            ))
        }
        Err(CalibrationError::Core(
            _,
            err @ (Error::NotIdentifiable { .. }
            | Error::TooFewEquations { .. }
            | Error::NotConverged { .. }),
        )) => {
            return Ok(Outcome::Rejected(format!(
                "rejected: its fit cannot be made ({err})"
            )))
        }
        Err(err) => return Err(err),
    };
    // A model that Gauss–Newton could not settle (no step lowered its cost,
    // or it ran out of steps) is no better known than the current one.
    if !next.converged {
        return Ok(Outcome::Rejected(format!(
            "rejected: its fit did not converge ({} Gauss-Newton relinearisations, {} \
             reweighting iterations)",
            next.relinearisations, next.fit.iterations
        )));
    }
    if let Some(why) = wandering(e, &next, c)? {
        return Ok(Outcome::Rejected(why));
    }
    // A mass is judged as the mass it is, not as its last step.
    let x: Vec<f64> = (next.params.iter().zip(&next.fit.x))
        .map(|(p, &v)| match p {
            Param::LinkMass { .. } => next.geometry.value(p, v),
            _ => v,
        })
        .collect();
    // A body heavier than all the robot's other bodies together is not a
    // correction of its mass model: a payload (a [load]), or an error of
    // another kind that the mass absorbs (Justin: a 2 kg lump fitted at
    // 75 ± 17 kg, no better held out).
    let heavy = (next.params.iter().zip(&x)).find_map(|(p, &m)| match p {
        Param::LinkMass { joint } if c.add.contains(p) => {
            let others = next.geometry.others_mass_kg(*joint);
            (m > others).then(|| {
                format!(
                    "{} = {m:.3} kg, more than all the robot's other bodies together, \
                     {others:.3} kg",
                    e.names.name(p)
                )
            })
        }
        _ => None,
    });
    if let Some(why) = heavy {
        return Ok(Outcome::Rejected(format!(
            "rejected: its estimate is not physical ({why})"
        )));
    }
    Ok(
        match inadmissible(&e.names, &e.policy, &next.params, &x, &c.add) {
            Some(why) => {
                Outcome::Rejected(format!("rejected: its estimate is not physical ({why})"))
            }
            None => Outcome::Admissible(Box::new(next)),
        },
    )
}

/// Why the trial `f` of candidate `c` is rejected when the data barely
/// tell its parameters from the model's: a parameter of `f` whose variance
/// inflation (its unweighted column regressed on the others',
/// [`crate::estimate::Identifiability::inflation`]) reaches
/// [`Policy::max_candidate_inflation`], and that is one of the candidate's
/// or explained mostly by one of them. Along such a direction the data
/// hardly change the fit, and Gauss–Newton settles wherever the unmodelled
/// rest of the data pulls it: a UR5's shoulder and elbow offsets at ∓1.29
/// rad with `elbow_joint.tx` at −1.05 m, predicting as well as the truth
/// (`shared/repro/ur5-joint-offsets`).
///
/// # Errors
/// As [`Engine::design`].
fn wandering(
    e: &Engine<'_>,
    f: &Fitted,
    c: &Candidate,
) -> Result<Option<String>, CalibrationError> {
    let Some(rank) = e.identifiability(f)? else {
        return Ok(None);
    };
    let added = |k: usize| c.add.contains(&f.params[k]);
    for i in 0..f.params.len() {
        let Some(inflation) = rank.inflation(i) else {
            continue;
        };
        if inflation < e.policy.max_candidate_inflation {
            continue;
        }
        let with: Vec<usize> = rank
            .explained_by(i)
            .iter()
            .take(3)
            .map(|a| a.param)
            .collect();
        if added(i) || with.iter().any(|&k| added(k)) {
            let names: Vec<String> = with.iter().map(|&k| e.names.name(&f.params[k])).collect();
            return Ok(Some(format!(
                "rejected: the data barely tell its parameters from the model's ({} has a \
                 variance inflation of {inflation:.1e} with it, with {}): its estimate would \
                 follow whatever else the data hold along that direction",
                e.names.name(&f.params[i]),
                names.join(", ")
            )));
        }
    }
    Ok(None)
}

/// The model `params` with candidate `c` added: its parameters go where the
/// parameters they replace were, else at the end; then the identifiable
/// subset.
fn extended(
    e: &Engine<'_>,
    params: &[Param],
    c: &Candidate,
) -> Result<Vec<Param>, CalibrationError> {
    let at = params
        .iter()
        .position(|p| c.remove.contains(p))
        .unwrap_or(params.len());
    let mut new: Vec<Param> = params[..at]
        .iter()
        .filter(|p| !c.remove.contains(p))
        .copied()
        .collect();
    new.extend(c.add.iter().filter(|a| !params.contains(a)));
    new.extend(params[at..].iter().filter(|p| !c.remove.contains(p)));
    let d = e.design(&new)?;
    let all: Vec<usize> = (0..new.len()).collect();
    let kept = d.independent(&[], &all);
    // The candidate's own columns (not the model's) within the loop's
    // bound on variance inflation ([`screened`]).
    let (added, model): (Vec<usize>, Vec<usize>) = kept
        .iter()
        .partition(|&&i| c.add.contains(&new[i]) && !params.contains(&new[i]));
    if added.is_empty() {
        return Ok(kept.iter().map(|&i| new[i]).collect());
    }
    let sums = information(&d, &all).map_err(|err| CalibrationError::Core("columns", err))?;
    let added = screened(&d, &sums, &model, &added, e.policy.max_candidate_inflation);
    Ok((0..new.len())
        .filter(|i| model.contains(i) || added.contains(i))
        .map(|i| new[i])
        .collect())
}

/// Of a candidate's columns `extra` of `d` (independent of the model's
/// columns `base` by the one test), those the data determine well enough
/// for the closed loop to add: while one has a variance inflation (its
/// column regressed on all the others of `base` and `extra`) at or above
/// `bound` ([`Policy::max_candidate_inflation`]), the largest such is
/// dropped. `sums` are the unit-weight sums of every column of `d`
/// ([`information`]): no pass over the rows.
pub(in crate::calibrate) fn screened(
    d: &Design,
    sums: &Accumulator<f64, Dyn>,
    base: &[usize],
    extra: &[usize],
    bound: f64,
) -> Vec<usize> {
    let mut keep = extra.to_vec();
    loop {
        let cols: Vec<usize> = base.iter().chain(&keep).copied().collect();
        let Some(rank) = d.identifiability_of(&cols, &columns_of(sums, &cols)) else {
            return keep;
        };
        let worst = (0..keep.len())
            .filter_map(|k| rank.inflation(base.len() + k).map(|v| (k, v)))
            .filter(|(_, v)| *v >= bound)
            .max_by(|a, b| a.1.total_cmp(&b.1));
        match worst {
            Some((k, _)) => {
                keep.remove(k);
            }
            None => return keep,
        }
    }
}
