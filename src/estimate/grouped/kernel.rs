//! The row update of [`super::GroupedStats`]: `S += b bᵀ`, `u += b y`,
//! `yy += y²` per axis, and the magnitude bounds that let the overflow
//! check run only near overflow.

use nalgebra::{DefaultAllocator, Dim, RealField};

use super::AxisMoments;
use crate::estimate::Alloc;

/// Rows of `B` per block of [`add_rows`]: the block's rows, axis by axis,
/// on the stack.
const BLOCK: usize = 12;

/// `S += b bᵀ` (upper triangle), `u += b y`, `yy += y²` and one more row,
/// for each axis `a` its row `b = B[a, ·]` and `y = Δp[a]` (`bs`: `B`,
/// 3 × `p` column-major). Every element is its old value plus one
/// product, `bᵢ bⱼ` or `bᵢ y`, so the order of the elements does not
/// matter to the result: `B`'s rows are copied to contiguous stack arrays
/// (blocks of [`BLOCK`] parameters) and each column of `S` is updated
/// from them two elements at a time, which the compiler turns into
/// vector instructions.
pub(super) fn add_rows<T: RealField + Copy, D: Dim>(
    axes: &mut [AxisMoments<T, D>; 3],
    p: usize,
    bs: &[T],
    ys: &[T],
) where
    DefaultAllocator: Alloc<D>,
{
    let zero = T::zero();
    let mut i0 = 0;
    while i0 < p {
        let len = BLOCK.min(p - i0);
        let blk = &bs[3 * i0..3 * (i0 + len)];
        let bt: [[T; BLOCK]; 3] = core::array::from_fn(|a| {
            core::array::from_fn(|k| blk.get(3 * k + a).copied().unwrap_or(zero))
        });
        for (j, bj) in bs.chunks_exact(3).enumerate().skip(i0) {
            // Rows i0 ..= j of column j, at most the block.
            let rows = (j + 1 - i0).min(len);
            for (a, ax) in axes.iter_mut().enumerate() {
                let col = &mut ax.s_upper.as_mut_slice()[j * p + i0..j * p + i0 + rows];
                add_scaled(col, &bt[a][..rows], bj[a]);
            }
        }
        for (a, ax) in axes.iter_mut().enumerate() {
            let y = ys[a];
            add_scaled(&mut ax.u.as_mut_slice()[i0..i0 + len], &bt[a][..len], y);
        }
        i0 += len;
    }
    for (ax, &y) in axes.iter_mut().zip(ys) {
        ax.yy += y * y;
        ax.n += 1;
    }
}

/// `dst[i] += src[i] * f`, two at a time.
#[inline(always)]
fn add_scaled<T: RealField + Copy>(dst: &mut [T], src: &[T], f: T) {
    let mut d = dst.chunks_exact_mut(2);
    let mut s = src.chunks_exact(2);
    for (d, s) in (&mut d).zip(&mut s) {
        d[0] += s[0] * f;
        d[1] += s[1] * f;
    }
    for (d, &s) in d.into_remainder().iter_mut().zip(s.remainder()) {
        *d += s * f;
    }
}

/// `mask` with bit `j` set for every column `j` of `B` (3 × `p`,
/// column-major) that has a value that is not zero: only the columns not
/// in it yet are looked at (none once every column is: full rows cost
/// nothing after the first). 0 for more than 64 parameters (not tracked).
#[inline(always)]
pub(super) fn grow_support<T: RealField + Copy>(mask: u64, bs: &[T], p: usize) -> u64 {
    if p == 0 || p > 64 {
        return 0;
    }
    let zero = T::zero();
    let full = u64::MAX >> (64 - p);
    let (mut rest, mut m) = (!mask & full, mask);
    while rest != 0 {
        let j = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        if let Some(c) = bs.get(3 * j..3 * j + 3) {
            if (c[0] != zero) | (c[1] != zero) | (c[2] != zero) {
                m |= 1 << j;
            }
        }
    }
    m
}

/// The largest magnitude in `v` and whether every value is finite (four
/// independent maxima, not one chain of dependent compares; finite as
/// `x · 0 = 0`, a floating-point compare, where `is_finite` compares the
/// bits as a 64-bit integer, which SSE2 does not have).
pub(super) fn magnitude<T: RealField + Copy>(v: &[T]) -> (T, bool) {
    let zero = T::zero();
    let mut m = [zero; 4];
    let mut finite = true;
    let mut lanes = v.chunks_exact(4);
    for c in &mut lanes {
        for (m, &x) in m.iter_mut().zip(c) {
            let a = x.abs();
            finite &= a * zero == zero;
            *m = if a > *m { a } else { *m };
        }
    }
    for (m, &x) in m.iter_mut().zip(lanes.remainder()) {
        let a = x.abs();
        finite &= a * zero == zero;
        *m = if a > *m { a } else { *m };
    }
    let max = |a: T, b: T| if a > b { a } else { b };
    (max(max(m[0], m[1]), max(m[2], m[3])), finite)
}

/// A bound of `|v + x y|` for `|v| ≤ bound` and `|x|, |y| ≤ m`, rounding
/// included: `(bound + m²)(1 + 8ε)`, `ε` the machine epsilon (the two
/// roundings of the sum and the three of the bound are each at most `ε/2`
/// relative).
pub(super) fn grow<T: RealField + Copy>(bound: T, m: T) -> T {
    let eight: T = nalgebra::convert(8.0);
    (bound + m * m) * (T::one() + eight * T::default_epsilon())
}
