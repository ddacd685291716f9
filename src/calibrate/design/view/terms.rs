//! The kernels of a [`crate::calibrate::design::view::View`]'s passes: the rank-3 updates of the
//! upper triangle in row order (by columns, so that threads can share a
//! triangle) and four rows' leverages at once.

use crate::calibrate::design::widest::{widest, Kernel};

/// One row's share of a rank-3 update: its three axes' columns, the factor
/// of each axis (`w²`, or `w⁴σ²` for `M`) and its `Δp`.
pub(in crate::calibrate) struct Term<'a> {
    pub(in crate::calibrate) b: [&'a [f64]; 3],
    pub(in crate::calibrate) k: [f64; 3],
    pub(in crate::calibrate) y: [f64; 3],
}

/// `m[i][j] += Σ_a b_a[i] (k_a b_a[j])` for `i ≤ j` (`m` column-major
/// `n × n`) and `η_j += Σ_a (k_a b_a[j]) y_a`, for every term in order:
/// each element's sum is the core's (`add_upper3`: the three axes left to
/// right, row after row), two rows per pass over the triangle. Only the
/// columns `j` in `columns` (and their `η_j`): each element's sum is the
/// same whichever columns a call takes, so that threads may share the
/// triangle by columns ([`column_shares`]).
///
/// Compiled for the widest instruction set the processor has
/// ([`crate::calibrate::design::widest`]): wider vectors across the elements of a
/// column, each element's arithmetic, and so its bits, those of the
/// baseline build.
pub(super) fn add_terms(
    m: &mut [f64],
    eta: Option<&mut [f64]>,
    n: usize,
    terms: &[Term<'_>],
    columns: std::ops::Range<usize>,
) {
    widest(AddTerms(m, eta, n, terms, columns));
}

/// [`add_terms`] as a [`Kernel`].
struct AddTerms<'m, 't, 'b>(
    &'m mut [f64],
    Option<&'m mut [f64]>,
    usize,
    &'t [Term<'b>],
    std::ops::Range<usize>,
);

impl Kernel for AddTerms<'_, '_, '_> {
    type Output = ();

    #[inline(always)]
    fn run(self) {
        let AddTerms(m, mut eta, n, terms, columns) = self;
        let mut pairs = terms.chunks_exact(2);
        for pair in pairs.by_ref() {
            let (t, u) = (&pair[0], &pair[1]);
            for (j, column) in triangle_columns(m, n, &columns) {
                let a = [t.k[0] * t.b[0][j], t.k[1] * t.b[1][j], t.k[2] * t.b[2][j]];
                let c = [u.k[0] * u.b[0][j], u.k[1] * u.b[1][j], u.k[2] * u.b[2][j]];
                if let Some(e) = eta.as_deref_mut() {
                    let v = ((e[j] + a[0] * t.y[0]) + a[1] * t.y[1]) + a[2] * t.y[2];
                    e[j] = ((v + c[0] * u.y[0]) + c[1] * u.y[1]) + c[2] * u.y[2];
                }
                let tb = (&t.b[0][..=j], &t.b[1][..=j], &t.b[2][..=j]);
                let ub = (&u.b[0][..=j], &u.b[1][..=j], &u.b[2][..=j]);
                for (i, x) in column[..=j].iter_mut().enumerate() {
                    let v = ((*x + tb.0[i] * a[0]) + tb.1[i] * a[1]) + tb.2[i] * a[2];
                    *x = ((v + ub.0[i] * c[0]) + ub.1[i] * c[1]) + ub.2[i] * c[2];
                }
            }
        }
        for t in pairs.remainder() {
            for (j, column) in triangle_columns(m, n, &columns) {
                let a = [t.k[0] * t.b[0][j], t.k[1] * t.b[1][j], t.k[2] * t.b[2][j]];
                if let Some(e) = eta.as_deref_mut() {
                    e[j] = ((e[j] + a[0] * t.y[0]) + a[1] * t.y[1]) + a[2] * t.y[2];
                }
                let tb = (&t.b[0][..=j], &t.b[1][..=j], &t.b[2][..=j]);
                for (i, x) in column[..=j].iter_mut().enumerate() {
                    *x = ((*x + tb.0[i] * a[0]) + tb.1[i] * a[1]) + tb.2[i] * a[2];
                }
            }
        }
    }
}

/// The columns `j` in `columns` of the column-major `n × n` matrix `m`,
/// with their index.
#[inline(always)]
fn triangle_columns<'m>(
    m: &'m mut [f64],
    n: usize,
    columns: &std::ops::Range<usize>,
) -> impl Iterator<Item = (usize, &'m mut [f64])> {
    m.chunks_exact_mut(n.max(1))
        .enumerate()
        .take(columns.end.min(n))
        .skip(columns.start)
}

/// Rows whose leverages [`leverage3_rows`] computes at once.
pub(super) const LANES: usize = 4;

/// `bᵀ Λ⁻¹ b` of the three axes of `LANES` rows (`b[(3k + a) LANES + j]`:
/// column `k`, axis `a`, row `j`; `inv` column-major `p × p`), at
/// `q[a LANES + j]`: for each row and axis the arithmetic of
/// [`crate::estimate::leverage`] (`Σ_c (Σ_r Λ⁻¹_rc b_r) b_c`, both sums in
/// index order), bit for bit; the `3 LANES` sums are independent chains
/// side by side (the processor overlaps them, the compiler may vectorise
/// across them: neither changes any lane's arithmetic).
///
/// Dispatched as [`add_terms`] is (the same bits on any instruction set).
pub(super) fn leverage3_rows(inv: &[f64], p: usize, b: &[f64]) -> [f64; 3 * LANES] {
    widest(Leverage3Rows(inv, p, b))
}

/// [`leverage3_rows`] as a [`Kernel`].
struct Leverage3Rows<'a>(&'a [f64], usize, &'a [f64]);

impl Kernel for Leverage3Rows<'_> {
    type Output = [f64; 3 * LANES];

    #[inline(always)]
    fn run(self) -> [f64; 3 * LANES] {
        let Leverage3Rows(inv, p, b) = self;
        let mut q = [0.0; 3 * LANES];
        let bk = |k: usize| -> &[f64] { &b[3 * LANES * k..3 * LANES * (k + 1)] };
        for (c, col) in inv.chunks_exact(p.max(1)).enumerate().take(p) {
            let mut s = [0.0; 3 * LANES];
            for (r, &v) in col.iter().enumerate() {
                for (s, &x) in s.iter_mut().zip(bk(r)) {
                    *s += v * x;
                }
            }
            for ((q, s), &x) in q.iter_mut().zip(&s).zip(bk(c)) {
                *q += s * x;
            }
        }
        q
    }
}

/// `threads` contiguous runs of the columns `0..n` of an upper triangle
/// with about the same number of elements each (column `j` has `j + 1`):
/// the columns each thread of a pass adds ([`add_terms`]).
pub(super) fn column_shares(n: usize, threads: usize) -> Vec<std::ops::Range<usize>> {
    if n == 0 {
        // One share, of no column (the pass still runs: `Δpᵀ W² Δp`).
        return std::iter::once(0..0).collect();
    }
    let threads = threads.clamp(1, n);
    let total = n * (n + 1) / 2;
    let mut out = Vec::with_capacity(threads);
    let (mut start, mut done) = (0, 0);
    for t in 1..=threads {
        let target = total * t / threads;
        let mut end = start;
        // Columns while the share gets nearer its target (at least one).
        while end < n
            && (end == start
                || done + end < target
                || done + end + 1 - target < target.saturating_sub(done))
        {
            done += end + 1;
            end += 1;
        }
        if t == threads {
            end = n;
        }
        out.push(start..end);
        start = end;
    }
    out.retain(|r| !r.is_empty());
    out
}

#[cfg(test)]
mod tests {
    use crate::calibrate::design::view::terms::*;

    #[test]
    fn shares_cover_the_columns_once_and_balance_the_triangle() {
        for n in 0..40 {
            for threads in 1..5 {
                let shares = column_shares(n, threads);
                assert!(!shares.is_empty() && shares.len() <= threads.max(1));
                assert_eq!(shares[0].start, 0);
                assert_eq!(shares.last().map(|r| r.end), Some(n));
                for w in shares.windows(2) {
                    assert_eq!(w[0].end, w[1].start);
                    assert!(!w[0].is_empty());
                }
                let work = |r: &std::ops::Range<usize>| r.clone().map(|j| j + 1).sum::<usize>();
                if n >= 2 * threads {
                    let (lo, hi) = (
                        shares.iter().map(work).min().unwrap_or(0),
                        shares.iter().map(work).max().unwrap_or(0),
                    );
                    // Each cut within a column of its target.
                    assert!(hi - lo <= 2 * n, "n {n}, threads {threads}: {shares:?}");
                }
            }
        }
    }

    #[test]
    fn columns_added_in_shares_are_the_whole_triangle_bit_for_bit() {
        let n = 11;
        let mut state = 0x9E37_79B9_7F4A_7C15_u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        // Seven rows (three pairs and one alone), each axis its columns.
        let b: Vec<f64> = (0..7 * 3 * n).map(|_| next()).collect();
        let k: Vec<[f64; 3]> = (0..7).map(|_| [next(), next(), next()]).collect();
        let y: Vec<[f64; 3]> = (0..7).map(|_| [next(), next(), next()]).collect();
        let terms: Vec<Term<'_>> = (0..7)
            .map(|r| Term {
                b: [0, 1, 2].map(|a| &b[(3 * r + a) * n..(3 * r + a + 1) * n]),
                k: k[r],
                y: y[r],
            })
            .collect();
        let (mut whole, mut whole_eta) = (vec![0.25; n * n], vec![0.5; n]);
        add_terms(&mut whole, Some(&mut whole_eta), n, &terms, 0..n);
        for threads in 2..5 {
            let (mut m, mut eta) = (vec![0.25; n * n], vec![0.5; n]);
            for share in column_shares(n, threads) {
                add_terms(&mut m, Some(&mut eta), n, &terms, share);
            }
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&m), bits(&whole));
            assert_eq!(bits(&eta), bits(&whole_eta));
        }
    }
}
