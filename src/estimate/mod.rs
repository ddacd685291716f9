//! The estimator (`no_std`, allocation-free): weighted least squares from
//! streamed identification rows `Δp = B X` (eq. 4), sections 3–5 of the
//! paper.
//!
//! ```text
//!   rows B, Δp, w ──update──► Accumulator  Λ = Σ BᵀW²B, η = Σ BᵀW²Δp     (eq. 9, 10)
//!                                  │ solve_active
//!                                  ▼
//!                 Factor (scaled Cholesky) ──► Solution  X̂, Λ⁻¹, RSS    (eq. 6, 10)
//!                                                 covariances            (eq. 7, 8, 11, 13)
//!
//!   rows per configuration ──► GroupedStats ─┐
//!   rows kept elsewhere (the host) ──────────┴─► Reweightable: OLS, WLS, iterative WLS
//!                                                 weights from σ per group and axis (eq. 14)
//!
//!   Λ of model + candidates ──► rank::identifiability   what the data can identify
//!                          ──► nested::nested_test     does a candidate explain the residuals
//!   rows of model + every candidate ──► screen::Augmented (one pass) ──► each candidate's test, the host's rule
//! ```
//!
//! Every type is generic over the scalar `T` (f32 on a microcontroller, f64
//! on the host) and over the number of parameters as a nalgebra dimension
//! `D`: `Const<N>` on the device (fixed size, no allocator), `Dyn` on the
//! host (the exact number of parameters of the model).
//!
//! | module | what |
//! |---|---|
//! | [`block`] | [`Block`]: one measurement, rows of `Δp = B X` with weights (eq. 4, 9) |
//! | [`accumulator`] | [`Accumulator`]: the streaming sufficient statistics (eq. 9, 10) |
//! | [`factor`] | [`Factor`], [`Solution`]: the scaled Cholesky and the covariances (eq. 6–8, 10–13) |
//! | [`grouped`] | [`GroupedStats`]: moments per configuration and axis |
//! | `grouped_fit` | [`GroupedStats`]' own fits: `Λ`, `η` once from the cells, the sandwich's `M` alone |
//! | [`weights`] | [`RobustWeight`]: eq. 12 and 14 |
//! | [`irls`] | [`Reweightable`], [`Fit`]: OLS, WLS, iterative WLS (section 5) |
//! | [`plan`] | [`plan::next_best`]: the candidate pose whose rows raise `ln det Λ` most (the determinant lemma), to choose the next measurement |
//! | [`rank`] | [`identifiability`]: the one column-independence test |
//! | [`nested`] | [`nested_test`]: the F test of a candidate effect from cross-products |
//! | [`screen`] | [`screen::Augmented`]: the in-stream diagnosis, `[B | C]` of every candidate in one pass, the host's rule |
//! | [`decision`] | [`decision::PureError`], [`decision::LackOfFit`], [`decision::Rule`]: the host's decision rule, shared with the device |
//! | [`distributions`] | χ² and F tail probabilities (no std) |
//! | `fmt` | with `defmt`: matrices in defmt logs as plain nested lists |
//! | `wide` | `std` only: `WideAccumulator`, the host's streaming update with run-time SIMD (blocked rank-`k` updates, AVX-512 / AVX2 + FMA / scalar), handing its sums to an [`Accumulator`] |

use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, U3};

/// The storage the estimator needs for `D` parameters: `D × D` matrices,
/// `D`-vectors and `3 × D` blocks. nalgebra's `DefaultAllocator` provides it
/// for every `Const<N>` (on the stack) and, with `std`, for `Dyn` (on the
/// heap); every type of this module is bounded by
/// `DefaultAllocator: Alloc<D>`.
pub trait Alloc<D: Dim>: Allocator<D, D> + Allocator<D> + Allocator<U3, D> {}

impl<D: Dim> Alloc<D> for DefaultAllocator where
    DefaultAllocator: Allocator<D, D> + Allocator<D> + Allocator<U3, D>
{
}

pub mod accumulator;
pub mod block;
pub mod decision;
pub mod distributions;
pub mod factor;
#[cfg(feature = "defmt")]
pub mod fmt;
pub mod grouped;
mod grouped_fit;
pub mod irls;
mod linalg;
pub mod nested;
pub mod plan;
pub mod rank;
pub mod screen;
pub mod weights;
#[cfg(feature = "std")]
pub mod wide;

pub use accumulator::Accumulator;
pub use block::Block;
pub use factor::{pivot_tolerance, std_devs, Factor, Solution};
pub use grouped::{group_dof, group_sigma, leverage, AxisMoments, GroupMoments, GroupedStats};
pub use irls::{
    estimated_weight_factor, pool_small_groups, robust_weights, Fit, IrlsSettings, Iteration,
    Noise, Reweightable, POOL_BELOW_DOF,
};
pub use nested::{nested_test, NestedTest};
pub use rank::{
    identifiability, identifiability_excluding, independence_tolerance, independent, Absorber,
    Identifiability, IdentifiabilitySettings, Pivoting,
};
pub use weights::{inverse_sigma, RobustWeight};
