//! The trial of candidate effects in the closed loop ([`super::diagnosis`]):
//! the model with a candidate added, fitted by Gauss–Newton from the
//! current model's state ([`Engine::fit`]), its estimate checked against
//! the plausibility rules ([`inadmissible`]).
//!
//! Every trial starts from the same state, the current model's rows bit for
//! bit: after a trial on the engine itself, [`Engine::restore_from`] puts
//! the rows' equilibria back where they started. The trials are therefore
//! independent of one another and of their order, and several can run side
//! by side with the answers of the serial loop ([`super::parallel`]): when
//! more than one candidate is eligible and the rows are too few for threads
//! inside one relinearisation (at most [`super::parallel::for_rows`]' one
//! thread), the candidates are fitted on copies of the engine's state on
//! worker threads, in order, up to the first whose estimate is admissible;
//! the engine takes over that one's state. A trial after an admissible one
//! stops at its next Gauss–Newton step ([`Engine::cancel`]): it would be
//! dropped.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use super::effects::{inadmissible, Candidate};
use super::engine::{Engine, Fitted, LastDesign};
use super::fit::FitSettings;
use super::geometry::Geometry;
use super::linearisation::Linearisation;
use super::names::Names;
use super::parallel;
use super::rows::Rows;
use super::settings::{CalibrationError, Policy};
use crate::model::Param;
use crate::Error;

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
    Ok(
        match inadmissible(&e.names, &e.policy, &next.params, &next.fit.x, &c.add) {
            Some(why) => {
                Outcome::Rejected(format!("rejected: its estimate is not physical ({why})"))
            }
            None => Outcome::Admissible(Box::new(next)),
        },
    )
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
    Ok(d.independent(&[], &all).iter().map(|&i| new[i]).collect())
}
