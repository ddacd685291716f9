//! Scripts of accumulator operations with hostile floats, and the
//! interpreter that runs them while checking the invariants of issue 8.
//!
//! Shared by the cargo-fuzz targets (`fuzz/fuzz_targets/*.rs`, which decode
//! the fuzzer's bytes with [`arbitrary`]) and by the stable property tests
//! (`host-tests/tests/fuzz_props.rs`, which decode proptest's bytes the same
//! way), so both check exactly the same things:
//!
//! 1. nothing panics;
//! 2. a rejected update or merge leaves the accumulator bit-identical
//!    (`Debug` text of every raw field and [`crate::state_bits`]);
//! 3. an accepted update or merge leaves every statistic finite (no silent
//!    poisoning of later solves);
//! 4. the information matrix `Λ` and `M` are exactly symmetric;
//! 5. a successful solve returns a finite estimate, `Λ⁻¹`, residual sum and
//!    `rcond ∈ (0, 1]`, zeros for inactive parameters, and is not garbage:
//!    the scaled normal equations are satisfied to a backward error of
//!    `c·n·ε` (Cholesky is backward stable, so anything worse is a bug);
//! 6. a `NotIdentifiable` error carries a column in range and a finite
//!    `rcond ∈ [0, 1]`; every error's `Display` works.

use arbitrary::{Arbitrary, Unstructured};
use nalgebra::{Const, SMatrix, Vector3};
use robcal::{Accumulator, Block, Error};

use crate::{snapshot, ToF64};

/// Parameters in the fuzzed accumulators.
pub const FN: usize = 4;

/// The fuzzed accumulators' dimension.
pub type FD = Const<FN>;

/// Accumulators a script works on (merges go between them).
pub const SLOTS: usize = 3;

/// A float biased towards trouble: special values (NaN, ±∞, ±0,
/// subnormals, 1e±300, values that overflow when squared in f64 or when
/// rounded to f32), small exact values, or any bit pattern.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Val(pub f64);

/// The special values [`Val`] draws from.
pub const SPECIAL: [f64; 32] = [
    0.0,
    -0.0,
    1.0,
    -1.0,
    0.5,
    3.0,
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::MIN_POSITIVE,
    5e-324,
    -5e-324,
    1e-300,
    1e300,
    -1e300,
    1e154,
    1.5e154,
    1e200,
    f64::MAX,
    f64::MIN,
    f32::MAX as f64,
    3.5e38,
    1e30,
    1e19,
    1.9e19,
    1e-45,
    1.2e-38,
    1e-20,
    1e-6,
    1e-9,
    1e3,
    -2.5,
];

impl<'a> Arbitrary<'a> for Val {
    fn arbitrary(u: &mut Unstructured<'a>) -> arbitrary::Result<Self> {
        let tag = u8::arbitrary(u)?;
        Ok(Val(match tag {
            0..=79 => SPECIAL[usize::from(tag) % SPECIAL.len()],
            80..=199 => f64::from(i16::arbitrary(u)?) / 64.0,
            _ => f64::from_bits(u64::arbitrary(u)?),
        }))
    }
}

/// A measurement block as the fuzzer draws it.
#[derive(Debug, Clone, Arbitrary)]
pub struct FBlock {
    /// Rows of `B`.
    pub b: [[Val; FN]; 3],
    /// `Δp`.
    pub dp: [Val; 3],
    /// Weights.
    pub w: [Val; 3],
    /// σ per row, if any.
    pub sigma: Option<[Val; 3]>,
    /// Rows used: mostly 1..=3, sometimes 0..=5 (invalid).
    pub rows: u8,
}

impl FBlock {
    /// The block in scalar type `T` (values rounded; beyond range → ±∞).
    pub fn to_block<T: ToF64>(&self) -> Block<T, FD> {
        let v = |x: Val| T::of_f64(x.0);
        Block {
            b: SMatrix::<T, 3, FN>::from_fn(|i, j| v(self.b[i][j])),
            dp: Vector3::from_fn(|i, _| v(self.dp[i])),
            w: Vector3::from_fn(|i, _| v(self.w[i])),
            sigma: self.sigma.map(|s| Vector3::from_fn(|i, _| v(s[i]))),
            rows: if self.rows < 200 {
                1 + usize::from(self.rows % 3)
            } else {
                usize::from(self.rows % 6)
            },
        }
    }
}

/// One operation of a script. Slot indices are taken modulo [`SLOTS`].
#[derive(Debug, Clone, Arbitrary)]
pub enum Op {
    /// `acc[slot].update(block)`.
    Update {
        /// Slot.
        slot: u8,
        /// Block.
        block: FBlock,
    },
    /// The same block `repeat` times (drives sums towards overflow).
    UpdateRepeated {
        /// Slot.
        slot: u8,
        /// Block.
        block: FBlock,
        /// Repetitions (at most 64).
        repeat: u8,
    },
    /// `acc[dst].merge(&acc[src])` (a copy of `src` when `dst == src`).
    Merge {
        /// Destination slot.
        dst: u8,
        /// Source slot.
        src: u8,
    },
    /// `acc[slot].solve_active(active)` and every covariance.
    Solve {
        /// Slot.
        slot: u8,
        /// Active parameters (one flag per parameter; passed as a slice).
        active: [bool; FN],
    },
    /// `acc[slot].reset()`.
    Reset {
        /// Slot.
        slot: u8,
    },
}

/// Counts of what a script did (for the fuzz report and to show the
/// property tests reach every branch).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    /// Updates accepted.
    pub updates_ok: usize,
    /// Updates rejected.
    pub updates_rejected: usize,
    /// Merges accepted.
    pub merges_ok: usize,
    /// Merges rejected.
    pub merges_rejected: usize,
    /// Solves that returned an estimate.
    pub solves_ok: usize,
    /// Solves that returned an error.
    pub solves_rejected: usize,
}

/// Decodes a script from raw bytes (what the fuzz targets and the byte
/// property tests do): operations one after the other until the bytes run
/// out. (Not `Vec::arbitrary_take_rest`, which reads a "continue" flag
/// before each element and so stops after two operations on average for
/// random bytes.)
pub fn decode(data: &[u8]) -> Vec<Op> {
    let mut u = Unstructured::new(data);
    let mut ops = Vec::new();
    while !u.is_empty() {
        match Op::arbitrary(&mut u) {
            Ok(op) => ops.push(op),
            Err(_) => break,
        }
    }
    ops
}

fn all_finite<T: ToF64>(acc: &Accumulator<T, FD>) -> bool {
    acc.information().iter().all(|v| v.is_finite())
        && acc.middle().iter().all(|v| v.is_finite())
        && acc.eta().iter().all(|v| v.is_finite())
        && acc.weighted_yy().is_finite()
}

fn check_symmetric<T: ToF64>(acc: &Accumulator<T, FD>) {
    let l = acc.information();
    let m = acc.middle();
    for i in 0..FN {
        for j in 0..FN {
            assert!(
                l[(i, j)].bits() == l[(j, i)].bits() && m[(i, j)].bits() == m[(j, i)].bits(),
                "Λ or M not exactly symmetric at ({i}, {j})"
            );
        }
    }
}

fn check_error(e: &Error) {
    // Display must work for every error (no panic, non-empty).
    assert!(!format!("{e}").is_empty());
    if let Error::NotIdentifiable { column, rcond } = *e {
        assert!(column < FN, "NotIdentifiable column {column} out of range");
        assert!(
            rcond.is_finite() && (0.0..=1.0).contains(&rcond),
            "NotIdentifiable rcond {rcond} outside [0, 1]"
        );
    }
}

/// Checks a successful solve (invariant 5).
fn check_solution<T: ToF64>(
    acc: &Accumulator<T, FD>,
    sol: &robcal::Solution<T, FD>,
    active: &[bool],
) {
    assert!(
        sol.x.iter().all(|v| v.is_finite()),
        "non-finite estimate accepted: {:?}",
        sol.x
    );
    assert!(
        sol.lambda_inv.iter().all(|v| v.is_finite()),
        "non-finite Λ⁻¹ accepted"
    );
    assert!(
        sol.wrss.is_finite() && sol.wrss >= T::zero(),
        "weighted RSS {:?} not finite and ≥ 0",
        sol.wrss
    );
    assert!(
        sol.rcond.is_finite() && sol.rcond > T::zero() && sol.rcond <= T::one(),
        "rcond {:?} outside (0, 1]",
        sol.rcond
    );
    assert_eq!(sol.equations, acc.equations());
    assert_eq!(sol.active.as_slice(), active, "the solution's mask");
    for (j, a) in active.iter().enumerate() {
        if !a {
            assert!(sol.x[j] == T::zero(), "inactive parameter {j} not zero");
        }
    }
    // Backward error of the scaled normal equations, in f64 from the stored
    // values: Λs = SΛS, S = diag(Λ)^(-1/2), xs = S⁻¹x, rhs = Sη.
    let l = acc.information().map(ToF64::f64);
    let eta = acc.eta().map(ToF64::f64);
    let x = sol.x.map(ToF64::f64);
    let idx: Vec<usize> = (0..FN).filter(|&j| active[j]).collect();
    let s: Vec<f64> = idx.iter().map(|&j| 1.0 / l[(j, j)].sqrt()).collect();
    let xs: Vec<f64> = idx.iter().zip(&s).map(|(&j, &sj)| x[j] / sj).collect();
    let rhs: Vec<f64> = idx.iter().zip(&s).map(|(&j, &sj)| eta[j] * sj).collect();
    let n = idx.len();
    let xs_inf = xs.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
    let rhs_inf = rhs.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
    let mut res_inf = 0.0_f64;
    let mut a_inf = 0.0_f64;
    for (p, &i) in idx.iter().enumerate() {
        let mut r = -rhs[p];
        let mut row = 0.0;
        for (q, &j) in idx.iter().enumerate() {
            let a = l[(i, j)] * s[p] * s[q];
            r += a * xs[q];
            row += a.abs();
        }
        res_inf = res_inf.max(r.abs());
        a_inf = a_inf.max(row);
    }
    let eps = T::default_epsilon().f64();
    // Plus absolute floors for results in the subnormal range of `T`,
    // where "relative" rounding does not hold: in the scaled system, and
    // for the unscaled `x = S xs`, whose components can underflow when
    // `Λⱼⱼ` is huge (`xⱼ = 1e-337` is not representable; 0 is the right
    // answer — fuzz finding `f64-tiny-estimate`). Both floors are
    // ~1e-290 for problems away from the edges of the range.
    let smax = s.iter().fold(0.0_f64, |a, &v| a.max(1.0 / v));
    let floor = 1e8 * (n.max(1) as f64) * T::tiny();
    let bound = 64.0 * (n.max(1) as f64) * eps * (a_inf * xs_inf + rhs_inf)
        + floor * (1.0 + a_inf)
        + floor * a_inf * smax;
    assert!(
        res_inf <= bound || !(xs_inf.is_finite() && rhs_inf.is_finite()),
        "garbage estimate: scaled residual {res_inf:e} > {bound:e} (x = {x:?})"
    );
}

/// Runs a script on `SLOTS` accumulators of scalar `T`, asserting the
/// invariants in the [module docs](self) (panics on a violation).
pub fn run<T: ToF64>(ops: &[Op]) -> Stats {
    let mut accs: [Accumulator<T, FD>; SLOTS] = core::array::from_fn(|_| Accumulator::new());
    let mut st = Stats::default();
    for op in ops {
        match op {
            Op::Update { slot, block } => {
                update(&mut accs[usize::from(*slot) % SLOTS], block, 1, &mut st);
            }
            Op::UpdateRepeated {
                slot,
                block,
                repeat,
            } => update(
                &mut accs[usize::from(*slot) % SLOTS],
                block,
                usize::from(*repeat % 65),
                &mut st,
            ),
            Op::Merge { dst, src } => {
                let (d, s) = (usize::from(*dst) % SLOTS, usize::from(*src) % SLOTS);
                let other = accs[s].clone();
                let acc = &mut accs[d];
                let before = snapshot(acc);
                let eqs = acc.equations() + other.equations();
                match acc.merge(&other) {
                    Ok(()) => {
                        st.merges_ok += 1;
                        assert!(all_finite(acc), "accepted merge left a non-finite sum");
                        assert_eq!(acc.equations(), eqs);
                    }
                    Err(e) => {
                        st.merges_rejected += 1;
                        check_error(&e);
                        assert!(snapshot(acc) == before, "rejected merge changed the state");
                    }
                }
                check_symmetric(acc);
            }
            Op::Solve { slot, active } => {
                let acc = &accs[usize::from(*slot) % SLOTS];
                match acc.solve_active(active) {
                    Ok(sol) => {
                        st.solves_ok += 1;
                        check_solution(acc, &sol, active);
                        // The covariances must not panic (their overflow on
                        // extreme inputs is documented, not asserted).
                        let _ = sol.cov_iid();
                        let _ = sol.cov_sandwich(&acc.middle());
                        let _ = robcal::estimate::std_devs(&sol.cov_information());
                    }
                    Err(e) => {
                        st.solves_rejected += 1;
                        check_error(&e);
                    }
                }
            }
            Op::Reset { slot } => {
                let acc = &mut accs[usize::from(*slot) % SLOTS];
                acc.reset();
                assert!(*acc == Accumulator::new());
            }
        }
    }
    st
}

fn update<T: ToF64>(acc: &mut Accumulator<T, FD>, block: &FBlock, repeat: usize, st: &mut Stats) {
    let blk = block.to_block::<T>();
    for _ in 0..repeat {
        let before = snapshot(acc);
        let eqs = acc.equations();
        match acc.update(&blk) {
            Ok(()) => {
                st.updates_ok += 1;
                assert!(
                    all_finite(acc),
                    "accepted update left a non-finite sum: {blk:?}"
                );
                assert!(acc.equations() >= eqs && acc.equations() <= eqs + 3);
            }
            Err(e) => {
                st.updates_rejected += 1;
                check_error(&e);
                assert!(
                    snapshot(acc) == before,
                    "rejected update changed the state: {e:?}, {blk:?}"
                );
                check_symmetric(acc);
                return;
            }
        }
        check_symmetric(acc);
    }
}
