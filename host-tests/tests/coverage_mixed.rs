//! Are robcal's σ true when a file's rows are of both kinds? The KR-270
//! experiment of `host_tests::exact` (no code shared with the estimator)
//! calibrated with the joints' offsets declared too: each unloaded point is
//! then an absolute row (its offsets) and, with its loaded point, a
//! deflection (the compliances). A deflection is the difference of two
//! points and has `√2` times their σ; one σ per configuration and axis for
//! both kinds (eq. 14) made the compliances' intervals too narrow and the
//! offsets' too wide (standard deviation of z 1.2 and 0.8; 95 % intervals
//! covering 89 % and 98 % in an outside Monte Carlo), until the design put
//! the deflections on a point's σ (`Rows::noise_scale`).
//!
//! For OLS and IRLS, 400 jobs each at Table 1's noise: every parameter's z
//! has a mean within ±0.2 and a standard deviation within 0.88–1.12 (3.5
//! standard errors at 400 jobs), and the 95 % intervals of each class
//! cover 95 % ± 3 binomial standard errors of 400 jobs.

use std::path::Path;

use robcal::calibrate::{self, Method, Settings};
use robcal::io::{parse_measurements, GeometryModel, Job};
use robcal_paper::kr270;
use robcal_paper::rng::SplitMix64;

use host_tests::coverage::in_parallel;
use host_tests::exact::Kr270;

const JOBS: usize = 400;

fn seed(i: usize) -> u64 {
    0x6d69_7865_645f_6b69 ^ (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
}

/// `data/kr270/setup.toml` with the joints' offsets declared, its robot
/// without the links' masses: the generator's unloaded robot does not sag
/// under its own weight, and robcal's absolute rows would.
fn job(method: Method) -> Job {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/kr270");
    // (One directory per test: the tests run at once.)
    let dir = std::env::temp_dir().join(format!(
        "robcal-coverage-mixed-{}-{}",
        std::process::id(),
        method.name()
    ));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let setup = std::fs::read_to_string(data.join("setup.toml")).expect("setup");
    let setup = setup.replace("geometry = \"none\"", "geometry = \"joint_offsets\"");
    let mut urdf = std::fs::read_to_string(data.join("kr270.urdf")).expect("urdf");
    while let (Some(a), Some(b)) = (urdf.find("<inertial>"), urdf.find("</inertial>")) {
        urdf.replace_range(a..b + "</inertial>".len(), "");
    }
    std::fs::write(dir.join("setup.toml"), setup).expect("write");
    std::fs::write(dir.join("kr270.urdf"), urdf).expect("write");
    let job = Job::load(dir.join("setup.toml")).expect("the setup reads");
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(job.setup.model.geometry, GeometryModel::JointOffsets);
    job
}

/// `z` of every reported parameter by name, over `JOBS` jobs.
fn run(method: Method) -> Vec<(String, Vec<f64>)> {
    let job = job(method);
    let model = Kr270::new();
    let settings = Settings {
        method,
        diagnose: false,
        heldout: false,
        ..Settings::default()
    };
    let one = |i: usize| {
        let text = model.csv(&mut SplitMix64::new(seed(i)), 1.0);
        let data = parse_measurements(text.as_bytes(), "mixed.csv", &job.robot, &job.setup)
            .expect("the generated file reads");
        calibrate::calibrate(&job, &data, &settings, &mut |_| {})
            .unwrap_or_else(|e| panic!("job {i}: {e}"))
    };
    let reports: Vec<_> = in_parallel(JOBS, one);
    // The truth: Table 3's compliances [µrad/(N·m)], offsets of 0.
    let truth = |name: &str| match kr270::PARAM_NAMES.iter().position(|n| *n == name) {
        Some(k) => Some(kr270::WLS_VALUE[k]),
        None => name.ends_with(".offset").then_some(0.0),
    };
    let mut z: Vec<(String, Vec<f64>)> = Vec::new();
    for r in &reports {
        for p in &r.parameters {
            let t = truth(&p.name).unwrap_or_else(|| panic!("{}: not declared", p.name));
            match z.iter_mut().find(|(n, _)| *n == p.name) {
                Some((_, v)) => v.push((p.value - t) / p.std),
                None => z.push((p.name.clone(), vec![(p.value - t) / p.std])),
            }
        }
    }
    z
}

fn check(method: Method) {
    let z = run(method);
    let mut table = String::new();
    let mut fails = Vec::new();
    let (mut inside, mut all) = ([0usize; 2], [0usize; 2]);
    for (name, v) in &z {
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let std = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let class = usize::from(name.ends_with(".offset"));
        inside[class] += v.iter().filter(|x| x.abs() <= 1.959_964).count();
        all[class] += v.len();
        table += &format!(
            "{name:<16} jobs {:>3}  mean z {mean:+.3}  std z {std:.3}\n",
            v.len()
        );
        if v.len() != JOBS || mean.abs() > 0.2 || !(0.88..=1.12).contains(&std) {
            fails.push(name.clone());
        }
    }
    for (class, what) in ["compliances", "offsets"].iter().enumerate() {
        let cover = inside[class] as f64 / all[class] as f64;
        // (The parameters of one job are correlated: the jobs count.)
        let se = (0.95 * 0.05 / JOBS as f64).sqrt();
        table += &format!("{what}: 95 % intervals cover {:.1} %\n", 100.0 * cover);
        if all[class] == 0 || (cover - 0.95).abs() > 3.0 * se {
            fails.push((*what).to_string());
        }
    }
    println!("{}\n{table}", method.name());
    assert!(fails.is_empty(), "{fails:?}\n{table}");
}

#[test]
fn ols_intervals_cover_rows_of_both_kinds() {
    check(Method::Ols);
}

#[test]
fn irls_intervals_cover_rows_of_both_kinds() {
    check(Method::Irls);
}
