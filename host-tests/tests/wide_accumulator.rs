//! `estimate::wide::WideAccumulator` (issue 16, item 3) against the core's
//! scalar `Accumulator<f64, Dyn>` on the same blocks: every statistic within
//! `1e-12` relative, on every instruction set this processor has (the one
//! detected, AVX2 + FMA, scalar), at N = 1, 2, 3, 7, 9, 30, 60, 61 (and 0,
//! 8, 11, 16, 23, 130: every width of the kernel's last column panel and of
//! the copy's last chunk), with weights (some zero), σ on some blocks, blocks of one and
//! two rows, and stream lengths that end on a full buffer, a partial one and a single
//! block; then every rejected input: the core's error, the statistics
//! unchanged, and the stream going on as if the block had not come. The
//! batched entry points (`update_many`, `update_rows`) give the same sums as
//! `update` one block at a time, bit for bit, and stop at a bad input with
//! its index, having taken what came before it.
//!
//! "Relative" for a sum whose terms cancel is relative to the scale of its
//! terms: `|Λᵢⱼ − Λ'ᵢⱼ| ≤ 1e-12 √(Λᵢᵢ Λⱼⱼ)` (Cauchy–Schwarz bounds
//! `Σ |w² bᵢ bⱼ|` by it), `|ηᵢ − η'ᵢ| ≤ 1e-12 √(Λᵢᵢ Σ Δpᵀ W² Δp)`, and the
//! same for `M`; the diagonals and `Σ Δpᵀ W² Δp` plainly relative. The two
//! differ only by fused multiply-adds: a few units of 2⁻⁵³ per row.

use host_tests::Rng;
use nalgebra::{DMatrix, Dyn, OMatrix, Vector3, U3};
use robcal::estimate::wide::{Instructions, Rejected, Rows, WideAccumulator};
use robcal::{Accumulator, Block, Error};

/// The sizes, the edges of the 8-column chunks, and one wider than
/// a first-level-cache buffer's minimum (24 rows). `(N + 1) mod 8`, the
/// width of the kernel's last column panel: 2, 3, 4, 0, 1, 2, 4, 1, 0, 7,
/// 5, 6, 3; `N mod 8`, the columns of AVX-512's last chunk before `Δp`
/// (taken from `B`'s last 24 values when `N ≥ 8`): 1, 2, 3, 7, 0, 1, 3, 0,
/// 7, 6, 4, 5, 2.
const SIZES: [usize; 13] = [1, 2, 3, 7, 8, 9, 11, 16, 23, 30, 60, 61, 130];

/// Every instruction set this processor runs.
fn instruction_sets(n: usize) -> Vec<WideAccumulator> {
    [
        Instructions::Detected,
        Instructions::Avx2Fma,
        Instructions::Scalar,
    ]
    .into_iter()
    .filter_map(|i| WideAccumulator::with_instructions(n, i))
    .collect()
}

/// A random block: `B` of mixed scales, `Δp`, weights in (0, 2) with a zero
/// now and then, σ on one block in three, one or two rows on one in seven.
fn block(rng: &mut Rng, n: usize, k: usize) -> Block<f64, Dyn> {
    let b = OMatrix::<f64, U3, Dyn>::from_fn(n, |_, c| {
        rng.normal() * if c % 5 == 0 { 1e3 } else { 1.0 }
    });
    let dp = Vector3::from_fn(|_, _| 1e-3 * rng.normal());
    let mut w = Vector3::from_fn(|_, _| rng.range(0.0, 2.0));
    if k % 11 == 3 {
        w[1] = 0.0;
    }
    let mut blk = Block::new(b, dp).with_weights(w);
    if k % 3 == 1 {
        blk = blk.with_sigma(Vector3::from_fn(|_, _| rng.range(1e-4, 1e-2)));
    }
    if k % 7 == 5 {
        blk.rows = 1 + k % 2;
        // Rows past `rows` are never read: make them poison.
        for r in blk.rows..3 {
            for c in 0..n {
                blk.b[(r, c)] = f64::NAN;
            }
            blk.dp[r] = f64::INFINITY;
            blk.w[r] = -1.0;
        }
    }
    blk
}

/// `|x − y| ≤ tol · scale`, with the position in the message.
#[track_caller]
fn close(what: &str, i: usize, j: usize, x: f64, y: f64, scale: f64) {
    let tol = 1e-12;
    assert!(
        (x - y).abs() <= tol * scale,
        "{what}[{i}, {j}]: wide {x:e}, core {y:e}, scale {scale:e} (difference {:e} relative)",
        (x - y).abs() / scale
    );
}

/// Every statistic of `wide` within 1e-12 (see the module docs) of `core`.
#[track_caller]
fn same_statistics(wide: &Accumulator<f64, Dyn>, core: &Accumulator<f64, Dyn>) {
    assert_eq!(wide.parameters(), core.parameters());
    assert_eq!(wide.equations(), core.equations());
    assert_eq!(wide.sigma_rows(), core.sigma_rows());
    let n = core.parameters();
    let (lw, lc) = (wide.information(), core.information());
    let (mw, mc) = (wide.middle(), core.middle());
    let yy = core.weighted_yy();
    close("yy", 0, 0, wide.weighted_yy(), yy, yy);
    for j in 0..n {
        for i in 0..=j {
            close(
                "Λ",
                i,
                j,
                lw[(i, j)],
                lc[(i, j)],
                (lc[(i, i)] * lc[(j, j)]).sqrt(),
            );
            close(
                "M",
                i,
                j,
                mw[(i, j)],
                mc[(i, j)],
                (mc[(i, i)] * mc[(j, j)]).sqrt(),
            );
        }
        close(
            "η",
            j,
            0,
            wide.eta()[j],
            core.eta()[j],
            (lc[(j, j)] * yy).sqrt(),
        );
    }
}

/// `count` blocks of size `n` into the core and every wide accumulator.
fn stream(n: usize, count: usize, seed: u64) {
    let mut rng = Rng::new(seed);
    let mut core = Accumulator::<f64, Dyn>::zeros(Dyn(n));
    let mut wides = instruction_sets(n);
    assert!(wides.len() >= 2, "at least the detected set and scalar");
    for k in 0..count {
        let blk = block(&mut rng, n, k);
        core.update(&blk).unwrap();
        for wide in &mut wides {
            wide.update(&blk).unwrap();
        }
    }
    for wide in &mut wides {
        let what = wide.instructions();
        let got = wide.accumulator();
        same_statistics(&got, &core);
        // The hand-over is the core's: the same solution, up to the
        // conditioning of Λ (the statistics agree to 1e-12; the solutions to
        // what that moves them, well under 1e-6 σ here).
        if core.equations() > 3 * n {
            let (sw, sc) = (got.solve().unwrap(), core.solve().unwrap());
            let sd = sc.cov_iid().diagonal().map(f64::sqrt);
            for i in 0..n {
                let d = (sw.x[i] - sc.x[i]).abs() / sd[i];
                assert!(d < 1e-6, "{what}: x[{i}] moved {d:e} σ");
            }
        }
        // Streaming on after the hand-over continues the same sums.
        let blk = block(&mut rng.clone(), n, 2);
        let mut more = core.clone();
        more.update(&blk).unwrap();
        wide.update(&blk).unwrap();
        same_statistics(&wide.accumulator(), &more);
    }
}

#[test]
fn matches_the_core_on_full_and_partial_buffers() {
    // 1 block, a partial buffer, exactly several buffers' worth (96 rows =
    // 32 blocks is the largest buffer), and long odd streams.
    for (t, &n) in SIZES.iter().enumerate() {
        for (u, &count) in [1usize, 5, 8, 32, 33, 96, 257].iter().enumerate() {
            stream(n, count, 1000 * t as u64 + u as u64);
        }
    }
}

#[test]
fn matches_the_core_on_a_long_stream() {
    // 10⁴ blocks: the differences grow with the stream, still within 1e-12.
    for n in [9, 60] {
        stream(n, 10_000, 77 + n as u64);
    }
}

#[test]
fn reports_its_instructions() {
    let wide = WideAccumulator::new(9);
    assert!(["avx512", "avx2+fma", "scalar"].contains(&wide.instructions()));
    let scalar = WideAccumulator::with_instructions(9, Instructions::Scalar).unwrap();
    assert_eq!(scalar.instructions(), "scalar");
    let (flops, check) = wide.fma_probe(1000);
    assert!(flops >= 2.0 * 12.0 * 1000.0 && check.is_finite());
}

/// A wide accumulator primed with a few blocks (some with σ), part of them
/// still buffered.
fn primed(
    n: usize,
    instructions: Instructions,
) -> Option<(WideAccumulator, Accumulator<f64, Dyn>)> {
    let mut wide = WideAccumulator::with_instructions(n, instructions)?;
    let mut core = Accumulator::<f64, Dyn>::zeros(Dyn(n));
    let mut rng = Rng::new(5);
    for k in 0..40 {
        let blk = block(&mut rng, n, k);
        wide.update(&blk).unwrap();
        core.update(&blk).unwrap();
    }
    Some((wide, core))
}

/// `update(bad)` fails as the core's does and changes no statistic; good
/// blocks after it give the core's sums without it.
#[track_caller]
fn rejects(n: usize, bad: &Block<f64, Dyn>) {
    for instructions in [Instructions::Detected, Instructions::Scalar] {
        let (mut wide, mut core) = primed(n, instructions).unwrap();
        let before = wide.clone().accumulator();
        let expected = core.clone().update(bad).unwrap_err();
        assert_eq!(
            wide.update(bad).unwrap_err(),
            expected,
            "{}",
            wide.instructions()
        );
        assert_eq!(wide.clone().accumulator(), before, "state changed");
        assert_eq!(wide.equations(), core.equations());
        let mut rng = Rng::new(9);
        for k in 0..50 {
            let blk = block(&mut rng, n, k);
            wide.update(&blk).unwrap();
            core.update(&blk).unwrap();
        }
        same_statistics(&wide.accumulator(), &core);
    }
}

#[test]
fn rejects_what_the_core_rejects_and_keeps_its_state() {
    for n in [3, 9, 30] {
        let good = || {
            let b = OMatrix::<f64, U3, Dyn>::from_fn(n, |r, c| (r * n + c) as f64 * 0.25 - 1.0);
            Block::new(b, Vector3::new(0.1, 0.2, 0.3))
                .with_weights(Vector3::repeat(1.0))
                .with_sigma(Vector3::repeat(1e-3))
        };
        let with = |f: &dyn Fn(&mut Block<f64, Dyn>)| {
            let mut b = good();
            f(&mut b);
            b
        };
        rejects(n, &with(&|b| b.b[(1, n - 1)] = f64::NAN));
        rejects(n, &with(&|b| b.b[(2, 0)] = f64::INFINITY));
        rejects(n, &with(&|b| b.dp[0] = f64::NEG_INFINITY));
        rejects(n, &with(&|b| b.w[1] = -0.5));
        rejects(n, &with(&|b| b.w[2] = f64::NAN));
        rejects(n, &with(&|b| b.w[0] = f64::INFINITY));
        rejects(n, &with(&|b| b.sigma = Some(Vector3::new(1e-3, 0.0, 1e-3))));
        rejects(
            n,
            &with(&|b| b.sigma = Some(Vector3::new(1e-3, f64::NAN, 1e-3))),
        );
        rejects(n, &with(&|b| b.rows = 0));
        rejects(n, &with(&|b| b.rows = 4));
        // A weight of zero does not excuse a non-finite value (0·∞).
        rejects(
            n,
            &with(&|b| {
                b.w[1] = 0.0;
                b.b[(1, 0)] = f64::INFINITY;
            }),
        );
        // Finite but the sums would overflow (b² ≈ 1e308 summed).
        rejects(n, &with(&|b| b.b.fill(1e154)));
        rejects(n, &with(&|b| b.w.fill(1e160)));
        // w² = ∞ on a row of zeros: the core's `b (w² b)` is NaN there.
        rejects(
            n,
            &with(&|b| {
                b.w[0] = 1e155;
                b.b.row_mut(0).fill(0.0);
                b.dp[0] = 0.0;
            }),
        );
        // The wrong size.
        let other = Block::new(OMatrix::<f64, U3, Dyn>::zeros(n + 1), Vector3::zeros());
        rejects(n, &other);
        assert!(matches!(
            WideAccumulator::new(n).update(&other),
            Err(Error::Mismatch { .. })
        ));
    }
}

#[test]
fn large_finite_values_are_accepted_as_by_the_core() {
    // b ≈ 1e150 (each b² ≈ 1e300) passes the cheap running bound; b ≈ 1e153
    // (the sums ≈ 1e307) fails it, and the exact check accepts, in both.
    // With and without σ, on an empty and on a primed accumulator.
    let n = 9;
    for scale in [1e150, 1e153] {
        for sigma in [false, true] {
            let b =
                OMatrix::<f64, U3, Dyn>::from_fn(n, |r, c| scale * (1.0 + (r + c) as f64 * 0.01));
            let mut blk = Block::new(b, Vector3::new(1.0, 2.0, 3.0));
            if sigma {
                blk = blk.with_sigma(Vector3::repeat(1e-3));
            }
            let mut core = Accumulator::<f64, Dyn>::zeros(Dyn(n));
            core.update(&blk).unwrap();
            for mut wide in instruction_sets(n) {
                wide.update(&blk).unwrap();
                same_statistics(&wide.accumulator(), &core);
            }
            for instructions in [Instructions::Detected, Instructions::Scalar] {
                let (mut wide, mut core) = primed(n, instructions).unwrap();
                core.update(&blk).unwrap();
                wide.update(&blk).unwrap();
                same_statistics(&wide.accumulator(), &core);
            }
        }
    }
}

#[test]
fn a_million_blocks_renew_the_running_bound() {
    // The running bound grows by 2⁻¹⁰ per update (the core's margin) and
    // reaches its limit after ~7·10⁵ updates: the exact check then renews
    // it, as the core's does. Both take that path on this stream.
    let n = 2;
    let mut rng = Rng::new(11);
    let ring: Vec<_> = (0..97).map(|k| block(&mut rng, n, 3 * k)).collect();
    let mut core = Accumulator::<f64, Dyn>::zeros(Dyn(n));
    let mut wide = WideAccumulator::new(n);
    for k in 0..1_000_000 {
        core.update(&ring[k % ring.len()]).unwrap();
        wide.update(&ring[k % ring.len()]).unwrap();
    }
    same_statistics(&wide.accumulator(), &core);
}

#[test]
fn no_parameters_still_sums_the_measurements() {
    // N = 0: only Σ Δpᵀ W² Δp and the counts.
    let mut rng = Rng::new(3);
    let mut core = Accumulator::<f64, Dyn>::zeros(Dyn(0));
    let mut wides = instruction_sets(0);
    for k in 0..100 {
        let blk = block(&mut rng, 0, k);
        core.update(&blk).unwrap();
        for wide in &mut wides {
            wide.update(&blk).unwrap();
        }
    }
    for wide in &mut wides {
        same_statistics(&wide.accumulator(), &core);
    }
}

#[test]
fn reset_forgets_everything() {
    let (mut wide, _) = primed(7, Instructions::Detected).unwrap();
    wide.reset();
    let empty = Accumulator::<f64, Dyn>::zeros(Dyn(7));
    let got = wide.accumulator();
    assert_eq!(got.information(), DMatrix::zeros(7, 7));
    assert_eq!(got.equations(), empty.equations());
    assert_eq!(got.weighted_yy(), 0.0);
}

/// Blocks' used rows, row-major, for `update_rows`.
#[derive(Default, Clone)]
struct RowData {
    n: usize,
    b: Vec<f64>,
    dp: Vec<f64>,
    w: Vec<f64>,
    sigma: Option<Vec<f64>>,
}

impl RowData {
    fn new(n: usize, sigma: bool) -> Self {
        Self {
            n,
            sigma: sigma.then(Vec::new),
            ..Self::default()
        }
    }

    /// The rows of `blk` (which carries σ exactly when these rows do).
    fn push(&mut self, blk: &Block<f64, Dyn>) {
        assert_eq!(blk.sigma.is_some(), self.sigma.is_some());
        for r in 0..blk.rows {
            self.b.extend((0..self.n).map(|c| blk.b[(r, c)]));
            self.dp.push(blk.dp[r]);
            self.w.push(blk.w[r]);
            if let (Some(s), Some(bs)) = (self.sigma.as_mut(), blk.sigma) {
                s.push(bs[r]);
            }
        }
    }

    fn rows(&self) -> Rows<'_> {
        self.slice(0, self.dp.len())
    }

    /// Rows `from .. to`.
    fn slice(&self, from: usize, to: usize) -> Rows<'_> {
        Rows {
            b: &self.b[from * self.n..to * self.n],
            dp: &self.dp[from..to],
            w: &self.w[from..to],
            sigma: self.sigma.as_ref().map(|s| &s[from..to]),
        }
    }
}

/// `blocks` through `update_rows`: runs of blocks with and without σ, each
/// run in calls of `step` rows (the last shorter).
fn feed_rows(wide: &mut WideAccumulator, blocks: &[Block<f64, Dyn>], step: usize) {
    let n = wide.parameters();
    let mut k = 0;
    while k < blocks.len() {
        let sigma = blocks[k].sigma.is_some();
        let mut data = RowData::new(n, sigma);
        while k < blocks.len() && blocks[k].sigma.is_some() == sigma {
            data.push(&blocks[k]);
            k += 1;
        }
        let len = data.dp.len();
        for from in (0..len).step_by(step) {
            wide.update_rows(data.slice(from, (from + step).min(len)))
                .unwrap();
        }
    }
}

#[test]
fn batched_updates_give_the_same_bits_as_one_block_at_a_time() {
    for (t, &n) in [0].iter().chain(&SIZES).enumerate() {
        for (u, &count) in [1usize, 5, 33, 257].iter().enumerate() {
            let mut rng = Rng::new(500 + 100 * t as u64 + u as u64);
            let blocks: Vec<_> = (0..count).map(|k| block(&mut rng, n, k)).collect();
            let mut core = Accumulator::<f64, Dyn>::zeros(Dyn(n));
            for blk in &blocks {
                core.update(blk).unwrap();
            }
            for one in instruction_sets(n) {
                let what = one.instructions();
                let mut one = one;
                for blk in &blocks {
                    one.update(blk).unwrap();
                }
                let expected = one.accumulator();
                same_statistics(&expected, &core);
                for step in [1, 7, 1000] {
                    let mut many = one.clone();
                    many.reset();
                    for part in blocks.chunks(step) {
                        many.update_many(part).unwrap();
                    }
                    assert_eq!(many.accumulator(), expected, "{what} update_many, {step}");
                    let mut rows = one.clone();
                    rows.reset();
                    feed_rows(&mut rows, &blocks, 3 * step + 1);
                    assert_eq!(rows.accumulator(), expected, "{what} update_rows, {step}");
                }
            }
        }
    }
}

/// Long runs of rows without σ, many buffers' worth: `update_rows` flushes
/// after fewer rows than `update` at some N (`ROWS_BYTES` in `wide.rs`).
/// Every N from 0 to 130 (every width of the last panel and chunk, every
/// buffer size), every instruction set: the same bits as `update` one
/// block at a time, in calls of many sizes, around a short run with σ, and
/// mixed with `update` (whose buffer can hold more rows than
/// `update_rows` fills: the rows find it fuller than their own limit).
#[test]
fn update_rows_in_long_runs_gives_the_same_bits_as_update() {
    for n in 0..=130 {
        let mut rng = Rng::new(9000 + n as u64);
        let blocks: Vec<_> = (0..150)
            .map(|k| {
                let mut blk = block(&mut rng, n, k);
                if !(60..64).contains(&k) {
                    blk.sigma = None;
                }
                blk
            })
            .collect();
        let mut core = Accumulator::<f64, Dyn>::zeros(Dyn(n));
        for blk in &blocks {
            core.update(blk).unwrap();
        }
        for one in instruction_sets(n) {
            let what = one.instructions();
            let mut one = one;
            for blk in &blocks {
                one.update(blk).unwrap();
            }
            let expected = one.accumulator();
            same_statistics(&expected, &core);
            for step in [1, 50, 64, 97, 1000] {
                let mut rows = one.clone();
                rows.reset();
                feed_rows(&mut rows, &blocks, step);
                assert_eq!(rows.accumulator(), expected, "{what} n {n} step {step}");
            }
            // Blocks through `update` and runs of rows through
            // `update_rows`, in turn.
            let mut mixed = one.clone();
            mixed.reset();
            for (k, part) in blocks.chunks(40).enumerate() {
                if k % 2 == 0 {
                    for blk in part {
                        mixed.update(blk).unwrap();
                    }
                } else {
                    feed_rows(&mut mixed, part, 1000);
                }
            }
            assert_eq!(mixed.accumulator(), expected, "{what} n {n} mixed");
        }
    }
}

#[test]
fn update_many_stops_at_a_bad_block_with_its_index() {
    for n in [3, 9, 30] {
        let mut rng = Rng::new(31 + n as u64);
        let mut blocks: Vec<_> = (0..40).map(|k| block(&mut rng, n, k)).collect();
        let bad = 23;
        blocks[bad].b[(0, n - 1)] = f64::NAN;
        for instructions in [Instructions::Detected, Instructions::Scalar] {
            let (mut many, _) = primed(n, instructions).unwrap();
            let mut one = many.clone();
            let err = many.update_many(&blocks).unwrap_err();
            let expected = one.clone().update(&blocks[bad]).unwrap_err();
            assert_eq!(
                err,
                Rejected {
                    index: bad,
                    error: expected
                }
            );
            for blk in &blocks[..bad] {
                one.update(blk).unwrap();
            }
            assert_eq!(many.clone().accumulator(), one.clone().accumulator());
            assert_eq!(many.equations(), one.equations());
            // Going on past it: as if it had not come.
            many.update_many(&blocks[bad + 1..]).unwrap();
            for blk in &blocks[bad + 1..] {
                one.update(blk).unwrap();
            }
            assert_eq!(many.accumulator(), one.accumulator());
        }
        // An empty batch changes nothing; a wrong size is refused at its index.
        let mut wide = WideAccumulator::new(n);
        wide.update_many(&[]).unwrap();
        let other = Block::new(OMatrix::<f64, U3, Dyn>::zeros(n + 1), Vector3::zeros());
        let err = wide.update_many(&[blocks[0].clone(), other]).unwrap_err();
        assert_eq!(err.index, 1);
        assert!(matches!(err.error, Error::Mismatch { .. }));
        assert_eq!(
            wide.equations(),
            blocks[0].w.iter().filter(|w| **w > 0.0).count()
        );
    }
}

/// A change that makes one row bad.
type Edit = Box<dyn Fn(&mut RowData)>;

/// A block of one row: `b`, `Δp`, `w`, `σ` (the other rows poison).
fn one_row(b: &[f64], dp: f64, w: f64, sigma: Option<f64>) -> Block<f64, Dyn> {
    let n = b.len();
    let m = OMatrix::<f64, U3, Dyn>::from_fn(n, |r, c| if r == 0 { b[c] } else { f64::NAN });
    let mut blk = Block::new(m, Vector3::new(dp, f64::NAN, f64::NAN))
        .with_weights(Vector3::new(w, -1.0, -1.0));
    if let Some(s) = sigma {
        blk = blk.with_sigma(Vector3::new(s, -1.0, -1.0));
    }
    blk.rows = 1;
    blk
}

#[test]
fn update_rows_stops_at_a_bad_row_with_the_error_of_update() {
    // Row 61 of 120: in the first buffer; row 300 of 420: several
    // flushes later.
    for (blocks, bad) in [(40, 61), (140, 300)] {
        bad_row(blocks, bad);
    }
}

/// `blocks` blocks' rows with row `bad` made bad in every way, at N = 3,
/// 9, 30, 60, with and without σ.
fn bad_row(blocks: usize, bad: usize) {
    for n in [3, 9, 30, 60] {
        for sigma in [false, true] {
            let mut rng = Rng::new(77 + n as u64);
            let mut data = RowData::new(n, sigma);
            for k in 0..blocks {
                // 7k + 1: never a block of fewer rows (poisoned past them).
                let mut blk = block(&mut rng, n, 7 * k + 1);
                assert_eq!(blk.rows, 3);
                blk.sigma = sigma.then(|| Vector3::from_fn(|_, _| rng.range(1e-4, 1e-2)));
                data.push(&blk);
            }
            let edits: Vec<Edit> = vec![
                Box::new(move |d| d.b[bad * n + n / 2] = f64::NAN),
                Box::new(move |d| d.b[bad * n] = f64::INFINITY),
                Box::new(move |d| d.dp[bad] = f64::NEG_INFINITY),
                Box::new(move |d| d.w[bad] = -0.5),
                Box::new(move |d| d.w[bad] = f64::NAN),
                Box::new(move |d| d.w[bad] = f64::INFINITY),
                Box::new(move |d| {
                    d.w[bad] = 0.0;
                    d.b[bad * n] = f64::INFINITY;
                }),
                // Finite, but the sums would overflow.
                Box::new(move |d| d.b[bad * n..(bad + 1) * n].fill(1e160)),
                Box::new(move |d| d.w[bad] = 1e160),
                // w² = ∞ on a row of zeros: the core's `b (w² b)` is NaN.
                Box::new(move |d| {
                    d.w[bad] = 1e155;
                    d.b[bad * n..(bad + 1) * n].fill(0.0);
                    d.dp[bad] = 0.0;
                }),
                Box::new(move |d| {
                    if let Some(s) = d.sigma.as_mut() {
                        s[bad] = 0.0;
                    }
                }),
                Box::new(move |d| {
                    if let Some(s) = d.sigma.as_mut() {
                        s[bad] = f64::NAN;
                    }
                }),
            ];
            for edit in &edits {
                let mut data = data.clone();
                edit(&mut data);
                let row = one_row(
                    &data.b[bad * n..(bad + 1) * n],
                    data.dp[bad],
                    data.w[bad],
                    data.sigma.as_ref().map(|s| s[bad]),
                );
                for instructions in [Instructions::Detected, Instructions::Scalar] {
                    let (mut wide, mut core) = primed(n, instructions).unwrap();
                    let mut expected = wide.clone();
                    let got = wide.update_rows(data.rows());
                    let Err(err) = expected.update(&row) else {
                        // Not a bad row after all (σ edits without σ).
                        got.unwrap();
                        continue;
                    };
                    assert_eq!(core.clone().update(&row).unwrap_err(), err);
                    assert_eq!(
                        got.unwrap_err(),
                        Rejected {
                            index: bad,
                            error: err
                        }
                    );
                    let mut before = expected.clone();
                    before.update_rows(data.slice(0, bad)).unwrap();
                    assert_eq!(wide.clone().accumulator(), before.clone().accumulator());
                    assert_eq!(wide.equations(), before.equations());
                    // Going on past it: as if it had not come.
                    let len = data.dp.len();
                    wide.update_rows(data.slice(bad + 1, len)).unwrap();
                    before.update_rows(data.slice(bad + 1, len)).unwrap();
                    assert_eq!(wide.clone().accumulator(), before.accumulator());
                    // And as the core with the same rows, one-row blocks.
                    for i in (0..len).filter(|&i| i != bad) {
                        let s = data.sigma.as_ref().map(|s| s[i]);
                        let r = one_row(&data.b[i * n..(i + 1) * n], data.dp[i], data.w[i], s);
                        core.update(&r).unwrap();
                    }
                    same_statistics(&wide.accumulator(), &core);
                }
            }
        }
    }
}

#[test]
fn update_rows_refuses_lengths_that_disagree_and_takes_nothing() {
    let n = 9;
    let mut rng = Rng::new(4);
    let mut data = RowData::new(n, true);
    for k in 0..5 {
        let mut blk = block(&mut rng, n, 3 * k + 1);
        blk.rows = 3;
        data.push(&blk);
    }
    let (mut wide, _) = primed(n, Instructions::Detected).unwrap();
    let before = wide.clone().accumulator();
    let rows = data.rows();
    let short = |f: &dyn Fn(&mut Rows)| {
        let mut r = rows;
        f(&mut r);
        r
    };
    for bad in [
        short(&|r| r.b = &r.b[1..]),
        short(&|r| r.w = &r.w[1..]),
        short(&|r| r.dp = &r.dp[1..]),
        short(&|r| r.sigma = r.sigma.map(|s| &s[1..])),
    ] {
        let err = wide.update_rows(bad).unwrap_err();
        assert_eq!(err.index, 0);
        assert!(matches!(err.error, Error::Mismatch { .. }));
        assert_eq!(wide.clone().accumulator(), before);
    }
    // No rows: nothing changes.
    wide.update_rows(data.slice(0, 0)).unwrap();
    assert_eq!(wide.clone().accumulator(), before);
    assert!(data.slice(0, 0).is_empty() && data.rows().len() == 15);
}

#[test]
fn update_rows_takes_large_finite_values_as_update_does() {
    // b ≈ 1e153: the running bound fails, the exact check accepts.
    let n = 9;
    for scale in [1e150, 1e153] {
        for sigma in [false, true] {
            let b =
                OMatrix::<f64, U3, Dyn>::from_fn(n, |r, c| scale * (1.0 + (r + c) as f64 * 0.01));
            let mut blk = Block::new(b, Vector3::new(1.0, 2.0, 3.0));
            if sigma {
                blk = blk.with_sigma(Vector3::repeat(1e-3));
            }
            let mut data = RowData::new(n, sigma);
            data.push(&blk);
            for mut wide in instruction_sets(n) {
                let mut one = wide.clone();
                one.update(&blk).unwrap();
                wide.update_rows(data.rows()).unwrap();
                assert_eq!(wide.accumulator(), one.accumulator());
            }
        }
    }
}

#[test]
fn update_rows_checks_the_weights_of_every_row_position() {
    // The weights are checked eight rows a vector, then the rest one by
    // one: a bad weight or σ at each of the 20 positions of a call (two
    // vectors and a tail of four), and zero weights, which count no
    // equation, at each position.
    let edits: [Weights; 7] = [
        |w, _| *w = -0.5,
        |w, _| *w = f64::NAN,
        |w, _| *w = 1e160,
        |w, _| *w = 0.0,
        |_, s| *s = 0.0,
        |_, s| *s = f64::NAN,
        // w⁴σ² = ∞, w² and σ finite.
        |w, s| (*w, *s) = (1e80, 1e10),
    ];
    for n in [9, 30] {
        weights_at_every_position(n, &edits, true, 0);
        // Without σ, after 2016 rows (a multiple of 48, 63, 72 and 96:
        // the buffer full), so that the call starts with a flush.
        weights_at_every_position(n, &edits[..4], false, 2016);
    }
}

type Weights = fn(&mut f64, &mut f64);

/// Each of `edits` at each of the 20 rows of one call, after `before`
/// good rows without σ.
fn weights_at_every_position(n: usize, edits: &[Weights], sigma: bool, before: usize) {
    {
        let mut rng = Rng::new(31 + n as u64);
        let mut good = RowData::new(n, false);
        for k in 0..before / 3 {
            let mut blk = block(&mut rng, n, 7 * k + 1);
            blk.sigma = None;
            good.push(&blk);
        }
        let mut data = RowData::new(n, sigma);
        for k in 0..7 {
            let mut blk = block(&mut rng, n, 7 * k + 1);
            blk.sigma = Some(Vector3::from_fn(|_, _| rng.range(1e-4, 1e-2)));
            if !sigma {
                blk.sigma = None;
            }
            data.push(&blk);
        }
        data.w.iter_mut().for_each(|w| *w = w.max(0.25));
        for edit in edits {
            for bad in 0..20 {
                let mut data = data.clone();
                let mut s = data.sigma.as_ref().map_or(1.0, |s| s[bad]);
                let mut w = data.w[bad];
                edit(&mut w, &mut s);
                data.w[bad] = w;
                if let Some(sig) = data.sigma.as_mut() {
                    sig[bad] = s;
                }
                for instructions in [Instructions::Detected, Instructions::Scalar] {
                    let Some(mut wide) = WideAccumulator::with_instructions(n, instructions) else {
                        continue;
                    };
                    if before > 0 {
                        wide.update_rows(good.rows()).unwrap();
                    }
                    let mut expected = wide.clone();
                    let got = wide.update_rows(data.slice(0, 20));
                    let mut refused = None;
                    for i in 0..20 {
                        let s = data.sigma.as_ref().map(|s| s[i]);
                        let r = one_row(&data.b[i * n..(i + 1) * n], data.dp[i], data.w[i], s);
                        if let Err(error) = expected.update(&r) {
                            refused = Some(Rejected { index: i, error });
                            break;
                        }
                    }
                    assert_eq!(got.err(), refused, "n {n} row {bad}");
                    assert_eq!(wide.equations(), expected.equations());
                    assert_eq!(wide.accumulator(), expected.accumulator());
                }
            }
        }
    }
}
