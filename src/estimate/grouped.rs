//! Grouped sufficient statistics: everything the iterative reweighting of
//! section 5 needs, without keeping the raw measurements.
//!
//! The paper estimates the noise σ per robot configuration (a *group*) and
//! per axis (x, y, z) from the residuals of the previous fit, turns it into
//! weights (eq. 14) and fits again. Within one group and axis `(g, a)` every
//! row shares one weight, so the unweighted moments
//!
//! - `S = Σ b bᵀ` (n × n, symmetric), `u = Σ b y`, `yy = Σ y²`, `n`
//!
//! are sufficient. From them, exactly (up to rounding):
//!
//! - the residual sum of squares for any `X`: `yy − 2 Xᵀu + Xᵀ S X`, hence σ
//!   per group and axis;
//! - the re-weighted statistics `Λ = Σ w²_ga S_ga`, `η = Σ w²_ga u_ga`;
//! - the sandwich middle term `M = Σ w⁴_ga σ²_ga S_ga` (eq. 11).
//!
//! Memory is `G · 3 · (n² + n + 2)` scalars (and a 64-bit mask per group),
//! fixed: it grows with the number of configurations, never with the
//! number of measurements.
//!
//! The residual sum of squares is a difference of large terms; it keeps its
//! accuracy while `yy` is within a few orders of magnitude of the residuals'
//! sum of squares. Feed `Δp` as deviations from a nominal model (deflections,
//! or measured − nominal positions), not as raw absolute coordinates.

use super::Alloc;
use nalgebra::{Const, DefaultAllocator, Dim, DimName, OMatrix, OVector, RealField, Vector3, U3};

use super::accumulator::Accumulator;
use super::factor::Solution;
use super::irls::Noise;
use super::linalg::dot;
use crate::error::Error;

mod kernel;
mod sums;
use kernel::{add_rows, finite_magnitude, grow, sum_squares};
pub(crate) use sums::support_indices;
use sums::{quadratics3, residual_sums3_sparse, traces3};

/// Moments of the rows of one group and one axis.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisMoments<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    /// `S = Σ b bᵀ`, upper triangle.
    pub s_upper: OMatrix<T, D, D>,
    /// `u = Σ b y`.
    pub u: OVector<T, D>,
    /// `Σ y²`.
    pub yy: T,
    /// Rows.
    pub n: usize,
}

/// `S` row by row and `u` as a list (not nalgebra's internals).
#[cfg(feature = "defmt")]
impl<T: RealField + Copy + defmt::Format, D: Dim> defmt::Format for AxisMoments<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn format(&self, f: defmt::Formatter<'_>) {
        use super::fmt::rows;
        defmt::write!(
            f,
            "AxisMoments {{ s_upper: {}, u: {}, yy: {}, n: {=usize} }}",
            rows(&self.s_upper),
            rows(&self.u),
            self.yy,
            self.n
        )
    }
}

impl<T: RealField + Copy, D: Dim> AxisMoments<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn zeros(dim: D) -> Self {
        Self {
            s_upper: OMatrix::zeros_generic(dim, dim),
            u: OVector::zeros_generic(dim, Const::<1>),
            yy: T::zero(),
            n: 0,
        }
    }

    /// Residual sum of squares `Σ (y − bᵀX)² = yy − 2Xᵀu + XᵀSX`, clamped at 0.
    pub fn rss(&self, x: &OVector<T, D>) -> T {
        let two = T::one() + T::one();
        (self.yy - two * dot(x, &self.u) + self.quadratic(x.as_slice())).max(T::zero())
    }

    /// `XᵀSX` from the upper triangle, with the arithmetic of
    /// `dot(mat_vec(symmetric(S), X), X)` (`(SX)ᵢ` summed over `k` in index
    /// order, then `Σᵢ (SX)ᵢ Xᵢ` in index order), bit for bit, without
    /// building the full `S` or the vector `SX`.
    fn quadratic(&self, x: &[T]) -> T {
        let n = self.s_upper.nrows();
        let s = self.s_upper.as_slice();
        // (`x` of another length: the common part, never out of bounds.)
        let x = &x[..x.len().min(n)];
        let mut q = T::zero();
        for (i, (col, &xi)) in s.chunks_exact(n.max(1)).zip(x).enumerate() {
            // Sᵢₖ = S[k, i] (column i) for k < i, S[i, k] (row i) after.
            let mut y = T::zero();
            for (&sik, &xk) in col[..i].iter().zip(x) {
                y += sik * xk;
            }
            for (k, &xk) in x.iter().enumerate().skip(i) {
                y += s[k * n + i] * xk;
            }
            q += y * xi;
        }
        q
    }
}

/// The moments of one group (robot configuration), per axis x, y, z.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GroupMoments<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    /// The group's id (e.g. the configuration number of the CSV).
    pub id: i32,
    /// Moments per axis: x, y, z.
    pub axes: [AxisMoments<T, D>; 3],
}

/// Grouped sufficient statistics of `D` parameters for at most `G` groups.
/// See the [module docs](self).
///
/// (`repr(C)`, the groups last: the fields that `new` sets are then next
/// to each other. In Rust's layout the groups' storage, not initialised,
/// lay between them, and the compiler filled all of it with one `memset`:
/// 33 KB on every `new` of the KR-270's statistics.)
#[derive(Debug, Clone)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(C)]
pub struct GroupedStats<T: RealField + Copy, D: Dim, const G: usize>
where
    DefaultAllocator: Alloc<D>,
{
    dim: D,
    /// At least the magnitude of every diagonal of `S`, every `u` and
    /// every `yy` (the overflow guard of [`GroupedStats::update`]); not
    /// part of the statistics.
    bound: T,
    /// Per group, the parameters whose column of `B` was not zero in some
    /// row (bit `j`; 0 with more than 64 parameters): every element of the
    /// group's `S` outside them is zero, and the fits leave them out
    /// (adding an exact zero changes no sum). Not part of the statistics.
    support: [u64; G],
    groups: heapless::Vec<GroupMoments<T, D>, G>,
}

/// The statistics compared, not the overflow guard's bound.
impl<T: RealField + Copy, D: Dim, const G: usize> PartialEq for GroupedStats<T, D, G>
where
    DefaultAllocator: Alloc<D>,
{
    fn eq(&self, other: &Self) -> bool {
        self.dim == other.dim && self.groups == other.groups
    }
}

impl<T: RealField + Copy, D: DimName, const G: usize> Default for GroupedStats<T, D, G>
where
    DefaultAllocator: Alloc<D>,
{
    fn default() -> Self {
        Self::new()
    }
}

impl<T: RealField + Copy, D: DimName, const G: usize> GroupedStats<T, D, G>
where
    DefaultAllocator: Alloc<D>,
{
    /// No groups yet (a fixed number of parameters).
    pub fn new() -> Self {
        Self::with_dim(D::name())
    }
}

impl<T: RealField + Copy, D: Dim, const G: usize> GroupedStats<T, D, G>
where
    DefaultAllocator: Alloc<D>,
{
    /// No groups yet, `dim` parameters.
    pub fn with_dim(dim: D) -> Self {
        Self {
            dim,
            groups: heapless::Vec::new(),
            bound: T::zero(),
            support: [0; G],
        }
    }

    /// The number of parameters.
    pub fn dim(&self) -> D {
        self.dim
    }

    /// The groups, in the order they first appeared.
    pub fn groups(&self) -> &[GroupMoments<T, D>] {
        &self.groups
    }

    /// Total number of rows.
    pub fn equations(&self) -> usize {
        self.groups
            .iter()
            .map(|g| g.axes.iter().map(|a| a.n).sum::<usize>())
            .sum()
    }

    /// Adds one measurement of group `id`: rows `b` (x, y, z) and `Δp` \[m\].
    /// Weights are not given here: they are chosen later, per group and axis.
    ///
    /// # Errors
    /// [`Error::Mismatch`] when `b` has not one column per parameter;
    /// [`Error::NonFinite`] for a non-finite value or an overflowing sum,
    /// [`Error::CapacityExceeded`] when `id` is new and `G` groups exist
    /// already. The statistics are unchanged on error.
    pub fn update(&mut self, id: i32, b: &OMatrix<T, U3, D>, dp: &Vector3<T>) -> Result<(), Error>
    where
        DefaultAllocator: Alloc<D>,
    {
        let p = self.dim.value();
        if b.ncols() != p {
            return Err(Error::Mismatch {
                what: "block size differs from the statistics'",
            });
        }
        let (bs, ys) = (b.as_slice(), dp.as_slice());
        // The inputs' sum of squares: finite only when every input is, and
        // at least the largest one's square (the overflow guard below).
        // Otherwise, value by value: which input is not finite, or the
        // largest magnitude when the squares overflow.
        let mut m2 = sum_squares(bs) + sum_squares(ys);
        if !m2.is_finite() {
            m2 = finite_magnitude(bs, ys)?;
        }
        // Rows usually come configuration by configuration: try the last
        // group first.
        let last = self.groups.len().checked_sub(1);
        let found = match last {
            Some(l) if self.groups[l].id == id => Some(l),
            _ => self.groups.iter().position(|g| g.id == id),
        };
        let index = match found {
            Some(i) => i,
            None => {
                if self.groups.is_full() {
                    return Err(Error::CapacityExceeded {
                        what: "groups",
                        capacity: G,
                    });
                }
                self.groups.len()
            }
        };
        // Overflow guard. Every new diagonal of `S` (they bound the
        // off-diagonals), `u` and `yy` is an old one plus a product of two
        // inputs, so its magnitude is at most `bound + m²` (`m` the inputs'
        // largest; `m2` is at least `m²`), rounding included (`grow`).
        // While that is at most half the largest finite value no sum can
        // overflow, and the value by value check is skipped; it decides
        // otherwise, with the same verdict as always.
        let bound = grow(self.bound, m2);
        if !(bound + bound).is_finite() {
            self.check_overflow(index, b, dp)?;
        }
        if index == self.groups.len() {
            let dim = self.dim;
            let fresh = GroupMoments {
                id,
                axes: core::array::from_fn(|_| AxisMoments::zeros(dim)),
            };
            // Cannot fail: checked `is_full` above.
            self.groups
                .push(fresh)
                .map_err(|_| Error::CapacityExceeded {
                    what: "groups",
                    capacity: G,
                })?;
        }
        self.bound = bound;
        let mask = self.support.get(index).copied().unwrap_or(0);
        let mask = add_rows(&mut self.groups[index].axes, p, bs, ys, mask);
        if let Some(m) = self.support.get_mut(index) {
            *m = mask;
        }
        Ok(())
    }

    /// The overflow guard of [`GroupedStats::update`] value by value: every
    /// new diagonal of `S`, `u` and `yy` of the group at `index` (a new
    /// one when `index` is the number of groups) finite. (Rarely needed:
    /// kept out of `update`'s code.)
    #[cold]
    #[inline(never)]
    fn check_overflow(
        &self,
        index: usize,
        b: &OMatrix<T, U3, D>,
        dp: &Vector3<T>,
    ) -> Result<(), Error> {
        let p = self.dim.value();
        let zero = T::zero();
        let mut ok = true;
        for a in 0..3 {
            let y = dp[a];
            let bcols = b.as_slice().chunks_exact(3);
            match self.groups.get(index).map(|g| &g.axes[a]) {
                Some(ax) => {
                    ok &= (ax.yy + y * y).is_finite();
                    let diag = ax.s_upper.as_slice().iter().step_by(p + 1);
                    for ((bi, &s), &u) in bcols.zip(diag).zip(ax.u.as_slice()) {
                        let bi = bi[a];
                        ok &= (s + bi * bi).is_finite() && (u + bi * y).is_finite();
                    }
                }
                None => {
                    ok &= (zero + y * y).is_finite();
                    for bi in bcols {
                        let bi = bi[a];
                        ok &= (zero + bi * bi).is_finite() && (zero + bi * y).is_finite();
                    }
                }
            }
        }
        if ok {
            Ok(())
        } else {
            Err(Error::NonFinite { what: "overflow" })
        }
    }

    /// σ per group and axis of the residuals of `fit`, made with `weights`:
    /// [`group_sigma`] of each group and axis's residual sum, rows and
    /// share of the leverage `h = w² tr(Λ⁻¹ S)`, written to `sigma`, and
    /// [`group_dof`] to `dof`.
    ///
    /// # Errors
    /// [`Error::Mismatch`] when `out` or `weights` does not have one entry
    /// per group, or `fit` has another number of parameters.
    pub fn residual_sigma_into(
        &self,
        fit: &Solution<T, D>,
        weights: &[Vector3<T>],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
    ) -> Result<(), Error> {
        let g = self.groups.len();
        if sigma.len() != g || dof.len() != g || weights.len() != g {
            return Err(Error::Mismatch {
                what: "one sigma and one weight per group",
            });
        }
        let (inv, n) = (&fit.lambda_inv, self.dim.value());
        if inv.nrows() != n || inv.ncols() != n || fit.x.len() != n {
            return Err(Error::Mismatch {
                what: "fit of another number of parameters",
            });
        }
        let two = T::one() + T::one();
        let mut idx = [0u8; 64];
        for (gi, (((o, d), g), w)) in sigma
            .iter_mut()
            .zip(dof.iter_mut())
            .zip(&self.groups)
            .zip(weights)
            .enumerate()
        {
            // The three axes side by side: each sum is a chain of dependent
            // additions (the same, in the same order, as one axis at a
            // time), and three independent chains keep the processor busy
            // where one would wait on each addition.
            let s = g.axes.each_ref().map(|ax| ax.s_upper.as_slice());
            let x = fit.x.as_slice();
            let (tr, q, xu) = match support_indices(self.support[gi], n, &mut idx) {
                Some(m) => {
                    let u = g.axes.each_ref().map(|ax| ax.u.as_slice());
                    let [t, q, d] = residual_sums3_sparse(inv.as_slice(), n, s, u, x, &idx[..m]);
                    (t, q, d)
                }
                None => (
                    traces3(inv.as_slice(), n, s),
                    quadratics3(s, n, x),
                    g.axes.each_ref().map(|ax| dot(&fit.x, &ax.u)),
                ),
            };
            let n = g.axes.each_ref().map(|ax| ax.n);
            // `AxisMoments::rss`, bit for bit.
            let rss = core::array::from_fn(|a| (g.axes[a].yy - two * xu[a] + q[a]).max(T::zero()));
            let h = core::array::from_fn(|a| w[a] * w[a] * tr[a]);
            let (sg, nu) = sigma3(rss, n, h);
            (o[0], o[1], o[2]) = (sg[0], sg[1], sg[2]);
            (d[0], d[1], d[2]) = (nu[0], nu[1], nu[2]);
        }
        Ok(())
    }

    /// Per group, the parameters outside which all its `S` are zero (bit
    /// `j`; 0 when not known).
    pub(crate) fn supports(&self) -> &[u64; G] {
        &self.support
    }

    /// The weighted statistics: every row of group `g`, axis `a` carries the
    /// weight `weights[g][a]`; with `sigma`, the sandwich middle term
    /// `M = Σ w⁴ σ² S` is accumulated too.
    ///
    /// # Errors
    /// [`Error::Mismatch`] when `weights` (or `sigma`) does not have one
    /// entry per group; [`Error::NonFinite`] / [`Error::NotPositive`] for bad
    /// weights.
    pub fn weighted(
        &self,
        weights: &[Vector3<T>],
        sigma: Option<&[Vector3<T>]>,
    ) -> Result<Accumulator<T, D>, Error> {
        self.weighted_noise(weights, sigma.map(Noise::known))
    }

    /// [`GroupedStats::weighted`] with the middle term's σ from `noise`
    /// ([`Noise::sigma`]).
    ///
    /// # Errors
    /// As [`GroupedStats::weighted`].
    pub fn weighted_noise(
        &self,
        weights: &[Vector3<T>],
        noise: Option<Noise<'_, T>>,
    ) -> Result<Accumulator<T, D>, Error> {
        let groups = self.groups.len();
        if weights.len() != groups || noise.is_some_and(|n| !n.fits(groups)) {
            return Err(Error::Mismatch {
                what: "one weight (and sigma) per group",
            });
        }
        let mut acc = Accumulator::zeros(self.dim);
        for (gi, g) in self.groups.iter().enumerate() {
            let s = noise.map(|n| n.sigma(gi, &weights[gi]));
            for (a, ax) in g.axes.iter().enumerate() {
                acc.add_moments(
                    &ax.s_upper,
                    &ax.u,
                    ax.yy,
                    ax.n,
                    weights[gi][a],
                    s.map(|s| s[a]),
                )?;
            }
        }
        Ok(acc)
    }
}

/// `σ̂ = √(RSS / (n − h))`: the residual σ of one group and axis from its
/// residual sum `rss` over `n` rows, `h` being its share of the fit's
/// leverage (`Σ w² bᵀ Λ⁻¹ b` over its rows; the shares of all groups and
/// axes add up to the number of parameters). The expected residual sum of
/// a group is `σ² (n − h)`, so this is unbiased group by group where the
/// global `m / (m − p)` is unbiased only on average: a group that pins a
/// parameter (a compensator bin seen in three configurations) leaves
/// smaller residuals, and the global correction would call it precise and
/// weight it up. The degrees of freedom are kept at ≥ ½ (a group that one
/// parameter fits exactly has no residual to speak of either way). 0 for
/// no row.
pub fn group_sigma<T: RealField + Copy>(rss: T, n: usize, h: T) -> T {
    if n == 0 {
        return T::zero();
    }
    (rss.max(T::zero()) / group_dof(n, h)).sqrt()
}

/// [`group_sigma`] and [`group_dof`] of three axes, the same values, in
/// four lanes (the fourth a dummy `1 / 1`) that the compiler pairs into
/// vector divisions and square roots (the divider is shared: one
/// instruction for two lanes takes about as long as one for one).
#[inline(always)]
fn sigma3<T: RealField + Copy>(rss: [T; 3], n: [usize; 3], h: [T; 3]) -> ([T; 3], [T; 3]) {
    let (zero, one) = (T::zero(), T::one());
    let half = nalgebra::convert::<f64, T>(0.5);
    let dof: [T; 4] = core::array::from_fn(|a| match a {
        3 => one,
        _ => (nalgebra::convert::<f64, T>(n[a] as f64) - h[a]).max(half),
    });
    let r: [T; 4] = core::array::from_fn(|a| if a < 3 { rss[a] } else { one });
    let mut q = [zero; 4];
    for ((q, &r), &d) in q.iter_mut().zip(&r).zip(&dof) {
        *q = (r / d).sqrt();
    }
    let pick = |a: usize, v: T| if n[a] == 0 { zero } else { v };
    (
        core::array::from_fn(|a| pick(a, q[a])),
        core::array::from_fn(|a| pick(a, dof[a])),
    )
}

/// `ν = n − h`, at least ½ (0 without rows): the degrees of freedom of
/// [`group_sigma`].
pub fn group_dof<T: RealField + Copy>(n: usize, h: T) -> T {
    if n == 0 {
        return T::zero();
    }
    let half = nalgebra::convert::<f64, T>(0.5);
    (nalgebra::convert::<f64, T>(n as f64) - h).max(half)
}

/// `w² bᵀ Λ⁻¹ b`: the leverage of one row of weight `w` in a fit with
/// `Λ⁻¹`, the row's elements given by `b(j)` (summed over a group and
/// axis, the `h` of [`group_sigma`]).
pub fn leverage<T: RealField + Copy, D: Dim>(
    lambda_inv: &OMatrix<T, D, D>,
    b: impl Fn(usize) -> T,
    w: T,
) -> T
where
    DefaultAllocator: Alloc<D>,
{
    let n = lambda_inv.nrows();
    let mut q = T::zero();
    for c in 0..n {
        let mut s = T::zero();
        for r in 0..n {
            s += lambda_inv[(r, c)] * b(r);
        }
        q += s * b(c);
    }
    w * w * q
}
