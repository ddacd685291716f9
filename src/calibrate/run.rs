//! A job calibrated: the rows prepared from the measurements (units
//! checked), the declared model fitted, the closed loop run
//! ([`crate::calibrate::diagnosis::run`]), and the report judged.

use nalgebra::Vector3;

use crate::calibrate::diagnosis;
use crate::calibrate::effects::declared;
use crate::calibrate::engine;
use crate::calibrate::fit;
use crate::calibrate::params::linearisation::Linearisation;
use crate::calibrate::params::names::Names;
use crate::calibrate::report::plausibility;
use crate::calibrate::report::Nominal;
use crate::calibrate::report::Report;
use crate::calibrate::robust;
use crate::calibrate::rows::RowKind;
use crate::calibrate::rows::Rows;
use crate::calibrate::settings::Method;
use crate::calibrate::settings::{CalibrationError, Policy, Progress, Settings};
use crate::calibrate::varied;
use crate::estimate::RobustWeight;
use crate::model::Param;

/// Runs the calibration of `job` on `data`: the declared model, then
/// (unless `settings.diagnose` is off) the diagnosis loop
/// ([`diagnosis::run`]). `progress` receives one line per long step.
///
/// # Errors
/// [`CalibrationError`] when the data cannot support the model.
pub fn calibrate(
    job: &crate::io::job::Job,
    data: &crate::io::measurements::Measurements,
    settings: &Settings,
    progress: Progress<'_>,
) -> Result<Report, CalibrationError> {
    let report = if settings.robust {
        robustly(job, data, settings, progress)?
    } else {
        let (rows, names, warnings) =
            prepare(job, std::borrow::Cow::Borrowed(data), &settings.policy)?;
        calibrate_rows(job, &data.file, rows, names, warnings, settings, progress)?
    };
    without_outliers(job, data, settings, report, progress)
}

/// With [`Settings::robust`]: the job fitted with each row weighted by
/// Huber's loss on its standardised residual of the fit before
/// ([`robust::huber`]; the first fit at unit weights), again until no
/// weight moves by more than [`Policy::robust_tolerance`], in
/// [`Policy::robust_iterations`] fits at most. The report is the last
/// fit's; its notes name the rows weighted down most, and a warning says
/// when the weights did not settle.
///
/// # Errors
/// As [`calibrate`], of any of the fits.
fn robustly(
    job: &crate::io::job::Job,
    data: &crate::io::measurements::Measurements,
    settings: &Settings,
    progress: Progress<'_>,
) -> Result<Report, CalibrationError> {
    let policy = &settings.policy;
    let mut used: Option<Vec<f64>> = None;
    let mut fits = 0;
    loop {
        let (mut rows, names, warnings) = prepare(job, std::borrow::Cow::Borrowed(data), policy)?;
        // Plane contacts and distances beside points are reported apart
        // (alone, they are the report's rows).
        let apart = rows.positions() > 0;
        let noise = robust::noise_of(&rows, &names);
        if let Some(w) = &used {
            let scales: Vec<f64> = w.iter().map(|w| w.sqrt()).collect();
            (rows.set_robust(&scales)).map_err(|e| CalibrationError::Core("robust weights", e))?;
        }
        let mut report =
            calibrate_rows(job, &data.file, rows, names, warnings, settings, progress)?;
        fits += 1;
        let res = robust::residuals(
            &report.row_errors,
            report.scalars.as_ref().filter(|_| apart),
            report.orientation.as_ref(),
        );
        let next = robust::huber(&noise, &res, policy.huber_k, policy.robust_group_rows);
        let change = match &used {
            Some(w) => (w.iter().zip(&next)).fold(0.0_f64, |m, (a, b)| m.max((a - b).abs())),
            None => next.iter().fold(0.0_f64, |m, b| m.max(1.0 - b)),
        };
        if change > policy.robust_tolerance && fits < policy.robust_iterations.max(1) {
            progress(&format!(
                "robust loss: fitting again, {} row(s) weighted down",
                next.iter().filter(|&&w| w < 1.0).count()
            ));
            used = Some(next);
            continue;
        }
        let w = used.unwrap_or_else(|| vec![1.0; next.len()]);
        let mut down: Vec<(usize, f64)> = (w.iter().copied().enumerate())
            .filter(|&(_, w)| w < 1.0)
            .collect();
        down.sort_by(|a, b| a.1.total_cmp(&b.1));
        let list: Vec<String> = (down.iter().take(5))
            .filter_map(|&(i, w)| Some((noise.get(i)?, res.get(i)?, w)))
            .map(|(n, r, w)| {
                let unit = if n.kind == robust::NoiseKind::Orientation {
                    "urad"
                } else {
                    "um"
                };
                format!(
                    "config {} marker {} ({}, weight {w:.3}, {:.1} {unit})",
                    n.config,
                    n.marker,
                    n.kind.name(),
                    r.norm()
                )
            })
            .collect();
        report.notes.push(format!(
            "robust loss (Huber, k = {}, --robust): {} fit(s); {} of {} row(s) weighted down{}",
            policy.huber_k,
            fits,
            down.len(),
            w.len(),
            if list.is_empty() {
                String::new()
            } else {
                format!(", most: {}", list.join(", "))
            }
        ));
        if change > policy.robust_tolerance {
            report.warnings.push(format!(
                "robust loss: the rows' weights did not settle in {fits} fits (the last moved \
                 one by {change:.3}); the report is the last fit's"
            ));
        }
        return Ok(report);
    }
}

/// With [`Settings::leave_out_outliers`]: the rows the outlier rule names
/// (`plausibility::outlying`: an absolute row's configuration and marker,
/// every repetition; a deflection's loaded row) left out and the job
/// calibrated again, once; the new report's notes list them with the RMS
/// before. `report` itself otherwise, or when the rule names none.
///
/// # Errors
/// As [`calibrate`], of the second calibration.
fn without_outliers(
    job: &crate::io::job::Job,
    data: &crate::io::measurements::Measurements,
    settings: &Settings,
    report: Report,
    progress: Progress<'_>,
) -> Result<Report, CalibrationError> {
    if !settings.leave_out_outliers {
        return Ok(report);
    }
    let far = plausibility::outlying(&report, &settings.policy);
    if far.is_empty() {
        return Ok(report);
    }
    let named = |deflection: bool| -> std::collections::BTreeSet<(i64, u32)> {
        far.iter()
            .filter(|r| r.deflection == deflection)
            .map(|r| (r.config, r.marker))
            .collect()
    };
    let (absolute, deflected) = (named(false), named(true));
    let kept = data.without(
        |o| o.is_unloaded() && absolute.contains(&(o.config, o.marker)),
        |d| deflected.contains(&(d.config, d.marker)),
    );
    progress(&format!(
        "fitting again without {} outlying row(s)",
        absolute.len() + deflected.len()
    ));
    let once = Settings {
        leave_out_outliers: false,
        ..*settings
    };
    let mut again = calibrate(job, &kept, &once, progress)?;
    let list: Vec<String> = far
        .iter()
        .map(|r| {
            format!(
                "config {} marker {} ({}, {:.1} um)",
                r.config,
                r.marker,
                r.kind_name(),
                r.final_um.norm()
            )
        })
        .collect();
    again.notes.push(format!(
        "left out as measurement errors by the outlier rule, and fitted again \
         (--leave-out-outliers): {} ({} of {} observations kept; RMS {:.1} um with them)",
        list.join(", "),
        kept.observations.len(),
        data.observations.len(),
        report.rms_um
    ));
    Ok(again)
}

/// [`calibrate`], taking the measurements: they are freed as the rows are
/// built from them ([`Rows::from_measurements`]; a million rows parsed
/// are ~350 MB, which were held with the rows' ~224 MB).
///
/// # Errors
/// As [`calibrate`].
pub fn calibrate_owned(
    job: &crate::io::job::Job,
    data: crate::io::measurements::Measurements,
    settings: &Settings,
    progress: Progress<'_>,
) -> Result<Report, CalibrationError> {
    if settings.leave_out_outliers || settings.robust {
        // The file again for the next fit: borrowed, not freed.
        return calibrate(job, &data, settings, progress);
    }
    let file = data.file.clone();
    let (rows, names, warnings) = prepare(job, std::borrow::Cow::Owned(data), &settings.policy)?;
    calibrate_rows(job, &file, rows, names, warnings, settings, progress)
}

/// The rows of `data` (taken: [`Rows::from_measurements`]), the names they
/// use, and the input's warnings. The units are checked first, on the
/// data whole; an error of the rows comes before theirs.
fn prepare(
    job: &crate::io::job::Job,
    data: std::borrow::Cow<'_, crate::io::measurements::Measurements>,
    policy: &Policy,
) -> Result<(Rows, Names, Vec<String>), CalibrationError> {
    let setup = &job.setup;
    let mut names = Names {
        joints: job.robot.joint_names.clone(),
        kinds: job.robot.chain.joints().iter().map(|j| j.kind).collect(),
        markers: setup
            .markers
            .iter()
            .map(|m| (m.id, Vector3::from(m.xyz)))
            .collect(),
        bins: Default::default(),
    };
    let mut warnings: Vec<String> = data.warnings.iter().map(ToString::to_string).collect();
    let units = plausibility::check_units(job, &data, policy);
    let absolute = declared::needs_absolute(job);
    let rows = Rows::build(job, data, absolute, &mut names, policy)?;
    warnings.extend(units?);
    Ok((rows, names, warnings))
}

/// [`calibrate`] from the rows of the measurements in `file`.
fn calibrate_rows(
    job: &crate::io::job::Job,
    file: &std::path::Path,
    rows: Rows,
    names: Names,
    mut warnings: Vec<String>,
    settings: &Settings,
    progress: Progress<'_>,
) -> Result<Report, CalibrationError> {
    let policy = settings.policy;
    let setup = &job.setup;
    let model = declared::declared(job, file, &rows, &names)?;
    // A pivot (every point measured at one place, `Rows::pivot`) tells
    // nothing of the base's turn about it, at any geometry: not fitted,
    // and reported left out. (At the fitted robot its columns are the
    // residuals turned, which a test of significance would take for a
    // signal: 200 KR-270 pivot jobs revived one in 2 % of them, and the
    // base's translation was reported 3 mm off along it.)
    let (model, unfitted): (Vec<Param>, Vec<Param>) = if rows.pivot() {
        (model.into_iter()).partition(|p| !matches!(p, Param::Base { axis } if *axis >= 3))
    } else {
        (model, Vec::new())
    };
    let weight = RobustWeight::new(
        setup.noise.sigma0_um * 1e-6,
        settings.lambda.unwrap_or(setup.noise.lambda),
    )
    .map_err(|e| CalibrationError::Core("noise settings", e))?;
    let weighting = weighting(setup, &rows, file)?;
    let mut e = engine::Engine::nominal(
        job,
        rows,
        names,
        Linearisation::nominal(settings.deflection_model),
        fit::FitSettings {
            method: settings.method,
            weight,
            max_iterations: settings.max_iterations,
            tolerance: policy.irls_tolerance,
            weighting,
        },
        policy,
        progress,
    );
    e.heldout = settings.heldout;
    // (With the model's design in the same pass: the independence test
    // below needs it.)
    e.relinearise_for(&model)?;
    plausibility::check_torques(&model, &e.rows, &e.names, &policy, file)?;

    // The declared model reduced to what the data can identify, at the
    // nominal robot (its dependences are structural, and read in the robot's
    // own axes: a1's offset is the base's turn about z). A Gauss–Newton
    // step that makes another one dependent leaves it out there
    // (`diagnosis::run`).
    let mut left_out = e.left_out(&model)?;
    let dropped: Vec<Param> = model
        .iter()
        .filter(|p| left_out.iter().any(|l| l.name == e.names.name(p)))
        .copied()
        .collect();
    let kept: Vec<usize> = (0..model.len())
        .filter(|&i| !dropped.contains(&model[i]))
        .collect();
    let declared: Vec<Param> = kept.iter().map(|&i| model[i]).collect();
    left_out.extend(unfitted.iter().map(|p| crate::calibrate::report::LeftOut {
        name: e.names.name(p),
        absorbed_by: Vec::new(),
    }));
    // Then the tracker frame (when declared), by a rigid registration; the
    // rows there, every parameter zero, are the nominal error.
    // (With the design of the declared parameters then the left-out ones:
    // the declared fit's first, `diagnosis::run`.)
    let with_dropped: Vec<Param> = declared.iter().chain(&dropped).copied().collect();
    e.register_base(&with_dropped)?;
    // (The rows keep no left-hand side: computed from their frames.)
    let nominal_y = e.lhs()?;
    // Of the points (a pose's orientation: `Report::orientation`).
    let nominal = Nominal::of(&nominal_y[..e.rows.error_rows()]);
    // Each row's, for the report: computed again at the end where the
    // nominal robot needed no equilibrium (`diagnosis::NominalRows`).
    let exact = (e.rows.rows.iter()).any(|r| r.extra.as_ref().is_some_and(|x| x.y.is_some()));
    let at = (e.rows.at.as_ref())
        .filter(|_| !exact)
        .map(|(g, _)| g.clone());
    let nominal_rows = match at {
        Some(at) => {
            drop(nominal_y);
            diagnosis::NominalRows::At(Box::new(at))
        }
        None => diagnosis::NominalRows::Held(nominal_y),
    };
    // A declared compliance the data cannot identify is too few
    // configurations (or markers, or a load that does not load the joint)
    // for the declared model: an error naming the parameters, not a fit that
    // silently leaves them out. (Geometric parameters that another declared
    // one absorbs, e.g. a1's offset and the base yaw, are a property of the
    // model, not of the data: left out and reported.)
    let missing: Vec<String> = dropped
        .iter()
        .filter(|p| p.is_compliance())
        .map(|p| e.names.name(p))
        .collect();
    if !missing.is_empty() {
        let deflections = e
            .rows
            .rows
            .iter()
            .filter(|r| r.kind == RowKind::Deflection)
            .count();
        return Err(CalibrationError::Data(format!(
            "{}: too few configurations for the declared model: {} cannot be identified \
             from {} configuration(s) and {} deflection(s) ({} equations for {} declared \
             parameters); measure more configurations (or markers), or remove them from \
             [model]",
            file.display(),
            missing.join(", "),
            e.rows.configs.len(),
            deflections,
            3 * deflections,
            model.len()
        )));
    }
    if declared.is_empty() {
        return Err(CalibrationError::Data(format!(
            "the declared model has no parameter these data can identify (nominal error \
             before calibration: {nominal}); declare one in [model]"
        )));
    }
    // As many identifiable parameters as equations: the fit reproduces
    // every measurement, and no residual is left to estimate the noise
    // from (eq. 14; the estimator's error was "sigma must be positive").
    let equations = e.rows.equations();
    if equations <= declared.len() {
        return Err(CalibrationError::Data(format!(
            "{}: too few measurements for the declared model: {} row(s) give {equations} \
             equations for {} identifiable parameters, which leaves no residual to estimate \
             the noise from; measure more configurations (or markers), or remove parameters \
             from [model]",
            file.display(),
            e.rows.rows.len(),
            declared.len()
        )));
    }
    let mut settings = *settings;
    let mut notes = Vec::new();
    if let Some(m) = setup.assumed_link_mass_kg {
        // The compliances are per the assumed torques: the reader must know.
        notes.push(format!(
            "assumed mass model (setup assumed_link_mass_kg): every joint whose moving body \
             has no mass in the URDF carries {m} kg at its frame's origin; compliances are \
             per the torques of these masses"
        ));
    }
    // Weights known in advance (the instrument's σ) need no scatter per
    // configuration; estimated ones fall back: `both` to the instrument's σ
    // alone (given σ enter the weights, data contract 7.2), `estimated`
    // to OLS.
    if e.fit_settings.weighting != fit::Weighting::Instrument {
        if let Some(note) = diagnosis::weighting_fallback(&e, settings.method) {
            if e.fit_settings.weighting == fit::Weighting::Both {
                let note = format!(
                    "{note}: weighted by the instrument's sigma alone (sx, sy, sz; sd), one weighted fit"
                );
                (e.progress)(&note);
                notes.push(note);
                e.fit_settings.weighting = fit::Weighting::Instrument;
            } else {
                let note = format!("{note}: fitted by OLS instead");
                (e.progress)(&note);
                notes.push(note);
                settings.method = Method::Ols;
                e.fit_settings.method = Method::Ols;
            }
        }
    }
    // Which declared geometric parameters other poses would identify: a
    // left-out one among them is the data's dependence (`varied`).
    let varied = varied::varied(job, &e, &model)?;
    let mut report = diagnosis::run(
        e,
        declared,
        left_out,
        &model,
        &settings,
        notes,
        nominal_rows,
    )?;
    report.nominal = nominal;
    // The input's, the run's (`diagnosis::run`), the left-out parameters
    // the data, not the model, leave out, then the result's.
    warnings.append(&mut report.warnings);
    if let Some(v) = &varied {
        warnings.extend(
            v.data_dependences(&report.left_out)
                .iter()
                .map(varied::DataDependence::warning),
        );
    }
    warnings.extend(plausibility::check_result(&report, &policy)?);
    report.warnings = warnings;
    report.failure = plausibility::failure(&report, &policy);
    Ok(report)
}

/// Which σ enters the weights ([`crate::io::setup::Weighting`]): the setup's
/// `[noise] weights`, else `both` when every row carries the instrument's
/// σ (`sx, sy, sz`, data contract 7.2) and `estimated` when none does.
///
/// # Errors
/// [`CalibrationError::Data`] when some rows carry it and some do not
/// (only deflections without both points' σ), or when the setup asks for
/// the instrument's σ and the data do not have it.
fn weighting(
    setup: &crate::io::setup::Setup,
    rows: &Rows,
    file: &std::path::Path,
) -> Result<fit::Weighting, CalibrationError> {
    use fit::Weighting;
    let with = rows.rows.iter().filter(|r| r.sigma().is_some()).count();
    let all = with == rows.rows.len();
    if with > 0 && !all {
        return Err(CalibrationError::Data(format!(
            "{}: {with} of {} rows carry the instrument's σ (sx, sy, sz): all or none",
            file.display(),
            rows.rows.len()
        )));
    }
    match setup.noise.weights {
        None if all && with > 0 => Ok(Weighting::Both),
        None => Ok(Weighting::Estimated),
        Some(w @ (Weighting::Instrument | Weighting::Both)) if with == 0 => {
            Err(CalibrationError::Data(format!(
                "{}: [noise] weights = \"{}\" needs the instrument's σ, but the \
                 measurements have no sx, sy, sz columns",
                file.display(),
                w.name()
            )))
        }
        Some(w) => Ok(w),
    }
}
