//! The paper's KR-270 experiment end to end (Klimchik et al., section 5),
//! through the product: `robcal::calibrate` on the reconstructed data set
//! `data/kr270/` with OLS, one-step WLS (λ = 0.5, 1, 2) and iterative WLS,
//! printed next to the paper's Tables 3 and 4 and Figure 3; then the closed
//! loop on the naive model.
//!
//! ```sh
//! cargo run --release --example kr270 [-- --data DIR --out DIR]
//! ```
//!
//! `--data` (default `data/kr270`) holds `setup.toml`, `setup-naive.toml`
//! and `measurements.csv`; `--out` (default `target/kr270`) receives
//! `figure3.svg` and `ci_comparison.svg`.
//!
//! Every estimate and standard deviation printed comes from
//! `robcal::calibrate`. Two columns ask questions the product does not:
//! the Cramér–Rao bound (the best σ any weighting could give, with Table 1's
//! true σ) and the covariance formulas that could give the paper's σ ratios.
//! They are computed with robcal's core on the same rows
//! (`robcal_paper::kr270::layout`, `Layout::block`, `GroupedStats`), which
//! this script checks against the product's OLS estimate first.
//!
//! Units: compliance in µrad/(N·m) (the paper prints "rad/N×µm"; its values
//! only make sense as µrad/(N·m), see `robcal_paper::kr270`); σ of the
//! measurements in µm. "±" is ±3σ throughout, as in the paper.

use std::path::{Path, PathBuf};

use nalgebra::{Const, SVector, Vector3};
use plotters::prelude::*;
use robcal::calibrate::{self, DeflectionModel, Method, Report, Settings};
use robcal::estimate::std_devs;
use robcal::io::{Job, Measurements};
use robcal::model::Marker;
use robcal::robot::PointLoad;
use robcal::{GroupedStats, Reweightable};
use robcal_paper::kr270::{self, PAPER_SYMBOLS};

type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// Parameters of the paper's model.
const N: usize = kr270::PARAMS;
/// Configurations.
const G: usize = kr270::CONFIGS;
type Stats = GroupedStats<f64, Const<N>, G>;

struct Args {
    data: PathBuf,
    out: PathBuf,
}

fn args() -> Res<Args> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut a = Args {
        data: root.join("data/kr270"),
        out: root.join("target/kr270"),
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("{flag} needs a value"));
        match flag.as_str() {
            "--data" => a.data = PathBuf::from(value()?),
            "--out" => a.out = PathBuf::from(value()?),
            "-h" | "--help" => {
                println!("usage: kr270 [--data DIR] [--out DIR]");
                std::process::exit(0);
            }
            other => return Err(format!("unknown argument {other:?} (try --help)").into()),
        }
    }
    Ok(a)
}

/// The fits of Tables 3 and 4, all by `robcal::calibrate` on the declared
/// model (no diagnosis).
struct Fits {
    ols: Report,
    /// One-step WLS for λ = 0.5, 1, 2.
    wls: [Report; 3],
    irls: Report,
    /// OLS and iterative WLS with the paper's first-order model (eq. 3).
    ols_linear: Report,
    irls_linear: Report,
}

fn run(job: &Job, data: &Measurements, method: Method, lambda: Option<f64>) -> Res<Report> {
    run_model(job, data, method, lambda, DeflectionModel::Exact)
}

fn run_model(
    job: &Job,
    data: &Measurements,
    method: Method,
    lambda: Option<f64>,
    deflection_model: DeflectionModel,
) -> Res<Report> {
    let settings = Settings {
        method,
        lambda,
        diagnose: false,
        heldout: false,
        deflection_model,
        ..Settings::default()
    };
    Ok(calibrate::calibrate(job, data, &settings, &mut |_| {})?)
}

fn x(r: &Report) -> Vec<f64> {
    r.parameters.iter().map(|p| p.value).collect()
}

fn sd(r: &Report) -> Vec<f64> {
    r.parameters.iter().map(|p| p.std).collect()
}

fn main() -> Res<()> {
    let args = args()?;
    let job = Job::load(args.data.join("setup.toml"))?;
    let data = job.read_measurements(args.data.join("measurements.csv"))?;
    for w in &data.warnings {
        eprintln!("warning: {w}");
    }
    let names: Vec<&str> = kr270::PARAM_NAMES.to_vec();
    let fits = Fits {
        ols: run(&job, &data, Method::Ols, None)?,
        wls: [
            run(&job, &data, Method::Wls, Some(kr270::LAMBDAS[0]))?,
            run(&job, &data, Method::Wls, Some(kr270::LAMBDAS[1]))?,
            run(&job, &data, Method::Wls, Some(kr270::LAMBDAS[2]))?,
        ],
        irls: run(&job, &data, Method::Irls, None)?,
        ols_linear: run_model(&job, &data, Method::Ols, None, DeflectionModel::Linear)?,
        irls_linear: run_model(&job, &data, Method::Irls, None, DeflectionModel::Linear)?,
    };
    let got: Vec<&str> = fits
        .irls
        .parameters
        .iter()
        .map(|p| p.name.as_str())
        .collect();
    if got != names {
        return Err(format!("setup.toml declares {got:?}, not the paper's model").into());
    }
    let stats = core_rows(&job, &data)?;
    check_rows(&stats, &fits.ols_linear)?;

    println!("robcal: the KR-270 experiment of Klimchik et al. (section 5), reproduced");
    println!(
        "data: {} ({} deflections, {} equations, {} configurations); 9 parameters",
        args.data.display(),
        data.deflections.len(),
        3 * fits.irls.rows,
        fits.irls.configurations
    );
    println!(
        "robcal calibrate --setup {}/setup.toml --no-diagnose, --method ols | wls --lambda L | irls",
        args.data.display()
    );
    println!(
        "σ0 = {} µm; iterative WLS: λ = {}, tolerance 1e-3 σ, {} iterations, converged: {}",
        job.setup.noise.sigma0_um,
        job.setup.noise.lambda,
        fits.irls.iterations,
        fits.irls.converged
    );
    println!(
        "compliance in µrad/(N·m); ± is 3σ; truth = Table 3's WLS column (the generator's input)\n"
    );

    table3(&fits, &stats)?;
    let crb = cramer_rao(&stats)?;
    table4(&fits, &crb);
    formula_mix(&fits, &stats, job.setup.noise.sigma0_um * 1e-6, &crb)?;
    figure3(&fits.irls);
    exact_vs_linear(&fits);
    residual_sigma(&fits.irls);
    closed_loop(&args.data)?;

    std::fs::create_dir_all(&args.out)?;
    let f3 = args.out.join("figure3.svg");
    plot_figure3(&fits.irls, &f3)?;
    let ci = args.out.join("ci_comparison.svg");
    plot_ci(&fits, &crb, &ci)?;
    println!("\nwrote {} and {}", f3.display(), ci.display());
    Ok(())
}

/// The paper's rows with robcal's core: the 9-parameter layout
/// ([`kr270::layout`]) at the unloaded pose of every deflection (eq. 3),
/// grouped by configuration.
fn core_rows(job: &Job, data: &Measurements) -> Res<Stats> {
    let chain = &job.robot.chain;
    let layout = kr270::layout(chain)?;
    let load = job.setup.load.ok_or("the setup has no [load]")?;
    let mut stats = Stats::new();
    for d in &data.deflections {
        let m = job
            .setup
            .markers
            .iter()
            .position(|m| m.id == d.marker)
            .ok_or("unknown marker")?;
        let marker = Marker {
            index: u8::try_from(m)?,
            xyz_m: Vector3::from(job.setup.markers[m].xyz),
        };
        let pl = PointLoad {
            mass_kg: d.load_kg,
            com_m: Vector3::from(load.com),
            gravity_mps2: Vector3::from(load.gravity),
        };
        let b = layout.block::<f64, { robcal::io::MAX_JOINTS }, Const<N>>(
            chain,
            &d.q,
            &marker,
            Some(&pl),
        )?;
        stats.update(i32::try_from(d.config)?, &b, &Vector3::from(d.dp_m))?;
    }
    Ok(stats)
}

/// The core's OLS on [`core_rows`] (eq. 3 at the unloaded pose) must be
/// the product's OLS with `--linear`: the same rows.
fn check_rows(stats: &Stats, ols: &Report) -> Res<()> {
    let mut w = vec![Vector3::zeros(); stats.groups().len()];
    let mut s = w.clone();
    let mut dof = w.clone();
    let fit = stats.fit_ols(&[true; N], &mut w, &mut s, &mut dof)?;
    let dev = (0..N)
        .map(|i| (fit.solution.x[i] - ols.parameters[i].value).abs() / ols.parameters[i].std)
        .fold(0.0, f64::max);
    if dev > 1e-9 {
        return Err(format!("core rows and the product's differ: {dev:e} σ").into());
    }
    Ok(())
}

/// The exact deflection model (the default) against eq. 3 (`--linear`):
/// estimates and their distance from the truth in σ.
fn exact_vs_linear(f: &Fits) {
    println!(
        "Exact deflection model (default) vs the paper's eq. 3 (--linear), value and (x - truth)/σ"
    );
    println!(
        "{:<4} {:>7} | {:>8} {:>6} {:>8} {:>6} | {:>8} {:>6} {:>8} {:>6}",
        "k", "truth", "OLS ex.", "z", "OLS lin", "z", "IRLS ex", "z", "IRLS li", "z"
    );
    let t = kr270::WLS_VALUE;
    let z = |r: &Report, i: usize| (r.parameters[i].value - t[i]) / r.parameters[i].std;
    for i in 0..N {
        let v = |r: &Report| r.parameters[i].value;
        println!(
            "{:<4} {:>7.3} | {:>8.4} {:>6.2} {:>8.4} {:>6.2} | {:>8.4} {:>6.2} {:>8.4} {:>6.2}",
            PAPER_SYMBOLS[i],
            t[i],
            v(&f.ols),
            z(&f.ols, i),
            v(&f.ols_linear),
            z(&f.ols_linear, i),
            v(&f.irls),
            z(&f.irls, i),
            v(&f.irls_linear),
            z(&f.irls_linear, i),
        );
    }
    let rms = |r: &Report| r.rms_um;
    println!(
        "fit RMS [µm]: exact OLS {:.2}, linear OLS {:.2}; exact IRLS {:.2} ({} Gauss-Newton relinearisations), linear IRLS {:.2}\n",
        rms(&f.ols),
        rms(&f.ols_linear),
        rms(&f.irls),
        f.irls.relinearisations,
        rms(&f.irls_linear)
    );
}

fn pm(v: f64, ci: f64) -> String {
    format!("{v:.4}±{ci:<6.4}")
}

fn table3(f: &Fits, stats: &Stats) -> Res<()> {
    let (xo, so) = (x(&f.ols), sd(&f.ols));
    let (xi, si) = (x(&f.irls), sd(&f.irls));
    // Eq. 7 (i.i.d. noise of unknown σ) of the same OLS fit, for the
    // question which formula the paper's OLS ±3σ used.
    let ones = vec![Vector3::new(1.0, 1.0, 1.0); stats.groups().len()];
    let ols7 = std_devs(&stats.weighted(&ones, None)?.solve()?.cov_iid()) * 3.0;
    let t = kr270::WLS_VALUE;
    println!("Table 3. Identified compliances [µrad/(N·m)], value ± 3σ");
    println!(
        "{:<4} {:>7} | {:<16} {:<16} {:>9} | {:<16} {:<16}",
        "k", "truth", "paper OLS", "robcal OLS (8)", "(7) ±3σ", "paper WLS", "robcal iter.WLS"
    );
    for i in 0..N {
        println!(
            "{:<4} {:>7.3} | {:<16} {:<16} {:>9.4} | {:<16} {:<16}",
            PAPER_SYMBOLS[i],
            t[i],
            pm(kr270::OLS_VALUE[i], kr270::OLS_CI3[i]),
            pm(xo[i], 3.0 * so[i]),
            ols7[i],
            pm(kr270::WLS_VALUE[i], kr270::WLS_CI3[i]),
            pm(xi[i], 3.0 * si[i]),
        );
    }
    println!(
        "(OLS (8): sandwich with σ per configuration and axis; (7): i.i.d. σ̂² Λ⁻¹, robcal's core)"
    );
    println!("\nTable 3 (cont.). One-step WLS (eq. 10, weights eq. 14 from the OLS residuals), covariance (11)");
    println!(
        "{:<4} {:>7} | {:<16} {:<16} {:<16} | {:<16}",
        "k", "truth", "λ = 0.5", "λ = 1", "λ = 2", "paper (all λ)"
    );
    for i in 0..N {
        let w: Vec<String> = f
            .wls
            .iter()
            .map(|r| pm(r.parameters[i].value, 3.0 * r.parameters[i].std))
            .collect();
        println!(
            "{:<4} {:>7.3} | {:<16} {:<16} {:<16} | {:<16}",
            PAPER_SYMBOLS[i],
            t[i],
            w[0],
            w[1],
            w[2],
            pm(kr270::WLS_VALUE[i], kr270::WLS_CI3[i])
        );
    }
    println!();
    Ok(())
}

/// Table 1's true σ \[m\] of each group of `stats`.
fn true_sigma(stats: &Stats) -> Vec<Vector3<f64>> {
    stats
        .groups()
        .iter()
        .map(|g| Vector3::from(kr270::SIGMA_UM[(g.id - 1) as usize]) * 1e-6)
        .collect()
}

/// `√diag (Bᵀ Σ⁻² B)⁻¹` with Table 1's true σ: the Cramér–Rao bound.
fn cramer_rao(stats: &Stats) -> Res<SVector<f64, N>> {
    let w: Vec<Vector3<f64>> = true_sigma(stats)
        .iter()
        .map(|s| s.map(|v| 1.0 / v))
        .collect();
    let sol = stats.weighted(&w, None)?.solve()?;
    Ok(std_devs(&sol.cov_information()))
}

fn table4(f: &Fits, crb: &SVector<f64, N>) {
    let (xo, so) = (x(&f.ols), sd(&f.ols));
    let (xi, si) = (x(&f.irls), sd(&f.irls));
    let s1 = sd(&f.wls[1]);
    println!("Table 4. Benefits of WLS: CI = 3σ as % of the value; σ_OLS / σ_WLS");
    println!(
        "{:<4} | {:>7} {:>7} | {:>7} {:>7} | {:>7} {:>7} {:>9} | {:>7} {:>9}",
        "k", "CI_OLS", "paper", "CI_WLS", "paper", "ratio", "paper", "1-step λ1", "CRB", "σOLS/CRB"
    );
    for i in 0..N {
        println!(
            "{:<4} | {:>6.2}% {:>6.1}% | {:>6.2}% {:>6.2}% | {:>7.2} {:>7.1} {:>9.2} | {:>7.4} {:>9.2}",
            PAPER_SYMBOLS[i],
            300.0 * so[i] / xo[i],
            kr270::CI_OLS_PERCENT[i],
            300.0 * si[i] / xi[i],
            kr270::CI_WLS_PERCENT[i],
            so[i] / si[i],
            kr270::SIGMA_RATIO[i],
            so[i] / s1[i],
            crb[i],
            so[i] / crb[i],
        );
    }
    println!(
        "(ratio: σ_OLS (8) / σ_iterative WLS (11); 1-step λ1: over one-step WLS λ = 1; \
         CRB: σ of (Bᵀ Σ⁻² B)⁻¹ with Table 1's true σ, the best any weighting can do;\n \
         Kantorovich bound on σ_OLS/σ_best for σ max/min = 153/17: (1 + 9²)/(2·9) = {:.2})\n",
        (1.0 + 81.0) / 18.0
    );
}

/// Which covariance formulas reproduce the paper's σ_OLS/σ_WLS = 27–42?
/// Each alternative formula evaluated with robcal's core on the weights the
/// product used.
fn formula_mix(f: &Fits, stats: &Stats, sigma0_m: f64, crb: &SVector<f64, N>) -> Res<()> {
    let so = sd(&f.ols);
    let weights = |r: &Report| -> Vec<Vector3<f64>> {
        r.noise.iter().map(|n| Vector3::from(n.weight)).collect()
    };
    // (13) read literally with the dimensionless weights of eq. 14 and Δp
    // in µm: (Bᵀ W² B)⁻¹ with B in µm per µrad/(N·m) = 1e-12 × Λ⁻¹ (B in m).
    let lit = |r: &Report| -> Res<SVector<f64, N>> {
        let sol = stats.weighted(&weights(r), None)?.solve()?;
        Ok(std_devs(&sol.cov_information()) * 1e-6)
    };
    // (12) + (13): w = a/σ̂ with a = σ0 (σ̂ of the final fit), (Bᵀ W² B)⁻¹, µm.
    let w12: Vec<Vector3<f64>> = f
        .irls
        .noise
        .iter()
        .map(|n| Vector3::from(n.sigma_um).map(|v| sigma0_m / (v * 1e-6)))
        .collect();
    let s12 = std_devs(&stats.weighted(&w12, None)?.solve()?.cov_information()) * 1e-6;
    let it = lit(&f.irls)?;
    let l = [lit(&f.wls[0])?, lit(&f.wls[1])?, lit(&f.wls[2])?];
    let si = sd(&f.irls);
    println!("Table 4, what could give the paper's 27–42: σ_OLS (8) divided by σ_WLS from");
    println!(
        "{:<4} | {:>7} | {:>9} {:>9} {:>9} {:>9} | {:>9} | {:>13}",
        "k", "paper", "A: (11)", "B: λ=0.5", "B: λ=1", "B: λ=2", "C: a=σ0", "paper WLS/CRB"
    );
    for i in 0..N {
        println!(
            "{:<4} | {:>7.1} | {:>9.2} {:>9.2} {:>9.2} {:>9.2} | {:>9.2} | {:>13.2}",
            PAPER_SYMBOLS[i],
            kr270::SIGMA_RATIO[i],
            so[i] / si[i],
            so[i] / l[0][i],
            so[i] / l[1][i],
            so[i] / l[2][i],
            so[i] / s12[i],
            kr270::WLS_CI3[i] / (3.0 * crb[i]),
        );
    }
    println!(
        "(A: the sandwich (11) of iterative WLS, the honest σ. B: (13) read as (Bᵀ W² B)⁻¹ with \
         eq. 14's dimensionless weights\n of one-step WLS and Δp in µm (iterative λ = 1: {}). \
         C: (13) with eq. 12's weights w = σ0/σ̂, Δp in µm: = σ0[µm] × CRB-like σ, λ-free.\n \
         paper WLS/CRB: the paper's WLS ±3σ over 3σ of the Cramér–Rao bound of this design — below 1 is impossible for an honest σ)\n",
        (0..N)
            .map(|i| format!("{:.1}", so[i] / it[i]))
            .collect::<Vec<_>>()
            .join(" ")
    );
    Ok(())
}

fn figure3(irls: &Report) {
    println!("Figure 3. Iterative WLS: k21 and its CI per iteration (0 = OLS)");
    println!(
        "{:>4} | {:>9} {:>9} {:>7} | {:>12}",
        "iter", "k21", "±3σ", "CI %", "max |Δx|/σ"
    );
    for (k, h) in irls.history.iter().enumerate() {
        println!(
            "{:>4} | {:>9.5} {:>9.5} {:>6.3}% | {:>12.2e}",
            k,
            h.x[0],
            3.0 * h.std[0],
            300.0 * h.std[0] / h.x[0],
            h.change
        );
    }
    let (first, last) = (&irls.history[0], &irls.history[irls.history.len() - 1]);
    println!(
        "(paper, Fig. 3: k21 moves 3.3 % from OLS, its CI shrinks by 40, stable after 10 iterations; \
         here it moves {:.1} % and the CI shrinks by {:.2})\n",
        100.0 * (last.x[0] - first.x[0]) / first.x[0],
        first.std[0] / last.std[0]
    );
}

fn residual_sigma(irls: &Report) {
    println!(
        "Residual σ per configuration and axis [µm]: iterative WLS estimate vs Table 1 (truth)"
    );
    println!(
        "{:>5} | {:>17} | {:>17}",
        "conf", "robcal x  y  z", "Table 1 x  y  z"
    );
    for n in &irls.noise {
        let t = kr270::SIGMA_UM[(n.config - 1) as usize];
        println!(
            "{:>5} | {:>5.0} {:>5.0} {:>5.0} | {:>5.0} {:>5.0} {:>5.0}",
            n.config, n.sigma_um[0], n.sigma_um[1], n.sigma_um[2], t[0], t[1], t[2]
        );
    }
    println!();
}

fn plot_figure3(irls: &Report, path: &Path) -> Res<()> {
    let root = SVGBackend::new(path, (1000, 420)).into_drawing_area();
    root.fill(&WHITE)?;
    let (a, b) = root.split_horizontally(500);
    let n = irls.history.len();
    let xs: Vec<(f64, f64, f64)> = irls
        .history
        .iter()
        .enumerate()
        .map(|(k, h)| (k as f64, h.x[0], 3.0 * h.std[0]))
        .collect();
    let lo = xs.iter().map(|v| v.1 - v.2).fold(f64::INFINITY, f64::min);
    let hi = xs
        .iter()
        .map(|v| v.1 + v.2)
        .fold(f64::NEG_INFINITY, f64::max);
    let pad = 0.05 * (hi - lo);
    let mut c = ChartBuilder::on(&a)
        .caption("(a) compliance k21 ± 3σ", ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d(-0.5..(n as f64 - 0.5), (lo - pad)..(hi + pad))?;
    c.configure_mesh()
        .x_desc("iteration (0 = OLS)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_desc("k21 [µrad/(N·m)]")
        .draw()?;
    c.draw_series(
        xs.iter()
            .map(|&(k, v, e)| PathElement::new(vec![(k, v - e), (k, v + e)], BLUE.stroke_width(1))),
    )?;
    c.draw_series(LineSeries::new(xs.iter().map(|&(k, v, _)| (k, v)), BLUE))?;
    c.draw_series(
        xs.iter()
            .map(|&(k, v, _)| Circle::new((k, v), 3, BLUE.filled())),
    )?;
    let t = kr270::WLS_VALUE[0];
    c.draw_series(LineSeries::new(
        [(-0.5, t), (n as f64 - 0.5, t)],
        RGBColor(213, 94, 0).stroke_width(1),
    ))?
    .label("truth (Table 3 WLS)")
    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(213, 94, 0)));
    c.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE)
        .border_style(BLACK)
        .draw()?;

    let ci: Vec<(f64, f64)> = xs.iter().map(|&(k, v, e)| (k, 100.0 * e / v)).collect();
    let top = ci.iter().map(|v| v.1).fold(0.0, f64::max) * 1.1;
    let mut c = ChartBuilder::on(&b)
        .caption("(b) CI of k21 (3σ, % of value)", ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d(-0.5..(n as f64 - 0.5), 0.0..top)?;
    c.configure_mesh()
        .x_desc("iteration (0 = OLS)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_desc("CI [%]")
        .draw()?;
    c.draw_series(LineSeries::new(ci.iter().copied(), BLUE))?;
    c.draw_series(ci.iter().map(|&p| Circle::new(p, 3, BLUE.filled())))?;
    root.present()?;
    Ok(())
}

fn plot_ci(f: &Fits, crb: &SVector<f64, N>, path: &Path) -> Res<()> {
    let root = SVGBackend::new(path, (900, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let pct = |r: &Report| -> Vec<f64> {
        r.parameters
            .iter()
            .map(|p| 300.0 * p.std / p.value)
            .collect()
    };
    let t = kr270::WLS_VALUE;
    let series: [(&str, Vec<f64>, RGBColor); 6] = [
        (
            "paper OLS",
            kr270::CI_OLS_PERCENT.to_vec(),
            RGBColor(230, 159, 0),
        ),
        (
            "paper WLS",
            kr270::CI_WLS_PERCENT.to_vec(),
            RGBColor(86, 180, 233),
        ),
        // Okabe–Ito: distinguishable with every common colour-vision
        // deficiency (no red/green pair).
        ("robcal OLS (8)", pct(&f.ols), RGBColor(213, 94, 0)),
        ("robcal WLS λ=1 (11)", pct(&f.wls[1]), RGBColor(0, 158, 115)),
        (
            "robcal iterative WLS (11)",
            pct(&f.irls),
            RGBColor(0, 114, 178),
        ),
        (
            "Cramér–Rao (true Σ)",
            (0..N).map(|i| 300.0 * crb[i] / t[i]).collect(),
            BLACK,
        ),
    ];
    let mut c = ChartBuilder::on(&root)
        .caption(
            "Confidence intervals (±3σ) as % of the value",
            ("sans-serif", 20),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d(-0.5f64..8.5, (0.05f64..50.0).log_scale())?;
    c.configure_mesh()
        .x_labels(N)
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && (0.0..9.0).contains(&i) {
                PAPER_SYMBOLS[i as usize].to_string()
            } else {
                String::new()
            }
        })
        .y_desc("CI [% of value]")
        .draw()?;
    for (k, (name, v, color)) in series.iter().enumerate() {
        let dx = (k as f64 - 2.5) * 0.08;
        let pts: Vec<(f64, f64)> = v
            .iter()
            .enumerate()
            .map(|(i, y)| (i as f64 + dx, *y))
            .collect();
        let col = *color;
        c.draw_series(pts.iter().map(|&p| Circle::new(p, 4, col.filled())))?
            .label(*name)
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, col.filled()));
    }
    c.configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// The closed loop on the same data: declare the naive model (one constant
/// compliance for A2) and let the diagnosis find what the residuals follow.
/// This is `robcal calibrate --setup data/kr270/setup-naive.toml --data
/// data/kr270/measurements.csv`.
fn closed_loop(data_dir: &Path) -> Res<()> {
    println!("\n== Closed loop: the naive model (constant k2) and the diagnosis");
    println!("   (robcal calibrate --setup data/kr270/setup-naive.toml --data data/kr270/measurements.csv)\n");
    let job = Job::load(data_dir.join("setup-naive.toml"))?;
    let data = job.read_measurements(data_dir.join("measurements.csv"))?;
    let report = calibrate::calibrate(&job, &data, &Settings::default(), &mut |_| {})?;
    println!("{report}");
    Ok(())
}
