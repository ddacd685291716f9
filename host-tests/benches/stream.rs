//! Host benchmarks of the streaming update (issue 16, item 3), criterion:
//! the core's scalar `Accumulator<f64, Dyn>` against
//! `estimate::wide::WideAccumulator` (blocked rank-k updates with SIMD
//! dispatched at run time) at N = 9, 30 and 60 — one update per block (a
//! live accumulator fed from a ring of 1000 weighted blocks; the wide one's
//! flush every few dozen rows amortised in it) and 10⁶ blocks streamed from
//! the same ring (through `update`, `update_many` a ring at a time, and
//! `update_rows` on the ring's rows row-major) — and the machine's FMA peak through the same dispatch
//! (independent FMA chains). Throughputs are in flops ("elem/s" is
//! FLOP/s): 3·N(N+1)/2·2 per block for the upper triangle of `Λ` plus
//! 3·N·2 for `η`; the peak probe's own count.
//!
//! ```text
//! cargo bench -p host-tests --bench stream
//! ```
//!
//! `bench/peers/run.sh --stream` measures the same streams interleaved with
//! numpy's normal equations; BENCHMARKS.md ("Streaming update on the host: SIMD") has the numbers.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use nalgebra::Dyn;
use robcal::estimate::wide::{Instructions, Rows, WideAccumulator};
use robcal::{Accumulator, Block};

/// Distinct blocks the updates cycle through.
const RING: usize = 1000;
/// Blocks of the streamed runs.
const BLOCKS: usize = 1_000_000;

fn ring(n: usize) -> Vec<Block<f64, Dyn>> {
    host_tests::stream_ring(n, RING)
}

/// The blocks' rows row-major: `b` (rows × N), `Δp`, `w`.
fn row_major(ring: &[Block<f64, Dyn>]) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (mut b, mut dp, mut w) = (Vec::new(), Vec::new(), Vec::new());
    for blk in ring {
        for r in 0..3 {
            b.extend(blk.b.row(r).iter());
            dp.push(blk.dp[r]);
            w.push(blk.w[r]);
        }
    }
    (b, dp, w)
}

/// Useful flops of one block: `Λ`'s upper triangle and `η`.
fn flops(n: usize) -> u64 {
    (3 * n * (n + 1) / 2 * 2 + 3 * n * 2) as u64
}

fn bench_n(c: &mut Criterion, n: usize) {
    let ring = ring(n);
    let mut group = c.benchmark_group("update");
    group.throughput(Throughput::Elements(flops(n)));
    let mut core = Accumulator::<f64, Dyn>::zeros(Dyn(n));
    let mut k = 0;
    group.bench_function(BenchmarkId::new("core", n), |b| {
        b.iter(|| {
            k = (k + 1) % RING;
            black_box(&mut core).update(black_box(&ring[k])).unwrap();
        })
    });
    // The detected instructions, and AVX2 + FMA where it is not what was
    // detected (on an AVX-512 machine: what a machine without it gets).
    let mut wides = vec![WideAccumulator::new(n)];
    wides.extend(WideAccumulator::with_instructions(n, Instructions::Avx2Fma));
    wides.dedup_by_key(|w| w.instructions());
    for mut wide in wides {
        let id = BenchmarkId::new(format!("wide-{}", wide.instructions()), n);
        group.bench_function(id, |b| {
            b.iter(|| {
                k = (k + 1) % RING;
                black_box(&mut wide).update(black_box(&ring[k])).unwrap();
            })
        });
    }
    group.finish();

    let mut group = c.benchmark_group("stream-1e6");
    group.sample_size(10);
    group.throughput(Throughput::Elements(flops(n) * BLOCKS as u64));
    group.bench_function(BenchmarkId::new("core", n), |b| {
        b.iter(|| {
            let mut acc = Accumulator::<f64, Dyn>::zeros(Dyn(n));
            for k in 0..BLOCKS {
                acc.update(&ring[k % RING]).unwrap();
            }
            black_box(acc)
        })
    });
    group.bench_function(BenchmarkId::new("wide", n), |b| {
        b.iter(|| {
            let mut acc = WideAccumulator::new(n);
            for k in 0..BLOCKS {
                acc.update(&ring[k % RING]).unwrap();
            }
            black_box(acc.accumulator())
        })
    });
    // The batched entry points on the same stream: a slice of blocks (the
    // ring) a call, and the ring's rows row-major a call.
    group.bench_function(BenchmarkId::new("wide-many", n), |b| {
        b.iter(|| {
            let mut acc = WideAccumulator::new(n);
            for _ in 0..BLOCKS / RING {
                acc.update_many(&ring).unwrap();
            }
            black_box(acc.accumulator())
        })
    });
    let (rb, rdp, rw) = row_major(&ring);
    group.bench_function(BenchmarkId::new("wide-rows", n), |b| {
        b.iter(|| {
            let mut acc = WideAccumulator::new(n);
            let rows = Rows {
                b: &rb,
                dp: &rdp,
                w: &rw,
                sigma: None,
            };
            for _ in 0..BLOCKS / RING {
                acc.update_rows(rows).unwrap();
            }
            black_box(acc.accumulator())
        })
    });
    group.finish();
}

/// The peak probe, at the start and at the end (`when`) of the run, on the
/// detected instructions and on AVX2 + FMA.
fn peak(c: &mut Criterion, when: &str) {
    let mut probes = vec![WideAccumulator::new(1)];
    probes.extend(WideAccumulator::with_instructions(1, Instructions::Avx2Fma));
    probes.dedup_by_key(|w| w.instructions());
    let iterations = 1_000_000;
    let mut group = c.benchmark_group("fma-peak");
    for probe in probes {
        let (flops, _) = probe.fma_probe(iterations);
        group.throughput(Throughput::Elements(flops as u64));
        group.bench_function(BenchmarkId::new(probe.instructions(), when), |b| {
            b.iter(|| black_box(probe.fma_probe(black_box(iterations))))
        });
    }
    group.finish();
}

fn benches(c: &mut Criterion) {
    peak(c, "first");
    for n in [9, 30, 60] {
        bench_n(c, n);
    }
    peak(c, "last");
}

criterion_group! {
    name = stream;
    // Short runs: the machine is shared; ratios come from bench/peers.
    config = Criterion::default()
        .warm_up_time(std::time::Duration::from_millis(500))
        .measurement_time(std::time::Duration::from_secs(2));
    targets = benches
}
criterion_main!(stream);
