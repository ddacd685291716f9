//! What a calibration is told: the user's [`Settings`], the engine's
//! [`Policy`] (every decision constant, stated once), and how it fails.

use crate::calibrate::params::names::Names;
use crate::error::Error;
use crate::model::Param;

/// Estimation method (data contract §4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Iteratively reweighted least squares (eq. 14, section 5).
    Irls,
    /// One reweighting step from OLS (eq. 10, 14).
    Wls,
    /// Ordinary least squares (eq. 6).
    Ols,
}

impl Method {
    /// Its name in the contract.
    pub fn name(self) -> &'static str {
        match self {
            Method::Irls => "irls",
            Method::Wls => "wls",
            Method::Ols => "ols",
        }
    }
}

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
    /// The deflection model of the rows: the exact equilibrium (default)
    /// or the paper's first-order eq. 3.
    pub deflection_model: crate::calibrate::params::linearisation::DeflectionModel,
    /// Leave out the rows the outlier rule names (a measurement error: a
    /// tracker point lost or mistaken) and fit again, once; the report's
    /// notes list them (`calibrate::run`). Off by default: the rule only
    /// warns.
    pub leave_out_outliers: bool,
    /// Fit with a robust loss (Huber, on the standardised residual of each
    /// row, on top of the paper's weights): the job fitted again with each
    /// row weighted by it until the weights settle
    /// ([`crate::calibrate::robust`]). Off by default.
    pub robust: bool,
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
            deflection_model: crate::calibrate::params::linearisation::DeflectionModel::Exact,
            leave_out_outliers: false,
            robust: false,
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
    /// Share of the drop in the residual sum of squares that the nested
    /// tests of re-added parameters predict (at the first fit's
    /// linearisation, [`crate::calibrate::diagnosis::retest`]) that the new fit must realise in
    /// its RMS (`1 − (RMS after / RMS before)²`); else the first fit
    /// stands. 0.5.
    pub min_realised: f64,
    /// A calibrated model is reported as fitting worse than the nominal
    /// robot ([`crate::calibrate::report::plausibility`]) when its root weighted sum of squares
    /// (the fit's weights; unweighted for OLS) exceeds the nominal robot's
    /// by more than this share. 0.01: a fit that only rounds to the nominal
    /// robot (a base-only model, whose registration is already the least
    /// squares one) is not one.
    pub worse_than_nominal: f64,
    /// At most this many effects are added. 8.
    pub max_effects: usize,
    /// When the next eligible candidate of a step (not tried) lowers the
    /// weighted sum of squares by between this share of the chosen one's
    /// drop and its inverse, a note names it: the data barely tell the two
    /// apart (a helper's generator: backlash named where a weak compliance
    /// was, 54.070 against 54.066 µm). 0.95.
    pub runner_up_share: f64,
    /// Fewest rows per configuration for IRLS/WLS: each configuration's σ
    /// per axis is estimated from its own rows' residuals, so a
    /// configuration with a single row (one marker, no repetition) has no
    /// scatter to weight by; with fewer, the fit falls back (`both` to the
    /// instrument's σ alone, `estimated` to OLS). 2.
    pub min_rows_per_group: usize,
    /// IRLS stops when no parameter moves by more than this many of its σ.
    /// 1e-3.
    pub irls_tolerance: f64,
    /// Gauss–Newton stops when no geometric step exceeds this (reported
    /// units: 1 nm, 1 µrad). 1e-6.
    pub step_tolerance: f64,
    /// Gauss–Newton stops when, besides the geometric steps, no parameter
    /// that acts through a joint value (compliances, backlash, …) moves by
    /// more than this many of its σ. 0.01: the bias left is a hundredth of
    /// the uncertainty.
    pub gauss_newton_sigma: f64,
    /// Gauss–Newton relinearisations at most. 50.
    pub max_steps: usize,
    /// Configurations drawn within the joint limits on which the declared
    /// geometric parameters left out on the data are tested again
    /// ([`crate::calibrate::varied`]): one kept there is the data's
    /// dependence, not the model's, and a warning. 0: not tested. 200.
    pub varied_poses: usize,
    /// A validation file whose points fit this many times better after its
    /// measurement frame is re-fitted (the calibrated model held fixed),
    /// the frame moved beyond [`Policy::frame_sigmas`] σ, was most likely
    /// measured with the tracker set up elsewhere: a warning unless the
    /// re-registration was asked for (`--reregister`). 3.
    pub reregistration_gain: f64,
    /// See [`Policy::reregistration_gain`]. 3.
    pub frame_sigmas: f64,
    /// Gauss–Newton takes its steps whole, and keeps the linearisation
    /// whose model fitted the rows best (its cost: the sum of squared
    /// residuals with the weights of the fit's first linearisation). A fit
    /// that runs out of steps ([`Policy::max_steps`]) at a model whose cost
    /// exceeds the best one's by more than this share, or that settles at
    /// one whose cost exceeds its start's by more than it (a wrong
    /// stationary point), goes back to the best model and ends there, not
    /// converged. 0.01 (a weighted fit's weights move between
    /// linearisations).
    pub max_cost_increase: f64,
    /// A design of more rows than this does not hold its columns: each
    /// pass that reads them computes them again from the rows, a block at
    /// a time, bit for bit the same (384 B a row fewer at 16 parameters,
    /// for a pass of forward kinematics per read). 100 000 (a held design
    /// of 16 parameters is then 38 MB at most): at 10⁶ rows a run without
    /// the held design takes 273 MiB where one with it took 630 MiB, in
    /// ~1.2× the time (`BENCHMARKS.md`); below, the time of the passes is
    /// worth more than the memory. `usize::MAX`: always held.
    pub max_held_design_rows: usize,
    /// A kept parameter whose variance inflation `1/(1 − R²)` (its
    /// unweighted column regressed on the other parameters' columns,
    /// [`crate::estimate::Identifiability::inflation`]) reaches this is
    /// reported as poorly determined, with the parameters it trades
    /// against. 1000: its column is 99.9 % explained by the others and its
    /// σ is ≥ 32× what its column alone would give; such a value and its
    /// partners' are determined mostly together (the sum is sharp, each
    /// term is not) and should not be read one by one. A parameter whose
    /// column is more than `1 − 1e-6` explained by the ones kept before it
    /// is left out instead ([`crate::estimate::rank`]).
    pub max_variance_inflation: f64,
    /// A candidate of the closed loop is rejected when its fitted model has
    /// a parameter whose variance inflation reaches this, the candidate's
    /// own or one that a candidate's parameter explains mostly
    /// (`trial::wandering`): 1e5, the column 99.999 % explained by the
    /// others (a declared parameter is left out at 1e6, and flagged from
    /// [`Policy::max_variance_inflation`]). The loop adds what the data
    /// determine, not a direction along which the estimate follows
    /// whatever the model lacks.
    pub max_candidate_inflation: f64,
    /// A declared parameter left out and absorbed by a kept one of the same
    /// unit with a coefficient beyond this (in magnitude) is reported in a
    /// warning: the kept parameters reproduce its effect only to first
    /// order, and a left-out error of δ moves them by the coefficient
    /// times δ, far enough for the second order to show in the residuals.
    /// 10.
    pub max_absorption: f64,
    /// Halvings of a Gauss–Newton step whose joint law leaves a loaded
    /// robot without equilibrium, at most. 10 (a step of 1/1024).
    pub max_halvings: usize,
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
    /// Largest admissible gravity compliance `|x| = (x_a² + x_b²)^½`
    /// \[mrad\] ([`crate::model::Param::GravityCompliance`]): a joint's sag
    /// under the robot's own weight with gravity across it in the worst
    /// direction. Stiff industrial joints sag a fraction of a milliradian to
    /// a few, torque-controlled lightweight arms ~10 to 20 (DLR's Justin:
    /// 10 to 19 mrad on its shoulders and torso); 50 mrad (2.9°, 50 mm at
    /// a metre's reach) would be a joint that does not hold its position,
    /// or an error of another kind that this effect's columns absorb.
    pub max_gravity_deflection_mrad: f64,
    /// Largest admissible measurement drift \[mm/h\] (norm over x, y, z): a
    /// thermal drift of a tracker or of the robot's base is a fraction of a
    /// millimetre per hour; 5 mm/h is not a drift but a moving base.
    pub max_drift_mm_per_h: f64,
    /// Largest admissible `|α|` of the links' thermal expansion
    /// \[µm/(m·K)\] ([`crate::model::Param::ThermalExpansion`]): an arm's
    /// metals expand by 11 (cast iron) to 26 (magnesium) µm/(m·K), steel
    /// 12, aluminium 23; 50 would be a plastic arm, or a temperature that
    /// drives something else (the tracker's air compensation, the floor).
    pub max_thermal_expansion_um_per_m_k: f64,
    /// A declared joint-law parameter needs a row with at least this
    /// torque at its joint \[N·m\]: below it (no load, gravity along the
    /// axis) the column is zero but for rounding. 1e-3.
    pub min_torque_nm: f64,
    /// Measured positions spread more than this many times as far as the
    /// nominal model predicts, or less than its inverse: another length
    /// unit (cm for mm is 10). 2.
    pub max_scale_ratio: f64,
    /// … more than this many times: a warning (markers' xyz far off?). 1.2.
    pub warn_scale_ratio: f64,
    /// A joint column whose values, read in the other angle unit, let the
    /// nominal model register onto the measured points this many times
    /// better is in the other unit. 3.
    pub unit_fit_ratio: f64,
    /// The scale and unit checks read at most this many unloaded points,
    /// evenly spaced in file order (every `⌈n / this⌉`-th): they are ratios
    /// of spreads and RMS, settled long before a million points, and each
    /// angle column's check is a forward kinematics of every point read.
    /// 4096.
    pub unit_check_points: usize,
    /// The nominal model moves the markers over less than this \[m\] (RMS
    /// about their centroid) across the configurations: the data excite
    /// the geometry only by its errors, so parameters that are left out at
    /// the nominal robot may matter at the true one; a warning (and no
    /// scale or unit check). Also the bound on the points' spread off
    /// their best line and off their best plane (their second and third
    /// principal spreads): less, a warning of its own. 0.01.
    pub min_spread_m: f64,
    /// A compliance or backlash below zero by more than this many σ is an
    /// error; within it, a warning (consistent with zero). 3.
    pub negative_sigmas: f64,
    /// A final estimate within this many σ of zero is not determined by
    /// the data ([`crate::calibrate::report::plausibility`]): a warning for a declared term of
    /// the joint law that follows the torque (it would be applied, as
    /// estimated, under any load), and for an effect the loop added whose
    /// every parameter ended there. 2.
    pub determined_sigmas: f64,
    /// A row whose final residual (its norm) exceeds this many times the
    /// median row's of its kind (absolute positions, deflections) is
    /// reported as a likely measurement error ([`crate::calibrate::report::plausibility`]).
    /// 20: for Gaussian noise the median norm is 1.54 σ (3 axes), so the
    /// bound is 31 σ, and still 6 σ for a configuration five times
    /// noisier than the median one (the paper's premise: the noise varies
    /// over the workspace); the largest ratio on the bundled and real data
    /// sets is in `docs/numerics.md`.
    pub outlier_ratio: f64,
    /// … and this \[µm\]: no residual below it is called an outlier
    /// (noise-free synthetic data has a median of rounding). 1.
    pub outlier_floor_um: f64,
    /// … among at least this many rows of the kind (a median of fewer
    /// says little about the noise). 10.
    pub outlier_min_rows: usize,
    /// The robust loss's threshold ([`crate::calibrate::robust`], `--robust`):
    /// a row whose standardised residual (per axis over the instrument's σ
    /// of the row at the rows' level, the σ of the other rows of its configuration, or the
    /// rows' own robust scale, `1.4826 · MAD`) has a norm `d` beyond this
    /// is weighted `k/d` (Huber). 3.37: the 99 %
    /// point of a norm of three unit normal components (√χ²₃), so that a
    /// clean row is down-weighted in 1 % of cases, and then barely.
    pub huber_k: f64,
    /// A row's residual is standardised for the robust loss by the σ of
    /// the other rows of its configuration and kind when there are at
    /// least this many of them (else by the rows' robust scale). 4: each
    /// axis's σ then has 4 degrees of freedom at least.
    pub robust_group_rows: usize,
    /// The held-out error of a fit whose weights are re-estimated (IRLS,
    /// eq. 14) refits each fold, weights and all, from the moments
    /// (`O(G² N²)` per reweighting) up to this many configurations; above,
    /// each fold is a downdate of the whole fit's weighted sums, its
    /// weights held (`O(G N³)`; `crate::calibrate::fit::moments::FixedFolds`).
    /// A configuration left out moves the others' σ only through the
    /// estimate, by `O(1/G)`: held, the held-out RMS moved by 0.8 % on
    /// TIAGo's 37 configurations (and `setup-select.toml`'s loop took
    /// another last effect), by 7e-6 on 400 UR10 configurations measured
    /// twice (`host-tests/tests/heldout_held_weights.rs`). 200: every
    /// bundled and real job keeps its exact folds.
    pub heldout_refit_groups: usize,
    /// Fits at most for the robust loss's weights to settle. 20.
    pub robust_iterations: usize,
    /// The robust loss's weights have settled when none moves by more than
    /// this between two fits. 0.01.
    pub robust_tolerance: f64,
}

impl Default for Policy {
    fn default() -> Self {
        Self {
            alpha: 0.01,
            min_share: 0.1,
            min_realised: 0.5,
            worse_than_nominal: 0.01,
            max_effects: 8,
            runner_up_share: 0.95,
            min_rows_per_group: 2,
            irls_tolerance: 1e-3,
            step_tolerance: 1e-6,
            varied_poses: 200,
            reregistration_gain: 3.0,
            frame_sigmas: 3.0,
            gauss_newton_sigma: 0.01,
            max_variance_inflation: 1000.0,
            max_candidate_inflation: 1e5,
            max_absorption: 10.0,
            max_steps: 50,
            max_cost_increase: 0.01,
            max_held_design_rows: 100_000,
            max_halvings: 10,
            max_bins: 32,
            compensator_bins: crate::model::bins::COMPENSATOR_BINS,
            compensator_min_configs: crate::model::bins::COMPENSATOR_MIN_CONFIGS,
            max_cyclic_mrad: 10.0,
            max_gravity_deflection_mrad: 50.0,
            max_drift_mm_per_h: 5.0,
            max_thermal_expansion_um_per_m_k: 50.0,
            min_torque_nm: 1e-3,
            max_scale_ratio: 2.0,
            warn_scale_ratio: 1.2,
            unit_fit_ratio: 3.0,
            unit_check_points: 4096,
            min_spread_m: 0.01,
            negative_sigmas: 3.0,
            determined_sigmas: 2.0,
            outlier_ratio: 20.0,
            outlier_floor_um: 1.0,
            outlier_min_rows: 10,
            huber_k: 3.37,
            robust_group_rows: 4,
            heldout_refit_groups: 200,
            robust_iterations: 20,
            robust_tolerance: 0.01,
        }
    }
}

impl Policy {
    /// Whether a joint's angle bins, seen in `bin_configs` configurations
    /// each, make a compensator candidate.
    pub fn compensator_eligible(&self, bin_configs: &[usize]) -> bool {
        crate::model::bins::compensator_eligible(
            bin_configs,
            self.compensator_bins,
            self.compensator_min_configs,
        )
    }
}

/// Why a calibration failed.
#[derive(Debug, Clone, PartialEq)]
pub enum CalibrationError {
    /// The data cannot support the model (one line for the user).
    Data(String),
    /// A numerical error of the core, with what was being done.
    Core(&'static str, Error),
    /// With the current joint law a loaded robot has no (stable)
    /// equilibrium near a measured pose (one line naming the row).
    NoEquilibrium(String),
    /// At the linearisation a Gauss–Newton step reached, these parameters
    /// (indices into the fitted list) are combinations of the others by the
    /// one independence test ([`crate::estimate::rank`]): the caller leaves
    /// them out (a declared parameter) or rejects the model (a candidate).
    /// The engine is left at that linearisation.
    Dependent(Vec<usize>),
    /// A candidate's trial abandoned because an earlier candidate of the
    /// same step was admissible ([`crate::calibrate::diagnosis::trial`]): never the run's error.
    Cancelled,
}

impl CalibrationError {
    /// An error of the estimator in the declared model's fit of `params`:
    /// a parameter the solver finds not identifiable, named (the
    /// independence test passed it on the unweighted columns; at the
    /// weights of the fit it is a combination of the others, e.g. when
    /// configurations of very different scatter weigh very differently),
    /// else the core's error.
    pub fn of_fit(e: Error, params: &[Param], names: &Names) -> Self {
        match e {
            Error::NotIdentifiable { column, rcond } if column < params.len() => {
                CalibrationError::Data(format!(
                    "fit: {} cannot be told apart from the other parameters at the weights of \
                     the fit (reciprocal condition {rcond:.1e}); check the data for outliers, \
                     or declare fewer parameters",
                    names.name(&params[column])
                ))
            }
            e => CalibrationError::Core("fit", e),
        }
    }
}

impl core::fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            CalibrationError::Data(s) | CalibrationError::NoEquilibrium(s) => write!(f, "{s}"),
            CalibrationError::Core(what, e) => write!(f, "{what}: {e}"),
            CalibrationError::Dependent(i) => {
                write!(f, "parameters {i:?} are combinations of the others")
            }
            CalibrationError::Cancelled => write!(f, "trial abandoned"),
        }
    }
}

impl std::error::Error for CalibrationError {}

/// Progress messages (stderr in the CLI).
pub type Progress<'a> = &'a mut dyn FnMut(&str);
