//! The trial of one candidate effect of the closed loop
//! ([`super::diagnosis`]): the model with it, fitted from the current
//! model's linearisation; whether its estimate is physical; its
//! leave-one-configuration-out RMS against the current model's.
//!
//! Every trial of a round starts from the same state, the engine as the
//! round's tests left it (at the current model's linearisation), on its own
//! copy of the engine ([`Start::engine`]): the trials are independent of
//! one another and of their order, and the loop runs them on worker
//! threads ([`super::parallel::map_until`]), taking their verdicts in order
//! of p-value. A trial's progress messages are kept and replayed by the
//! loop, in that order, on the calling thread.

use super::effects::{inadmissible, Candidate};
use super::engine::{Engine, Fitted};
use super::fit::FitSettings;
use super::geometry::Geometry;
use super::linearisation::Linearisation;
use super::names::Names;
use super::report::Tested;
use super::rows::Rows;
use super::settings::{CalibrationError, Policy};
use crate::model::Param;
use crate::Error;

/// What every trial of a round starts from: the engine's state, without
/// its progress callback (which stays on the calling thread).
pub struct Start {
    rows: Rows,
    names: Names,
    geometry: Geometry,
    lin: Linearisation,
    fit_settings: FitSettings,
    policy: Policy,
    heldout: bool,
}

/// The verdict of a trial.
pub enum Verdict {
    /// Not added, and why (a note).
    Rejected(String),
    /// Added: the fit with its held-out RMS, and the state the engine is
    /// left in.
    Accepted(Box<Fitted>, Box<End>),
    /// The run fails.
    Failed(CalibrationError),
}

/// The engine's state after an accepted trial.
pub struct End {
    rows: Rows,
    geometry: Geometry,
    lin: Linearisation,
}

/// A trial: its progress messages and its verdict.
pub struct Trial {
    /// Progress messages, in order.
    pub messages: Vec<String>,
    /// The verdict.
    pub verdict: Verdict,
}

impl Trial {
    /// Whether the loop stops at this trial (it is the last one looked at).
    pub fn ends_round(&self) -> bool {
        !matches!(self.verdict, Verdict::Rejected(_))
    }
}

impl Start {
    /// The state of `e`.
    pub fn of(e: &Engine<'_>) -> Self {
        Self {
            rows: e.rows.clone(),
            names: e.names.clone(),
            geometry: e.geometry.clone(),
            lin: e.lin.clone(),
            fit_settings: e.fit_settings,
            policy: e.policy,
            heldout: e.heldout,
        }
    }

    /// A copy of the engine at this state, its progress messages to `log`.
    fn engine<'a>(&self, log: &'a mut dyn FnMut(&str)) -> Engine<'a> {
        Engine {
            rows: self.rows.clone(),
            names: self.names.clone(),
            geometry: self.geometry.clone(),
            lin: self.lin.clone(),
            fit_settings: self.fit_settings,
            policy: self.policy,
            heldout: self.heldout,
            progress: log,
        }
    }

    /// The trial of candidate `c` (tested as `t`) against `current`.
    pub fn trial(&self, current: &Fitted, c: &Candidate, t: &Tested) -> Trial {
        let mut messages = Vec::new();
        let mut log = |m: &str| messages.push(m.to_string());
        let mut e = self.engine(&mut log);
        let verdict = match verdict(&mut e, current, c, t) {
            Ok(Ok(next)) => Verdict::Accepted(
                Box::new(next),
                Box::new(End {
                    rows: e.rows,
                    geometry: e.geometry,
                    lin: e.lin,
                }),
            ),
            Ok(Err(why)) => Verdict::Rejected(why),
            Err(err) => Verdict::Failed(err),
        };
        Trial { messages, verdict }
    }
}

impl End {
    /// Puts `e` in this state.
    pub fn restore(self, e: &mut Engine<'_>) {
        e.rows = self.rows;
        e.geometry = self.geometry;
        e.lin = self.lin;
    }
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

/// The fit of `current` with `c` added, if it is to be added (its estimate
/// physical, its held-out RMS lower than `current`'s when both are
/// computed), else why not.
///
/// # Errors
/// An error of the fit that is not the candidate's (those reject it).
fn verdict(
    e: &mut Engine<'_>,
    current: &Fitted,
    c: &Candidate,
    t: &Tested,
) -> Result<Result<Fitted, String>, CalibrationError> {
    let new_params = extended(e, &current.params, c)?;
    // A candidate whose fit cannot be made is rejected, never the run: no
    // equilibrium under its estimate, or a column the estimator finds
    // dependent on the others.
    let next = match e.fit(&new_params) {
        Ok(next) => next,
        Err(CalibrationError::NoEquilibrium(why)) => {
            return Ok(Err(format!(
                "rejected: with its estimate the robot has no equilibrium ({why})"
            )))
        }
        Err(CalibrationError::Dependent(_)) => {
            return Ok(Err(
                "rejected: at its fitted geometry a column is a combination of the others"
                    .to_string(),
            ))
        }
        Err(CalibrationError::Core(
            _,
            err @ (Error::NotIdentifiable { .. }
            | Error::TooFewEquations { .. }
            | Error::NotConverged { .. }),
        )) => return Ok(Err(format!("rejected: its fit cannot be made ({err})"))),
        Err(err) => return Err(err),
    };
    if let Some(why) = inadmissible(&e.names, &e.policy, &next.params, &next.fit.x, &c.add) {
        return Ok(Err(format!(
            "rejected: its estimate is not physical ({why})"
        )));
    }
    let next = e.with_heldout(next)?;
    match (current.heldout_rms_um, next.heldout_rms_um) {
        (Some(before), Some(after)) if after >= before => Ok(Err(format!(
            "not added: significant (p = {:.1e}) but the \
             leave-one-configuration-out RMS does not drop \
             ({before:.1} -> {after:.1} um)",
            t.p_value
        ))),
        _ => Ok(Ok(next)),
    }
}
