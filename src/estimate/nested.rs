//! Does an effect the model lacks explain the residuals? Nested F tests
//! computed from the accumulated cross-products alone.
//!
//! The accumulator holds columns for the declared model `A` *and* for the
//! candidate effects. For a candidate with columns `C` (not in `A`), with
//! `X̂_A` the fit of the model alone:
//!
//! - score `g = η_C − Λ_CA X̂_A = B_Cᵀ W² r` (the candidate columns against the
//!   weighted residuals `r`);
//! - `S = Λ_CC − Λ_CA Λ_AA⁻¹ Λ_AC`, the information on `C` left after `A`;
//! - `ΔRSS = gᵀ S⁻¹ g` is exactly how much the weighted residual sum of
//!   squares drops when `C` is added (the Lagrange-multiplier statistic,
//!   before scaling by σ²);
//! - `F = (ΔRSS / q) / ((RSS_A − ΔRSS) / (m − p − q))` with `q = |C|`,
//!   `p = |A|`, `m` equations, and its p-value from `F(q, m − p − q)`.
//!
//! No raw data is needed, so the test also runs in the `no_std` core. When
//! several candidates are tried, compare `p · (number tried)` with the
//! significance level (Bonferroni).

use super::Alloc;
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector, RealField};

use super::accumulator::Accumulator;
use super::distributions;
use super::factor::{pivot_tolerance, Solution};
use super::linalg::{dot, mat_mul, mat_vec};
use crate::error::Error;

/// The outcome of one nested test.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NestedTest {
    /// Drop in the weighted residual sum of squares when the candidate is
    /// added (`gᵀ S⁻¹ g`), in the squared unit of the weighted rows.
    pub delta_rss: f64,
    /// Weighted RSS of the model without the candidate.
    pub rss_before: f64,
    /// The F statistic.
    pub f: f64,
    /// Numerator degrees of freedom `q`.
    pub dof_num: usize,
    /// Denominator degrees of freedom `m − p − q`.
    pub dof_den: usize,
    /// `P(F(q, m − p − q) > f)`.
    pub p_value: f64,
}

/// Tests adding the columns marked in `candidate` to a fitted `model` (one
/// flag per parameter each).
///
/// `fit` must be `acc.solve_active(model)`.
///
/// # Errors
/// - [`Error::Mismatch`] when `candidate` overlaps the model, is empty, a
///   mask has the wrong length, or `fit` was not solved on `model`;
/// - [`Error::TooFewEquations`] when no degrees of freedom are left;
/// - [`Error::NotIdentifiable`] when a candidate column is (numerically) a
///   combination of the model's columns and the candidate's columns before
///   it: the data cannot tell that effect from the model.
#[inline(never)]
pub fn nested_test<T: RealField + Copy, D: Dim>(
    acc: &Accumulator<T, D>,
    model: &[bool],
    fit: &Solution<T, D>,
    candidate: &[bool],
) -> Result<NestedTest, Error>
where
    DefaultAllocator: Alloc<D>,
{
    let n = acc.parameters();
    if model.len() != n || candidate.len() != n || fit.active.as_slice() != model {
        return Err(Error::Mismatch {
            what: "fit was not solved on this model",
        });
    }
    let q = candidate.iter().filter(|c| **c).count();
    if q == 0 || (0..n).any(|i| candidate[i] && model[i]) {
        return Err(Error::Mismatch {
            what: "candidate must be non-empty and outside the model",
        });
    }
    let p = fit.parameters();
    let m = acc.equations();
    if m <= p + q {
        return Err(Error::TooFewEquations {
            equations: m,
            parameters: p + q,
        });
    }
    let dim = acc.dim();
    let lambda = acc.information();
    // Λ_CA Λ_AA⁻¹ Λ_AC: `lambda_inv` is zero outside A.
    let through_model: OMatrix<T, D, D> = mat_mul(&mat_mul(&lambda, &fit.lambda_inv), &lambda);
    let lx: OVector<T, D> = mat_vec(&lambda, &fit.x);
    let mut schur = OMatrix::<T, D, D>::zeros_generic(dim, dim);
    let mut g = OVector::<T, D>::zeros_generic(dim, Const::<1>);
    for j in (0..n).filter(|&j| candidate[j]) {
        g[j] = acc.eta()[j] - lx[j];
        for i in (0..n).filter(|&i| candidate[i]) {
            schur[(i, j)] = lambda[(i, j)] - through_model[(i, j)];
        }
    }
    // A candidate column the model absorbs: what is left of it after the
    // model, `S_jj / Λ_jj = 1 − R²`, is at rounding level. (The solve below
    // scales S by its own diagonal, so it cannot see this.)
    let tol = pivot_tolerance::<T>();
    for j in (0..n).filter(|&j| candidate[j]) {
        // Negated so that a NaN is refused too.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        let absorbed = !(schur[(j, j)] > tol * lambda[(j, j)]);
        if absorbed {
            let left = schur[(j, j)] / lambda[(j, j)];
            return Err(Error::NotIdentifiable {
                column: j,
                rcond: nalgebra::try_convert::<T, f64>(left)
                    .unwrap_or(0.0)
                    .max(0.0),
            });
        }
    }
    // S⁻¹ g on the candidate block; its pivot check tells when candidate
    // columns are combinations of each other (after the model).
    let z = Solution::new(&schur, &g, T::zero(), m, candidate)?;
    Ok(from_delta(dot(&z.x, &g), fit.wrss, q, m - p - q))
}

/// The test from `gᵀ S⁻¹ g` (`delta`), the model's weighted RSS and the
/// degrees of freedom `q`, `m − p − q` (shared with
/// [`super::screen::Augmented::test_fitted`]).
pub(crate) fn from_delta<T: RealField + Copy>(
    delta: T,
    rss_before: T,
    q: usize,
    dof_den: usize,
) -> NestedTest {
    let to_f64 = |v: T| nalgebra::try_convert::<T, f64>(v).unwrap_or(f64::NAN);
    let rss_before = to_f64(rss_before);
    // Not `clamp`: it panics when a bound is NaN (and links the float
    // formatting of its message into a firmware).
    let delta = to_f64(delta).max(0.0).min(rss_before);
    let rss_after = rss_before - delta;
    let f = if delta <= 0.0 {
        0.0
    } else if rss_after > 0.0 {
        (delta / q as f64) / (rss_after / dof_den as f64)
    } else {
        f64::INFINITY
    };
    let p_value = if f.is_finite() {
        distributions::f_sf(f, q, dof_den)
    } else {
        0.0
    };
    NestedTest {
        delta_rss: delta,
        rss_before,
        f,
        dof_num: q,
        dof_den,
        p_value,
    }
}
