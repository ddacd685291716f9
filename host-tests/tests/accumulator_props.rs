//! Property tests of the accumulator against the independent batch
//! reference (`host_tests::Batch`: stacked dense system, SVD, covariances
//! from explicit diagonal `W` and `Σ`).
//!
//! Problems are drawn from a `u64` seed (`host_tests::random_blocks`), so a
//! failing case is reproducible from the seed proptest prints. `N` is a
//! const generic (the estimator at `Const<N>`), so a few sizes are
//! instantiated: 1, 3, 6 and 12. `const_equals_dyn_*` run the same data at
//! `Const<N>` and at `Dyn` and compare bit for bit.
//!
//! "Well-posed" means: at least as many weighted rows as parameters and a
//! column-equilibrated `W B` with 2-norm condition ≤ [`MAX_COND`]; cases
//! beyond are discarded with `prop_assume!` (they are the subject of
//! `docs/numerics.md`, not of an equality test).
//!
//! Tolerances (all relative, see `host_tests::{scaled_rel_err,
//! cov_rel_err}` for the metrics):
//! - f64 estimate and `Λ⁻¹` against batch: 1e-10 (the figure). The
//!   normal equations square the condition, and forming `Λ` from `m` rows
//!   adds up to `m·ε` per entry: the error is up to about
//!   `m·ε·cond(Λs) ≤ 144 · 1.1e-16 · MAX_COND²` = 1.6e-10 at the bound,
//!   typically 10–100 times less. Measured: with `MAX_COND` = 1000 a
//!   1000-case run found 1.1e-10, with 300 a 20 000-case run found 4e-10
//!   (the permuted order), with 100 none above 1e-10.
//! - f32 with columns scaled 1e-6 and 1: 1e-4 (the figure). The
//!   solve equilibrates the columns, so only `cond` of the equilibrated
//!   matrix counts: `6e-8 · m · cond(Λs)`.
//! - `σ̂²` (eq. 7) comes from `Σ Δpᵀ W² Δp − X̂ᵀη`, a difference that
//!   cancels: its error is `≈ ε · Σ Δpᵀ W² Δp / RSS`, so eq. 7 is compared
//!   with that bound added (see `docs/numerics.md`).

use host_tests::{
    accumulate, accumulate_in, convert_block, cov_rel_err, random_blocks, scaled_rel_err,
    state_bits, to_dyn, Batch, Rng, Spec, ToF64,
};
use nalgebra::{Const, DMatrix, DefaultAllocator, Dim, Dyn, SMatrix};
use proptest::prelude::*;
use robcal::estimate::{identifiability, Alloc, IdentifiabilitySettings};
use robcal::{Accumulator, Block, Solution};

/// Largest condition number of the column-equilibrated `W B` accepted as
/// well-posed.
const MAX_COND: f64 = 100.0;

fn equilibrated_cond(batch: &Batch) -> f64 {
    let wb = batch.w_mat() * &batch.b;
    let mut e = wb.clone();
    for (j, mut c) in e.column_iter_mut().enumerate() {
        let n = wb.column(j).norm();
        if n > 0.0 {
            c /= n;
        }
    }
    let sv = e.singular_values();
    sv.max() / sv.min()
}

fn spec(blocks: usize, weight_decades: f64) -> Spec {
    Spec {
        blocks,
        weight_decades,
        ..Spec::default()
    }
}

/// Draws a well-posed problem or discards the case.
fn problem<const N: usize>(
    seed: u64,
    spec: &Spec,
    col_scale: &[f64; N],
) -> Result<Vec<Block<f64, Const<N>>>, TestCaseError> {
    let mut rng = Rng::new(seed);
    let (blocks, _) = random_blocks::<N>(&mut rng, spec, col_scale);
    let batch = Batch::from_blocks(&blocks);
    prop_assume!(batch.rows() >= N);
    prop_assume!(equilibrated_cond(&batch) <= MAX_COND);
    Ok(blocks)
}

fn check_f64<const N: usize>(seed: u64, blocks: usize, wdec: f64) -> Result<(), TestCaseError> {
    let blocks = problem::<N>(seed, &spec(blocks, wdec), &[1.0; N])?;
    let batch = Batch::from_blocks(&blocks);
    let reference = batch.solve();
    let acc = accumulate(&blocks);
    let sol = acc
        .solve()
        .map_err(|e| TestCaseError::fail(format!("{e}")))?;
    let ex = scaled_rel_err(&sol.x, &batch, &reference);
    prop_assert!(ex <= 1e-10, "estimate: {ex:e}");
    let el = cov_rel_err(&sol.lambda_inv, &reference.lambda_inv);
    prop_assert!(el <= 1e-10, "Λ⁻¹: {el:e}");
    // Sandwich (eq. 11) against P W Σ² W Pᵀ.
    let es = cov_rel_err(
        &sol.cov_sandwich(&acc.middle()),
        &batch.cov_sandwich(&reference),
    );
    // Loosened to 1e-9: the sandwich has Λ⁻¹ twice, and M weights rows by
    // w⁴σ² (6 decades here) where Λ weights them by w² — its diagonal can
    // be far smaller than Λ⁻¹'s, and the element errors are judged
    // against it. Worst measured in 20 000 cases: 2.9e-10 (m = n = 3); and
    // it grows with the conditioning: 1.55e-9 at κ = 83 (m = 18, n = 6, a
    // case `.ci/props.sh` drew, pinned in `f64_equals_batch_n6_drawn_case`),
    // hence 1e-9 per ten of κ.
    let kappa_s = equilibrated_cond(&batch);
    prop_assert!(
        es <= 1e-9 * (1.0 + kappa_s / 10.0),
        "sandwich: {es:e} (κ {kappa_s:e})"
    );
    // Eq. 7, with the cancellation bound of σ̂² (module docs): the RSS is
    // `Σ Δpᵀ W² Δp − X̂ᵀ η`, and an estimate error of order κ·ε (κ the
    // equilibrated condition number) enters `X̂ᵀ η ≈ yy` as κ·ε·yy. (Without
    // κ the bound failed at 1.5× on 1 case in ~10⁴: κ = 60, m = 9, n = 3.)
    let yy = acc.weighted_yy();
    let kappa = equilibrated_cond(&batch);
    let cancel = 64.0 * f64::EPSILON * kappa.max(1.0) * yy / reference.wrss.max(f64::MIN_POSITIVE);
    let ei = cov_rel_err(&sol.cov_iid(), &batch.cov_iid(&reference));
    prop_assert!(
        ei <= 1e-10 + cancel,
        "eq. 7: {ei:e} (cancellation {cancel:e})"
    );
    prop_assert_eq!(sol.equations, reference.equations);

    // Eq. 13: with W = Σ⁻¹ the covariance is Λ⁻¹ = (Bᵀ Σ⁻² B)⁻¹, against
    // the batch computed from Σ alone; and the sandwich agrees with it.
    let inv: Vec<Block<f64, Const<N>>> = blocks
        .iter()
        .map(|b| b.with_weights(b.sigma.unwrap().map(|s| 1.0 / s)))
        .collect();
    let b13 = Batch::from_blocks(&inv);
    let acc13 = accumulate(&inv);
    let sol13 = acc13
        .solve()
        .map_err(|e| TestCaseError::fail(format!("{e}")))?;
    let e13 = cov_rel_err(&sol13.cov_information(), &b13.cov_eq13());
    prop_assert!(e13 <= 1e-10, "eq. 13: {e13:e}");
    let e11 = cov_rel_err(&sol13.cov_sandwich(&acc13.middle()), &b13.cov_eq13());
    prop_assert!(e11 <= 1e-10, "eq. 11 with WΣ = I: {e11:e}");
    Ok(())
}

fn check_f32_scaled<const N: usize>(seed: u64, blocks: usize) -> Result<(), TestCaseError> {
    // Compliances ~1e-6 next to lengths ~1: every other column scaled 1e-6
    // (the true parameter is then ~1e6 times larger, as with rad/(N·m)
    // against N·m loads). Unit weights: the scaling is what is tested here.
    let scale: [f64; N] = core::array::from_fn(|j| if j % 2 == 0 { 1.0 } else { 1e-6 });
    let s = Spec {
        weight_decades: 0.3,
        ..spec(blocks, 0.0)
    };
    let blocks64 = problem::<N>(seed, &s, &scale)?;
    let blocks: Vec<Block<f32, Const<N>>> = blocks64.iter().map(convert_block).collect();
    // The reference solves the f32-rounded data exactly widened to f64, so
    // only the accumulator's arithmetic is measured, not the input rounding.
    let batch = Batch::from_blocks(&blocks);
    prop_assume!(equilibrated_cond(&batch) <= 100.0);
    let reference = batch.solve();
    let acc = accumulate(&blocks);
    let sol = acc
        .solve()
        .map_err(|e| TestCaseError::fail(format!("{e}")))?;
    let ex = scaled_rel_err(&sol.x, &batch, &reference);
    prop_assert!(ex <= 1e-4, "f32 estimate: {ex:e}");
    // (Not componentwise: a parameter whose effect on the rows is 1 % of
    // the largest one carries 100× the relative error of the norm-wise
    // figure, as the conditioning of the problem dictates, not the solver.)
    let el = cov_rel_err(&sol.lambda_inv, &reference.lambda_inv);
    prop_assert!(el <= 1e-4, "f32 Λ⁻¹: {el:e}");
    let es = cov_rel_err(
        &sol.cov_sandwich(&acc.middle()),
        &batch.cov_sandwich(&reference),
    );
    prop_assert!(es <= 1e-4, "f32 sandwich: {es:e}");
    Ok(())
}

fn shuffled<T: Clone>(v: &[T], seed: u64) -> Vec<T> {
    let mut rng = Rng::new(seed ^ 0x5eed);
    let mut out = v.to_vec();
    for i in (1..out.len()).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        out.swap(i, j);
    }
    out
}

/// Same statistics up to rounding: counts exact, matrices within
/// `m·ε` of their diagonal scale (sums of the same terms in another order).
fn same_up_to_rounding<T: ToF64, const N: usize>(
    a: &Accumulator<T, Const<N>>,
    b: &Accumulator<T, Const<N>>,
) -> Result<(), TestCaseError> {
    prop_assert_eq!(a.equations(), b.equations());
    prop_assert_eq!(a.sigma_rows(), b.sigma_rows());
    let tol = 4.0 * (a.equations() as f64 + 1.0) * T::default_epsilon().f64();
    let la = a.information();
    let lb = DMatrix::from_fn(N, N, |i, j| b.information()[(i, j)].f64());
    prop_assert!(cov_rel_err(&la, &lb) <= tol, "Λ differs beyond rounding");
    let ma = a.middle();
    let mb = DMatrix::from_fn(N, N, |i, j| b.middle()[(i, j)].f64());
    prop_assert!(cov_rel_err(&ma, &mb) <= tol, "M differs beyond rounding");
    Ok(())
}

fn check_order<const N: usize>(seed: u64, blocks: usize, split: f64) -> Result<(), TestCaseError> {
    let blocks = problem::<N>(seed, &spec(blocks, 1.0), &[1.0; N])?;
    let batch = Batch::from_blocks(&blocks);
    let reference = batch.solve();
    let seq = accumulate(&blocks);
    let sol = seq
        .solve()
        .map_err(|e| TestCaseError::fail(format!("{e}")))?;

    // Permutation invariance.
    let perm = accumulate(&shuffled(&blocks, seed));
    same_up_to_rounding(&seq, &perm)?;
    let sp = perm
        .solve()
        .map_err(|e| TestCaseError::fail(format!("{e}")))?;
    let d =
        scaled_rel_err(&sp.x, &batch, &reference).max(scaled_rel_err(&sol.x, &batch, &reference));
    prop_assert!(d <= 1e-10, "permuted estimate: {d:e}");

    // Merge == sequential, split at a random point, merged both ways.
    let k = ((blocks.len() as f64) * split) as usize;
    let (left, right) = blocks.split_at(k);
    let mut a = accumulate(left);
    let b = accumulate(right);
    a.merge(&b)
        .map_err(|e| TestCaseError::fail(format!("{e}")))?;
    same_up_to_rounding(&seq, &a)?;
    let mut b2 = b.clone();
    b2.merge(&accumulate(left))
        .map_err(|e| TestCaseError::fail(format!("{e}")))?;
    same_up_to_rounding(&seq, &b2)?;
    let sm = a.solve().map_err(|e| TestCaseError::fail(format!("{e}")))?;
    let d = scaled_rel_err(&sm.x, &batch, &reference);
    prop_assert!(d <= 1e-10, "merged estimate: {d:e}");

    // Merging an empty accumulator changes nothing, bit for bit.
    let mut c = seq.clone();
    c.merge(&Accumulator::new()).unwrap();
    let (tc, ts) = (format!("{c:?}"), format!("{seq:?}"));
    prop_assert_eq!(tc, ts);

    // Exact symmetry of Λ and M, after updates and after merges.
    for acc in [&seq, &perm, &a, &b2] {
        let l = acc.information();
        prop_assert!(l == l.transpose(), "Λ not exactly symmetric");
        let m = acc.middle();
        prop_assert!(m == m.transpose(), "M not exactly symmetric");
    }
    Ok(())
}

/// Λ⁻¹ as returned by the solve (and so eq. 13) is exactly symmetric.
fn check_inverse_symmetric<const N: usize>(seed: u64, blocks: usize) -> Result<(), TestCaseError> {
    let scale: [f64; N] = core::array::from_fn(|j| 10f64.powi(j as i32 % 7 - 3));
    let blocks = problem::<N>(seed, &spec(blocks, 1.0), &scale)?;
    let sol = accumulate(&blocks)
        .solve()
        .map_err(|e| TestCaseError::fail(format!("{e}")))?;
    let l: SMatrix<f64, N, N> = sol.lambda_inv;
    prop_assert!(l == l.transpose(), "Λ⁻¹ not exactly symmetric: {l}");
    Ok(())
}

/// What a solve estimates, as bit patterns (`Err` as its text): `X̂`, `Λ⁻¹`,
/// the mask, the residual sum, `rcond` and the equations.
fn estimate_bits<T: ToF64, D: Dim>(
    r: &Result<Solution<T, D>, robcal::Error>,
) -> Result<Vec<u64>, String>
where
    DefaultAllocator: Alloc<D>,
{
    match r {
        Ok(s) => {
            let mut v: Vec<u64> = s.x.iter().map(|x| x.bits()).collect();
            v.extend(s.lambda_inv.iter().map(|x| x.bits()));
            v.extend(s.active.iter().map(|a| u64::from(*a)));
            v.extend([s.wrss.bits(), s.rcond.bits(), s.equations as u64]);
            Ok(v)
        }
        Err(e) => Err(format!("{e:?}")),
    }
}

/// The promise of the Dim-generic core: the same blocks through
/// `Accumulator<T, Const<N>>` (the firmware) and `Accumulator<T, Dyn>` (the
/// host) are the same arithmetic in the same order, so the statistics, the
/// estimate `X̂`, `Λ⁻¹`, the residual sum, `rcond` and the identifiable set
/// are bit-identical — also after a merge and for a random mask. No
/// well-posedness is assumed: a refusal must be the same refusal. (This
/// test found that nalgebra sums a static dot product of 4 elements and a
/// `Dyn` matrix product above 5 in other orders than their counterparts;
/// the core now sums them in its own loops, `estimate::linalg`.)
fn check_const_equals_dyn<T: ToF64, const N: usize>(
    seed: u64,
    blocks: usize,
    wdec: f64,
    split: f64,
    mask: u64,
) -> Result<(), TestCaseError> {
    let mut rng = Rng::new(seed);
    let scale: [f64; N] = core::array::from_fn(|j| 10f64.powi(j as i32 % 5 - 2));
    let (b64, _) = random_blocks::<N>(&mut rng, &spec(blocks, wdec), &scale);
    let fixed: Vec<Block<T, Const<N>>> = b64.iter().map(convert_block).collect();
    let dynamic: Vec<Block<T, Dyn>> = fixed.iter().map(to_dyn).collect();
    let a = accumulate(&fixed);
    let d = accumulate_in(Dyn(N), &dynamic);
    prop_assert_eq!(d.parameters(), N);
    prop_assert_eq!(state_bits(&a), state_bits(&d), "statistics differ");
    let (sa, sd) = (a.solve(), d.solve());
    prop_assert_eq!(estimate_bits(&sa), estimate_bits(&sd), "solve differs");
    let active: Vec<bool> = (0..N).map(|j| mask >> (j % 64) & 1 == 1).collect();
    let (sa, sd) = (a.solve_active(&active), d.solve_active(&active));
    prop_assert_eq!(
        estimate_bits(&sa),
        estimate_bits(&sd),
        "solve_active({:?}) differs",
        active
    );
    // The identifiable set and its conditioning, from the same Λ.
    let settings = IdentifiabilitySettings::default();
    let ia = identifiability(&a.information(), &[true; N], &settings);
    let id = identifiability(&d.information(), &[true; N], &settings);
    match (ia, id) {
        (Ok(ia), Ok(id)) => {
            prop_assert_eq!(ia.kept.as_slice(), id.kept.as_slice());
            prop_assert_eq!(ia.rcond.bits(), id.rcond.bits());
        }
        (ia, id) => prop_assert_eq!(ia.err(), id.err()),
    }
    // Split, accumulate both halves, merge: the same merge at both sizes.
    let k = ((blocks as f64) * split) as usize;
    let mut am = accumulate(&fixed[..k]);
    am.merge(&accumulate(&fixed[k..])).unwrap();
    let mut dm = accumulate_in(Dyn(N), &dynamic[..k]);
    dm.merge(&accumulate_in(Dyn(N), &dynamic[k..])).unwrap();
    prop_assert_eq!(state_bits(&am), state_bits(&dm), "merged statistics differ");
    let (sa, sd) = (am.solve(), dm.solve());
    prop_assert_eq!(
        estimate_bits(&sa),
        estimate_bits(&sd),
        "merged solve differs"
    );
    Ok(())
}

/// A case `.ci/props.sh` drew (2 000 cases of the batch properties,
/// 2026-12-07) where the sandwich's relative error reached 1.55e-9, over
/// the bound of 1e-9 it had then (κ = 83): pinned.
#[test]
fn f64_equals_batch_n6_drawn_case() {
    check_f64::<6>(1_729_237_308_343_678_365, 6, 0.933_573_188_381_966_2).unwrap();
}

proptest! {
    // 64 cases per property by default (fast `cargo test`); `PROPTEST_CASES`
    // overrides (`.ci/props.sh`).
    #![proptest_config(ProptestConfig {
        cases: std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(64),
        max_global_rejects: 1 << 16,
        ..ProptestConfig::default()
    })]

    #[test]
    fn f64_equals_batch_n1(seed: u64, blocks in 1usize..8, wdec in 0.0..1.0f64) {
        check_f64::<1>(seed, blocks, wdec)?;
    }
    #[test]
    fn f64_equals_batch_n3(seed: u64, blocks in 3usize..16, wdec in 0.0..1.0f64) {
        check_f64::<3>(seed, blocks, wdec)?;
    }
    #[test]
    fn f64_equals_batch_n6(seed: u64, blocks in 6usize..30, wdec in 0.0..1.0f64) {
        check_f64::<6>(seed, blocks, wdec)?;
    }
    #[test]
    fn f64_equals_batch_n12(seed: u64, blocks in 14usize..48, wdec in 0.0..1.0f64) {
        check_f64::<12>(seed, blocks, wdec)?;
    }

    #[test]
    fn f32_scaled_equals_batch_n1(seed: u64, blocks in 2usize..8) {
        check_f32_scaled::<1>(seed, blocks)?;
    }
    #[test]
    fn f32_scaled_equals_batch_n3(seed: u64, blocks in 8usize..20) {
        check_f32_scaled::<3>(seed, blocks)?;
    }
    #[test]
    fn f32_scaled_equals_batch_n6(seed: u64, blocks in 16usize..40) {
        check_f32_scaled::<6>(seed, blocks)?;
    }
    #[test]
    fn f32_scaled_equals_batch_n12(seed: u64, blocks in 32usize..64) {
        check_f32_scaled::<12>(seed, blocks)?;
    }

    #[test]
    fn order_merge_symmetry_n3(seed: u64, blocks in 3usize..16, split in 0.0..1.0f64) {
        check_order::<3>(seed, blocks, split)?;
    }
    #[test]
    fn order_merge_symmetry_n6(seed: u64, blocks in 6usize..30, split in 0.0..1.0f64) {
        check_order::<6>(seed, blocks, split)?;
    }
    #[test]
    fn order_merge_symmetry_n12(seed: u64, blocks in 14usize..48, split in 0.0..1.0f64) {
        check_order::<12>(seed, blocks, split)?;
    }

    // A regression of the first session's finding F1: `solve` scaled Λs⁻¹
    // back with `(inv·sᵢ)·sⱼ`, which rounds differently from `(inv·sⱼ)·sᵢ`,
    // so the returned Λ⁻¹ (the eq. 13 covariance) was asymmetric in the
    // last bit. Fixed by scaling the upper triangle and mirroring it.
    #[test]
    fn lambda_inv_exactly_symmetric_n6(seed: u64, blocks in 8usize..30) {
        check_inverse_symmetric::<6>(seed, blocks)?;
    }

    #[test]
    fn const_equals_dyn_bitwise_f64_n1(seed: u64, blocks in 1usize..8, wdec in 0.0..1.0f64, split in 0.0..1.0f64, mask: u64) {
        check_const_equals_dyn::<f64, 1>(seed, blocks, wdec, split, mask)?;
    }
    #[test]
    fn const_equals_dyn_bitwise_f64_n5(seed: u64, blocks in 2usize..20, wdec in 0.0..1.0f64, split in 0.0..1.0f64, mask: u64) {
        check_const_equals_dyn::<f64, 5>(seed, blocks, wdec, split, mask)?;
    }
    #[test]
    fn const_equals_dyn_bitwise_f64_n4(seed: u64, blocks in 2usize..16, wdec in 0.0..1.0f64, split in 0.0..1.0f64, mask: u64) {
        check_const_equals_dyn::<f64, 4>(seed, blocks, wdec, split, mask)?;
    }
    #[test]
    fn const_equals_dyn_bitwise_f64_n9(seed: u64, blocks in 3usize..30, wdec in 0.0..1.0f64, split in 0.0..1.0f64, mask: u64) {
        check_const_equals_dyn::<f64, 9>(seed, blocks, wdec, split, mask)?;
    }
    #[test]
    fn const_equals_dyn_bitwise_f64_n12(seed: u64, blocks in 4usize..48, wdec in 0.0..1.0f64, split in 0.0..1.0f64, mask: u64) {
        check_const_equals_dyn::<f64, 12>(seed, blocks, wdec, split, mask)?;
    }
    #[test]
    fn const_equals_dyn_bitwise_f32_n9(seed: u64, blocks in 3usize..30, wdec in 0.0..1.0f64, split in 0.0..1.0f64, mask: u64) {
        check_const_equals_dyn::<f32, 9>(seed, blocks, wdec, split, mask)?;
    }
}

/// A case over the κ-free bound of eq. 7 (4.0× over it: error 1.55e-7
/// against 3.86e-8; κ ≈ 34, 4 equations, 3 parameters; 0.12 of the bound
/// with κ). The random stream changed with the move to the project's one
/// generator (`robcal_paper::rng::SplitMix64`), so the seeds of the cases
/// that first showed the bound needed κ (a 2000-case run, κ ≈ 60, 9
/// equations; and `.ci/props.sh` on the parser-fuzzing branch, 2.53e-5
/// against 2.30e-5) no longer draw them (0.56 and 0.03 of the κ-free bound
/// now); these two were found by a search of 400 000 problems with the new
/// stream, 5 of which were over the κ-free bound.
#[test]
fn eq7_bound_regression_kappa() {
    check_f64::<3>(5_753_322_206_045_857_732, 3, 0.9408).unwrap();
}

/// A second case over the κ-free bound (1.7×: 7.47e-6 against 4.33e-6;
/// κ ≈ 53, 4 equations), from the same search.
#[test]
fn eq7_bound_regression_kappa_2() {
    check_f64::<3>(14_111_439_246_169_560_396, 4, 0.977).unwrap();
}
