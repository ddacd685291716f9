//! The host's streaming update with SIMD (issue 16): the statistics of
//! [`Accumulator`] — `Λ = Σ Bᵀ W² B`, `η = Σ Bᵀ W² Δp` (eq. 10),
//! `Σ Δpᵀ W² Δp` and, with σ, `M = Σ Bᵀ W² Σ² W² B` (eq. 11) — at a size
//! `n` chosen at run time, from blocks fed one at a time like
//! [`Accumulator::update`], several times faster on a processor with wide
//! vectors.
//!
//! A block's rows are buffered, weighted (`U = W [B | Δp]`, up to a few
//! dozen rows, sized so that they stay in the first-level cache); a full
//! buffer of `k` rows is added to the upper triangles in one rank-`k`
//! update `Λ += Uₖᵀ Uₖ = Bₖᵀ W² Bₖ`, blocked in register tiles, with fused
//! multiply-adds on the widest vectors the processor has: AVX-512, AVX2 +
//! FMA, or plain scalar code, chosen once at run time (the `pulp` crate: no
//! `unsafe` in robcal, no `target-cpu`, one binary for every x86-64). `η`
//! and `Σ Δpᵀ W² Δp` come from the same update, `Δp` being one more column
//! (`[B | Δp]ᵀ W² [B | Δp]`); `M` from `V = W²Σ [B | Δp]` the same way.
//!
//! Blocks can also come several at a time ([`WideAccumulator::update_many`],
//! one dispatch per call), or as rows already row-major
//! ([`WideAccumulator::update_rows`] with [`Rows`]: no de-interleave of a
//! column-major block, the checks once per buffer of rows): the same sums
//! to the last bit, a bad input refused with its index, what came before
//! it taken.
//!
//! The sums are the scalar update's terms, row by row in the same order;
//! each term is `(w bᵢ)(w bⱼ)` where the core has `bᵢ (w² bⱼ)`, and each
//! product is fused with its addition (one rounding instead of two): they
//! agree with [`Accumulator`] to a few units in the last place per row, far
//! inside the `1e-12` relative of issue 16
//! (`host-tests/tests/wide_accumulator.rs`). The solution is the core's:
//! [`WideAccumulator::accumulator`] hands the sums over to an
//! [`Accumulator<f64, Dyn>`], whose `solve` and everything after it are the
//! same code as for the streamed core accumulator.
//!
//! ```
//! use nalgebra::{DVector, Dyn, OMatrix, Vector3, U3};
//! use robcal::estimate::wide::WideAccumulator;
//! use robcal::{Accumulator, Block};
//!
//! let n = 4;
//! let mut wide = WideAccumulator::new(n);
//! let mut core = Accumulator::<f64, Dyn>::zeros(Dyn(n));
//! let x = DVector::from_fn(n, |i, _| 0.1 * i as f64);
//! for k in 0..50 {
//!     let b = OMatrix::<f64, U3, Dyn>::from_fn(n, |r, c| ((7 * k + 3 * r + c) % 11) as f64 - 5.0);
//!     let block = Block::new(b.clone(), b * &x).with_weights(Vector3::new(1.0, 0.5, 2.0));
//!     wide.update(&block).unwrap();
//!     core.update(&block).unwrap();
//! }
//! let (wide, core) = (wide.accumulator(), core);
//! assert_eq!(wide.equations(), core.equations());
//! let d = (wide.information() - core.information()).amax();
//! assert!(d <= 1e-12 * core.information().amax());
//! assert!((wide.solve().unwrap().x - &x).amax() < 1e-12);
//! ```

use nalgebra::{DMatrix, DVector, Dyn};

use super::block::{validate_rows, Block};
use super::Accumulator;
use crate::error::Error;

mod copy;
mod kernel;
mod many;
mod rows;
use copy::{Copier, Dispatched, Push};
use kernel::{at, PAD};
pub use many::Rejected;
pub use rows::Rows;

/// The instruction set of a [`WideAccumulator`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Instructions {
    /// The widest this processor has (AVX-512, else AVX2 + FMA, else
    /// scalar).
    Detected,
    /// AVX2 with FMA (4 lanes), where the processor has it.
    Avx2Fma,
    /// Scalar code (1 lane): any processor.
    Scalar,
}

/// Streaming `Λ`, `η`, `Σ Δpᵀ W² Δp` and `M` with a blocked SIMD update.
/// See the [module docs](self).
#[derive(Debug)]
pub struct WideAccumulator {
    /// Parameters.
    n: usize,
    /// `n + 1` rounded up to [`PAD`]: the row length of the buffers, the
    /// side of `C`.
    mp: usize,
    /// Rows the buffers hold; at most `rows_cap` of them in
    /// [`Self::update_rows`] ([`ROWS_BYTES`]).
    cap: usize,
    rows_cap: usize,
    /// The instruction set and its `f64` lanes (the buffers' chunk width).
    arch: pulp::Arch,
    lanes: usize,
    /// Buffered rows, weighted: `U = W [B | Δp]` and `V = W²Σ [B | Δp]` (`v`:
    /// empty until a block carries σ), laid out for the kernel
    /// (`kernel::at`); `PAD` more values than needed, to start at a 64-byte
    /// boundary.
    u: Vec<f64>,
    v: Vec<f64>,
    /// `Uᵀ U = [B | Δp]ᵀ W² [B | Δp]` (upper triangle, `mp × mp`,
    /// column-major) and `M = Vᵀ V` (empty until σ), the rows flushed so far.
    c: Vec<f64>,
    cm: Vec<f64>,
    /// Rows in the buffer; whether one of their blocks carried σ.
    rows: usize,
    sigma_pending: bool,
    /// Rows with a positive weight (buffered ones included); those with σ.
    equations: usize,
    sigma_rows: usize,
    /// At least the largest `Λⱼⱼ`, `|ηⱼ|`, `Mⱼⱼ` and `Σ Δpᵀ W² Δp`, buffered
    /// rows included (the core's overflow check, see
    /// [`Accumulator::update`]).
    bound: f64,
    /// The permutes of the last chunk of a block's copy (AVX-512):
    /// [`copy::row_permutes`]`(n mod 8)`.
    tail: [[[i64; 8]; 2]; 3],
}

/// The bytes of `U` the buffer is sized to (half of a 48 KiB first-level
/// cache: the rows stay there between the block's copy and the kernel).
const BUFFER_BYTES: usize = 24 * 1024;

/// The bytes of `U` [`WideAccumulator::update_rows`] fills before a flush,
/// but at least 48 rows and at most the buffer: 72 rows instead of 96 at
/// N = 23 … 30, fewer also at N = 31 … 54; the other N unchanged. Its copy of
/// a row is cheaper than `update`'s, and with less of the first-level
/// cache taken (which the other hyperthread shares) it was 3–5 % faster at
/// N = 30 (measured: 63, 72, 84, 96 rows), which `update` is not.
/// Where a flush falls does not change the sums.
const ROWS_BYTES: usize = 18 * 1024;

/// `v[..len]` from the first 64-byte boundary (`v` has `PAD` spare values).
fn aligned(v: &[f64], len: usize) -> &[f64] {
    let off = v.as_ptr().align_offset(64).min(PAD);
    &v[off..off + len]
}

fn aligned_mut(v: &mut [f64], len: usize) -> &mut [f64] {
    let off = v.as_ptr().align_offset(64).min(PAD);
    &mut v[off..off + len]
}

/// A copy's buffers start at their own 64-byte boundary: each vector is
/// copied from where the original's aligned part starts to where the copy's
/// does (a plain `Vec` clone would shift them).
impl Clone for WideAccumulator {
    fn clone(&self) -> Self {
        let copy = |v: &Vec<f64>| {
            if v.is_empty() {
                return Vec::new();
            }
            let len = v.len() - PAD;
            let mut w = vec![0.0; v.len()];
            aligned_mut(&mut w, len).copy_from_slice(aligned(v, len));
            w
        };
        Self {
            u: copy(&self.u),
            v: copy(&self.v),
            c: copy(&self.c),
            cm: copy(&self.cm),
            ..*self
        }
    }
}

impl WideAccumulator {
    /// An empty accumulator of `n` parameters on the widest instructions of
    /// this processor.
    pub fn new(n: usize) -> Self {
        Self::on(n, pulp::Arch::new())
    }

    /// An empty accumulator of `n` parameters on `instructions`; `None`
    /// where the processor does not have them.
    pub fn with_instructions(n: usize, instructions: Instructions) -> Option<Self> {
        let arch = match instructions {
            Instructions::Detected => pulp::Arch::new(),
            Instructions::Scalar => pulp::Arch::Scalar,
            #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
            Instructions::Avx2Fma => pulp::Arch::V3(pulp::x86::V3::try_new()?),
            #[cfg(not(any(target_arch = "x86", target_arch = "x86_64")))]
            Instructions::Avx2Fma => return None,
        };
        Some(Self::on(n, arch))
    }

    fn on(n: usize, arch: pulp::Arch) -> Self {
        let mp = (n + 1).div_ceil(PAD) * PAD;
        let cap = (BUFFER_BYTES / (8 * mp) / 3 * 3).clamp(24, 96);
        Self {
            n,
            mp,
            cap,
            rows_cap: (ROWS_BYTES / (8 * mp) / 3 * 3).max(48).min(cap),
            arch,
            lanes: kernel::lanes(arch),
            u: vec![0.0; cap * mp + PAD],
            v: Vec::new(),
            c: vec![0.0; mp * mp + PAD],
            cm: Vec::new(),
            rows: 0,
            sigma_pending: false,
            equations: 0,
            sigma_rows: 0,
            bound: 0.0,
            tail: copy::row_permutes(n % 8),
        }
    }

    /// The instruction set in use: `"avx512"`, `"avx2+fma"` or `"scalar"`.
    pub fn instructions(&self) -> &'static str {
        match self.lanes {
            8 => "avx512",
            4 => "avx2+fma",
            _ => "scalar",
        }
    }

    /// The number of parameters.
    pub fn parameters(&self) -> usize {
        self.n
    }

    /// Rows with a positive weight so far.
    pub fn equations(&self) -> usize {
        self.equations
    }

    /// Rows that carried a σ (and enter `M`).
    pub fn sigma_rows(&self) -> usize {
        self.sigma_rows
    }

    /// Forgets every measurement.
    pub fn reset(&mut self) {
        self.c.fill(0.0);
        self.cm.clear();
        self.rows = 0;
        self.sigma_pending = false;
        self.equations = 0;
        self.sigma_rows = 0;
        self.bound = 0.0;
    }

    /// Adds one measurement block, as [`Accumulator::update`]: `Λ += Bᵀ W² B`,
    /// `η += Bᵀ W² Δp`, `Σ Δpᵀ W² Δp += Δpᵀ W² Δp` and, when the block
    /// carries σ, `M += Bᵀ W² Σ² W² B` — once the buffer is full, or at
    /// [`Self::accumulator`]. Nothing is allocated (but the buffers of `M`
    /// at the first block with σ).
    ///
    /// # Errors
    /// Those of [`Accumulator::update`], for the same inputs: the block's
    /// size, [`Block::validate`], and [`Error::NonFinite`] with
    /// `what = "overflow"` when a sum could overflow (here refused already
    /// when the exactly computed new `Λⱼⱼ`, `|ηⱼ|`, `Mⱼⱼ` or `Σ Δpᵀ W² Δp`
    /// would exceed half the largest `f64`, ~9e307: the vector code adds in
    /// another order than that check). The statistics are unchanged on
    /// error.
    pub fn update(&mut self, block: &Block<f64, Dyn>) -> Result<(), Error> {
        self.push_block(block, &Dispatched(self.arch))
    }

    /// [`Self::update`] with the copy of the rows run by `copier`.
    #[inline(always)]
    fn push_block<C: Copier>(&mut self, block: &Block<f64, Dyn>, copier: &C) -> Result<(), Error> {
        let (b, dp, w, sigma, rows) = (
            &block.b,
            &block.dp,
            &block.w,
            block.sigma.as_ref(),
            block.rows,
        );
        if b.ncols() != self.n {
            return Err(Error::Mismatch {
                what: "block size differs from the accumulator's",
            });
        }
        if rows == 0 || rows > 3 {
            return validate_rows(b, dp, w, sigma, rows);
        }
        let Some(rw) = RowWeights::new(w.as_slice(), sigma, rows) else {
            validate_rows(b, dp, w, sigma, rows)?;
            return Err(Error::NonFinite { what: "weight" });
        };
        if self.rows + rows > self.cap {
            self.flush();
        }
        if rw.sigma {
            self.start_sigma();
        }
        // Rows without σ in a buffer with σ rows: zero rows of `V`.
        let ws = if rw.sigma {
            Some(&rw.ws)
        } else {
            self.sigma_pending.then_some(&[0.0; 3])
        };
        let len = self.cap * self.mp;
        let q = copier.copy(&mut Push {
            b: b.as_slice(),
            dp: &dp.data.0[0],
            w: &rw.w,
            ws,
            rows,
            cap: self.cap,
            row0: self.rows,
            du: aligned_mut(&mut self.u, len),
            dv: ws.map(|_| aligned_mut(&mut self.v, len)),
            tail: &self.tail,
        });
        // The core's running bound: `(Σ w² + Σ w⁴σ²) q` bounds the change of
        // every checked value (`q` ≥ every b², Δp²).
        let k = ((rw.w2[0] + rw.w2[1]) + (rw.w2[2] + rw.s2[0])) + (rw.s2[1] + rw.s2[2]);
        let next = (self.bound + k * q) * (1.0 + 1.0 / 1024.0);
        let bound = if next <= f64::MAX / 16.0 {
            next
        } else {
            validate_rows(b, dp, w, sigma, rows)?;
            // An infinite w² or w⁴σ² makes every one of the core's sums of
            // that row infinite or NaN (`b · (w² b)`), whatever `b`; the
            // rows here hold `w b`, which can stay finite.
            let finite = rw.w2.iter().chain(&rw.s2).all(|v| v.is_finite());
            finite
                .then(|| self.exact_bound(rows, rw.sigma))
                .flatten()
                .ok_or(Error::NonFinite { what: "overflow" })?
        };
        // Commit: the rows written past `self.rows` join the buffer.
        self.rows += rows;
        self.sigma_pending |= rw.sigma;
        self.equations += rw.equations;
        if rw.sigma {
            self.sigma_rows += rw.equations;
        }
        self.bound = bound;
        Ok(())
    }

    /// The buffers of `M` at the first block with σ (zeros), and zero `V`
    /// rows for the buffered rows without σ.
    fn start_sigma(&mut self) {
        let len = self.cap * self.mp;
        if self.cm.is_empty() {
            self.cm = vec![0.0; self.mp * self.mp + PAD];
        }
        if self.v.is_empty() {
            self.v = vec![0.0; len + PAD];
        } else if !self.sigma_pending {
            let (l, cap, rows) = (self.lanes, self.cap, self.rows);
            let v = aligned_mut(&mut self.v, len);
            for chunk in v.chunks_exact_mut(cap * l) {
                chunk[..rows * l].fill(0.0);
            }
        }
    }

    /// The new checked values computed one by one (after the buffered rows
    /// and the `rows` just written past them), as the slow path of the
    /// core's check: their largest, if all are at most `f64::MAX / 2`.
    #[cold]
    fn exact_bound(&self, rows: usize, sigma: bool) -> Option<f64> {
        let (n, mp, cap, l) = (self.n, self.mp, self.cap, self.lanes);
        let len = cap * mp;
        let u = aligned(&self.u, len);
        let v = (sigma || self.sigma_pending).then(|| aligned(&self.v, len));
        let c = aligned(&self.c, mp * mp);
        let cm = (!self.cm.is_empty()).then(|| aligned(&self.cm, mp * mp));
        let limit = f64::MAX / 2.0;
        let mut bound = 0.0f64;
        for j in 0..=n {
            let (mut lambda, mut eta) = (c[j * mp + j], c[n * mp + j]);
            let mut mid = match cm {
                Some(cm) if j < n => cm[j * mp + j],
                _ => 0.0,
            };
            for r in 0..self.rows + rows {
                let x = u[at(l, cap, r, j)];
                lambda += x * x;
                eta += x * u[at(l, cap, r, n)];
                if let (Some(v), true) = (v, j < n) {
                    let y = v[at(l, cap, r, j)];
                    mid += y * y;
                }
            }
            // j = n: `lambda` is Σ Δpᵀ W² Δp.
            let ok = lambda <= limit && eta.abs() <= limit && mid <= limit;
            if !ok {
                return None;
            }
            bound = bound.max(lambda).max(eta.abs()).max(mid);
        }
        Some(bound)
    }

    /// Adds the buffered rows to the sums (the rank-`k` update).
    pub fn flush(&mut self) {
        if self.rows == 0 {
            return;
        }
        let (mp, cap, len) = (self.mp, self.cap, self.cap * self.mp);
        let u = aligned(&self.u, len);
        let c = aligned_mut(&mut self.c, mp * mp);
        kernel::rank_k(self.arch, c, u, u, self.n + 1, mp, cap, self.rows);
        if self.sigma_pending {
            let v = aligned(&self.v, len);
            let cm = aligned_mut(&mut self.cm, mp * mp);
            kernel::rank_k(self.arch, cm, v, v, self.n, mp, cap, self.rows);
        }
        self.rows = 0;
        self.sigma_pending = false;
    }

    /// The statistics so far as the core's accumulator (after a
    /// [`Self::flush`]), for [`Accumulator::solve`] and everything after it.
    pub fn accumulator(&mut self) -> Accumulator<f64, Dyn> {
        self.flush();
        let (n, mp) = (self.n, self.mp);
        let c = aligned(&self.c, mp * mp);
        let upper =
            |c: &[f64]| DMatrix::from_fn(n, n, |i, j| if i <= j { c[j * mp + i] } else { 0.0 });
        let eta = DVector::from_fn(n, |i, _| c[n * mp + i]);
        let acc = Accumulator::from_sums(upper(c), eta, c[n * mp + n], self.equations);
        if self.cm.is_empty() {
            acc
        } else {
            acc.with_middle(upper(aligned(&self.cm, mp * mp)), self.sigma_rows)
        }
    }

    /// The machine's peak through this accumulator's instructions: `iterations`
    /// rounds of independent fused multiply-adds on as many vector registers
    /// as cover the units' latency. Returns the flops done and a value that
    /// depends on all of them (for the benchmarks' "% of peak", measured).
    pub fn fma_probe(&self, iterations: usize) -> (f64, f64) {
        let flops = 2.0 * (self.lanes * kernel::CHAINS) as f64 * iterations as f64;
        (flops, kernel::fma_chains(self.arch, iterations))
    }
}

/// The checked per-row quantities of one block: `w`, `w²σ` (the rows'
/// factors in `U` and `V`), `w²`, `w⁴σ²` (for the bound, as the core's
/// update computes them; all zero past the block's rows or without σ) and
/// the rows with a positive weight.
struct RowWeights {
    w: [f64; 3],
    ws: [f64; 3],
    w2: [f64; 3],
    s2: [f64; 3],
    sigma: bool,
    equations: usize,
}

impl RowWeights {
    /// `None` when a weight is negative or NaN or a σ is not positive.
    ///
    /// Written with a fixed index per row (the rows past `rows` as zero
    /// weights), not a loop to `rows`: the values stay in registers, where
    /// arrays written one value at a time and then copied in wide moves
    /// stall the processor (store forwarding) in the batched loop.
    #[inline(always)]
    fn new(w: &[f64], sigma: Option<&nalgebra::Vector3<f64>>, rows: usize) -> Option<Self> {
        let used = [true, rows > 1, rows > 2];
        let w: [f64; 3] = core::array::from_fn(|r| if used[r] { w[r] } else { 0.0 });
        // `x >= 0` is false for NaN.
        if !w.iter().all(|&x| x >= 0.0) {
            return None;
        }
        let w2 = w.map(|x| x * x);
        let equations = w2.iter().map(|&k| usize::from(k > 0.0)).sum();
        let (ws, s2) = match sigma {
            Some(s) => {
                let s: [f64; 3] = core::array::from_fn(|r| if used[r] { s[r] } else { 0.0 });
                if !(0..3).all(|r| !used[r] || s[r] > 0.0) {
                    return None;
                }
                (
                    core::array::from_fn(|r| w2[r] * s[r]),
                    core::array::from_fn(|r| w2[r] * w2[r] * s[r] * s[r]),
                )
            }
            None => ([0.0; 3], [0.0; 3]),
        };
        Some(Self {
            w,
            ws,
            w2,
            s2,
            sigma: sigma.is_some(),
            equations,
        })
    }
}
