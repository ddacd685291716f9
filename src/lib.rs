#![doc = include_str!("../README.md")]
//!
//! # Crate map
//!
//! How a measurement flows through robcal, with the paper's equation
//! numbers (Klimchik et al., *Robust algorithm for calibration of robotic
//! manipulator model*):
//!
//! ```text
//!  URDF, setup, CSV ──io──► Job + Measurements                                 (std)
//!                              │
//!                              ▼
//!  robot    Chain ──frames──► Frames, joint torques of a load / own weight      (no_std)
//!                              │
//!  model    Sample (one measured point at the current model)
//!           Param::column ──► Bᵢ = [Jᵢ Aᵢ] in reported units           (eq. 2, 3, 4)
//!                              │
//!  estimate Accumulator  Λ = Σ BᵀW²B, η = Σ BᵀW²Δp                    (eq. 9, 10)
//!           Factor → Solution  X̂ = Λ⁻¹η, covariances            (eq. 6–8, 11, 13)
//!           Reweightable: OLS, WLS, iterative WLS, weights from σ    (eq. 12, 14)
//!           rank (what is identifiable), nested (F test of a candidate effect)
//!           plan (the next best pose: the determinant lemma)
//!                              │
//!  calibrate  the closed loop: fit the declared model (Gauss–Newton),           (std)
//!             diagnose the residuals, add the effect that explains them,
//!             refit, report before/after; validate on another file;
//!             predict: the calibrated robot applied — a point for joints
//!             and payload, the compensated command (robot::compensate);
//!             plan: the poses to measure, chosen before measuring
//!                              │
//!  render     the JSON, model.json, report.html and its figures               (render)
//!                              │
//!  bin/robcal  `robcal calibrate`, `import`, `predict`, `compensate`,            (cli)
//!              `check`, `compare`, `plan`, `init`
//!  python/     the Python package `robcal` (PyO3): the same calls from numpy    (python)
//! ```
//!
//! | module | what | needs |
//! |---|---|---|
//! | [`robot`] | the serial chain (or a tree, markers on several links), forward kinematics, loads and joint torques, the deflected equilibrium, compensation | — (trees: `tree`, on with `std`) |
//! | [`model`] | [`model::Param`] (every parameter and effect, with units), [`model::Sample`], the columns, the device's [`model::Layout`] | — |
//! | [`estimate`] | the streaming estimator: accumulator, factorisation, grouped statistics, iterative reweighting, identifiability, nested tests, the next best pose | — |
//! | [`Error`] | the core's one error type | — |
//! | `parallel` | independent work on worker threads, the serial loop's answers bit for bit (`ROBCAL_THREADS`) | `std` |
//! | `io` | the data contract's files: URDF, setup TOML, measurement CSV, importers | `std` |
//! | `calibrate` | the one calibration engine, `calibrate::calibrate`: fourteen modules in the order a calibration flows through them (its own map) | `std` |
//! | `render` | what a calibration hands on, written out: the contract's JSON, `model.json` (and read back), `report.html` and its figures, `--output DIR`'s files; the command and the Python package (`python/`) write through it | `render` (on with `cli`) |
//!
//! The `tree` feature (no_std too; `std` turns it on) lets a chain branch:
//! a controller of a serial arm leaves it off and saves ~600 bytes of flash.
//!
//! Everything without a feature is `no_std`, allocation-free and free of
//! `unsafe`; it builds for `thumbv7em-none-eabihf` and `thumbv7m-none-eabi`
//! and runs in `examples/firmware` on a Cortex-M under QEMU. Sizes are
//! nalgebra dimensions: `Const<N>` on a device, `Dyn` on the host.
//! `docs/architecture.md` has the same map, where each equation lives, and
//! where to add an effect or an importer.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
// Index loops mirror the matrix formulas of the paper; iterator chains over
// three parallel arrays would hide them.
#![allow(clippy::needless_range_loop)]

#[cfg(feature = "std")]
pub mod calibrate;
mod error;
pub mod estimate;
#[cfg(feature = "std")]
pub mod io;
pub mod model;
#[cfg(feature = "std")]
pub mod parallel;
#[cfg(feature = "render")]
pub mod render;
pub mod robot;

pub use error::Error;
pub use estimate::{
    Accumulator, Block, Fit, GroupedStats, IrlsSettings, Iteration, Reweightable, Solution,
};
pub use robot::{Chain, Joint, JointKind, LinkInertia};
