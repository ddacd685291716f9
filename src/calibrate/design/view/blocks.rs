//! How a [`View`]'s rows reach its passes: copied a block at a time into
//! the layout the kernels of [`crate::calibrate::design::view::terms`] stream (each row's three
//! axes as three contiguous runs of its columns), the blocks taken in turn
//! by worker threads, or one block's triangle shared between them by
//! columns.

use crate::calibrate::design::view::terms::column_shares;
use crate::calibrate::design::view::View;

impl View<'_> {
    /// The columns of the included rows `first..first + len`: row `k`'s
    /// axis `a` at `[(3k + a) n..(3k + a + 1) n]`.
    pub(super) fn copy(&self, first: usize, len: usize) -> Vec<f64> {
        let mut b = Vec::new();
        self.copy_into(first, len, &mut b);
        b
    }

    /// [`View::copy`] into `b` (resized): [`crate::calibrate::design::view::Design::rows_into`],
    /// held or computed.
    fn copy_into(&self, first: usize, len: usize, b: &mut Vec<f64>) {
        self.d
            .rows_into(&self.rows[first..first + len], self.cols, b);
    }

    /// `f(t, rows, b, columns)` for each block of the included rows, in
    /// order, and each share `t` of the triangle's columns `columns`:
    /// `rows` the block's design rows, `b` their columns ([`View::copy`]'s
    /// layout). Each element of a block's sums is summed by one share over
    /// the block's rows in order; a view of at most `block` rows is one
    /// block whose columns are shared between worker threads
    /// ([`View::by_columns`]); a larger one is blocks of `block` rows, each
    /// all columns on one worker thread, taken in turn. The results are
    /// the same whatever the number of threads.
    pub(super) fn by_blocks<T: Send>(
        &self,
        f: impl Fn(usize, &[usize], &[f64], std::ops::Range<usize>) -> T + Sync,
    ) -> Vec<Vec<(std::ops::Range<usize>, T)>> {
        if self.rows.len() <= self.block {
            return vec![self.by_columns(|t, columns| f(t, &self.rows, &self.b, columns))];
        }
        let n = self.cols.len();
        let blocks = self.rows.len().div_ceil(self.block);
        let threads = crate::parallel::for_rows(self.rows.len());
        crate::parallel::map(blocks, threads, |k| {
            let first = k * self.block;
            let len = self.block.min(self.rows.len() - first);
            let mut b = Vec::new();
            self.copy_into(first, len, &mut b);
            vec![(0..n, f(0, &self.rows[first..first + len], &b, 0..n))]
        })
    }

    /// `f(t, columns)` for each share `t` of the triangle's columns
    /// ([`column_shares`]), on worker threads when the rows are many
    /// ([`crate::parallel::for_rows`]), with the shares: each element of
    /// the triangle is summed by one share, over every row in order, as a
    /// pass on one thread sums it (the same bits on any number of threads).
    pub(super) fn by_columns<T: Send>(
        &self,
        f: impl Fn(usize, std::ops::Range<usize>) -> T + Sync,
    ) -> Vec<(std::ops::Range<usize>, T)> {
        let n = self.cols.len();
        let shares = column_shares(n, crate::parallel::for_rows(self.rows.len()));
        let parts = crate::parallel::map(shares.len(), shares.len(), |t| f(t, shares[t].clone()));
        shares.into_iter().zip(parts).collect()
    }

    /// The three axes of row `k` of a copy `b`.
    pub(super) fn row_of<'b>(&self, b: &'b [f64], k: usize) -> [&'b [f64]; 3] {
        let n = self.cols.len();
        let at = |a: usize| &b[(3 * k + a) * n..(3 * k + a + 1) * n];
        [at(0), at(1), at(2)]
    }
}
