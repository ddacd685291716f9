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

/// One element of the rank-3 update: `x + bᵢ · a`, summed over the rows in
/// order (three multiply-adds).
#[inline(always)]
fn madd3<T: RealField + Copy>(x: T, bi: &[T], a: &[T; 3]) -> T {
    ((x + bi[0] * a[0]) + bi[1] * a[1]) + bi[2] * a[2]
}

/// The rank-3 update of an upper triangle, three columns at a time: for
/// columns `j`, `j + 1`, `j + 2` of `B` (3 × n, column-major: three
/// contiguous values), `a = k ∘ bⱼ` (`k` = `w²` per row), then
/// `m[i][j] += bᵢ · a` for `i ≤ j` — the diagonal included — and
/// `ηⱼ += a · Δp`, in the same pass. Three multiply-adds per element, summed
/// over the rows in order. First the three columns' diagonal block (six
/// elements) and their three `η`, straight code; then the rows above the
/// block in one loop that loads each `bᵢ` once for the three columns, the
/// `a` of the three in registers (in this order the firmware's f32 update
/// takes 28 instructions less than with the rows first). The last `n mod 3`
/// columns go one at a time.
#[inline(always)]
fn add_upper3_tiled<T: RealField + Copy, D: Dim>(
    m: &mut OMatrix<T, D, D>,
    eta: &mut [T],
    k: &[T; 3],
    y: &[T; 3],
    b: &[T],
) where
    DefaultAllocator: Alloc<D>,
{
    let n = m.nrows();
    let scaled = |c: &[T]| [k[0] * c[0], k[1] * c[1], k[2] * c[2]];
    let (eta3, eta1) = eta.split_at_mut(3 * (n / 3));
    let (mut eta3, mut eta1) = (eta3.chunks_exact_mut(3), eta1.iter_mut());
    let bcols = b.chunks_exact(3);
    let mut tiles = m.as_mut_slice().chunks_exact_mut(3 * n.max(1));
    let mut btiles = b.chunks_exact(9);
    for ((t, tile), bt) in tiles.by_ref().enumerate().zip(btiles.by_ref()) {
        let j = 3 * t;
        let (c0, rest) = tile.split_at_mut(n);
        let (c1, c2) = rest.split_at_mut(n);
        let (b0, b12) = bt.split_at(3);
        let (b1, b2) = b12.split_at(3);
        let (a0, a1, a2) = (scaled(b0), scaled(b1), scaled(b2));
        let (c0, d0) = c0.split_at_mut(j);
        let (c1, d1) = c1.split_at_mut(j);
        let (c2, d2) = c2.split_at_mut(j);
        if let ([x00, ..], [x01, x11, ..], [x02, x12, x22, ..]) = (d0, d1, d2) {
            *x00 = madd3(*x00, b0, &a0);
            *x01 = madd3(*x01, b0, &a1);
            *x11 = madd3(*x11, b1, &a1);
            *x02 = madd3(*x02, b0, &a2);
            *x12 = madd3(*x12, b1, &a2);
            *x22 = madd3(*x22, b2, &a2);
        }
        if let Some([e0, e1, e2]) = eta3.next() {
            *e0 = fma3(*e0, &a0, y);
            *e1 = fma3(*e1, &a1, y);
            *e2 = fma3(*e2, &a2, y);
        }
        let rows = c0.iter_mut().zip(c1.iter_mut()).zip(c2.iter_mut());
        for (((x0, x1), x2), bi) in rows.zip(bcols.clone()) {
            *x0 = madd3(*x0, bi, &a0);
            *x1 = madd3(*x1, bi, &a1);
            *x2 = madd3(*x2, bi, &a2);
        }
    }
    let done = 3 * (n / 3);
    let rest = tiles.into_remainder().chunks_exact_mut(n.max(1));
    for ((j, column), bj) in rest.enumerate().zip(btiles.remainder().chunks_exact(3)) {
        let a = scaled(bj);
        if let Some(e) = eta1.next() {
            *e = fma3(*e, &a, y);
        }
        for (x, bi) in column.iter_mut().zip(bcols.clone()).take(done + j + 1) {
            *x = madd3(*x, bi, &a);
        }
    }
}

/// [`add_upper3`] one column at a time: for column `j` of `B`, `a = k ∘ bⱼ`,
/// then `m[i][j] += bᵢ · a` for `i ≤ j` and `ηⱼ += a · Δp`. The smallest
/// code: where `T` is soft floating point, each multiply-add is two calls.
#[inline(always)]
pub(super) fn add_upper3_columns<T: RealField + Copy, D: Dim>(
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
        .chunks_exact_mut(n.max(1))
        .enumerate()
        .zip(bcols.clone())
    {
        let a = [k[0] * bj[0], k[1] * bj[1], k[2] * bj[2]];
        if let Some(e) = etas.as_mut().and_then(Iterator::next) {
            *e = fma3(*e, &a, y);
        }
        for (x, bi) in column.iter_mut().zip(bcols.clone()).take(j + 1) {
            *x = madd3(*x, bi, &a);
        }
    }
}

/// Whether `T`'s arithmetic is in hardware, as far as the update's code
/// shape cares: everywhere but on 32-bit ARM, where only the hard-float ABI
/// (`eabihf`) has an FPU, and that may be single precision only (the
/// Cortex-M4F's FPv4-SP). Soft floating point makes every multiply-add two
/// calls: there the column tiles of [`add_upper3_tiled`] would cost flash
/// for little, so soft-float types take [`add_upper3_columns`].
#[inline(always)]
fn hard_float<T>() -> bool {
    !cfg!(target_arch = "arm") || (cfg!(target_abi = "eabihf") && core::mem::size_of::<T>() <= 4)
}

/// The rank-3 update of `Λ`'s upper triangle and `η` (see
/// [`add_upper3_tiled`] and [`add_upper3_columns`]: the same values, bit for
/// bit; tiles where `T` is hardware floating point).
#[inline(always)]
pub(super) fn add_upper3<T: RealField + Copy, D: Dim>(
    m: &mut OMatrix<T, D, D>,
    eta: &mut [T],
    k: &[T; 3],
    y: &[T; 3],
    b: &[T],
) where
    DefaultAllocator: Alloc<D>,
{
    if hard_float::<T>() {
        add_upper3_tiled(m, eta, k, y, b);
    } else {
        add_upper3_columns(m, Some(eta), k, y, b);
    }
}

/// A bound of every `b²` and `Δp²` of a 3-row block (`B` column-major,
/// `Δp = y`): with hardware floating point the sum of the squares (one
/// multiply-add per value, nine a step); with soft floating point, where a
/// multiplication costs dearly, the square of the sum of the absolute values
/// (one addition per value). Not finite when a value is not (or when the
/// sum overflows: then the caller checks exactly).
#[inline(always)]
pub(super) fn magnitude<T: RealField + Copy>(b: &[T], y: &[T; 3]) -> T {
    if hard_float::<T>() {
        let sq3 = |s: T, c: &[T]| ((s + c[0] * c[0]) + c[1] * c[1]) + c[2] * c[2];
        let mut s = sq3(T::zero(), y);
        let mut nines = b.chunks_exact(9);
        for c in nines.by_ref() {
            s = sq3(sq3(sq3(s, c), &c[3..]), &c[6..]);
        }
        for c in nines.remainder().chunks_exact(3) {
            s = sq3(s, c);
        }
        s
    } else {
        let mut s = (y[0].abs() + y[1].abs()) + y[2].abs();
        for c in b.chunks_exact(3) {
            s = ((s + c[0].abs()) + c[1].abs()) + c[2].abs();
        }
        s * s
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
        .chunks_exact_mut(n.max(1))
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
