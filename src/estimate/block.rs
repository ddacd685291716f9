//! One measurement as rows of the identification equations `Δp = B X`
//! (eq. 4): the x, y and z rows of one marker, with a weight per row
//! (eq. 9) and, when known, a σ per row (eq. 8, 11).

use nalgebra::{DefaultAllocator, Dim, OMatrix, RealField, Vector3, U3};

use super::Alloc;
use crate::error::Error;

/// One measurement: up to three rows of `Δp = B X` with their weights.
///
/// Rows are the x, y, z components of a marker displacement or position, in
/// metres; `B` in metres per unit of each parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Block<T: RealField + Copy, D: Dim>
where
    DefaultAllocator: Alloc<D>,
{
    /// `B`: one row per equation (x, y, z).
    pub b: OMatrix<T, U3, D>,
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

impl<T: RealField + Copy, D: Dim> Copy for Block<T, D>
where
    DefaultAllocator: Alloc<D>,
    OMatrix<T, U3, D>: Copy,
{
}

/// `B` row by row, `Δp`, `w` and `σ` as lists (not nalgebra's internals).
#[cfg(feature = "defmt")]
impl<T: RealField + Copy + defmt::Format, D: Dim> defmt::Format for Block<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    fn format(&self, f: defmt::Formatter<'_>) {
        use super::fmt::rows;
        defmt::write!(
            f,
            "Block {{ b: {}, dp: {}, w: {}, sigma: {}, rows: {=usize} }}",
            rows(&self.b),
            rows(&self.dp),
            rows(&self.w),
            self.sigma.as_ref().map(rows),
            self.rows
        )
    }
}

impl<T: RealField + Copy, D: Dim> Block<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    /// Three rows with unit weights and no σ.
    pub fn new(b: OMatrix<T, U3, D>, dp: Vector3<T>) -> Self {
        Self {
            b,
            dp,
            w: Vector3::new(T::one(), T::one(), T::one()),
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
        validate_rows(&self.b, &self.dp, &self.w, self.sigma.as_ref(), self.rows)
    }
}

/// [`Block::validate`] on the parts of a block.
pub(crate) fn validate_rows<T: RealField + Copy, D: Dim>(
    b: &OMatrix<T, U3, D>,
    dp: &Vector3<T>,
    w: &Vector3<T>,
    sigma: Option<&Vector3<T>>,
    rows: usize,
) -> Result<(), Error>
where
    DefaultAllocator: Alloc<D>,
{
    if rows == 0 || rows > 3 {
        return Err(Error::OutOfRange {
            what: "block rows",
            index: rows,
            len: 4,
        });
    }
    for r in 0..rows {
        let row_finite = b
            .as_slice()
            .chunks_exact(3)
            .all(|c| c.get(r).is_some_and(|v| v.is_finite()));
        if !row_finite {
            return Err(Error::NonFinite { what: "row" });
        }
        if !dp[r].is_finite() {
            return Err(Error::NonFinite { what: "dp" });
        }
        if !w[r].is_finite() {
            return Err(Error::NonFinite { what: "weight" });
        }
        if w[r] < T::zero() {
            return Err(Error::NotPositive { what: "weight" });
        }
        if let Some(s) = sigma {
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
