//! The Monte Carlo coverage table of `docs/numerics.md`: robcal's ±3σ on
//! independent KR-270 jobs (`host_tests::coverage`).
//!
//! ```sh
//! cargo run --release -p host-tests --example coverage             # 1,000 jobs per cell
//! cargo run --release -p host-tests --example coverage -- 200 ols 1 # jobs, methods, noise
//! ```
//!
//! Arguments: jobs per cell (1000), methods (`ols,wls,irls`), noise factors
//! (`0.1,1,3`).

use host_tests::coverage::run;
use robcal::calibrate::Method;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let jobs = args.first().map_or(1000, |s| s.parse().expect("jobs"));
    let methods: Vec<Method> = args
        .get(1)
        .map_or("ols,wls,irls", |s| s.as_str())
        .split(',')
        .map(|m| match m {
            "ols" => Method::Ols,
            "wls" => Method::Wls,
            "irls" => Method::Irls,
            other => panic!("unknown method {other}"),
        })
        .collect();
    let noise: Vec<f64> = args
        .get(2)
        .map_or("0.1,1,3", |s| s.as_str())
        .split(',')
        .map(|v| v.parse().expect("noise factor"))
        .collect();
    println!("| method | noise × Table 1 | ±3σ coverage | worst mean z (parameter) | std z, all parameters | jobs |");
    println!("|---|---|---|---|---|---|");
    let start = std::time::Instant::now();
    for &m in &methods {
        for &n in &noise {
            println!("{}", run(m, n, jobs, false).row());
        }
    }
    eprintln!("{:.1} s", start.elapsed().as_secs_f64());
}
