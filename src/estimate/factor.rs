//! Solving the normal equations `Λ X̂ = η` and the covariances of `X̂`.
//!
//! Parameters of a calibration have very different units (compliances of
//! ~1e-6 rad/(N·m), lengths in m, angles in rad), so `Λ` is first scaled to
//! unit diagonal, `Λs = S Λ S` with `S = diag(Λ)^(-1/2)` (Jacobi scaling),
//! then factored by Cholesky, `Λs = L Lᵀ` ([`Factor`]). The pivots
//! `dⱼ = Lⱼⱼ²` lie in `[0, 1]`: `dⱼ = 1 − R²ⱼ`, where `R²ⱼ` is how well
//! parameter `j`'s (weighted) column is explained by the columns before it.
//! A pivot below [`pivot_tolerance`] means parameter `j` is not
//! identifiable from these data given the ones before it, and the
//! factorisation returns [`Error::NotIdentifiable`] naming `j` instead of an
//! estimate. (A model is reduced to an identifiable set before it is solved,
//! [`super::rank`], with a wider margin: the refusal here is the last guard
//! of the arithmetic.)
//!
//! Covariances (the paper's equation numbers), from a [`Solution`]:
//! - (7)  OLS with i.i.d. noise: `σ̂² Λ⁻¹`, `σ̂² = RSS / (m − n)`;
//! - (8), (11) sandwich: `Λ⁻¹ M Λ⁻¹`, `M = Bᵀ W² Σ² W² B` (with `W = I`: eq. 8);
//! - (13) `Λ⁻¹` itself, which is the covariance when `W Σ = I` (the paper
//!   prints `Σ²` in (13) where it means `Σ⁻²`).

use super::linalg::{dot, mat_mul};
use super::Alloc;
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector, RealField};

use crate::error::Error;

/// Pivot tolerance on the scaled matrix: `√ε` of the scalar type
/// (1.5e-8 for f64, 3.5e-4 for f32). A parameter whose column is explained
/// to better than `1 − √ε` by the others cannot be estimated meaningfully in
/// that precision.
pub fn pivot_tolerance<T: RealField + Copy>() -> T {
    T::default_epsilon().sqrt()
}

/// The Cholesky factorisation of the column-scaled information matrix on a
/// set of active parameters: a value to ask for solutions, the inverse and
/// the conditioning. See the [module docs](self).
///
/// ```
/// use nalgebra::{Matrix2, Vector2};
/// use robcal::estimate::Factor;
///
/// let lambda = Matrix2::new(4.0, 2.0, 2.0, 3.0);
/// let f = Factor::new(&lambda, &[true, true]).unwrap();
/// let x = f.solve(&Vector2::new(2.0, 1.0));
/// assert!((lambda * x - Vector2::new(2.0, 1.0)).norm() < 1e-14);
/// assert!((f.inverse() * lambda - Matrix2::identity()).norm() < 1e-14);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Factor<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    /// `L` of `Λs = L Lᵀ`; identity rows and columns for inactive parameters.
    l: OMatrix<T, D, D>,
    /// `S = diag(Λ)^(-1/2)` on the active parameters, 1 elsewhere.
    scale: OVector<T, D>,
    /// The factored parameters.
    active: OVector<bool, D>,
    /// Smallest and largest pivot of the active parameters.
    pivots: (T, T),
}

/// `L` row by row, `S` and the active flags as lists (not nalgebra's
/// internals).
#[cfg(feature = "defmt")]
impl<T: RealField + Copy + defmt::Format, D: Dim> defmt::Format for Factor<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn format(&self, f: defmt::Formatter<'_>) {
        use super::fmt::rows;
        defmt::write!(
            f,
            "Factor {{ l: {}, scale: {}, active: {}, pivots: {} }}",
            rows(&self.l),
            rows(&self.scale),
            rows(&self.active),
            self.pivots
        )
    }
}

impl<T: RealField + Copy, D: Dim> Factor<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    /// Scales `lambda` (the full symmetric `Λ`) to unit diagonal on the
    /// parameters marked in `active` and factors it.
    ///
    /// # Errors
    /// [`Error::Mismatch`] when `active` has not one flag per row of `Λ`;
    /// [`Error::NonFinite`] for a non-finite `Λ`; [`Error::NotIdentifiable`]
    /// naming the first active parameter whose pivot is at or below
    /// [`pivot_tolerance`].
    pub fn new(lambda: &OMatrix<T, D, D>, active: &[bool]) -> Result<Self, Error> {
        if active.len() != lambda.nrows() {
            return Err(Error::Mismatch {
                what: "one active flag per parameter",
            });
        }
        let dim = lambda.shape_generic().0;
        Self::with_mask(
            lambda,
            OVector::from_iterator_generic(dim, Const::<1>, active.iter().copied()),
        )
    }

    /// [`Factor::new`] with the flags as a vector.
    ///
    /// # Errors
    /// As [`Factor::new`].
    pub(crate) fn with_mask(
        lambda: &OMatrix<T, D, D>,
        active: OVector<bool, D>,
    ) -> Result<Self, Error> {
        let n = lambda.nrows();
        if !all_finite(lambda.as_slice()) {
            return Err(Error::NonFinite {
                what: "information",
            });
        }
        let dim = lambda.shape_generic().0;
        let mut scale = OVector::<T, D>::from_element_generic(dim, Const::<1>, T::one());
        for i in 0..n {
            if active[i] {
                let d = lambda[(i, i)];
                if d <= T::zero() {
                    return Err(Error::NotIdentifiable {
                        column: i,
                        rcond: 0.0,
                    });
                }
                scale[i] = T::one() / d.sqrt();
            }
        }
        // Inactive parameters become decoupled unit rows.
        let mut l = OMatrix::<T, D, D>::identity_generic(dim, dim);
        for j in 0..n {
            if !active[j] {
                continue;
            }
            for i in 0..n {
                if active[i] {
                    l[(i, j)] = lambda[(i, j)] * scale[i] * scale[j];
                }
            }
        }
        let pivots = cholesky_in_place(&mut l, pivot_tolerance())?;
        Ok(Self {
            l,
            scale,
            active,
            pivots,
        })
    }

    /// The number of parameters (active or not).
    pub fn parameters(&self) -> usize {
        self.scale.len()
    }

    /// Which parameters were factored.
    pub fn active(&self) -> &[bool] {
        self.active.as_slice()
    }

    /// Smallest over largest pivot of the scaled matrix, in (0, 1]: a
    /// reciprocal condition estimate (`≈ 1/cond(equilibrated WB)²`).
    pub fn rcond(&self) -> T {
        self.pivots.0 / self.pivots.1
    }

    /// `Λ⁻¹ r` on the active parameters (zero elsewhere; entries of `r` of
    /// inactive parameters are ignored).
    #[must_use]
    pub fn solve(&self, r: &OVector<T, D>) -> OVector<T, D> {
        // Inactive parameters are decoupled unit rows of `L`: whatever `r`
        // holds for them stays out of the others, and is masked below.
        let mut x = r.component_mul(&self.scale);
        solve_lower_in_place(&self.l, &mut x);
        solve_upper_t_in_place(&self.l, &mut x);
        let mut x = x.component_mul(&self.scale);
        self.mask(&mut x);
        x
    }

    /// `Λ⁻¹` over the active parameters (rows and columns of inactive ones
    /// are zero), exactly symmetric.
    #[must_use]
    #[inline(never)]
    pub fn inverse(&self) -> OMatrix<T, D, D> {
        let n = self.parameters();
        let dim = self.l.shape_generic().0;
        // L⁻¹ column by column (lower triangular: column k starts at row k),
        // then Λs⁻¹ = L⁻ᵀ L⁻¹ on the upper triangle, every sum in index
        // order in robcal's own loops: the same arithmetic at every size
        // (`Const<N>` on a device, `Dyn` on the host), bit for bit.
        let mut linv = OMatrix::<T, D, D>::zeros_generic(dim, dim);
        for k in 0..n {
            linv[(k, k)] = T::one() / self.l[(k, k)];
            for i in (k + 1)..n {
                let mut v = T::zero();
                for m in k..i {
                    v -= self.l[(i, m)] * linv[(m, k)];
                }
                linv[(i, k)] = v / self.l[(i, i)];
            }
        }
        let mut inv = OMatrix::<T, D, D>::zeros_generic(dim, dim);
        for j in 0..n {
            for i in 0..=j {
                let mut v = T::zero();
                for k in j..n {
                    v += linv[(k, i)] * linv[(k, j)];
                }
                inv[(i, j)] = v;
            }
        }
        // Scale the upper triangle and mirror it: `(v·sᵢ)·sⱼ` and `(v·sⱼ)·sᵢ`
        // round differently, and Λ⁻¹ (the eq. 13 covariance) must be exactly
        // symmetric. (Not `v·(sᵢ·sⱼ)`: that product can overflow where the
        // result does not.)
        for j in 0..n {
            for i in 0..=j {
                let v = if self.active[i] && self.active[j] {
                    inv[(i, j)] * self.scale[i] * self.scale[j]
                } else {
                    T::zero()
                };
                inv[(i, j)] = v;
                inv[(j, i)] = v;
            }
        }
        inv
    }

    /// `L⁻¹ S b` on the active parameters (zero elsewhere): a row `b` of
    /// `B` whitened by `Λ`, so that `b Λ⁻¹ cᵀ` is the dot product of the
    /// two whitened rows (the determinant lemma of [`super::plan`]).
    #[must_use]
    pub fn whiten(&self, b: &OVector<T, D>) -> OVector<T, D> {
        let mut x = b.component_mul(&self.scale);
        self.mask(&mut x);
        solve_lower_in_place(&self.l, &mut x);
        self.mask(&mut x);
        x
    }

    /// `ln det Λ` over the active parameters: `Σ ln Lⱼⱼ² − 2 Σ ln Sⱼ`.
    #[must_use]
    pub fn log_det(&self) -> T {
        let mut v = T::zero();
        for j in 0..self.parameters() {
            if self.active[j] {
                let d = self.l[(j, j)];
                v += (d * d).ln() - (self.scale[j] * self.scale[j]).ln();
            }
        }
        v
    }

    fn mask(&self, x: &mut OVector<T, D>) {
        for (v, &a) in x.as_mut_slice().iter_mut().zip(self.active.as_slice()) {
            if !a {
                *v = T::zero();
            }
        }
    }
}

/// A weighted least-squares estimate and what is needed for its covariances.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    /// `X̂ = Λ⁻¹ η` (eq. 6 / 10); zero for inactive parameters.
    pub x: OVector<T, D>,
    /// `Λ⁻¹` over the active parameters (rows and columns of inactive
    /// parameters are zero).
    pub lambda_inv: OMatrix<T, D, D>,
    /// The parameters that were estimated.
    pub active: OVector<bool, D>,
    /// Equations (rows with positive weight) behind the estimate.
    pub equations: usize,
    /// Weighted residual sum of squares `Σ (Δp − B X̂)ᵀ W² (Δp − B X̂)`,
    /// computed as `Σ Δpᵀ W² Δp − X̂ᵀ η` (clamped at 0).
    pub wrss: T,
    /// Reciprocal condition estimate of the scaled information matrix:
    /// smallest over largest Cholesky pivot, in (0, 1].
    pub rcond: T,
}

/// `X̂` and the active flags as lists, `Λ⁻¹` row by row (not nalgebra's
/// internals).
#[cfg(feature = "defmt")]
impl<T: RealField + Copy + defmt::Format, D: Dim> defmt::Format for Solution<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn format(&self, f: defmt::Formatter<'_>) {
        use super::fmt::rows;
        defmt::write!(
            f,
            "Solution {{ x: {}, lambda_inv: {}, active: {}, equations: {=usize}, wrss: {}, rcond: {} }}",
            rows(&self.x),
            rows(&self.lambda_inv),
            rows(&self.active),
            self.equations,
            self.wrss,
            self.rcond
        )
    }
}

impl<T: RealField + Copy, D: Dim> Solution<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    /// Solves `Λ X = η` on the active parameters. `lambda` must be the full
    /// symmetric matrix; `yy = Σ Δpᵀ W² Δp`; `equations` the number of rows.
    ///
    /// # Errors
    /// As [`Factor::new`]; [`Error::Mismatch`] when `η` has another length;
    /// [`Error::NonFinite`] when the input or the result is not finite.
    pub fn new(
        lambda: &OMatrix<T, D, D>,
        eta: &OVector<T, D>,
        yy: T,
        equations: usize,
        active: &[bool],
    ) -> Result<Self, Error> {
        if active.len() != lambda.nrows() {
            return Err(Error::Mismatch {
                what: "one active flag per parameter",
            });
        }
        let dim = lambda.shape_generic().0;
        let mask = OVector::from_iterator_generic(dim, Const::<1>, active.iter().copied());
        Self::with_mask(lambda, eta, yy, equations, mask)
    }

    /// [`Solution::new`] with the flags as a vector.
    ///
    /// # Errors
    /// As [`Solution::new`].
    pub(crate) fn with_mask(
        lambda: &OMatrix<T, D, D>,
        eta: &OVector<T, D>,
        yy: T,
        equations: usize,
        active: OVector<bool, D>,
    ) -> Result<Self, Error> {
        if eta.len() != lambda.nrows() {
            return Err(Error::Mismatch {
                what: "one eta per parameter",
            });
        }
        if !all_finite(eta.as_slice()) {
            return Err(Error::NonFinite {
                what: "information",
            });
        }
        // By reference: a `?` would copy the factor out of its result.
        let factored = Factor::with_mask(lambda, active);
        let f = match &factored {
            Ok(f) => f,
            Err(e) => return Err(*e),
        };
        let x = f.solve(eta);
        let inv = f.inverse();
        if !(all_finite(x.as_slice()) && all_finite(inv.as_slice())) {
            return Err(Error::NonFinite { what: "estimate" });
        }
        let wrss = (yy - dot(&x, eta)).max(T::zero());
        Ok(Self {
            x,
            lambda_inv: inv,
            active: f.active.clone(),
            equations,
            wrss,
            rcond: f.pivots.0 / f.pivots.1,
        })
    }

    /// Number of estimated parameters.
    pub fn parameters(&self) -> usize {
        self.active.iter().filter(|a| **a).count()
    }

    /// `σ̂² = RSS / (m − n)`: the residual variance of an (unit-weight) OLS
    /// fit, 0 when there are no degrees of freedom left.
    pub fn sigma2_hat(&self) -> T {
        let dof = self.equations.saturating_sub(self.parameters());
        if dof == 0 {
            return T::zero();
        }
        self.wrss / nalgebra::convert::<f64, T>(dof as f64)
    }

    /// Eq. 7: `σ̂² Λ⁻¹`, the covariance under i.i.d. noise of unknown σ.
    #[must_use]
    pub fn cov_iid(&self) -> OMatrix<T, D, D> {
        &self.lambda_inv * self.sigma2_hat()
    }

    /// Eq. 13: `Λ⁻¹`, the covariance when the weights are `W = Σ⁻¹`.
    #[must_use]
    pub fn cov_information(&self) -> OMatrix<T, D, D> {
        self.lambda_inv.clone()
    }

    /// Eq. 8 / 11, the sandwich `Λ⁻¹ M Λ⁻¹` with
    /// `M = Bᵀ W² Σ² W² B` (e.g. [`super::Accumulator::middle`]).
    #[must_use]
    #[inline(never)]
    pub fn cov_sandwich(&self, middle: &OMatrix<T, D, D>) -> OMatrix<T, D, D> {
        let c = mat_mul(&mat_mul(&self.lambda_inv, middle), &self.lambda_inv);
        // Symmetrise what rounding left asymmetric.
        (&c + c.transpose()) * nalgebra::convert::<f64, T>(0.5)
    }
}

impl<T: RealField + Copy, D: Dim> Solution<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    /// [`std_devs`] of [`Solution::cov_sandwich`]`(middle)`, bit for bit,
    /// without the rest of the covariance: `Λ⁻¹ M` in full (every row is
    /// needed), then only the diagonal of its product with `Λ⁻¹`, each
    /// element summed in index order from +0 as [`mat_mul`] does, and
    /// symmetrised as `cov_sandwich` does (`(c + c) · ½`). The iterations
    /// of [`super::Reweightable::fit_irls`] that are not the last need
    /// nothing else.
    #[must_use]
    #[inline(never)]
    pub(crate) fn sandwich_std(&self, middle: &OMatrix<T, D, D>) -> OVector<T, D> {
        let p = mat_mul(&self.lambda_inv, middle);
        let n = p.nrows().max(1);
        let half = nalgebra::convert::<f64, T>(0.5);
        let mut std = OVector::<T, D>::zeros_generic(p.shape_generic().0, Const::<1>);
        // Column `i` of `Λ⁻¹` gives `cᵢᵢ = Σₖ pᵢₖ Λ⁻¹ₖᵢ`.
        let cols = self.lambda_inv.as_slice().chunks_exact(n);
        for (i, (s, inv_col)) in std.as_mut_slice().iter_mut().zip(cols).enumerate() {
            let mut c = T::zero();
            for (k, &v) in inv_col.iter().enumerate() {
                c += p[(i, k)] * v;
            }
            *s = ((c + c) * half).max(T::zero()).sqrt();
        }
        std
    }
}

/// Whether every value is finite. On the host as `v · 0 = 0` (a
/// floating-point compare; `is_finite` compares the bits as a 64-bit
/// integer, which SSE2 does not have), over all of them without an early
/// exit: the compiler does two at a time. On a device (no `std`) as
/// `is_finite` with an early exit: with soft floats the product is a call
/// per value, and the fold's code did not fit the Cortex-M3's 64 KiB
/// flash. The same verdict either way (`∞ · 0` and `NaN · 0` are NaN).
#[cfg(feature = "std")]
fn all_finite<T: RealField + Copy>(v: &[T]) -> bool {
    let zero = T::zero();
    v.iter().fold(true, |ok, &v| ok & (v * zero == zero))
}

/// [`all_finite`] on a device: see the host's.
#[cfg(not(feature = "std"))]
fn all_finite<T: RealField + Copy>(v: &[T]) -> bool {
    v.iter().all(|v| v.is_finite())
}

/// Standard deviations `√diag(C)` of a covariance matrix.
#[must_use]
pub fn std_devs<T: RealField + Copy, D: Dim>(cov: &OMatrix<T, D, D>) -> OVector<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    cov.map_diagonal(|v| v.max(T::zero()).sqrt())
}

/// Cholesky `A = L Lᵀ` of a unit-diagonal symmetric matrix, in place: the
/// lower triangle of `a` becomes `L` (the strict upper triangle is left as
/// it was and is never read), refusing a pivot `dⱼ ≤ tol`. Returns the
/// smallest and largest pivot.
pub(crate) fn cholesky_in_place<T: RealField + Copy, D: Dim>(
    a: &mut OMatrix<T, D, D>,
    tol: T,
) -> Result<(T, T), Error>
where
    DefaultAllocator: Alloc<D>,
{
    let n = a.nrows();
    let mut dmin = T::one();
    let mut dmax = T::zero();
    for j in 0..n {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= a[(j, k)] * a[(j, k)];
        }
        if !d.is_finite() || d <= tol {
            let rcond = if dmax > T::zero() {
                d.max(T::zero()) / dmax
            } else {
                T::zero()
            };
            return Err(Error::NotIdentifiable {
                column: j,
                rcond: nalgebra::try_convert::<T, f64>(rcond).unwrap_or(0.0),
            });
        }
        dmin = dmin.min(d);
        dmax = dmax.max(d);
        let ljj = d.sqrt();
        a[(j, j)] = ljj;
        for i in (j + 1)..n {
            let mut v = a[(i, j)];
            for k in 0..j {
                v -= a[(i, k)] * a[(j, k)];
            }
            a[(i, j)] = v / ljj;
        }
    }
    Ok((dmin, dmax))
}

/// Forward substitution `L y = b`, in place.
pub(crate) fn solve_lower_in_place<T: RealField + Copy, D: Dim>(
    l: &OMatrix<T, D, D>,
    y: &mut OVector<T, D>,
) where
    DefaultAllocator: Alloc<D>,
{
    for i in 0..y.len() {
        let mut v = y[i];
        for k in 0..i {
            v -= l[(i, k)] * y[k];
        }
        y[i] = v / l[(i, i)];
    }
}

/// Back substitution `Lᵀ x = y`, in place.
pub(crate) fn solve_upper_t_in_place<T: RealField + Copy, D: Dim>(
    l: &OMatrix<T, D, D>,
    x: &mut OVector<T, D>,
) where
    DefaultAllocator: Alloc<D>,
{
    for i in (0..x.len()).rev() {
        let mut v = x[i];
        for k in (i + 1)..x.len() {
            v -= l[(k, i)] * x[k];
        }
        x[i] = v / l[(i, i)];
    }
}
