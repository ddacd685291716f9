//! Solving the normal equations `Λ X̂ = η` and the covariances of `X̂`.
//!
//! Parameters of a calibration have very different units (compliances of
//! ~1e-6 rad/(N·m), lengths in m, angles in rad), so `Λ` is first scaled to
//! unit diagonal, `Λs = S Λ S` with `S = diag(Λ)^(-1/2)` (Jacobi scaling),
//! then factored by Cholesky, `Λs = L Lᵀ`. The pivots `dⱼ = Lⱼⱼ²` lie in
//! `[0, 1]`: `dⱼ = 1 − R²ⱼ`, where `R²ⱼ` is how well parameter `j`'s (weighted)
//! column is explained by the columns before it. A pivot below the tolerance
//! means parameter `j` is not identifiable from these data given the ones
//! before it, and the solve returns [`Error::NotIdentifiable`] naming `j`
//! instead of an estimate.
//!
//! Covariances (the paper's equation numbers):
//! - (7)  OLS with i.i.d. noise: `σ̂² Λ⁻¹`, `σ̂² = RSS / (m − n)`;
//! - (8), (11) sandwich: `Λ⁻¹ M Λ⁻¹`, `M = Bᵀ W² Σ² W² B` (with `W = I`: eq. 8);
//! - (13) `Λ⁻¹` itself, which is the covariance when `W Σ = I` (the paper
//!   prints `Σ²` in (13) where it means `Σ⁻²`).

use nalgebra::{RealField, SMatrix, SVector};

use crate::Error;

/// Which parameters are in the model: `true` = estimated, `false` = held at
/// zero.
pub type Active<const N: usize> = [bool; N];

/// A weighted least-squares estimate and what is needed for its covariances.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Solution<T: RealField + Copy, const N: usize> {
    /// `X̂ = Λ⁻¹ η` (eq. 6 / 10); zero for inactive parameters.
    pub x: SVector<T, N>,
    /// `Λ⁻¹` over the active parameters (rows and columns of inactive
    /// parameters are zero).
    pub lambda_inv: SMatrix<T, N, N>,
    /// The parameters that were estimated.
    pub active: Active<N>,
    /// Equations (rows with positive weight) behind the estimate.
    pub equations: usize,
    /// Weighted residual sum of squares `Σ (Δp − B X̂)ᵀ W² (Δp − B X̂)`,
    /// computed as `Σ Δpᵀ W² Δp − X̂ᵀ η` (clamped at 0).
    pub wrss: T,
    /// Reciprocal condition estimate of the scaled information matrix:
    /// smallest over largest Cholesky pivot, in (0, 1].
    pub rcond: T,
}

impl<T: RealField + Copy, const N: usize> Solution<T, N> {
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
    pub fn cov_iid(&self) -> SMatrix<T, N, N> {
        self.lambda_inv * self.sigma2_hat()
    }

    /// Eq. 13: `Λ⁻¹`, the covariance when the weights are `W = Σ⁻¹`.
    #[must_use]
    pub fn cov_information(&self) -> SMatrix<T, N, N> {
        self.lambda_inv
    }

    /// Eq. 8 / 11, the sandwich `Λ⁻¹ M Λ⁻¹` with
    /// `M = Bᵀ W² Σ² W² B` (e.g. [`crate::Accumulator::middle`]).
    #[must_use]
    pub fn cov_sandwich(&self, middle: &SMatrix<T, N, N>) -> SMatrix<T, N, N> {
        let c = self.lambda_inv * middle * self.lambda_inv;
        // Symmetrise what rounding left asymmetric.
        (c + c.transpose()) * nalgebra::convert::<f64, T>(0.5)
    }
}

/// Standard deviations `√diag(C)` of a covariance matrix.
#[must_use]
pub fn std_devs<T: RealField + Copy, const N: usize>(cov: &SMatrix<T, N, N>) -> SVector<T, N> {
    SVector::from_fn(|i, _| cov[(i, i)].max(T::zero()).sqrt())
}

/// Pivot tolerance on the scaled matrix: `√ε` of the scalar type
/// (1.5e-8 for f64, 3.5e-4 for f32). A parameter whose column is explained
/// to better than `1 − √ε` by the others cannot be estimated meaningfully in
/// that precision.
pub fn pivot_tolerance<T: RealField + Copy>() -> T {
    T::default_epsilon().sqrt()
}

/// Solves `Λ X = η` on the active parameters. `lambda` must be the full
/// symmetric matrix; `yy = Σ Δpᵀ W² Δp`; `equations` the number of rows.
///
/// # Errors
/// [`Error::NotIdentifiable`] (see the [module docs](self)), or
/// [`Error::NonFinite`] when the input or the result is not finite.
pub fn solve<T: RealField + Copy, const N: usize>(
    lambda: &SMatrix<T, N, N>,
    eta: &SVector<T, N>,
    yy: T,
    equations: usize,
    active: &Active<N>,
) -> Result<Solution<T, N>, Error> {
    if !(lambda.iter().all(|v| v.is_finite()) && eta.iter().all(|v| v.is_finite())) {
        return Err(Error::NonFinite {
            what: "information",
        });
    }
    // Scale to unit diagonal; inactive parameters become decoupled unit rows.
    let mut s = SVector::<T, N>::repeat(T::one());
    for i in 0..N {
        if active[i] {
            let d = lambda[(i, i)];
            if d <= T::zero() {
                return Err(Error::NotIdentifiable {
                    column: i,
                    rcond: 0.0,
                });
            }
            s[i] = T::one() / d.sqrt();
        }
    }
    let mut a = SMatrix::<T, N, N>::identity();
    let mut rhs = SVector::<T, N>::zeros();
    for j in 0..N {
        if !active[j] {
            continue;
        }
        rhs[j] = eta[j] * s[j];
        for i in 0..N {
            if active[i] {
                a[(i, j)] = lambda[(i, j)] * s[i] * s[j];
            }
        }
    }
    let tol = pivot_tolerance::<T>();
    let (l, dmin, dmax) = cholesky_checked(&a, tol)?;

    // X̂s = Λs⁻¹ (S η), then X̂ = S X̂s.
    let y = solve_lower(&l, &rhs);
    let xs = solve_upper_t(&l, &y);
    let x = xs.component_mul(&s);

    // Λ⁻¹ = S Λs⁻¹ S with Λs⁻¹ = L⁻ᵀ L⁻¹.
    let mut linv = SMatrix::<T, N, N>::zeros();
    for k in 0..N {
        let mut e = SVector::<T, N>::zeros();
        e[k] = T::one();
        linv.set_column(k, &solve_lower(&l, &e));
    }
    let mut inv = linv.transpose() * linv;
    // Scale the upper triangle and mirror it: `(v·sᵢ)·sⱼ` and `(v·sⱼ)·sᵢ`
    // round differently, and Λ⁻¹ (the eq. 13 covariance) must be exactly
    // symmetric. (Not `v·(sᵢ·sⱼ)`: that product can overflow where the
    // result does not.)
    for j in 0..N {
        for i in 0..=j {
            let v = if active[i] && active[j] {
                inv[(i, j)] * s[i] * s[j]
            } else {
                T::zero()
            };
            inv[(i, j)] = v;
            inv[(j, i)] = v;
        }
    }
    let x: SVector<T, N> = SVector::from_fn(|i, _| if active[i] { x[i] } else { T::zero() });
    if !(x.iter().all(|v| v.is_finite()) && inv.iter().all(|v| v.is_finite())) {
        return Err(Error::NonFinite { what: "estimate" });
    }
    let wrss = (yy - x.dot(eta)).max(T::zero());
    Ok(Solution {
        x,
        lambda_inv: inv,
        active: *active,
        equations,
        wrss,
        rcond: dmin / dmax,
    })
}

/// Cholesky `A = L Lᵀ` of a unit-diagonal symmetric matrix, refusing a
/// pivot `dⱼ ≤ tol`. Returns `L` and the smallest and largest pivot.
pub(crate) fn cholesky_checked<T: RealField + Copy, const N: usize>(
    a: &SMatrix<T, N, N>,
    tol: T,
) -> Result<(SMatrix<T, N, N>, T, T), Error> {
    let mut l = SMatrix::<T, N, N>::zeros();
    let mut dmin = T::one();
    let mut dmax = T::zero();
    for j in 0..N {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
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
        l[(j, j)] = ljj;
        for i in (j + 1)..N {
            let mut v = a[(i, j)];
            for k in 0..j {
                v -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = v / ljj;
        }
    }
    Ok((l, dmin, dmax))
}

/// Forward substitution `L y = b`.
pub(crate) fn solve_lower<T: RealField + Copy, const N: usize>(
    l: &SMatrix<T, N, N>,
    b: &SVector<T, N>,
) -> SVector<T, N> {
    let mut y = *b;
    for i in 0..N {
        let mut v = y[i];
        for k in 0..i {
            v -= l[(i, k)] * y[k];
        }
        y[i] = v / l[(i, i)];
    }
    y
}

/// Back substitution `Lᵀ x = y`.
pub(crate) fn solve_upper_t<T: RealField + Copy, const N: usize>(
    l: &SMatrix<T, N, N>,
    y: &SVector<T, N>,
) -> SVector<T, N> {
    let mut x = *y;
    for i in (0..N).rev() {
        let mut v = x[i];
        for k in (i + 1)..N {
            v -= l[(k, i)] * x[k];
        }
        x[i] = v / l[(i, i)];
    }
    x
}
