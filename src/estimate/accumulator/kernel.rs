//! The per-measurement update's kernel ([`super::Accumulator::update`]):
//! the checked row weights of one block and the column passes that add
//! `b bᵀ w²` (and `w⁴σ²`) to the upper triangles, with the overflow bound
//! they keep.

use nalgebra::{DefaultAllocator, Dim, OMatrix, RealField};

use super::super::Alloc;

/// The checked per-row quantities of one block: `w²`, `w⁴σ²` (with σ), `Δp`
/// (all zero past the block's rows) and the rows with a positive weight.
pub(super) struct RowWeights<T> {
    pub(super) w2: [T; 3],
    pub(super) s2: [T; 3],
    pub(super) sigma: bool,
    pub(super) y: [T; 3],
    pub(super) equations: usize,
}

impl<T: RealField + Copy> RowWeights<T> {
    /// The weights of the first `rows` rows (`1 ≤ rows ≤ 3`), `None` when a
    /// weight is negative or NaN or a σ is not positive (NaN included).
    // `!(w >= 0)` is meant: it is true for NaN, which `w < 0` is not.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    #[inline(always)]
    pub(super) fn new(
        dp: &nalgebra::Vector3<T>,
        w: &nalgebra::Vector3<T>,
        sigma: Option<&nalgebra::Vector3<T>>,
        rows: usize,
    ) -> Option<Self> {
        let zero = T::zero();
        let mut rw = Self {
            w2: [zero; 3],
            s2: [zero; 3],
            sigma: sigma.is_some(),
            y: [zero; 3],
            equations: 0,
        };
        // Row by row, unrolled (three calls, not a loop: the firmware
        // profile would not unroll it).
        let mut row = |r: usize| -> Option<()> {
            if r >= rows {
                return Some(());
            }
            let (wr, k) = (w[r], w[r] * w[r]);
            if !(wr >= zero) {
                return None;
            }
            rw.w2[r] = k;
            rw.y[r] = dp[r];
            rw.equations += usize::from(k > zero);
            if let Some(s) = sigma {
                if !(s[r] > zero) {
                    return None;
                }
                rw.s2[r] = k * k * s[r] * s[r];
            }
            Some(())
        };
        row(0)?;
        row(1)?;
        row(2)?;
        Some(rw)
    }
}

/// `x + Σ_r u_r v_r`, summed left to right (three multiply-adds).
#[inline(always)]
fn fma3<T: RealField + Copy>(x: T, u: &[T; 3], v: &[T; 3]) -> T {
    ((x + u[0] * v[0]) + u[1] * v[1]) + u[2] * v[2]
}

/// The growth factor of the running bound per update, `1 + 2⁻¹⁰`: it covers
/// the rounding of the bound and of the sums it bounds (a few units of
/// `1 + ε` per update), so that the bound stays above every checked value
/// (up to absolute errors of the order of the smallest normal number, from
/// underflow, far below the headroom of the limit).
#[inline(always)]
pub(super) fn bound_margin<T: RealField + Copy>() -> T {
    T::from_subset(&(1.0 + 1.0 / 1024.0))
}

/// The limit of the running bound, `max/16`: below it no sum of the update
/// can overflow.
#[inline(always)]
pub(super) fn bound_limit<T: RealField + Copy>() -> T {
    T::max_value().map_or(T::zero(), |m| m * T::from_subset(&0.0625))
}

/// The rank-3 update of an upper triangle, column by column: for column `j`
/// of `B` (3 × n, column-major: three contiguous values), `a = k ∘ bⱼ`
/// (`k` = `w²` or `w⁴σ²` per row), then `m[i][j] += bᵢ · a` for `i ≤ j` —
/// the diagonal included — and, with `eta`, `ηⱼ += a · Δp`, in the same
/// pass. Three multiply-adds per element, summed over the rows in order;
/// the inner loop runs over contiguous slices without bounds checks, `a` in
/// registers.
#[inline(always)]
pub(super) fn add_upper3<T: RealField + Copy, D: Dim>(
    m: &mut OMatrix<T, D, D>,
    eta: Option<&mut [T]>,
    k: &[T; 3],
    y: &[T; 3],
    b: &[T],
) where
    DefaultAllocator: Alloc<D>,
{
    let n = m.nrows();
    let bcols = b.chunks_exact(3);
    let mut etas = eta.map(|e| e.iter_mut());
    for ((j, column), bj) in m
        .as_mut_slice()
        .chunks_exact_mut(n)
        .enumerate()
        .zip(bcols.clone())
    {
        let a = [k[0] * bj[0], k[1] * bj[1], k[2] * bj[2]];
        if let Some(e) = etas.as_mut().and_then(Iterator::next) {
            *e = fma3(*e, &a, y);
        }
        for (x, bi) in column.iter_mut().zip(bcols.clone()).take(j + 1) {
            *x = ((*x + bi[0] * a[0]) + bi[1] * a[1]) + bi[2] * a[2];
        }
    }
}

/// [`add_upper3`] over the first `rows` rows of `B` only.
pub(super) fn add_upper<T: RealField + Copy, D: Dim>(
    m: &mut OMatrix<T, D, D>,
    eta: Option<&mut [T]>,
    k: &[T; 3],
    y: &[T; 3],
    b: &[T],
    rows: usize,
) where
    DefaultAllocator: Alloc<D>,
{
    let n = m.nrows();
    let bcols = b.chunks_exact(3);
    let mut etas = eta.map(|e| e.iter_mut());
    for ((j, column), bj) in m
        .as_mut_slice()
        .chunks_exact_mut(n)
        .enumerate()
        .zip(bcols.clone())
    {
        let mut a = [T::zero(); 3];
        for ((a, k), b) in a.iter_mut().zip(k).zip(bj).take(rows) {
            *a = *k * *b;
        }
        if let Some(e) = etas.as_mut().and_then(Iterator::next) {
            for (a, y) in a.iter().zip(y).take(rows) {
                *e += *a * *y;
            }
        }
        for (x, bi) in column.iter_mut().zip(bcols.clone()).take(j + 1) {
            for (b, a) in bi.iter().zip(&a).take(rows) {
                *x += *b * *a;
            }
        }
    }
}
