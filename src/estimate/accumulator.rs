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
use nalgebra::{DefaultAllocator, Dim, DimName, OMatrix, OVector, RealField};

use super::block::{validate_rows, Block};
use super::factor::Solution;
use crate::error::Error;

mod kernel;
use kernel::{
    add_upper, add_upper3, add_upper3_columns, bound_limit, bound_margin, magnitude, RowWeights,
};

/// Sufficient statistics of a weighted least-squares problem with `D`
/// parameters. See the [module docs](self).
///
/// Besides the statistics it keeps `bound`, an upper bound of the values an
/// update checks for overflow, so that an update can validate a block in
/// one cheap sweep and then commit it in one pass: it is not part of the
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
    /// At least the largest of `Λᵢᵢ`, `|ηᵢ|`, `Mᵢᵢ` and `Σ Δpᵀ W² Δp` (see
    /// [`Accumulator::update`]).
    bound: T,
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
            bound: T::zero(),
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
        self.bound = T::zero();
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
        // show (negative weight, σ ≤ 0); everything non-finite shows up in
        // the bound or the new values `add_rows` checks (every b, Δp and w
        // enters them, also with w = 0: 0·∞ = NaN). Any failure takes the
        // slow path, `validate_rows`, for the precise error. Rows past
        // `rows` are never read: they count as zero rows of weight 0.
        let what = match RowWeights::new(dp, w, sigma, rows) {
            Some(rw) if rows == 3 => self.add_rows3(b.as_slice(), &rw),
            Some(rw) => self.add_rows(b.as_slice(), &rw, rows),
            None => Err("weight"),
        };
        let Err(what) = what else {
            return Ok(());
        };
        validate_rows(b, dp, w, sigma, rows)?;
        Err(Error::NonFinite { what })
    }

    /// The update of a block of three rows, on `B` (column-major, 3 × n)
    /// and the checked weights.
    ///
    /// Validation first, without touching the state: one sweep over `B`
    /// gives `q` ≥ every `b²` and `Δp²` ([`magnitude`]: `Σ b² + Σ Δp²`
    /// where `T` is hardware floating point, `(Σ |b| + Σ |Δp|)²` where a
    /// multiplication costs dearly — soft floating point, f64 on the
    /// Cortex-M4F, everything on the M3), and `(Σ w² + Σ w⁴σ²) q` bounds the
    /// change of every checked value (`Λⱼⱼ`, `ηⱼ`, `Mⱼⱼ`, `Σ Δpᵀ W² Δp`: each
    /// term is a weight times `b²`, `b Δp` or `Δp²`, and `|b Δp| ≤ q`). While
    /// the running bound stays below `max/16`, no new value can overflow —
    /// which is the check — and a non-finite input makes the bound NaN or ∞.
    /// Otherwise (rare: huge values, or a non-finite input)
    /// [`Self::fits_exactly`] computes the new checked values as the commit
    /// will: the check of the two-sweep update this replaced. Then one pass
    /// over the columns commits everything ([`add_upper3`]; `M`, with σ,
    /// one column at a time: the smaller code, flash). `Err("overflow")`,
    /// the state untouched, when a sum could overflow.
    #[inline]
    fn add_rows3(&mut self, b: &[T], rw: &RowWeights<T>) -> Result<(), &'static str> {
        let (w2, y) = (&rw.w2, &rw.y);
        let bound = match self.next_bound(magnitude(b, y), rw) {
            None => self.fits_exactly(b, rw, 3),
            fast => fast,
        };
        if bound.is_none() {
            return Err("overflow");
        }
        add_upper3(&mut self.info, self.eta.as_mut_slice(), w2, y, b);
        if rw.sigma {
            add_upper3_columns(&mut self.middle, None, &rw.s2, y, b);
        }
        self.commit_rest(rw, bound);
        Ok(())
    }

    /// [`Self::add_rows3`] for a block of one or two rows: the same values
    /// (the unused rows' terms, `+0` each, left out) in loops over the
    /// rows, out of line, always checked by [`Self::fits_exactly`].
    #[inline(never)]
    fn add_rows(&mut self, b: &[T], rw: &RowWeights<T>, rows: usize) -> Result<(), &'static str> {
        let bound = self.fits_exactly(b, rw, rows);
        if bound.is_none() {
            return Err("overflow");
        }
        add_upper(
            &mut self.info,
            Some(self.eta.as_mut_slice()),
            &rw.w2,
            &rw.y,
            b,
            rows,
        );
        if rw.sigma {
            add_upper(&mut self.middle, None, &rw.s2, &rw.y, b, rows);
        }
        self.commit_rest(rw, bound);
        Ok(())
    }

    /// The running bound after an update with `q` ≥ every `b²` and `Δp²`
    /// ([`magnitude`]), if it stays below the limit (see
    /// [`Self::add_rows3`]).
    #[inline(always)]
    fn next_bound(&self, q: T, rw: &RowWeights<T>) -> Option<T> {
        let (w2, s2) = (&rw.w2, &rw.s2);
        let k = (((((w2[0] + w2[1]) + w2[2]) + s2[0]) + s2[1]) + s2[2]) * q;
        let bound = (self.bound + k) * bound_margin::<T>();
        (bound <= bound_limit::<T>()).then_some(bound)
    }

    /// The rest of a commit: `Σ Δpᵀ W² Δp`, the counts, the new bound.
    #[inline(always)]
    fn commit_rest(&mut self, rw: &RowWeights<T>, bound: Option<T>) {
        let (w2, y) = (&rw.w2, &rw.y);
        self.yy = ((self.yy + w2[0] * y[0] * y[0]) + w2[1] * y[1] * y[1]) + w2[2] * y[2] * y[2];
        self.equations += rw.equations;
        if rw.sigma {
            self.sigma_rows += rw.equations;
        }
        if let Some(bound) = bound {
            self.bound = bound;
        }
    }

    /// The largest of the new `Λⱼⱼ`, `|ηⱼ|`, `Mⱼⱼ` and `Σ Δpᵀ W² Δp` after
    /// the update of the first `rows` rows of `B`, computed as the commit
    /// computes them, if they are all finite (the exact check; the new
    /// bound).
    #[cold]
    #[inline(never)]
    fn fits_exactly(&self, b: &[T], rw: &RowWeights<T>, rows: usize) -> Option<T> {
        let (w2, y) = (&rw.w2, &rw.y);
        let yy = ((self.yy + w2[0] * y[0] * y[0]) + w2[1] * y[1] * y[1]) + w2[2] * y[2] * y[2];
        let mut ok = yy.is_finite();
        let mut bound = yy;
        let columns = b.chunks_exact(3).zip(diagonal(&self.info));
        for ((c, mut lambda), (mut eta, mut mid)) in
            columns.zip(self.eta.iter().copied().zip(diagonal(&self.middle)))
        {
            for (r, &v) in c.iter().enumerate().take(rows) {
                let a = w2[r] * v;
                lambda += v * a;
                eta += a * y[r];
                mid += v * (rw.s2[r] * v);
            }
            ok &= lambda.is_finite() && eta.is_finite() && mid.is_finite();
            bound = bound.max(lambda).max(eta.abs()).max(mid);
        }
        ok.then_some(bound)
    }

    /// Sets `bound` to the largest checked value (after an update that took
    /// the slow path, and after `merge` and `add_moments`).
    fn refresh_bound(&mut self) {
        let mut bound = self.yy;
        for v in diagonal(&self.info).chain(diagonal(&self.middle)) {
            bound = bound.max(v);
        }
        for v in self.eta.iter() {
            bound = bound.max(v.abs());
        }
        self.bound = bound;
    }

    /// The statistics of a subset of columns, as if only they had been
    /// streamed: `info` upper triangle (row ≤ column) of `Λ`, `η`,
    /// `Σ Δpᵀ W² Δp` and the number of rows (no σ, so no `M`). For
    /// [`super::screen::Augmented`], which keeps the sums of more columns
    /// than it tests at once.
    pub(crate) fn from_sums(
        info: OMatrix<T, D, D>,
        eta: OVector<T, D>,
        yy: T,
        equations: usize,
    ) -> Self {
        let dim = info.shape_generic().0;
        let mut acc = Self {
            info,
            eta,
            yy,
            middle: OMatrix::zeros_generic(dim, dim),
            equations,
            sigma_rows: 0,
            bound: T::zero(),
        };
        acc.refresh_bound();
        acc
    }

    /// [`Self::from_sums`] with the sandwich's middle term `M` (upper
    /// triangle) over `sigma_rows` rows: the host's
    /// [`super::wide::WideAccumulator`] hands over its sums this way.
    #[cfg(feature = "std")]
    pub(crate) fn with_middle(mut self, middle: OMatrix<T, D, D>, sigma_rows: usize) -> Self {
        self.middle = middle;
        self.sigma_rows = sigma_rows;
        self.refresh_bound();
        self
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
        self.refresh_bound();
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
                    && m2.is_none_or(|m2| (self.middle[(i, i)] + m2 * s_upper[(i, i)]).is_finite())
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
        self.refresh_bound();
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

/// The diagonal of a square matrix.
fn diagonal<T: RealField + Copy, D: Dim>(m: &OMatrix<T, D, D>) -> impl Iterator<Item = T> + '_
where
    DefaultAllocator: Alloc<D>,
{
    m.as_slice().iter().step_by(m.nrows() + 1).copied()
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
