//! Ordinary, weighted and iteratively reweighted least squares (sections
//! 3–5 of the paper) on anything [`Reweightable`].
//!
//! - **OLS** (eq. 6): all weights 1. Its covariance is the sandwich (eq. 8)
//!   with σ per group and axis estimated from the OLS residuals.
//! - **WLS** (eq. 10): weights `w_ga = σ0 / (σ0 + λ σ_ga)` (eq. 14) from the
//!   residual σ of a previous fit; covariance by the sandwich (eq. 11) with
//!   σ re-estimated from the WLS residuals. With one step from OLS this is
//!   the paper's Table 3 "WLS" column.
//! - **Iterative WLS** (section 5, Fig. 3): repeat — σ from the last fit's
//!   residuals, new weights, new fit — until no parameter moves by more than
//!   `tolerance` of its own standard deviation, or `max_iterations` is
//!   reached. Every iteration's estimate and standard deviation goes to a
//!   caller's callback (the paper's Figure 3).
//!
//! The fits work on anything that can re-weight its rows per group and
//! axis and report the residual σ of an estimate: [`Reweightable`].
//! [`super::GroupedStats`] does it from sufficient statistics (firmware); a
//! host program that keeps its rows can do it from them. The weights and σ
//! per group and axis live in the caller's memory (two slices of one
//! `Vector3` per group), so nothing here allocates.
//!
//! Units: σ0 must be given in the unit of `Δp` (metres in robcal's rows).

use super::Alloc;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, RealField, Vector3};

use super::accumulator::Accumulator;
use super::factor::{std_devs, Solution};
use super::grouped::GroupedStats;
use super::weights::RobustWeight;
use crate::Error;

/// Settings of the iteration.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IrlsSettings<T> {
    /// σ0 and λ of eq. 14, σ0 in the unit of `Δp`.
    pub weight: RobustWeight<T>,
    /// Stop when `max_i |X̂ₖ,ᵢ − X̂ₖ₋₁,ᵢ| / σᵢ < tolerance`.
    pub tolerance: T,
    /// At most this many WLS fits after the OLS start (≥ 1).
    pub max_iterations: usize,
}

impl<T: RealField + Copy> IrlsSettings<T> {
    /// Settings with the paper's weights (eq. 14), a tolerance of 1e-3 σ
    /// and at most 100 iterations.
    pub fn new(weight: RobustWeight<T>) -> Self {
        Self {
            weight,
            tolerance: nalgebra::convert(1e-3),
            max_iterations: 100,
        }
    }
}

/// One iteration's estimate (for the convergence plot, Fig. 3).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Iteration<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    /// The estimate `X̂ₖ`.
    pub x: OVector<T, D>,
    /// Its standard deviations (sandwich, eq. 8 for k = 0, eq. 11 after).
    pub std: OVector<T, D>,
    /// `max_i |X̂ₖ,ᵢ − X̂ₖ₋₁,ᵢ| / σᵢ` (0 for the OLS start).
    pub change: T,
}

impl<T: RealField + Copy, D: Dim> Copy for Iteration<T, D>
where
    DefaultAllocator: Alloc<D>,
    OVector<T, D>: Copy,
{
}

/// A fit and its covariance. The weights it used and the residual σ per
/// group and axis are in the slices the caller passed.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Fit<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    /// The estimate and `Λ⁻¹`.
    pub solution: Solution<T, D>,
    /// Sandwich covariance (eq. 8 for OLS, eq. 11 for WLS) with σ per group
    /// and axis estimated from this fit's residuals.
    pub covariance: OMatrix<T, D, D>,
    /// WLS fits after the OLS start (0 for OLS).
    pub iterations: usize,
    /// Whether the last step moved every parameter by less than the
    /// tolerance (always `false` for OLS and a single WLS step).
    pub converged: bool,
}

impl<T: RealField + Copy, D: Dim> Fit<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    /// Standard deviations of the estimate.
    #[must_use]
    pub fn std(&self) -> OVector<T, D> {
        std_devs(&self.covariance)
    }
}

/// Data that can be re-weighted per group (configuration) and axis.
pub trait Reweightable<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    /// Number of groups.
    fn group_count(&self) -> usize;

    /// The statistics with weight `weights[g][a]` on every row of group `g`,
    /// axis `a`; with `sigma`, the sandwich middle term `M = Σ w⁴σ² bbᵀ` too.
    ///
    /// # Errors
    /// [`Error::Mismatch`] without one entry per group; bad weights.
    fn weighted(
        &self,
        weights: &[Vector3<T>],
        sigma: Option<&[Vector3<T>]>,
    ) -> Result<Accumulator<T, D>, Error>;

    /// σ per group and axis of the residuals of `x`, with the global
    /// degrees-of-freedom correction `m / (m − parameters)`, written to
    /// `out` (one entry per group).
    ///
    /// # Errors
    /// [`Error::Mismatch`] when `out` does not have one entry per group.
    fn residual_sigma_into(
        &self,
        x: &OVector<T, D>,
        parameters: usize,
        out: &mut [Vector3<T>],
    ) -> Result<(), Error>;

    /// Fit with the given weights per group and axis; covariance by the
    /// sandwich (eq. 11) with σ from this fit's residuals, which are
    /// written to `sigma` (one entry per group).
    ///
    /// # Errors
    /// From [`Reweightable::weighted`] and the solve.
    fn fit_weighted(
        &self,
        weights: &[Vector3<T>],
        active: &[bool],
        sigma: &mut [Vector3<T>],
    ) -> Result<Fit<T, D>, Error> {
        let acc = self.weighted(weights, None)?;
        let solution = acc.solve_active(active)?;
        self.residual_sigma_into(&solution.x, solution.parameters(), sigma)?;
        let middle = self.weighted(weights, Some(sigma))?.middle();
        let covariance = solution.cov_sandwich(&middle);
        Ok(Fit {
            solution,
            covariance,
            iterations: 0,
            converged: false,
        })
    }

    /// Ordinary least squares (eq. 6) with the sandwich covariance (eq. 8).
    /// `weights` is set to one and `sigma` to the residual σ.
    ///
    /// # Errors
    /// As [`Reweightable::fit_weighted`].
    fn fit_ols(
        &self,
        active: &[bool],
        weights: &mut [Vector3<T>],
        sigma: &mut [Vector3<T>],
    ) -> Result<Fit<T, D>, Error> {
        weights.fill(Vector3::repeat(T::one()));
        self.fit_weighted(weights, active, sigma)
    }

    /// Iteratively reweighted least squares from the OLS start (section 5).
    /// On return `weights` and `sigma` hold the final fit's weights and
    /// residual σ. The OLS start and every iteration are passed to
    /// `history`.
    ///
    /// # Errors
    /// [`Error::OutOfRange`] for `max_iterations == 0`; errors of the fits.
    fn fit_irls(
        &self,
        settings: &IrlsSettings<T>,
        active: &[bool],
        weights: &mut [Vector3<T>],
        sigma: &mut [Vector3<T>],
        mut history: impl FnMut(&Iteration<T, D>),
    ) -> Result<Fit<T, D>, Error> {
        if settings.max_iterations == 0 {
            return Err(Error::OutOfRange {
                what: "max_iterations",
                index: 0,
                len: 0,
            });
        }
        let mut fit = self.fit_ols(active, weights, sigma)?;
        history(&Iteration {
            x: fit.solution.x.clone(),
            std: fit.std(),
            change: T::zero(),
        });
        for k in 1..=settings.max_iterations {
            robust_weights(sigma, &settings.weight, weights)?;
            let next = self.fit_weighted(weights, active, sigma)?;
            let std = next.std();
            let mut change = T::zero();
            for i in 0..active.len() {
                if active[i] && std[i] > T::zero() {
                    change = change.max((next.solution.x[i] - fit.solution.x[i]).abs() / std[i]);
                }
            }
            history(&Iteration {
                x: next.solution.x.clone(),
                std,
                change,
            });
            fit = next;
            fit.iterations = k;
            if change < settings.tolerance {
                fit.converged = true;
                break;
            }
        }
        Ok(fit)
    }
}

/// The weights of eq. 14 from a fit's residual σ, per group and axis,
/// written to `out`.
///
/// # Errors
/// [`Error::Mismatch`] when `out` and `sigma` differ in length;
/// [`Error::NonFinite`] / [`Error::NotPositive`] for a bad σ. `out` is
/// unchanged on error.
pub fn robust_weights<T: RealField + Copy>(
    sigma: &[Vector3<T>],
    weight: &RobustWeight<T>,
    out: &mut [Vector3<T>],
) -> Result<(), Error> {
    if out.len() != sigma.len() {
        return Err(Error::Mismatch {
            what: "one weight per group",
        });
    }
    for s in sigma {
        for a in 0..3 {
            weight.weight(s[a])?;
        }
    }
    for (o, s) in out.iter_mut().zip(sigma) {
        *o = s.map(|v| weight.weight(v).unwrap_or(T::zero()));
    }
    Ok(())
}

impl<T: RealField + Copy, D: Dim, const G: usize> Reweightable<T, D> for GroupedStats<T, D, G>
where
    DefaultAllocator: Alloc<D>,
{
    fn group_count(&self) -> usize {
        self.groups().len()
    }

    fn weighted(
        &self,
        weights: &[Vector3<T>],
        sigma: Option<&[Vector3<T>]>,
    ) -> Result<Accumulator<T, D>, Error> {
        GroupedStats::weighted(self, weights, sigma)
    }

    fn residual_sigma_into(
        &self,
        x: &OVector<T, D>,
        parameters: usize,
        out: &mut [Vector3<T>],
    ) -> Result<(), Error> {
        GroupedStats::residual_sigma_into(self, x, parameters, out)
    }
}
