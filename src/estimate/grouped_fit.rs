//! Fits from [`GroupedStats`]: its [`Reweightable`] implementation.
//!
//! The generic [`fit_with`](super::irls) builds `Λ` and `η` in an
//! [`Accumulator`](super::accumulator::Accumulator) and, for the sandwich
//! (eq. 8, 11), builds them again beside the middle term `M`. From grouped
//! moments that is wasted work: here `Λ = Σ w² S` and `η = Σ w² u` are built
//! once from the cells' upper triangles (every `S` has a zero lower
//! triangle), and the second pass computes `M = Σ w⁴ σ² S` alone. The
//! checks, the errors and every sum (groups and axes in the same order,
//! element by element) are those of the generic path, so the result is the
//! same bit for bit (`host-tests/tests/grouped_fit.rs`).

use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector, RealField, Vector3};

use super::accumulator::{symmetric, Accumulator};
use super::factor::Solution;
use super::grouped::GroupedStats;
use super::irls::{pool_small_groups, robust_weights, Fit, Noise, Reweightable};
use super::weights::RobustWeight;
use super::Alloc;
use crate::Error;

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
        noise: Option<Noise<'_, T>>,
    ) -> Result<Accumulator<T, D>, Error> {
        GroupedStats::weighted_noise(self, weights, noise)
    }

    fn residual_sigma_into(
        &self,
        fit: &Solution<T, D>,
        weights: &[Vector3<T>],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
    ) -> Result<(), Error> {
        GroupedStats::residual_sigma_into(self, fit, weights, sigma, dof)
    }

    fn fit_weighted(
        &self,
        weights: &[Vector3<T>],
        active: &[bool],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
    ) -> Result<Fit<T, D>, Error> {
        fit_grouped(self, weights, active, sigma, dof, false)
    }

    fn fit_reweighted(
        &self,
        weight: &RobustWeight<T>,
        active: &[bool],
        weights: &mut [Vector3<T>],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
    ) -> Result<Fit<T, D>, Error> {
        robust_weights(sigma, weight, weights)?;
        fit_grouped(self, weights, active, sigma, dof, true)
    }
}

/// [`fit_with`] on grouped statistics, the same result bit for bit and the
/// same errors, in fewer passes: `Λ` and `η` once, without an
/// [`Accumulator`] (only their upper triangle; `S`'s lower is zero), and
/// the second pass computes the sandwich's middle term `M` alone (in
/// [`fit_with`] it recomputes `Λ` and `η` beside it, unused).
fn fit_grouped<T: RealField + Copy, D: Dim, const G: usize>(
    stats: &GroupedStats<T, D, G>,
    weights: &[Vector3<T>],
    active: &[bool],
    sigma: &mut [Vector3<T>],
    dof: &mut [Vector3<T>],
    estimated: bool,
) -> Result<Fit<T, D>, Error>
where
    DefaultAllocator: Alloc<D>,
{
    let info = stats.information_upper(weights)?;
    // As `Accumulator::solve_active`.
    let (equations, parameters) = (info.equations, active.iter().filter(|a| **a).count());
    if active.len() == info.upper.nrows() && equations < parameters {
        return Err(Error::TooFewEquations {
            equations,
            parameters,
        });
    }
    let lambda = symmetric(&info.upper);
    let solution = Solution::new(&lambda, &info.eta, info.yy, equations, active)?;
    stats.residual_sigma_into(&solution, weights, sigma, dof)?;
    pool_small_groups(sigma, dof);
    let noise = Noise {
        sigma,
        estimated_from: estimated.then_some(&*dof),
    };
    let middle = symmetric(&stats.middle_upper(weights, noise)?);
    let covariance = solution.cov_sandwich(&middle);
    Ok(Fit {
        solution,
        covariance,
        iterations: 0,
        converged: false,
    })
}

impl<T: RealField + Copy, D: Dim, const G: usize> GroupedStats<T, D, G>
where
    DefaultAllocator: Alloc<D>,
{
    /// `Λ = Σ w² S` (upper triangle), `η = Σ w² u`, `Σ w² yy` and the rows
    /// of positive weight: what [`GroupedStats::weighted`] accumulates
    /// without σ, with the same checks and errors and the same sums bit for
    /// bit (the groups and axes in the same order, `Λ += S w²` element by
    /// element), but neither the lower triangle (zero in every `S`) nor an
    /// [`Accumulator`].
    pub(crate) fn information_upper(
        &self,
        weights: &[Vector3<T>],
    ) -> Result<Information<T, D>, Error> {
        if weights.len() != self.groups().len() {
            return Err(Error::Mismatch {
                what: "one weight (and sigma) per group",
            });
        }
        let (dim, p) = (self.dim(), self.dim().value());
        let mut info = OMatrix::<T, D, D>::zeros_generic(dim, dim);
        let mut eta = OVector::<T, D>::zeros_generic(dim, Const::<1>);
        let (mut yy, mut equations) = (T::zero(), 0);
        for (g, w) in self.groups().iter().zip(weights) {
            for (ax, &w) in g.axes.iter().zip(w.iter()) {
                let Some(w2) = moment_weight(w, None, ax.n)? else {
                    continue;
                };
                // As `Accumulator::add_moments`: every new diagonal and η
                // checked before anything is added.
                let new_yy = yy + w2 * ax.yy;
                let ok = new_yy.is_finite()
                    && (0..p).all(|i| {
                        (info[(i, i)] + w2 * ax.s_upper[(i, i)]).is_finite()
                            && (eta[i] + w2 * ax.u[i]).is_finite()
                    });
                if !ok {
                    return Err(Error::NonFinite { what: "overflow" });
                }
                add_upper(&mut info, &ax.s_upper, w2);
                eta.zip_apply(&ax.u, |a, v| *a += v * w2);
                yy = new_yy;
                equations += ax.n;
            }
        }
        Ok(Information {
            upper: info,
            eta,
            yy,
            equations,
        })
    }

    /// The sandwich middle term `M = Σ w⁴ σ² S` (upper triangle) of
    /// [`GroupedStats::weighted_noise`] with this `noise`, the same checks,
    /// errors and sums bit for bit, without recomputing `Λ` and `η`: call it
    /// with weights that [`GroupedStats::information_upper`] accepted (its
    /// overflow checks of `Λ` and `η` are not repeated).
    pub(crate) fn middle_upper(
        &self,
        weights: &[Vector3<T>],
        noise: Noise<'_, T>,
    ) -> Result<OMatrix<T, D, D>, Error> {
        let groups = self.groups().len();
        if weights.len() != groups || !noise.fits(groups) {
            return Err(Error::Mismatch {
                what: "one weight (and sigma) per group",
            });
        }
        let (dim, p) = (self.dim(), self.dim().value());
        let mut middle = OMatrix::<T, D, D>::zeros_generic(dim, dim);
        for (gi, (g, w)) in self.groups().iter().zip(weights).enumerate() {
            let s = noise.sigma(gi, w);
            for ((ax, &w), &s) in g.axes.iter().zip(w.iter()).zip(s.iter()) {
                let Some(w2) = moment_weight(w, Some(s), ax.n)? else {
                    continue;
                };
                let m2 = w2 * w2 * s * s;
                if !(0..p).all(|i| (middle[(i, i)] + m2 * ax.s_upper[(i, i)]).is_finite()) {
                    return Err(Error::NonFinite { what: "overflow" });
                }
                add_upper(&mut middle, &ax.s_upper, m2);
            }
        }
        Ok(middle)
    }
}

/// `Λ` (upper triangle), `η`, `Σ Δpᵀ W² Δp` and the rows of a weighting
/// of [`GroupedStats`] ([`GroupedStats::information_upper`]).
pub(crate) struct Information<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    pub(crate) upper: OMatrix<T, D, D>,
    pub(crate) eta: OVector<T, D>,
    pub(crate) yy: T,
    pub(crate) equations: usize,
}

/// The checks of `Accumulator::add_moments` on one group and axis's weight
/// `w` (and σ), in its order: `Some(w²)` when its `n` rows enter the sums,
/// `None` when they do not (no rows, or weight 0).
fn moment_weight<T: RealField + Copy>(
    w: T,
    sigma: Option<T>,
    n: usize,
) -> Result<Option<T>, Error> {
    if !w.is_finite() || sigma.is_some_and(|s| !s.is_finite()) {
        return Err(Error::NonFinite { what: "weight" });
    }
    if w < T::zero() {
        return Err(Error::NotPositive { what: "weight" });
    }
    let w2 = w * w;
    Ok((n > 0 && w2 != T::zero()).then_some(w2))
}

/// `m += s k` on the upper triangle (column by column, each column's rows
/// `0..=j` a contiguous slice).
fn add_upper<T: RealField + Copy, D: Dim>(m: &mut OMatrix<T, D, D>, s: &OMatrix<T, D, D>, k: T)
where
    DefaultAllocator: Alloc<D>,
{
    let n = m.nrows().max(1);
    let cols = m
        .as_mut_slice()
        .chunks_exact_mut(n)
        .zip(s.as_slice().chunks_exact(n));
    for (j, (mc, sc)) in cols.enumerate() {
        for (a, &v) in mc[..=j].iter_mut().zip(&sc[..=j]) {
            *a += v * k;
        }
    }
}
