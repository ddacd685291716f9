//! robcal's side of the peer benchmark of issue 16 (`bench/peers/`): the
//! paper's KR-270 iterative WLS (section 5: OLS start, eq. 14 weights per
//! configuration and axis, WLS refits until no parameter moves by more than
//! 1e-3 σ, sandwich covariance eq. 8 / 11) on the bundled data, timed
//! in-process.
//!
//! ```text
//! cargo run --release -p host-tests --example kr270_irls_timing                 # time robcal alone
//! cargo run --release -p host-tests --example kr270_irls_timing -- export DIR   # the problem for the peers
//! cargo run --release -p host-tests --example kr270_irls_timing -- serve        # driven by bench/peers/peers.py
//! ```
//!
//! The problem is the 810 rows `B` (270 deflections × x, y, z, 9
//! parameters) and `Δp` exactly as `host-tests/benches/kr270.rs` builds
//! them (the firmware's source, `examples/firmware/kr270.rs`, in f64),
//! computed once before any timing: the forward kinematics is not part of
//! the job, for robcal or for the peers. `export` writes them, with their
//! configuration and axis, to `DIR/kr270_rows.csv` (shortest round-trip
//! decimals, so the peers read the same doubles) and robcal's result and
//! settings to `DIR/kr270_reference.txt`.
//!
//! One timed calibration is: [`GroupedStats`] built from the 810 rows (270
//! `update`s), then `fit_irls` (OLS and 5 WLS steps, each with its σ per
//! configuration and axis and its sandwich). `serve` reads commands from
//! stdin, one per line, and answers each with one line:
//!
//! - `run K const` / `run K dyn`: K calibrations with `Const<9>` (the
//!   device's instantiation) or `Dyn(9)` (the CLI's), the time of each in
//!   ns, space-separated;
//! - `quit`.

#[allow(dead_code)]
#[path = "../../examples/firmware/kr270.rs"]
mod kr270;

use std::hint::black_box;
use std::io::{BufRead, Write};
use std::time::Instant;

use kr270::{Dn, Kr270, G, N};
use nalgebra::{Dyn, OMatrix, SMatrix, Vector3, U3};
use robcal::{Fit, GroupedStats, IrlsSettings, Reweightable};

/// One deflection: configuration, `B` (3 × 9), `Δp` \[m\].
type Row = (usize, SMatrix<f64, 3, N>, Vector3<f64>);
/// The same at the run-time size.
type RowDyn = (usize, OMatrix<f64, U3, Dyn>, Vector3<f64>);

/// The rows as the bench builds them.
fn rows() -> Vec<Row> {
    let src = Kr270::<f64>::new().expect("the KR-270 model");
    let mut rows = Vec::with_capacity(270);
    src.stream(|g, b, dp| {
        rows.push((g, *b, *dp));
        Ok(())
    })
    .expect("the KR-270 rows");
    rows
}

fn scratch() -> [Vec<Vector3<f64>>; 3] {
    [
        vec![Vector3::zeros(); G],
        vec![Vector3::zeros(); G],
        vec![Vector3::zeros(); G],
    ]
}

/// One calibration at the fixed size (the device's `Const<9>`).
fn calibrate_const(rows: &[Row], settings: &IrlsSettings<f64>) -> Fit<f64, Dn> {
    let mut stats = GroupedStats::<f64, Dn, G>::new();
    for (g, b, dp) in rows {
        stats.update(*g as i32, b, dp).expect("finite rows");
    }
    let [mut w, mut s, mut n] = scratch();
    stats
        .fit_irls(settings, &[true; N], &mut w, &mut s, &mut n, |_| {})
        .expect("the KR-270 fit")
}

/// One calibration at the run-time size (the CLI's `Dyn`).
fn calibrate_dyn(rows: &[RowDyn], settings: &IrlsSettings<f64>) -> Fit<f64, Dyn> {
    let mut stats = GroupedStats::<f64, Dyn, G>::with_dim(Dyn(N));
    for (g, b, dp) in rows {
        stats.update(*g as i32, b, dp).expect("finite rows");
    }
    let [mut w, mut s, mut n] = scratch();
    stats
        .fit_irls(settings, &[true; N], &mut w, &mut s, &mut n, |_| {})
        .expect("the KR-270 fit")
}

fn median(v: &mut [u64]) -> u64 {
    v.sort_unstable();
    v[v.len() / 2]
}

fn export(dir: &str, rows: &[Row], settings: &IrlsSettings<f64>) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let mut csv = String::from("config,axis");
    for j in 1..=N {
        csv += &format!(",b{j}");
    }
    csv += ",dp_m\n";
    for (g, b, dp) in rows {
        for a in 0..3 {
            // `{:e}` of an f64 is the shortest decimal that reads back to
            // the same double.
            csv += &format!("{g},{a}");
            for j in 0..N {
                csv += &format!(",{:e}", b[(a, j)]);
            }
            csv += &format!(",{:e}\n", dp[a]);
        }
    }
    std::fs::write(format!("{dir}/kr270_rows.csv"), csv)?;
    let fit = calibrate_const(rows, settings);
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:e}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let text = format!(
        "# robcal's KR-270 iterative WLS on kr270_rows.csv (GroupedStats<f64, Const<9>, 15>)\n\
         sigma0_m {:e}\nlambda {:e}\ntolerance {:e}\nmax_iterations {}\npool_below_dof {:e}\n\
         iterations {}\nconverged {}\nx {}\nsd {}\n",
        settings.weight.sigma0,
        settings.weight.lambda,
        settings.tolerance,
        settings.max_iterations,
        robcal::estimate::POOL_BELOW_DOF,
        fit.iterations,
        fit.converged,
        list(fit.solution.x.as_slice()),
        list(fit.std().as_slice()),
    );
    std::fs::write(format!("{dir}/kr270_reference.txt"), text)?;
    println!(
        "wrote {} rows to {dir}/kr270_rows.csv and {dir}/kr270_reference.txt",
        rows.len() * 3
    );
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let rows = rows();
    let settings = kr270::settings::<f64>().map_err(|e| format!("{e}"))?;
    let rows_dyn: Vec<RowDyn> = rows
        .iter()
        .map(|(g, b, dp)| {
            (
                *g,
                OMatrix::<f64, U3, Dyn>::from_column_slice(b.as_slice()),
                *dp,
            )
        })
        .collect();

    // Both instantiations give the same fit, bit for bit.
    let (a, b) = (
        calibrate_const(&rows, &settings),
        calibrate_dyn(&rows_dyn, &settings),
    );
    assert_eq!(a.solution.x.as_slice(), b.solution.x.as_slice());
    assert_eq!(a.covariance.as_slice(), b.covariance.as_slice());
    assert_eq!(a.iterations, b.iterations);

    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("export") => {
            let dir = args.get(1).ok_or("usage: export DIR")?;
            export(dir, &rows, &settings)?;
        }
        Some("serve") => {
            let stdin = std::io::stdin();
            let mut out = std::io::stdout().lock();
            for line in stdin.lock().lines() {
                let line = line?;
                let words: Vec<&str> = line.split_whitespace().collect();
                match words.as_slice() {
                    ["run", k, variant] => {
                        let k: usize = k.parse()?;
                        let mut t = Vec::with_capacity(k);
                        for _ in 0..k {
                            let start = Instant::now();
                            match *variant {
                                "const" => {
                                    black_box(calibrate_const(black_box(&rows), &settings));
                                }
                                _ => {
                                    black_box(calibrate_dyn(black_box(&rows_dyn), &settings));
                                }
                            }
                            t.push(start.elapsed().as_nanos().to_string());
                        }
                        writeln!(out, "{}", t.join(" "))?;
                        out.flush()?;
                    }
                    ["quit"] | [] => break,
                    _ => return Err(format!("unknown command: {line}").into()),
                }
            }
        }
        None => {
            let mut tc = Vec::new();
            let mut td = Vec::new();
            for _ in 0..200 {
                for _ in 0..20 {
                    let s = Instant::now();
                    black_box(calibrate_const(black_box(&rows), &settings));
                    tc.push(s.elapsed().as_nanos() as u64);
                    let s = Instant::now();
                    black_box(calibrate_dyn(black_box(&rows_dyn), &settings));
                    td.push(s.elapsed().as_nanos() as u64);
                }
            }
            println!(
                "KR-270 iterative WLS ({} iterations), median of {} each, interleaved: \
                 Const<9> {:.1} µs, Dyn(9) {:.1} µs",
                a.iterations,
                tc.len(),
                median(&mut tc) as f64 / 1e3,
                median(&mut td) as f64 / 1e3
            );
        }
        Some("parts") => {
            // Where the time goes: the statistics built from the rows, and
            // the fit from built statistics.
            let (mut tb, mut tf) = (Vec::new(), Vec::new());
            for _ in 0..4000 {
                let s = Instant::now();
                let mut stats = GroupedStats::<f64, Dn, G>::new();
                for (g, b, dp) in black_box(&rows) {
                    stats.update(*g as i32, b, dp)?;
                }
                tb.push(s.elapsed().as_nanos() as u64);
                let built = black_box(stats);
                let s = Instant::now();
                let [mut w, mut sg, mut n] = scratch();
                black_box(built.fit_irls(
                    &settings,
                    &[true; N],
                    &mut w,
                    &mut sg,
                    &mut n,
                    |_| {},
                )?);
                tf.push(s.elapsed().as_nanos() as u64);
            }
            println!(
                "Const<9>: build {:.1} µs, fit_irls {:.1} µs",
                median(&mut tb) as f64 / 1e3,
                median(&mut tf) as f64 / 1e3
            );
        }
        Some(other) => return Err(format!("unknown mode {other}").into()),
    }
    Ok(())
}
