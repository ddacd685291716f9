//! The SIMD kernels of [`super::WideAccumulator`], dispatched at run time
//! by [`pulp::Arch`]: AVX-512 (8 `f64` lanes), AVX2 + FMA (4), or a scalar
//! fallback (1) on other processors. robcal calls no `unsafe` (pulp checks
//! the processor once and hands out a token that makes its intrinsics safe
//! to call) and needs no `target-cpu`: the same binary runs everywhere.
//!
//! Layout (all `f64`; `L` the dispatched lanes, `m = n + 1`, `mp` = `m`
//! rounded up to [`PAD`]):
//!
//! - the buffer `U` holds up to `cap` weighted rows `w [bᵀ | Δp]` (`m`
//!   values, the rest of `mp` zero) in chunks of `L` columns: chunk `q` is
//!   `cap` rows of `L` values, so that each vector of a row streams
//!   contiguously through the kernel ([`at`]); `V = W²Σ [B | Δp]` for `M`,
//!   the same layout;
//! - the sums `C` (`mp × mp`, column-major): `C += Uᵀ U` on the upper
//!   triangle, so that `C[..n, ..n] = Λ = Σ Bᵀ W² B`, `C[..n, n] = η` and
//!   `C[n, n] = Σ Δpᵀ W² Δp` (eq. 10) — one kernel for the three (and
//!   `M = Vᵀ V`).
//!
//! The rank-`k` update ([`rank_k`]) walks `C` in column panels of `NC = L`
//! columns (the last one exactly as wide as the columns left); in a panel
//! `j0 .. j0 + NC`, the rows `0 .. j0 + NC` (the upper triangle and the
//! panel's diagonal block, rounded up to whole vectors) in register tiles
//! of up to `NV` vectors (as even as they go; taller in the last, narrower
//! panel), kept in registers while the buffered rows stream by: per row,
//! `NV` vector loads of `B`, `NC` broadcasts of `A` and `NV · NC` fused
//! multiply-adds, summed over the rows in order (the scalar update's
//! order, each product fused). With 8-lane vectors and at least 16
//! columns, the first two panels are one tile of 24 accumulators
//! ([`first_two`]) instead of tiles of 8 and 16.

use pulp::{Arch, Simd, WithSimd};

/// Row length granularity of the buffers and of `C`: one AVX-512 vector.
pub(super) const PAD: usize = 8;

/// Position of row `r`, column `j` in a buffer of `cap` rows with chunks of
/// `lanes` columns.
#[inline(always)]
pub(super) fn at(lanes: usize, cap: usize, r: usize, j: usize) -> usize {
    (j / lanes) * cap * lanes + r * lanes + j % lanes
}

/// The `f64` lanes of the instruction set `arch` dispatches to.
pub(super) fn lanes(arch: Arch) -> usize {
    struct Lanes;
    impl WithSimd for Lanes {
        type Output = usize;
        #[inline(always)]
        fn with_simd<S: Simd>(self, _s: S) -> usize {
            S::F64_LANES
        }
    }
    arch.dispatch(Lanes)
}

/// `C += Bᵀ A` over the first `rows` buffered rows (`A = B = U`, or `V`), on the upper triangle
/// of the leading `m × m` block of `C` (see the module docs; the lower parts
/// of the diagonal tiles get sums too, which are never read).
#[allow(clippy::too_many_arguments)]
pub(super) fn rank_k(
    arch: Arch,
    c: &mut [f64],
    b: &[f64],
    a: &[f64],
    m: usize,
    mp: usize,
    cap: usize,
    rows: usize,
) {
    arch.dispatch(RankK {
        c,
        b,
        a,
        m,
        mp,
        cap,
        rows,
    });
}

struct RankK<'a> {
    c: &'a mut [f64],
    b: &'a [f64],
    a: &'a [f64],
    m: usize,
    mp: usize,
    cap: usize,
    rows: usize,
}

impl WithSimd for RankK<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, s: S) {
        // Registers: NV·NC accumulators, NV loads, one broadcast. AVX-512
        // (32 registers): 3 × 8; AVX2 (16): 3 × 4; scalar: 4 × 1.
        match S::F64_LANES {
            8 => panels::<S, 3, 8>(s, self),
            4 => panels::<S, 3, 4>(s, self),
            _ => panels::<S, 4, 1>(s, self),
        }
    }
}

#[inline(always)]
fn panels<S: Simd, const NV: usize, const NC: usize>(s: S, mut op: RankK<'_>) {
    let m = op.m;
    let mut j0 = 0;
    if NC == 8 && S::F64_LANES == 8 && m >= 16 {
        first_two::<S>(s, &mut op);
        j0 = 16;
    }
    while j0 + NC <= m {
        panel::<S, NC>(s, &mut op, j0, NV);
        j0 += NC;
    }
    // The last `w < NC` columns: one panel exactly that wide, its tiles
    // taller (see `panel`).
    let budget = if S::REGISTER_COUNT >= 32 { 24 } else { 12 };
    let tall = |w: usize| (budget / w).min(8);
    match m - j0 {
        0 => {}
        1 => panel::<S, 1>(s, &mut op, j0, tall(1)),
        2 => panel::<S, 2>(s, &mut op, j0, tall(2)),
        3 => panel::<S, 3>(s, &mut op, j0, tall(3)),
        4 => panel::<S, 4>(s, &mut op, j0, tall(4)),
        5 => panel::<S, 5>(s, &mut op, j0, tall(5)),
        6 => panel::<S, 6>(s, &mut op, j0, tall(6)),
        _ => panel::<S, 7>(s, &mut op, j0, tall(7)),
    }
}

/// The first two column panels of eight (columns `0 .. 16`) with 8-lane
/// vectors, in one tile of 24 accumulators: vector 0 × columns `0 .. 16`
/// and vector 1 × columns `8 .. 16`. As two panels, the first is a tile of
/// one vector × 8 columns: 8 accumulators, exactly the FMA latency × units,
/// no slack. Each element gets the same fused products in the same order.
#[inline(always)]
fn first_two<S: Simd>(s: S, op: &mut RankK<'_>) {
    let (rows, cap, mp) = (op.rows, op.cap, op.mp);
    let (bv, _) = S::as_simd_f64s(op.b);
    let (b0, b1) = (&bv[..rows], &bv[cap..cap + rows]);
    // Row r's columns 0 .. 8 and 8 .. 16 (chunks 0 and 1 of the buffer).
    let (a0, a1) = (&op.a[..rows * 8], &op.a[cap * 8..cap * 8 + rows * 8]);
    let (cv, _) = S::as_mut_simd_f64s(op.c);
    let vcol = mp / 8;
    let mut lo = [s.splat_f64s(0.0); 16];
    let mut hi = [s.splat_f64s(0.0); 8];
    for k in 0..16 {
        lo[k] = cv[k * vcol];
    }
    for k in 0..8 {
        hi[k] = cv[(8 + k) * vcol + 1];
    }
    for r in 0..rows {
        let (x0, x1) = (b0[r], b1[r]);
        let (r0, r1) = (&a0[r * 8..r * 8 + 8], &a1[r * 8..r * 8 + 8]);
        for k in 0..8 {
            lo[k] = s.mul_add_e_f64s(x0, s.splat_f64s(r0[k]), lo[k]);
        }
        for k in 0..8 {
            let y = s.splat_f64s(r1[k]);
            lo[8 + k] = s.mul_add_e_f64s(x0, y, lo[8 + k]);
            hi[k] = s.mul_add_e_f64s(x1, y, hi[k]);
        }
    }
    for k in 0..16 {
        cv[k * vcol] = lo[k];
    }
    for k in 0..8 {
        cv[(8 + k) * vcol + 1] = hi[k];
    }
}

/// Columns `j0 .. j0 + NC`, rows `0 .. j0 + NC` in whole vectors, in tiles
/// of at most `nv_max` vectors, as even as they go (`4 = 2 + 2`, not
/// `3 + 1`: a one-vector tile of eight columns needs more loads than
/// multiply-adds, and has fewer accumulators than cover their latency).
#[inline(always)]
fn panel<S: Simd, const NC: usize>(s: S, op: &mut RankK<'_>, j0: usize, nv_max: usize) {
    let nvec = (j0 + NC).div_ceil(S::F64_LANES);
    // `nv_max` is a constant where this is inlined: one division a panel.
    let count = nvec.div_ceil(nv_max);
    let base = nvec / count;
    let taller = count - (nvec - base * count);
    let mut iv = 0;
    for t in 0..count {
        let nv = base + usize::from(t >= taller);
        tiles::<S, NC>(s, op, iv, j0, nv);
        iv += nv;
    }
}

/// [`tile`] of `nv` (1 ..= 8) vectors.
#[inline(always)]
fn tiles<S: Simd, const NC: usize>(s: S, op: &mut RankK<'_>, iv: usize, j0: usize, nv: usize) {
    match nv {
        1 => tile::<S, 1, NC>(s, op, iv, j0),
        2 => tile::<S, 2, NC>(s, op, iv, j0),
        3 => tile::<S, 3, NC>(s, op, iv, j0),
        4 => tile::<S, 4, NC>(s, op, iv, j0),
        5 => tile::<S, 5, NC>(s, op, iv, j0),
        6 => tile::<S, 6, NC>(s, op, iv, j0),
        7 => tile::<S, 7, NC>(s, op, iv, j0),
        _ => tile::<S, 8, NC>(s, op, iv, j0),
    }
}

/// One register tile: rows `iv·L .. (iv + NV)·L` of columns `j0 .. j0 + NC`
/// of `C`, from its current values through every buffered row in order.
#[inline(always)]
fn tile<S: Simd, const NV: usize, const NC: usize>(s: S, op: &mut RankK<'_>, iv: usize, j0: usize) {
    let l = S::F64_LANES;
    let (rows, cap, mp) = (op.rows, op.cap, op.mp);
    let (bv, _) = S::as_simd_f64s(op.b);
    // Row r of vector iv + v is bv[(iv + v)·cap + r]: one contiguous stream
    // per vector.
    let bs: [&[S::f64s]; NV] = core::array::from_fn(|v| &bv[(iv + v) * cap..][..rows]);
    let (abase, off) = (at(l, cap, 0, j0 - j0 % l), j0 % l);
    let ast = &op.a[abase..abase + rows * l];
    let (cv, _) = S::as_mut_simd_f64s(op.c);
    let vcol = mp / l;
    let mut acc = [[s.splat_f64s(0.0); NV]; NC];
    for (k, col) in acc.iter_mut().enumerate() {
        let at = (j0 + k) * vcol + iv;
        col.copy_from_slice(&cv[at..at + NV]);
    }
    for r in 0..rows {
        let arow = &ast[r * l + off..r * l + off + NC];
        for (col, &x) in acc.iter_mut().zip(arow) {
            let x = s.splat_f64s(x);
            for (acc, bs) in col.iter_mut().zip(&bs) {
                *acc = s.mul_add_e_f64s(bs[r], x, *acc);
            }
        }
    }
    for (k, col) in acc.iter().enumerate() {
        let at = (j0 + k) * vcol + iv;
        cv[at..at + NV].copy_from_slice(col);
    }
}

/// The machine's fused multiply-add peak through the same dispatch as
/// [`rank_k`]: [`CHAINS`] independent accumulator vectors, each through
/// `iterations` multiply-adds (`2 · lanes` flops each). Returns a value
/// that depends on every step, so that nothing is optimised away.
pub(super) fn fma_chains(arch: Arch, iterations: usize) -> f64 {
    arch.dispatch(Chains { iterations })
}

struct Chains {
    iterations: usize,
}

/// Independent chains of the peak probe: enough to cover the latency of
/// two FMA units (4 cycles × 2) with room, within the 16 registers of AVX2.
pub(super) const CHAINS: usize = 12;

impl WithSimd for Chains {
    type Output = f64;

    #[inline(always)]
    fn with_simd<S: Simd>(self, s: S) -> f64 {
        let mut acc: [S::f64s; CHAINS] = core::array::from_fn(|k| s.splat_f64s(k as f64));
        let x = s.splat_f64s(core::hint::black_box(0.999_999));
        let y = s.splat_f64s(core::hint::black_box(1e-9));
        for _ in 0..self.iterations {
            for a in acc.iter_mut() {
                *a = s.mul_add_e_f64s(*a, x, y);
            }
        }
        let mut t = 0.0;
        for a in acc {
            t += pulp::bytemuck::cast_slice::<S::f64s, f64>(&[a])
                .iter()
                .sum::<f64>();
        }
        t
    }
}
