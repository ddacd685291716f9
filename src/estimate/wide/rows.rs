//! [`WideAccumulator::update_rows`]: measurement rows given row-major, each
//! row's `N` values contiguous, as a caller that keeps its rows that way has
//! them (the host's fits keep each row's three axes as three runs of its
//! columns). The copy into the buffer is then a weighted copy of contiguous
//! values, with no de-interleave of a column-major 3 × N block, and the
//! checks and the running overflow bound are done once per buffer's worth
//! of rows, not once per block.

use pulp::{Arch, Simd, WithSimd};

use super::kernel::at;
use super::{aligned_mut, Rejected, WideAccumulator};
use crate::error::Error;

/// Measurement rows, row-major: row `i` is the equation
/// `w[i] (b[i·N .. (i + 1)·N] · x − dp[i])`, with `σ = sigma[i]` when
/// given (for `M`, as a block's σ) — the rows of [`crate::estimate::Block`]s, one
/// axis each, laid out one after the other.
#[derive(Debug, Clone, Copy)]
pub struct Rows<'a> {
    /// `rows × N` values, row after row.
    pub b: &'a [f64],
    /// One `Δp` per row.
    pub dp: &'a [f64],
    /// One weight per row (`≥ 0`, finite).
    pub w: &'a [f64],
    /// One σ per row (`> 0`, finite), or none (the rows do not enter `M`).
    pub sigma: Option<&'a [f64]>,
}

impl Rows<'_> {
    /// The number of rows (`dp`'s length).
    pub fn len(&self) -> usize {
        self.dp.len()
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.dp.is_empty()
    }
}

/// What a copy of rows reports: `Σ (w b)² + Σ (w Δp)²` and the same of
/// `w²σ` (not finite when a value is not), whether a weight or σ was
/// refused or `w²`, `w⁴σ²` overflowed, the rows with `w² > 0`.
struct Copied {
    q: f64,
    bad: bool,
    equations: usize,
}

impl WideAccumulator {
    /// Adds measurement rows given row-major ([`Rows`]), in order: the same
    /// sums, to the last bit, as [`Self::update`] with blocks holding the
    /// same rows in the same order (a row is a block's row: one axis of one
    /// measurement). For a caller that has its rows this way, or can write
    /// them so as cheaply as a [`crate::estimate::Block`]: the copy into the buffer
    /// needs no de-interleave of a column-major block, and the checks run
    /// once per buffer of rows, in the vector code. On AVX-512 a block's
    /// three rows take about 40 % less time than [`Self::update`] of the
    /// block at N = 9, 15 to 20 % less at N = 30 and a few percent less at
    /// N = 60 (BENCHMARKS.md). On instruction sets other than AVX-512 the
    /// copy goes one value at a time.
    ///
    /// # Errors
    /// When the lengths of `b`, `dp`, `w` and `sigma` do not agree with one
    /// another and with [`Self::parameters`]: [`Error::Mismatch`] at index
    /// 0, nothing taken. Otherwise at the first row that [`Self::update`]
    /// would refuse as a one-row block (a non-finite value, a negative
    /// weight, a σ not positive, a sum that could overflow): [`Rejected`]
    /// with its index and that error. The rows before it are taken, it and
    /// the rows after it are not.
    pub fn update_rows(&mut self, rows: Rows<'_>) -> Result<(), Rejected> {
        let (n, count) = (self.n, rows.len());
        let agree = rows.b.len() == count * n
            && rows.w.len() == count
            && rows.sigma.is_none_or(|s| s.len() == count);
        if !agree {
            return Err(Rejected {
                index: 0,
                error: Error::Mismatch {
                    what: "rows: the lengths of b, dp, w, sigma and the parameters",
                },
            });
        }
        // At most `rows_cap` rows in the buffer here: fewer than `update`
        // buffers at some N (see `ROWS_BYTES`).
        let cap = self.rows_cap;
        let mut done = 0;
        while done < count {
            if self.rows >= cap {
                self.flush();
            }
            let take = (count - done).min(cap - self.rows);
            let part = Rows {
                b: &rows.b[done * n..(done + take) * n],
                dp: &rows.dp[done..done + take],
                w: &rows.w[done..done + take],
                sigma: rows.sigma.map(|s| &s[done..done + take]),
            };
            if let Err((index, error)) = self.push_rows(part) {
                return Err(Rejected {
                    index: done + index,
                    error,
                });
            }
            done += take;
        }
        Ok(())
    }

    /// Rows that fit in the buffer: copied past the buffered rows, then
    /// taken (all, or those before the first refused one, whose index and
    /// error are returned).
    fn push_rows(&mut self, rows: Rows<'_>) -> Result<(), (usize, Error)> {
        let sigma = rows.sigma.is_some();
        if sigma {
            self.start_sigma();
        }
        let len = self.cap * self.mp;
        let op = CopyRows {
            rows,
            n: self.n,
            cap: self.cap,
            row0: self.rows,
            du: aligned_mut(&mut self.u, len),
            dv: (sigma || self.sigma_pending).then(|| aligned_mut(&mut self.v, len)),
        };
        let copied = op.run(self.arch);
        let next = (self.bound + copied.q) * (1.0 + 1.0 / 1024.0);
        if !copied.bad && next <= f64::MAX / 16.0 {
            self.take_rows(rows.len(), copied.equations, sigma, next);
            return Ok(());
        }
        self.push_rows_checked(rows)
    }

    /// The slow path of [`Self::push_rows`] (a refused row, or the running
    /// bound at its limit): the rows checked one by one as one-row blocks,
    /// the sums' exact check ([`Self::exact_bound`]) for those taken.
    #[cold]
    fn push_rows_checked(&mut self, rows: Rows<'_>) -> Result<(), (usize, Error)> {
        let (n, sigma) = (self.n, rows.sigma.is_some());
        let mut refused = None;
        let mut ok = rows.len();
        for i in 0..rows.len() {
            if let Err(error) = check_row(&rows, n, i) {
                (ok, refused) = (i, Some(error));
                break;
            }
        }
        // The longest prefix of the valid rows whose sums pass the exact
        // check (the check is monotone in the rows: sums of squares).
        let mut bound = self.exact_bound(ok, sigma);
        if bound.is_none() {
            let mut take = 0;
            while let Some(b) = self.exact_bound(take + 1, sigma) {
                (take, bound) = (take + 1, Some(b));
            }
            ok = take;
            refused = Some(Error::NonFinite { what: "overflow" });
        }
        if ok > 0 {
            let eq = rows.w[..ok].iter().filter(|&&w| w * w > 0.0).count();
            self.take_rows(ok, eq, sigma, bound.unwrap_or(self.bound));
        }
        match refused {
            Some(error) => Err((ok, error)),
            None => Ok(()),
        }
    }

    /// Commits `rows` rows written past the buffered ones.
    fn take_rows(&mut self, rows: usize, equations: usize, sigma: bool, bound: f64) {
        self.rows += rows;
        self.sigma_pending |= sigma;
        self.equations += equations;
        if sigma {
            self.sigma_rows += equations;
        }
        self.bound = bound;
    }
}

/// Row `i` of `rows` as [`crate::estimate::Block::validate`] and
/// [`WideAccumulator::update`] see a one-row block: the same errors in the
/// same order, and the overflow of `w²` or `w⁴σ²` (the core's sums of that
/// row are then infinite or NaN).
fn check_row(rows: &Rows<'_>, n: usize, i: usize) -> Result<(), Error> {
    if !rows.b[i * n..(i + 1) * n].iter().all(|v| v.is_finite()) {
        return Err(Error::NonFinite { what: "row" });
    }
    if !rows.dp[i].is_finite() {
        return Err(Error::NonFinite { what: "dp" });
    }
    let w = rows.w[i];
    if !w.is_finite() {
        return Err(Error::NonFinite { what: "weight" });
    }
    if w < 0.0 {
        return Err(Error::NotPositive { what: "weight" });
    }
    let k = w * w;
    let mut finite = k.is_finite();
    if let Some(s) = rows.sigma {
        let s = s[i];
        if !s.is_finite() {
            return Err(Error::NonFinite { what: "sigma" });
        }
        if s <= 0.0 {
            return Err(Error::NotPositive { what: "sigma" });
        }
        finite &= (k * k * s * s).is_finite();
    }
    if finite {
        Ok(())
    } else {
        Err(Error::NonFinite { what: "overflow" })
    }
}

/// Rows into the buffers: row `row0 + i` of `U` gets `w[i] [bᵢᵀ | Δpᵢ]`, of
/// `V` (when given) `w[i]² σ[i] [bᵢᵀ | Δpᵢ]` (zeros without σ).
struct CopyRows<'a, 'b> {
    rows: Rows<'b>,
    n: usize,
    cap: usize,
    row0: usize,
    du: &'a mut [f64],
    dv: Option<&'a mut [f64]>,
}

impl CopyRows<'_, '_> {
    fn run(self, arch: Arch) -> Copied {
        #[cfg(target_arch = "x86_64")]
        if let Arch::V4(v4) = arch {
            return v4.vectorize(CopyRowsV4 { op: self, v4 });
        }
        arch.dispatch(self)
    }
}

/// Row `i`'s weight checks: its `w`, `w²σ` (zero without σ), whether it is
/// refused, whether it counts (`w² > 0`).
#[inline(always)]
fn weights(rows: &Rows<'_>, i: usize) -> (f64, f64, bool, bool) {
    let w = rows.w[i];
    let k = w * w;
    // `x >= 0` and `x > 0` are false for NaN; `k < ∞` false for ∞, NaN.
    let mut bad = !(w >= 0.0 && k < f64::INFINITY);
    let ws = match rows.sigma {
        Some(s) => {
            let s = s[i];
            bad |= !(s > 0.0 && k * k * s * s < f64::INFINITY);
            k * s
        }
        None => 0.0,
    };
    (w, ws, bad, k > 0.0)
}

/// [`CopyRows`] on any instruction set: one value at a time.
impl WithSimd for CopyRows<'_, '_> {
    type Output = Copied;

    #[inline(always)]
    fn with_simd<S: Simd>(mut self, _s: S) -> Copied {
        let (n, l, cap) = (self.n, S::F64_LANES, self.cap);
        let mut out = Copied {
            q: 0.0,
            bad: false,
            equations: 0,
        };
        let mut q = [0.0; 4];
        for i in 0..self.rows.len() {
            let (w, ws, bad, counts) = weights(&self.rows, i);
            out.bad |= bad;
            out.equations += usize::from(counts);
            let row = &self.rows.b[i * n..(i + 1) * n];
            for (j, &x) in row.iter().chain([&self.rows.dp[i]]).enumerate() {
                let k = at(l, cap, self.row0 + i, j);
                let y = w * x;
                self.du[k] = y;
                q[j % 2] += y * y;
                if let Some(dv) = self.dv.as_deref_mut() {
                    let z = ws * x;
                    dv[k] = z;
                    q[2 + j % 2] += z * z;
                }
            }
        }
        out.q = (q[0] + q[1]) + (q[2] + q[3]);
        out
    }
}

/// [`CopyRows`] with AVX-512: the rows' weight checks first, then the rows
/// four at a time ([`Chunks::group`]), eight columns a vector, the last
/// chunk (the row's `N mod 8` last values, then `Δp`, then zeros) from the
/// row's last eight values by one permute, or at `N < 8` from its first
/// eight ([`Chunks::short_row`]; one value at a time, the copy was three
/// quarters of `update_rows` at N = 1).
#[cfg(target_arch = "x86_64")]
struct CopyRowsV4<'a, 'b> {
    op: CopyRows<'a, 'b>,
    v4: pulp::x86::V4,
}

#[cfg(target_arch = "x86_64")]
impl pulp::NullaryFnOnce for CopyRowsV4<'_, '_> {
    type Output = Copied;

    #[inline(always)]
    fn call(self) -> Copied {
        use pulp::x86::V4;
        let CopyRowsV4 { op, v4 } = self;
        let (n, cap, row0) = (op.n, op.cap, op.row0);
        let rows = op.rows;
        let (bad, equations) = checks(v4, &rows);
        let mut out = Copied {
            q: 0.0,
            bad,
            equations,
        };
        let t = n % 8;
        // Lane c < t of the last chunk: the row's value n − t + c, which is
        // lane 8 − t + c of its last eight values.
        let idx: [i64; 8] = core::array::from_fn(|c| ((c + 8 - t) % 8) as i64);
        let idx: core::arch::x86_64::__m512i = pulp::cast(idx);
        let (low, dp_lane) = ((1u8 << t) - 1, 1u8 << t);
        let (du, _) = V4::as_mut_simd_f64s(op.du);
        let dv = op.dv.map(|dv| V4::as_mut_simd_f64s(dv).0);
        let chunks = Chunks {
            rows,
            n,
            cap,
            row0,
            idx,
            low,
            dp_lane,
        };
        out.q += chunks.copy(v4, du, |i| rows.w[i]);
        if let Some(dv) = dv {
            out.q += match rows.sigma {
                Some(s) => chunks.copy(v4, dv, |i| rows.w[i] * rows.w[i] * s[i]),
                None => chunks.copy(v4, dv, |_| 0.0),
            };
        }
        out
    }
}

/// [`weights`] of every row, eight rows a vector (the scalar checks, one
/// row at a time, were about a sixth of the copy at N = 30): whether one is
/// refused, the rows with `w² > 0`. The same comparisons (ordered: false for
/// NaN) on the same products.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn checks(v4: pulp::x86::V4, rows: &Rows<'_>) -> (bool, usize) {
    let count = rows.len();
    let whole = count - count % 8;
    let (zero, inf) = (v4.splat_f64s(0.0), v4.splat_f64s(f64::INFINITY));
    let load = |x: &[f64], i0: usize| -> pulp::f64x8 {
        let v: [f64; 8] = x[i0..i0 + 8].try_into().unwrap_or([0.0; 8]);
        pulp::cast(v)
    };
    let (mut good, mut equations) = (0xffu8, 0);
    for i0 in (0..whole).step_by(8) {
        let w = load(rows.w, i0);
        let k = v4.mul_f64s(w, w);
        good &= v4.cmp_ge_f64x8(w, zero).0 & v4.cmp_lt_f64x8(k, inf).0;
        if let Some(s) = rows.sigma {
            let s = load(s, i0);
            let t = v4.mul_f64s(v4.mul_f64s(v4.mul_f64s(k, k), s), s);
            good &= v4.cmp_gt_f64x8(s, zero).0 & v4.cmp_lt_f64x8(t, inf).0;
        }
        equations += v4.cmp_gt_f64x8(k, zero).0.count_ones() as usize;
    }
    let mut bad = good != 0xff;
    for i in whole..count {
        let (_, _, refused, counts) = weights(rows, i);
        bad |= refused;
        equations += usize::from(counts);
    }
    (bad, equations)
}

/// The rows' column chunks for [`CopyRowsV4`].
#[cfg(target_arch = "x86_64")]
struct Chunks<'a> {
    rows: Rows<'a>,
    n: usize,
    cap: usize,
    row0: usize,
    idx: core::arch::x86_64::__m512i,
    low: u8,
    dp_lane: u8,
}

#[cfg(target_arch = "x86_64")]
impl Chunks<'_> {
    /// Row `row0 + i` of `d` gets `scale(i) [bᵢᵀ | Δpᵢ]`; returns the sum of
    /// the squares written.
    #[inline(always)]
    fn copy(
        &self,
        v4: pulp::x86::V4,
        d: &mut [pulp::f64x8],
        scale: impl Fn(usize) -> f64 + Copy,
    ) -> f64 {
        let count = self.rows.len();
        let mut q = [v4.splat_f64s(0.0); 4];
        let whole = count - count % 4;
        for i0 in (0..whole).step_by(4) {
            self.group::<4>(v4, d, scale, i0, &mut q);
        }
        for i0 in whole..count {
            self.group::<1>(v4, d, scale, i0, &mut q);
        }
        let s = v4.add_f64s(v4.add_f64s(q[0], q[1]), v4.add_f64s(q[2], q[3]));
        v4.reduce_sum_f64s(s)
    }

    /// Row `i`'s values at `N < 8` (its only chunk): the eight values from
    /// its first where they are all in `b` (lanes `N ..` are the next row's,
    /// cleared by the caller), else a partial load.
    #[inline(always)]
    fn short_row(&self, v4: pulp::x86::V4, i: usize) -> pulp::f64x8 {
        let (b, n) = (self.rows.b, self.n);
        match b.get(i * n..i * n + 8) {
            Some(v) => pulp::cast::<[f64; 8], _>(v.try_into().unwrap_or([0.0; 8])),
            None => v4.partial_load_f64s(&b[i * n..(i + 1) * n]),
        }
    }

    /// Rows `i0 .. i0 + G`, every chunk: each chunk's `G` loads before its
    /// `G` stores (a load after a store to an address equal modulo 4 KiB
    /// waits for it), the squares into `G` running sums.
    #[inline(always)]
    fn group<const G: usize>(
        &self,
        v4: pulp::x86::V4,
        d: &mut [pulp::f64x8],
        scale: impl Fn(usize) -> f64,
        i0: usize,
        q: &mut [pulp::f64x8; 4],
    ) {
        let avx = v4.avx512f;
        let (n, cap, full) = (self.n, self.cap, self.n / 8);
        let rs = &self.rows.b[i0 * n..(i0 + G) * n];
        // Loops, not `array::from_fn`: a closure does not inherit the target
        // features, and an intrinsic in it becomes a call.
        let mut k = [v4.splat_f64s(0.0); G];
        for g in 0..G {
            k[g] = v4.splat_f64s(scale(i0 + g));
        }
        let at = self.row0 + i0;
        let mut x = [v4.splat_f64s(0.0); G];
        // Whole chunks of eight as arrays, and the buffer's chunks zipped:
        // no bounds check in the loop (they were a third of its
        // instructions).
        let cols: [&[[f64; 8]]; G] = core::array::from_fn(|g| rs[g * n..][..n].as_chunks().0);
        // The buffer's chunks split off one by one (`chunks_exact_mut`
        // divides by `cap` to start).
        let mut rest = &mut d[at..];
        for c in 0..full {
            let (col, next) = rest.split_at_mut(cap.min(rest.len()));
            rest = next;
            for g in 0..G {
                x[g] = pulp::cast(cols[g][c]);
            }
            let dst = &mut col[..G];
            for g in 0..G {
                let y = v4.mul_f64s(k[g], x[g]);
                dst[g] = y;
                q[g] = v4.mul_add_f64s(y, y, q[g]);
            }
        }
        for g in 0..G {
            let v = if n >= 8 {
                let v: [f64; 8] = rs[g * n + n - 8..][..8].try_into().unwrap_or([0.0; 8]);
                avx._mm512_maskz_permutexvar_pd(self.low, self.idx, pulp::cast(v))
            } else {
                avx._mm512_maskz_mov_pd(self.low, pulp::cast(self.short_row(v4, i0 + g)))
            };
            let dp = avx._mm512_set1_pd(self.rows.dp[i0 + g]);
            x[g] = pulp::cast(avx._mm512_mask_mov_pd(v, self.dp_lane, dp));
        }
        let dst = &mut d[full * cap + at..][..G];
        for g in 0..G {
            let y = v4.mul_f64s(k[g], x[g]);
            dst[g] = y;
            q[g] = v4.mul_add_f64s(y, y, q[g]);
        }
    }
}
