//! Host benchmarks of the paper's experiment (section 5, 270 deflections,
//! 810 rows, N = 9, 15 configurations): the iterative WLS as the firmware
//! runs it, and in the same run a dense batch baseline. See BENCHMARKS.md.
//!
//! - `irls/stream`: the firmware's streaming source (`examples/firmware/kr270.rs`)
//!   in f64: every pass recomputes the rows from the joint angles (15
//!   forward kinematics) and takes each marker's repetitions together, one
//!   pass per fit (residual σ, sandwich, the next fit's `Λ`, `η`); memory
//!   O(N² + G).
//! - `irls/grouped`: `GroupedStats<f64, 9, 15>` built once from the rows
//!   (included in the time), then re-weighted from the statistics.
//! - `irls/dense_qr`: the same iteration on the stored 810 × 9 matrix
//!   (nalgebra `DMatrix`): each fit is a Householder QR of `W B` and `W Δp`,
//!   residuals from `Δp − B x̂`, the sandwich middle `(W² Σ B)ᵀ (W² Σ B)`.
//!   Rows are computed once, outside the timing (the baseline is the batch
//!   solver, not the model).
//! - `wls/*`: one weighted fit (no iteration): streamed pass + solve vs dense
//!   QR, with the weights of the first WLS step (the source's generic
//!   `weighted` pass: every deflection through an `Accumulator`).

#[allow(dead_code)]
#[path = "../../examples/firmware/kr270.rs"]
mod kr270;

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use kr270::{Dn, Kr270, G, N};
use nalgebra::{DMatrix, DVector, Vector3};
use robcal::estimate::{robust_weights, IrlsSettings, Reweightable};

/// The data as a dense problem: 810 rows, their group, and `Δp`.
struct Dense {
    b: DMatrix<f64>,
    y: DVector<f64>,
    group: Vec<usize>,
}

impl Dense {
    fn new(src: &Kr270<f64>) -> Self {
        let mut rows = Vec::new();
        let mut y = Vec::new();
        let mut group = Vec::new();
        src.stream(|g, b, dp| {
            for a in 0..3 {
                rows.extend(b.row(a).iter().copied());
                y.push(dp[a]);
                group.push(g);
            }
            Ok(())
        })
        .unwrap();
        Self {
            b: DMatrix::from_row_iterator(y.len(), N, rows),
            y: DVector::from_vec(y),
            group,
        }
    }

    /// Weighted least squares by QR of `W B`; returns `x̂` and `Λ⁻¹`.
    fn wls(&self, w: &[Vector3<f64>]) -> (DVector<f64>, DMatrix<f64>) {
        let m = self.b.nrows();
        let wr = DVector::from_fn(m, |r, _| w[self.group[r]][r % 3]);
        let mut bw = self.b.clone();
        for (r, mut row) in bw.row_iter_mut().enumerate() {
            row *= wr[r];
        }
        let mut yw = self.y.component_mul(&wr);
        let qr = bw.qr();
        qr.q_tr_mul(&mut yw);
        let r = qr.r();
        let x = r
            .solve_upper_triangular(&yw.rows(0, N).into_owned())
            .expect("full rank");
        let r_inv = r
            .solve_upper_triangular(&DMatrix::identity(N, N))
            .expect("full rank");
        (x, &r_inv * r_inv.transpose())
    }

    /// σ per group and axis of the residuals of the fit `x`, `Λ⁻¹` made
    /// with weights `w`: `RSS / (n − h)`, `h` the group and axis's part of
    /// the trace of the hat matrix; and those degrees of freedom.
    fn sigma(
        &self,
        x: &DVector<f64>,
        li: &DMatrix<f64>,
        w: &[Vector3<f64>],
    ) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
        let r = &self.y - &self.b * x;
        let mut s = vec![Vector3::<f64>::zeros(); G];
        let mut h = vec![Vector3::<f64>::zeros(); G];
        let mut n = [0usize; G];
        for (k, v) in r.iter().enumerate() {
            let (g, a) = (self.group[k], k % 3);
            s[g][a] += v * v;
            let b = self.b.row(k).transpose();
            h[g][a] += w[g][a] * w[g][a] * (b.transpose() * li * &b)[0];
            if a == 0 {
                n[g] += 1;
            }
        }
        let nu: Vec<Vector3<f64>> = (0..G).map(|g| h[g].map(|h: f64| n[g] as f64 - h)).collect();
        let sigma = (0..G)
            .map(|g| s[g].component_div(&nu[g]).map(f64::sqrt))
            .collect();
        (sigma, nu)
    }

    /// One fit as `Reweightable::fit_weighted` (`estimated`: as
    /// `fit_reweighted`, eq. 14 weights from these data): x̂, σ from its
    /// residuals, sandwich covariance (eq. 11) — with the middle term's σ²
    /// times `ν / (ν − 4(1 − w))` when the weights were estimated.
    fn fit(
        &self,
        w: &[Vector3<f64>],
        estimated: bool,
    ) -> (DVector<f64>, DVector<f64>, Vec<Vector3<f64>>) {
        let (x, li) = self.wls(w);
        let (sigma, nu) = self.sigma(&x, &li, w);
        let mut bs = self.b.clone();
        for (r, mut row) in bs.row_iter_mut().enumerate() {
            let (g, a) = (self.group[r], r % 3);
            let c = if estimated {
                nu[g][a] / (nu[g][a] - 4.0 * (1.0 - w[g][a]))
            } else {
                1.0
            };
            row *= w[g][a] * w[g][a] * sigma[g][a] * c.sqrt();
        }
        let middle = bs.transpose() * &bs;
        let cov = &li * middle * &li;
        let sd = cov.diagonal().map(|v| v.max(0.0).sqrt());
        (x, sd, sigma)
    }

    /// The iterative WLS of `robcal::estimate::irls` (same weights, same stop rule).
    fn irls(&self, settings: &IrlsSettings<f64>) -> (DVector<f64>, DVector<f64>, usize) {
        let (mut x, mut sd, mut sigma) = self.fit(&[Vector3::new(1.0, 1.0, 1.0); G], false);
        for k in 1..=settings.max_iterations {
            let mut w = vec![Vector3::zeros(); G];
            robust_weights(&sigma, &settings.weight, &mut w).unwrap();
            let (nx, nsd, ns) = self.fit(&w, true);
            let change = (0..N)
                .map(|i| (nx[i] - x[i]).abs() / nsd[i])
                .fold(0.0, f64::max);
            (x, sd, sigma) = (nx, nsd, ns);
            if change < settings.tolerance {
                return (x, sd, k);
            }
        }
        (x, sd, settings.max_iterations)
    }
}

/// The iterative WLS of a source, as the firmware runs it.
fn irls_of<R: Reweightable<f64, Dn>>(
    src: &R,
    settings: &IrlsSettings<f64>,
) -> robcal::Fit<f64, Dn> {
    let (mut w, mut s, mut n) = (
        [Vector3::zeros(); G],
        [Vector3::zeros(); G],
        [Vector3::zeros(); G],
    );
    src.fit_irls(settings, &[true; N], &mut w, &mut s, &mut n, |_| {})
        .unwrap()
}

fn benches(c: &mut Criterion) {
    let src = Kr270::<f64>::new().unwrap();
    let settings = kr270::settings::<f64>().unwrap();
    let dense = Dense::new(&src);
    assert_eq!(dense.b.shape(), (810, N));

    // The three agree before anything is timed.
    let fit = irls_of(&src, &settings);
    let (dx, dsd, dit) = dense.irls(&settings);
    assert_eq!(dit, fit.iterations);
    let sd = fit.std();
    for i in 0..N {
        assert!((dx[i] - fit.solution.x[i]).abs() < 1e-6 * sd[i]);
        assert!((dsd[i] / sd[i] - 1.0).abs() < 1e-6);
    }

    let mut group = c.benchmark_group("kr270/irls");
    group.bench_function("stream", |b| b.iter(|| irls_of(black_box(&src), &settings)));
    group.bench_function("grouped", |b| {
        b.iter(|| {
            let stats = kr270::grouped(black_box(&src)).unwrap();
            irls_of(&stats, &settings)
        })
    });
    group.bench_function("dense_qr", |b| b.iter(|| black_box(&dense).irls(&settings)));
    group.finish();

    // One weighted fit with the first WLS step's weights.
    let (mut w, mut sigma, mut dof) = (
        [Vector3::zeros(); G],
        [Vector3::zeros(); G],
        [Vector3::zeros(); G],
    );
    src.fit_ols(&[true; N], &mut w, &mut sigma, &mut dof)
        .unwrap();
    robust_weights(&sigma, &settings.weight, &mut w).unwrap();
    let mut group = c.benchmark_group("kr270/wls");
    group.bench_function("stream_pass_solve", |b| {
        b.iter(|| black_box(&src).weighted(&w, None).unwrap().solve().unwrap())
    });
    group.bench_function("dense_qr", |b| b.iter(|| black_box(&dense).wls(&w)));
    group.finish();
}

criterion_group! {
    name = kr270_benches;
    // Short runs: the machine is shared; the spread is in BENCHMARKS.md.
    config = Criterion::default()
        .warm_up_time(std::time::Duration::from_millis(500))
        .measurement_time(std::time::Duration::from_secs(3));
    targets = benches
}
criterion_main!(kr270_benches);
