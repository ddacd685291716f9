//! A design's unit-weight sums made in the pass that builds it
//! ([`crate::calibrate::design::Design::relinearised`]): each block of
//! [`crate::calibrate::design::view::BLOCK_ROWS`] rows summed from its columns while
//! they are in cache, the blocks merged in order, as
//! [`crate::calibrate::design::view::View::information`] sums and merges them, bit for
//! bit. The Gauss–Newton step at a linearisation then makes no pass of its
//! own over the design for them (at 10⁶ rows a pass is ~0.15 s).

use nalgebra::Dyn;

use crate::calibrate::design::view::{block_sums, merged, Sums, Term, BLOCK_ROWS};
use crate::estimate::Accumulator;

/// One run's rows' columns, a block at a time, and its blocks' sums.
pub(super) struct RunSums {
    /// Rows in the run.
    len: usize,
    /// The block's rows' columns: row `r`'s axis `a` at
    /// `[(3r + a) n..(3r + a + 1) n]` (the view's layout).
    b: Vec<f64>,
    /// The block's rows' `Δp`, scaled as the design's
    /// ([`crate::calibrate::rows::noise_scale`]).
    y: Vec<[f64; 3]>,
    /// The block's rows' axes that are equations (1) or not (0).
    live: Vec<[f64; 3]>,
    /// The run's blocks' sums, in order.
    sums: Vec<Sums>,
}

impl RunSums {
    /// For a run of `len` rows.
    pub(super) fn new(len: usize) -> Self {
        Self {
            len,
            b: Vec::new(),
            y: Vec::new(),
            live: Vec::new(),
            sums: Vec::new(),
        }
    }

    /// Row `k` of the run, axis `a` of its column `c` `at(c, a)` (of `n`
    /// columns), its `Δp` `y` as the design's, `live` its axes that are
    /// equations ([`crate::calibrate::design::Design::live`]).
    pub(super) fn add(
        &mut self,
        n: usize,
        at: impl Fn(usize, usize) -> f64,
        k: usize,
        y: [f64; 3],
        live: [f64; 3],
    ) {
        for a in 0..3 {
            self.b.extend((0..n).map(|c| at(c, a)));
        }
        self.y.push(y);
        self.live.push(live);
        if self.y.len() == BLOCK_ROWS || k + 1 == self.len {
            let b = &self.b;
            let terms = (self.y.iter().zip(&self.live))
                .enumerate()
                .map(|(r, (&y, &k))| Term {
                    b: [0, 1, 2].map(|a| &b[(3 * r + a) * n..(3 * r + a + 1) * n]),
                    k,
                    y,
                });
            self.sums.push(block_sums(n, terms, 0..n, true));
            self.b.clear();
            self.y.clear();
            self.live.clear();
            if k + 1 == self.len {
                // The run's last block: its room goes back (1.5 MB a run of
                // 15 columns, 16 runs at 10⁶ rows).
                self.b = Vec::new();
                self.y = Vec::new();
                self.live = Vec::new();
            }
        }
    }
}

/// Whether runs of `per` rows (of `rows`) start at the view's blocks.
pub(super) fn aligned(rows: usize, per: usize) -> bool {
    per >= rows || per.is_multiple_of(BLOCK_ROWS)
}

/// The unit-weight sums of `n` columns from the runs' blocks, in order:
/// [`crate::calibrate::design::view::View::information`]'s; `None` where it has none.
pub(super) fn merge_runs(n: usize, runs: Vec<RunSums>) -> Option<Accumulator<f64, Dyn>> {
    let blocks = runs
        .into_iter()
        .flat_map(|r| r.sums)
        .map(|s| vec![(0..n, s)])
        .collect();
    merged(n, blocks)
}

#[cfg(test)]
mod tests {
    use crate::calibrate::design::testing::design;
    use crate::calibrate::design::unit_sums::*;
    use crate::calibrate::design::view::View;

    /// Runs of whole blocks, their rows added one by one, give the view's
    /// sums of the design, bit for bit.
    #[test]
    fn runs_of_blocks_sum_as_the_view() {
        let (m, n) = (3 * BLOCK_ROWS + 100, 5);
        let d = design(m, 1, n, 3);
        let cols: Vec<usize> = (0..n).collect();
        let want = View::new(&d, &cols, &[], None)
            .information()
            .expect("finite");
        for per in [BLOCK_ROWS, 2 * BLOCK_ROWS, m] {
            assert!(aligned(m, per));
            let runs = (0..m)
                .step_by(per)
                .map(|first| {
                    let len = per.min(m - first);
                    let mut columns: Vec<Vec<f64>> = (0..n)
                        .map(|c| (0..3 * len).map(|r| d.held()[(3 * first + r, c)]).collect())
                        .collect();
                    let piece: Vec<&mut [f64]> =
                        columns.iter_mut().map(Vec::as_mut_slice).collect();
                    let mut sums = RunSums::new(len);
                    for k in 0..len {
                        let i = first + k;
                        let y = [d.y[3 * i], d.y[3 * i + 1], d.y[3 * i + 2]];
                        sums.add(n, |c, a| piece[c][3 * k + a], k, y, [1.0; 3]);
                    }
                    sums
                })
                .collect();
            let got = merge_runs(n, runs).expect("finite");
            let bits = |v: &[f64]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(got.information().as_slice()),
                bits(want.information().as_slice()),
                "runs of {per}"
            );
            assert_eq!(bits(got.eta().as_slice()), bits(want.eta().as_slice()));
            assert_eq!(got.weighted_yy().to_bits(), want.weighted_yy().to_bits());
            assert_eq!(got.equations(), want.equations());
        }
        assert!(!aligned(m, BLOCK_ROWS + 1) && aligned(m, m + 1));
    }
}
