//! Error paths of the solve: too few equations, singular and
//! near-singular systems (`NotIdentifiable` naming the right column, with
//! the condition it saw), and that a solve never changes the accumulator.

use host_tests::{snapshot, Rng, ToF64};
use nalgebra::{Const, SMatrix, Vector3, U2};
use robcal::{Accumulator, Block, Error};

const N: usize = 4;
type D = Const<N>;

/// Random blocks whose column `dup` is a copy of column `of` (times
/// `factor`), or of the combination `col0 + col1` when `of == usize::MAX`.
fn with_dependent_column<T: ToF64>(
    dup: usize,
    of: usize,
    factor: f64,
    blocks: usize,
) -> Accumulator<T, D> {
    let mut rng = Rng::new(3 + dup as u64);
    let mut acc = Accumulator::new();
    for _ in 0..blocks {
        let mut b = SMatrix::<f64, 3, N>::from_fn(|_, _| rng.normal());
        for r in 0..3 {
            b[(r, dup)] = if of == usize::MAX {
                b[(r, 0)] + b[(r, 1)]
            } else {
                factor * b[(r, of)]
            };
        }
        let dp = Vector3::from_fn(|_, _| rng.normal());
        acc.update(&Block::new(b.map(T::of_f64), dp.map(T::of_f64)))
            .unwrap();
    }
    acc
}

fn not_identifiable<T: ToF64>(acc: &Accumulator<T, D>) -> (usize, f64) {
    let before = snapshot(acc);
    let r = acc.solve();
    assert_eq!(snapshot(acc), before, "solve changed the accumulator");
    match r {
        Err(Error::NotIdentifiable { column, rcond }) => {
            assert!((0.0..=1.0).contains(&rcond), "rcond {rcond}");
            (column, rcond)
        }
        other => panic!("expected NotIdentifiable, got {other:?}"),
    }
}

fn duplicates<T: ToF64>() {
    // Column j duplicates an earlier column i: j is named (the first
    // parameter that is a combination of the ones before it).
    for (dup, of) in [(1, 0), (2, 0), (3, 1), (3, 2)] {
        for factor in [1.0, -2.5, 1e-3] {
            let acc = with_dependent_column::<T>(dup, of, factor, 6);
            let (column, rcond) = not_identifiable(&acc);
            assert_eq!(column, dup, "duplicate of {of} × {factor}");
            assert!(rcond < 1e-3, "rcond {rcond}");
        }
    }
    // Column 3 = column 0 + column 1.
    let acc = with_dependent_column::<T>(3, usize::MAX, 1.0, 6);
    assert_eq!(not_identifiable(&acc).0, 3);
    // Holding the dependent parameter at zero makes the rest identifiable.
    let acc = with_dependent_column::<T>(2, 0, 1.0, 6);
    let sol = acc.solve_active(&[true, true, false, true]).unwrap();
    assert_eq!(sol.x[2], T::zero());
    assert_eq!(sol.parameters(), 3);
}

#[test]
fn duplicate_column_names_the_later_column_f64() {
    duplicates::<f64>();
}

#[test]
fn duplicate_column_names_the_later_column_f32() {
    duplicates::<f32>();
}

#[test]
fn zero_column_is_not_identifiable() {
    let mut acc = Accumulator::<f64, D>::new();
    let mut rng = Rng::new(1);
    for _ in 0..4 {
        let mut b = SMatrix::<f64, 3, N>::from_fn(|_, _| rng.normal());
        b.set_column(2, &Vector3::zeros());
        acc.update(&Block::new(b, Vector3::new(1.0, 2.0, 3.0)))
            .unwrap();
    }
    assert_eq!(
        acc.solve(),
        Err(Error::NotIdentifiable {
            column: 2,
            rcond: 0.0
        })
    );
    // Without parameter 2 it solves.
    assert!(acc.solve_active(&[true, true, false, true]).is_ok());
}

#[test]
fn too_few_equations() {
    let mut acc = Accumulator::<f64, D>::new();
    assert_eq!(
        acc.solve(),
        Err(Error::TooFewEquations {
            equations: 0,
            parameters: 4
        })
    );
    let b = SMatrix::<f64, 3, N>::from_fn(|i, j| (i + 2 * j) as f64 + 1.0);
    let mut blk = Block::new(b, Vector3::new(1.0, 2.0, 3.0));
    blk.rows = 3;
    acc.update(&blk).unwrap();
    assert_eq!(
        acc.solve(),
        Err(Error::TooFewEquations {
            equations: 3,
            parameters: 4
        })
    );
    // Zero-weight rows are not equations.
    let mut acc = Accumulator::<f64, U2>::new();
    let b = SMatrix::<f64, 3, 2>::new(1.0, 0.0, 0.0, 1.0, 1.0, 1.0);
    acc.update(&Block::new(b, Vector3::zeros()).with_weights(Vector3::new(1.0, 0.0, 0.0)))
        .unwrap();
    assert_eq!(
        acc.solve(),
        Err(Error::TooFewEquations {
            equations: 1,
            parameters: 2
        })
    );
    // Fewer active parameters: enough.
    assert!(acc.solve_active(&[true, false]).is_ok());
}

#[test]
fn near_collinear_is_refused_with_the_condition_seen() {
    // Column 1 = column 0 + δ·noise: the squared correlation is
    // 1 − O(δ²), the Cholesky pivot of column 1 is O(δ²). f64 refuses
    // below √ε ≈ 1.5e-8, i.e. around δ ≈ 1e-4; f32 below 3.5e-4, δ ≈ 2e-2.
    fn pivot_refusal<T: ToF64>(delta: f64) -> Result<f64, (usize, f64)> {
        let mut rng = Rng::new(5);
        let mut acc = Accumulator::<T, U2>::new();
        for _ in 0..50 {
            let c0 = Vector3::from_fn(|_, _| rng.normal());
            let c1 = c0 + Vector3::from_fn(|_, _| delta * rng.normal());
            let b = SMatrix::<f64, 3, 2>::from_columns(&[c0, c1]);
            acc.update(&Block::new(
                b.map(T::of_f64),
                (b * nalgebra::Vector2::new(1.0, 1.0)).map(T::of_f64),
            ))
            .unwrap();
        }
        match acc.solve() {
            Ok(s) => Ok(s.rcond.f64()),
            Err(Error::NotIdentifiable { column, rcond }) => Err((column, rcond)),
            Err(e) => panic!("{e}"),
        }
    }
    assert!(pivot_refusal::<f64>(1e-3).is_ok());
    let (col, rcond) = pivot_refusal::<f64>(1e-5).unwrap_err();
    assert_eq!(col, 1);
    assert!(rcond < 1.5e-8, "rcond {rcond}");
    assert!(pivot_refusal::<f32>(1e-1).is_ok());
    let (col, rcond) = pivot_refusal::<f32>(1e-3).unwrap_err();
    assert_eq!(col, 1);
    assert!(rcond < 3.5e-4, "rcond {rcond}");
}
