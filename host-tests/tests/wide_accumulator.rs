//! `estimate::wide::WideAccumulator` (issue 16, item 3) against the core's
//! scalar `Accumulator<f64, Dyn>` on the same blocks: every statistic within
//! `1e-12` relative, on every instruction set this processor has (the one
//! detected, AVX2 + FMA, scalar), at N = 1, 2, 3, 7, 9, 30, 60, 61 (and 0,
//! 8, 11, 16, 23, 130: every width of the kernel's last column panel and of
//! the copy's last chunk), with weights (some zero), σ on some blocks, blocks of one and
//! two rows, and stream lengths that end on a full buffer, a partial one and a single
//! block; then every rejected input: the core's error, the statistics
//! unchanged, and the stream going on as if the block had not come.
//!
//! "Relative" for a sum whose terms cancel is relative to the scale of its
//! terms: `|Λᵢⱼ − Λ'ᵢⱼ| ≤ 1e-12 √(Λᵢᵢ Λⱼⱼ)` (Cauchy–Schwarz bounds
//! `Σ |w² bᵢ bⱼ|` by it), `|ηᵢ − η'ᵢ| ≤ 1e-12 √(Λᵢᵢ Σ Δpᵀ W² Δp)`, and the
//! same for `M`; the diagonals and `Σ Δpᵀ W² Δp` plainly relative. The two
//! differ only by fused multiply-adds: a few units of 2⁻⁵³ per row.

use host_tests::Rng;
use nalgebra::{DMatrix, Dyn, OMatrix, Vector3, U3};
use robcal::estimate::wide::{Instructions, WideAccumulator};
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
