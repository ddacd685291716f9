//! Ordinary, weighted and iteratively reweighted least squares on
//! [`GroupedStats`] (sections 3–5 of the paper).
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
//!   reached. Every iteration's estimate and standard deviation can be kept
//!   in a caller-provided history (the paper's Figure 3).
//!
//! The fits work on anything that can re-weight its rows per group and
//! axis and report the residual σ of an estimate: [`Reweightable`].
//! [`GroupedStats`] does it from sufficient statistics (firmware); a host
//! program that keeps its rows can do it from them.
//!
//! Units: σ0 must be given in the unit of `Δp` (metres in robcal's rows).

use nalgebra::{RealField, SMatrix, SVector, Vector3};

use crate::accumulator::Accumulator;
use crate::grouped::GroupedStats;
use crate::solve::{std_devs, Active, Solution};
use crate::weights::RobustWeight;
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
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Iteration<T: RealField + Copy, const N: usize> {
    /// The estimate `X̂ₖ`.
    pub x: SVector<T, N>,
    /// Its standard deviations (sandwich, eq. 8 for k = 0, eq. 11 after).
    pub std: SVector<T, N>,
    /// `max_i |X̂ₖ,ᵢ − X̂ₖ₋₁,ᵢ| / σᵢ` (0 for the OLS start).
    pub change: T,
}

/// A fit and its noise model.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Fit<T: RealField + Copy, const N: usize, const G: usize> {
    /// The estimate and `Λ⁻¹`.
    pub solution: Solution<T, N>,
    /// Sandwich covariance (eq. 8 for OLS, eq. 11 for WLS) with σ per group
    /// and axis estimated from this fit's residuals.
    pub covariance: SMatrix<T, N, N>,
    /// Weights the fit used, per group and axis.
    pub weights: heapless::Vec<Vector3<T>, G>,
    /// Residual σ per group and axis of this fit, in the unit of `Δp`.
    pub sigma: heapless::Vec<Vector3<T>, G>,
    /// WLS fits after the OLS start (0 for OLS).
    pub iterations: usize,
    /// Whether the last step moved every parameter by less than the
    /// tolerance (always `false` for OLS and a single WLS step).
    pub converged: bool,
}

impl<T: RealField + Copy, const N: usize, const G: usize> Fit<T, N, G> {
    /// Standard deviations of the estimate.
    #[must_use]
    pub fn std(&self) -> SVector<T, N> {
        std_devs(&self.covariance)
    }
}

/// Data that can be re-weighted per group (configuration) and axis.
pub trait Reweightable<T: RealField + Copy, const N: usize> {
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
    ) -> Result<Accumulator<T, N>, Error>;

    /// σ per group and axis of the residuals of `x`, with the global
    /// degrees-of-freedom correction `m / (m − parameters)`, written to
    /// `out` (one entry per group).
    ///
    /// # Errors
    /// [`Error::Mismatch`] when `out` does not have one entry per group.
    fn residual_sigma_into(
        &self,
        x: &SVector<T, N>,
        parameters: usize,
        out: &mut [Vector3<T>],
    ) -> Result<(), Error>;

    /// Fit with given weights per group and axis; covariance by the
    /// sandwich (eq. 11) with σ from this fit's residuals. `G` bounds the
    /// number of groups.
    ///
    /// # Errors
    /// From [`Reweightable::weighted`] and the solve;
    /// [`Error::CapacityExceeded`] with more than `G` groups.
    fn fit_weighted<const G: usize>(
        &self,
        weights: &[Vector3<T>],
        active: &Active<N>,
    ) -> Result<Fit<T, N, G>, Error> {
        let acc = self.weighted(weights, None)?;
        let solution = acc.solve_active(active)?;
        let mut sigma: heapless::Vec<Vector3<T>, G> = heapless::Vec::new();
        sigma
            .resize(self.group_count(), Vector3::zeros())
            .map_err(|_| Error::CapacityExceeded {
                what: "groups",
                capacity: G,
            })?;
        self.residual_sigma_into(&solution.x, solution.parameters(), &mut sigma)?;
        let middle = self.weighted(weights, Some(&sigma))?.middle();
        let covariance = solution.cov_sandwich(&middle);
        let mut w = heapless::Vec::new();
        for v in weights {
            w.push(*v).map_err(|_| Error::CapacityExceeded {
                what: "groups",
                capacity: G,
            })?;
        }
        Ok(Fit {
            solution,
            covariance,
            weights: w,
            sigma,
            iterations: 0,
            converged: false,
        })
    }

    /// Ordinary least squares (eq. 6) with the sandwich covariance (eq. 8).
    ///
    /// # Errors
    /// As [`Reweightable::fit_weighted`].
    fn fit_ols<const G: usize>(&self, active: &Active<N>) -> Result<Fit<T, N, G>, Error> {
        let mut ones: heapless::Vec<Vector3<T>, G> = heapless::Vec::new();
        ones.resize(self.group_count(), Vector3::repeat(T::one()))
            .map_err(|_| Error::CapacityExceeded {
                what: "groups",
                capacity: G,
            })?;
        self.fit_weighted(&ones, active)
    }

    /// Iteratively reweighted least squares from the OLS start (section 5).
    /// The OLS start and every iteration are pushed to `history` while it
    /// has room (it is cleared first); the fit goes on when it is full.
    ///
    /// # Errors
    /// [`Error::OutOfRange`] for `max_iterations == 0`; errors of the fits.
    fn fit_irls<const G: usize, const H: usize>(
        &self,
        settings: &IrlsSettings<T>,
        active: &Active<N>,
        history: &mut heapless::Vec<Iteration<T, N>, H>,
    ) -> Result<Fit<T, N, G>, Error> {
        if settings.max_iterations == 0 {
            return Err(Error::OutOfRange {
                what: "max_iterations",
                index: 0,
                len: 0,
            });
        }
        history.clear();
        let mut fit: Fit<T, N, G> = self.fit_ols(active)?;
        let _ = history.push(Iteration {
            x: fit.solution.x,
            std: fit.std(),
            change: T::zero(),
        });
        for k in 1..=settings.max_iterations {
            let weights = robust_weights::<T, G>(&fit.sigma, &settings.weight)?;
            let next: Fit<T, N, G> = self.fit_weighted(&weights, active)?;
            let std = next.std();
            let mut change = T::zero();
            for i in 0..N {
                if active[i] && std[i] > T::zero() {
                    change = change.max((next.solution.x[i] - fit.solution.x[i]).abs() / std[i]);
                }
            }
            let _ = history.push(Iteration {
                x: next.solution.x,
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

/// The weights of eq. 14 from a fit's residual σ, per group and axis.
///
/// # Errors
/// [`Error::NonFinite`] / [`Error::NotPositive`] for a bad σ;
/// [`Error::CapacityExceeded`] with more than `G` groups.
pub fn robust_weights<T: RealField + Copy, const G: usize>(
    sigma: &[Vector3<T>],
    weight: &RobustWeight<T>,
) -> Result<heapless::Vec<Vector3<T>, G>, Error> {
    let mut out = heapless::Vec::new();
    for s in sigma {
        let w = Vector3::new(
            weight.weight(s.x)?,
            weight.weight(s.y)?,
            weight.weight(s.z)?,
        );
        out.push(w).map_err(|_| Error::CapacityExceeded {
            what: "groups",
            capacity: G,
        })?;
    }
    Ok(out)
}

impl<T: RealField + Copy, const N: usize, const G: usize> Reweightable<T, N>
    for GroupedStats<T, N, G>
{
    fn group_count(&self) -> usize {
        self.groups().len()
    }

    fn weighted(
        &self,
        weights: &[Vector3<T>],
        sigma: Option<&[Vector3<T>]>,
    ) -> Result<Accumulator<T, N>, Error> {
        GroupedStats::weighted(self, weights, sigma)
    }

    fn residual_sigma_into(
        &self,
        x: &SVector<T, N>,
        parameters: usize,
        out: &mut [Vector3<T>],
    ) -> Result<(), Error> {
        if out.len() != self.groups().len() {
            return Err(Error::Mismatch {
                what: "one sigma per group",
            });
        }
        for (o, s) in out.iter_mut().zip(self.residual_sigma(x, parameters)) {
            *o = s;
        }
        Ok(())
    }
}
