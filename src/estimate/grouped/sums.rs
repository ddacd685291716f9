//! The per-group sums of [`super::GroupedStats::residual_sigma_into`]:
//! the leverage share `tr(Λ⁻¹ S)` and the quadratic form `xᵀ S x` of a
//! group's three axes side by side, over every parameter or over the
//! group's support (the parameters outside which its `S` are zero).

use nalgebra::RealField;

/// `tr(Λ⁻¹ S)` of three `n × n` matrices `S` from their upper triangles
/// (column-major slices, as `inv`): the diagonal term and then the column's
/// off-diagonal ones, doubled, column by column.
pub(super) fn traces3<T: RealField + Copy>(inv: &[T], n: usize, s: [&[T]; 3]) -> [T; 3] {
    let mut t = [T::zero(); 3];
    for c in 0..n {
        let d = inv[c * n + c];
        for a in 0..3 {
            t[a] += d * s[a][c * n + c];
        }
        for r in 0..c {
            let v = inv[c * n + r] + inv[c * n + r];
            for a in 0..3 {
                t[a] += v * s[a][c * n + r];
            }
        }
    }
    t
}

/// `XᵀSX` of three matrices `S` from their upper triangles, each with the
/// arithmetic of `AxisMoments::rss` (`(SX)ᵢ` over `k` in index order, then
/// `Σᵢ (SX)ᵢ Xᵢ`).
pub(super) fn quadratics3<T: RealField + Copy>(s: [&[T]; 3], n: usize, x: &[T]) -> [T; 3] {
    let x = &x[..x.len().min(n)];
    let mut q = [T::zero(); 3];
    for (i, &xi) in x.iter().enumerate() {
        let mut y = [T::zero(); 3];
        for (k, &xk) in x.iter().enumerate() {
            // `Sᵢₖ` from the upper triangle.
            let at = if k < i { i * n + k } else { k * n + i };
            for a in 0..3 {
                y[a] += s[a][at] * xk;
            }
        }
        for a in 0..3 {
            q[a] += y[a] * xi;
        }
    }
    q
}

/// The parameters of a support mask ([`super::GroupedStats::supports`]) in
/// increasing order, into `idx`: their number, or `None` when the mask is
/// not known (0) or holds all `p` parameters.
pub(crate) fn support_indices(mask: u64, p: usize, idx: &mut [u8; 64]) -> Option<usize> {
    // (The count from the loop, not `count_ones`: the default x86-64
    // target has no population count instruction, and its emulation cost
    // more than the loop, three times per group in every fit.)
    let (mut bits, mut m) = (mask, 0);
    while bits != 0 {
        // (A bit index, below 64.)
        idx[m] = bits.trailing_zeros() as u8;
        bits &= bits - 1;
        m += 1;
    }
    (m > 0 && m < p).then_some(m)
}

/// [`traces3`], [`quadratics3`] and the three `Xᵀu` (with the arithmetic
/// of `dot`: the products in index order from +0) over the parameters
/// `idx` only (increasing; every element of `S` and `u` outside them is
/// zero, `u`'s +0): the same sums in the same order without the terms
/// that are exact zeros (adding one changes no sum; none of these sums is
/// ever −0), in one pass over the support. Each sum gets its terms in its
/// own order (the trace of column `i`: its diagonal, then rows `r < i`;
/// `(SX)ᵢ`: `k < i` from the same column, `k = i`, then `k > i` from row
/// `i` of the later columns; a row `i` outside `idx` has `(SX)ᵢ = 0`), and
/// column `i`'s elements above the diagonal are read once for both.
/// (Inlined into its one caller, so that the nine sums stay in registers:
/// returned through memory, as eight-byte stores, they were read back by
/// sixteen-byte loads, which cannot be forwarded from two stores and
/// waited for them to reach the cache; `perf` put the stall on that load.
/// The KR-270's six fits 13.5 -> 11.8 µs.)
#[inline(always)]
pub(super) fn residual_sums3_sparse<T: RealField + Copy>(
    inv: &[T],
    n: usize,
    s: [&[T]; 3],
    u: [&[T]; 3],
    x: &[T],
    idx: &[u8],
) -> [[T; 3]; 3] {
    let (mut t, mut q, mut d) = ([T::zero(); 3], [T::zero(); 3], [T::zero(); 3]);
    for (ii, &i) in idx.iter().enumerate() {
        let i = usize::from(i);
        let (col, xi) = (i * n, x[i]);
        let di = inv[col + i];
        for a in 0..3 {
            t[a] += di * s[a][col + i];
        }
        let mut y = [T::zero(); 3];
        for &r in &idx[..ii] {
            let r = usize::from(r);
            let v = inv[col + r] + inv[col + r];
            for a in 0..3 {
                let sv = s[a][col + r];
                t[a] += v * sv;
                y[a] += sv * x[r];
            }
        }
        for a in 0..3 {
            y[a] += s[a][col + i] * xi;
        }
        for &k in &idx[ii + 1..] {
            let k = usize::from(k);
            for a in 0..3 {
                y[a] += s[a][k * n + i] * x[k];
            }
        }
        for a in 0..3 {
            q[a] += y[a] * xi;
            d[a] += xi * u[a][i];
        }
    }
    [t, q, d]
}
