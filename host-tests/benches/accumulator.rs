//! Host benchmarks of the streaming estimator (criterion): one block update
//! (three rows, unit weights, no σ) and one solve, for N = 9, 30 and 48 in
//! f32 and f64. See BENCHMARKS.md for the numbers and the command.
//!
//! The update is measured on a live accumulator fed from a ring of 64
//! pre-generated blocks (generation is not timed); the solve on an
//! accumulator holding 2N blocks (6N equations) of the same data.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use host_tests::Rng;
use nalgebra::{Const, RealField, SMatrix, Vector3};
use robcal::{Accumulator, Block};

/// Blocks in the ring the update benchmark cycles through.
const RING: usize = 64;

/// Deterministic rows from the project's one generator, uniform in
/// (-1, 1): `Δp = B x` with x = 1e-3 per parameter, plus 10 µm of noise.
fn block<T: RealField + Copy, const N: usize>(rng: &mut Rng) -> Block<T, Const<N>> {
    let b = SMatrix::<f64, 3, N>::from_fn(|_, _| rng.range(-1.0, 1.0));
    let dp = b * SMatrix::<f64, N, 1>::repeat(1e-3)
        + Vector3::from_fn(|_, _| 1e-5 * rng.range(-1.0, 1.0));
    Block::new(b.map(nalgebra::convert), dp.map(nalgebra::convert))
}

fn bench_n<T: RealField + Copy, const N: usize>(c: &mut Criterion, ty: &str) {
    let mut gen = Rng::new(0x5EED_0000 + N as u64);
    let ring: Vec<Block<T, Const<N>>> = (0..RING).map(|_| block(&mut gen)).collect();

    let mut group = c.benchmark_group(format!("update/{ty}"));
    let mut acc = Accumulator::<T, Const<N>>::new();
    let mut k = 0;
    group.bench_function(BenchmarkId::from_parameter(N), |bch| {
        bch.iter(|| {
            k = (k + 1) % RING;
            black_box(&mut acc).update(black_box(&ring[k])).unwrap();
        })
    });
    group.finish();

    let mut full = Accumulator::<T, Const<N>>::new();
    for _ in 0..2 * N {
        full.update(&block(&mut gen)).unwrap();
    }
    let mut group = c.benchmark_group(format!("solve/{ty}"));
    group.bench_function(BenchmarkId::from_parameter(N), |bch| {
        bch.iter(|| black_box(&full).solve().unwrap())
    });
    group.finish();
}

fn benches(c: &mut Criterion) {
    bench_n::<f32, 9>(c, "f32");
    bench_n::<f64, 9>(c, "f64");
    bench_n::<f32, 30>(c, "f32");
    bench_n::<f64, 30>(c, "f64");
    bench_n::<f32, 48>(c, "f32");
    bench_n::<f64, 48>(c, "f64");
}

criterion_group! {
    name = accumulator;
    // Short runs: the machine is shared; the spread is in BENCHMARKS.md.
    config = Criterion::default()
        .warm_up_time(std::time::Duration::from_millis(500))
        .measurement_time(std::time::Duration::from_secs(2));
    targets = benches
}
criterion_main!(accumulator);
