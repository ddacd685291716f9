//! Regenerates `data/kr270/measurements.csv`: the paper's KR-270 experiment
//! (section 5) reconstructed from what the paper publishes.
//!
//! ```sh
//! cargo run --release -p host-tests --example generate_kr270
//! ```
//!
//! - configurations: Table 2; loads 250–280 kg per configuration;
//! - true compliances: Table 3, WLS column (µrad/(N·m)); k1 = 0 (A1 is
//!   vertical: a hanging load puts no torque on it);
//! - deflections of the robot **as it behaves**: the load acts on the
//!   deflected robot, the loaded pose is the equilibrium `θ = q + K τ(θ)`,
//!   the deflection `p(θ) − p(q)` from the forward kinematics — computed by
//!   `host_tests::exact`, which shares no code with robcal's kinematics or
//!   engine;
//! - noise: Gaussian with σ per configuration and base axis from Table 1, in
//!   the deflection: the unloaded and the loaded position each get σ/√2;
//! - 6 repetitions × 3 markers, each measured unloaded and loaded.
//!
//! The random numbers come from SplitMix64 and Box–Muller written out in
//! `robcal_paper::rng`, so the file is the same bit for bit with any version
//! of any crate.

use std::path::Path;

use host_tests::exact::Kr270;
use robcal_paper::rng::SplitMix64;

/// Seed of the data set.
const SEED: u64 = 0x4b52_3237_3020_2013; // "KR270" + the paper's year

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/kr270/measurements.csv");
    let text = Kr270::new().csv(&mut SplitMix64::new(SEED), 1.0);
    let rows = text.lines().count() - 1;
    robcal::io::write_atomic(&out, text.as_bytes())?;
    println!("wrote {rows} rows to {}", out.display());
    Ok(())
}
