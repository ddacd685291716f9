//! In-stream diagnosis: which effect the model lacks, decided from
//! cross-products accumulated in one pass, without storing rows.
//!
//! The host's closed loop (`calibrate::diagnosis`) keeps every row in
//! memory and, for each candidate effect with columns `C`, builds the
//! cross-products of `[B_A | B_C]` (the model's columns `A`, eq. 4, then
//! the candidate's), keeps the candidate columns that the unweighted
//! columns tell apart from the model's ([`super::rank`]) and runs the
//! nested F test ([`super::nested_test`]) at the model fit's weights `W`
//! (eq. 9, 12, 14). Every quantity it needs is an entry of
//!
//! ```text
//!   Λ = Σ [B_A | B_C]ᵀ W² [B_A | B_C],   η = Σ [B_A | B_C]ᵀ W² Δp,   Σ Δpᵀ W² Δp, m
//!   Λ⁰ = Σ [B_A | B_C]ᵀ [B_A | B_C]   (unweighted: the independence test, as the host's)
//! ```
//!
//! over the model's columns *and every candidate's columns at once*
//! (`K` of them): [`Augmented`] accumulates them in one stream, `O((N+K)²)`
//! scalars (packed upper triangles, no `M`), and [`Augmented::test`] cuts
//! out the principal sub-problem `[A | C]` of one candidate and runs the
//! host's path on it: the same arithmetic on the same sums.
//!
//! The host's multiple-testing rule ([`Rule`]): a candidate is eligible when
//! `p · tried < α` (Bonferroni over the candidates tested) and, when the
//! lack of fit against the repetitions is significant, when its `ΔRSS`
//! explains at least `min_share` of the lack-of-fit sum of squares above its
//! noise expectation. The lack of fit needs the pure error: the scatter of
//! the repetitions within each cell (configuration, marker), where the rows
//! share their regressors, so that it does not depend on the fit;
//! [`PureError`] keeps it per cell, `O(G)`, and
//! `SS_lof = RSS_w − SS_pe` at the fit's weights.
//!
//! Memory: `2·(N+K)(N+K+1)/2 + (N+K)` scalars for [`Augmented`] and seven
//! per cell for [`PureError`] (in [`super::decision`], with [`Rule`]); each test works on an accumulator of the
//! size of the model plus one candidate.

use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector, RealField, SMatrix, Vector3};

use super::accumulator::Accumulator;
use super::factor::{pivot_tolerance, Factor, Solution};
use super::linalg::dot;
use super::nested::{from_delta, nested_test, NestedTest};
use super::rank::independent;
use super::Alloc;
use crate::error::Error;

pub use super::decision::{rank_tests, LackOfFit, PureError, Rule};

/// Most columns of one sub-problem (model plus one candidate).
pub const MAX_SUB: usize = 64;

/// Index of `(i, j)`, `i ≤ j`, in a packed upper triangle (column-major).
fn packed(i: usize, j: usize) -> usize {
    let (i, j) = if i <= j { (i, j) } else { (j, i) };
    j * (j + 1) / 2 + i
}

/// The weighted and unweighted cross-products of `P` columns (the model's
/// and every candidate's), accumulated in one stream. `L` must be
/// `P (P + 1) / 2` (the packed upper triangle; checked by [`Augmented::new`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Augmented<T: RealField + Copy, const P: usize, const L: usize> {
    /// `Λ = Σ Bᵀ W² B`, packed upper triangle.
    info: [T; L],
    /// `Λ⁰ = Σ Bᵀ B`, packed upper triangle.
    plain: [T; L],
    /// `η = Σ Bᵀ W² Δp`.
    eta: [T; P],
    /// `Σ Δpᵀ W² Δp`.
    yy: T,
    /// Rows with a positive weight.
    equations: usize,
}

impl<T: RealField + Copy, const P: usize, const L: usize> Augmented<T, P, L> {
    /// Empty sums.
    ///
    /// # Errors
    /// [`Error::Mismatch`] when `L ≠ P (P + 1) / 2`.
    pub fn new() -> Result<Self, Error> {
        if L != P * (P + 1) / 2 {
            return Err(Error::Mismatch {
                what: "L must be P (P + 1) / 2",
            });
        }
        Ok(Self {
            info: [T::zero(); L],
            plain: [T::zero(); L],
            eta: [T::zero(); P],
            yy: T::zero(),
            equations: 0,
        })
    }

    /// Rows with a positive weight accumulated so far.
    pub fn equations(&self) -> usize {
        self.equations
    }

    /// Adds one measurement: the three rows `b` (x, y, z) of all `P`
    /// columns (zero past the layout), `Δp` and the weight of each row
    /// (eq. 9). Unchanged on error.
    ///
    /// # Errors
    /// [`Error::NonFinite`] for a non-finite entry or weight, or when a sum
    /// would overflow (checked on the diagonals, which bound the rest);
    /// [`Error::OutOfRange`] for a negative weight.
    pub fn update(
        &mut self,
        b: &SMatrix<T, 3, P>,
        dp: &Vector3<T>,
        w: &Vector3<T>,
    ) -> Result<(), Error> {
        if !(b.iter().all(|v| v.is_finite())
            && dp.iter().all(|v| v.is_finite())
            && w.iter().all(|v| v.is_finite()))
        {
            return Err(Error::NonFinite { what: "row" });
        }
        if w.iter().any(|v| *v < T::zero()) {
            return Err(Error::OutOfRange {
                what: "weight",
                index: 0,
                len: 0,
            });
        }
        let w2 = w.component_mul(w);
        // The diagonals and Σ Δpᵀ W² Δp after the update bound every other
        // sum (Cauchy–Schwarz): check them before changing anything.
        let mut yy = self.yy;
        for a in 0..3 {
            yy += w2[a] * dp[a] * dp[a];
        }
        let mut ok = yy.is_finite();
        for j in 0..P {
            let d = packed(j, j);
            let (mut s, mut s0) = (self.info[d], self.plain[d]);
            for a in 0..3 {
                s += w2[a] * b[(a, j)] * b[(a, j)];
                s0 += b[(a, j)] * b[(a, j)];
            }
            ok &= s.is_finite() && s0.is_finite();
        }
        if !ok {
            return Err(Error::NonFinite { what: "overflow" });
        }
        for j in 0..P {
            for i in 0..=j {
                let k = packed(i, j);
                for a in 0..3 {
                    let bb = b[(a, i)] * b[(a, j)];
                    self.info[k] += w2[a] * bb;
                    self.plain[k] += bb;
                }
            }
            for a in 0..3 {
                self.eta[j] += w2[a] * b[(a, j)] * dp[a];
            }
        }
        self.yy = yy;
        self.equations += w.iter().filter(|v| **v > T::zero()).count();
        Ok(())
    }

    /// The accumulator of the columns `cols` (in that order; columns of
    /// `dim` past them are zero): weighted, or the unweighted `Λ⁰` (then
    /// `η` and `Σ Δpᵀ Δp` are zero).
    ///
    /// # Errors
    /// [`Error::Mismatch`] when `cols` does not fit in `dim`;
    /// [`Error::OutOfRange`] for a column `≥ P`.
    pub fn select<D: Dim>(
        &self,
        cols: &[usize],
        dim: D,
        weighted: bool,
    ) -> Result<Accumulator<T, D>, Error>
    where
        DefaultAllocator: Alloc<D>,
    {
        if cols.len() > dim.value() {
            return Err(Error::Mismatch {
                what: "more columns than the sub-problem's size",
            });
        }
        if let Some(&c) = cols.iter().find(|&&c| c >= P) {
            return Err(Error::OutOfRange {
                what: "column",
                index: c,
                len: P,
            });
        }
        let sums = if weighted { &self.info } else { &self.plain };
        let mut info = OMatrix::<T, D, D>::zeros_generic(dim, dim);
        let mut eta = OVector::<T, D>::zeros_generic(dim, Const::<1>);
        for (j, &cj) in cols.iter().enumerate() {
            for (i, &ci) in cols.iter().enumerate().take(j + 1) {
                info[(i, j)] = sums[packed(ci, cj)];
            }
            if weighted {
                eta[j] = self.eta[cj];
            }
        }
        let yy = if weighted { self.yy } else { T::zero() };
        Ok(Accumulator::from_sums(info, eta, yy, self.equations))
    }

    /// Whether `model` and `candidate` make a sub-problem: at most
    /// `MAX_SUB` columns, each one of the `P`.
    fn check_sub(model: &[usize], candidate: &[usize]) -> Result<(), Error> {
        if model.len() + candidate.len() > MAX_SUB {
            return Err(Error::Mismatch {
                what: "candidate does not fit in the sub-problem",
            });
        }
        if let Some(&c) = model.iter().chain(candidate).find(|&&c| c >= P) {
            return Err(Error::OutOfRange {
                what: "column",
                index: c,
                len: P,
            });
        }
        Ok(())
    }

    /// The host's test of one candidate: of its columns `candidate`, those
    /// the unweighted columns tell apart from the model's `model` and from
    /// the candidate's before them ([`super::rank`]); the nested F test of
    /// adding them to the model ([`nested_test`]) at the accumulated
    /// weights. `dim` holds the sub-problem (`model.len() + candidate.len()`
    /// columns at least; `Dyn` on the host, `Const<S>` on the device).
    ///
    /// `Ok(None)` when nothing of the candidate is left after the model or
    /// the data cannot test it (no degrees of freedom left, a column the
    /// model absorbs): the host does not count it as tried either.
    ///
    /// # Errors
    /// As [`Augmented::select`]; [`Error::Mismatch`] for more than 64
    /// candidate columns; errors of the model's solve other than those.
    #[inline(never)]
    pub fn test<D: Dim>(
        &self,
        model: &[usize],
        candidate: &[usize],
        dim: D,
    ) -> Result<Option<NestedTest>, Error>
    where
        DefaultAllocator: Alloc<D>,
    {
        let n = model.len();
        Self::check_sub(model, candidate)?;
        // The columns in one list: model, then candidate. A candidate column
        // without information (`Λ⁰ᵢᵢ ≤ ε² max Λ⁰ₖₖ`, e.g. the torque of a
        // vertical load about a vertical axis) is left out here, as the
        // independence test would (`rank::independent`, its first step):
        // the sub-problem stays the size of what can be tested.
        let Some((mut cols, q)) = self.informative(model, candidate, dim)? else {
            return Ok(None);
        };
        let mut informative = [0usize; MAX_SUB];
        informative[..q].copy_from_slice(&cols[n..n + q]);
        let candidate = &informative[..q];
        let plain = self.select(&cols[..n + q], dim, false)?;
        let all = OVector::<bool, D>::from_element_generic(dim, Const::<1>, true);
        let kept = match independent(&plain.information(), all.as_slice()) {
            Ok(kept) => kept,
            Err(_) => return Ok(None),
        };
        let mut len = 0;
        for (k, &c) in candidate.iter().enumerate() {
            if kept[n + k] {
                cols[n + len] = c;
                len += 1;
            }
        }
        if len == 0 {
            return Ok(None);
        }
        let acc = self.select(&cols[..n + len], dim, true)?;
        let mut m = OVector::<bool, D>::from_element_generic(dim, Const::<1>, false);
        let mut cm = m.clone();
        for k in 0..n {
            m[k] = true;
        }
        for k in n..n + len {
            cm[k] = true;
        }
        let fit = match acc.solve_active(m.as_slice()) {
            Ok(fit) => fit,
            Err(Error::NotIdentifiable { .. } | Error::TooFewEquations { .. }) => return Ok(None),
            Err(e) => return Err(e),
        };
        match nested_test(&acc, m.as_slice(), &fit, cm.as_slice()) {
            Ok(t) => Ok(Some(t)),
            Err(Error::NotIdentifiable { .. } | Error::TooFewEquations { .. }) => Ok(None),
            Err(e) => Err(e),
        }
    }
}

impl<T: RealField + Copy, const P: usize, const L: usize> Augmented<T, P, L> {
    /// The model's weighted fit on its columns `model` (the first
    /// `model.len()` of `dim`): what [`Augmented::test`] solves once per
    /// candidate, solved once per round for [`Augmented::test_fitted`] and
    /// the lack of fit (its `wrss`).
    ///
    /// # Errors
    /// As [`Augmented::select`] and [`Accumulator::solve_active`].
    #[inline(never)]
    pub fn solve_model<D: Dim>(&self, model: &[usize], dim: D) -> Result<Solution<T, D>, Error>
    where
        DefaultAllocator: Alloc<D>,
    {
        // `select(model, dim, true)?.solve_active(..)` without the
        // accumulator's copy: the same full `Λ`, `η` and checks.
        let n = model.len();
        if n > dim.value() {
            return Err(Error::Mismatch {
                what: "more columns than the sub-problem's size",
            });
        }
        if let Some(&c) = model.iter().find(|&&c| c >= P) {
            return Err(Error::OutOfRange {
                what: "column",
                index: c,
                len: P,
            });
        }
        if self.equations < n {
            return Err(Error::TooFewEquations {
                equations: self.equations,
                parameters: n,
            });
        }
        let lambda = OMatrix::<T, D, D>::from_fn_generic(dim, dim, |i, j| {
            if i < n && j < n {
                self.info[packed(model[i], model[j])]
            } else {
                T::zero()
            }
        });
        let eta = OVector::<T, D>::from_fn_generic(dim, Const::<1>, |i, _| {
            if i < n {
                self.eta[model[i]]
            } else {
                T::zero()
            }
        });
        let m = OVector::<bool, D>::from_fn_generic(dim, Const::<1>, |i, _| i < n);
        Solution::with_mask(&lambda, &eta, self.yy, self.equations, m)
    }

    /// [`Augmented::test`] with the model's fit `fit` given
    /// ([`Augmented::solve_model`] of the same `model` and `dim`): the lean
    /// path of a device. The sub-problem's sums are read from the packed
    /// triangles in place (no accumulator copies), the model is factored
    /// once per round instead of once per candidate, and of
    /// `S = Λ_CC − Λ_CA Λ_AA⁻¹ Λ_AC` only `S⁻¹ g` is formed (not `S⁻¹`; a
    /// non-finite `S⁻¹` with a finite `S⁻¹ g` is not refused here). Every
    /// sum is that of [`Augmented::test`] in the same order, so the result
    /// is the same bit for bit (tested).
    ///
    /// # Errors
    /// As [`Augmented::test`]; [`Error::Mismatch`] when `fit` is not a fit
    /// of `model.len()` leading columns of `dim`.
    #[inline(never)]
    pub fn test_fitted<D: Dim>(
        &self,
        model: &[usize],
        fit: &Solution<T, D>,
        candidate: &[usize],
        dim: D,
    ) -> Result<Option<NestedTest>, Error>
    where
        DefaultAllocator: Alloc<D>,
    {
        let n = model.len();
        Self::check_sub(model, candidate)?;
        if fit.active.len() != dim.value()
            || n > dim.value()
            || fit.active.iter().enumerate().any(|(k, &a)| a != (k < n))
        {
            return Err(Error::Mismatch {
                what: "fit was not solved on this model",
            });
        }
        // As `test`: the informative candidate columns, then those the
        // unweighted columns tell apart from the model's.
        let Some((mut cols, q)) = self.informative(model, candidate, dim)? else {
            return Ok(None);
        };
        let Some(kept) = self.kept(&cols[..n + q], dim) else {
            return Ok(None);
        };
        let mut len = 0;
        for k in 0..q {
            if kept[n + k] {
                cols[n + len] = cols[n + k];
                len += 1;
            }
        }
        if len == 0 {
            return Ok(None);
        }
        self.nested(&cols[..n + len], n, fit, dim)
    }

    /// The sub-problem's columns: the model's, then the candidate's that
    /// carry information (`Λ⁰ᵢᵢ > ε² max Λ⁰ₖₖ`, as the first step of
    /// `rank::independent`), and how many of the latter; `None` when none
    /// does.
    ///
    /// # Errors
    /// [`Error::Mismatch`] when they do not fit in `dim`.
    fn informative<D: Dim>(
        &self,
        model: &[usize],
        candidate: &[usize],
        dim: D,
    ) -> Result<Option<([usize; MAX_SUB], usize)>, Error> {
        let n = model.len();
        let diag = |c: usize| self.plain[packed(c, c)];
        let dmax = model
            .iter()
            .chain(candidate)
            .fold(T::zero(), |m, &c| m.max(diag(c)));
        let floor = T::default_epsilon() * T::default_epsilon() * dmax;
        let mut cols = [0usize; MAX_SUB];
        cols[..n].copy_from_slice(model);
        let mut q = 0;
        for &c in candidate {
            if diag(c) > floor && diag(c) > T::zero() {
                cols[n + q] = c;
                q += 1;
            }
        }
        if q == 0 {
            return Ok(None);
        }
        if n + q > dim.value() {
            return Err(Error::Mismatch {
                what: "candidate does not fit in the sub-problem",
            });
        }
        Ok(Some((cols, q)))
    }

    /// `rank::independent` of the unweighted sub-problem of `cols` (`None`
    /// when it refuses).
    #[inline(never)]
    fn kept<D: Dim>(&self, cols: &[usize], dim: D) -> Option<OVector<bool, D>>
    where
        DefaultAllocator: Alloc<D>,
    {
        let k = cols.len();
        let plain = OMatrix::<T, D, D>::from_fn_generic(dim, dim, |i, j| {
            if i < k && j < k {
                self.plain[packed(cols[i], cols[j])]
            } else {
                T::zero()
            }
        });
        let all = OVector::<bool, D>::from_element_generic(dim, Const::<1>, true);
        independent(&plain, all.as_slice()).ok()
    }

    /// `nested_test` of the columns `cols[n..]` after the model `cols[..n]`
    /// fitted by `fit`, on the packed sums: the rows of `Λ Λ_A⁻¹` one
    /// candidate column at a time, in `mat_mul`'s and `mat_vec`'s order.
    #[inline(never)]
    fn nested<D: Dim>(
        &self,
        cols: &[usize],
        n: usize,
        fit: &Solution<T, D>,
        dim: D,
    ) -> Result<Option<NestedTest>, Error>
    where
        DefaultAllocator: Alloc<D>,
    {
        let k = cols.len();
        let (p, q, m) = (n, k - n, self.equations);
        if m <= p + q {
            return Ok(None);
        }
        let d = dim.value();
        let lam = |i: usize, j: usize| {
            if i < k && j < k {
                self.info[packed(cols[i], cols[j])]
            } else {
                T::zero()
            }
        };
        let mut schur = OMatrix::<T, D, D>::zeros_generic(dim, dim);
        let mut g = OVector::<T, D>::zeros_generic(dim, Const::<1>);
        let mut row = OVector::<T, D>::zeros_generic(dim, Const::<1>);
        for i in n..k {
            // (Λ X̂)ᵢ and the row i of Λ Λ_A⁻¹, each sum in index order.
            let mut lx = T::zero();
            for c in 0..d {
                lx += lam(i, c) * fit.x[c];
            }
            g[i] = self.eta[cols[i]] - lx;
            for c in 0..d {
                let mut v = T::zero();
                for r in 0..d {
                    v += lam(i, r) * fit.lambda_inv[(r, c)];
                }
                row[c] = v;
            }
            for j in n..k {
                let mut v = T::zero();
                for c in 0..d {
                    v += row[c] * lam(c, j);
                }
                schur[(i, j)] = lam(i, j) - v;
            }
        }
        let tol = pivot_tolerance::<T>();
        for j in n..k {
            #[allow(clippy::neg_cmp_op_on_partial_ord)]
            if !(schur[(j, j)] > tol * lam(j, j)) {
                return Ok(None);
            }
        }
        if !g.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite {
                what: "information",
            });
        }
        let mask = OVector::<bool, D>::from_fn_generic(dim, Const::<1>, |i, _| i >= n && i < k);
        let f = match Factor::with_mask(&schur, mask) {
            Ok(f) => f,
            Err(Error::NotIdentifiable { .. } | Error::TooFewEquations { .. }) => return Ok(None),
            Err(e) => return Err(e),
        };
        let z = f.solve(&g);
        if !z.iter().all(|v| v.is_finite()) {
            return Err(Error::NonFinite { what: "estimate" });
        }
        Ok(Some(from_delta(dot(&z, &g), fit.wrss, q, m - p - q)))
    }
}
