//! `robcal plan`: the configurations to measure, chosen before measuring
//! (`robcal::calibrate::plan`).

use std::fmt::Write as _;
use std::path::PathBuf;

use clap::ValueEnum;
use robcal::calibrate::plan::{self, Criterion, PlanSettings, Scores};
use robcal::io::Job;

/// `--criterion`.
#[derive(Clone, Copy, ValueEnum)]
pub enum CriterionArg {
    /// ln det of the information (D-optimal).
    D,
    /// Minus the trace of its inverse (A-optimal).
    A,
    /// Minus the mean variance of the calibrated model's prediction over
    /// the candidates (I-optimal: the predicted error after calibration).
    I,
    /// Its smallest eigenvalue (E-optimal).
    E,
    /// Minus the condition number of the weighted design.
    Condition,
}

/// `robcal plan`.
#[derive(clap::Args)]
pub struct PlanArgs {
    /// The setup: robot, markers, load, the instrument's sigma (sigma0_um)
    /// and the declared model to plan for.
    #[arg(long)]
    setup: PathBuf,
    /// Configurations to choose.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=100_000))]
    poses: u64,
    /// Random candidates to choose from, within the joint limits.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..=plan::MAX_CANDIDATES as u64))]
    candidates: u64,
    /// Candidates of your own instead (the points CSV of `robcal predict`:
    /// `<joint>_rad`/`<joint>_m`, optional `load_kg` with `com_*_m`;
    /// `marker`, `id` and the centre of mass ignored: the setup's is
    /// planned for).
    #[arg(long, conflicts_with = "candidates")]
    pool: Option<PathBuf>,
    /// What to maximise.
    #[arg(long, value_enum, default_value_t = CriterionArg::D)]
    criterion: CriterionArg,
    /// A payload mass [kg] a random candidate may carry (repeat for
    /// several; 0 is unloaded). A model with compliances needs one above 0.
    #[arg(long = "load-kg", value_parser = mass, allow_negative_numbers = true)]
    load_kg: Vec<f64>,
    /// A joint range tighter than the URDF's, NAME=LO:HI [rad, or m for a
    /// prismatic joint] (repeat for several).
    #[arg(long, value_parser = limit, allow_hyphen_values = true)]
    limit: Vec<(String, f64, f64)>,
    /// Seed of the random candidates.
    #[arg(long, default_value_t = 0x706c_616e)]
    seed: u64,
    /// Exchange passes at most after the greedy choice (0: greedy only).
    #[arg(long = "exchange-passes", default_value_t = 10, value_parser = clap::value_parser!(u64).range(0..=100))]
    exchange_passes: u64,
    /// A 6-D instrument (a tracker's 6-D probe, a motion-capture body):
    /// each candidate measured as a pose, its orientation's sigma per axis
    /// [urad] (the points' is the setup's sigma0_um).
    #[arg(long = "orientation-urad", value_parser = positive)]
    orientation_urad: Option<f64>,
    /// Write the chosen configurations here (the points CSV: id, load_kg,
    /// the setup's payload centre of mass, one column per joint in rad or
    /// m; all or nothing).
    #[arg(long)]
    output: PathBuf,
    /// The plan's report as JSON on stdout.
    #[arg(long)]
    json: bool,
}

/// Parses a σ: a finite number above 0.
fn positive(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("{s}: a number above 0")),
    }
}

/// Parses a payload mass \[kg\]: from 0 to the measurement reader's
/// bound.
fn mass(s: &str) -> Result<f64, String> {
    let m: f64 = s.trim().parse().map_err(|_| format!("{s}: not a number"))?;
    let max = robcal::io::units::MAX_LOAD_KG;
    if !(m.is_finite() && (0.0..=max).contains(&m)) {
        return Err(format!("{s}: a mass from 0 to {max} kg"));
    }
    Ok(m)
}

/// Parses `NAME=LO:HI`.
fn limit(s: &str) -> Result<(String, f64, f64), String> {
    let bad = || format!("--limit {s}: expected NAME=LO:HI (rad, or m)");
    let (name, range) = s.split_once('=').ok_or_else(bad)?;
    let (lo, hi) = range.split_once(':').ok_or_else(bad)?;
    let lo: f64 = lo.trim().parse().map_err(|_| bad())?;
    let hi: f64 = hi.trim().parse().map_err(|_| bad())?;
    if !lo.is_finite() || !hi.is_finite() {
        return Err(bad());
    }
    Ok((name.trim().to_string(), lo, hi))
}

/// The scores as JSON.
fn scores_json(s: &Scores) -> serde_json::Value {
    let num = |v: f64| {
        if v.is_finite() {
            serde_json::json!(v)
        } else {
            serde_json::Value::Null
        }
    };
    serde_json::json!({
        "log_det": num(s.log_det),
        "trace_scaled": num(s.trace),
        "min_eigenvalue_scaled": num(s.min_eigen),
        "condition": num(s.condition),
        "predicted_rms_um": num(s.predicted_um),
    })
}

/// `robcal plan`.
pub fn run_plan(a: &PlanArgs) -> Result<(), String> {
    let job = Job::load(&a.setup).map_err(|e| e.to_string())?;
    let settings = PlanSettings {
        poses: a.poses as usize,
        candidates: a.candidates as usize,
        criterion: match a.criterion {
            CriterionArg::D => Criterion::D,
            CriterionArg::A => Criterion::A,
            CriterionArg::I => Criterion::I,
            CriterionArg::E => Criterion::E,
            CriterionArg::Condition => Criterion::Condition,
        },
        seed: a.seed,
        loads_kg: a.load_kg.clone(),
        limits: a.limit.clone(),
        exchange_passes: a.exchange_passes as usize,
        orientation_sigma_urad: a.orientation_urad,
    };
    let pool_candidates = match &a.pool {
        None => None,
        Some(path) => Some(plan::read_pool(&job, path).map_err(|e| e.to_string())?),
    };
    let policy = robcal::calibrate::Policy::default();
    let (pool, planned, baseline) =
        plan::make(&job, &settings, pool_candidates, &policy).map_err(|e| e.to_string())?;
    let csv = plan::points_csv(&job, &pool, &planned.chosen);
    robcal::io::write_all_atomic(
        &[(a.output.clone(), csv.into_bytes())],
        &[a.setup.as_path()],
    )
    .map_err(|e| robcal::io::atomic::about(&a.output, &e))?;

    let s = &planned.scores;
    if a.json {
        let params: Vec<serde_json::Value> = (pool.params.iter().enumerate())
            .map(|(k, name)| {
                let sd = |sc: &Scores| {
                    let v = sc.std[k];
                    if v.is_finite() {
                        serde_json::json!(v)
                    } else {
                        serde_json::Value::Null
                    }
                };
                serde_json::json!({
                    "name": name,
                    "unit": pool.units[k],
                    "std": sd(s),
                    "std_random": baseline.as_ref().map(sd),
                })
            })
            .collect();
        let v = serde_json::json!({
            "criterion": planned.criterion.name(),
            "candidates": pool.candidates.len(),
            "poses": planned.chosen.len(),
            "exchanges": planned.exchanges,
            "output": a.output.display().to_string(),
            "parameters": params,
            "left_out": pool.left_out,
            "plan": scores_json(s),
            "random": baseline.as_ref().map(scores_json),
            "notes": pool.notes,
        });
        println!(
            "{}",
            serde_json::to_string_pretty(&v).map_err(|e| e.to_string())?
        );
        return Ok(());
    }
    let mut t = format!(
        "plan: {} of {} candidates by criterion {} ({} exchanges), written to {}\n",
        planned.chosen.len(),
        pool.candidates.len(),
        planned.criterion.name(),
        planned.exchanges,
        a.output.display()
    );
    let row = |t: &mut String, label: &str, s: &Scores| {
        let _ = writeln!(
            t,
            "  {label:<22} ln det {:>10.3}  trace {:>11.4e}  condition {:>10.1}  predicted error {:>9.2} um",
            s.log_det, s.trace, s.condition, s.predicted_um
        );
    };
    row(&mut t, "planned", s);
    if let Some(b) = &baseline {
        row(&mut t, &format!("{} random", planned.chosen.len()), b);
    }
    let w = pool
        .params
        .iter()
        .map(|p| p.chars().count())
        .max()
        .unwrap_or(0)
        .max(12);
    let _ = writeln!(
        t,
        "\n  {:<w$} {:>12} {:>12}  unit   (predicted 1 sd)",
        "parameter",
        "planned",
        if baseline.is_some() { "random" } else { "" }
    );
    for (k, name) in pool.params.iter().enumerate() {
        let _ = write!(t, "  {name:<w$} {:>12.4e}", s.std[k]);
        if let Some(b) = &baseline {
            let _ = write!(t, " {:>12.4e}", b.std[k]);
        } else {
            let _ = write!(t, " {:>12}", "");
        }
        let _ = writeln!(t, "  {}", pool.units[k]);
    }
    if !pool.left_out.is_empty() {
        let _ = writeln!(
            t,
            "\n  not identifiable from any of these candidates (left out): {}",
            pool.left_out.join(", ")
        );
    }
    for n in &pool.notes {
        let _ = writeln!(t, "  note: {n}");
    }
    print!("{t}");
    Ok(())
}
