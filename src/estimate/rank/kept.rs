//! The kept set of [`super::identifiability`]: the kept block of the
//! scaled `Λ` factored, and the kept set verified (a column whose variance
//! inflation exceeds the tolerance's inverse left out, worst first).

use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector, RealField};

use super::super::factor::{
    cholesky_in_place, pivot_tolerance, solve_lower_in_place, solve_upper_t_in_place,
};
use super::super::Alloc;
use crate::error::Error;

/// The kept block of the scaled `a` (identity elsewhere), factored by a
/// plain Cholesky in layout order with pivot tolerance `tol`.
pub(super) fn kept_factor<T: RealField + Copy, D: Dim>(
    a: &OMatrix<T, D, D>,
    kept: &OVector<bool, D>,
    tol: T,
) -> Result<OMatrix<T, D, D>, Error>
where
    DefaultAllocator: Alloc<D>,
{
    let dim = a.shape_generic().0;
    let mut l = OMatrix::<T, D, D>::from_fn_generic(dim, dim, |i, j| {
        if kept[i] && kept[j] {
            a[(i, j)]
        } else if i == j {
            T::one()
        } else {
            T::zero()
        }
    });
    cholesky_in_place(&mut l, tol)?;
    Ok(l)
}

/// Whether every kept column of the scaled `a` has `1 − R²` on all the
/// other kept ones (`1/VIF`, from the kept block factored in layout
/// order) above `tolerance`; `false` when the block does not factor.
pub(super) fn within_inflation<T: RealField + Copy, D: Dim>(
    a: &OMatrix<T, D, D>,
    kept: &OVector<bool, D>,
    tolerance: T,
) -> bool
where
    DefaultAllocator: Alloc<D>,
{
    let Ok(l) = kept_factor(a, kept, T::zero()) else {
        return false;
    };
    let (n, dim) = (a.nrows(), a.shape_generic().0);
    (0..n).filter(|&d| kept[d]).all(|d| {
        let mut x = OVector::<T, D>::zeros_generic(dim, Const::<1>);
        x[d] = T::one();
        solve_lower_in_place(&l, &mut x);
        solve_upper_t_in_place(&l, &mut x);
        let vif = x[d];
        vif.is_finite() && vif > T::zero() && T::one() / vif > tolerance
    })
}

/// The greedy pivots bound each kept column's `1 − R²` on the columns kept
/// *before it in pivot order*, not on all the others. On rare near-dependent
/// sets (a random 6R chain with 24 geometric parameters and 21 poses:
/// every greedy pivot ≥ 5e-6 of the largest) the kept block is nevertheless
/// numerically singular, and the solver ([`crate::estimate::Factor`], a plain
/// Cholesky in layout order with [`pivot_tolerance`]) would refuse it. When
/// the kept block does not factor as the solver factors it (with twice its
/// tolerance), the criterion is applied as stated — `1 − R² = 1/VIF` of
/// every kept column on all the other kept ones above the tolerance — by
/// leaving out the most inflated column (the later one on a tie) until it
/// holds. Sets the greedy pivots got right are untouched.
pub(super) fn verify_kept<T: RealField + Copy, D: Dim>(
    a: &OMatrix<T, D, D>,
    kept: &mut OVector<bool, D>,
    left_out: &mut OVector<bool, D>,
    tolerance: T,
) where
    DefaultAllocator: Alloc<D>,
{
    let two = T::one() + T::one();
    if kept_factor(a, kept, two * pivot_tolerance::<T>()).is_ok() {
        return;
    }
    let (n, dim) = (a.nrows(), a.shape_generic().0);
    // Each round leaves one column out: at most n rounds.
    for _ in 0..n {
        let worst = match kept_factor(a, kept, T::zero()) {
            Err(Error::NotIdentifiable { column, .. }) => Some(column),
            Err(_) => None,
            Ok(l) => {
                let mut worst: Option<(usize, T)> = None;
                for d in (0..n).filter(|&d| kept[d]) {
                    let mut x = OVector::<T, D>::zeros_generic(dim, Const::<1>);
                    x[d] = T::one();
                    solve_lower_in_place(&l, &mut x);
                    solve_upper_t_in_place(&l, &mut x);
                    let vif = x[d];
                    let fine = vif.is_finite() && vif > T::zero() && T::one() / vif > tolerance;
                    if fine {
                        continue;
                    }
                    let score = if vif.is_finite() {
                        vif
                    } else {
                        T::max_value().unwrap_or(vif)
                    };
                    let replace = match worst {
                        None => true,
                        Some((_, w)) => score >= w,
                    };
                    if replace {
                        worst = Some((d, score));
                    }
                }
                worst.map(|(d, _)| d)
            }
        };
        match worst {
            Some(d) if d < n && kept[d] => {
                kept[d] = false;
                left_out[d] = true;
            }
            _ => return,
        }
    }
}
