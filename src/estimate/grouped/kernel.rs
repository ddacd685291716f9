//! The row update of [`super::GroupedStats`]: `S += b bᵀ`, `u += b y`,
//! `yy += y²` per axis, and the magnitude bounds that let the overflow
//! check run only near overflow.

use nalgebra::{DefaultAllocator, Dim, RealField};

use super::AxisMoments;
use crate::error::Error;
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
/// vector instructions. A column `j` of `B` that is zero on all three
/// axes is left out: it adds `bᵢ · 0` to column `j` of every `S` and
/// `0 · y` to `uⱼ`, exact zeros, and an `S` or `u` is never −0 (it starts
/// at +0, and a sum is −0 only when both terms are), so adding one
/// changes nothing. In one block (at most [`BLOCK`] parameters) so are
/// the two rows `i, i + 1` of a column whose columns of `B` are both zero
/// (their terms `0 · bⱼ`; every input is finite, `GroupedStats::update`
/// checked): the KR-270's rows have 5 of 9 columns that are not zero,
/// and half of the elements of their columns of `S` were such zeros
/// (the build 9.2 -> 8.1 µs). Returns `mask` with bit `j` set for every column `j`
/// that is not zero (the group's support, [`super::GroupedStats`]; 0 for
/// more than 64 parameters, not tracked).
pub(super) fn add_rows<T: RealField + Copy, D: Dim>(
    axes: &mut [AxisMoments<T, D>; 3],
    p: usize,
    bs: &[T],
    ys: &[T],
    mask: u64,
) -> u64
where
    DefaultAllocator: Alloc<D>,
{
    let zero = T::zero();
    let mut nonzero = 0u64;
    if p <= BLOCK {
        // One block, each column at a constant index, so that the
        // compiler lays every column's update out in full (a loop over
        // the columns with the test in it is not unrolled: 11 -> 14 µs on
        // the KR-270 build).
        let bt: [[T; BLOCK]; 3] = core::array::from_fn(|a| {
            core::array::from_fn(|k| bs.get(3 * k + a).copied().unwrap_or(zero))
        });
        let mut col = |j: usize, nonzero: u64| column::<T, D>(axes, p, bs, &bt, nonzero, j);
        nonzero |= col(0, nonzero);
        nonzero |= col(1, nonzero);
        nonzero |= col(2, nonzero);
        nonzero |= col(3, nonzero);
        nonzero |= col(4, nonzero);
        nonzero |= col(5, nonzero);
        nonzero |= col(6, nonzero);
        nonzero |= col(7, nonzero);
        nonzero |= col(8, nonzero);
        nonzero |= col(9, nonzero);
        nonzero |= col(10, nonzero);
        nonzero |= col(11, nonzero);
        for (a, ax) in axes.iter_mut().enumerate() {
            add_scaled(&mut ax.u.as_mut_slice()[..p], &bt[a][..p], ys[a]);
        }
        for (ax, &y) in axes.iter_mut().zip(ys) {
            ax.yy += y * y;
            ax.n += 1;
        }
        return mask | nonzero;
    }
    let mut i0 = 0;
    while i0 < p {
        let len = BLOCK.min(p - i0);
        let blk = &bs[3 * i0..3 * (i0 + len)];
        let bt: [[T; BLOCK]; 3] = core::array::from_fn(|a| {
            core::array::from_fn(|k| blk.get(3 * k + a).copied().unwrap_or(zero))
        });
        for (j, bj) in bs.chunks_exact(3).enumerate().skip(i0) {
            let nz = (bj[0] != zero) | (bj[1] != zero) | (bj[2] != zero);
            nonzero |= u64::from(nz) << (j & 63);
            if nz {
                // Rows i0 ..= j of column j, at most the block.
                let rows = (j + 1 - i0).min(len);
                for (a, ax) in axes.iter_mut().enumerate() {
                    let col = &mut ax.s_upper.as_mut_slice()[j * p + i0..j * p + i0 + rows];
                    add_scaled(col, &bt[a][..rows], bj[a]);
                }
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
    if p > 64 {
        0
    } else {
        mask | nonzero
    }
}

/// Column `j < p` of [`add_rows`]' one block: `S[0..=j, j] += b[0..=j] bⱼ`
/// on each axis unless column `j` of `B` is zero, two rows at a time,
/// leaving out the pairs of rows before `j` whose columns of `B` are both
/// zero (`nonzero`: bit `i` for the columns `i < j` that are not; their
/// terms are `0 · bⱼ`, exact zeros); its bit of the support (`1 << j`, or
/// 0).
#[inline(always)]
fn column<T: RealField + Copy, D: Dim>(
    axes: &mut [AxisMoments<T, D>; 3],
    p: usize,
    bs: &[T],
    bt: &[[T; BLOCK]; 3],
    nonzero: u64,
    j: usize,
) -> u64
where
    DefaultAllocator: Alloc<D>,
{
    let zero = T::zero();
    let Some(bj) = bs.get(3 * j..3 * j + 3).filter(|_| j < p) else {
        return 0;
    };
    if (bj[0] != zero) | (bj[1] != zero) | (bj[2] != zero) {
        // The pair that holds row `j` is always added.
        let nonzero = nonzero | (3 << (j & !1));
        for (a, ax) in axes.iter_mut().enumerate() {
            let col = &mut ax.s_upper.as_mut_slice()[j * p..j * p + j + 1];
            for_pairs(col, &bt[a], nonzero, bj[a]);
        }
        1 << j
    } else {
        0
    }
}

/// `dst[i] += src[i] * f`, two at a time, leaving out the pairs
/// `i, i + 1` whose bits in `nonzero` are both 0 (`src` is zero there, and
/// `f` finite: the terms are exact zeros); `src` at least as long as
/// `dst` (the common part otherwise).
#[inline(always)]
fn for_pairs<T: RealField + Copy>(dst: &mut [T], src: &[T], nonzero: u64, f: T) {
    let src = &src[..dst.len().min(src.len())];
    let mut d = dst.chunks_exact_mut(2);
    let mut s = src.chunks_exact(2);
    for (i, (d, s)) in (&mut d).zip(&mut s).enumerate() {
        if (nonzero >> (2 * i)) & 3 != 0 {
            d[0] += s[0] * f;
            d[1] += s[1] * f;
        }
    }
    for (d, &s) in d.into_remainder().iter_mut().zip(s.remainder()) {
        *d += s * f;
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

/// `Σ x²` over `v` in four independent lanes (vector instructions): not
/// finite when a value is not, and at least the largest value's square
/// (a sum of non-negative terms, each rounded to nearest, is at least
/// each rounded term).
#[inline(always)]
pub(super) fn sum_squares<T: RealField + Copy>(v: &[T]) -> T {
    let mut s = [T::zero(); 4];
    let mut lanes = v.chunks_exact(4);
    for c in &mut lanes {
        for (s, &x) in s.iter_mut().zip(c) {
            *s += x * x;
        }
    }
    for (s, &x) in s.iter_mut().zip(lanes.remainder()) {
        *s += x * x;
    }
    (s[0] + s[1]) + (s[2] + s[3])
}

/// The inputs of [`super::GroupedStats::update`] value by value, when
/// their sum of squares is not finite: [`Error::NonFinite`] for a value of
/// `B` (`bs`) or of `Δp` (`ys`) that is not finite (`B` first), otherwise
/// the square of the largest magnitude. (Rarely needed: out of line.)
#[cold]
#[inline(never)]
pub(super) fn finite_magnitude<T: RealField + Copy>(bs: &[T], ys: &[T]) -> Result<T, Error> {
    let (mb, fb) = magnitude(bs);
    let (my, fy) = magnitude(ys);
    if !fb {
        return Err(Error::NonFinite { what: "row" });
    }
    if !fy {
        return Err(Error::NonFinite { what: "dp" });
    }
    let m = if mb > my { mb } else { my };
    Ok(m * m)
}

/// The largest magnitude in `v` and whether every value is finite (four
/// independent maxima, not one chain of dependent compares; finite as
/// `x · 0 = 0`, a floating-point compare, where `is_finite` compares the
/// bits as a 64-bit integer, which SSE2 does not have).
fn magnitude<T: RealField + Copy>(v: &[T]) -> (T, bool) {
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
/// included, from `m2 ≥ fl(m · m)`: `(bound + m2)(1 + 8ε)`, `ε` the
/// machine epsilon (the two roundings of the sum and the three of the
/// bound are each at most `ε/2` relative).
pub(super) fn grow<T: RealField + Copy>(bound: T, m2: T) -> T {
    let eight: T = nalgebra::convert(8.0);
    (bound + m2) * (T::one() + eight * T::default_epsilon())
}
