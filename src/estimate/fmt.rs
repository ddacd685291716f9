//! nalgebra matrices and vectors in defmt logs as plain numbers (issue 19).
//!
//! A derived `defmt::Format` prints nalgebra's internals
//! (`Matrix { data: ArrayStorage([[..]]), _phantoms: PhantomData }`,
//! column by column). The manual `defmt::Format` impls of this module's
//! types print their matrices through [`rows`] instead:
//!
//! ```text
//! a 2 × 2 matrix   [[1.0, 2.0], [3.0, 4.0]]    row by row
//! a vector         [1.0, 2.0]                  one list
//! ```
//!
//! `no_std`, allocation-free and without panics: the elements are written
//! one at a time with `defmt::write!` from the matrix's own storage.
//!
//! ```ignore
//! defmt::info!("B = {}", robcal::estimate::fmt::rows(&block.b));
//! ```

use nalgebra::{Dim, IsContiguous, Matrix, RawStorage};

/// A matrix or vector borrowed for a defmt log: nested lists, row-major
/// (see the [module docs](self)). Made by [`rows`].
#[derive(Clone, Copy)]
pub struct Rows<'a, T> {
    /// The elements in nalgebra's order (column-major).
    data: &'a [T],
    nrows: usize,
    ncols: usize,
    /// A column vector by type (`C = U1`): one flat list.
    vector: bool,
}

/// `m` for a defmt log: `[[a, b], [c, d]]` row by row, or `[a, b]` for a
/// column vector (a matrix whose column dimension is `U1`). Works for any
/// scalar with `defmt::Format` (f32, f64, bool, …) and for `Const<N>` and
/// `Dyn` dimensions alike.
pub fn rows<T, R: Dim, C: Dim, S>(m: &Matrix<T, R, C, S>) -> Rows<'_, T>
where
    S: RawStorage<T, R, C> + IsContiguous,
{
    Rows {
        data: m.as_slice(),
        nrows: m.nrows(),
        ncols: m.ncols(),
        vector: C::try_to_usize() == Some(1),
    }
}

impl<T: defmt::Format> defmt::Format for Rows<'_, T> {
    fn format(&self, f: defmt::Formatter<'_>) {
        if self.vector {
            // Contiguous: defmt's own list, `[a, b, c]`.
            defmt::write!(f, "{=[?]}", self.data);
            return;
        }
        let sep = |k: usize| if k == 0 { "" } else { ", " };
        defmt::write!(f, "[");
        for i in 0..self.nrows {
            defmt::write!(f, "{=str}[", sep(i));
            for j in 0..self.ncols {
                // Element (i, j) is at j·nrows + i (column-major); `get`
                // cannot miss, and would print nothing rather than panic.
                if let Some(x) = self.data.get(j * self.nrows + i) {
                    defmt::write!(f, "{=str}{}", sep(j), x);
                }
            }
            defmt::write!(f, "]");
        }
        defmt::write!(f, "]");
    }
}
