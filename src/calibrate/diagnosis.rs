//! The closed loop: fit the declared model, test every effect it lacks
//! against the residuals, add the first that passes, refit, repeat; report
//! the errors before and after each step.
//!
//! Its parts: the declared model's first fit and the parameters left out
//! tested again at the fitted robot ([`retest`]), and a candidate's trial
//! from the current model with the columns the data determine ([`trial`]).

pub mod retest;
pub mod trial;

use crate::calibrate::diagnosis::trial::Outcome;
use crate::calibrate::effects::{candidates, Candidate};
use crate::calibrate::engine::{Engine, Fitted};
use crate::calibrate::fit::residuals::{
    lack_of_fit, most_followed, traced_variable, variable_values, LackOfFit,
};
use crate::calibrate::fit::{self, Method};
use crate::calibrate::report::{
    ConfigNoises, EffectStep, LeftOut, NearDependent, PlotSeries, Report, RowErrors, Tested,
    Unexplained,
};
use crate::calibrate::rows::RowKind;
use crate::calibrate::settings::{CalibrationError, Settings};
use crate::error::Error;
use crate::model::Param;
use nalgebra::Vector3;

/// When IRLS/WLS cannot estimate a σ per configuration and axis (a
/// configuration with fewer than [`crate::calibrate::settings::Policy::min_rows_per_group`]
/// rows), the fit falls back (to the instrument's σ alone for `both`, to
/// OLS for `estimated`); the reason, for the report.
pub fn weighting_fallback(e: &Engine<'_>, method: Method) -> Option<String> {
    if method == Method::Ols {
        return None;
    }
    let n = e.rows.per_group();
    let least = e.policy.min_rows_per_group;
    let (g, &fewest) = n.iter().enumerate().min_by_key(|(_, &c)| c)?;
    (fewest < least).then(|| {
        format!(
            "{} needs a scatter per configuration to weight by, and configuration {} has {fewest} row(s) \
             (at least {least})",
            method.name(),
            e.rows.configs[g]
        )
    })
}

/// The kept parameters of `f` that the data determine poorly: variance
/// inflation of their unweighted columns above
/// [`crate::calibrate::settings::Policy::max_variance_inflation`], largest first.
///
/// # Errors
/// As [`Engine::design`].
fn near_dependent(e: &Engine<'_>, f: &Fitted) -> Result<Vec<NearDependent>, CalibrationError> {
    let Some(rank) = e.identifiability(f)? else {
        return Ok(Vec::new());
    };
    let mut out: Vec<NearDependent> = (0..f.params.len())
        .filter_map(|i| {
            let inflation = rank.inflation(i)?;
            (inflation >= e.policy.max_variance_inflation).then(|| NearDependent {
                name: e.names.name(&f.params[i]),
                inflation,
                with: rank
                    .explained_by(i)
                    .iter()
                    .take(3)
                    .map(|a| e.names.name(&f.params[a.param]))
                    .collect(),
            })
        })
        .collect();
    out.sort_by(|a, b| b.inflation.total_cmp(&a.inflation));
    Ok(out)
}

/// The candidates of one round and the tests of those that could be
/// tested: `(index into the candidates, test)`, most significant first.
type Round = (Vec<Candidate>, Vec<(usize, Tested)>);

/// Every candidate `current` lacks, tested against its residuals; most
/// significant first.
fn test_round(e: &mut Engine<'_>, current: &Fitted) -> Result<Round, CalibrationError> {
    let cands = candidates(
        &e.names,
        &current.params,
        e.rows.kinds,
        &e.rows.bins,
        &e.rows.compensator_ok,
    );
    // Every parameter any candidate may test, after the model.
    let mut params = current.params.clone();
    for c in &cands {
        for p in &c.test {
            if !params.contains(p) {
                params.push(*p);
            }
        }
    }
    e.restore(current)?;
    let d = e.design(&params)?;
    let model: Vec<usize> = (0..current.params.len()).collect();
    // Each candidate's test on its own (on worker threads: they share only
    // the design); up to the first error in the candidates' order, as the
    // serial loop.
    let threads = crate::parallel::threads().min(cands.len());
    let names = &e.names;
    // (Every column's unit-weight sums, for the candidates' screening.)
    let every: Vec<usize> = (0..params.len()).collect();
    let sums =
        fit::information(&d, &every).map_err(|err| CalibrationError::Core("columns", err))?;
    let bound = e.policy.max_candidate_inflation;
    let outcomes = crate::parallel::map_until(
        cands.len(),
        threads,
        |ci| {
            let c = &cands[ci];
            let cols: Vec<usize> = c.test.iter().filter_map(|p| d.index(p)).collect();
            let cols = d.independent(&model, &cols);
            let cols = trial::screened(&d, &sums, &model, &cols, bound);
            if cols.is_empty() {
                return Ok(None);
            }
            match fit::test(&d, &model, &cols, &current.fit.weights) {
                Ok(t) => Ok(Some(Tested {
                    effect: c.effect,
                    about: c.about(names),
                    q: t.dof_num,
                    f: t.f,
                    p_value: t.p_value,
                    delta_rss: t.delta_rss,
                })),
                Err(Error::NotIdentifiable { .. } | Error::TooFewEquations { .. }) => Ok(None),
                Err(err) => Err(err),
            }
        },
        Result::is_err,
    );
    let mut tested: Vec<(usize, Tested)> = Vec::new();
    for (ci, outcome) in outcomes.into_iter().enumerate() {
        match outcome {
            Ok(Some(t)) => tested.push((ci, t)),
            Ok(None) => {}
            Err(err) => return Err(CalibrationError::Core("effect test", err)),
        }
    }
    tested.sort_by(|a, b| {
        a.1.p_value
            .total_cmp(&b.1.p_value)
            .then(b.1.f.total_cmp(&a.1.f))
    });
    // Tests equal but for rounding (two candidates whose columns span the
    // same space: `gear_cyclic` and `gravity_compliance` on a horizontal
    // joint whose gravity direction only its own angle turns) keep the
    // rule's order, not the rounding's.
    let close = |a: f64, b: f64| a == b || (a - b).abs() <= 1e-9 * a.abs().max(b.abs());
    let mut i = 0;
    while i < tested.len() {
        let (p, f) = (tested[i].1.p_value, tested[i].1.f);
        let tie = tested[i..]
            .iter()
            .take_while(|t| close(t.1.p_value, p) && close(t.1.f, f))
            .count();
        tested[i..i + tie].sort_by_key(|t| t.0);
        i += tie;
    }
    Ok((cands, tested))
}

/// The nominal robot's error per row \[m\] ([`crate::calibrate::report::RowErrors`]' nominal
/// column, the rows' left-hand sides at the nominal robot): held through
/// the fit, or, when no row needed the exact model's equilibrium there,
/// computed again at its end from the geometry it was at
/// ([`crate::calibrate::rows::Rows::rigid_lhs_at`]: 24 MB not held at 10⁶ rows).
#[derive(Debug, Clone)]
pub enum NominalRows {
    /// Held, one per row.
    Held(Vec<Vector3<f64>>),
    /// At this geometry, without a joint law.
    At(Box<crate::calibrate::params::geometry::Geometry>),
}

/// The calibration on a prepared engine: the declared model, then (unless
/// `settings.diagnose` is off) the diagnosis loop.
///
/// Decisions (constants in [`crate::calibrate::settings::Policy`]):
/// - an effect is added only if it passes the Bonferroni-corrected test
///   (`p · tried < α`) and, when the lack of fit is significant, explains
///   at least `min_share` of the lack-of-fit sum of squares above its noise
///   expectation: an effect that only nibbles at a structure it does not
///   describe is not named;
/// - and only if its estimate is physical ([`crate::calibrate::effects::inadmissible`]) and the
///   leave-one-configuration-out RMS drops with it (when it is computed):
///   a significant effect that predicts unseen configurations worse is
///   fitting this data set, not the robot. The candidates are tried in
///   order of p-value until one passes.
///
/// # Errors
/// [`CalibrationError`] from the fits.
#[allow(clippy::too_many_arguments)]
pub fn run(
    mut e: Engine<'_>,
    declared: Vec<Param>,
    mut left_out: Vec<LeftOut>,
    model: &[Param],
    settings: &Settings,
    mut notes: Vec<String>,
    nominal: NominalRows,
) -> Result<Report, CalibrationError> {
    let alpha = e.policy.alpha;
    (e.progress)("fitting the declared model");
    // What the nominal robot left out (and what the fit leaves out on the
    // way), tested again at the fitted one.
    let mut carried: Vec<Param> = model
        .iter()
        .filter(|p| !declared.contains(p))
        .copied()
        .collect();
    let (first, info) = retest::first_fit(&mut e, declared, &mut left_out, &mut carried)?;
    let mut warnings = Vec::new();
    let first = retest::revive(
        &mut e,
        first,
        info,
        &carried,
        model,
        &mut left_out,
        &mut notes,
        &mut warnings,
    )?;
    let mut current = e.with_heldout(first)?;
    let declared_rms = (current.rms_um, current.heldout_rms_um);
    let declared_structure = lack_of_fit(
        &e.rows,
        &current.fit,
        current.params.len(),
        &current.residuals,
    )
    .map(|l| {
        let (variable, _) =
            most_followed(&e.rows, &e.names, &current.fit.weights, &current.residuals);
        Unexplained {
            variable,
            statistic: l.f,
            p_value: l.p_value,
        }
    });
    let mut steps: Vec<EffectStep> = Vec::new();
    let mut unexplained = None;
    let mut last_round: Vec<Tested> = Vec::new();
    let mut plots: Vec<PlotSeries> = Vec::new();
    let mut rejected: Vec<String> = Vec::new();
    if settings.diagnose {
        loop {
            let lof = lack_of_fit(
                &e.rows,
                &current.fit,
                current.params.len(),
                &current.residuals,
            );
            let (cands, tested) = test_round(&mut e, &current)?;
            last_round = tested.iter().map(|t| t.1.clone()).collect();
            let tried = tested.len().max(1) as f64;
            let lof_significant = lof.is_some_and(|l| l.p_value < alpha);
            let eligible: Vec<&(usize, Tested)> = tested
                .iter()
                .filter(|(_, t)| {
                    let significant = t.p_value * tried < alpha;
                    let share_ok = match lof {
                        Some(l) if lof_significant && l.excess() > 0.0 => {
                            t.delta_rss >= e.policy.min_share * l.excess()
                        }
                        _ => true,
                    };
                    significant && share_ok
                })
                .collect();
            if !eligible.is_empty() && steps.len() >= e.policy.max_effects {
                break;
            }
            // The most significant candidate whose estimate is physical and that
            // lowers the leave-one-configuration-out RMS; one that fails is
            // rejected (a note the first time) and the next is tried. Every
            // trial starts from the current model's rows (`trial`).
            let start = e.rows.start_points();
            let mut accepted = None;
            let mut from = 0;
            while accepted.is_none() && from < eligible.len() {
                let queue: Vec<&Candidate> =
                    eligible[from..].iter().map(|(ci, _)| &cands[*ci]).collect();
                let outcomes = trial::first_admissible(&mut e, &current, &start, &queue)?;
                for outcome in outcomes {
                    let (ci, t) = eligible[from];
                    from += 1;
                    let c = &cands[*ci];
                    let why = match outcome {
                        Outcome::Rejected(why) => Some(why),
                        Outcome::Admissible(next) => {
                            let next = e.with_heldout(*next)?;
                            match (current.heldout_rms_um, next.heldout_rms_um) {
                                (Some(before), Some(after)) if after >= before => {
                                    // Back to the current model (a rejected
                                    // trial left the engine there).
                                    e.restore_from(&current, &start)?;
                                    Some(format!(
                                        "not added: significant (p = {:.1e}) but the \
                                         leave-one-configuration-out RMS does not drop \
                                         ({before:.1} -> {after:.1} um)",
                                        t.p_value
                                    ))
                                }
                                _ => {
                                    accepted = Some((*ci, t.clone(), next));
                                    None
                                }
                            }
                        }
                    };
                    if let Some(why) = why {
                        let on = t
                            .about
                            .as_deref()
                            .map(|a| format!(" on {a}"))
                            .unwrap_or_default();
                        let key = format!("{}{on}", c.effect);
                        if !rejected.contains(&key) {
                            let note = format!("{key} {why} (step {})", steps.len() + 1);
                            (e.progress)(&note);
                            notes.push(note);
                            rejected.push(key);
                        }
                    }
                }
            }
            let Some((ci, t, next)) = accepted else {
                if let Some(l) = lof.filter(|_| lof_significant) {
                    let (variable, _) =
                        most_followed(&e.rows, &e.names, &current.fit.weights, &current.residuals);
                    unexplained = Some(Unexplained {
                        variable,
                        statistic: l.f,
                        p_value: l.p_value,
                    });
                }
                break;
            };
            let c = &cands[ci];
            let on = t
                .about
                .as_deref()
                .map(|a| format!(" on {a}"))
                .unwrap_or_default();
            (e.progress)(&format!("adding {}{on} (p = {:.3e})", c.effect, t.p_value));
            // The next eligible candidate, not tried, when it lowers the
            // sum of squares about as much: the data barely tell the two
            // apart.
            if let Some((ri, r)) = eligible.get(from).map(|x| (x.0, &x.1)) {
                let share = r.delta_rss / t.delta_rss;
                let band = e.policy.runner_up_share..=1.0 / e.policy.runner_up_share;
                if t.delta_rss > 0.0 && band.contains(&share) {
                    let on_r = r
                        .about
                        .as_deref()
                        .map(|a| format!(" on {a}"))
                        .unwrap_or_default();
                    notes.push(format!(
                        "step {}: {}{on} chosen ({} column(s)); {}{on_r} ({} column(s)) lowers \
                         the weighted sum of squares about as much ({:.1} %), less significantly: \
                         these data barely tell the two apart",
                        steps.len() + 1,
                        c.effect,
                        t.q,
                        cands[ri].effect,
                        r.q,
                        100.0 * share
                    ));
                }
            }
            let (variable, x) = traced_variable(&e.rows, &e.names, c);
            plots.push(PlotSeries {
                title: format!(
                    "{}{}",
                    c.effect,
                    t.about
                        .as_deref()
                        .map(|a| format!(" {a}"))
                        .unwrap_or_default()
                ),
                variable,
                x,
                before_um: current.residuals.iter().map(|r| r * 1e6).collect(),
                after_um: next.residuals.iter().map(|r| r * 1e6).collect(),
            });
            steps.push(EffectStep {
                effect: c.effect,
                joint: c.joint.map(|j| e.names.joints[j].clone()),
                marker: c.marker.map(|m| e.names.marker_id(m)),
                p_value: t.p_value,
                f: t.f,
                tried: tested.len(),
                rms_um_before: current.rms_um,
                rms_um_after: next.rms_um,
                heldout_rms_um_before: current.heldout_rms_um,
                heldout_rms_um_after: next.heldout_rms_um,
                parameters_before: e.parameters(&current),
                parameters_after: e.parameters(&next),
            });
            current = next;
        }
    }
    let final_lof: Option<LackOfFit> = lack_of_fit(
        &e.rows,
        &current.fit,
        current.params.len(),
        &current.residuals,
    );
    if let Some(u) = &unexplained {
        plots.push(PlotSeries {
            title: format!("unexplained: {}", u.variable),
            variable: u.variable.clone(),
            x: variable_values(&e.rows, &e.names, &u.variable),
            before_um: current.residuals.iter().map(|r| r * 1e6).collect(),
            after_um: Vec::new(),
        });
    }
    e.restore(&current)?;
    let near_dependent = near_dependent(&e, &current)?;
    // The last design is not needed past here: its memory back before the
    // report's vectors per row and per configuration are built (at 10⁶
    // rows 300 MB of the design against 120 MB of them).
    e.last_design
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .take();
    // The nominal robot's error per row (in the room of the design's
    // left-hand sides just freed, when it is computed again).
    let mut nominal_um = match nominal {
        NominalRows::Held(v) => v,
        NominalRows::At(g) => e
            .rows
            .rigid_lhs_at(&g)
            .map_err(|err| CalibrationError::Core("forward kinematics", err))?,
    };
    // The points' in µm; the plane contacts and distances beside points
    // apart, in m (in data of those alone they are the points'); a pose's
    // orientations (the last rows) apart, in rad.
    let (errors, scalar) = (e.rows.error_rows(), e.rows.scalar_rows());
    let len = nominal_um.len();
    let scalar_nominal = nominal_um[scalar.start.min(len)..scalar.end.min(len)].to_vec();
    let turned_nominal = nominal_um.split_off(scalar.end.max(errors).min(len));
    nominal_um.truncate(errors);
    for y in &mut nominal_um {
        *y *= 1e6;
    }
    let model = e.calibrated(&current);
    let rigid = crate::calibrate::outputs::export::rigid_urdf(&mut e, &current, &model);
    if let Some(r) = rigid.as_ref().filter(|r| r.refit.is_some()) {
        let others: Vec<String> = (current.params.iter())
            .filter(|p| !p.is_geometric() && **p != Param::ThermalExpansion)
            .map(|p| e.names.name(p))
            .collect();
        let listed = match others.len() {
            n if n > 6 => format!("{} and {} more", others[..5].join(", "), n - 5),
            _ => others.join(", "),
        };
        notes.push(format!(
            "robot.urdf holds the geometric parameters refitted as a rigid robot (RMS {:.1} um \
             over the absolute rows), since a URDF cannot hold {}: the model's own geometry \
             alone gives {:.1} um; model.json holds the whole model",
            r.rms_um, listed, r.own_rms_um
        ));
    }
    // Which masses the model identified, and from what (the others keep
    // their mass model's).
    let masses: Vec<String> = (current.params.iter().zip(&current.fit.x))
        .filter(|(p, _)| matches!(p, Param::LinkMass { .. }))
        .map(|(p, &x)| {
            let now = current.geometry.value(p, x);
            let was = now - current.geometry.applied(p) - x;
            format!("{} {now:.3} kg (mass model {was:.3} kg)", e.names.name(p))
        })
        .collect();
    if !masses.is_empty() {
        notes.push(format!(
            "link masses identified: {}; every other moving body keeps its mass model's \
             (the URDF's, or the setup's assumed_link_mass_kg)",
            masses.join(", ")
        ));
    }
    // Thermal expansion's reference: the model's lengths hold there.
    if let (Some((column, mean)), true) = (
        &e.rows.temperature_ref_c,
        current.params.contains(&Param::ThermalExpansion),
    ) {
        notes.push(format!(
            "thermal_expansion is about the data's mean temperature, {mean:.2} degC (column \
             {column}): the identified lengths hold there, and predict, compensate and \
             robot.urdf give the robot at that temperature"
        ));
    }
    let parameters = e.parameters(&current);
    let covariance = current
        .geometry
        .reported_covariance(&current.params, &current.fit.covariance);
    // The report's vectors per configuration and per row: the fit's own,
    // taken over (`report/per_row.rs`).
    // The points' rows and configurations; a pose's orientation (the
    // last rows and groups) in its own statistics, in rad.
    let (points, point_groups) = (errors, e.rows.error_groups());
    let configs: std::sync::Arc<[i64]> = e.rows.configs[..point_groups].into();
    let mut sigma = std::mem::take(&mut current.fit.sigma);
    let mut weights = std::mem::take(&mut current.fit.weights);
    sigma.truncate(point_groups);
    weights.truncate(point_groups);
    let noise = ConfigNoises::new(configs.clone(), sigma, weights);
    let mut residuals = std::mem::take(&mut current.residuals);
    let len = residuals.len();
    let scalars = crate::calibrate::report::ScalarErrors::of(
        &scalar_nominal,
        &residuals[scalar.start.min(len)..scalar.end.min(len)],
    );
    let turned = residuals.split_off(scalar.end.max(points).min(len));
    residuals.truncate(points);
    let mut orientation = crate::calibrate::report::OrientationErrors::of(&turned_nominal, &turned);
    if let Some(o) = &mut orientation {
        o.identified = e.identified_by_orientations(&current.params)?;
    }
    let mut row_errors = RowErrors::new(
        configs,
        e.names.markers.iter().map(|m| m.0).collect(),
        (e.rows.rows[..points].iter())
            .map(|r| (r.group(), r.marker, r.kind == RowKind::Deflection)),
        residuals,
    );
    row_errors.set_nominal_um(nominal_um);
    Ok(Report {
        method: e.fit_settings.method.name(),
        weights: if e.fit_settings.method == Method::Ols {
            "none"
        } else {
            e.fit_settings.weighting.name()
        },
        nominal: Default::default(),
        iterations: current.fit.iterations,
        relinearisations: current.relinearisations,
        converged: current.converged,
        deflection_model: current.linearisation.model.name(),
        parameters,
        covariance,
        history: current.fit.history.clone(),
        noise,
        rms_um: current.rms_um,
        heldout_rms_um: current.heldout_rms_um,
        declared_rms_um: declared_rms.0,
        declared_heldout_rms_um: declared_rms.1,
        declared_structure,
        effects: steps,
        unexplained,
        lack_of_fit: final_lof,
        validation: None,
        last_round,
        left_out,
        near_dependent,
        rows: e.rows.rows.len(),
        equations: e.rows.equations(),
        configurations: point_groups,
        plots,
        row_errors,
        orientation,
        scalars,
        model,
        notes,
        rigid,
        warnings,
        failure: None,
    })
}
