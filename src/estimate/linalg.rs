//! The few products the estimator needs, summed in index order in robcal's
//! own loops: the same arithmetic at every size, so that `Const<N>` on a
//! device and `Dyn` on the host give the same bits. (nalgebra sums small
//! static dot products and large dynamic matrix products in other orders.)

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, RealField};

use super::Alloc;

/// `Σᵢ aᵢ bᵢ`, in index order.
pub(crate) fn dot<T: RealField + Copy, D: Dim>(a: &OVector<T, D>, b: &OVector<T, D>) -> T
where
    DefaultAllocator: Alloc<D>,
{
    a.iter()
        .zip(b.iter())
        .fold(T::zero(), |s, (x, y)| s + *x * *y)
}

/// `A v`, each element summed in index order. (Column by column: every
/// `yᵢ` still gets its terms in the order `k = 0, 1, …`, and the inner loop
/// runs down a contiguous column.)
pub(crate) fn mat_vec<T: RealField + Copy, D: Dim>(
    a: &OMatrix<T, D, D>,
    v: &OVector<T, D>,
) -> OVector<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    let mut y = OVector::<T, D>::zeros_generic(v.shape_generic().0, nalgebra::Const::<1>);
    let n = v.len();
    let ys = y.as_mut_slice();
    for (col, &vk) in a.as_slice().chunks_exact(n.max(1)).zip(v.iter()) {
        for (yi, &aik) in ys.iter_mut().zip(col) {
            *yi += aik * vk;
        }
    }
    y
}

/// `A B` of square matrices, each element summed in index order (column
/// by column, as [`mat_vec`]).
pub(crate) fn mat_mul<T: RealField + Copy, D: Dim>(
    a: &OMatrix<T, D, D>,
    b: &OMatrix<T, D, D>,
) -> OMatrix<T, D, D>
where
    DefaultAllocator: Alloc<D>,
{
    let dim = a.shape_generic().0;
    let n = a.nrows().max(1);
    let mut c = OMatrix::<T, D, D>::zeros_generic(dim, dim);
    let a_cols = a.as_slice();
    for (c_col, b_col) in c
        .as_mut_slice()
        .chunks_exact_mut(n)
        .zip(b.as_slice().chunks_exact(n))
    {
        for (a_col, &bkj) in a_cols.chunks_exact(n).zip(b_col) {
            for (cij, &aik) in c_col.iter_mut().zip(a_col) {
                *cij += aik * bkj;
            }
        }
    }
    c
}
