//! Measures robcal's numerical limits and prints the tables of
//! `docs/numerics.md`:
//!
//! ```text
//! cargo run --release -p host-tests --example numerics            # all tables
//! cargo run --release -p host-tests --example numerics -- quick   # 10⁵ instead of 10⁶ streamed
//! ```
//!
//! 1. near-collinear columns: where the solve refuses, and the error of the
//!    estimate just before;
//! 2. parameters scaled 1e-9 (and smaller) against 1e3;
//! 3. f32 against f64 on the same data;
//! 4. 10⁶ measurements streamed: accumulated rounding of `Λ`, `η` and the
//!    estimate against a compensated reference (Neumaier summation in f64,
//!    of the f32-rounded data for the f32 run), and two remedies for f32:
//!    chunked accumulation merged with `Accumulator::merge` (public API),
//!    and a square-root information form updated by Givens rotations;
//! 5. the residual variance `σ̂²` from `ΣΔpᵀW²Δp − X̂ᵀη` against the
//!    signal-to-noise ratio (cancellation).
//!
//! Every reference is computed by another code path (SVD of the stacked
//! system, `host_tests::Batch`, or compensated sums), never by robcal.

use host_tests::{convert_block, Batch, Rng, ToF64};
use nalgebra::{Const, DMatrix, DVector, SMatrix, SVector, Vector3};
use robcal::{Accumulator, Block, Error};

fn scaled_err<T: ToF64, const N: usize>(
    x: &SVector<T, N>,
    batch: &Batch,
    xref: &DVector<f64>,
) -> f64 {
    let wb = batch.w_mat() * &batch.b;
    let (mut num, mut den) = (0.0_f64, 0.0_f64);
    for j in 0..N {
        let c = wb.column(j).norm();
        num = num.max((x[j].f64() - xref[j]).abs() * c);
        den = den.max(xref[j].abs() * c);
    }
    num / den
}

fn equilibrated_cond(batch: &Batch) -> f64 {
    let mut e = batch.w_mat() * &batch.b;
    for mut c in e.column_iter_mut() {
        let n = c.norm();
        if n > 0.0 {
            c /= n;
        }
    }
    let sv = e.singular_values();
    sv.max() / sv.min()
}

fn outcome<T: ToF64, const N: usize>(blocks: &[Block<T, Const<N>>]) -> String {
    let mut acc = Accumulator::<T, Const<N>>::new();
    for b in blocks {
        if let Err(e) = acc.update(b) {
            return format!("update: {e}");
        }
    }
    let batch = Batch::from_blocks(blocks);
    // The f64 reference itself fails at the edge of the f64 range (column
    // norms underflow): then only the outcome is printed.
    let reference = std::panic::catch_unwind(|| batch.solve()).ok();
    match acc.solve() {
        Ok(sol) => match reference {
            Some(r) => format!(
                "ok   rcond {:8.1e}  err {:8.1e}",
                sol.rcond.f64(),
                scaled_err(&sol.x, &batch, &r.x)
            ),
            None => format!("ok   rcond {:8.1e}  (no f64 reference)", sol.rcond.f64()),
        },
        Err(Error::NotIdentifiable { column, rcond }) => {
            format!("REFUSED col {column} rcond {rcond:8.1e}")
        }
        Err(e) => format!("error: {e}"),
    }
}

/// Table 1: column 1 = column 0 + δ·noise (4 parameters, 40 blocks).
fn collinear() {
    println!("\n## 1. Near-collinear columns (N = 4, 120 rows; column 1 = column 0 + δ·noise)\n");
    println!("| δ | cond(equilibrated WB) | f64 | f32 |");
    println!("|---|---|---|---|");
    for k in 1..=16 {
        let delta = 10f64.powf(-(k as f64) / 2.0);
        let mut rng = Rng::new(42);
        let x_true = SVector::<f64, 4>::new(0.3, -0.7, 1.1, 0.5);
        let blocks: Vec<Block<f64, Const<4>>> = (0..40)
            .map(|_| {
                let mut b = SMatrix::<f64, 3, 4>::from_fn(|_, _| rng.normal());
                for r in 0..3 {
                    b[(r, 1)] = b[(r, 0)] + delta * rng.normal();
                }
                let noise = Vector3::from_fn(|_, _| 1e-6 * rng.normal());
                Block::new(b, b * x_true + noise)
            })
            .collect();
        let b32: Vec<Block<f32, Const<4>>> = blocks.iter().map(convert_block).collect();
        let cond = equilibrated_cond(&Batch::from_blocks(&blocks));
        println!(
            "| {delta:.0e} | {cond:.1e} | {} | {} |",
            outcome(&blocks),
            outcome(&b32)
        );
    }
}

/// Table 2: columns scaled `small` and 1e3 (and 1), 4 parameters.
fn scaling() {
    println!("\n## 2. Column scales: 1e3, 1, `small`, `small` (N = 4, 120 rows, unit weights)\n");
    println!("| small | f64 | f32 |");
    println!("|---|---|---|");
    for e in [
        0, 3, 6, 9, 12, 15, 18, 19, 20, 21, 22, 25, 30, 40, 100, 150, 160,
    ] {
        let small = 10f64.powi(-e);
        let scale = [1e3, 1.0, small, small];
        let mut rng = Rng::new(7);
        let x_true = SVector::<f64, 4>::from_fn(|j, _| rng.normal() / scale[j]);
        let blocks: Vec<Block<f64, Const<4>>> = (0..40)
            .map(|_| {
                let b = SMatrix::<f64, 3, 4>::from_fn(|_, j| rng.normal() * scale[j]);
                Block::new(b, b * x_true + Vector3::from_fn(|_, _| 1e-6 * rng.normal()))
            })
            .collect();
        let b32: Vec<Block<f32, Const<4>>> = blocks.iter().map(convert_block).collect();
        println!("| 1e-{e} | {} | {} |", outcome(&blocks), outcome(&b32));
    }
}

/// Neumaier (improved Kahan) summation.
#[derive(Clone, Copy, Default)]
struct Neumaier {
    s: f64,
    c: f64,
}

impl Neumaier {
    fn add(&mut self, v: f64) {
        let t = self.s + v;
        if self.s.abs() >= v.abs() {
            self.c += (self.s - t) + v;
        } else {
            self.c += (v - t) + self.s;
        }
        self.s = t;
    }
    fn get(&self) -> f64 {
        self.s + self.c
    }
}

const NS: usize = 6;

/// Square-root information form `R` (upper triangular, `RᵀR = Λ`) and
/// `z` (`Rᵀz = η`), updated per row by Givens rotations: the remedy for
/// f32 when normal equations lose too much (error ~ ε·cond(WB) instead of
/// ε·cond(WB)², and no growth with the running sum's magnitude).
struct SqrtInfo {
    r: SMatrix<f32, NS, NS>,
    z: SVector<f32, NS>,
}

impl SqrtInfo {
    fn new() -> Self {
        Self {
            r: SMatrix::zeros(),
            z: SVector::zeros(),
        }
    }
    fn add_row(&mut self, b: &[f32; NS], y: f32, w: f32) {
        let mut row: [f32; NS] = core::array::from_fn(|j| b[j] * w);
        let mut yy = y * w;
        for k in 0..NS {
            let (a, c) = (self.r[(k, k)], row[k]);
            if c == 0.0 {
                continue;
            }
            let h = a.hypot(c);
            let (cs, sn) = (a / h, c / h);
            for (j, x) in row.iter_mut().enumerate().skip(k) {
                let (rk, xk) = (self.r[(k, j)], *x);
                self.r[(k, j)] = cs * rk + sn * xk;
                *x = -sn * rk + cs * xk;
            }
            let zk = self.z[k];
            self.z[k] = cs * zk + sn * yy;
            yy = -sn * zk + cs * yy;
        }
    }
    fn solve(&self) -> SVector<f64, NS> {
        // Back substitution R x = z (in f64 from the f32 factor: the factor
        // is what is being measured, not the 6×6 substitution).
        let r = self.r.map(f64::from);
        let z = self.z.map(f64::from);
        let mut x = SVector::<f64, NS>::zeros();
        for i in (0..NS).rev() {
            let mut v = z[i];
            for j in (i + 1)..NS {
                v -= r[(i, j)] * x[j];
            }
            x[i] = v / r[(i, i)];
        }
        x
    }
}

fn solve_ref(l: &DMatrix<f64>, e: &DVector<f64>) -> DVector<f64> {
    l.clone()
        .cholesky()
        .expect("reference Λ is positive definite")
        .solve(e)
}

/// Table 4: `m` measurements (3 rows each) streamed, N = 6.
fn streaming(m: usize) {
    println!("\n## 4. {m} measurements streamed (N = 6, 3 rows each, weights in [0.5, 2])\n");
    let mut rng = Rng::new(2026);
    let x_true = SVector::<f64, NS>::from_fn(|j, _| 1e-3 * (j as f64 + 1.0));
    let mut a64 = Accumulator::<f64, Const<NS>>::new();
    let mut a32 = Accumulator::<f32, Const<NS>>::new();
    let mut chunk32 = Accumulator::<f32, Const<NS>>::new();
    let mut total32 = Accumulator::<f32, Const<NS>>::new();
    let chunk = 1000;
    let mut sri = SqrtInfo::new();
    // Compensated references: over the f64 data, and over the f32-rounded
    // data widened to f64.
    let mut l64 = [[Neumaier::default(); NS]; NS];
    let mut e64 = [Neumaier::default(); NS];
    let mut l32 = [[Neumaier::default(); NS]; NS];
    let mut e32 = [Neumaier::default(); NS];
    for k in 0..m {
        let b = SMatrix::<f64, 3, NS>::from_fn(|_, _| rng.normal());
        let dp = b * x_true + Vector3::from_fn(|_, _| 2e-5 * rng.normal());
        let w = Vector3::from_fn(|_, _| rng.range(0.5, 2.0));
        let blk = Block::new(b, dp).with_weights(w);
        let b32: Block<f32, Const<NS>> = convert_block(&blk);
        a64.update(&blk).unwrap();
        a32.update(&b32).unwrap();
        chunk32.update(&b32).unwrap();
        if (k + 1) % chunk == 0 {
            total32.merge(&chunk32).unwrap();
            chunk32.reset();
        }
        for r in 0..3 {
            let w2 = w[r] * w[r];
            let w32 = f64::from(b32.w[r]);
            let w2_32 = w32 * w32;
            let row32: [f32; NS] = core::array::from_fn(|j| b32.b[(r, j)]);
            sri.add_row(&row32, b32.dp[r], b32.w[r]);
            for i in 0..NS {
                e64[i].add(w2 * b[(r, i)] * dp[r]);
                e32[i].add(w2_32 * f64::from(b32.b[(r, i)]) * f64::from(b32.dp[r]));
                for j in 0..NS {
                    l64[i][j].add(w2 * b[(r, i)] * b[(r, j)]);
                    l32[i][j].add(w2_32 * f64::from(b32.b[(r, i)]) * f64::from(b32.b[(r, j)]));
                }
            }
        }
    }
    total32.merge(&chunk32).unwrap();
    let to_mat = |l: &[[Neumaier; NS]; NS]| DMatrix::from_fn(NS, NS, |i, j| l[i][j].get());
    let to_vec = |e: &[Neumaier; NS]| DVector::from_fn(NS, |i, _| e[i].get());
    let (rl64, re64, rl32, re32) = (to_mat(&l64), to_vec(&e64), to_mat(&l32), to_vec(&e32));
    let (rx64, rx32) = (solve_ref(&rl64, &re64), solve_ref(&rl32, &re32));

    let lam_err = |l: DMatrix<f64>, r: &DMatrix<f64>| {
        let mut e = 0.0_f64;
        for i in 0..NS {
            for j in 0..NS {
                e = e.max((l[(i, j)] - r[(i, j)]).abs() / (r[(i, i)] * r[(j, j)]).sqrt());
            }
        }
        e
    };
    let vec_err = |v: DVector<f64>, r: &DVector<f64>| (v - r).amax() / r.amax();
    let row = |name: &str,
               l: DMatrix<f64>,
               e: DVector<f64>,
               x: DVector<f64>,
               rl: &DMatrix<f64>,
               re: &DVector<f64>,
               rx: &DVector<f64>| {
        println!(
            "| {name} | {:.1e} | {:.1e} | {:.1e} |",
            lam_err(l, rl),
            vec_err(e, re),
            vec_err(x, rx)
        );
    };
    println!("| accumulation | Λ rel. err | η rel. err | X̂ rel. err |");
    println!("|---|---|---|---|");
    let dm = |a: SMatrix<f64, NS, NS>| DMatrix::from_fn(NS, NS, |i, j| a[(i, j)]);
    let dv = |a: &SVector<f64, NS>| DVector::from_fn(NS, |i, _| a[i]);
    let x64 = a64.solve().unwrap().x;
    row(
        "f64 naive (robcal)",
        dm(a64.information()),
        dv(a64.eta()),
        dv(&x64),
        &rl64,
        &re64,
        &rx64,
    );
    let x32 = a32.solve().unwrap().x.map(f64::from);
    row(
        "f32 naive (robcal)",
        dm(a32.information().map(f64::from)),
        dv(&a32.eta().map(f64::from)),
        dv(&x32),
        &rl32,
        &re32,
        &rx32,
    );
    let xc = total32.solve().unwrap().x.map(f64::from);
    row(
        &format!("f32, chunks of {chunk} merged (robcal API)"),
        dm(total32.information().map(f64::from)),
        dv(&total32.eta().map(f64::from)),
        dv(&xc),
        &rl32,
        &re32,
        &rx32,
    );
    let rf = sri.r.map(f64::from);
    let lam_sri = rf.transpose() * rf;
    let eta_sri = rf.transpose() * sri.z.map(f64::from);
    row(
        "f32 square-root information, Givens (example code)",
        dm(lam_sri),
        dv(&eta_sri),
        dv(&sri.solve()),
        &rl32,
        &re32,
        &rx32,
    );
    println!(
        "\n(X̂ of the f64 reference vs the true X: {:.1e} relative — the statistical error, for scale.)",
        vec_err(rx64.clone(), &DVector::from_fn(NS, |i, _| x_true[i]))
    );
}

/// Table 5: σ̂² from the sufficient statistics against the residuals.
fn cancellation() {
    println!("\n## 5. σ̂² (eq. 7) from `ΣΔpᵀW²Δp − X̂ᵀη` against signal/noise (N = 4, 300 rows)\n");
    println!("| signal/noise | ΣΔpᵀW²Δp / RSS | σ̂² rel. err f64 | σ̂² rel. err f32 |");
    println!("|---|---|---|---|");
    for e in 0..=7 {
        let noise = 10f64.powi(-e);
        let mut rng = Rng::new(5);
        let x_true = SVector::<f64, 4>::new(0.3, -0.7, 1.1, 0.5);
        let blocks: Vec<Block<f64, Const<4>>> = (0..100)
            .map(|_| {
                let b = SMatrix::<f64, 3, 4>::from_fn(|_, _| rng.normal());
                Block::new(
                    b,
                    b * x_true + Vector3::from_fn(|_, _| noise * rng.normal()),
                )
            })
            .collect();
        let b32: Vec<Block<f32, Const<4>>> = blocks.iter().map(convert_block).collect();
        let rel = |s2: f64, blocks_ref: &Batch| {
            let r = blocks_ref.solve();
            let want = r.wrss / (blocks_ref.rows() - 4) as f64;
            ((s2 - want) / want).abs()
        };
        let acc = host_tests::accumulate(&blocks);
        let acc32 = host_tests::accumulate(&b32);
        let s64 = acc.solve().unwrap().sigma2_hat();
        let s32 = f64::from(acc32.solve().unwrap().sigma2_hat());
        let batch = Batch::from_blocks(&blocks);
        let ratio = acc.weighted_yy() / batch.solve().wrss;
        println!(
            "| 1e{e} | {ratio:.1e} | {:.1e} | {:.1e} |",
            rel(s64, &batch),
            rel(s32, &Batch::from_blocks(&b32))
        );
    }
}

fn main() {
    std::panic::set_hook(Box::new(|_| {}));
    let quick = std::env::args().any(|a| a == "quick");
    collinear();
    scaling();
    streaming(if quick { 100_000 } else { 1_000_000 });
    cancellation();
}
