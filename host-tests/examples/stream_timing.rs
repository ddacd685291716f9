//! robcal's side of the streaming peer benchmark of issue 16
//! (`bench/peers/run.sh --stream`): 10⁶ measurement blocks (3 rows × N,
//! weighted, no σ) streamed into the core's scalar `Accumulator<f64, Dyn>`
//! and into `estimate::wide::WideAccumulator`, and the machine's SIMD FMA
//! peak through the same run-time dispatch, timed in-process.
//!
//! ```text
//! cargo run --release -p host-tests --example stream_timing -- export DIR N   # the blocks for numpy, robcal's sums
//! cargo run --release -p host-tests --example stream_timing -- serve N        # driven by bench/peers/peers.py
//! ```
//!
//! The stream is a ring of [`RING`] blocks (`B` uniform in (−1, 1), `Δp =
//! B x + noise`, weights uniform in (0.5, 1.5) per row), made once before
//! any timing and read 10⁶ / [`RING`] times over: numpy gets exactly these
//! rows (`DIR/stream_N.f64`: per row `b₁ … b_N Δp w`, little-endian `f64`)
//! and streams them in chunks of one ring (3000 rows). `export` also writes
//! robcal's `Λ` (upper triangle), `η` and `Σ Δpᵀ W² Δp` after the 10⁶ blocks
//! (`DIR/stream_N_sums.txt`), which the peer reproduces before it is timed.
//!
//! `serve N` reads commands, one per line, and answers each with one line:
//!
//! - `run K core` / `run K wide`: K streams of 10⁶ blocks, the time of each
//!   in ns (the wide one includes the last flush); `run K many`: the same
//!   through `WideAccumulator::update_many`, one call per pass over the ring
//!   (1000 blocks); `run K rows`: the ring's rows row-major (made once,
//!   before any timing) through `WideAccumulator::update_rows`, one call per
//!   pass (3000 rows) — the same sums to the last bit (checked by `export`);
//! - `peak K`: the flops of one peak probe, then K times in ns;
//! - `info`: the instruction set the wide accumulator dispatched to;
//! - `quit`.

use std::hint::black_box;
use std::io::{BufRead, Write};
use std::time::Instant;

use nalgebra::Dyn;
use robcal::estimate::wide::{Rows, WideAccumulator};
use robcal::{Accumulator, Block};

/// Distinct blocks in the stream (3000 rows).
const RING: usize = 1000;
/// Blocks streamed per timed run.
const BLOCKS: usize = 1_000_000;
/// Rounds of the peak probe per timed run (~20 ms with AVX-512).
const PROBE: usize = 10_000_000;

fn ring(n: usize) -> Vec<Block<f64, Dyn>> {
    host_tests::stream_ring(n, RING)
}

fn stream_core(n: usize, ring: &[Block<f64, Dyn>]) -> Accumulator<f64, Dyn> {
    let mut acc = Accumulator::<f64, Dyn>::zeros(Dyn(n));
    for k in 0..BLOCKS {
        acc.update(&ring[k % RING]).expect("finite blocks");
    }
    acc
}

fn stream_wide(n: usize, ring: &[Block<f64, Dyn>]) -> Accumulator<f64, Dyn> {
    let mut acc = WideAccumulator::new(n);
    for k in 0..BLOCKS {
        acc.update(&ring[k % RING]).expect("finite blocks");
    }
    acc.accumulator()
}

/// The same stream through [`WideAccumulator::update_many`], one call per
/// pass over the ring (1000 blocks a call).
fn stream_many(n: usize, ring: &[Block<f64, Dyn>]) -> Accumulator<f64, Dyn> {
    let mut acc = WideAccumulator::new(n);
    for _ in 0..BLOCKS / RING {
        acc.update_many(ring).expect("finite blocks");
    }
    acc.accumulator()
}

/// The ring's rows row-major (`b`, `Δp`, `w`), for
/// [`WideAccumulator::update_rows`].
struct RowMajor {
    b: Vec<f64>,
    dp: Vec<f64>,
    w: Vec<f64>,
}

fn row_major(ring: &[Block<f64, Dyn>]) -> RowMajor {
    let mut rm = RowMajor {
        b: Vec::new(),
        dp: Vec::new(),
        w: Vec::new(),
    };
    for blk in ring {
        for r in 0..3 {
            rm.b.extend(blk.b.row(r).iter());
            rm.dp.push(blk.dp[r]);
            rm.w.push(blk.w[r]);
        }
    }
    rm
}

/// The same stream through [`WideAccumulator::update_rows`], one call per
/// pass over the ring (3000 rows a call).
fn stream_rows(n: usize, rm: &RowMajor) -> Accumulator<f64, Dyn> {
    let mut acc = WideAccumulator::new(n);
    let rows = Rows {
        b: &rm.b,
        dp: &rm.dp,
        w: &rm.w,
        sigma: None,
    };
    for _ in 0..BLOCKS / RING {
        acc.update_rows(rows).expect("finite rows");
    }
    acc.accumulator()
}

fn export(dir: &str, n: usize, ring: &[Block<f64, Dyn>]) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut bytes = Vec::with_capacity(RING * 3 * (n + 2) * 8);
    for blk in ring {
        for r in 0..3 {
            for c in 0..n {
                bytes.extend_from_slice(&blk.b[(r, c)].to_le_bytes());
            }
            bytes.extend_from_slice(&blk.dp[r].to_le_bytes());
            bytes.extend_from_slice(&blk.w[r].to_le_bytes());
        }
    }
    std::fs::write(format!("{dir}/stream_{n}.f64"), bytes)?;
    let acc = stream_wide(n, ring);
    let core = stream_core(n, ring);
    assert!(
        stream_many(n, ring) == acc && stream_rows(n, &row_major(ring)) == acc,
        "update_many and update_rows give update's sums"
    );
    let info = acc.information();
    let list = |v: &mut dyn Iterator<Item = f64>| {
        v.map(|x| format!("{x:e}")).collect::<Vec<_>>().join(" ")
    };
    let upper = (0..n).flat_map(|j| (0..=j).map(move |i| (i, j)));
    let text = format!(
        "# robcal's sums of {BLOCKS} blocks of stream_{n}.f64 (ring of {RING}), WideAccumulator\n\
         blocks {BLOCKS}\nupper {}\neta {}\nyy {:e}\n\
         # the core's scalar Accumulator on the same stream differs from it by at most {:e} (relative to max |Λ|)\n",
        list(&mut upper.map(|(i, j)| info[(i, j)])),
        list(&mut acc.eta().iter().copied()),
        acc.weighted_yy(),
        (info - core.information()).amax() / core.information().amax(),
    );
    std::fs::write(format!("{dir}/stream_{n}_sums.txt"), text)?;
    println!("wrote {dir}/stream_{n}.f64 and {dir}/stream_{n}_sums.txt");
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let n_arg = |i: usize| -> Result<usize, Box<dyn std::error::Error>> {
        Ok(args.get(i).ok_or("missing N")?.parse()?)
    };
    match args.first().map(String::as_str) {
        Some("export") => {
            let dir = args.get(1).ok_or("usage: export DIR N")?;
            let n = n_arg(2)?;
            export(dir, n, &ring(n))?;
        }
        Some("serve") => {
            let n = n_arg(1)?;
            let ring = ring(n);
            let rm = row_major(&ring);
            let probe = WideAccumulator::new(n);
            let stdin = std::io::stdin();
            let mut out = std::io::stdout().lock();
            for line in stdin.lock().lines() {
                let line = line?;
                let words: Vec<&str> = line.split_whitespace().collect();
                let time = |k: usize, f: &mut dyn FnMut()| {
                    (0..k)
                        .map(|_| {
                            let start = Instant::now();
                            f();
                            start.elapsed().as_nanos().to_string()
                        })
                        .collect::<Vec<_>>()
                        .join(" ")
                };
                match words.as_slice() {
                    ["run", k, "core"] => {
                        let t = time(k.parse()?, &mut || {
                            black_box(stream_core(n, black_box(&ring)));
                        });
                        writeln!(out, "{t}")?;
                    }
                    ["run", k, "wide"] => {
                        let t = time(k.parse()?, &mut || {
                            black_box(stream_wide(n, black_box(&ring)));
                        });
                        writeln!(out, "{t}")?;
                    }
                    ["run", k, "many"] => {
                        let t = time(k.parse()?, &mut || {
                            black_box(stream_many(n, black_box(&ring)));
                        });
                        writeln!(out, "{t}")?;
                    }
                    ["run", k, "rows"] => {
                        let t = time(k.parse()?, &mut || {
                            black_box(stream_rows(n, black_box(&rm)));
                        });
                        writeln!(out, "{t}")?;
                    }
                    ["peak", k] => {
                        let (flops, _) = probe.fma_probe(PROBE);
                        let t = time(k.parse()?, &mut || {
                            black_box(probe.fma_probe(black_box(PROBE)));
                        });
                        writeln!(out, "{flops} {t}")?;
                    }
                    ["info"] => writeln!(out, "{}", probe.instructions())?,
                    ["quit"] | [] => break,
                    _ => return Err(format!("unknown command: {line}").into()),
                }
                out.flush()?;
            }
        }
        _ => return Err("usage: stream_timing export DIR N | serve N".into()),
    }
    Ok(())
}
