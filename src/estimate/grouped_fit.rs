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
//! same bit for bit (`host-tests/tests/grouped_fit.rs`). Where a group's
//! rows leave columns of `B` zero (the KR-270's: 5 of 9 parameters per
//! configuration), its `S` are zero outside the others' rows and columns,
//! and every pass leaves those elements out: an exact zero added changes
//! no sum.

use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector, RealField, Vector3};

use super::accumulator::Accumulator;
use super::factor::Solution;
use super::grouped::{support_indices, GroupMoments, GroupedStats};
use super::irls::{
    change, pool_small_groups, robust_weights, Fit, IrlsSettings, Iteration, Noise, Reweightable,
};
use super::weights::RobustWeight;
use super::Alloc;
use crate::error::Error;

mod fused;

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

    /// The default [`Reweightable::fit_irls`] (OLS, then
    /// [`Reweightable::fit_reweighted`] until the change is below the
    /// tolerance), the same fits, history and result bit for bit, but the
    /// sandwich covariance in full only for the fit it returns: the others
    /// need only its diagonal, the standard deviations
    /// (`Solution::sandwich_std`).
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
        weights.fill(Vector3::repeat(T::one()));
        let dim = self.dim();
        let mut ahead = Ahead {
            weight: &settings.weight,
            info: Information::zeros(dim),
            weights: [Vector3::zeros(); G],
            ready: false,
        };
        // (A first reweighted fit follows: `max_iterations` ≥ 1.)
        let (ols, ols_middle) = fit_parts(
            self,
            weights,
            active,
            sigma,
            dof,
            false,
            Some(&mut ahead),
            true,
        )?;
        history(&Iteration {
            x: ols.x.clone(),
            std: ols.sandwich_std(&ols_middle),
            change: T::zero(),
        });
        let mut x = ols.x;
        let mut k = 1;
        loop {
            if ahead.ready {
                // `robust_weights(sigma, …)`, computed by the last fit.
                weights.copy_from_slice(&ahead.weights[..weights.len()]);
            } else {
                robust_weights(sigma, &settings.weight, weights)?;
            }
            // (No head start on a fit after the last one.)
            let more = k < settings.max_iterations;
            let (fit, middle) = fit_parts(
                self,
                weights,
                active,
                sigma,
                dof,
                true,
                Some(&mut ahead),
                more,
            )?;
            let std = fit.sandwich_std(&middle);
            let change = change(active, &fit.x, &x, &std);
            history(&Iteration {
                x: fit.x.clone(),
                std,
                change,
            });
            let converged = change < settings.tolerance;
            if converged || !more {
                return Ok(Fit {
                    covariance: fit.cov_sandwich(&middle),
                    solution: fit,
                    iterations: k,
                    converged,
                });
            }
            x = fit.x;
            k += 1;
        }
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
    let (solution, middle) = fit_parts(stats, weights, active, sigma, dof, estimated, None, false)?;
    let covariance = solution.cov_sandwich(&middle);
    Ok(Fit {
        solution,
        covariance,
        iterations: 0,
        converged: false,
    })
}

/// [`fit_grouped`] without the covariance: the solution and the
/// sandwich's middle term `M` (full, symmetric). With `ahead`, `Λ` from
/// it when it is ready (computed by the fit before, for these weights);
/// and with `next`, it is filled for the next fit
/// ([`GroupedStats::middle_and_next`]).
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
fn fit_parts<T: RealField + Copy, D: Dim, const G: usize>(
    stats: &GroupedStats<T, D, G>,
    weights: &[Vector3<T>],
    active: &[bool],
    sigma: &mut [Vector3<T>],
    dof: &mut [Vector3<T>],
    estimated: bool,
    mut ahead: Option<&mut Ahead<'_, T, D, G>>,
    next: bool,
) -> Result<(Solution<T, D>, OMatrix<T, D, D>), Error>
where
    DefaultAllocator: Alloc<D>,
{
    let mut fresh;
    let info = match ahead.as_deref_mut() {
        Some(a) if a.ready => &mut a.info,
        _ => {
            fresh = stats.information_upper(weights)?;
            &mut fresh
        }
    };
    // As `Accumulator::solve_active`.
    let (equations, parameters) = (info.equations, active.iter().filter(|a| **a).count());
    if active.len() == info.upper.nrows() && equations < parameters {
        return Err(Error::TooFewEquations {
            equations,
            parameters,
        });
    }
    // `Λ` in full where its upper triangle was (the head start's is
    // overwritten in full by the next one; not copied).
    info.upper.fill_lower_triangle_with_upper_triangle();
    let solution = Solution::new(&info.upper, &info.eta, info.yy, equations, active)?;
    stats.residual_sigma_into(&solution, weights, sigma, dof)?;
    pool_small_groups(sigma, dof);
    let noise = Noise {
        sigma,
        estimated_from: estimated.then_some(&*dof),
    };
    let mut middle = match ahead {
        Some(a) if next => {
            let (middle, ready) =
                stats.middle_and_next(weights, noise, a.weight, &mut a.info, &mut a.weights)?;
            a.ready = ready;
            middle
        }
        a => {
            if let Some(a) = a {
                a.ready = false;
            }
            stats.middle_upper(weights, noise)?
        }
    };
    middle.fill_lower_triangle_with_upper_triangle();
    Ok((solution, middle))
}

/// The next fit's weights and `Λ`, `η`, … computed ahead: `ready` when
/// `weights` holds `robust_weights` of the last fit's σ (eq. 14 with
/// `weight`, every σ accepted) and `info` their
/// [`GroupedStats::information_upper`].
struct Ahead<'a, T: RealField + Copy, D: Dim, const G: usize>
where
    DefaultAllocator: Alloc<D>,
{
    weight: &'a RobustWeight<T>,
    info: Information<T, D>,
    weights: [Vector3<T>; G],
    ready: bool,
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
        let dim = self.dim();
        let n = dim.value();
        let mut info = OMatrix::<T, D, D>::zeros_generic(dim, dim);
        let mut eta = OVector::<T, D>::zeros_generic(dim, Const::<1>);
        let (mut yy, mut equations) = (T::zero(), 0);
        // `Accumulator::add_moments` checks every new diagonal and η before
        // it adds anything and stops at the first that is not finite; here
        // everything is added and the sums are checked once, at the end or
        // at a bad weight: the same verdict, because a sum that is not
        // finite stays so whatever is added to it.
        let mut idx = [0u8; 64];
        for (gi, (g, w)) in self.groups().iter().zip(weights).enumerate() {
            let Some(m) = support_indices(self.supports()[gi], n, &mut idx) else {
                for (ax, &w) in g.axes.iter().zip(w.iter()) {
                    let w2 = match moment_weight(w, None, ax.n) {
                        Ok(Some(w2)) => w2,
                        Ok(None) => continue,
                        Err(e) => return Err(overflow_first(&info, Some(&eta), yy, e)),
                    };
                    add_upper(&mut info, &ax.s_upper, w2);
                    eta.zip_apply(&ax.u, |a, v| *a += v * w2);
                    yy += w2 * ax.yy;
                    equations += ax.n;
                }
                continue;
            };
            // On the support: the three axes' weights first (0: the axis
            // adds nothing); a bad one ends the sums after the axes before
            // it, as one axis at a time would.
            let (k, bad) = axis_factors(|a| {
                moment_weight(w[a], None, g.axes[a].n).map(|w2| w2.unwrap_or(T::zero()))
            });
            add_group(&mut info, g, k, &idx[..m]);
            for (ax, &w2) in g.axes.iter().zip(&k) {
                if w2 != T::zero() {
                    // `η` on the support: `u` is +0 elsewhere (its terms
                    // `bⱼ y` all zeros), and `η` never −0.
                    let (e, u) = (eta.as_mut_slice(), ax.u.as_slice());
                    for &j in &idx[..m] {
                        let j = usize::from(j);
                        e[j] += u[j] * w2;
                    }
                    yy += w2 * ax.yy;
                    equations += ax.n;
                }
            }
            if let Some(e) = bad {
                return Err(overflow_first(&info, Some(&eta), yy, e));
            }
        }
        if !finite_sums(&info, Some(&eta), yy) {
            return Err(Error::NonFinite { what: "overflow" });
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
        let dim = self.dim();
        let n = dim.value();
        let mut middle = OMatrix::<T, D, D>::zeros_generic(dim, dim);
        // The overflow check once, as in `information_upper`.
        let mut idx = [0u8; 64];
        for (gi, (g, w)) in self.groups().iter().zip(weights).enumerate() {
            let s = noise.sigma(gi, w);
            let Some(m) = support_indices(self.supports()[gi], n, &mut idx) else {
                for ((ax, &w), &s) in g.axes.iter().zip(w.iter()).zip(s.iter()) {
                    let w2 = match moment_weight(w, Some(s), ax.n) {
                        Ok(Some(w2)) => w2,
                        Ok(None) => continue,
                        Err(e) => return Err(overflow_first(&middle, None, T::zero(), e)),
                    };
                    add_upper(&mut middle, &ax.s_upper, w2 * w2 * s * s);
                }
                continue;
            };
            let (k, bad) = middle_factors(g, w, &s);
            add_group(&mut middle, g, k, &idx[..m]);
            if let Some(e) = bad {
                return Err(overflow_first(&middle, None, T::zero(), e));
            }
        }
        if !finite_sums(&middle, None, T::zero()) {
            return Err(Error::NonFinite { what: "overflow" });
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

impl<T: RealField + Copy, D: Dim> Information<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn zeros(dim: D) -> Self {
        Self {
            upper: OMatrix::zeros_generic(dim, dim),
            eta: OVector::zeros_generic(dim, Const::<1>),
            yy: T::zero(),
            equations: 0,
        }
    }
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

/// `f(a)` of the three axes up to the first error, 0 from it on, and that
/// error. (Straight-line code, not a loop with a `break`: the factors
/// then stay in registers, where the loop stored them one by one and
/// `add_group` read two at once, a load the stores could not forward.)
#[inline(always)]
fn axis_factors<T: RealField + Copy>(
    f: impl Fn(usize) -> Result<T, Error>,
) -> ([T; 3], Option<Error>) {
    let zero = T::zero();
    match (f(0), f(1), f(2)) {
        (Ok(a), Ok(b), Ok(c)) => ([a, b, c], None),
        (Err(e), _, _) => ([zero; 3], Some(e)),
        (Ok(a), Err(e), _) => ([a, zero, zero], Some(e)),
        (Ok(a), Ok(b), Err(e)) => ([a, b, zero], Some(e)),
    }
}

/// The factors `w⁴ σ²` of `M` of a group's three axes, with weights `w`
/// and the middle term's σ `s` ([`axis_factors`] of [`moment_weight`]).
#[inline(always)]
fn middle_factors<T: RealField + Copy, D: Dim>(
    g: &GroupMoments<T, D>,
    w: &Vector3<T>,
    s: &Vector3<T>,
) -> ([T; 3], Option<Error>)
where
    DefaultAllocator: Alloc<D>,
{
    axis_factors(|a| {
        moment_weight(w[a], Some(s[a]), g.axes[a].n)
            .map(|w2| w2.map_or(T::zero(), |w2| w2 * w2 * s[a] * s[a]))
    })
}

/// `m += S₀ k₀`, `+= S₁ k₁`, `+= S₂ k₂` on the upper triangle, `Sₐ` the
/// group's axes (`kₐ = 0`: the axis adds nothing), only the elements whose
/// row and column are both in `idx` (the group's support, from
/// [`GroupedStats::supports`]), the three axes at once: every `S` is zero
/// elsewhere, and an exact zero added changes no sum, so every element
/// gets the same sums in the same order as one axis at a time.
fn add_group<T: RealField + Copy, D: Dim>(
    m: &mut OMatrix<T, D, D>,
    g: &GroupMoments<T, D>,
    k: [T; 3],
    idx: &[u8],
) where
    DefaultAllocator: Alloc<D>,
{
    let n = m.nrows();
    let s = g.axes.each_ref().map(|ax| ax.s_upper.as_slice());
    let m = m.as_mut_slice();
    for (ci, &c) in idx.iter().enumerate() {
        for &r in &idx[..=ci] {
            let o = usize::from(c) * n + usize::from(r);
            m[o] = ((m[o] + s[0][o] * k[0]) + s[1][o] * k[1]) + s[2][o] * k[2];
        }
    }
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

/// Whether the diagonal of `m`, `eta` and `yy` are finite: the overflow
/// check of `Accumulator::add_moments` on sums of moments (the diagonals
/// bound the rest). A float compare (`v · 0 = 0`) per value.
fn finite_sums<T: RealField + Copy, D: Dim>(
    m: &OMatrix<T, D, D>,
    eta: Option<&OVector<T, D>>,
    yy: T,
) -> bool
where
    DefaultAllocator: Alloc<D>,
{
    let zero = T::zero();
    let finite = |v: &T| *v * zero == zero;
    let n = m.nrows();
    let diag = m.as_slice().iter().step_by(n + 1).all(finite);
    diag && finite(&yy) && eta.is_none_or(|e| e.as_slice().iter().all(finite))
}

/// The error of a bad weight met after the sums so far, or the overflow
/// that `Accumulator::add_moments` would have reported before it.
fn overflow_first<T: RealField + Copy, D: Dim>(
    m: &OMatrix<T, D, D>,
    eta: Option<&OVector<T, D>>,
    yy: T,
    e: Error,
) -> Error
where
    DefaultAllocator: Alloc<D>,
{
    if finite_sums(m, eta, yy) {
        e
    } else {
        Error::NonFinite { what: "overflow" }
    }
}
