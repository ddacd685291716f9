//! Many dot products of the columns of a tall matrix in one pass over its
//! rows, each exactly as nalgebra's `dot` computes it.
//!
//! nalgebra's `dot` of two columns of `m` values keeps eight running sums,
//! `s_k += a[8t + k] · b[8t + k]` over the `⌊m/8⌋` whole runs of eight, then
//! `r = 0; r += s₀ + s₄; r += s₁ + s₅; r += s₂ + s₆; r += s₃ + s₇` and the
//! last `m mod 8` products one by one. Each sum here takes the same
//! products in the same order, a block of rows at a time for every pair, so
//! each result is `dot`'s, bit for bit (but for the sign of a NaN, which
//! nothing reads); but the columns are read once per thread instead of once
//! per pair (the held-out's `Λ` of 15 columns of 3·10⁶ rows: 135 dots were
//! 135 passes over two 24 MB columns).

use crate::calibrate::design::widest::{widest, Kernel};
use crate::calibrate::design::Design;

/// Rows a block (8 KiB of a column): the block of every column (128 KiB
/// at 16 columns) stays in the second-level cache while the pairs of a
/// thread go by.
const BLOCK: usize = 1024;

/// `dot(columns[i], columns[j])` (nalgebra's, bit for bit) for every
/// `(i, j)` of `pairs`, in order, on up to `threads` threads (each a
/// contiguous run of the pairs). All columns have the same length.
pub(super) fn column_dots(
    columns: &[&[f64]],
    pairs: &[(usize, usize)],
    threads: usize,
) -> Vec<f64> {
    let m = columns.first().map_or(0, |c| c.len());
    let whole = m - m % 8;
    let parts = threads.clamp(1, pairs.len().max(1));
    let runs = crate::parallel::map(parts, parts, |k| {
        let run = &pairs[k * pairs.len() / parts..(k + 1) * pairs.len() / parts];
        let mut sums = vec![[0.0_f64; 8]; run.len()];
        let mut lo = 0;
        while lo < whole {
            let hi = (lo + BLOCK).min(whole);
            widest(Block {
                columns,
                run,
                sums: &mut sums,
                rows: lo..hi,
            });
            lo = hi;
        }
        run.iter()
            .zip(&sums)
            .map(|(&(i, j), s)| finished(s, (whole..m).map(|t| (columns[i][t], columns[j][t]))))
            .collect::<Vec<f64>>()
    });
    runs.concat()
}

/// [`column_dots`] of the columns `cols` of `d` then its `Δp` (column
/// `cols.len()` of `pairs`), the columns computed a block of rows at a time
/// where `d` does not hold them ([`Design::columns_into`], each block's
/// halves on two threads): each block's values go to every pair's sums in
/// the order of the whole columns (a block is a multiple of eight values),
/// so each result is [`column_dots`]' of the whole columns, bit for bit.
pub(super) fn design_dots(
    d: &Design,
    cols: &[usize],
    pairs: &[(usize, usize)],
    threads: usize,
) -> Vec<f64> {
    let m = 3 * d.rows();
    let whole = m - m % 8;
    let parts = threads.clamp(1, pairs.len().max(1));
    let runs: Vec<&[(usize, usize)]> = (0..parts)
        .map(|k| &pairs[k * pairs.len() / parts..(k + 1) * pairs.len() / parts])
        .collect();
    let mut sums: Vec<Vec<[f64; 8]>> = runs.iter().map(|r| vec![[0.0; 8]; r.len()]).collect();
    // The last block's columns (the values past the last whole run of
    // eight are in it).
    let mut last: Vec<Vec<f64>> = Vec::new();
    let mut first = 0;
    while first < d.rows() {
        let len = DESIGN_BLOCK_ROWS.min(d.rows() - first);
        let half = (len / 2).next_multiple_of(8).min(len);
        let halves = crate::parallel::map(2, 2, |h| {
            let (lo, n) = if h == 0 {
                (first, half)
            } else {
                (first + half, len - half)
            };
            let mut b = Vec::new();
            d.columns_into(lo, n, cols, &mut b);
            (lo, n, b)
        });
        for (lo, n, b) in halves.iter().filter(|(_, n, _)| *n > 0) {
            let h = 3 * n;
            let mut columns: Vec<&[f64]> =
                (0..cols.len()).map(|j| &b[j * h..(j + 1) * h]).collect();
            columns.push(&d.y[3 * lo..3 * (lo + n)]);
            // This piece's whole runs of eight (all of it but for the
            // design's last values).
            let upto = whole.saturating_sub(3 * lo).min(h);
            let _ = crate::parallel::for_each_mut(&mut sums, parts, |k, s| {
                widest(Block {
                    columns: &columns,
                    run: runs[k],
                    sums: s,
                    rows: 0..upto,
                });
                Ok::<(), std::convert::Infallible>(())
            });
            if 3 * (lo + n) == m {
                last = columns[..].iter().map(|c| c[upto..].to_vec()).collect();
            }
        }
        first += len;
    }
    runs.iter()
        .zip(&sums)
        .flat_map(|(run, sums)| run.iter().zip(sums))
        .map(|(&(i, j), s)| {
            let tail = |c: usize| last.get(c).into_iter().flatten().copied();
            finished(s, tail(i).zip(tail(j)))
        })
        .collect()
}

/// A dot from its eight running sums `s` and the values past the last
/// whole run of eight, `tail` (pairs, in order): nalgebra's ending.
fn finished(s: &[f64; 8], tail: impl Iterator<Item = (f64, f64)>) -> f64 {
    let mut r = 0.0;
    r += s[0] + s[4];
    r += s[1] + s[5];
    r += s[2] + s[6];
    r += s[3] + s[7];
    for (a, b) in tail {
        r += a * b;
    }
    r
}

/// Rows of a block of [`design_dots`] (a multiple of eight: its values
/// are whole runs of eight).
const DESIGN_BLOCK_ROWS: usize = 4096;

/// The rows `rows` (whole runs of eight) into every pair's eight sums.
struct Block<'a, 'b> {
    columns: &'a [&'a [f64]],
    run: &'a [(usize, usize)],
    sums: &'b mut [[f64; 8]],
    rows: std::ops::Range<usize>,
}

impl Kernel for Block<'_, '_> {
    type Output = ();

    #[inline(always)]
    fn run(self) {
        for (&(i, j), s) in self.run.iter().zip(self.sums.iter_mut()) {
            let a = &self.columns[i][self.rows.clone()];
            let b = &self.columns[j][self.rows.clone()];
            let mut acc = *s;
            for (x, y) in a.as_chunks::<8>().0.iter().zip(b.as_chunks::<8>().0) {
                for k in 0..8 {
                    acc[k] += x[k] * y[k];
                }
            }
            *s = acc;
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::calibrate::fit::heldout::dots::*;
    use nalgebra::DVector;

    /// A design's columns and `Δp` a block of rows at a time give the
    /// whole columns' dots, bit for bit: rows around the runs of eight
    /// and the blocks, all columns and some.
    #[test]
    fn a_designs_dots_by_blocks_are_the_whole_columns() {
        use crate::calibrate::design::testing::design;
        for rows in [
            1,
            2,
            3,
            7,
            8,
            9,
            100,
            DESIGN_BLOCK_ROWS + 5,
            2 * DESIGN_BLOCK_ROWS + 11,
        ] {
            let d = design(rows, 1, 4, rows as u64);
            for cols in [vec![0, 1, 2, 3], vec![3, 1]] {
                let n = cols.len();
                let b = d.held().select_columns(&cols);
                let m = b.nrows();
                let columns: Vec<&[f64]> = (0..n)
                    .map(|c| &b.as_slice()[c * m..(c + 1) * m])
                    .chain([d.y.as_slice()])
                    .collect();
                let pairs: Vec<(usize, usize)> =
                    (0..n).flat_map(|i| (i..=n).map(move |j| (i, j))).collect();
                for threads in [1, 2, 3] {
                    let want = column_dots(&columns, &pairs, threads);
                    let got = design_dots(&d, &cols, &pairs, threads);
                    let bits = |v: &[f64]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&got), bits(&want), "{rows} rows, {threads} threads");
                }
            }
        }
    }

    /// Against nalgebra's `dot` itself, bit for bit, for lengths around
    /// the runs of eight and the blocks, on one and several threads.
    #[test]
    fn every_dot_is_nalgebras_bit_for_bit() {
        let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for m in [
            0,
            1,
            7,
            8,
            9,
            15,
            16,
            17,
            BLOCK - 1,
            BLOCK,
            BLOCK + 3,
            3 * BLOCK + 13,
        ] {
            let cols: Vec<DVector<f64>> = (0..5)
                .map(|c| DVector::from_fn(m, |_, _| next() * 10f64.powi(c - 2)))
                .collect();
            let columns: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
            let pairs: Vec<(usize, usize)> =
                (0..5).flat_map(|i| (i..5).map(move |j| (i, j))).collect();
            for threads in [1, 2, 3] {
                let got = column_dots(&columns, &pairs, threads);
                for (&(i, j), g) in pairs.iter().zip(&got) {
                    assert_eq!(
                        g.to_bits(),
                        cols[i].dot(&cols[j]).to_bits(),
                        "m {m} ({i}, {j})"
                    );
                }
            }
        }
    }
}
