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
use super::weights::RobustWeight;
use crate::error::Error;

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

/// `x` and `std` as lists (not nalgebra's internals).
#[cfg(feature = "defmt")]
impl<T: RealField + Copy + defmt::Format, D: Dim> defmt::Format for Iteration<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn format(&self, f: defmt::Formatter<'_>) {
        use super::fmt::rows;
        defmt::write!(
            f,
            "Iteration {{ x: {}, std: {}, change: {} }}",
            rows(&self.x),
            rows(&self.std),
            self.change
        )
    }
}

/// A fit and its covariance. The weights it used and the residual σ per
/// group and axis are in the slices the caller passed.
#[derive(Debug, Clone, PartialEq)]
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

/// The covariance row by row (not nalgebra's internals).
#[cfg(feature = "defmt")]
impl<T: RealField + Copy + defmt::Format, D: Dim> defmt::Format for Fit<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(
            f,
            "Fit {{ solution: {}, covariance: {}, iterations: {=usize}, converged: {=bool} }}",
            self.solution,
            super::fmt::rows(&self.covariance),
            self.iterations,
            self.converged
        )
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
    /// axis `a`; with `noise`, the sandwich middle term `M = Σ w⁴σ² bbᵀ`
    /// too, `σ` per group from [`Noise::sigma`].
    ///
    /// # Errors
    /// [`Error::Mismatch`] without one entry per group; bad weights.
    fn weighted(
        &self,
        weights: &[Vector3<T>],
        noise: Option<Noise<'_, T>>,
    ) -> Result<Accumulator<T, D>, Error>;

    /// σ per group and axis of the residuals of `fit`, made with `weights`
    /// (one entry per group), written to `sigma`, and its degrees of
    /// freedom to `dof`: each group and axis on its own, `ν = n − h` and
    /// `σ̂ = √(RSS / ν)` ([`crate::estimate::grouped::group_sigma`]; `h` is the group and axis's share
    /// of the fit's leverage, [`crate::estimate::grouped::leverage`]).
    ///
    /// # Errors
    /// [`Error::Mismatch`] when `sigma`, `dof` or `weights` does not have
    /// one entry per group.
    fn residual_sigma_into(
        &self,
        fit: &Solution<T, D>,
        weights: &[Vector3<T>],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
    ) -> Result<(), Error>;

    /// Fit with the given weights per group and axis, known in advance
    /// (not estimated from these data); covariance by the sandwich (eq. 11)
    /// with σ from this fit's residuals, which are written to `sigma` and
    /// their degrees of freedom to `dof` (one entry per group; groups too
    /// small for their own σ pooled, [`pool_small_groups`]).
    ///
    /// # Errors
    /// From [`Reweightable::weighted`] and the solve.
    fn fit_weighted(
        &self,
        weights: &[Vector3<T>],
        active: &[bool],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
    ) -> Result<Fit<T, D>, Error> {
        fit_with(self, weights, active, sigma, dof, false)
    }

    /// One WLS step (eq. 10) with the weights of eq. 14 computed from the
    /// previous fit's `sigma` and `dof` (which are overwritten with this
    /// fit's); the weights are written to `weights`. The sandwich (eq. 11)
    /// accounts for the weights having been estimated from the same data
    /// ([`estimated_weight_factor`]).
    ///
    /// # Errors
    /// As [`robust_weights`] and [`Reweightable::fit_weighted`].
    fn fit_reweighted(
        &self,
        weight: &RobustWeight<T>,
        active: &[bool],
        weights: &mut [Vector3<T>],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
    ) -> Result<Fit<T, D>, Error> {
        robust_weights(sigma, weight, weights)?;
        fit_with(self, weights, active, sigma, dof, true)
    }

    /// Ordinary least squares (eq. 6) with the sandwich covariance (eq. 8).
    /// `weights` is set to one, `sigma` and `dof` to the residual σ.
    ///
    /// # Errors
    /// As [`Reweightable::fit_weighted`].
    fn fit_ols(
        &self,
        active: &[bool],
        weights: &mut [Vector3<T>],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
    ) -> Result<Fit<T, D>, Error> {
        weights.fill(Vector3::repeat(T::one()));
        self.fit_weighted(weights, active, sigma, dof)
    }

    /// Iteratively reweighted least squares from the OLS start (section 5):
    /// [`Reweightable::fit_reweighted`] until no parameter moves by more
    /// than the tolerance. On return `weights`, `sigma` and `dof` hold the
    /// final fit's. The OLS start and every iteration are passed to
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
        dof: &mut [Vector3<T>],
        mut history: impl FnMut(&Iteration<T, D>),
    ) -> Result<Fit<T, D>, Error> {
        if settings.max_iterations == 0 {
            return Err(Error::OutOfRange {
                what: "max_iterations",
                index: 0,
                len: 0,
            });
        }
        let mut fit = self.fit_ols(active, weights, sigma, dof)?;
        history(&Iteration {
            x: fit.solution.x.clone(),
            std: fit.std(),
            change: T::zero(),
        });
        for k in 1..=settings.max_iterations {
            let next = self.fit_reweighted(&settings.weight, active, weights, sigma, dof)?;
            let std = next.std();
            let change = change(active, &next.solution.x, &fit.solution.x, &std);
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

/// The largest move `|xᵢ − previousᵢ| / σᵢ` of an active parameter with
/// `σᵢ > 0` (0 for none): the convergence test of iterative reweighting.
pub(crate) fn change<T: RealField + Copy, D: Dim>(
    active: &[bool],
    x: &OVector<T, D>,
    previous: &OVector<T, D>,
    std: &OVector<T, D>,
) -> T
where
    DefaultAllocator: Alloc<D>,
{
    let mut change = T::zero();
    for i in 0..active.len() {
        if active[i] && std[i] > T::zero() {
            change = change.max((x[i] - previous[i]).abs() / std[i]);
        }
    }
    change
}

/// The fit behind [`Reweightable::fit_weighted`] (`estimated = false`) and
/// [`Reweightable::fit_reweighted`] (`true`: eq. 14 weights from these
/// data's σ, the middle term corrected by [`estimated_weight_factor`]).
fn fit_with<T: RealField + Copy, D: Dim, R: Reweightable<T, D> + ?Sized>(
    src: &R,
    weights: &[Vector3<T>],
    active: &[bool],
    sigma: &mut [Vector3<T>],
    dof: &mut [Vector3<T>],
    estimated: bool,
) -> Result<Fit<T, D>, Error>
where
    DefaultAllocator: Alloc<D>,
{
    // Results matched by reference (a `?` would copy them out).
    let solved = solve_weighted(src, weights, active);
    let solution = match &solved {
        Ok(s) => s,
        Err(e) => return Err(*e),
    };
    src.residual_sigma_into(solution, weights, sigma, dof)?;
    pool_small_groups(sigma, dof);
    let noise = Noise {
        sigma,
        estimated_from: estimated.then_some(&*dof),
    };
    let middle = middle(src, weights, noise);
    let covariance = match &middle {
        Ok(m) => solution.cov_sandwich(m),
        Err(e) => return Err(*e),
    };
    Ok(Fit {
        solution: solution.clone(),
        covariance,
        iterations: 0,
        converged: false,
    })
}

/// The first half of [`fit_with`]: the weighted sums and their solve.
/// Not inlined (nor [`middle`]): each one's temporaries are on the
/// stack only while it runs, not under the other's stream (a device's
/// stack is the sum of the frames of one call chain).
#[inline(never)]
fn solve_weighted<T: RealField + Copy, D: Dim, R: Reweightable<T, D> + ?Sized>(
    src: &R,
    weights: &[Vector3<T>],
    active: &[bool],
) -> Result<Solution<T, D>, Error>
where
    DefaultAllocator: Alloc<D>,
{
    // By reference: the sums are not moved out of the result (a copy).
    match &src.weighted(weights, None) {
        Ok(acc) => solve(acc, active),
        Err(e) => Err(*e),
    }
}

/// [`Accumulator::solve_active`], not inlined: the solve's temporaries are
/// not in the frame that waits for the stream.
#[inline(never)]
fn solve<T: RealField + Copy, D: Dim>(
    acc: &Accumulator<T, D>,
    active: &[bool],
) -> Result<Solution<T, D>, Error>
where
    DefaultAllocator: Alloc<D>,
{
    acc.solve_active(active)
}

/// The second half of [`fit_with`]: the sandwich's middle term with
/// `noise`.
#[inline(never)]
fn middle<T: RealField + Copy, D: Dim, R: Reweightable<T, D> + ?Sized>(
    src: &R,
    weights: &[Vector3<T>],
    noise: Noise<'_, T>,
) -> Result<OMatrix<T, D, D>, Error>
where
    DefaultAllocator: Alloc<D>,
{
    match &src.weighted(weights, Some(noise)) {
        Ok(acc) => Ok(acc.middle()),
        Err(e) => Err(*e),
    }
}

/// The noise of the sandwich's middle term (eq. 8, 11): σ per group and
/// axis, and whether the weights were estimated from it.
#[derive(Debug, Clone, Copy)]
pub struct Noise<'a, T> {
    /// σ per group and axis, in the unit of `Δp`.
    pub sigma: &'a [Vector3<T>],
    /// `Some(ν)`: the weights are eq. 14 of this σ, estimated from these
    /// data with `ν` degrees of freedom per group and axis; the middle term
    /// then uses `σ² · c` ([`estimated_weight_factor`]). `None`: weights
    /// known in advance.
    pub estimated_from: Option<&'a [Vector3<T>]>,
}

impl<'a, T: RealField + Copy> Noise<'a, T> {
    /// Weights known in advance (OLS, or weights not from these data).
    pub fn known(sigma: &'a [Vector3<T>]) -> Self {
        Self {
            sigma,
            estimated_from: None,
        }
    }

    /// Whether `σ` (and `ν`) have one entry for each of `groups`.
    pub fn fits(&self, groups: usize) -> bool {
        self.sigma.len() == groups && self.estimated_from.is_none_or(|d| d.len() == groups)
    }

    /// The middle term's σ of group `g` whose rows carry the weights `w`:
    /// `σ √c` per axis, `c` the [`estimated_weight_factor`] of eq. 14's
    /// elasticity `1 − w` when the weights were estimated, else `σ`.
    pub fn sigma(&self, g: usize, w: &Vector3<T>) -> Vector3<T> {
        let s = self.sigma[g];
        match self.estimated_from {
            None => s,
            Some(dof) => Vector3::from_fn(|a, _| {
                s[a] * estimated_weight_factor(dof[g][a], T::one() - w[a]).sqrt()
            }),
        }
    }
}

/// A group and axis whose σ has fewer degrees of freedom than this shares
/// one σ with the other such groups of its axis ([`pool_small_groups`]).
/// 8: below it a single group's σ is too uncertain to weight by (its
/// relative standard deviation exceeds 25 %) and the estimated-weight
/// correction of the covariance ([`estimated_weight_factor`]) exceeds 2.
pub const POOL_BELOW_DOF: f64 = 8.0;

/// Pools the σ of every group and axis with fewer than [`POOL_BELOW_DOF`]
/// degrees of freedom: per axis, all such groups get
/// `σ² = Σ ν σ² / Σ ν` over them and `ν = Σ ν`; when they have fewer than
/// [`POOL_BELOW_DOF`] together, the pool takes every group of that axis.
/// Groups without rows (`ν = 0`) are left as they are. Pooled entries are
/// recognisable by their `dof`, the pool's.
pub fn pool_small_groups<T: RealField + Copy>(sigma: &mut [Vector3<T>], dof: &mut [Vector3<T>]) {
    let min: T = nalgebra::convert(POOL_BELOW_DOF);
    for a in 0..3 {
        let small = |n: T| n > T::zero() && n < min;
        let sum = |all: bool| {
            sigma
                .iter()
                .zip(dof.iter())
                .filter(|(_, n)| if all { n[a] > T::zero() } else { small(n[a]) })
                .fold((T::zero(), T::zero()), |(s, v), (sg, n)| {
                    (s + sg[a] * sg[a] * n[a], v + n[a])
                })
        };
        let (s, v) = sum(false);
        if v == T::zero() {
            continue;
        }
        let (s, v) = if v < min { sum(true) } else { (s, v) };
        let pooled = (s / v).sqrt();
        for (sg, n) in sigma.iter_mut().zip(dof.iter_mut()) {
            if small(n[a]) {
                sg[a] = pooled;
                n[a] = v;
            }
        }
    }
}

/// `c = ν / (ν − 4ε)`: how much the sandwich's middle term of one group
/// and axis understates its variance when its weight was computed from its
/// own residual σ̂ (`ν` degrees of freedom). With a weight of elasticity
/// `ε = −∂ln w/∂ln σ̂` (eq. 14: `ε = λσ̂/(σ0 + λσ̂) = 1 − w`; eq. 12:
/// `ε = 1`), the middle term estimates `E[w⁴ σ̂²]` where the variance is
/// `E[w⁴ σ²]`; for `σ̂²/σ² ~ χ²_ν/ν` and `w ∝ σ̂^−ε` their ratio is
/// `E[u^−2ε] / E[u^(1−2ε)] = ν / (ν − 4ε)` (`u = σ̂²/σ²`). Groups whose
/// weights are known in advance (OLS: `ε = 0`) need none. Measured on the
/// KR-270 (docs/numerics.md): without it the IRLS σ are 5–19 % too small.
/// Capped at 2 (`ν − 4ε ≥ ν/2`; pooling keeps `ν ≥ 8`).
pub fn estimated_weight_factor<T: RealField + Copy>(dof: T, elasticity: T) -> T {
    if dof <= T::zero() {
        return T::one();
    }
    let four: T = nalgebra::convert(4.0);
    let half: T = nalgebra::convert(0.5);
    let e = elasticity.max(T::zero()).min(T::one());
    dof / (dof - four * e).max(dof * half)
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
    // The checks of `RobustWeight::weight` first, in its order, without
    // its division (the weights are computed once, below).
    for s in sigma {
        for a in 0..3 {
            weight.check_sigma(s[a])?;
        }
    }
    for (o, s) in out.iter_mut().zip(sigma) {
        *o = s.map(|v| weight.weight(v).unwrap_or(T::zero()));
    }
    Ok(())
}
