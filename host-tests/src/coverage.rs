//! Monte Carlo check of robcal's reported σ: many independent KR-270 jobs
//! from [`crate::exact`] (which shares no code with the estimator), each
//! calibrated by `robcal::calibrate` exactly as `robcal calibrate` would,
//! and the standardised errors `z = (x̂ − x) / σ̂` of every parameter
//! collected. An honest σ gives `z` with mean 0 and standard deviation 1,
//! and ±3σ covers 99.73 %.

use std::path::Path;

use robcal::calibrate::{self, Method, Settings};
use robcal::io::{parse_measurements, Job};
use robcal_paper::kr270;
use robcal_paper::rng::SplitMix64;

use crate::exact::Kr270;

/// Seed of job `i` (jobs of one cell differ only by it).
fn seed(i: usize) -> u64 {
    0x6b72_3237_305f_6d63 ^ (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
}

/// The outcome of one cell: a method at a noise level.
#[derive(Debug, Clone)]
pub struct Cell {
    /// The method.
    pub method: Method,
    /// Noise as a multiple of Table 1.
    pub noise: f64,
    /// `z` per parameter (in `kr270::PARAM_NAMES` order), one per job whose
    /// report has the declared model.
    pub z: Vec<Vec<f64>>,
    /// Jobs to which the diagnosis added an effect (with `diagnose`), and
    /// what it added.
    pub added: Vec<String>,
    /// Jobs run.
    pub jobs: usize,
}

/// Summary of one parameter's `z`.
#[derive(Debug, Clone, Copy)]
pub struct Summary {
    /// Share of `|z| ≤ 3`.
    pub coverage: f64,
    /// Mean of `z`.
    pub mean: f64,
    /// Standard deviation of `z`.
    pub std: f64,
}

fn summary(z: &[f64]) -> Summary {
    let n = z.len() as f64;
    let mean = z.iter().sum::<f64>() / n;
    let var = z.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    Summary {
        coverage: z.iter().filter(|v| v.abs() <= 3.0).count() as f64 / n,
        mean,
        std: var.sqrt(),
    }
}

impl Cell {
    /// Per parameter.
    pub fn parameters(&self) -> Vec<Summary> {
        self.z.iter().map(|z| summary(z)).collect()
    }

    /// Share of `|z| ≤ 3` over every parameter and job.
    pub fn coverage(&self) -> f64 {
        let all: Vec<f64> = self.z.iter().flatten().copied().collect();
        summary(&all).coverage
    }

    /// One line of a Markdown table: method, noise, coverage, worst mean z
    /// (parameter), std z range, jobs.
    pub fn row(&self) -> String {
        let p = self.parameters();
        let (worst, w) = p
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.mean.abs().total_cmp(&b.1.mean.abs()))
            .map(|(i, s)| (kr270::PARAM_NAMES[i], s.mean))
            .unwrap_or(("-", 0.0));
        let lo = p.iter().map(|s| s.std).fold(f64::INFINITY, f64::min);
        let hi = p.iter().map(|s| s.std).fold(0.0, f64::max);
        format!(
            "| {} | ×{} | {:.2} % | {w:+.3} ({worst}) | {lo:.3} – {hi:.3} | {} |",
            self.method.name(),
            self.noise,
            100.0 * self.coverage(),
            self.jobs
        )
    }
}

/// `f` of every job `0..jobs`, on as many threads as the machine has, in
/// job order.
pub fn in_parallel<T: Send>(jobs: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let f = &f;
                s.spawn(move || {
                    (t..jobs)
                        .step_by(threads)
                        .map(|i| (i, f(i)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        let mut all: Vec<_> = handles
            .into_iter()
            .flat_map(|h| h.join().expect("a job thread"))
            .collect();
        all.sort_by_key(|(i, _)| *i);
        all.into_iter().map(|(_, v)| v).collect()
    })
}

/// Runs `jobs` KR-270 jobs (seeds 0..jobs) at `noise` × Table 1 with
/// `method`, no held-out error, the diagnosis on or off; on as many threads
/// as the machine has.
///
/// # Panics
/// When a job fails (a calibration error is a finding of this check).
pub fn run(method: Method, noise: f64, jobs: usize, diagnose: bool) -> Cell {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let job = Job::load(root.join("data/kr270/setup.toml")).expect("setup");
    let model = Kr270::new();
    let settings = Settings {
        method,
        diagnose,
        heldout: false,
        ..Settings::default()
    };
    let one = |i: usize| {
        let text = model.csv(&mut SplitMix64::new(seed(i)), noise);
        let data = parse_measurements(text.as_bytes(), "mc.csv", &job.robot, &job.setup)
            .expect("the generated file reads");
        calibrate::calibrate(&job, &data, &settings, &mut |_| {})
            .unwrap_or_else(|e| panic!("job {i}: {e}"))
    };
    let reports: Vec<_> = in_parallel(jobs, one).into_iter().enumerate().collect();
    let truth = kr270::WLS_VALUE;
    let mut z = vec![Vec::new(); kr270::PARAMS];
    let mut added = Vec::new();
    for (i, r) in &reports {
        if !r.effects.is_empty() {
            let names: Vec<String> = r
                .effects
                .iter()
                .map(|e| {
                    format!(
                        "{}{}",
                        e.effect.name(),
                        e.joint
                            .as_deref()
                            .map(|j| format!(" on {j}"))
                            .unwrap_or_default()
                    )
                })
                .collect();
            added.push(format!("job {i}: {}", names.join(", ")));
            continue;
        }
        let names: Vec<&str> = r.parameters.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, kr270::PARAM_NAMES, "job {i}: the declared model");
        for (k, p) in r.parameters.iter().enumerate() {
            z[k].push((p.value - truth[k]) / p.std);
        }
    }
    Cell {
        method,
        noise,
        z,
        added,
        jobs,
    }
}
