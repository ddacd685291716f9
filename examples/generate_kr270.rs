//! Regenerates `data/kr270/measurements.csv`: the paper's KR-270 experiment
//! (section 5) reconstructed from what the paper publishes.
//!
//! ```sh
//! cargo run --release --example generate_kr270
//! ```
//!
//! - configurations: Table 2; loads 250–280 kg per configuration;
//! - true compliances: Table 3, WLS column (µrad/(N·m)); k1 = 0 (A1 is
//!   vertical: a hanging load puts no torque on it);
//! - deflections from the **exact** forward kinematics of the deflected pose,
//!   `p(q + δq) − p(q)` with `δqⱼ = kⱼ τⱼ` and `τ` the load's joint torques at
//!   `q` — not from the linear model (eq. 3);
//! - noise: Gaussian with σ per configuration and base axis from Table 1, in
//!   the deflection: the unloaded and the loaded position each get σ/√2;
//! - 6 repetitions × 3 markers, each measured unloaded and loaded.
//!
//! The random numbers come from SplitMix64 and Box–Muller written out in
//! `robcal_paper::rng`, so the file is the same bit for bit with any version
//! of any crate.

use std::path::Path;

use nalgebra::Vector3;
use robcal::io::{Job, Observation};
use robcal_paper::kr270;
use robcal_paper::rng::SplitMix64;

/// Seed of the data set.
const SEED: u64 = 0x4b52_3237_3020_2013; // "KR270" + the paper's year

/// True compliance [rad/(N·m)] of joints a1..a6 at configuration `c`.
fn true_compliance(c: usize) -> [f64; 6] {
    let q2 = kr270::CONFIGURATIONS_DEG[c][1];
    let group = kr270::q2_group(q2).expect("Table 2 q2 is one of the five groups");
    let v = kr270::WLS_VALUE;
    [0.0, v[group], v[5], v[6], v[7], v[8]].map(|k| k * 1e-6)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/kr270");
    let job = Job::load(dir.join("setup.toml"))?;
    let chain = &job.robot.chain;
    let load = job.setup.load.ok_or("setup.toml has no [load]")?;
    let com = Vector3::from(load.com);
    let gravity = Vector3::from(load.gravity);
    let mut rng = SplitMix64::new(SEED);
    let mut rows = Vec::new();
    for c in 0..kr270::CONFIGS {
        let q: Vec<f64> = kr270::CONFIGURATIONS_DEG[c]
            .iter()
            .map(|d| d.to_radians())
            .collect();
        // Load of this configuration, 250–280 kg, to 0.1 kg.
        let (lo, hi) = kr270::LOAD_KG_RANGE;
        let load_kg = ((lo + (hi - lo) * rng.uniform()) * 10.0).round() / 10.0;
        // Joint torques of the hanging load at the unloaded pose [N·m].
        let frames = chain.frames(&q)?;
        let force = gravity * load_kg;
        let at = frames.point_m(&com);
        let k = true_compliance(c);
        let q_loaded: Vec<f64> = frames
            .joints()
            .iter()
            .zip(&q)
            .zip(k)
            .map(|((jf, qj), kj)| {
                let tau = jf.axis.dot(&(at - jf.origin_m()).cross(&force));
                qj + kj * tau
            })
            .collect();
        let loaded = chain.frames(&q_loaded)?;
        let sigma_m = Vector3::from(kr270::SIGMA_UM[c]) * 1e-6;
        for rep in 1..=kr270::REPS {
            for marker in &job.setup.markers {
                let m = Vector3::from(marker.xyz);
                let p0 = frames.point_m(&m);
                let p1 = loaded.point_m(&m);
                for (mass, p) in [(0.0, p0), (load_kg, p1)] {
                    let noise = Vector3::from_fn(|a, _| rng.normal() * sigma_m[a] / 2f64.sqrt());
                    let p = p + noise;
                    rows.push(Observation {
                        config: c as i64 + 1,
                        rep: rep as i64,
                        marker: marker.id,
                        load_kg: mass,
                        q: q.clone(),
                        p_m: [p.x, p.y, p.z],
                        ..Observation::default()
                    });
                }
            }
        }
    }
    let out = dir.join("measurements.csv");
    job.write_measurements(&out, &rows)?;
    println!("wrote {} rows to {}", rows.len(), out.display());
    Ok(())
}
