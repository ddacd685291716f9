//! The streaming weighted-least-squares accumulator.
//!
//! Each measurement contributes a block of up to three identification
//! equations `Δp = B X` (eq. 4) — the x, y and z rows of one marker — with a
//! weight per row. The accumulator keeps the sufficient statistics of the
//! weighted problem (eq. 9):
//!
//! - `Λ = Σ Bᵀ W² B`, the information matrix (eq. 10), `n × n`, symmetric;
//! - `η = Σ Bᵀ W² Δp` (eq. 10);
//! - `Σ Δpᵀ W² Δp`, for the residual sum of squares `Σ Δpᵀ W² Δp − X̂ᵀ η`;
//! - optionally `M = Σ Bᵀ W² Σ² W² B`, the middle of the sandwich covariance
//!   (eq. 8, 11), when the σ of a row is known.
//!
//! An update costs `O(n²)` per row and touches only the upper triangle of the
//! symmetric matrices; memory is fixed and does not grow with the number of
//! measurements. With `W = I` the same statistics give ordinary least squares
//! (eq. 6, 7).
//!
//! The number of parameters is a nalgebra dimension `D`: `Const<N>` on a
//! microcontroller (everything on the stack, no allocator), `Dyn` on the
//! host (the exact number of parameters of the model, no padding).
//!
//! ```
//! use nalgebra::{Matrix3x2, Vector3, U2};
//! use robcal::{Accumulator, Block};
//!
//! // Two parameters, two measurements of three rows each.
//! let mut acc = Accumulator::<f64, U2>::new();
//! let b = Matrix3x2::new(1.0, 0.0, 0.0, 1.0, 1.0, 1.0);
//! let x_true = nalgebra::Vector2::new(0.5, -2.0);
//! acc.update(&Block::new(b, b * x_true)).unwrap();
//! acc.update(&Block::new(2.0 * b, 2.0 * b * x_true)).unwrap();
//! let sol = acc.solve().unwrap();
//! assert!((sol.x - x_true).norm() < 1e-12);
//! ```

use super::Alloc;
use nalgebra::{DefaultAllocator, Dim, DimName, OMatrix, OVector, RealField, U3};

use super::block::{validate_rows, Block};
use super::factor::Solution;
use crate::Error;

/// Sufficient statistics of a weighted least-squares problem with `D`
/// parameters. See the [module docs](self).
///
/// Besides the statistics it owns a workspace of three vectors that an
/// update fills before it commits anything (so that a rejected update leaves
/// the statistics as they were, without allocating): it is not part of the
/// state, and `PartialEq`, `Debug` and `defmt::Format` ignore it.
#[derive(Clone)]
pub struct Accumulator<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    /// `Λ = Σ Bᵀ W² B`; only the upper triangle (row ≤ column) is kept.
    info: OMatrix<T, D, D>,
    /// `η = Σ Bᵀ W² Δp`.
    eta: OVector<T, D>,
    /// `Σ Δpᵀ W² Δp`.
    yy: T,
    /// `M = Σ Bᵀ W² Σ² W² B`, upper triangle, from rows with a known σ.
    middle: OMatrix<T, D, D>,
    /// Rows with a positive weight.
    equations: usize,
    /// Rows with a positive weight that carried a σ.
    sigma_rows: usize,
    /// The update under way: its new diagonals and `η`, and a block with
    /// fewer than three rows, its unused rows zeroed.
    work: Work<T, D>,
}

/// The workspace of an update (see [`Accumulator`]).
#[derive(Clone)]
struct Work<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    /// New diagonal of `Λ`.
    diag: OVector<T, D>,
    /// New `η`.
    eta: OVector<T, D>,
    /// New diagonal of `M`.
    mdiag: OVector<T, D>,
    /// `B` of a block of one or two rows, the other rows zero (3 × n,
    /// column-major).
    b: OMatrix<T, U3, D>,
}

impl<T: RealField + Copy, D: Dim> PartialEq for Accumulator<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn eq(&self, other: &Self) -> bool {
        self.info == other.info
            && self.eta == other.eta
            && self.yy == other.yy
            && self.middle == other.middle
            && self.equations == other.equations
            && self.sigma_rows == other.sigma_rows
    }
}

impl<T: RealField + Copy, D: Dim> core::fmt::Debug for Accumulator<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Accumulator")
            .field("info", &self.info)
            .field("eta", &self.eta)
            .field("yy", &self.yy)
            .field("middle", &self.middle)
            .field("equations", &self.equations)
            .field("sigma_rows", &self.sigma_rows)
            .finish()
    }
}

#[cfg(feature = "defmt")]
impl<T: RealField + Copy + defmt::Format, D: Dim> defmt::Format for Accumulator<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(
            f,
            "Accumulator {{ parameters: {=usize}, equations: {=usize}, sigma_rows: {=usize}, yy: {} }}",
            self.parameters(),
            self.equations,
            self.sigma_rows,
            self.yy
        )
    }
}

impl<T: RealField + Copy, D: DimName> Default for Accumulator<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn default() -> Self {
        Self::new()
    }
}

impl<T: RealField + Copy, D: DimName> Accumulator<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    /// An empty accumulator of a fixed size (`Const<N>`).
    pub fn new() -> Self {
        Self::zeros(D::name())
    }
}

impl<T: RealField + Copy, D: Dim> Accumulator<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    /// An empty accumulator of `dim` parameters (e.g. `Dyn(n)` on the host).
    pub fn zeros(dim: D) -> Self {
        Self {
            info: OMatrix::zeros_generic(dim, dim),
            eta: OVector::zeros_generic(dim, nalgebra::Const::<1>),
            yy: T::zero(),
            middle: OMatrix::zeros_generic(dim, dim),
            equations: 0,
            sigma_rows: 0,
            work: Work {
                diag: OVector::zeros_generic(dim, nalgebra::Const::<1>),
                eta: OVector::zeros_generic(dim, nalgebra::Const::<1>),
                mdiag: OVector::zeros_generic(dim, nalgebra::Const::<1>),
                b: OMatrix::zeros_generic(U3, dim),
            },
        }
    }

    /// The number of parameters, as a dimension.
    pub fn dim(&self) -> D {
        self.info.shape_generic().0
    }

    /// The number of parameters.
    pub fn parameters(&self) -> usize {
        self.info.nrows()
    }

    /// Forgets every measurement.
    pub fn reset(&mut self) {
        self.info.fill(T::zero());
        self.eta.fill(T::zero());
        self.middle.fill(T::zero());
        self.yy = T::zero();
        self.equations = 0;
        self.sigma_rows = 0;
    }

    /// Adds one measurement block: `Λ += Bᵀ W² B`, `η += Bᵀ W² Δp`, and, when
    /// the block carries σ, `M += Bᵀ W² Σ² W² B`.
    ///
    /// The accumulator is unchanged on error. The host keeps one block and
    /// refills it for each measurement: nothing is allocated per update.
    ///
    /// # Errors
    /// - [`Error::Mismatch`] when `b` does not have one column per parameter;
    /// - whatever [`Block::validate`] finds;
    /// - [`Error::NonFinite`] with `what = "overflow"` when the sums would
    ///   overflow (checked on the diagonal, which bounds every off-diagonal
    ///   element of a sum of positive semi-definite terms).
    // `!(w >= 0)` is meant: it is true for NaN, which `w < 0` is not.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn update(&mut self, block: &Block<T, D>) -> Result<(), Error> {
        let (b, dp, w, sigma, rows) = (
            &block.b,
            &block.dp,
            &block.w,
            block.sigma.as_ref(),
            block.rows,
        );
        if b.ncols() != self.parameters() {
            return Err(Error::Mismatch {
                what: "block size differs from the accumulator's",
            });
        }
        if rows == 0 || rows > 3 {
            return validate_rows(b, dp, w, sigma, rows);
        }
        // Cheap screening of the values whose problems the sums below cannot
        // show (negative weight, σ ≤ 0); everything non-finite shows up as a
        // non-finite new diagonal, η or Σ Δpᵀ W² Δp (every b, Δp and w enters
        // one of them, also with w = 0: 0·∞ = NaN). Any failure takes the
        // slow path, `validate_rows`, for the precise error. Rows past
        // `rows` are never read: they count as zero rows of weight 0.
        let zero = T::zero();
        let mut rw = RowWeights {
            w2: [zero; 3],
            s2: sigma.map(|_| [zero; 3]),
            y: [zero; 3],
            equations: 0,
        };
        for r in 0..rows {
            let wr = w[r];
            if !(wr >= zero) {
                return validate_rows(b, dp, w, sigma, rows);
            }
            rw.w2[r] = wr * wr;
            rw.y[r] = dp[r];
            rw.equations += usize::from(rw.w2[r] > zero);
            if let (Some(s), Some(s2)) = (sigma, rw.s2.as_mut()) {
                if !(s[r] > zero) {
                    return validate_rows(b, dp, w, sigma, rows);
                }
                s2[r] = rw.w2[r] * rw.w2[r] * s[r] * s[r];
            }
        }
        if rows < 3 {
            // The used rows into the workspace, the others zero.
            let copy = self.work.b.as_mut_slice().chunks_exact_mut(3);
            for (dst, src) in copy.zip(b.as_slice().chunks_exact(3)) {
                for (r, (d, s)) in dst.iter_mut().zip(src).enumerate() {
                    *d = if r < rows { *s } else { zero };
                }
            }
        }
        let added = self.add_rows(rows < 3, b, &rw);
        if added.is_err() {
            validate_rows(b, dp, w, sigma, rows)?;
        }
        added
    }

    /// The update proper, on `B` (column-major, 3 × n: the block's, or the
    /// workspace's copy of a block of fewer rows) and the checked weights:
    /// a first sweep computes the new diagonal of `Λ` (and `M`) and the new
    /// `η` into the workspace, and checks them; only then one sweep over the
    /// columns commits the strict upper triangle and the workspace.
    #[inline]
    fn add_rows(
        &mut self,
        masked: bool,
        block_b: &OMatrix<T, U3, D>,
        rw: &RowWeights<T>,
    ) -> Result<(), Error> {
        let zero = T::zero();
        let (w2, y) = (&rw.w2, &rw.y);
        let Work {
            diag,
            eta,
            mdiag,
            b: wb,
        } = &mut self.work;
        let b = if masked { &*wb } else { block_b };
        let new_yy = ((self.yy + w2[0] * y[0] * y[0]) + w2[1] * y[1] * y[1]) + w2[2] * y[2] * y[2];
        // `t` collects x·0 over every new value: NaN iff one is not finite
        // (one multiply-add per value instead of a compare and a branch).
        let mut t = new_yy * zero;
        for (j, bj) in b.as_slice().chunks_exact(3).enumerate() {
            let bj = [bj[0], bj[1], bj[2]];
            diag[j] = fma3(self.info[(j, j)], w2, &bj, &bj);
            eta[j] = fma3(self.eta[j], w2, &bj, y);
            t += diag[j] * zero;
            t += eta[j] * zero;
            if let Some(s2) = &rw.s2 {
                mdiag[j] = fma3(self.middle[(j, j)], s2, &bj, &bj);
                t += mdiag[j] * zero;
            }
        }
        if !t.is_finite() {
            return Err(Error::NonFinite { what: "overflow" });
        }
        // Commit: the strict upper triangle, then the checked diagonal and η.
        add_strict_upper3(&mut self.info, w2, b);
        if let Some(s2) = &rw.s2 {
            add_strict_upper3(&mut self.middle, s2, b);
            self.sigma_rows += rw.equations;
        }
        self.eta.copy_from(eta);
        let sigma = rw.s2.is_some();
        for j in 0..self.info.nrows() {
            self.info[(j, j)] = diag[j];
            if sigma {
                self.middle[(j, j)] = mdiag[j];
            }
        }
        self.yy = new_yy;
        self.equations += rw.equations;
        Ok(())
    }

    /// Adds the statistics of `other` (measurements taken elsewhere, e.g. on
    /// another core): the result equals feeding both streams to one
    /// accumulator, up to rounding.
    ///
    /// # Errors
    /// [`Error::Mismatch`] for another number of parameters;
    /// [`Error::NonFinite`] (`"overflow"`) when a sum would overflow. `self`
    /// is unchanged on error.
    pub fn merge(&mut self, other: &Self) -> Result<(), Error> {
        let n = self.parameters();
        if other.parameters() != n {
            return Err(Error::Mismatch {
                what: "accumulator sizes differ",
            });
        }
        let yy = self.yy + other.yy;
        let ok = yy.is_finite()
            && (0..n).all(|i| {
                (self.info[(i, i)] + other.info[(i, i)]).is_finite()
                    && (self.middle[(i, i)] + other.middle[(i, i)]).is_finite()
                    && (self.eta[i] + other.eta[i]).is_finite()
            });
        if !ok {
            return Err(Error::NonFinite { what: "overflow" });
        }
        self.info += &other.info;
        self.middle += &other.middle;
        self.eta += &other.eta;
        self.yy = yy;
        self.equations += other.equations;
        self.sigma_rows += other.sigma_rows;
        Ok(())
    }

    /// Adds the moments of `n` rows that all carry the same weight `w`:
    /// `Λ += w² S`, `η += w² u`, `Σ Δpᵀ W² Δp += w² yy`, and, with `σ`,
    /// `M += w⁴ σ² S`. `s_upper` is `S = Σ b bᵀ` (upper triangle), `u = Σ b y`,
    /// `yy = Σ y²`. Used by [`super::grouped`] to re-weight without raw data.
    pub(crate) fn add_moments(
        &mut self,
        s_upper: &OMatrix<T, D, D>,
        u: &OVector<T, D>,
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
        let p = self.parameters();
        let ok = new_yy.is_finite()
            && (0..p).all(|i| {
                (self.info[(i, i)] + w2 * s_upper[(i, i)]).is_finite()
                    && (self.eta[i] + w2 * u[i]).is_finite()
                    && m2.map_or(true, |m2| {
                        (self.middle[(i, i)] + m2 * s_upper[(i, i)]).is_finite()
                    })
            });
        if !ok {
            return Err(Error::NonFinite { what: "overflow" });
        }
        self.info.zip_apply(s_upper, |a, s| *a += s * w2);
        self.eta.zip_apply(u, |a, v| *a += v * w2);
        self.yy = new_yy;
        self.equations += n;
        if let Some(m2) = m2 {
            self.middle.zip_apply(s_upper, |a, s| *a += s * m2);
            self.sigma_rows += n;
        }
        Ok(())
    }

    /// `Λ = Σ Bᵀ W² B` (eq. 10), the full symmetric matrix.
    #[must_use]
    pub fn information(&self) -> OMatrix<T, D, D> {
        symmetric(&self.info)
    }

    /// `M = Σ Bᵀ W² Σ² W² B` (middle of eq. 11), the full symmetric matrix,
    /// over the rows that carried a σ.
    #[must_use]
    pub fn middle(&self) -> OMatrix<T, D, D> {
        symmetric(&self.middle)
    }

    /// `η = Σ Bᵀ W² Δp` (eq. 10).
    pub fn eta(&self) -> &OVector<T, D> {
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

    /// The estimate over all parameters, `X̂ = Λ⁻¹ η` (eq. 6 / 10).
    ///
    /// # Errors
    /// See [`Accumulator::solve_active`].
    pub fn solve(&self) -> Result<Solution<T, D>, Error> {
        let parameters = self.parameters();
        if self.equations < parameters {
            return Err(Error::TooFewEquations {
                equations: self.equations,
                parameters,
            });
        }
        let all = OVector::<bool, D>::from_element_generic(self.dim(), nalgebra::Const::<1>, true);
        Solution::with_mask(&self.information(), &self.eta, self.yy, self.equations, all)
    }

    /// The estimate over the parameters marked `true` in `active` (one flag
    /// per parameter); the others are held at zero (they are not in the
    /// model).
    ///
    /// # Errors
    /// - [`Error::Mismatch`] when `active` does not have one flag per
    ///   parameter;
    /// - [`Error::TooFewEquations`] with fewer equations than active
    ///   parameters;
    /// - [`Error::NotIdentifiable`] naming the first active parameter that is
    ///   (numerically) a combination of the ones before it.
    pub fn solve_active(&self, active: &[bool]) -> Result<Solution<T, D>, Error> {
        let parameters = active.iter().filter(|a| **a).count();
        if active.len() == self.parameters() && self.equations < parameters {
            return Err(Error::TooFewEquations {
                equations: self.equations,
                parameters,
            });
        }
        Solution::new(
            &self.information(),
            &self.eta,
            self.yy,
            self.equations,
            active,
        )
    }
}

/// The checked per-row quantities of one block: `w²`, `w⁴σ²` (with σ), `Δp`
/// (zero past the block's rows) and the rows with a positive weight.
struct RowWeights<T> {
    w2: [T; 3],
    s2: Option<[T; 3]>,
    y: [T; 3],
    equations: usize,
}

/// `x + Σ_r (k_r u_r) v_r`, summed left to right (three multiply-adds).
#[inline(always)]
fn fma3<T: RealField + Copy>(x: T, k: &[T; 3], u: &[T; 3], v: &[T; 3]) -> T {
    ((x + (k[0] * u[0]) * v[0]) + (k[1] * u[1]) * v[1]) + (k[2] * u[2]) * v[2]
}

/// `m[i][j] += Σ_r b[r][i] k[r] b[r][j]` for `i < j`: the strict upper
/// triangle of the rank-3 update `Bᵀ K B`, `K = diag(k)`. `B` is 3 × n,
/// column-major, so column `i` of `B` is three contiguous values and the
/// inner loop runs over contiguous slices without bounds checks: three
/// multiply-adds per element, the column's `k b[·][j]` in registers.
fn add_strict_upper3<T: RealField + Copy, D: Dim>(
    m: &mut OMatrix<T, D, D>,
    k: &[T; 3],
    b: &OMatrix<T, U3, D>,
) where
    DefaultAllocator: Alloc<D>,
{
    let n = m.nrows();
    let bcols = b.as_slice().chunks_exact(3);
    for ((j, col), bj) in m
        .as_mut_slice()
        .chunks_exact_mut(n)
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
pub(crate) fn symmetric<T: RealField + Copy, D: Dim>(upper: &OMatrix<T, D, D>) -> OMatrix<T, D, D>
where
    DefaultAllocator: Alloc<D>,
{
    let mut m = upper.clone();
    m.fill_lower_triangle_with_upper_triangle();
    m
}
