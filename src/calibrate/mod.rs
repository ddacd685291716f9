//! The one calibration engine of robcal (`std`): fit the declared model,
//! find the structure left in the residuals, trace it to an effect the
//! model lacks, add it, refit, and report the error before and after each
//! step. `robcal calibrate` is this function; so are the examples and the
//! real-data analyses.
//!
//! ```text
//!   Job + Measurements
//!     │ rows        Rows: deflections and absolute positions, configurations = groups
//!     │ declared    the setup's [model] → parameters (crate::model::Param)
//!     ▼
//!   Engine ─ design   columns of the parameters at every row (B of eq. 4)
//!          ─ fit      OLS | WLS | IRLS through the core's Reweightable   (eq. 6, 10, 14)
//!          ─ geometry Gauss–Newton: apply the geometric step, relinearise
//!          ─ heldout  leave-one-configuration-out prediction RMS
//!     │
//!   diagnosis  lack of fit (residuals) → every candidate of the effect
//!              library (effects) → nested F test (crate::estimate::nested)
//!              → Bonferroni, physical, held-out RMS drops → add, refit, repeat
//!     ▼
//!   Report (report) + CalibratedModel (calibrated) ──validate──► another file
//! ```
//!
//! | module | what |
//! |---|---|
//! | [`names`] | contract names of parameters, joints, markers, angle bins |
//! | [`rows`] | [`Row`]s from the measurements, recomputed at the current geometry |
//! | [`declared`] | the setup's `[model]` as parameters |
//! | [`design`] | the stacked columns of some parameters; the independence test |
//! | [`fit`] | the core's fits and nested test on a design, at the exact size |
//! | [`geometry`] | the current geometry (Gauss–Newton, registration) |
//! | [`engine`] | one model fitted to convergence, and its held-out error |
//! | [`residuals`] | RMS, lack of fit, the variable the residuals follow |
//! | [`effects`] | the effect library and its physical limits |
//! | [`diagnosis`] | the closed loop |
//! | [`report`], [`calibrated`], [`validate`] | what comes out |
//!
//! Every decision constant is a field of [`Policy`], stated once; what the
//! user sets (method, λ, iterations, diagnose) is [`Settings`].
//!
//! Units: rows in metres; every parameter in its reported unit
//! ([`crate::model::param`]); RMS in µm (validation in mm, as the data
//! contract says). RMS is the RMS of the norm of the 3-D position residual
//! of each row, unweighted; held-out RMS is the same over the predictions of
//! each configuration from a fit without it (same method).

pub mod calibrated;
pub mod declared;
pub mod design;
pub mod diagnosis;
pub mod effects;
pub mod engine;
pub mod fit;
pub mod geometry;
pub mod names;
pub mod report;
pub mod residuals;
pub mod rows;
pub mod validate;

use nalgebra::Vector3;

pub use calibrated::CalibratedModel;
pub use effects::{Candidate, Effect};
pub use fit::Method;
pub use geometry::Geometry;
pub use names::Names;
pub use fit::Step;
pub use report::{ConfigNoise, EffectStep, Parameter, PlotSeries, Report, Unexplained, Validation};
pub use rows::{DataKinds, Row, RowKind, Rows};
pub use validate::validate;

use crate::estimate::RobustWeight;
use crate::model::Param;
use crate::Error;

/// What the user sets (the CLI's flags).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// OLS, WLS or IRLS.
    pub method: Method,
    /// λ of eq. 14; `None`: the setup's.
    pub lambda: Option<f64>,
    /// IRLS iterations at most.
    pub max_iterations: usize,
    /// Run the diagnosis loop.
    pub diagnose: bool,
    /// Compute the leave-one-configuration-out RMS, and add an effect only
    /// when it lowers it.
    pub heldout: bool,
    /// The decision constants.
    pub policy: Policy,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            method: Method::Irls,
            lambda: None,
            max_iterations: 100,
            diagnose: true,
            heldout: true,
            policy: Policy::default(),
        }
    }
}

/// Every decision constant of the engine, in one place. The defaults are
/// robcal's; each is documented with its reason.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Policy {
    /// Significance level of the effect tests (Bonferroni over the
    /// candidates tried: `p · tried < α`) and of the lack-of-fit test.
    /// 0.01.
    pub alpha: f64,
    /// Share of the excess lack-of-fit sum of squares an effect must explain
    /// to be named when the lack of fit is significant. 0.1.
    pub min_share: f64,
    /// At most this many effects are added. 8.
    pub max_effects: usize,
    /// Fewest rows per configuration for IRLS/WLS: each configuration's σ
    /// per axis is estimated from its own rows' residuals, so a
    /// configuration with a single row (one marker, no repetition) has no
    /// scatter to weight by; with fewer, the fit falls back to OLS. 2.
    pub min_rows_per_group: usize,
    /// IRLS stops when no parameter moves by more than this many of its σ.
    /// 1e-3.
    pub irls_tolerance: f64,
    /// Gauss–Newton stops when no geometric step exceeds this (reported
    /// units: 1 nm, 1 µrad). 1e-6.
    pub step_tolerance: f64,
    /// Gauss–Newton relinearisations at most. 50.
    pub max_steps: usize,
    /// Refits of a model with linearised effects (`load_com`) about the
    /// new compliances, at most. 5.
    pub linearised_passes: u32,
    /// A joint with more distinct angles than this gets no angle bins (no
    /// compensator candidate, no `compliance_by_angle`). 32.
    pub max_bins: usize,
    /// A compensator candidate needs this many distinct angles of its joint
    /// (from, to). 2 to 8.
    pub compensator_bins: (usize, usize),
    /// … each seen in at least this many configurations. 2.
    pub compensator_min_configs: usize,
    /// Largest admissible first-harmonic gear cyclic error amplitude
    /// \[mrad\]: a gear's transmission error is a fraction of a milliradian
    /// to a few; 10 mrad (0.6°) would be a broken gear.
    pub max_cyclic_mrad: f64,
    /// Largest admissible measurement drift \[mm/h\] (norm over x, y, z): a
    /// thermal drift of a tracker or of the robot's base is a fraction of a
    /// millimetre per hour; 5 mm/h is not a drift but a moving base.
    pub max_drift_mm_per_h: f64,
}

impl Default for Policy {
    fn default() -> Self {
        Self {
            alpha: 0.01,
            min_share: 0.1,
            max_effects: 8,
            min_rows_per_group: 2,
            irls_tolerance: 1e-3,
            step_tolerance: 1e-6,
            max_steps: 50,
            linearised_passes: 5,
            max_bins: 32,
            compensator_bins: (2, 8),
            compensator_min_configs: 2,
            max_cyclic_mrad: 10.0,
            max_drift_mm_per_h: 5.0,
        }
    }
}

impl Policy {
    /// Whether a joint's angle bins, seen in `bin_configs` configurations
    /// each, make a compensator candidate.
    pub fn compensator_eligible(&self, bin_configs: &[usize]) -> bool {
        let (lo, hi) = self.compensator_bins;
        (lo..=hi).contains(&bin_configs.len())
            && bin_configs
                .iter()
                .all(|&n| n >= self.compensator_min_configs)
    }
}

/// Why a calibration failed.
#[derive(Debug, Clone, PartialEq)]
pub enum CalibrationError {
    /// The data cannot support the model (one line for the user).
    Data(String),
    /// A numerical error of the core, with what was being done.
    Core(&'static str, Error),
}

impl core::fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            CalibrationError::Data(s) => write!(f, "{s}"),
            CalibrationError::Core(what, e) => write!(f, "{what}: {e}"),
        }
    }
}

impl std::error::Error for CalibrationError {}

/// Progress messages (stderr in the CLI).
pub type Progress<'a> = &'a mut dyn FnMut(&str);

/// Runs the calibration of `job` on `data`: the declared model, then
/// (unless `settings.diagnose` is off) the diagnosis loop
/// ([`diagnosis::run`]). `progress` receives one line per long step.
///
/// # Errors
/// [`CalibrationError`] when the data cannot support the model.
pub fn calibrate(
    job: &crate::io::Job,
    data: &crate::io::Measurements,
    settings: &Settings,
    progress: Progress<'_>,
) -> Result<Report, CalibrationError> {
    let policy = settings.policy;
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
    let rows = Rows::new(
        job,
        data,
        declared::needs_absolute(job),
        &mut names,
        &policy,
    )?;
    let model = declared::declared(job, &data.file, &rows, &names)?;
    let weight = RobustWeight::new(
        setup.noise.sigma0_um * 1e-6,
        settings.lambda.unwrap_or(setup.noise.lambda),
    )
    .map_err(|e| CalibrationError::Core("noise settings", e))?;
    let markers: Vec<Vector3<f64>> = names.markers.iter().map(|m| m.1).collect();
    let mut e = engine::Engine {
        geometry: Geometry::nominal(&job.robot.chain, &markers),
        rows,
        names,
        compliances: Default::default(),
        fit_settings: fit::FitSettings {
            method: settings.method,
            weight,
            max_iterations: settings.max_iterations,
            tolerance: policy.irls_tolerance,
        },
        policy,
        heldout: settings.heldout,
        progress,
    };
    e.relinearise()?;

    // The declared model reduced to what the data can identify.
    let d = e.design(&model)?;
    let all: Vec<usize> = (0..model.len()).collect();
    let kept = d.independent(&[], &all);
    let dropped: Vec<Param> = all
        .iter()
        .filter(|i| !kept.contains(i))
        .map(|&i| model[i])
        .collect();
    let declared: Vec<Param> = kept.iter().map(|&i| model[i]).collect();
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
            data.file.display(),
            missing.join(", "),
            e.rows.configs.len(),
            deflections,
            3 * deflections,
            model.len()
        )));
    }
    if declared.is_empty() {
        return Err(CalibrationError::Data(
            "the declared model has no parameter these data can identify".into(),
        ));
    }
    let mut settings = *settings;
    let mut notes = Vec::new();
    if let Some(note) = diagnosis::weighting_fallback(&e, settings.method) {
        (e.progress)(&note);
        notes.push(note);
        settings.method = Method::Ols;
        e.fit_settings.method = Method::Ols;
    }
    let dropped = dropped.iter().map(|p| e.names.name(p)).collect();
    diagnosis::run(e, declared, dropped, &settings, notes)
}

#[cfg(test)]
mod tests {
    use super::effects::inadmissible;
    use super::*;
    use crate::robot::JointKind;

    fn names() -> Names {
        Names {
            joints: vec!["a1".into(), "a2".into()],
            kinds: vec![JointKind::Revolute; 2],
            markers: vec![(1, Vector3::zeros())],
            bins: Default::default(),
        }
    }

    #[test]
    fn physical_limits_reject_impossible_estimates() {
        let (n, p) = (names(), Policy::default());
        let k = [Param::Compliance { joint: 1 }];
        assert!(inadmissible(&n, &p, &k, &[0.5], &k).is_none());
        assert!(inadmissible(&n, &p, &k, &[-0.5], &k)
            .unwrap()
            .contains("< 0"));
        let b = [Param::Backlash { joint: 0 }];
        assert!(inadmissible(&n, &p, &b, &[-1.0], &b).is_some());
        assert!(inadmissible(&n, &p, &b, &[1.0], &b).is_none());
        // A negative compliance already in the model is not the candidate's.
        let params = [Param::Compliance { joint: 0 }, Param::Backlash { joint: 1 }];
        assert!(inadmissible(
            &n,
            &p,
            &params,
            &[-1.0, 1.0],
            &[Param::Backlash { joint: 1 }]
        )
        .is_none());
        let cyc = [
            Param::GearCyclic {
                joint: 0,
                cos: false,
            },
            Param::GearCyclic {
                joint: 0,
                cos: true,
            },
        ];
        assert!(inadmissible(&n, &p, &cyc, &[6.0, 8.0], &cyc).is_none()); // 10 mrad
        assert!(inadmissible(&n, &p, &cyc, &[6.0, 8.1], &cyc).is_some());
        let drift: Vec<Param> = (0..3).map(|axis| Param::Drift { axis }).collect();
        // 1 µm/s = 3.6 mm/h.
        assert!(inadmissible(&n, &p, &drift, &[1.0, 0.0, 0.0], &drift).is_none());
        assert!(inadmissible(&n, &p, &drift, &[1.0, 1.0, 0.0], &drift).is_some());
    }
}
