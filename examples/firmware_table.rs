//! Generates the firmware's flash table `examples/firmware/kr270_table.rs`
//! from the paper's data set (`data/kr270/measurements.csv`), with the
//! host's reference result the firmware checks itself against.
//!
//! ```sh
//! cargo run --example firmware_table           # rewrite the table
//! cargo run --example firmware_table -- --check  # fail if it is stale
//! ```
//!
//! The table (section 5's experiment, 15 configurations × 6 repetitions ×
//! 3 markers = 270 deflections, 3.7 KB of flash):
//!
//! - `Q_CDEG`: the joint angles of each configuration once, in 0.01° (`i16`):
//!   Table 2 prints them to 0.01°, so this is exact (checked here);
//! - `LOAD_DKG`: the load of each configuration in 0.1 kg (`u16`), exact (the
//!   CSV gives it to 0.1 kg; checked here);
//! - per deflection, `KEYS`: configuration and marker index in one byte
//!   (`config << 2 | marker`), and `DP_NM`: `Δp = p_loaded − p_unloaded`
//!   (x, y, z, base frame) as `i32` in nanometres, each below 2²⁴ (16.7 mm,
//!   checked here) so that f32 holds it exactly. Rounding moves a
//!   coordinate by at most 0.5 nm (RMS 0.29 nm), 3e-5 of the smallest σ of
//!   Table 1 (17 µm) and 2e-6 of the largest (153 µm); what it does to the
//!   estimate is measured below (≈ 1e-5 σ) and written into the table.
//!   13 bytes per deflection: 3.5 KB, plus 210 bytes per configuration data. (`i16` in 0.5 µm would fit the
//!   largest deflection, 11.2 mm, in 2 bytes per coordinate, but moves
//!   the estimate by 0.009 σ, which would eat most of the f32 tolerance.)
//!
//! The reference (`HOST_*`): the product, `robcal::calibrate` in f64 on
//! the CSV with the declared model of `setup.toml` (k21…k25, k3…k6) and no
//! diagnosis — rows at the unloaded pose (eq. 3), iterative WLS (section 5)
//! with σ0 = 10 µm, λ = 1, tolerance 1e-3 σ, sandwich covariance (eq. 11).
//! The firmware runs the same model with the core alone (`Layout::fill`,
//! rows streamed into an `Accumulator`) and checks its f32 estimate against
//! this reference.

use std::error::Error as StdError;
use std::fmt::Write as _;
use std::path::Path;

use nalgebra::Vector3;
use robcal::calibrate::{self, DeflectionModel, Report, Settings};
use robcal::io::{Job, Measurements};
use robcal_paper::kr270;

const N: usize = kr270::PARAMS;
const G: usize = kr270::CONFIGS;
/// Quantum of the stored deflections \[m\].
const DP_QUANTUM_M: f64 = 1e-9;

/// The reference: the declared model of the job, iterative WLS, nothing
/// added by the diagnosis — with the first-order deflection model of
/// eq. 3 (`robcal calibrate --linear`), which is what the device streams:
/// its rows are the columns at the commanded pose (the exact equilibrium
/// per row and pass would cost the device several times the fit).
fn irls(job: &Job, data: &Measurements) -> Result<Report, Box<dyn StdError>> {
    let settings = Settings {
        diagnose: false,
        heldout: false,
        deflection_model: DeflectionModel::Linear,
        ..Settings::default()
    };
    let report = calibrate::calibrate(job, data, &settings, &mut |_| {})?;
    let names: Vec<&str> = report.parameters.iter().map(|p| p.name.as_str()).collect();
    if names != kr270::PARAM_NAMES {
        return Err(format!("setup.toml declares {names:?}, not the paper's model").into());
    }
    Ok(report)
}

fn main() -> Result<(), Box<dyn StdError>> {
    let check = std::env::args().any(|a| a == "--check");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let job = Job::load(root.join("data/kr270/setup.toml"))?;
    let data = job.read_measurements(root.join("data/kr270/measurements.csv"))?;
    let noise = job.setup.noise;
    let sigma0_m = noise.sigma0_um * 1e-6;

    // Per configuration: angles (0.01°) and load (0.1 kg), exact.
    let mut q_cdeg = [[0i16; 6]; G];
    let mut load_dkg = [0u16; G];
    let mut seen = [false; G];
    let mut quantised = data.clone();
    let mut records = Vec::new();
    let (mut max_dp, mut max_err, mut sum_err2) = (0.0f64, 0.0f64, 0.0f64);
    for d in &data.deflections {
        let g = usize::try_from(d.config - 1)?;
        if g >= G || d.q.len() != 6 {
            return Err(format!(
                "config {} / {} joints: not the paper's",
                d.config,
                d.q.len()
            )
            .into());
        }
        let cdeg: Vec<f64> = d.q.iter().map(|q| q.to_degrees() * 100.0).collect();
        let cdeg_i: Vec<i16> = cdeg.iter().map(|v| v.round() as i16).collect();
        for (v, i) in cdeg.iter().zip(&cdeg_i) {
            if (v - f64::from(*i)).abs() > 1e-9 {
                return Err(format!("angle {v} cdeg is not a multiple of 0.01°").into());
            }
        }
        let dkg = (d.load_kg * 10.0).round();
        if (d.load_kg * 10.0 - dkg).abs() > 1e-9 || !(0.0..65536.0).contains(&dkg) {
            return Err(format!("load {} kg is not a multiple of 0.1 kg", d.load_kg).into());
        }
        if seen[g] && (q_cdeg[g][..] != cdeg_i[..] || load_dkg[g] != dkg as u16) {
            return Err(format!("config {}: angles or load differ between rows", d.config).into());
        }
        seen[g] = true;
        q_cdeg[g].copy_from_slice(&cdeg_i);
        load_dkg[g] = dkg as u16;

        let m = job
            .setup
            .markers
            .iter()
            .position(|m| m.id == d.marker)
            .ok_or("unknown marker")?;
        let dp = Vector3::from(d.dp_m);
        let units = dp / DP_QUANTUM_M;
        let stored = units.map(f64::round);
        for a in 0..3 {
            // Below 2²⁴: exact in f32, which the device converts it to
            // without going through f64 (`kr270::dp_m`).
            if stored[a].abs() >= 16_777_216.0 {
                return Err(format!("deflection {} m is not below 2^24 nm", dp[a]).into());
            }
            let err = (stored[a] - units[a]).abs() * DP_QUANTUM_M;
            max_err = max_err.max(err);
            sum_err2 += err * err;
            max_dp = max_dp.max(dp[a].abs());
        }
        records.push((g, m, stored.map(|v| v as i32)));
    }
    for d in &mut quantised.deflections {
        d.dp_m = d.dp_m.map(|v| (v / DP_QUANTUM_M).round() * DP_QUANTUM_M);
    }
    if seen.iter().any(|s| !s) {
        return Err("a configuration has no measurement".into());
    }
    records.sort_by_key(|r| r.0); // stable: file order within a configuration

    let reference = irls(&job, &data)?;
    let from_table = irls(&job, &quantised)?;
    let x: Vec<f64> = reference.parameters.iter().map(|p| p.value).collect();
    let sd: Vec<f64> = reference.parameters.iter().map(|p| p.std).collect();
    let quant_sigmas = (0..N)
        .map(|i| (from_table.parameters[i].value - x[i]).abs() / sd[i])
        .fold(0.0, f64::max);
    let rms_err = (sum_err2 / (3 * records.len()) as f64).sqrt();

    let mut s = String::new();
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:e}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    writeln!(
        s,
        "// @generated by `cargo run --example firmware_table` from\n\
         // data/kr270/measurements.csv; do not edit. Included by examples/firmware/kr270.rs.\n\
         //\n\
         // {} deflections; largest |Δp| component {:.3} mm; quantisation error max {:.3} nm,\n\
         // RMS {:.3} nm; it moves the f64 iterative-WLS estimate by {:.2e} σ at most.\n",
        records.len(),
        max_dp * 1e3,
        max_err * 1e9,
        rms_err * 1e9,
        quant_sigmas
    )?;
    writeln!(
        s,
        "/// Unit of `DP_NM` \\[m\\].\npub const DP_QUANTUM_M: f64 = {DP_QUANTUM_M:e};\n"
    )?;
    writeln!(
        s,
        "/// Joint angles q1…q6 of each configuration (Table 2) in 0.01°.\npub const Q_CDEG: [[i16; 6]; {G}] = ["
    )?;
    for q in &q_cdeg {
        writeln!(s, "    {q:?},")?;
    }
    writeln!(s, "];\n")?;
    writeln!(
        s,
        "/// Load of each configuration in 0.1 kg.\npub const LOAD_DKG: [u16; {G}] = {load_dkg:?};\n"
    )?;
    let n = records.len();
    writeln!(
        s,
        "/// Per deflection (sorted by configuration, file order within one):\n\
         /// `config << 2 | marker`, both 0-based.\npub const KEYS: [u8; {n}] = ["
    )?;
    for chunk in records.chunks(18) {
        let keys: Vec<String> = chunk
            .iter()
            .map(|(g, m, _)| format!("{}", g << 2 | m))
            .collect();
        writeln!(s, "    {},", keys.join(", "))?;
    }
    writeln!(s, "];\n")?;
    writeln!(
        s,
        "/// Per deflection: Δp = p_loaded − p_unloaded (x, y, z, base frame) [nm].\n\
         pub const DP_NM: [[i32; 3]; {n}] = ["
    )?;
    for (_, _, dp) in &records {
        writeln!(s, "    [{}, {}, {}],", dp[0], dp[1], dp[2])?;
    }
    writeln!(s, "];\n")?;
    writeln!(
        s,
        "/// Host reference (f64, from the CSV, `robcal::calibrate`): iterative WLS\n\
         /// estimate \\[µrad/(N·m)\\].\npub const HOST_X: [f64; {N}] = [{}];",
        list(&x)
    )?;
    writeln!(
        s,
        "/// Its standard deviations (sandwich, eq. 11) \\[µrad/(N·m)\\].\npub const HOST_SD: [f64; {N}] = [{}];",
        list(&sd)
    )?;
    writeln!(
        s,
        "/// WLS iterations after the OLS start.\npub const HOST_ITERATIONS: usize = {};",
        reference.iterations
    )?;
    writeln!(
        s,
        "/// σ0 \\[m\\] and λ of eq. 14 (`setup.toml`).\npub const SIGMA0_M: f64 = {sigma0_m:e};\npub const LAMBDA: f64 = {:e};",
        noise.lambda
    )?;
    writeln!(
        s,
        "/// Largest |x̂(quantised table) − x̂(CSV)| / σ of the f64 fit.\npub const QUANTISATION_SIGMAS: f64 = {quant_sigmas:e};"
    )?;

    let out = root.join("examples/firmware/kr270_table.rs");
    eprintln!(
        "{} deflections, max |dp| {:.3} mm, quantisation max {:.3} nm RMS {:.3} nm -> {:.2e} sigma; \
         reference: {} iterations, converged {}",
        records.len(),
        max_dp * 1e3,
        max_err * 1e9,
        rms_err * 1e9,
        quant_sigmas,
        reference.iterations,
        reference.converged
    );
    for i in 0..N {
        eprintln!(
            "  {:>4} {:10.6} ± {:.6} (3σ)",
            kr270::PAPER_SYMBOLS[i],
            x[i],
            3.0 * sd[i]
        );
    }
    if check {
        let committed = std::fs::read_to_string(&out)?;
        if committed != s {
            return Err(format!("{} is stale: regenerate it", out.display()).into());
        }
        eprintln!("{} is up to date", out.display());
    } else {
        std::fs::write(&out, s)?;
        eprintln!("wrote {}", out.display());
    }
    Ok(())
}
