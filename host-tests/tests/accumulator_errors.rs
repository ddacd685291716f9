//! Every error path of `Accumulator::update` and `merge`, in f64 and f32,
//! and the state after each rejection: bit-identical (the `Debug` text of
//! every raw field, the widened bit patterns of `Λ`, `M`, `η`, `ΣΔpᵀW²Δp`
//! and the counts, and `==` on the whole accumulator — the state never
//! holds a NaN, so `==` is meaningful).

use host_tests::{snapshot, Rng, ToF64};
use nalgebra::{Const, SMatrix, Vector3};
use robcal::{Accumulator, Block, Error};

const N: usize = 3;
type D = Const<N>;

/// A non-trivial accumulator: 5 blocks with weights and σ.
fn primed<T: ToF64>() -> Accumulator<T, D> {
    let mut rng = Rng::new(7);
    let mut acc = Accumulator::new();
    for _ in 0..5 {
        let b = SMatrix::<T, 3, N>::from_fn(|_, _| T::of_f64(rng.normal()));
        let dp = Vector3::from_fn(|_, _| T::of_f64(rng.normal()));
        let w = Vector3::from_fn(|_, _| T::of_f64(rng.range(0.5, 2.0)));
        let s = Vector3::from_fn(|_, _| T::of_f64(rng.range(1e-3, 1e-2)));
        acc.update(&Block::new(b, dp).with_weights(w).with_sigma(s))
            .unwrap();
    }
    acc
}

fn good<T: ToF64>() -> Block<T, D> {
    let b = SMatrix::<T, 3, N>::from_fn(|i, j| T::of_f64((i * N + j) as f64 * 0.25 - 1.0));
    Block::new(b, Vector3::from_fn(|i, _| T::of_f64(i as f64)))
        .with_weights(Vector3::repeat(T::one()))
        .with_sigma(Vector3::repeat(T::of_f64(1e-3)))
}

/// `update(block)` fails with `expected` and leaves `acc` bit-identical.
#[track_caller]
fn rejects<T: ToF64>(acc: &mut Accumulator<T, D>, block: &Block<T, D>, expected: Error) {
    let before = snapshot(acc);
    let copy = acc.clone();
    assert_eq!(acc.update(block), Err(expected), "block {block:?}");
    assert_eq!(snapshot(acc), before, "state changed after {expected:?}");
    assert!(*acc == copy);
    // And the error is printable.
    assert!(!expected.to_string().is_empty());
}

fn non_finite_values<T: ToF64>() -> [T; 3] {
    [
        T::of_f64(f64::NAN),
        T::of_f64(f64::INFINITY),
        T::of_f64(f64::NEG_INFINITY),
    ]
}

/// `big`: a value whose square overflows `T`; `half`: `√max / 2`, whose
/// square fits but a few of which overflow a sum.
fn all_error_paths<T: ToF64>(big: f64, half: f64) {
    let mut acc = primed::<T>();
    for v in non_finite_values::<T>() {
        for r in 0..3 {
            for c in 0..N {
                let mut b = good::<T>();
                b.b[(r, c)] = v;
                rejects(&mut acc, &b, Error::NonFinite { what: "row" });
            }
            let mut b = good::<T>();
            b.dp[r] = v;
            rejects(&mut acc, &b, Error::NonFinite { what: "dp" });
            let mut b = good::<T>();
            b.w[r] = v;
            rejects(&mut acc, &b, Error::NonFinite { what: "weight" });
            let mut b = good::<T>();
            b.sigma.as_mut().unwrap()[r] = v;
            rejects(&mut acc, &b, Error::NonFinite { what: "sigma" });
        }
    }
    for r in 0..3 {
        for s in [0.0, -0.0, -1e-3, -f64::MIN_POSITIVE] {
            let mut b = good::<T>();
            b.sigma.as_mut().unwrap()[r] = T::of_f64(s);
            rejects(&mut acc, &b, Error::NotPositive { what: "sigma" });
        }
        for w in [-1.0, -1e-30] {
            let mut b = good::<T>();
            b.w[r] = T::of_f64(w);
            rejects(&mut acc, &b, Error::NotPositive { what: "weight" });
        }
    }
    for rows in [0, 4, 5, usize::MAX] {
        let mut b = good::<T>();
        b.rows = rows;
        rejects(
            &mut acc,
            &b,
            Error::OutOfRange {
                what: "block rows",
                index: rows,
                len: 4,
            },
        );
    }
    // Overflow of one update: a value `big` whose square overflows, in B,
    // Δp, w and σ (w⁴σ² of the middle term).
    let overflow = Error::NonFinite { what: "overflow" };
    for r in 0..3 {
        let mut b = good::<T>();
        b.b[(r, 1)] = T::of_f64(big);
        rejects(&mut acc, &b, overflow);
        let mut b = good::<T>();
        b.dp[r] = T::of_f64(-big);
        rejects(&mut acc, &b, overflow);
        let mut b = good::<T>();
        b.w[r] = T::of_f64(big);
        rejects(&mut acc, &b, overflow);
        let mut b = good::<T>();
        b.sigma.as_mut().unwrap()[r] = T::of_f64(big);
        rejects(&mut acc, &b, overflow);
    }
    // Overflow of the running sums: each update alone is fine, the sum is
    // not (one update adds max/4 to Λ₁₁).
    let mut b = good::<T>();
    b.b[(0, 0)] = T::of_f64(half);
    let mut sums = acc.clone();
    let mut n = 0;
    loop {
        let before = snapshot(&sums);
        match sums.update(&b) {
            Ok(()) => n += 1,
            Err(e) => {
                assert_eq!(e, overflow);
                assert_eq!(snapshot(&sums), before);
                break;
            }
        }
        assert!(n < 100, "sums never overflowed");
    }
    assert!(n >= 1);
    // Merge overflow: the accumulator that is almost full merged with
    // itself; `self` unchanged.
    let copy = sums.clone();
    let before = snapshot(&sums);
    assert_eq!(sums.merge(&copy), Err(overflow));
    assert_eq!(snapshot(&sums), before);
    // The primed accumulator is still what it was after all that.
    assert!(acc == primed::<T>());
    // And a good block is still accepted.
    acc.update(&good::<T>()).unwrap();
}

#[test]
fn every_update_error_f64() {
    all_error_paths::<f64>(1e200, f64::MAX.sqrt() / 2.0);
}

#[test]
fn every_update_error_f32() {
    all_error_paths::<f32>(1e30, f64::from(f32::MAX).sqrt() / 2.0);
}

#[test]
fn rejection_after_many_random_states_is_bit_identical() {
    // From 200 random states (incl. merges), one random invalid block each.
    let mut rng = Rng::new(11);
    for k in 0..200 {
        let mut acc = primed::<f64>();
        for _ in 0..(k % 7) {
            let other = primed::<f64>();
            acc.merge(&other).unwrap();
        }
        let mut b = good::<f64>();
        let r = (rng.next_u64() % 3) as usize;
        let bad = [f64::NAN, f64::INFINITY, -1.0, 1e300][(rng.next_u64() % 4) as usize];
        match rng.next_u64() % 4 {
            0 => b.b[(r, (rng.next_u64() % N as u64) as usize)] = bad,
            1 => b.dp[r] = bad,
            2 => b.w[r] = bad,
            _ => b.sigma.as_mut().unwrap()[r] = bad,
        }
        let before = snapshot(&acc);
        if acc.update(&b).is_err() {
            assert_eq!(snapshot(&acc), before);
        }
    }
}

#[test]
fn zero_weight_drops_the_row() {
    let mut acc = primed::<f64>();
    let eqs = acc.equations();
    let mut b = good::<f64>();
    b.w = Vector3::new(0.0, 1.0, 0.0);
    acc.update(&b).unwrap();
    assert_eq!(acc.equations(), eqs + 1);
    assert_eq!(acc.sigma_rows(), 15 + 1);
}

#[test]
fn unused_rows_of_b_w_and_sigma_are_ignored() {
    // `rows` = 1: rows 1 and 2 of B, w and σ are not read.
    let mut acc = primed::<f64>();
    let mut b = good::<f64>();
    b.rows = 1;
    b.b[(1, 0)] = f64::NAN;
    b.b[(2, 2)] = f64::INFINITY;
    b.w[1] = -1.0;
    b.sigma.as_mut().unwrap()[2] = f64::NAN;
    acc.update(&b).unwrap();
    assert_eq!(acc.equations(), 16);
}

// A regression of the first session's finding F2: `Block::rows` says "rows past
// it are ignored", and they are for B, w and σ, but not for Δp: the update
// multiplies the zero weighted row by Δp[r] for all three rows, so a NaN or
// ∞ in an unused Δp makes 0·NaN = NaN and the block is rejected as
// "overflow" (the state stays intact; the error is wrong and misleading).
#[test]
fn unused_rows_of_dp_are_ignored() {
    for v in [f64::NAN, f64::INFINITY] {
        let mut acc = primed::<f64>();
        let mut b = good::<f64>();
        b.rows = 2;
        b.dp[2] = v;
        assert_eq!(acc.update(&b), Ok(()));
        assert!(acc.eta().iter().all(|e| e.is_finite()));
    }
}

#[test]
fn reset_forgets_everything() {
    let mut acc = primed::<f32>();
    acc.reset();
    assert!(acc == Accumulator::new());
    assert_eq!(acc.equations(), 0);
}

/// Masks are slices now: one flag per parameter, else `Mismatch` (and the
/// accumulator is untouched).
#[test]
fn mask_of_the_wrong_length_is_a_mismatch() {
    let acc = primed::<f64>();
    let before = snapshot(&acc);
    for mask in [&[true, true][..], &[true; 4][..], &[][..]] {
        assert!(
            matches!(acc.solve_active(mask), Err(Error::Mismatch { .. })),
            "mask of {} flags",
            mask.len()
        );
    }
    assert_eq!(snapshot(&acc), before);
    assert!(acc.solve_active(&[true; N]).is_ok());
}

/// At `Dyn` the block's width is a run-time value: a block of another width
/// is refused with `Mismatch`, and the state is bit-identical.
#[test]
fn dyn_block_of_another_width_is_a_mismatch() {
    use nalgebra::{Dyn, OMatrix, U3};
    let mut acc = Accumulator::<f64, Dyn>::zeros(Dyn(N));
    acc.update(&host_tests::to_dyn(&good::<f64>())).unwrap();
    let before = snapshot(&acc);
    for width in [0, N - 1, N + 1] {
        let b = OMatrix::<f64, U3, Dyn>::from_element_generic(U3, Dyn(width), 1.0);
        let blk = Block::new(b, Vector3::zeros());
        assert!(
            matches!(acc.update(&blk), Err(Error::Mismatch { .. })),
            "width {width}"
        );
        assert_eq!(snapshot(&acc), before);
    }
    // Merging accumulators of different sizes, likewise.
    let other = Accumulator::<f64, Dyn>::zeros(Dyn(N + 1));
    assert!(matches!(acc.merge(&other), Err(Error::Mismatch { .. })));
    assert_eq!(snapshot(&acc), before);
}

/// No parameters at all (`Dyn(0)`, `Const<0>`): an update only counts its
/// rows and adds `Σ Δpᵀ W² Δp` — it does not panic (the kernels' chunk
/// sizes are at least 1).
#[test]
fn zero_parameters_update_without_panic() {
    use nalgebra::{Dyn, OMatrix, U3};
    fn check<T: ToF64, D: nalgebra::Dim>(mut acc: Accumulator<T, D>, dim: D)
    where
        nalgebra::DefaultAllocator: robcal::estimate::Alloc<D>,
    {
        for rows in 1..=3 {
            let b = OMatrix::<T, U3, D>::from_element_generic(U3, dim, T::one());
            let mut blk = Block::new(b, Vector3::repeat(T::of_f64(2.0)));
            blk.rows = rows;
            acc.update(&blk).unwrap();
        }
        assert_eq!(acc.equations(), 6);
        assert_eq!(acc.weighted_yy().f64(), 24.0);
    }
    check(Accumulator::<f64, Dyn>::zeros(Dyn(0)), Dyn(0));
    check(Accumulator::<f32, Dyn>::zeros(Dyn(0)), Dyn(0));
    check(Accumulator::<f64, Const<0>>::new(), Const::<0>);
    check(Accumulator::<f32, Const<0>>::new(), Const::<0>);
}
