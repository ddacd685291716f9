#![doc = include_str!("../README.md")]
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
// Index loops mirror the matrix formulas of the paper; iterator chains over
// three parallel arrays would hide them.
#![allow(clippy::needless_range_loop)]

// How data flows through the crate (the paper's equation numbers):
//
//   chain,         robot geometry, forward kinematics        (URDF)
//   kinematics
//     ↓
//   geometric,     identification rows  Bᵢ = [Jᵢ  Aᵢ]         (eq. 2, 3, 4)
//   elastostatic,  named by `layout`, which also reports what the data
//   layout         cannot identify
//     ↓
//   accumulator    Λ = Σ Bᵀ W² B,  η = Σ Bᵀ W² Δp              (eq. 10)
//     ↓
//   solve          X̂ = Λ⁻¹ η and its covariances               (eq. 6–8, 10–13)
//
//   grouped, irls  per-configuration, per-axis statistics and the
//                  iteratively reweighted fit                 (eq. 14, section 5)
//
//   diagnose,      does an effect the model lacks explain the residuals?
//   stats          nested F tests from the accumulated cross-products
//
//   kr270          the paper's published numbers (section 5)
//   paper (std)    the paper's experiment end to end: rows, fits, and the
//                  Gauss–Newton refinement on the exact deflection model
//
// Everything above is no_std and allocation-free. With the `std` feature,
// `io` reads the data contract's files (URDF, setup TOML, measurement CSV).

pub mod accumulator;
#[cfg(feature = "std")]
pub mod calibrate;
pub mod chain;
pub mod diagnose;
pub mod elastostatic;
mod error;
pub mod geometric;
pub mod grouped;
#[cfg(feature = "std")]
pub mod io;
pub mod irls;
pub mod kinematics;
pub mod kr270;
pub mod layout;
#[cfg(feature = "std")]
pub mod paper;
pub mod solve;
pub mod stats;
pub mod weights;

pub use accumulator::{Accumulator, Block};
pub use chain::{Chain, Joint, JointKind, LinkInertia};
pub use error::Error;
pub use grouped::GroupedStats;
pub use irls::{Fit, IrlsSettings, Iteration, Reweightable};
pub use solve::Solution;
