//! The copy of a block's rows into the buffers of [`super::WideAccumulator`]
//! (`U = W [B | Δp]`, `V = W²Σ [B | Δp]`, laid out for [`super::kernel`]),
//! on the instruction set [`pulp::Arch`] dispatches to; AVX-512 splits a
//! column-major 3 × N block into its rows with permutes.

use pulp::{Arch, Simd, WithSimd};

use super::kernel::at;
/// One block's rows into the buffers: row `row0 + r` of `U` gets
/// `w[r] [bᵀ | Δp]` of the block's row `r` (`B` column-major 3 × n), of `V`
/// (with σ) `ws[r] [bᵀ | Δp]`, for `r < rows`. Returns `Σ b² + Σ Δp²` over
/// those rows (unweighted): not finite when a value is not (nor when the
/// sum overflows).
pub(super) struct Push<'a> {
    pub(super) b: &'a [f64],
    /// References, not copies: a copy of values just written one at a
    /// time, made in wide moves, stalls the processor (store forwarding).
    pub(super) dp: &'a [f64; 3],
    pub(super) w: &'a [f64; 3],
    pub(super) ws: Option<&'a [f64; 3]>,
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
    pub(super) fn run(&mut self, arch: Arch) -> f64 {
        #[cfg(target_arch = "x86_64")]
        if let Arch::V4(v4) = arch {
            if self.rows == 3 {
                return v4.vectorize(PushV4 { push: self, v4 });
            }
        }
        arch.dispatch(PushAny(self))
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

/// How [`Push`] runs: dispatched per block, or inlined into a function
/// already dispatched (the batched entry points: no dispatch per block).
pub(super) trait Copier {
    fn copy(&self, push: &mut Push<'_>) -> f64;
}

/// [`Push::run`]: one dispatch per block ([`super::WideAccumulator::update`]).
pub(super) struct Dispatched(pub(super) Arch);

impl Copier for Dispatched {
    #[inline(always)]
    fn copy(&self, push: &mut Push<'_>) -> f64 {
        push.run(self.0)
    }
}

/// Inside a function dispatched to `S`: the same code as [`Push::run`]
/// takes there, inlined.
pub(super) struct InSimd<S>(pub(super) S);

impl<S: Simd> Copier for InSimd<S> {
    #[inline(always)]
    fn copy(&self, push: &mut Push<'_>) -> f64 {
        PushAny(push).with_simd(self.0)
    }
}

/// Inside a function dispatched to AVX-512: the same code as [`Push::run`]
/// takes there, inlined.
#[cfg(target_arch = "x86_64")]
pub(super) struct InV4(pub(super) pulp::x86::V4);

#[cfg(target_arch = "x86_64")]
impl Copier for InV4 {
    #[inline(always)]
    fn copy(&self, push: &mut Push<'_>) -> f64 {
        use pulp::NullaryFnOnce;
        if push.rows == 3 {
            PushV4 { push, v4: self.0 }.call()
        } else {
            PushAny(push).with_simd(self.0)
        }
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
        for &x in tail.iter().chain(push.dp) {
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
