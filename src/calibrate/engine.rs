//! The fit of a model: rows at the current linearisation, the estimator
//! (`fit`), Gauss–Newton on the geometry and the linearised effects, and
//! the leave-one-configuration-out prediction error.

use std::sync::{Arc, Mutex};

use nalgebra::Vector3;

mod heldout;

use crate::calibrate::design::Design;
use crate::calibrate::fit::residuals::rms_um;
use crate::calibrate::fit::{
    fit_with_residuals, information, leading, FitOut, FitSettings, Method,
};
use crate::calibrate::params::geometry::Geometry;
use crate::calibrate::params::linearisation::Linearisation;
use crate::calibrate::params::names::Names;
use crate::calibrate::report::calibrated::CalibratedModel;
use crate::calibrate::report::{Absorbed, LeftOut, Parameter};
use crate::calibrate::rows::{RowKind, Rows};
use crate::calibrate::settings::{CalibrationError, Policy, Progress};
use crate::estimate::Accumulator;
use crate::model::Param;

/// A fitted model: its parameters, estimate and errors, and the
/// linearisation it was fitted at.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// The model's parameters.
    pub params: Vec<Param>,
    /// The fit (all columns of `params`, in order).
    pub fit: FitOut,
    /// The geometry the fit is linearised at (its geometric steps are below
    /// [`Policy::step_tolerance`]).
    pub geometry: Geometry,
    /// The joint law the rows were evaluated at.
    pub linearisation: Linearisation,
    /// Gauss–Newton relinearisations.
    pub relinearisations: usize,
    /// Whether Gauss–Newton settled within [`Policy::max_steps`] (and, for
    /// IRLS, the reweighting within its iterations).
    pub converged: bool,
    /// RMS of the position residuals \[µm\].
    pub rms_um: f64,
    /// Leave-one-configuration-out RMS \[µm\], when computed.
    pub heldout_rms_um: Option<f64>,
    /// Residual \[m\] of every row.
    pub residuals: Vec<Vector3<f64>>,
    /// The unit-weight sums of the columns of `params` at `geometry`
    /// ([`information`]) when the fit made them (OLS): the independence
    /// test of the final model needs no pass of its own.
    pub information: Option<Accumulator<f64, nalgebra::Dyn>>,
}

/// The problem being solved: rows, names, the current linearisation, and
/// how to fit.
pub struct Engine<'a> {
    /// The rows at the current linearisation, shared with the designs
    /// that recompute their columns from them ([`Design`]'s columns are
    /// held, or recomputed from these rows where a pass reads them: see
    /// [`Policy::max_held_design_rows`]). Changed through
    /// [`Engine::rows_mut`].
    pub rows: Arc<Rows>,
    /// Names of joints, markers, bins.
    pub names: Names,
    /// The current geometry (Gauss–Newton).
    pub geometry: Geometry,
    /// The current joint law and deflection model.
    pub lin: Linearisation,
    /// How each fit is made.
    pub fit_settings: FitSettings,
    /// Decision constants.
    pub policy: Policy,
    /// Compute the held-out RMS (and require it to drop for an effect).
    pub heldout: bool,
    /// Progress messages.
    pub progress: Progress<'a>,
    /// Whether to abandon a fit ([`Engine::fit`] checks it before each
    /// Gauss–Newton step): a candidate's trial on a worker thread once an
    /// earlier candidate was admissible ([`crate::calibrate::diagnosis::trial`]).
    pub cancel: Option<&'a (dyn Fn() -> bool + Sync)>,
    /// The last design [`Engine::design`] built: its parameters, the rows'
    /// linearisation it was built at ([`Rows::at`]), the design. A fit's
    /// last design is asked for again by its held-out error and its
    /// identifiability report; with many rows a design is seconds and
    /// hundreds of MB.
    pub last_design: Mutex<Option<LastDesign>>,
}

/// A design and what it was built from: [`Engine::last_design`].
pub type LastDesign = (Vec<Param>, (Geometry, Linearisation), Arc<Design>);

/// A linearisation a fit went through, and the cost of its model
/// ([`Engine::fit_carrying`]): where a fit that does not settle ends.
struct Good {
    geometry: Geometry,
    lin: Linearisation,
    /// The cost of its model, with the fit's first weights.
    cost: f64,
}

/// Whether the cost `c` is above `bound`, or not a number.
fn above(c: f64, bound: f64) -> bool {
    c.is_nan() || c > bound
}

/// The cost of the model `v` (values of the columns `cols` of `d`): the
/// sum of its squared residuals (scaled, as the fit sees them) weighted by
/// `weights` per group and axis (unit weights when `None`). With unit
/// weights and the unit-weight sums `ols` of those columns, from the sums,
/// `yᵀy − 2vᵀη + vᵀΛv`, without a pass over the rows.
fn cost(
    d: &Design,
    cols: &[usize],
    v: &[f64],
    ols: Option<&Accumulator<f64, nalgebra::Dyn>>,
    weights: Option<&[Vector3<f64>]>,
) -> f64 {
    if let (Some(acc), None) = (ols, weights) {
        let v = nalgebra::DVector::from_column_slice(v);
        return acc.weighted_yy() - 2.0 * v.dot(acc.eta()) + v.dot(&(acc.information() * &v));
    }
    let one = Vector3::repeat(1.0);
    (d.scaled_residuals(cols, v).iter().enumerate())
        .map(|(i, r)| {
            let w = weights.and_then(|w| w.get(d.group[i])).unwrap_or(&one);
            w.component_mul(r).norm_squared()
        })
        .sum()
}

/// [`Engine::rows_mut`] of the engine's `rows` and `last` design.
fn rows_mut<'r>(rows: &'r mut Arc<Rows>, last: &mut Mutex<Option<LastDesign>>) -> &'r mut Rows {
    let last = last
        .get_mut()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if last.as_ref().is_some_and(|(_, _, d)| !d.is_held()) {
        *last = None;
    }
    Arc::make_mut(rows)
}

impl<'a> Engine<'a> {
    /// An engine at `job`'s nominal robot, without a held-out error: as
    /// rows of poses to be measured need it ([`crate::calibrate::varied`]'s
    /// poses, [`crate::calibrate::plan`]'s candidates); a calibration
    /// (`calibrate::run`) turns [`Engine::heldout`] on as its settings say.
    pub fn nominal(
        job: &crate::io::job::Job,
        rows: Rows,
        names: Names,
        lin: Linearisation,
        fit_settings: FitSettings,
        policy: Policy,
        progress: Progress<'a>,
    ) -> Self {
        let markers: Vec<Vector3<f64>> = names.markers.iter().map(|m| m.1).collect();
        Engine {
            cancel: None,
            geometry: Geometry::nominal_tree(
                &job.robot.chain,
                &job.robot.ends,
                &markers,
                &job.marker_ends(),
            ),
            rows: Arc::new(rows),
            names,
            lin,
            fit_settings,
            policy,
            heldout: false,
            progress,
            last_design: Default::default(),
        }
    }
}

impl Engine<'_> {
    /// The design of `params` at the rows' current linearisation (the
    /// last one built again when nothing changed since).
    ///
    /// # Errors
    /// [`CalibrationError::Core`] when a column cannot be computed.
    pub fn design(&self, params: &[Param]) -> Result<Arc<Design>, CalibrationError> {
        let mut last = self
            .last_design
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let (Some((p, at, d)), Some(now)) = (last.as_ref(), self.rows.at.as_ref()) {
            if p == params && at == now {
                return Ok(Arc::clone(d));
            }
        }
        // Dropped before the next is built: one design in memory, not two;
        // its storage reused when nobody else holds it.
        let old = last
            .take()
            .and_then(|(_, _, d)| Arc::try_unwrap(d).ok())
            .map(Design::into_storage);
        let d = Design::built(
            &self.rows,
            params,
            &self.lin,
            &self.names,
            old,
            self.policy.max_held_design_rows,
        );
        let d = Arc::new(
            d.map_err(|e| CalibrationError::Core("columns", e))?
                .reading(&self.rows),
        );
        if let Some(at) = &self.rows.at {
            *last = Some((params.to_vec(), at.clone(), Arc::clone(&d)));
        }
        Ok(d)
    }

    /// Recomputes the rows at the current geometry.
    ///
    /// # Errors
    /// As [`Rows::relinearise`].
    pub fn relinearise(&mut self) -> Result<(), CalibrationError> {
        rows_mut(&mut self.rows, &mut self.last_design).relinearise(&self.geometry, &self.lin)
    }

    /// The rows, to change: the last design let go first when it reads
    /// them (it is of the rows before the change), so that they are not
    /// copied ([`Arc::make_mut`] copies rows someone else still holds).
    pub fn rows_mut(&mut self) -> &mut Rows {
        rows_mut(&mut self.rows, &mut self.last_design)
    }

    /// [`Engine::relinearise`], with the design of `params` there built in
    /// the same pass ([`Design::relinearised`]: one forward kinematics per
    /// row, not two) and kept for the next [`Engine::design`] of `params`.
    /// (A column that cannot be computed is [`Engine::design`]'s error,
    /// when it is asked for.)
    ///
    /// # Errors
    /// As [`Rows::relinearise`].
    pub fn relinearise_for(&mut self, params: &[Param]) -> Result<(), CalibrationError> {
        let last = self
            .last_design
            .get_mut()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        // (Its storage only: a design that reads the rows lets them go.)
        let old = last
            .take()
            .and_then(|(_, _, d)| Arc::try_unwrap(d).ok())
            .map(Design::into_storage);
        let d = Design::relinearised(
            Arc::make_mut(&mut self.rows),
            &self.geometry,
            &self.lin,
            params,
            &self.names,
            old,
            self.policy.max_held_design_rows,
        )?;
        if let (Ok(d), Some(at)) = (d, &self.rows.at) {
            let d = d.reading(&self.rows);
            *self
                .last_design
                .get_mut()
                .unwrap_or_else(std::sync::PoisonError::into_inner) =
                Some((params.to_vec(), at.clone(), Arc::new(d)));
        }
        Ok(())
    }

    /// Every row's left-hand side \[m\] at the rows' linearisation
    /// ([`Rows::lhs`]): the last design's own when it was built there and
    /// holds them unscaled ([`Rows::scaled`]), else from the frames.
    ///
    /// # Errors
    /// As [`Rows::frames`].
    pub fn lhs(&self) -> Result<Vec<Vector3<f64>>, CalibrationError> {
        let last = self
            .last_design
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let (Some((_, at, d)), Some(now)) = (last.as_ref(), self.rows.at.as_ref()) {
            if at == now && !self.rows.scaled() && d.y.len() == 3 * self.rows.rows.len() {
                return Ok(d.y.as_chunks::<3>().0.iter().map(|&y| y.into()).collect());
            }
        }
        drop(last);
        (self.rows.lhs()).map_err(|e| CalibrationError::Core("forward kinematics", e))
    }

    /// Places the base by a rigid registration of the predicted marker
    /// positions onto the measured ones ([`Geometry::register`]), when
    /// `model` identifies the base and there are absolute rows.
    ///
    /// # Errors
    /// As [`Rows::relinearise`].
    pub fn register_base(&mut self, model: &[Param]) -> Result<(), CalibrationError> {
        let absolute: Vec<_> = self
            .rows
            .rows
            .iter()
            .filter(|r| r.kind == RowKind::Absolute && !r.orientation && r.scalar().is_none())
            .collect();
        // (Plane contacts and distances alone: the base starts at the
        // nominal one, the planes and anchors given near the robot's base
        // frame.)
        if !model.iter().any(|p| matches!(p, Param::Base { .. })) || absolute.len() < 3 {
            return Ok(());
        }
        let predicted = self
            .rows
            .points_m(&absolute)
            .map_err(|e| CalibrationError::Core("forward kinematics", e))?;
        let measured: Vec<Vector3<f64>> = absolute.iter().map(|r| r.measured).collect();
        self.geometry.register(&predicted, &measured);
        self.relinearise_for(model)
    }

    /// Fits `params` by Gauss–Newton ([`crate::calibrate::params::linearisation`]): the
    /// rows at the current model, the fit, the geometric step applied and
    /// the joint law moved to the estimate, until no geometric step exceeds
    /// [`Policy::step_tolerance`] and no parameter acting through a joint
    /// value moves by more than [`Policy::gauss_newton_sigma`] of its σ (at
    /// most [`Policy::max_steps`] relinearisations).
    ///
    /// # Errors
    /// [`CalibrationError::Dependent`] when at some linearisation a
    /// parameter is a combination of the others (the engine stays there);
    /// [`CalibrationError::Core`] from the estimator;
    /// [`CalibrationError::Cancelled`] when [`Engine::cancel`] says so.
    pub fn fit(&mut self, params: &[Param]) -> Result<Fitted, CalibrationError> {
        self.fit_carrying(params, &[]).map(|(f, _)| f)
    }

    /// [`Engine::fit`] of `params` with the columns of `carried` in every
    /// design after theirs, not fitted: at the fitted geometry the design
    /// of `params` then `carried` is [`Engine::design`]'s last one (for a
    /// test of `carried` there without a design more; at 10⁶ rows a
    /// design is a pass of forward kinematics and 300 MB). With OLS, also
    /// the unit-weight sums of all those columns there ([`information`]),
    /// of which the fit's own `Λ` is the leading block, bit for bit.
    ///
    /// # Errors
    /// As [`Engine::fit`] (a carried column takes no part in the
    /// independence test of the fit).
    pub fn fit_carrying(
        &mut self,
        params: &[Param],
        carried: &[Param],
    ) -> Result<(Fitted, Option<Accumulator<f64, nalgebra::Dyn>>), CalibrationError> {
        let geometric = self.rows.kinds.absolute && params.iter().any(Param::is_stepped);
        let iterates = self.lin.iterates(params);
        let mut relinearisations = 0;
        let mut settled = true;
        let cols: Vec<usize> = (0..params.len()).collect();
        let all: Vec<Param> = params.iter().chain(carried).copied().collect();
        let every: Vec<usize> = (0..all.len()).collect();
        // The linearisation whose model fitted the rows best so far (by
        // the cost with the first fit's weights), the first one's cost, and
        // those weights: a fit that does not settle, or settles worse than
        // where it started, ends at the best one, not converged.
        let mut best: Option<Good> = None;
        let mut start_cost: Option<f64> = None;
        let mut reference: Option<Option<Vec<Vector3<f64>>>> = None;
        // The fit is back at the best linearisation and ends there.
        let mut stuck = false;
        let mut masses = MassSteps::default();
        loop {
            if self.cancel.is_some_and(|c| c()) {
                return Err(CalibrationError::Cancelled);
            }
            let d = self.design(&all)?;
            // The one independence test at every linearisation: a step can
            // turn a kept parameter into a combination of the others (the
            // columns move with the geometry); the solver never sees it.
            // With OLS its information `Σ BᵀB` is the fit's own `Λ` (the
            // same sums, bit for bit), and when no σ decides the step the
            // estimate `Λ⁻¹η` alone does: a step that is not the last needs
            // neither the residuals' σ nor the sandwich (two passes over the
            // rows fewer; 10⁶ rows: ~0.3 s each).
            let info = if self.fit_settings.method == Method::Ols && !cols.is_empty() {
                Some(information(&d, &every).map_err(|e| CalibrationError::Core("fit", e))?)
            } else {
                None
            };
            // The fit's own sums, and those of every column when some are
            // carried.
            let (ols, info) = match info {
                Some(acc) if !carried.is_empty() => (Some(leading(&acc, params.len())), Some(acc)),
                other => (other, None),
            };
            let rank = match &ols {
                Some(acc) => d.identifiability_of(&cols, acc),
                None => d.identifiability(&[], &cols),
            };
            if let Some(rank) = rank {
                let left: Vec<usize> = rank.left_out().collect();
                if !left.is_empty() {
                    return Err(CalibrationError::Dependent(left));
                }
            }
            let full_fit = || {
                fit_with_residuals(&d, &cols, None, &self.fit_settings)
                    .map_err(|e| CalibrationError::Core("fit", e))
            };
            let by_sigma = iterates && params.iter().any(Linearisation::tracks);
            let estimate_only = match &ols {
                Some(acc) if !by_sigma => Some(
                    acc.solve_active(&vec![true; cols.len()])
                        .map_err(|e| CalibrationError::Core("fit", e))?,
                ),
                _ => None,
            };
            let mut out = None;
            let x: Vec<f64> = match &estimate_only {
                Some(s) => s.x.as_slice().to_vec(),
                None => {
                    let o = full_fit()?;
                    let x = o.0.x.clone();
                    out = Some(o);
                    x
                }
            };
            // The model at this linearisation (no geometric step, the joint
            // law the rows were evaluated at, every other parameter at this
            // estimate) and its cost with the first fit's weights.
            let cost_here = (geometric || iterates).then(|| {
                let w = reference
                    .get_or_insert_with(|| out.as_ref().map(|o| o.0.weights.clone()))
                    .as_deref();
                cost(&d, &cols, &self.model_here(params, &x), ols.as_ref(), w)
            });
            if let Some(c) = cost_here {
                start_cost.get_or_insert(c);
                if best.as_ref().is_none_or(|b| above(b.cost, c)) {
                    best = Some(Good {
                        geometry: self.geometry.clone(),
                        lin: self.lin.clone(),
                        cost: c,
                    });
                }
            }
            let step = params
                .iter()
                .zip(&x)
                .filter(|(p, _)| p.is_stepped())
                .fold(0.0_f64, |m, (_, v)| m.max(v.abs()));
            let moved = match &out {
                Some((out, _)) if by_sigma => params
                    .iter()
                    .zip(out.x.iter().zip(&out.std))
                    .filter(|(p, _)| Linearisation::tracks(p))
                    .map(|(p, (x, sd))| {
                        (x - self.lin.value(p, &self.names)).abs() / sd.max(f64::MIN_POSITIVE)
                    })
                    .fold(0.0_f64, f64::max),
                _ => 0.0,
            };
            let more = (geometric && step > self.policy.step_tolerance)
                || moved > self.policy.gauss_newton_sigma;
            // Settled, or out of steps: a fit whose model is not its best
            // one (it ran out of steps away from it, or settled worse than
            // where it started: a wrong stationary point) goes back there
            // and ends, not converged.
            let worse = match (cost_here, start_cost, &best) {
                (Some(c), Some(s0), Some(b)) => {
                    let tol = 1.0 + self.policy.max_cost_increase;
                    (!more && above(c, s0 * tol)) || (more && above(c, b.cost * tol))
                }
                _ => false,
            };
            if !stuck && more && relinearisations < self.policy.max_steps {
                // This design's storage is the next one's: nobody else
                // may hold it (a second 300 MB at 10⁶ rows).
                drop(d);
                let x = masses.damped(params, &x, &self.lin, &self.names);
                self.geometry.apply(params, &x);
                let to = Linearisation::of(self.lin.model, params, &x, &self.names);
                self.step_towards(&to, &all)?;
                relinearisations += 1;
                continue;
            }
            if more {
                settled = false;
            }
            if !stuck && worse {
                if let Some(b) = best.take() {
                    drop(d);
                    settled = false;
                    stuck = true;
                    self.geometry = b.geometry;
                    self.lin = b.lin;
                    self.relinearise_for(&all)?;
                    relinearisations += 1;
                    continue;
                }
            }
            let (mut out, kept) = match (out, &ols) {
                (Some(out), _) => out,
                // OLS: the fit's sums are the ones just made.
                (None, Some(acc)) => {
                    fit_with_residuals(&d, &cols, Some(acc.clone()), &self.fit_settings)
                        .map_err(|e| CalibrationError::Core("fit", e))?
                }
                (None, None) => full_fit()?,
            };
            // A fit that did not settle is the model at its last good
            // linearisation, as it is written (no step it did not take):
            // its estimate and residuals there, not the linearised ones of
            // a step that was not applied.
            let residuals = if settled {
                // The residuals of the fit's last σ pass when it made them
                // at its estimate (the same bits as a pass of their own).
                match kept {
                    Some(r) => r
                        .into_iter()
                        .enumerate()
                        .map(|(i, r)| self.rows.unscaled(i, r))
                        .collect(),
                    None => d.residuals(&self.rows, &cols, &out.x),
                }
            } else {
                out.x = self.model_here(params, &out.x);
                d.residuals(&self.rows, &cols, &out.x)
            };
            let fitted = Fitted {
                params: params.to_vec(),
                // Of the points: a pose's orientation is in rad (and a
                // plane contact or a distance one number, apart).
                rms_um: rms_um(&residuals[..self.rows.error_rows()]),
                converged: settled && out.converged,
                fit: out,
                geometry: self.geometry.clone(),
                linearisation: self.lin.clone(),
                relinearisations,
                heldout_rms_um: None,
                residuals,
                information: ols,
            };
            return Ok((fitted, info));
        }
    }

    /// The estimate `x` of `params` as the model at the current
    /// linearisation: no geometric step (the geometry as it is), every
    /// parameter of the joint law at the value the rows were evaluated at
    /// (exact deflection model), every other one at `x`.
    fn model_here(&self, params: &[Param], x: &[f64]) -> Vec<f64> {
        let exact =
            self.lin.model == crate::calibrate::params::linearisation::DeflectionModel::Exact;
        params
            .iter()
            .zip(x)
            .map(|(p, &v)| {
                if p.is_stepped() {
                    0.0
                } else if exact && Linearisation::tracks(p) {
                    self.lin.value(p, &self.names)
                } else {
                    v
                }
            })
            .collect()
    }

    /// After [`Engine::fit_carrying`]: the last design without the carried
    /// columns, as the design of `params` (its leading columns; nothing is
    /// copied), so that what follows the fit finds it.
    pub fn drop_carried(&mut self, params: &[Param]) {
        let mut last = self
            .last_design
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let Some((p, at, d)) = last.take() else {
            return;
        };
        if p.len() <= params.len() || p[..params.len()] != *params {
            *last = Some((p, at, d));
            return;
        }
        if let Ok(mut d) = Arc::try_unwrap(d) {
            d.keep_leading(params.len());
            *last = Some((params.to_vec(), at, Arc::new(d)));
        }
    }

    /// Moves the joint law to `to` and relinearises (with the design of
    /// `params`, [`Engine::relinearise_for`]); where a loaded robot
    /// has no equilibrium there, halves the step (at most
    /// [`Policy::max_halvings`] times) — damped Gauss–Newton.
    ///
    /// # Errors
    /// [`CalibrationError::NoEquilibrium`] when even the smallest step has
    /// none; as [`Rows::relinearise`].
    fn step_towards(
        &mut self,
        to: &Linearisation,
        params: &[Param],
    ) -> Result<(), CalibrationError> {
        let from = self.lin.clone();
        let mut t = 1.0;
        let mut halvings = 0;
        loop {
            self.lin = from.towards(to, t);
            match self.relinearise_for(params) {
                Err(CalibrationError::NoEquilibrium(_)) if halvings < self.policy.max_halvings => {
                    t *= 0.5;
                    halvings += 1;
                }
                other => return other,
            }
        }
    }

    /// Puts the problem back at `f`'s linearisation: its joint law and its
    /// geometry (nothing to do when the rows are there: a relinearisation
    /// at the same law and geometry recomputes the same rows).
    ///
    /// # Errors
    /// As [`Rows::relinearise`].
    pub fn restore(&mut self, f: &Fitted) -> Result<(), CalibrationError> {
        let there = self.rows_at(f);
        self.lin = f.linearisation.clone();
        self.geometry = f.geometry.clone();
        if there {
            return Ok(());
        }
        self.relinearise()
    }

    /// [`Engine::restore`] with the rows' equilibria starting from `start`
    /// ([`Rows::start_points`] taken at `f`'s linearisation): the rows are
    /// then `f`'s, bit for bit, whatever was fitted in between (a
    /// candidate's trial moves the equilibria it starts the next
    /// relinearisation from).
    ///
    /// # Errors
    /// As [`Rows::relinearise`].
    pub fn restore_from(&mut self, f: &Fitted, start: &[Vec<f64>]) -> Result<(), CalibrationError> {
        if !self.rows_at(f) {
            self.rows_mut().start_from(start);
        }
        self.restore(f)
    }

    /// Whether the rows are at `f`'s linearisation (its joint law and
    /// geometry).
    fn rows_at(&self, f: &Fitted) -> bool {
        let at = |(g, l): &(Geometry, Linearisation)| *g == f.geometry && *l == f.linearisation;
        self.rows.at.as_ref().is_some_and(at)
    }

    /// The one independence test of `f`'s parameters at the current
    /// linearisation (`f`'s, [`Design::identifiability`]): from the fit's
    /// own unit-weight sums when it made them (OLS: the same test, no
    /// pass), else from its design. `None` without a column.
    ///
    /// # Errors
    /// As [`Engine::design`].
    pub fn identifiability(
        &self,
        f: &Fitted,
    ) -> Result<Option<crate::estimate::Identifiability<f64, nalgebra::Dyn>>, CalibrationError>
    {
        let all: Vec<usize> = (0..f.params.len()).collect();
        Ok(match &f.information {
            Some(acc) => acc.identifiable().ok(),
            None => self.design(&f.params)?.identifiability(&[], &all),
        })
    }

    /// The identifiability report of `params` at the current linearisation
    /// ([`Design::identifiability`]): each parameter the one independence
    /// test leaves out, with the kept parameters that absorb it.
    ///
    /// # Errors
    /// As [`Engine::design`].
    pub fn left_out(&self, params: &[Param]) -> Result<Vec<LeftOut>, CalibrationError> {
        let d = self.design(params)?;
        let all: Vec<usize> = (0..params.len()).collect();
        let Some(rank) = d.identifiability(&[], &all) else {
            return Ok(Vec::new());
        };
        let unit = |p: &Param| self.names.unit(p).name;
        Ok(rank
            .left_out()
            .map(|i| LeftOut {
                name: self.names.name(&params[i]),
                absorbed_by: rank
                    .absorbed_by(i)
                    .iter()
                    .map(|a| Absorbed {
                        name: self.names.name(&params[a.param]),
                        coefficient: a.coefficient,
                        unit: format!("{}/{}", unit(&params[a.param]), unit(&params[i])),
                    })
                    .collect(),
            })
            .collect())
    }

    /// Of `params`, those the rows determine but the points alone would
    /// leave out: what a pose's orientation adds (issue 53), by the one
    /// independence test ([`crate::estimate::rank`]) on the unit-weight
    /// sums of every row and of the points' rows alone (the orientations'
    /// groups, the last ones, weighed 0). Empty without orientations.
    ///
    /// # Errors
    /// As [`Engine::design`].
    pub fn identified_by_orientations(
        &self,
        params: &[Param],
    ) -> Result<Vec<String>, CalibrationError> {
        let oriented = self.rows.orientation_groups;
        if oriented == 0 || params.is_empty() {
            return Ok(Vec::new());
        }
        let d = self.design(params)?;
        let all: Vec<usize> = (0..params.len()).collect();
        let Some(every) = d.identifiability(&[], &all) else {
            return Ok(Vec::new());
        };
        // The points' groups and the plane contacts' and distances' (the
        // orientations' are the last).
        let points = self.rows.scalar_range().end;
        let weights: Vec<nalgebra::Vector3<f64>> = (0..d.groups)
            .map(|g| nalgebra::Vector3::repeat(if g < points { 1.0 } else { 0.0 }))
            .collect();
        let view = crate::calibrate::design::view::View::new(&d, &all, &[], None);
        let alone = crate::estimate::Reweightable::weighted(&view, &weights, None)
            .ok()
            .and_then(|acc| acc.identifiable().ok());
        Ok(all
            .iter()
            .filter(|&&i| every.kept[i] && alone.as_ref().is_none_or(|a| !a.kept[i]))
            .map(|&i| self.names.name(&params[i]))
            .collect())
    }

    /// The report's parameters of `f`: geometric ones as their values in
    /// the model (the base as its pose in the measurement frame).
    pub fn parameters(&self, f: &Fitted) -> Vec<Parameter> {
        // The base's σ of its pose, not of its last step.
        let std = f
            .geometry
            .reported_std(&f.params, &f.fit.covariance, &f.fit.std);
        f.params
            .iter()
            .zip(f.fit.x.iter().zip(&std))
            .map(|(p, (&x, &std))| {
                let value = if p.is_stepped() {
                    f.geometry.value(p, x)
                } else {
                    x
                };
                // A mass is told from its nominal value, not from zero.
                let moved = match p {
                    Param::LinkMass { .. } => f.geometry.applied(p) + x,
                    _ => value,
                };
                Parameter {
                    name: self.names.name(p),
                    value,
                    std,
                    unit: self.names.unit(p).name.to_string(),
                    determined: matches!(p, Param::Base { .. })
                        || moved.abs() >= self.policy.determined_sigmas * std,
                }
            })
            .collect()
    }

    /// The calibrated model of `f`, for validation and prediction.
    pub fn calibrated(&self, f: &Fitted) -> CalibratedModel {
        CalibratedModel {
            names: self.names.clone(),
            geometry: f.geometry.clone(),
            params: f.params.clone(),
            x: f.fit.x.clone(),
            linearisation: Linearisation::of(
                f.linearisation.model,
                &f.params,
                &f.fit.x,
                &self.names,
            ),
            kinds: self.rows.kinds,
            policy: self.policy,
            covariance: nalgebra::DMatrix::from_iterator(
                f.params.len(),
                f.params.len(),
                f.fit.covariance.iter().copied(),
            ),
            heaviest_payload_kg: self.rows.rows.iter().fold(0.0, |m, r| r.load_kg().max(m)),
            temperature_ref_c: self.rows.temperature_ref_c.as_ref().map(|t| t.1),
        }
    }
}

/// Gauss–Newton's steps damped where a link's mass is among the
/// parameters ([`Param::LinkMass`]): bilinear with the compliances it
/// loads, on a valley as flat as DLR Justin's its full steps overshoot,
/// each undoing most of the last (measured: the sign alternating, each
/// step −0.8 times the one before, 50 relinearisations without settling).
/// When a mass's step turns back by more than a third of the one before,
/// the next steps go half as far along the Gauss–Newton direction (the
/// geometry's and the masses' steps; the joint law's values from where
/// they are), down to 1/32 of it; a step that keeps its sign doubles the
/// fraction again, up to the whole step. Without a mass every step is
/// whole.
#[derive(Debug, Default)]
struct MassSteps {
    /// Each mass's last whole step \[kg\], by its index in the parameters.
    last: Vec<(usize, f64)>,
    /// The fraction of the step taken (the whole at the first).
    scale: f64,
}

impl MassSteps {
    fn damped(
        &mut self,
        params: &[Param],
        x: &[f64],
        lin: &Linearisation,
        names: &crate::calibrate::params::names::Names,
    ) -> Vec<f64> {
        let now: Vec<(usize, f64)> = (params.iter().zip(x).enumerate())
            .filter(|(_, (p, _))| matches!(p, Param::LinkMass { .. }))
            .map(|(i, (_, &v))| (i, v))
            .collect();
        if now.is_empty() {
            return x.to_vec();
        }
        let back = (now.iter().zip(&self.last))
            .any(|(&(_, v), &(_, u))| v * u < 0.0 && v.abs() > u.abs() / 3.0);
        self.scale = if self.last.is_empty() {
            1.0
        } else if back {
            (self.scale * 0.5).max(1.0 / 32.0)
        } else {
            (self.scale * 2.0).min(1.0)
        };
        self.last = now;
        let s = self.scale;
        (params.iter().zip(x))
            .map(|(p, &v)| {
                if p.is_stepped() {
                    v * s
                } else if Linearisation::tracks(p) {
                    let at = lin.value(p, names);
                    at + (v - at) * s
                } else {
                    v
                }
            })
            .collect()
    }
}
