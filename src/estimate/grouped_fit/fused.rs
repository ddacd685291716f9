//! The sandwich's middle term of one fit and the next fit's `Λ` in one
//! pass over the cells.
//!
//! In the iteration of [`super::Reweightable::fit_irls`] the middle term
//! `M = Σ w⁴ σ² c S` of fit `k` and the information `Λ = Σ w'² S`, `η`
//! of fit `k + 1` both come from the same σ (fit `k`'s, pooled): `w'` is
//! eq. 14 of it. One pass reads each cell's `S` once for both, and the
//! two chains of additions (one per matrix element) run side by side.
//! Each sum gets the same terms in the same order as
//! [`GroupedStats::middle_upper`] and [`GroupedStats::information_upper`]
//! one after the other, so the bits are the same. The next fit's sums are
//! only a head start: when anything about them is not as
//! `information_upper` would accept it (a σ that eq. 14 refuses, a bad
//! weight, a sum that is not finite), they are dropped and the next fit
//! computes them itself, with its own checks and errors.

use nalgebra::{DefaultAllocator, Dim, OMatrix, RealField, Vector3};

use super::{
    add_group, add_upper, axis_factors, finite_sums, middle_factors, moment_weight, overflow_first,
    Information,
};
use crate::error::Error;
use crate::estimate::grouped::{support_indices, GroupMoments, GroupedStats};
use crate::estimate::irls::Noise;
use crate::estimate::weights::RobustWeight;
use crate::estimate::Alloc;

impl<T: RealField + Copy, D: Dim, const G: usize> GroupedStats<T, D, G>
where
    DefaultAllocator: Alloc<D>,
{
    /// [`GroupedStats::middle_upper`] (the same result and errors), and
    /// beside it [`GroupedStats::information_upper`] of the weights that
    /// `robust_weights(noise.sigma, weight, …)` would give, into `next`:
    /// `true` when it would give them and `information_upper` would
    /// accept them (`next` is not to be used otherwise); the weights
    /// into `next_weights`.
    pub(crate) fn middle_and_next(
        &self,
        weights: &[Vector3<T>],
        noise: Noise<'_, T>,
        weight: &RobustWeight<T>,
        next: &mut Information<T, D>,
        next_weights: &mut [Vector3<T>],
    ) -> Result<(OMatrix<T, D, D>, bool), Error> {
        let groups = self.groups().len();
        if weights.len() != groups || !noise.fits(groups) || next_weights.len() < groups {
            return Err(Error::Mismatch {
                what: "one weight (and sigma) per group",
            });
        }
        let dim = self.dim();
        let n = dim.value();
        let mut middle = OMatrix::<T, D, D>::zeros_generic(dim, dim);
        // (Slices: nalgebra's `fill` goes element by element through its
        // iterator.)
        next.upper.as_mut_slice().fill(T::zero());
        next.eta.as_mut_slice().fill(T::zero());
        let Information {
            upper: info,
            eta,
            yy,
            equations,
        } = next;
        (*yy, *equations) = (T::zero(), 0);
        let mut next = true;
        let mut idx = [0u8; 64];
        let groups = self.groups().iter().zip(weights).zip(next_weights);
        for (gi, ((g, w), next_w)) in groups.enumerate() {
            let s = noise.sigma(gi, w);
            // The next weights (`robust_weights`) and their `w'²` (0: the
            // axis adds nothing), as `information_upper` takes them.
            let (wn, bad) = axis_factors(|a| weight.weight(noise.sigma[gi][a]));
            *next_w = Vector3::new(wn[0], wn[1], wn[2]);
            next &= bad.is_none();
            let (kl, bad) = axis_factors(|a| {
                moment_weight(wn[a], None, g.axes[a].n).map(|w2| w2.unwrap_or(T::zero()))
            });
            next &= bad.is_none();
            let Some(m) = support_indices(self.supports()[gi], n, &mut idx) else {
                // Every parameter: as `middle_upper`, then as
                // `information_upper`, axis by axis.
                for ((ax, &w), &s) in g.axes.iter().zip(w.iter()).zip(s.iter()) {
                    let w2 = match moment_weight(w, Some(s), ax.n) {
                        Ok(Some(w2)) => w2,
                        Ok(None) => continue,
                        Err(e) => return Err(overflow_first(&middle, None, T::zero(), e)),
                    };
                    add_upper(&mut middle, &ax.s_upper, w2 * w2 * s * s);
                }
                if next {
                    for (ax, &w2) in g.axes.iter().zip(&kl) {
                        if w2 != T::zero() {
                            add_upper(info, &ax.s_upper, w2);
                            eta.zip_apply(&ax.u, |a, v| *a += v * w2);
                            *yy += w2 * ax.yy;
                            *equations += ax.n;
                        }
                    }
                }
                continue;
            };
            let (km, bad) = middle_factors(g, w, &s);
            if let Some(e) = bad {
                add_group(&mut middle, g, km, &idx[..m]);
                return Err(overflow_first(&middle, None, T::zero(), e));
            }
            let idx = &idx[..m];
            if !next {
                add_group(&mut middle, g, km, idx);
                continue;
            }
            add_group2(&mut middle, info, g, km, kl, idx);
            for (ax, &w2) in g.axes.iter().zip(&kl) {
                if w2 != T::zero() {
                    // As `information_upper`: `η` on the support.
                    let (e, u) = (eta.as_mut_slice(), ax.u.as_slice());
                    for &j in idx {
                        let j = usize::from(j);
                        e[j] += u[j] * w2;
                    }
                    *yy += w2 * ax.yy;
                    *equations += ax.n;
                }
            }
        }
        if !finite_sums(&middle, None, T::zero()) {
            return Err(Error::NonFinite { what: "overflow" });
        }
        Ok((middle, next && finite_sums(info, Some(eta), *yy)))
    }
}

/// `add_group(m, g, km, idx)` and `add_group(l, g, kl, idx)` in one pass:
/// each element of `S` read once for both, each sum in its order. Two
/// rows that follow each other in `idx` are done together (the same
/// operations on two elements side by side, which the compiler turns into
/// vector instructions).
fn add_group2<T: RealField + Copy, D: Dim>(
    m: &mut OMatrix<T, D, D>,
    l: &mut OMatrix<T, D, D>,
    g: &GroupMoments<T, D>,
    km: [T; 3],
    kl: [T; 3],
    idx: &[u8],
) where
    DefaultAllocator: Alloc<D>,
{
    let n = m.nrows();
    let s = g.axes.each_ref().map(|ax| ax.s_upper.as_slice());
    let (m, l) = (m.as_mut_slice(), l.as_mut_slice());
    for (ci, &c) in idx.iter().enumerate() {
        let rows = &idx[..=ci];
        let mut ri = 0;
        while let Some(&r) = rows.get(ri) {
            let o = usize::from(c) * n + usize::from(r);
            if rows
                .get(ri + 1)
                .is_some_and(|&q| usize::from(q) == usize::from(r) + 1)
            {
                let pair = |v: &[T]| [v[o], v[o + 1]];
                let (s0, s1, s2) = (pair(s[0]), pair(s[1]), pair(s[2]));
                let (mut mo, mut lo) = (pair(m), pair(l));
                for k in 0..2 {
                    mo[k] = ((mo[k] + s0[k] * km[0]) + s1[k] * km[1]) + s2[k] * km[2];
                    lo[k] = ((lo[k] + s0[k] * kl[0]) + s1[k] * kl[1]) + s2[k] * kl[2];
                }
                (m[o], m[o + 1], l[o], l[o + 1]) = (mo[0], mo[1], lo[0], lo[1]);
                ri += 2;
            } else {
                let (s0, s1, s2) = (s[0][o], s[1][o], s[2][o]);
                m[o] = ((m[o] + s0 * km[0]) + s1 * km[1]) + s2 * km[2];
                l[o] = ((l[o] + s0 * kl[0]) + s1 * kl[1]) + s2 * kl[2];
                ri += 1;
            }
        }
    }
}
