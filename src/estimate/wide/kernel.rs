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
//! order, each product fused).

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

/// One block's rows into the buffers: row `row0 + r` of `U` gets
/// `w[r] [bᵀ | Δp]` of the block's row `r` (`B` column-major 3 × n), of `V`
/// (with σ) `ws[r] [bᵀ | Δp]`, for `r < rows`. Returns `Σ b² + Σ Δp²` over
/// those rows (unweighted): not finite when a value is not (nor when the
/// sum overflows).
pub(super) struct Push<'a> {
    pub(super) b: &'a [f64],
    pub(super) dp: [f64; 3],
    pub(super) w: [f64; 3],
    pub(super) ws: Option<[f64; 3]>,
    pub(super) rows: usize,
    pub(super) cap: usize,
    pub(super) row0: usize,
    pub(super) du: &'a mut [f64],
    pub(super) dv: Option<&'a mut [f64]>,
    /// [`row_permutes`]`(n mod 8)` (AVX-512's last chunk).
    pub(super) tail: &'a [[[i64; 8]; 2]; 3],
}

impl Push<'_> {
    /// Runs on the instruction set of `arch` (the kernel's layout). The
    /// dispatched code gets a reference, not a copy: a copy of the fields
    /// just written, read back in wide vectors, stalls the processor
    /// (store forwarding) for longer than a small block's whole update.
    pub(super) fn run(mut self, arch: Arch) -> f64 {
        #[cfg(target_arch = "x86_64")]
        if let Arch::V4(v4) = arch {
            if self.rows == 3 {
                return v4.vectorize(PushV4 {
                    push: &mut self,
                    v4,
                });
            }
        }
        arch.dispatch(PushAny(&mut self))
    }

    /// Columns `j0 ..` and `Δp` of the used rows, one value at a time (a
    /// partial sum of squares per row: no long chain of dependent adds).
    #[inline(always)]
    fn columns_from(&mut self, l: usize, j0: usize) -> f64 {
        let n = self.b.len() / 3;
        let mut q = [0.0; 3];
        for j in j0..=n {
            for r in 0..self.rows {
                let x = if j < n { self.b[3 * j + r] } else { self.dp[r] };
                q[r] += x * x;
                let i = at(l, self.cap, self.row0 + r, j);
                self.du[i] = self.w[r] * x;
                if let (Some(dv), Some(ws)) = (self.dv.as_deref_mut(), self.ws) {
                    dv[i] = ws[r] * x;
                }
            }
        }
        (q[0] + q[1]) + q[2]
    }
}

/// [`Push`] on any instruction set: one value at a time.
struct PushAny<'a, 'b>(&'b mut Push<'a>);

impl WithSimd for PushAny<'_, '_> {
    type Output = f64;

    #[inline(always)]
    fn with_simd<S: Simd>(self, s: S) -> f64 {
        let push = self.0;
        if push.rows < 3 {
            return push.columns_from(S::F64_LANES, 0);
        }
        // All three rows: the squares over the block as it lies (vectors,
        // four partial sums), the copy without a chain of dependent adds.
        let (head, tail) = S::as_simd_f64s(push.b);
        let mut acc = [s.splat_f64s(0.0); 4];
        let mut quads = head.chunks_exact(4);
        for v in quads.by_ref() {
            for (a, &x) in acc.iter_mut().zip(v) {
                *a = s.mul_add_e_f64s(x, x, *a);
            }
        }
        for (a, &x) in acc.iter_mut().zip(quads.remainder()) {
            *a = s.mul_add_e_f64s(x, x, *a);
        }
        let t = s.add_f64s(s.add_f64s(acc[0], acc[1]), s.add_f64s(acc[2], acc[3]));
        let mut q = s.reduce_sum_f64s(t);
        for &x in tail.iter().chain(&push.dp) {
            q += x * x;
        }
        let (l, cap, row0) = (S::F64_LANES, push.cap, push.row0);
        for (j, x) in push.b.chunks_exact(3).chain([&push.dp[..]]).enumerate() {
            for r in 0..3 {
                let i = at(l, cap, row0 + r, j);
                push.du[i] = push.w[r] * x[r];
                if let (Some(dv), Some(ws)) = (push.dv.as_deref_mut(), push.ws) {
                    dv[i] = ws[r] * x[r];
                }
            }
        }
        q
    }
}

/// The permutes of [`Push`] with AVX-512 that take row `r` of `t` columns
/// (1 ..= 8; 0: none) out of 24 values `x` (three vectors: `t` columns,
/// column-major 3 × 8, ending at the 24th value; the first `8 − t` columns
/// before them are not used): lane `c < t` of the result is `x[3(c + 8 − t) + r]`, the
/// first permute taking what the first two vectors hold, the second the
/// rest from the third (other lanes: anything). `[first, second]` per row.
pub(super) const fn row_permutes(t: usize) -> [[[i64; 8]; 2]; 3] {
    let mut p = [[[0i64; 8]; 2]; 3];
    let mut r = 0;
    while r < 3 {
        let mut c = 0;
        while c < 8 {
            p[r][1][c] = c as i64;
            if c < t {
                let i = 3 * (c + 8 - t) + r;
                if i < 16 {
                    p[r][0][c] = i as i64;
                } else {
                    p[r][1][c] = (i - 8) as i64;
                }
            }
            c += 1;
        }
        r += 1;
    }
    p
}

/// [`row_permutes`] of a whole chunk (eight columns).
const BODY: [[[i64; 8]; 2]; 3] = row_permutes(8);

/// [`Push`] of a three-row block with AVX-512: eight columns (24 values,
/// three vectors) at a time, split into the three rows by two permutes
/// each. The last chunk (the remaining `t = n mod 8` columns, then `Δp` as
/// one more column, then zeros: the buffer's padding) from the last 24
/// values of `B` (permutes of their own, `tail`), or, when `B` has fewer
/// (`n < 8`), from masked loads.
#[cfg(target_arch = "x86_64")]
struct PushV4<'a, 'b> {
    push: &'b mut Push<'a>,
    v4: pulp::x86::V4,
}

#[cfg(target_arch = "x86_64")]
impl pulp::NullaryFnOnce for PushV4<'_, '_> {
    type Output = f64;

    #[inline(always)]
    fn call(self) -> f64 {
        use core::arch::x86_64::__m512d;
        use pulp::x86::V4;
        let PushV4 { push, v4 } = self;
        let avx = v4.avx512f;
        let (cap, row0) = (push.cap, push.row0);
        let n = push.b.len() / 3;
        let (full, t) = (n / 8, n % 8);
        let perms = v4_permutes(&BODY);
        let k = push.w.map(|k| v4.splat_f64s(k));
        let ks = push.ws.map(|s| s.map(|k| v4.splat_f64s(k)));
        let mut q = [v4.splat_f64s(0.0); 3];
        let (du, _) = V4::as_mut_simd_f64s(push.du);
        let mut dv = push.dv.as_deref_mut().map(|dv| V4::as_mut_simd_f64s(dv).0);
        let (src, _) = V4::as_simd_f64s(&push.b[..24 * full]);
        for (chunk, x) in src.chunks_exact(3).enumerate() {
            let x: [__m512d; 3] = [x[0], x[1], x[2]].map(pulp::cast);
            for r in 0..3 {
                let y = v4_split(v4, x, perms[r]);
                let i = chunk * cap + row0 + r;
                q[r] = v4.mul_add_f64s(y, y, q[r]);
                du[i] = v4.mul_f64s(k[r], y);
                if let (Some(dv), Some(ks)) = (dv.as_deref_mut(), ks) {
                    dv[i] = v4.mul_f64s(ks[r], y);
                }
            }
        }
        // The last chunk: lane t is Δp, the lanes past it zero.
        let x: [__m512d; 3] = if t == 0 {
            [avx._mm512_setzero_pd(); 3]
        } else if n >= 8 {
            let (src, _) = V4::as_simd_f64s(&push.b[3 * n - 24..]);
            [src[0], src[1], src[2]].map(pulp::cast)
        } else {
            let b = push.b;
            [0, 8, 16].map(|v| pulp::cast(v4.partial_load_f64s(b.get(v..).unwrap_or(&[]))))
        };
        let tail = if n >= 8 {
            v4_permutes(push.tail)
        } else {
            perms
        };
        let (low, dp_lane) = ((1u8 << t) - 1, 1u8 << t);
        for r in 0..3 {
            let dp = avx._mm512_maskz_mov_pd(dp_lane, avx._mm512_set1_pd(push.dp[r]));
            let y = avx._mm512_mask_mov_pd(dp, low, pulp::cast(v4_split(v4, x, tail[r])));
            let y: pulp::f64x8 = pulp::cast(y);
            let i = full * cap + row0 + r;
            q[r] = v4.mul_add_f64s(y, y, q[r]);
            du[i] = v4.mul_f64s(k[r], y);
            if let (Some(dv), Some(ks)) = (dv.as_deref_mut(), ks) {
                dv[i] = v4.mul_f64s(ks[r], y);
            }
        }
        v4.reduce_sum_f64s(v4.add_f64s(v4.add_f64s(q[0], q[1]), q[2]))
    }
}

/// [`row_permutes`] as AVX-512 index vectors.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn v4_permutes(p: &[[[i64; 8]; 2]; 3]) -> [[core::arch::x86_64::__m512i; 2]; 3] {
    [
        [pulp::cast(p[0][0]), pulp::cast(p[0][1])],
        [pulp::cast(p[1][0]), pulp::cast(p[1][1])],
        [pulp::cast(p[2][0]), pulp::cast(p[2][1])],
    ]
}

/// One row out of three vectors (see [`row_permutes`]).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn v4_split(
    v4: pulp::x86::V4,
    x: [core::arch::x86_64::__m512d; 3],
    p: [core::arch::x86_64::__m512i; 2],
) -> pulp::f64x8 {
    let avx = v4.avx512f;
    let y = avx._mm512_permutex2var_pd(x[0], p[0], x[1]);
    pulp::cast(avx._mm512_permutex2var_pd(y, p[1], x[2]))
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
