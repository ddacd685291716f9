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
    pub fn update(&mut self, block: &Block<T, N>) -> Result<(), Error> {
        block.validate()?;
        // Weighted rows w²b (and w⁴σ²b for the middle term), computed once.
        let mut wb = [SVector::<T, N>::zeros(); 3];
        let mut sb = [SVector::<T, N>::zeros(); 3];
        let mut b = [SVector::<T, N>::zeros(); 3];
        let mut new_yy = self.yy;
        let mut eqs = 0;
        for r in 0..block.rows {
            let w2 = block.w[r] * block.w[r];
            if w2 == T::zero() {
                continue;
            }
            b[r] = block.b.row(r).transpose();
            wb[r] = b[r] * w2;
            if let Some(s) = block.sigma {
                sb[r] = wb[r] * (w2 * s[r] * s[r]);
            }
            new_yy += w2 * block.dp[r] * block.dp[r];
            eqs += 1;
        }
        // Overflow guard: the new diagonal of Λ and M, η and Σ Δpᵀ W² Δp.
        if !new_yy.is_finite() {
            return Err(Error::NonFinite { what: "overflow" });
        }
        for i in 0..N {
            let mut d = self.info[(i, i)];
            let mut m = self.middle[(i, i)];
            let mut e = self.eta[i];
            for r in 0..3 {
                d += wb[r][i] * b[r][i];
                m += sb[r][i] * b[r][i];
                e += wb[r][i] * block.dp[r];
            }
            if !(d.is_finite() && m.is_finite() && e.is_finite()) {
                return Err(Error::NonFinite { what: "overflow" });
            }
        }
        // Commit. Rows left at zero (dropped or unused) add nothing.
        add_upper3(&mut self.info, &wb, &b);
        if block.sigma.is_some() {
            add_upper3(&mut self.middle, &sb, &b);
            self.sigma_rows += eqs;
        }
        for r in 0..3 {
            self.eta += wb[r] * block.dp[r];
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

/// `m[i][j] += Σ_r u_r[i] v_r[j]` for `i ≤ j`: the upper triangle of a rank-3
/// update. The inner loop runs over a contiguous column slice (column-major
/// storage) so it needs no bounds checks: three multiply-adds per element.
fn add_upper3<T: RealField + Copy, const N: usize>(
    m: &mut SMatrix<T, N, N>,
    u: &[SVector<T, N>; 3],
    v: &[SVector<T, N>; 3],
) {
    let (u0, u1, u2) = (u[0].as_slice(), u[1].as_slice(), u[2].as_slice());
    for (j, col) in m.as_mut_slice().chunks_exact_mut(N).enumerate() {
        let (a, b, c) = (v[0][j], v[1][j], v[2][j]);
        let upper = &mut col[..=j];
        for (((x, &p), &q), &r) in upper.iter_mut().zip(u0).zip(u1).zip(u2) {
            *x += p * a + q * b + r * c;
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
