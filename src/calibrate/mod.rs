//! The one calibration engine of robcal (`std`): fit the declared model,
//! find the structure left in the residuals, trace it to an effect the
//! model lacks, add it, refit, and report the error before and after each
//! step. `robcal calibrate` is [`calibrate()`]; so are the examples, the
//! Python package and the real-data analyses.
//!
//! The modules, in the order a calibration flows through them; each
//! imports only from those above it in this table (and from the core,
//! [`crate::io`] and [`crate::parallel`]):
//!
//! ```text
//!   params ─► settings ─► rows ─► effects ─► design ─► fit ─► report ─► engine ─► outputs ─► diagnosis ─► varied ─► plan ─► robust ─► run
//! ```
//!
//! | module | one concept |
//! |---|---|
//! | [`params`] | what a parameter is called, and the model's value the rows are evaluated at: [`Names`], [`Geometry`] (Gauss–Newton's current robot), [`Linearisation`] (the joint law; the exact or first-order deflection model) |
//! | [`settings`] | [`Settings`] (what the user sets), [`Policy`] (every decision constant), [`CalibrationError`] |
//! | [`rows`] | the measurements as [`Row`]s (deflections, absolute positions, a pose's orientation, a plane contact or a distance; configurations as groups), recomputed at the current geometry |
//! | [`effects`] | which parameters: the setup's declared model, and the effect library's candidates with their physical limits |
//! | [`design`] | the columns of some parameters at every row (`B` of eq. 4), held or computed again from the rows, and their sums in the core's order (`view`) |
//! | [`fit`] | the core's OLS, WLS and IRLS on a design (eq. 6, 10, 14), the nested test, the held-out predictions, the residuals' RMS and lack of fit |
//! | [`report`] | what a calibration says: [`Report`] and its parts, the [`CalibratedModel`], and the rules that judge it a calibration (`plausibility`) |
//! | [`engine`] | one model fitted to convergence by Gauss–Newton, keeping its best model, and its held-out error |
//! | [`outputs`] | the calibrated robot handed on: URDF (`export`), `model.json` (`model_file`), prediction and compensation (`predict`), validation on another file |
//! | [`diagnosis`] | the closed loop: the declared model's first fit and re-tests (`retest`), every candidate tested and tried (`trial`), added while the data ask |
//! | [`varied`] | the declared geometric parameters on varied poses within the joint limits: which of those the data leave out are the data's dependence, not the model's |
//! | [`plan`] | choosing the poses before measuring: a pool of candidate configurations and payloads, the declared model's rows at each, the `K` that maximise a criterion of the information (D-optimal by default) |
//! | [`robust`] | a robust loss: each row's Huber weight from its standardised residual, so that outlying rows do not steer the fit |
//! | [`run`] | a job calibrated: rows prepared, the loop run, the report judged |
//!
//! Every decision constant is a field of [`Policy`], stated once; what the
//! user sets (method, λ, iterations, diagnose) is [`Settings`].
//!
//! Units: rows in metres; every parameter in its reported unit
//! ([`crate::model::param`]); RMS in µm (validation in mm, as the data
//! contract says). RMS is the RMS of the norm of the 3-D position residual
//! of each row, unweighted; held-out RMS is the same over the predictions of
//! each configuration from a fit without it (same method; for OLS by the
//! closed form of [`fit::heldout`], linear in the number of configurations;
//! for WLS and IRLS from the moments of [`fit::moments`], built once).

pub mod design;
pub mod diagnosis;
pub mod effects;
pub mod engine;
pub mod fit;
pub mod outputs;
pub mod params;
pub mod plan;
pub mod report;
pub mod robust;
pub mod rows;
pub mod run;
pub mod settings;
pub mod varied;

pub use effects::{Candidate, Effect};
pub use fit::Step;
pub use outputs::export;
pub use outputs::model_file::ModelFile;
pub use outputs::predict::{Payload, Predictor};
pub use outputs::validate::{validate, validate_with};
pub use params::geometry::Geometry;
pub use params::linearisation::{DeflectionModel, Linearisation};
pub use params::names::Names;
pub use report::calibrated::CalibratedModel;
pub use report::{
    weights_line, Absorbed, ConfigNoise, ConfigNoises, EffectStep, LeftOut, NearDependent, Nominal,
    Parameter, PlotSeries, Report, Reregistration, RowError, RowErrors, Unexplained, Validation,
};
pub use rows::{DataKinds, Row, RowKind, Rows};
pub use run::{calibrate, calibrate_owned};
pub use settings::{CalibrationError, Method, Policy, Progress, Settings};
