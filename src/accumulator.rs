//! The streaming weighted-least-squares accumulator.
//!
//! Each measurement contributes a block of up to three identification
//! equations `Δp = B X` (eq. 4) — the x, y and z rows of one marker — with a
//! weight per row. The accumulator keeps the sufficient statistics of the
//! weighted problem (eq. 9):
//!
//! - `Λ = Σ Bᵀ W² B`, the information matrix (eq. 10), `N × N`, symmetric;
//! - `η = Σ Bᵀ W² Δp` (eq. 10);
//! - `Σ Δpᵀ W² Δp`, for the residual sum of squares `Σ Δpᵀ W² Δp − X̂ᵀ η`;
//! - optionally `M = Σ Bᵀ W² Σ² W² B`, the middle of the sandwich covariance
//!   (eq. 8, 11), when the σ of a row is known.
//!
//! An update costs `O(N²)` per row and touches only the upper triangle of the
//! symmetric matrices; memory is fixed and does not grow with the number of
//! measurements. With `W = I` the same statistics give ordinary least squares
//! (eq. 6, 7).
//!
//! ```
//! use nalgebra::{Matrix3x2, Vector3};
//! use robcal::{Accumulator, Block};
//!
//! // Two parameters, two measurements of three rows each.
//! let mut acc = Accumulator::<f64, 2>::new();
//! let b = Matrix3x2::new(1.0, 0.0, 0.0, 1.0, 1.0, 1.0);
//! let x_true = nalgebra::Vector2::new(0.5, -2.0);
//! acc.update(&Block::new(b, b * x_true)).unwrap();
//! acc.update(&Block::new(2.0 * b, 2.0 * b * x_true)).unwrap();
//! let sol = acc.solve().unwrap();
//! assert!((sol.x - x_true).norm() < 1e-12);
//! ```

use nalgebra::{RealField, SMatrix, SVector, Vector3};

use crate::solve::{self, Active, Solution};
use crate::Error;

/// One measurement: up to three rows of `Δp = B X` with their weights.
///
/// Rows are the x, y, z components of a marker displacement or position, in
/// metres; `B` in metres per unit of each parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Block<T: RealField + Copy, const N: usize> {
    /// `B`: one row per equation (x, y, z).
    pub b: SMatrix<T, 3, N>,
    /// `Δp` \[m\]: the measured left-hand side.
    pub dp: Vector3<T>,
    /// `w` per row (eq. 9): finite, ≥ 0. A zero weight drops the row.
    pub w: Vector3<T>,
    /// σ per row \[m\], when known: adds `w⁴σ² bbᵀ` to the sandwich middle
    /// term `M` (eq. 11). Finite, > 0.
    pub sigma: Option<Vector3<T>>,
    /// How many of the three rows are used (1..=3); rows past it are ignored.
    pub rows: usize,
}

impl<T: RealField + Copy, const N: usize> Block<T, N> {
    /// Three rows with unit weights and no σ.
    pub fn new(b: SMatrix<T, 3, N>, dp: Vector3<T>) -> Self {
        Self {
            b,
            dp,
            w: Vector3::repeat(T::one()),
            sigma: None,
            rows: 3,
        }
    }

    /// The same block with weights `w` per row (eq. 9).
    #[must_use]
    pub fn with_weights(mut self, w: Vector3<T>) -> Self {
        self.w = w;
        self
    }

    /// The same block with a known σ per row \[m\] (for eq. 8 / 11).
    #[must_use]
    pub fn with_sigma(mut self, sigma: Vector3<T>) -> Self {
        self.sigma = Some(sigma);
        self
    }

    /// Checks every value the update reads: finite `B`, `Δp`, weights ≥ 0,
    /// σ > 0, `1 ≤ rows ≤ 3`.
    ///
    /// # Errors
    /// The first problem found.
    pub fn validate(&self) -> Result<(), Error> {
        if self.rows == 0 || self.rows > 3 {
            return Err(Error::OutOfRange {
                what: "block rows",
                index: self.rows,
                len: 4,
            });
        }
        for r in 0..self.rows {
            if !self.b.row(r).iter().all(|v| v.is_finite()) {
                return Err(Error::NonFinite { what: "row" });
            }
            if !self.dp[r].is_finite() {
                return Err(Error::NonFinite { what: "dp" });
            }
            if !self.w[r].is_finite() {
                return Err(Error::NonFinite { what: "weight" });
            }
            if self.w[r] < T::zero() {
                return Err(Error::NotPositive { what: "weight" });
            }
            if let Some(s) = self.sigma {
                if !s[r].is_finite() {
                    return Err(Error::NonFinite { what: "sigma" });
                }
                if s[r] <= T::zero() {
                    return Err(Error::NotPositive { what: "sigma" });
                }
            }
        }
        Ok(())
    }
}

/// Sufficient statistics of a weighted least-squares problem with `N`
/// parameters. See the [module docs](self).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Accumulator<T: RealField + Copy, const N: usize> {
    /// `Λ = Σ Bᵀ W² B`; only the upper triangle (row ≤ column) is kept.
    info: SMatrix<T, N, N>,
    /// `η = Σ Bᵀ W² Δp`.
    eta: SVector<T, N>,
    /// `Σ Δpᵀ W² Δp`.
    yy: T,
    /// `M = Σ Bᵀ W² Σ² W² B`, upper triangle, from rows with a known σ.
    middle: SMatrix<T, N, N>,
    /// Rows with a positive weight.
    equations: usize,
    /// Rows with a positive weight that carried a σ.
    sigma_rows: usize,
}

impl<T: RealField + Copy, const N: usize> Default for Accumulator<T, N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: RealField + Copy, const N: usize> Accumulator<T, N> {
    /// An empty accumulator.
    pub fn new() -> Self {
        Self {
            info: SMatrix::zeros(),
            eta: SVector::zeros(),
            yy: T::zero(),
            middle: SMatrix::zeros(),
            equations: 0,
            sigma_rows: 0,
        }
    }

    /// Forgets every measurement.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Adds one measurement block: `Λ += Bᵀ W² B`, `η += Bᵀ W² Δp`, and, when
    /// the block carries σ, `M += Bᵀ W² Σ² W² B`.
    ///
    /// # Errors
    /// - whatever [`Block::validate`] finds;
    /// - [`Error::NonFinite`] with `what = "overflow"` when the sums would
    ///   overflow (checked on the diagonal, which bounds every off-diagonal
    ///   element of a sum of positive semi-definite terms).
    ///
    /// The accumulator is unchanged on error.
    // `!(w >= 0)` is meant: it is true for NaN, which `w < 0` is not.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn update(&mut self, block: &Block<T, N>) -> Result<(), Error> {
        let rows = block.rows;
        if rows == 0 || rows > 3 {
            return block.validate();
        }
        // Cheap screening of the values whose problems the sums below cannot
        // show (negative weight, σ ≤ 0); everything non-finite shows up as a
        // non-finite new diagonal, η or Σ Δpᵀ W² Δp (every b, Δp and w enters
        // one of them, also with w = 0: 0·∞ = NaN). Any failure takes the
        // slow path, `validate`, for the precise error.
        let zero = T::zero();
        let mut w2 = [zero; 3];
        let mut s2 = [zero; 3];
        let mut eqs = 0;
        for r in 0..rows {
            let w = block.w[r];
            if !(w >= zero) {
                return block.validate();
            }
            w2[r] = w * w;
            eqs += usize::from(w2[r] > zero);
            if let Some(s) = block.sigma {
                if !(s[r] > zero) {
                    return block.validate();
                }
                s2[r] = w2[r] * w2[r] * s[r] * s[r];
            }
        }
        // Rows past `rows` are not read: with fewer than three rows, work on
        // a copy with them zeroed (their weight is already 0).
        let masked;
        let (b, dp) = if rows == 3 {
            (&block.b, block.dp)
        } else {
            masked =
                SMatrix::<T, 3, N>::from_fn(|r, j| if r < rows { block.b[(r, j)] } else { zero });
            (
                &masked,
                Vector3::from_fn(|r, _| if r < rows { block.dp[r] } else { zero }),
            )
        };
        // The new diagonal of Λ (and M), η and Σ Δpᵀ W² Δp, not yet stored.
        // `t` collects x·0 over them: NaN iff one is not finite (one
        // multiply-add per value instead of a compare and a branch).
        let new_yy =
            ((self.yy + w2[0] * dp[0] * dp[0]) + w2[1] * dp[1] * dp[1]) + w2[2] * dp[2] * dp[2];
        let mut t = new_yy * zero;
        let mut diag = [zero; N];
        let mut eta = SVector::<T, N>::zeros();
        let mut mdiag = [zero; N];
        let sigma = block.sigma.is_some();
        for j in 0..N {
            let (b0, b1, b2) = (b[(0, j)], b[(1, j)], b[(2, j)]);
            diag[j] = fma3(self.info[(j, j)], &w2, b0, b1, b2, b0, b1, b2);
            eta[j] = fma3(self.eta[j], &w2, b0, b1, b2, dp[0], dp[1], dp[2]);
            t += diag[j] * zero;
            t += eta[j] * zero;
            if sigma {
                mdiag[j] = fma3(self.middle[(j, j)], &s2, b0, b1, b2, b0, b1, b2);
                t += mdiag[j] * zero;
            }
        }
        if !t.is_finite() {
            block.validate()?;
            return Err(Error::NonFinite { what: "overflow" });
        }
        // Commit: the strictly upper triangle, then the checked diagonal and η.
        add_strict_upper3(&mut self.info, &w2, b);
        if sigma {
            add_strict_upper3(&mut self.middle, &s2, b);
            self.sigma_rows += eqs;
        }
        self.eta = eta;
        for j in 0..N {
            self.info[(j, j)] = diag[j];
            if sigma {
                self.middle[(j, j)] = mdiag[j];
            }
        }
        self.yy = new_yy;
        self.equations += eqs;
        Ok(())
    }

    /// Adds the statistics of `other` (measurements taken elsewhere, e.g. on
    /// another core): the result equals feeding both streams to one
    /// accumulator, up to rounding.
    ///
    /// # Errors
    /// [`Error::NonFinite`] (`"overflow"`) when a sum would overflow; `self`
    /// is unchanged on error.
    pub fn merge(&mut self, other: &Self) -> Result<(), Error> {
        let yy = self.yy + other.yy;
        let ok = yy.is_finite()
            && (0..N).all(|i| {
                (self.info[(i, i)] + other.info[(i, i)]).is_finite()
                    && (self.middle[(i, i)] + other.middle[(i, i)]).is_finite()
                    && (self.eta[i] + other.eta[i]).is_finite()
            });
        if !ok {
            return Err(Error::NonFinite { what: "overflow" });
        }
        self.info += other.info;
        self.middle += other.middle;
        self.eta += other.eta;
        self.yy = yy;
        self.equations += other.equations;
        self.sigma_rows += other.sigma_rows;
        Ok(())
    }

    /// Adds the moments of `n` rows that all carry the same weight `w`:
    /// `Λ += w² S`, `η += w² u`, `Σ Δpᵀ W² Δp += w² yy`, and, with `σ`,
    /// `M += w⁴ σ² S`. `s_upper` is `S = Σ b bᵀ` (upper triangle), `u = Σ b y`,
    /// `yy = Σ y²`. Used by [`crate::grouped`] to re-weight without raw data.
    pub(crate) fn add_moments(
        &mut self,
        s_upper: &SMatrix<T, N, N>,
        u: &SVector<T, N>,
        yy: T,
        n: usize,
        w: T,
        sigma: Option<T>,
    ) -> Result<(), Error> {
        if !w.is_finite() || sigma.is_some_and(|s| !s.is_finite()) {
            return Err(Error::NonFinite { what: "weight" });
        }
        if w < T::zero() {
            return Err(Error::NotPositive { what: "weight" });
        }
        let w2 = w * w;
        if n == 0 || w2 == T::zero() {
            return Ok(());
        }
        let m2 = sigma.map(|s| w2 * w2 * s * s);
        let new_yy = self.yy + w2 * yy;
        let ok = new_yy.is_finite()
            && (0..N).all(|i| {
                (self.info[(i, i)] + w2 * s_upper[(i, i)]).is_finite()
                    && (self.eta[i] + w2 * u[i]).is_finite()
                    && m2.map_or(true, |m2| {
                        (self.middle[(i, i)] + m2 * s_upper[(i, i)]).is_finite()
                    })
            });
        if !ok {
            return Err(Error::NonFinite { what: "overflow" });
        }
        self.info += s_upper * w2;
        self.eta += u * w2;
        self.yy = new_yy;
        self.equations += n;
        if let Some(m2) = m2 {
            self.middle += s_upper * m2;
            self.sigma_rows += n;
        }
        Ok(())
    }

    /// `Λ = Σ Bᵀ W² B` (eq. 10), the full symmetric matrix.
    #[must_use]
    pub fn information(&self) -> SMatrix<T, N, N> {
        symmetric(&self.info)
    }

    /// `M = Σ Bᵀ W² Σ² W² B` (middle of eq. 11), the full symmetric matrix,
    /// over the rows that carried a σ.
    #[must_use]
    pub fn middle(&self) -> SMatrix<T, N, N> {
        symmetric(&self.middle)
    }

    /// `η = Σ Bᵀ W² Δp` (eq. 10).
    pub fn eta(&self) -> &SVector<T, N> {
        &self.eta
    }

    /// `Σ Δpᵀ W² Δp`.
    pub fn weighted_yy(&self) -> T {
        self.yy
    }

    /// Rows with a positive weight accumulated so far.
    pub fn equations(&self) -> usize {
        self.equations
    }

    /// Rows that carried a σ (and entered `M`).
    pub fn sigma_rows(&self) -> usize {
        self.sigma_rows
    }

    /// The estimate over all `N` parameters, `X̂ = Λ⁻¹ η` (eq. 6 / 10).
    ///
    /// # Errors
    /// See [`Accumulator::solve_active`].
    pub fn solve(&self) -> Result<Solution<T, N>, Error> {
        self.solve_active(&[true; N])
    }

    /// The estimate over the parameters marked `true` in `active`; the
    /// others are held at zero (they are not in the model).
    ///
    /// # Errors
    /// - [`Error::TooFewEquations`] with fewer equations than active
    ///   parameters;
    /// - [`Error::NotIdentifiable`] naming the first active parameter that is
    ///   (numerically) a combination of the ones before it.
    pub fn solve_active(&self, active: &Active<N>) -> Result<Solution<T, N>, Error> {
        let parameters = active.iter().filter(|a| **a).count();
        if self.equations < parameters {
            return Err(Error::TooFewEquations {
                equations: self.equations,
                parameters,
            });
        }
        solve::solve(
            &self.information(),
            &self.eta,
            self.yy,
            self.equations,
            active,
        )
    }
}

/// `x + Σ_r (k_r u_r) v_r`, summed left to right (three multiply-adds).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn fma3<T: RealField + Copy>(x: T, k: &[T; 3], u0: T, u1: T, u2: T, v0: T, v1: T, v2: T) -> T {
    ((x + (k[0] * u0) * v0) + (k[1] * u1) * v1) + (k[2] * u2) * v2
}

/// `m[i][j] += Σ_r b[r][i] k[r] b[r][j]` for `i < j`: the strictly upper
/// triangle of the rank-3 update `Bᵀ K B`, `K = diag(k)`. `B` is 3 × N,
/// column-major, so column `i` of `B` is three contiguous values and the
/// inner loop runs over contiguous slices without bounds checks: three
/// multiply-adds per element, the column's `k b[·][j]` in registers.
fn add_strict_upper3<T: RealField + Copy, const N: usize>(
    m: &mut SMatrix<T, N, N>,
    k: &[T; 3],
    b: &SMatrix<T, 3, N>,
) {
    let bcols = b.as_slice().chunks_exact(3);
    for ((j, col), bj) in m
        .as_mut_slice()
        .chunks_exact_mut(N)
        .enumerate()
        .zip(bcols.clone())
    {
        let (a0, a1, a2) = (k[0] * bj[0], k[1] * bj[1], k[2] * bj[2]);
        for (x, bi) in col[..j].iter_mut().zip(bcols.clone()) {
            *x = ((*x + bi[0] * a0) + bi[1] * a1) + bi[2] * a2;
        }
    }
}

/// The full symmetric matrix from its upper triangle.
pub(crate) fn symmetric<T: RealField + Copy, const N: usize>(
    upper: &SMatrix<T, N, N>,
) -> SMatrix<T, N, N> {
    let mut m = *upper;
    for j in 0..N {
        for i in (j + 1)..N {
            m[(i, j)] = m[(j, i)];
        }
    }
    m
}
