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

/// `A v`, each element summed in index order.
pub(crate) fn mat_vec<T: RealField + Copy, D: Dim>(
    a: &OMatrix<T, D, D>,
    v: &OVector<T, D>,
) -> OVector<T, D>
where
    DefaultAllocator: Alloc<D>,
{
    OVector::from_fn_generic(v.shape_generic().0, nalgebra::Const::<1>, |i, _| {
        (0..v.len()).fold(T::zero(), |s, k| s + a[(i, k)] * v[k])
    })
}

/// `A B` of square matrices, each element summed in index order.
pub(crate) fn mat_mul<T: RealField + Copy, D: Dim>(
    a: &OMatrix<T, D, D>,
    b: &OMatrix<T, D, D>,
) -> OMatrix<T, D, D>
where
    DefaultAllocator: Alloc<D>,
{
    let dim = a.shape_generic().0;
    let n = a.nrows();
    OMatrix::from_fn_generic(dim, dim, |i, j| {
        (0..n).fold(T::zero(), |s, k| s + a[(i, k)] * b[(k, j)])
    })
}
