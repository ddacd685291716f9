#![doc = include_str!("../README.md")]
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

// How data flows through the crate (the paper's equation numbers):
//
//   chain          robot geometry, forward kinematics        (URDF)
//     ↓
//   geometric,     identification rows  Bᵢ = [Jᵢ  Aᵢ]         (eq. 2, 3, 4)
//   elastostatic
//     ↓
//   accumulator    Λ = Σ Bᵀ W² B,  η = Σ Bᵀ W² Δp              (eq. 10)
//     ↓
//   solve          X̂ = Λ⁻¹ η and its covariances               (eq. 6–8, 10–13)
//
//   grouped, irls  per-configuration, per-axis statistics and the
//                  iteratively reweighted fit                 (eq. 14, section 5)
//
// Everything above is no_std and allocation-free. With the `std` feature,
// `io` reads the data contract's files (URDF, setup TOML, measurement CSV).

pub mod accumulator;
pub mod chain;
mod error;
#[cfg(feature = "std")]
pub mod io;
pub mod solve;
pub mod weights;

pub use accumulator::{Accumulator, Block};
pub use chain::{Chain, Joint, JointKind, LinkInertia};
pub use error::Error;
pub use solve::Solution;
