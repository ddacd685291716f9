//! Shared helpers for robcal's host tests: independent batch references.
//!
//! The accumulator never sees a stacked matrix; these helpers do nothing
//! else. [`Batch`] stacks every row of every block into a dense `f64`
//! system (`nalgebra::DMatrix`), applies the weights as explicit diagonal
//! matrices and solves by Householder QR, so the reference shares no code path with
//! `robcal::estimate::factor` (no normal equations, no Cholesky, no column scaling):
//!
//! - estimate (eq. 6 / 10): `X̂ = (W B)⁺ W Δp`, the pseudo-inverse by QR of
//!   the column-equilibrated `W B D = Q R`;
//! - eq. 7: `σ̂² (Bᵀ W² B)⁻¹`, `σ̂² = ‖W (Δp − B X̂)‖² / (m − n)` from the
//!   residuals themselves;
//! - eq. 8 / 11: `P W Σ² W Pᵀ` with `P = (W B)⁺ W = (BᵀW²B)⁻¹ BᵀW` and
//!   explicit `diag(w)`, `diag(σ)`;
//! - eq. 13: `(Bᵀ Σ⁻² B)⁻¹ = (Σ⁻¹B)⁺ (Σ⁻¹B)⁺ᵀ`, from `Σ` alone (not from `W`).
//!
//! [`exact`] is an independent model of a loaded robot (forward kinematics
//! from the URDF text, the equilibrium of the deflected robot) that makes
//! the KR-270 data and the Monte Carlo jobs; [`arms`] builds random serial
//! chains and the UR10 of `shared/repro` with their measured data for the
//! identifiability tests.
//!
//! Also: a small deterministic generator of random problems ([`Rng`],
//! [`random_blocks`]), comparison helpers and the fuzz-script interpreter
//! shared by the fuzz targets and the stable property tests ([`fuzz_ops`]).
//!
//! The helpers take the number of parameters as a const generic `N` and
//! the estimator's types at `Const<N>`; [`to_dyn`] and [`accumulate_in`]
//! run the same data through `Dyn`.

use nalgebra::{
    Const, DMatrix, DVector, DefaultAllocator, Dim, Dyn, RealField, SMatrix, SVector, Vector3,
};
use robcal::estimate::Alloc;
use robcal::{Accumulator, Block};

/// The project's one seeded generator (`robcal_paper::rng::SplitMix64`),
/// so problems are reproducible from a `u64` that proptest can shrink and
/// report.
pub use robcal_paper::rng::SplitMix64 as Rng;

pub mod arms;
pub mod contacts;
pub mod coverage;
pub mod exact;
pub mod fuzz_io;
pub mod fuzz_ops;
pub mod poses;

/// Lossless widening of the scalar types under test to `f64`.
pub trait ToF64: RealField + Copy {
    /// `self` as `f64` (exact for `f32` and `f64`).
    fn f64(self) -> f64;
    /// `f64` rounded to `Self`.
    fn of_f64(v: f64) -> Self;
    /// The bit pattern, widened (distinguishes −0 and NaN payloads).
    fn bits(self) -> u64;
    /// The smallest positive normal number of `Self`, as `f64`.
    fn tiny() -> f64;
}

impl ToF64 for f64 {
    fn f64(self) -> f64 {
        self
    }
    fn of_f64(v: f64) -> Self {
        v
    }
    fn bits(self) -> u64 {
        self.to_bits()
    }
    fn tiny() -> f64 {
        f64::MIN_POSITIVE
    }
}

impl ToF64 for f32 {
    fn f64(self) -> f64 {
        f64::from(self)
    }
    fn of_f64(v: f64) -> Self {
        v as f32
    }
    fn bits(self) -> u64 {
        u64::from(self.to_bits())
    }
    fn tiny() -> f64 {
        f64::from(f32::MIN_POSITIVE)
    }
}

/// A stacked weighted least-squares problem in `f64`: `m` rows, `n`
/// parameters.
#[derive(Debug, Clone)]
pub struct Batch {
    /// `B_a`, `m × n`.
    pub b: DMatrix<f64>,
    /// `Δp_a`, `m`.
    pub dp: DVector<f64>,
    /// Weights `w`, `m` (the diagonal of `W`).
    pub w: DVector<f64>,
    /// σ per row, `m`, when every row carries one.
    pub sigma: Option<DVector<f64>>,
}

/// The batch estimate and its covariances.
#[derive(Debug, Clone)]
pub struct BatchSolution {
    /// `X̂`.
    pub x: DVector<f64>,
    /// `(Bᵀ W² B)⁻¹`.
    pub lambda_inv: DMatrix<f64>,
    /// `‖W (Δp − B X̂)‖²`, from the residual vector.
    pub wrss: f64,
    /// Rows with a positive weight.
    pub equations: usize,
    /// 2-norm condition number of the column-equilibrated `W B` (its
    /// square is that of the equilibrated `Bᵀ W² B`).
    pub cond_wb: f64,
}

impl Batch {
    /// Stacks the rows of `blocks` that the accumulator would use (the first
    /// `rows` rows with a positive weight), widened exactly to `f64`.
    /// `sigma` is kept only if every used row carries one.
    pub fn from_blocks<T: ToF64, const N: usize>(blocks: &[Block<T, Const<N>>]) -> Self {
        let mut rows: Vec<[f64; N]> = Vec::new();
        let (mut dp, mut w, mut sg) = (Vec::new(), Vec::new(), Vec::new());
        let mut all_sigma = true;
        for blk in blocks {
            for r in 0..blk.rows {
                let wr = blk.w[r].f64();
                if wr * wr == 0.0 || (blk.w[r] * blk.w[r]) == T::zero() {
                    continue;
                }
                rows.push(core::array::from_fn(|j| blk.b[(r, j)].f64()));
                dp.push(blk.dp[r].f64());
                w.push(wr);
                match blk.sigma {
                    Some(s) => sg.push(s[r].f64()),
                    None => all_sigma = false,
                }
            }
        }
        let m = rows.len();
        Self {
            b: DMatrix::from_fn(m, N, |i, j| rows[i][j]),
            dp: DVector::from_vec(dp),
            w: DVector::from_vec(w),
            sigma: (all_sigma && m > 0).then(|| DVector::from_vec(sg)),
        }
    }

    /// Number of rows `m`.
    pub fn rows(&self) -> usize {
        self.b.nrows()
    }

    /// `W = diag(w)`, explicit.
    pub fn w_mat(&self) -> DMatrix<f64> {
        DMatrix::from_diagonal(&self.w)
    }

    /// The weighted least-squares solution by QR of `W B` (eq. 10).
    ///
    /// # Panics
    /// If `R` is singular (the problem is not well-posed).
    pub fn solve(&self) -> BatchSolution {
        let w = self.w_mat();
        let wb = &w * &self.b;
        let wdp = &w * &self.dp;
        // An SVD is not invariant to column scaling (its error is ε·σ_max
        // in every direction), so with columns of 1e3 next to 1e-15 the
        // small columns would drown. Solve `(W B D) y = W Δp`, `X = D y`,
        // with `D = diag(1/‖(WB)ⱼ‖)`: the same least-squares problem.
        let d = DVector::from_fn(self.b.ncols(), |j, _| {
            let n = wb.column(j).norm();
            if n > 0.0 {
                1.0 / n
            } else {
                1.0
            }
        });
        let wbd = &wb * DMatrix::from_diagonal(&d);
        let sv = wbd.singular_values();
        let (smax, smin) = (sv.max(), sv.min());
        // Householder QR, `W B D = Q R`: `y = R⁻¹ Qᵀ W Δp`, `(WBD)⁺ = R⁻¹ Qᵀ`.
        // (Not the SVD solve: nalgebra's SVD was measured 1e-9 off on a
        // problem of condition 1.6 where QR, LU and robcal agree to 1e-16.)
        let n = self.b.ncols();
        let qr = wbd.qr();
        let (q, r) = (qr.q(), qr.r());
        let rinv = r
            .solve_upper_triangular(&DMatrix::identity(n, n))
            .expect("R non-singular for a well-posed problem");
        let y = &rinv * (q.transpose() * &wdp);
        let x = y.component_mul(&d);
        let pinv = DMatrix::from_diagonal(&d) * &rinv * q.transpose();
        let lambda_inv = &pinv * pinv.transpose();
        let res = &wdp - &wb * &x;
        BatchSolution {
            x,
            lambda_inv,
            wrss: res.norm_squared(),
            equations: self.rows(),
            cond_wb: smax / smin,
        }
    }

    /// Eq. 7 generalised to weights: `σ̂² (BᵀW²B)⁻¹`, `σ̂² = wrss / (m − n)`.
    pub fn cov_iid(&self, sol: &BatchSolution) -> DMatrix<f64> {
        let dof = self.rows().saturating_sub(self.b.ncols());
        let s2 = if dof == 0 { 0.0 } else { sol.wrss / dof as f64 };
        &sol.lambda_inv * s2
    }

    /// Eq. 8 / 11: `(BᵀW²B)⁻¹ BᵀW²Σ²W²B (BᵀW²B)⁻¹`, written as `P W Σ² W Pᵀ`
    /// with `P = (BᵀW²B)⁻¹ BᵀW` and explicit diagonal `W`, `Σ`.
    ///
    /// # Panics
    /// Without σ.
    pub fn cov_sandwich(&self, sol: &BatchSolution) -> DMatrix<f64> {
        let sigma = self.sigma.as_ref().expect("sandwich needs σ");
        let w = self.w_mat();
        let s2 = DMatrix::from_diagonal(&sigma.component_mul(sigma));
        let p = &sol.lambda_inv * self.b.transpose() * &w;
        &p * &w * s2 * &w * p.transpose()
    }

    /// Eq. 13: `(Bᵀ Σ⁻² B)⁻¹` from `Σ` alone, by QR of `Σ⁻¹ B` (columns
    /// equilibrated as in [`Batch::solve`]).
    ///
    /// # Panics
    /// Without σ.
    pub fn cov_eq13(&self) -> DMatrix<f64> {
        let sigma = self.sigma.as_ref().expect("eq. 13 needs σ");
        let sinv = DMatrix::from_diagonal(&sigma.map(|s| 1.0 / s));
        let sb = sinv * &self.b;
        let d = DMatrix::from_diagonal(&DVector::from_fn(self.b.ncols(), |j, _| {
            let n = sb.column(j).norm();
            if n > 0.0 {
                1.0 / n
            } else {
                1.0
            }
        }));
        // (Σ⁻¹BD)⁺ = R⁻¹Qᵀ by Householder QR, as in `solve`.
        let n = self.b.ncols();
        let qr = (sb * &d).qr();
        let rinv = qr
            .r()
            .solve_upper_triangular(&DMatrix::identity(n, n))
            .expect("R non-singular for a well-posed problem");
        let pinv = &d * rinv * qr.q().transpose();
        &pinv * pinv.transpose()
    }
}

/// `max |a − b| / max(|b|_∞, floor)`: the error relative to the largest
/// reference element (norm-wise, so a small element is judged against the
/// scale of the whole vector or matrix).
pub fn rel_err_max<I: IntoIterator<Item = (f64, f64)>>(pairs: I, floor: f64) -> f64 {
    let (mut num, mut den) = (0.0_f64, floor);
    for (a, b) in pairs {
        num = num.max((a - b).abs());
        den = den.max(b.abs());
    }
    num / den
}

/// Norm-wise relative error of an estimate `x` against the batch `x_ref`,
/// with each parameter measured in the units of its effect on the rows:
/// `max_j |x_j − x_ref,j| ‖b_j‖ / max_j |x_ref,j| ‖b_j‖` (`b_j` = column `j`
/// of `W B`). This is the error that matters when columns have very
/// different scales (1e-6 against 1): parameter `j` is judged by how much
/// of the fit it moves, not by its raw magnitude.
pub fn scaled_rel_err<T: ToF64, const N: usize>(
    x: &SVector<T, N>,
    batch: &Batch,
    reference: &BatchSolution,
) -> f64 {
    let wb = batch.w_mat() * &batch.b;
    rel_err_max(
        (0..N).map(|j| {
            let c = wb.column(j).norm();
            (x[j].f64() * c, reference.x[j] * c)
        }),
        f64::MIN_POSITIVE,
    )
}

/// Relative error of an `N × N` matrix against a reference, elementwise
/// differences over the largest reference element.
pub fn mat_rel_err<T: ToF64, const N: usize>(a: &SMatrix<T, N, N>, b: &DMatrix<f64>) -> f64 {
    rel_err_max(
        (0..N).flat_map(|i| (0..N).map(move |j| (a[(i, j)].f64(), b[(i, j)]))),
        f64::MIN_POSITIVE,
    )
}

/// Relative error of a covariance in the metric of its own diagonal:
/// `max_ij |a_ij − b_ij| / √(b_ii b_jj)` — each element against the
/// standard deviations it is made of, so tiny variances of a parameter
/// scaled by 1e-6 are judged on their own scale.
pub fn cov_rel_err<T: ToF64, const N: usize>(a: &SMatrix<T, N, N>, b: &DMatrix<f64>) -> f64 {
    let mut e = 0.0_f64;
    for i in 0..N {
        for j in 0..N {
            let s = (b[(i, i)] * b[(j, j)]).sqrt().max(f64::MIN_POSITIVE);
            e = e.max((a[(i, j)].f64() - b[(i, j)]).abs() / s);
        }
    }
    e
}

/// Every bit of an accumulator's observable state, widened to `u64`: the
/// raw fields through `Debug` are compared elsewhere; this adds a
/// NaN-payload- and sign-of-zero-exact view of `Λ`, `M`, `η`, `Σ Δpᵀ W² Δp`
/// and the counts.
pub fn state_bits<T: ToF64, D: Dim>(acc: &Accumulator<T, D>) -> Vec<u64>
where
    DefaultAllocator: Alloc<D>,
{
    let mut v: Vec<u64> = acc.information().iter().map(|x| x.bits()).collect();
    v.extend(acc.middle().iter().map(|x| x.bits()));
    v.extend(acc.eta().iter().map(|x| x.bits()));
    v.push(acc.weighted_yy().bits());
    v.push(acc.equations() as u64);
    v.push(acc.sigma_rows() as u64);
    v
}

/// A snapshot to compare an accumulator against after a rejected call:
/// the `Debug` text (every raw field, including the unused lower
/// triangles; `{:?}` of a float is its shortest round-trip form, so equal
/// text means equal bits except NaN payloads) and [`state_bits`].
pub fn snapshot<T: ToF64, D: Dim>(acc: &Accumulator<T, D>) -> (String, Vec<u64>)
where
    DefaultAllocator: Alloc<D>,
{
    (format!("{acc:?}"), state_bits(acc))
}

/// How [`random_blocks`] draws a problem.
#[derive(Debug, Clone, Copy)]
pub struct Spec {
    /// Number of measurement blocks.
    pub blocks: usize,
    /// Weights log-uniform in `[10^-w, 10^w]` (0 = unit weights).
    pub weight_decades: f64,
    /// σ per row log-uniform in `[σ_lo, σ_hi]` \[m\], and noise of that σ.
    pub sigma: (f64, f64),
    /// Attach σ to every block (for the sandwich).
    pub with_sigma: bool,
    /// Draw the number of rows per block in 1..=3 instead of always 3.
    pub random_rows: bool,
}

impl Default for Spec {
    fn default() -> Self {
        Self {
            blocks: 10,
            weight_decades: 1.0,
            sigma: (1e-5, 1e-4),
            with_sigma: true,
            random_rows: true,
        }
    }
}

/// A random well-posed problem: Gaussian `B` with column `j` multiplied by
/// `col_scale[j]`, a true `X` with `X_j = O(1) / col_scale[j]` (every
/// parameter moves the rows by O(1) m·scale), `Δp = B X + σ·noise`.
/// Returns the blocks and the true `X`.
pub fn random_blocks<const N: usize>(
    rng: &mut Rng,
    spec: &Spec,
    col_scale: &[f64; N],
) -> (Vec<Block<f64, Const<N>>>, SVector<f64, N>) {
    let x_true = SVector::<f64, N>::from_fn(|j, _| rng.normal() / col_scale[j]);
    let mut out = Vec::with_capacity(spec.blocks);
    for _ in 0..spec.blocks {
        let b = SMatrix::<f64, 3, N>::from_fn(|_, j| rng.normal() * col_scale[j]);
        let sigma =
            Vector3::from_fn(|_, _| rng.log_uniform(spec.sigma.0.log10(), spec.sigma.1.log10()));
        let noise = Vector3::from_fn(|i, _| rng.normal() * sigma[i]);
        let w = if spec.weight_decades > 0.0 {
            Vector3::from_fn(|_, _| rng.log_uniform(-spec.weight_decades, spec.weight_decades))
        } else {
            Vector3::repeat(1.0)
        };
        let mut blk = Block::new(b, b * x_true + noise).with_weights(w);
        if spec.with_sigma {
            blk = blk.with_sigma(sigma);
        }
        if spec.random_rows {
            blk.rows = 1 + (rng.next_u64() % 3) as usize;
        }
        out.push(blk);
    }
    (out, x_true)
}

/// A closed loop's report in one line, for assertion messages: the effects
/// added with their p, what is left unexplained, and the next three
/// candidates of the last round.
pub fn loop_summary(r: &robcal::calibrate::Report) -> String {
    let mut s: Vec<String> = r
        .effects
        .iter()
        .map(|e| format!("{}:{:?} p={:.1e}", e.effect, e.joint, e.p_value))
        .collect();
    if let Some(u) = &r.unexplained {
        s.push(format!("unexplained {} p={:.1e}", u.variable, u.p_value));
    }
    s.extend(
        r.last_round
            .iter()
            .take(3)
            .map(|t| format!("[next {}:{:?} p={:.1e}]", t.effect, t.about, t.p_value)),
    );
    s.join("; ")
}

/// The streaming benchmarks' blocks at `n` parameters (`benches/stream.rs`,
/// `examples/stream_timing.rs`): `len` blocks, `B` uniform in (−1, 1),
/// `Δp = B x + 10 µm` noise, weights uniform in (0.5, 1.5); the same
/// blocks for the same `n`.
pub fn stream_ring(n: usize, len: usize) -> Vec<Block<f64, Dyn>> {
    let mut rng = Rng::new(0x5EED_5000 + n as u64);
    let x = DVector::from_fn(n, |_, _| 1e-3 * rng.range(-1.0, 1.0));
    (0..len)
        .map(|_| {
            let b = nalgebra::OMatrix::<f64, nalgebra::U3, Dyn>::from_fn(n, |_, _| {
                rng.range(-1.0, 1.0)
            });
            let dp = &b * &x + Vector3::from_fn(|_, _| 1e-5 * rng.normal());
            let w = Vector3::from_fn(|_, _| rng.range(0.5, 1.5));
            Block::new(b, dp).with_weights(w)
        })
        .collect()
}

/// A block rounded to another scalar type (`f64 → f32` rounds; values
/// beyond `f32::MAX` become ±∞).
pub fn convert_block<T: ToF64, const N: usize>(b: &Block<f64, Const<N>>) -> Block<T, Const<N>> {
    Block {
        b: b.b.map(T::of_f64),
        dp: b.dp.map(T::of_f64),
        w: b.w.map(T::of_f64),
        sigma: b.sigma.map(|s| s.map(T::of_f64)),
        rows: b.rows,
    }
}

/// The same block at `Dyn` (the host's dimension): the same values, the
/// same column-major layout.
pub fn to_dyn<T: ToF64, const N: usize>(b: &Block<T, Const<N>>) -> Block<T, Dyn> {
    Block {
        b: nalgebra::OMatrix::<T, nalgebra::U3, Dyn>::from_column_slice_generic(
            nalgebra::U3,
            Dyn(N),
            b.b.as_slice(),
        ),
        dp: b.dp,
        w: b.w,
        sigma: b.sigma,
        rows: b.rows,
    }
}

/// Feeds `blocks` to a fresh accumulator in order.
///
/// # Panics
/// If an update is rejected (the helpers only feed valid blocks).
pub fn accumulate<T: ToF64, const N: usize>(
    blocks: &[Block<T, Const<N>>],
) -> Accumulator<T, Const<N>> {
    accumulate_in(Const::<N>, blocks)
}

/// [`accumulate`] at any dimension (e.g. `Dyn(n)` for blocks from
/// [`to_dyn`]).
///
/// # Panics
/// If an update is rejected.
pub fn accumulate_in<T: ToF64, D: Dim>(dim: D, blocks: &[Block<T, D>]) -> Accumulator<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    let mut acc = Accumulator::zeros(dim);
    for b in blocks {
        acc.update(b).expect("valid block");
    }
    acc
}

/// `shared/<sub>` beside the repository (as in CI, and as the bundled
/// setups name it), when `shared/<sub>/<probe>` is there; `None` on a plain
/// clone, after saying on stderr that `test` is skipped; a failure with
/// `ROBCAL_REQUIRE_SHARED=1` (CI).
pub fn shared_or_skip(sub: &str, probe: &str, test: &str) -> Option<std::path::PathBuf> {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared")
        .join(sub);
    if p.join(probe).exists() {
        return Some(p);
    }
    if std::env::var_os("ROBCAL_REQUIRE_SHARED").is_some_and(|v| v == "1") {
        panic!("shared/{sub} not found, and ROBCAL_REQUIRE_SHARED=1 (CI) requires it");
    }
    eprintln!("skipped {test}: shared/{sub} not found beside the repository (CI has it)");
    None
}
