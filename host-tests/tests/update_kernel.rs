//! `Accumulator::update` against an independent reference, bit for bit
//! (issue 17: the update was restructured into a validation pass and one
//! commit pass; its results must be those of the two-sweep update it
//! replaced).
//!
//! The reference below is plain loops over a dense copy of the state, in
//! the order of operations the update has always had, per element:
//!
//! - `w² = w·w`, `s² = ((w²·w²)·σ)·σ` (the weight of a row in `M`);
//! - `Λᵢⱼ ← ((Λᵢⱼ + b₀ᵢ(k₀b₀ⱼ)) + b₁ᵢ(k₁b₁ⱼ)) + b₂ᵢ(k₂b₂ⱼ)` for `i ≤ j`, `k = w²`
//!   (and `k = s²` for `M`);
//! - `ηⱼ ← ((ηⱼ + (k₀b₀ⱼ)Δp₀) + (k₁b₁ⱼ)Δp₁) + (k₂b₂ⱼ)Δp₂`;
//! - `Σ Δpᵀ W² Δp ← ((yy + (k₀Δp₀)Δp₀) + (k₁Δp₁)Δp₁) + (k₂Δp₂)Δp₂`;
//! - rows past `rows` enter as zero rows of weight 0 (`x + 0·0 = x`);
//! - an update is rejected, state unchanged, when [`Block::validate`] fails
//!   or when a new diagonal of `Λ` or `M`, a new `η` or the new
//!   `Σ Δpᵀ W² Δp` is not finite (`"overflow"`).
//!
//! Products commute exactly in IEEE arithmetic (`(k b)b = b(k b)`), sums do
//! not: the reference fixes the association, and the comparison is of bit
//! patterns, in f64 and in f32 (the host never contracts `a + b·c` into a
//! fused multiply-add; on the Cortex-M4F `vmla.f32` rounds the product too,
//! so the firmware computes the same bits — its own checks compare f32 with
//! f64 within a tolerance).

use host_tests::{Rng, ToF64};
use nalgebra::{Const, DMatrix, Dim, Dyn, OMatrix, Vector3, U3};
use robcal::estimate::Alloc;
use robcal::{Accumulator, Block, Error};

/// The state of an accumulator, dense, as the reference keeps it.
#[derive(Debug, Clone, PartialEq)]
struct Reference<T> {
    n: usize,
    /// Column-major `n × n`; only `i ≤ j` is used.
    info: Vec<T>,
    middle: Vec<T>,
    eta: Vec<T>,
    yy: T,
    equations: usize,
    sigma_rows: usize,
}

impl<T: ToF64> Reference<T> {
    fn new(n: usize) -> Self {
        Self {
            n,
            info: vec![T::zero(); n * n],
            middle: vec![T::zero(); n * n],
            eta: vec![T::zero(); n],
            yy: T::zero(),
            equations: 0,
            sigma_rows: 0,
        }
    }

    /// The update, or the error it must give (state unchanged then).
    fn update<D: Dim>(&mut self, block: &Block<T, D>) -> Result<(), Error>
    where
        nalgebra::DefaultAllocator: Alloc<D>,
    {
        let n = self.n;
        if block.b.ncols() != n {
            return Err(Error::Mismatch {
                what: "block size differs from the accumulator's",
            });
        }
        block.validate()?;
        let zero = T::zero();
        // B, w², s², Δp with the unused rows zero.
        let used = |r: usize| r < block.rows;
        let b = |r: usize, j: usize| if used(r) { block.b[(r, j)] } else { zero };
        let mut k = [zero; 3];
        let mut s = [zero; 3];
        let mut y = [zero; 3];
        let mut eqs = 0;
        for r in 0..3 {
            if used(r) {
                k[r] = block.w[r] * block.w[r];
                y[r] = block.dp[r];
                if let Some(sig) = &block.sigma {
                    s[r] = k[r] * k[r] * sig[r] * sig[r];
                }
                eqs += usize::from(k[r] > zero);
            }
        }
        let sum3 = |x: T, f: &dyn Fn(usize) -> T| ((x + f(0)) + f(1)) + f(2);
        let mut next = self.clone();
        for j in 0..n {
            for i in 0..=j {
                let e = j * n + i;
                next.info[e] = sum3(self.info[e], &|r| b(r, i) * (k[r] * b(r, j)));
                if block.sigma.is_some() {
                    next.middle[e] = sum3(self.middle[e], &|r| b(r, i) * (s[r] * b(r, j)));
                }
            }
            next.eta[j] = sum3(self.eta[j], &|r| (k[r] * b(r, j)) * y[r]);
        }
        next.yy = sum3(self.yy, &|r| (k[r] * y[r]) * y[r]);
        let finite = next.yy.is_finite()
            && (0..n).all(|j| {
                let e = j * n + j;
                next.info[e].is_finite() && next.middle[e].is_finite() && next.eta[j].is_finite()
            });
        if !finite {
            return Err(Error::NonFinite { what: "overflow" });
        }
        next.equations += eqs;
        if block.sigma.is_some() {
            next.sigma_rows += eqs;
        }
        *self = next;
        Ok(())
    }

    /// Merging another accumulator's statistics (what `merge` adds).
    fn merge(&mut self, other: &Self) {
        for (a, b) in self.info.iter_mut().zip(&other.info) {
            *a += *b;
        }
        for (a, b) in self.middle.iter_mut().zip(&other.middle) {
            *a += *b;
        }
        for (a, b) in self.eta.iter_mut().zip(&other.eta) {
            *a += *b;
        }
        self.yy += other.yy;
        self.equations += other.equations;
        self.sigma_rows += other.sigma_rows;
    }
}

/// The accumulator's statistics equal the reference's, bit for bit (the
/// upper triangles of `Λ` and `M`, `η`, `Σ Δpᵀ W² Δp`, the counts).
#[track_caller]
fn same<T: ToF64, D: Dim>(acc: &Accumulator<T, D>, reference: &Reference<T>, context: &str)
where
    nalgebra::DefaultAllocator: Alloc<D>,
{
    let n = reference.n;
    let (info, middle) = (acc.information(), acc.middle());
    for j in 0..n {
        for i in 0..=j {
            let e = j * n + i;
            assert_eq!(
                info[(i, j)].bits(),
                reference.info[e].bits(),
                "{context}: Λ[{i},{j}] = {:e}, reference {:e}",
                info[(i, j)].f64(),
                reference.info[e].f64()
            );
            assert_eq!(
                middle[(i, j)].bits(),
                reference.middle[e].bits(),
                "{context}: M[{i},{j}] = {:e}, reference {:e}",
                middle[(i, j)].f64(),
                reference.middle[e].f64()
            );
        }
        assert_eq!(
            acc.eta()[j].bits(),
            reference.eta[j].bits(),
            "{context}: η[{j}]"
        );
    }
    assert_eq!(
        acc.weighted_yy().bits(),
        reference.yy.bits(),
        "{context}: yy"
    );
    assert_eq!(acc.equations(), reference.equations, "{context}: equations");
    assert_eq!(acc.sigma_rows(), reference.sigma_rows, "{context}: σ rows");
}

/// A random block of `n` columns: entries over a few decades around
/// `scale`, some zero weights, σ on about half the blocks, 1–3 rows with
/// garbage (NaN, ∞, negative weight) in the unused rows.
fn random_block<T: ToF64, D: Dim>(rng: &mut Rng, dim: D, scale: f64) -> Block<T, D>
where
    nalgebra::DefaultAllocator: Alloc<D>,
{
    let v = |rng: &mut Rng| T::of_f64(scale * rng.normal() * rng.log_uniform(-2.0, 2.0));
    let b = OMatrix::<T, U3, D>::from_fn_generic(U3, dim, |_, _| v(rng));
    let dp = Vector3::from_fn(|_, _| v(rng));
    let w = Vector3::from_fn(|_, _| match rng.next_u64() % 8 {
        0 => T::zero(),
        1 => T::one(),
        _ => T::of_f64(rng.log_uniform(-3.0, 3.0)),
    });
    let mut block = Block {
        b,
        dp,
        w,
        sigma: None,
        rows: 3,
    };
    if rng.next_u64().is_multiple_of(2) {
        block.sigma = Some(Vector3::from_fn(|_, _| {
            T::of_f64(rng.log_uniform(-6.0, 0.0))
        }));
    }
    if rng.next_u64().is_multiple_of(4) {
        block.rows = 1 + (rng.next_u64() % 2) as usize;
        for r in block.rows..3 {
            for j in 0..block.b.ncols() {
                block.b[(r, j)] = T::of_f64(f64::NAN);
            }
            block.dp[r] = T::of_f64(f64::INFINITY);
            block.w[r] = T::of_f64(-1.0);
            if let Some(s) = block.sigma.as_mut() {
                s[r] = T::of_f64(f64::NAN);
            }
        }
    }
    block
}

/// One value of a block made invalid (or huge, for the overflow paths).
fn spoil<T: ToF64, D: Dim>(rng: &mut Rng, block: &mut Block<T, D>)
where
    nalgebra::DefaultAllocator: Alloc<D>,
{
    let bad = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        -1.0,
        0.0,
        1e300,
        1e30,
        1e20,
    ][(rng.next_u64() % 8) as usize];
    let r = (rng.next_u64() % 3) as usize;
    let n = block.b.ncols();
    match rng.next_u64() % 6 {
        0 => block.b[(r, (rng.next_u64() % n as u64) as usize)] = T::of_f64(bad),
        1 => block.dp[r] = T::of_f64(bad),
        2 => block.w[r] = T::of_f64(bad),
        3 => {
            if let Some(s) = block.sigma.as_mut() {
                s[r] = T::of_f64(bad);
            } else {
                block.sigma = Some(Vector3::repeat(T::of_f64(bad)));
            }
        }
        4 => block.rows = [0, 4, usize::MAX][(rng.next_u64() % 3) as usize],
        _ => block.w[r] = T::of_f64(-bad),
    }
}

/// A stream of random updates (some invalid, a merge now and then) on an
/// accumulator of dimension `dim` and on the reference, compared after
/// every step. Returns the numbers of accepted and rejected updates.
fn stream<T: ToF64, D: Dim>(seed: u64, dim: D, steps: usize, scale: f64) -> (usize, usize)
where
    nalgebra::DefaultAllocator: Alloc<D>,
{
    let n = dim.value();
    let mut rng = Rng::new(seed);
    let mut acc = Accumulator::<T, D>::zeros(dim);
    let mut reference = Reference::<T>::new(n);
    let (mut accepted, mut rejected) = (0, 0);
    for step in 0..steps {
        let context = format!("seed {seed}, n = {n}, step {step}");
        let mut block = random_block::<T, D>(&mut rng, dim, scale);
        if rng.next_u64().is_multiple_of(5) {
            spoil(&mut rng, &mut block);
        }
        let expected = reference.update(&block);
        let before = acc.clone();
        let got = acc.update(&block);
        assert_eq!(got, expected, "{context}: {block:?}");
        if got.is_ok() {
            accepted += 1;
        } else {
            rejected += 1;
            assert!(acc == before, "{context}: state changed on {got:?}");
        }
        same(&acc, &reference, &context);
        if rng.next_u64().is_multiple_of(50) {
            // A merge with a copy (doubles everything; may overflow, then
            // both are unchanged).
            let copy = acc.clone();
            if acc.merge(&copy).is_ok() {
                let r = reference.clone();
                reference.merge(&r);
            }
            same(&acc, &reference, &format!("{context}, merge"));
        }
        if rng.next_u64().is_multiple_of(200) {
            acc.reset();
            reference = Reference::new(n);
        }
    }
    (accepted, rejected)
}

/// [`stream`] with mostly valid updates (and some rejected).
fn normal_stream<T: ToF64, D: Dim>(seed: u64, dim: D, steps: usize, scale: f64)
where
    nalgebra::DefaultAllocator: Alloc<D>,
{
    let (accepted, rejected) = stream::<T, D>(seed, dim, steps, scale);
    assert!(accepted > steps / 2, "{accepted} accepted of {steps}");
    assert!(rejected > 0, "nothing rejected in {steps} steps");
}

#[test]
fn f64_dynamic_sizes_bit_for_bit() {
    for (seed, n) in [(1, 1), (2, 2), (3, 3), (4, 5), (5, 9), (6, 12), (7, 17)] {
        normal_stream::<f64, Dyn>(seed, Dyn(n), 400, 1.0);
    }
}

#[test]
fn f32_dynamic_sizes_bit_for_bit() {
    for (seed, n) in [(11, 1), (12, 2), (13, 4), (14, 9), (15, 13)] {
        normal_stream::<f32, Dyn>(seed, Dyn(n), 400, 1.0);
    }
}

#[test]
fn fixed_size_nine_bit_for_bit() {
    // The firmware's instantiation (`Const<9>`), at the firmware's scales:
    // B in metres per unit, weights 1/σ with σ ~ 10 µm (`Λ` ~ 1e10 per row).
    for seed in 21..25 {
        normal_stream::<f64, Const<9>>(seed, Const::<9>, 400, 1.0);
        normal_stream::<f32, Const<9>>(seed + 100, Const::<9>, 400, 1.0);
        normal_stream::<f32, Const<9>>(seed + 200, Const::<9>, 200, 1e4);
    }
}

#[test]
fn near_overflow_bit_for_bit() {
    // Entries whose squares reach a sizeable part of the largest value:
    // sums overflow after a few updates (rejected, state unchanged), and
    // every accepted update, close to the limit, still matches.
    let runs = [
        stream::<f32, Dyn>(31, Dyn(4), 300, 1e16),
        stream::<f32, Const<9>>(32, Const::<9>, 300, 3e15),
        stream::<f64, Dyn>(33, Dyn(6), 300, 1e150),
        stream::<f64, Const<9>>(34, Const::<9>, 300, 3e149),
        // Scales at which the squares of some entries overflow outright.
        stream::<f32, Dyn>(35, Dyn(3), 200, 1e19),
        stream::<f64, Dyn>(36, Dyn(3), 200, 1e154),
    ];
    println!("accepted, rejected: {runs:?}");
    for (accepted, rejected) in runs {
        assert!(accepted >= 10 && rejected >= 10, "{runs:?}");
    }
}

#[test]
fn tiny_values_bit_for_bit() {
    // Subnormal products and sums (nothing overflows; zeros keep their sign).
    normal_stream::<f32, Dyn>(41, Dyn(5), 300, 1e-20);
    normal_stream::<f64, Dyn>(42, Dyn(5), 300, 1e-160);
}

#[test]
fn long_stream_up_to_overflow() {
    // One row, the same block again and again: Λ₀₀ grows to the largest
    // value; every update until the first rejection is accepted and matches,
    // the rejected one leaves the state as it was, and so do the ones after.
    for (n, scale) in [(1, 1e18), (9, 3e17)] {
        let dim = Dyn(n);
        let mut acc = Accumulator::<f32, Dyn>::zeros(dim);
        let mut reference = Reference::<f32>::new(n);
        let b = OMatrix::<f32, U3, Dyn>::from_fn_generic(U3, dim, |r, j| {
            scale * (1.0 + r as f32) / (1.0 + j as f32)
        });
        let block = Block::new(b, Vector3::new(1.0, -2.0, 3.0));
        let mut first_rejection = None;
        for step in 0..2000 {
            let expected = reference.update(&block);
            let before = acc.clone();
            let got = acc.update(&block);
            assert_eq!(got, expected, "n = {n}, step {step}");
            if got.is_err() {
                first_rejection.get_or_insert(step);
                assert!(acc == before);
            }
            same(&acc, &reference, &format!("n = {n}, step {step}"));
        }
        assert!(
            first_rejection.is_some_and(|s| s > 10),
            "{first_rejection:?}"
        );
    }
}

#[test]
fn dense_reference_agrees_with_the_batch_formula() {
    // The reference itself, checked against Bᵀ W² B of the stacked rows
    // (to rounding): it computes the statistics, not just some numbers.
    let mut rng = Rng::new(51);
    let n = 6;
    let mut reference = Reference::<f64>::new(n);
    let mut stacked = DMatrix::<f64>::zeros(0, n);
    let mut weights = Vec::new();
    for _ in 0..20 {
        let block: Block<f64, Dyn> = random_block(&mut rng, Dyn(n), 1.0);
        reference.update(&block).unwrap();
        for r in 0..block.rows {
            let m = stacked.nrows();
            stacked = stacked.insert_row(m, 0.0);
            for j in 0..n {
                stacked[(m, j)] = block.b[(r, j)];
            }
            weights.push(block.w[r] * block.w[r]);
        }
    }
    let w2 = nalgebra::DVector::from_vec(weights);
    let info = stacked.transpose() * DMatrix::from_diagonal(&w2) * &stacked;
    for j in 0..n {
        for i in 0..=j {
            let (a, b) = (reference.info[j * n + i], info[(i, j)]);
            assert!(
                (a - b).abs() <= 1e-12 * info[(i, i)].max(info[(j, j)]),
                "{i},{j}"
            );
        }
    }
}
