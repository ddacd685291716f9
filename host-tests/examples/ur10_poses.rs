//! Writes the UR10 of `shared/repro/ur10-offsets` measured at N random
//! poses (`host_tests::arms::ur10_csv_within`: the repro's tracker frame,
//! offsets and noise), every joint within ±RANGE rad of its zero (default
//! π), for the timing of many configurations in BENCHMARKS.md and the
//! near-dependence of poses in a small range in docs/numerics.md.
//!
//! ```sh
//! cargo run --release -p host-tests --example ur10_poses -- 10000 /tmp/ur10-10000.csv
//! cargo run --release -p host-tests --example ur10_poses -- 60 /tmp/ur10-narrow.csv 0.1 7
//! ```

use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(n), Some(out)) = (args.get(1), args.get(2)) else {
        eprintln!("usage: ur10_poses N OUT.csv [RANGE_RAD [SEED]]");
        std::process::exit(2);
    };
    let n: usize = n.parse().expect("N: a number of poses");
    let range: f64 = args.get(3).map_or(std::f64::consts::PI, |r| {
        r.parse().expect("RANGE_RAD: a number")
    });
    let seed: u64 = args
        .get(4)
        .map_or(0x5552_3130, |s| s.parse().expect("SEED: an integer"));
    let urdf =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/repro/ur10-offsets/ur10.urdf");
    let csv = host_tests::arms::ur10_csv_within(&urdf, n, seed, range);
    std::fs::write(out, csv).expect("write the CSV");
}
