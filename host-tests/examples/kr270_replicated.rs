//! Writes the KR-270 experiment of `data/kr270/measurements.csv` with its
//! 15 configurations replicated: COPIES copies, each with fresh noise and
//! loads (the generator's random stream continued), configuration `c` of
//! copy `k` numbered `15 k + c`. For the timing of the CLI as the number of
//! configurations grows (BENCHMARKS.md, "The CLI as configurations grow").
//!
//! ```sh
//! cargo run --release -p host-tests --example kr270_replicated -- 16 /tmp/kr270-240.csv
//! ```
//!
//! Copy 0 with the default seed is `data/kr270/measurements.csv` itself.

use host_tests::exact::Kr270;
use robcal_paper::rng::SplitMix64;

/// The seed of `generate_kr270` (the bundled file is copy 0).
const SEED: u64 = 0x4b52_3237_3020_2013;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(copies), Some(out)) = (args.get(1), args.get(2)) else {
        eprintln!("usage: kr270_replicated COPIES OUT.csv [SEED]");
        std::process::exit(2);
    };
    let copies: usize = copies.parse().expect("COPIES: a number");
    let seed: u64 = args
        .get(3)
        .map_or(SEED, |s| s.parse().expect("SEED: an integer"));
    let kr = Kr270::new();
    let mut rng = SplitMix64::new(seed);
    let configs = robcal_paper::kr270::CONFIGS;
    let mut text = String::new();
    for k in 0..copies {
        let one = kr.csv(&mut rng, 1.0);
        let mut lines = one.lines();
        let header = lines.next().expect("a header");
        if k == 0 {
            text.push_str(header);
            text.push('\n');
        }
        for line in lines {
            let (config, rest) = line.split_once(',').expect("config first");
            let c: usize = config.parse().expect("a configuration number");
            text.push_str(&format!("{},{rest}\n", c + k * configs));
        }
    }
    std::fs::write(out, text).expect("write the CSV");
}
