//! `robcal`: calibration jobs from the command line (data contract §4).
//!
//! ```text
//! robcal calibrate --setup S.toml --data D.csv
//!                  [--method irls|wls|ols] [--lambda L] [--max-iter N]
//!                  [--no-diagnose] [--validate V.csv] [--plots DIR] [--json]
//! robcal import figaroh-mocap IN.csv OUT.csv
//! robcal import poses IN.csv OUT.csv [--split NAME]
//! robcal predict --model DIR/model.json --poses P.csv [--output OUT.csv]
//! robcal compensate --model DIR/model.json --targets T.csv [--output OUT.csv]
//! robcal init --urdf R.urdf [--base B] [--tip T] [--output SETUP.toml]
//! ```
//!
//! Exit status 0 on success; otherwise one line on stderr saying why, and
//! nothing written (files are written to a temporary name and renamed).

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressDrawTarget, ProgressStyle};

use robcal::calibrate::{self, DeflectionModel, Method, Settings};
use robcal::io::Job;
use robcal::render::files;
use robcal::render::html::JobInfo;

mod apply;
mod plan;

#[derive(Parser)]
#[command(
    name = "robcal",
    version,
    about = "Calibrate robot manipulators from tracker measurements"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Print no progress on stderr (errors still are; calibrate's warnings
    /// are in its report, predict's and compensate's still on stderr).
    #[arg(short, long, global = true, conflicts_with = "verbose")]
    quiet: bool,
    /// Print each progress step with the time since the start.
    #[arg(short, long, global = true)]
    verbose: bool,
}

/// How much `robcal` says on stderr besides errors.
#[derive(Clone, Copy, PartialEq)]
enum Verbosity {
    Quiet,
    Normal,
    Verbose,
}

/// One variant per subcommand (`import ...` goes here too).
#[derive(Subcommand)]
enum Command {
    /// Fit the declared model, trace what the residuals follow to the
    /// effects it lacks, add them, report the errors before and after.
    Calibrate(CalibrateArgs),
    /// Convert another tool's recording into the data contract's CSV.
    #[command(subcommand)]
    Import(ImportCommand),
    /// Where the calibrated robot (a model file of `calibrate --output`)
    /// puts a marker for given joint values and payload.
    Predict(apply::PredictArgs),
    /// The joint commands whose loaded, deflected calibrated robot puts a
    /// marker on each target (geometric and deflection compensation).
    Compensate(apply::CompensateArgs),
    /// A calibrated robot (a model file of `calibrate --output`) against a
    /// new recording: the error after re-registering its frame, a verdict
    /// (exit 1 when it fails), and the joints whose zero moved.
    Check(apply::CheckArgs),
    /// Two calibrations of one robot side by side: parameters in σ,
    /// effects in one only, and how far apart they put the markers.
    Compare(apply::CompareArgs),
    /// Choose the configurations to measure before measuring: the K of a
    /// pool of candidates (random within the joint limits, or yours) that
    /// determine the declared model best (D-optimal by default).
    Plan(plan::PlanArgs),
    /// Write a commented setup file for a robot, every key with its
    /// default and the CSV header its measurements need.
    Init(apply::InitArgs),
}

/// `robcal import <format> IN OUT`.
#[derive(Subcommand)]
enum ImportCommand {
    /// FIGAROH's motion-capture layout (`x1..z4` in m, joint columns by URDF
    /// name, optional `t_start_robot`/`t_end_robot`): one `config` per
    /// posture, markers 1..4 = the four points, SI units (rad, m).
    #[command(name = "figaroh-mocap")]
    FigarohMocap {
        /// FIGAROH CSV.
        input: PathBuf,
        /// Contract CSV to write (left untouched on error).
        output: PathBuf,
    },
    /// The wide one-row-per-pose layout of the real data sets
    /// (`<urdf joint>_rad`/`_m`, `x<i>_m, y<i>_m, z<i>_m` per marker,
    /// optional `pose_id`, `split`, per-axis uncertainty `ux<i>_m` or
    /// `std_x<i>_m`) and 6-D exports (a marker's orientation as a
    /// quaternion `qw<i>, qx<i>, qy<i>, qz<i>` or Euler angles
    /// `rx<i>_deg, ry<i>_deg, rz<i>_deg`): one row per measured point, SI
    /// units (rad, m), an orientation as the rotation vector `rx, ry, rz`.
    Poses {
        /// Pose CSV.
        input: PathBuf,
        /// Contract CSV to write (left untouched on error).
        output: PathBuf,
        /// Keep only the rows whose `split` column is NAME.
        #[arg(long, value_name = "NAME")]
        split: Option<String>,
        /// How Euler angle columns compose: `fixed-xyz` (= `moving-zyx`:
        /// R = Rz Ry Rx; URDF rpy, SpatialAnalyzer/T-Mac "Fixed XYZ", KUKA
        /// A B C) or `moving-xyz` (= `fixed-zyx`: R = Rx Ry Rz). Required
        /// with Euler columns.
        #[arg(long, value_name = "CONVENTION")]
        euler: Option<robcal::io::poses::Euler>,
    },
}

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    Irls,
    Wls,
    Ols,
}

#[derive(clap::Args)]
struct CalibrateArgs {
    /// Setup file (TOML).
    #[arg(long)]
    setup: PathBuf,
    /// Measurements (CSV).
    #[arg(long)]
    data: PathBuf,
    /// Estimation method.
    #[arg(long, value_enum, default_value = "irls")]
    method: MethodArg,
    /// λ of eq. 14 (default: the setup's `[noise] lambda`).
    #[arg(long, allow_negative_numbers = true, value_parser = finite_non_negative)]
    lambda: Option<f64>,
    /// IRLS iterations at most.
    #[arg(long = "max-iter", default_value_t = 100, value_parser = at_least_one)]
    max_iter: usize,
    /// Fit the declared model only.
    #[arg(long = "no-diagnose")]
    no_diagnose: bool,
    /// Accept a result that is not a calibration (a fit that did not
    /// converge, or a model worse than the nominal robot on its own data):
    /// exit 0. Without it such a run writes its report and exits 1.
    #[arg(long = "accept-unconverged")]
    accept_unconverged: bool,
    /// With --validate: re-fit the validation file's measurement frame
    /// (the calibrated model held fixed) and report the error after it:
    /// for a file measured with the tracker set up elsewhere.
    #[arg(long, requires = "validate")]
    reregister: bool,
    /// Leave out the rows the outlier rule names (a residual above 20 times
    /// the median row's: a measurement error) and fit again, once; the
    /// report's notes list them.
    #[arg(long = "leave-out-outliers")]
    leave_out_outliers: bool,
    /// Fit with a robust loss: each row weighted by Huber's loss on its
    /// standardised residual (beyond 3.37; over the instrument's sigma at
    /// the rows' level, the other rows of its configuration, or the rows'
    /// robust scale), fitted again until the weights settle;
    /// the report's notes name the rows weighted down.
    #[arg(long)]
    robust: bool,
    /// With --output: keep each marker's nominal position in robot.urdf
    /// too, as `marker_<id>_nominal` (`marker_<id>` is the calibrated one).
    #[arg(long = "keep-nominal-markers")]
    keep_nominal_markers: bool,
    /// The paper's first-order deflection model (eq. 3: torques and
    /// columns at the commanded pose) instead of the exact equilibrium of
    /// the deflected robot.
    #[arg(long)]
    linear: bool,
    /// Evaluate the fitted model on this file without re-estimating.
    #[arg(long)]
    validate: Option<PathBuf>,
    /// Write SVG plots of the residuals against the traced variable here.
    #[arg(long)]
    plots: Option<PathBuf>,
    /// Print the contract's JSON on stdout.
    #[arg(long)]
    json: bool,
    /// Write the calibrated robot here, all or nothing: `robot.urdf` (the
    /// input URDF with the geometry folded in, refitted as a rigid robot
    /// when the model has parameters a URDF cannot hold; a
    /// `measurement_frame` root and `marker_<id>` links at the calibrated
    /// markers, the URDF's own where it has them) and
    /// `model.json` (the report's JSON with
    /// the full covariance, and the `predictor` that `robcal predict` and
    /// `robcal compensate` read).
    #[arg(long)]
    output: Option<PathBuf>,
    /// Largest measurement file (`--data`, `--validate`) read, in MiB
    /// (1 MiB = 1,048,576 bytes).
    #[arg(long = "max-data-mib", default_value_t = 1024)]
    max_data_mib: u64,
}

/// The message of the first panic (see `main`), on whichever thread it
/// was: a panic on one of the engine's worker threads is carried to the
/// main thread by `resume_unwind`, which does not call the hook again.
static FIRST_PANIC: std::sync::Mutex<Option<String>> = std::sync::Mutex::new(None);

/// An argument that is a finite number ≥ 0 (a bad one is a usage error,
/// exit 2, as any other).
fn finite_non_negative(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err("must be a finite number >= 0".into()),
    }
}

/// An argument that is a finite number > 0.
fn finite_positive(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err("must be a finite number > 0".into()),
    }
}

/// A count of at least 1.
fn at_least_one(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(v) if v >= 1 => Ok(v),
        _ => Err(format!("must be a whole number from 1 to {}", usize::MAX)),
    }
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
                let _ = e.print();
                return ExitCode::SUCCESS;
            }
            // The contract's one line: clap's message, its indented lines
            // (the arguments it names) joined to it, without the usage.
            let text = e.to_string();
            if e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand {
                // The help's command list, by name.
                let commands: Vec<&str> = text
                    .lines()
                    .skip_while(|l| !l.starts_with("Commands:"))
                    .skip(1)
                    .take_while(|l| l.starts_with(' '))
                    .filter_map(|l| l.split_whitespace().next())
                    .filter(|c| *c != "help")
                    .collect();
                eprintln!(
                    "robcal: a command is needed: {} (see --help)",
                    commands.join(", ")
                );
                return ExitCode::from(2);
            }
            let mut lines = text
                .lines()
                .take_while(|l| !l.trim().is_empty() && !l.starts_with("Usage:"));
            let first = lines.next().unwrap_or("bad arguments");
            let first = first.trim_start_matches("error: ").trim();
            let named: Vec<&str> = lines.map(str::trim).collect();
            if named.is_empty() {
                eprintln!("robcal: {first}");
            } else {
                eprintln!("robcal: {} {}", first, named.join(", "));
            }
            return ExitCode::from(2);
        }
    };
    let verbosity = match (cli.quiet, cli.verbose) {
        (true, _) => Verbosity::Quiet,
        (_, true) => Verbosity::Verbose,
        _ => Verbosity::Normal,
    };
    // A panic (a dependency's; robcal's own code does not panic on input)
    // is one line on stderr, like every error: the hook keeps its message
    // instead of printing it, and the run is wrapped. A panic robcal
    // catches and turns into an error (urdf-rs's XML parser) prints nothing.
    std::panic::set_hook(Box::new(|info| {
        let message = info.to_string().replace('\n', " ");
        let mut first = FIRST_PANIC
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        first.get_or_insert(message);
    }));
    let command = cli.command;
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match command {
        Command::Calibrate(args) => run_calibrate(&args, verbosity),
        Command::Predict(args) => apply::run_predict(&args),
        Command::Compensate(args) => apply::run_compensate(&args),
        Command::Check(args) => apply::run_check(&args),
        Command::Compare(args) => apply::run_compare(&args),
        Command::Init(args) => apply::run_init(&args),
        Command::Plan(args) => plan::run_plan(&args),
        Command::Import(ImportCommand::FigarohMocap { input, output }) => {
            robcal::io::figaroh::import_mocap(&input, &output, None)
                .map(|n| {
                    eprintln!(
                        "robcal: {} postures, {} rows written to {}",
                        n.postures,
                        n.rows,
                        output.display()
                    );
                })
                .map_err(|e| e.to_string())
        }
        Command::Import(ImportCommand::Poses {
            input,
            output,
            split,
            euler,
        }) => {
            let options = robcal::io::poses::ImportOptions { split, euler };
            robcal::io::poses::import_poses(&input, &output, &options)
                .map(|n| {
                    for w in &n.warnings {
                        eprintln!("robcal: warning: {w}");
                    }
                    if !n.left_out.is_empty() {
                        eprintln!(
                            "robcal: left out (not needed by the model): {}",
                            n.left_out.join(", ")
                        );
                    }
                    let markers: Vec<String> = n.markers.iter().map(u32::to_string).collect();
                    eprintln!(
                        "robcal: {} poses, {} rows (markers {}{}) written to {}",
                        n.poses,
                        n.rows,
                        markers.join(", "),
                        match (n.has_sigma, n.orientations) {
                            (false, 0) => String::new(),
                            (true, 0) => "; with sx, sy, sz".into(),
                            (false, r) => format!("; {r} with rx, ry, rz"),
                            (true, r) => format!("; with sx, sy, sz; {r} with rx, ry, rz"),
                        },
                        output.display()
                    );
                })
                .map_err(|e| e.to_string())
        }
    }))
    .unwrap_or_else(|_| {
        Err(format!(
            "internal error: {}",
            FIRST_PANIC
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .take()
                .unwrap_or_default()
        ))
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line, and short: inputs are echoed cut by their readers,
            // this is the last guard.
            let line = robcal::io::input::shorten(&e.replace('\n', " "));
            eprintln!("robcal: error: {line}");
            ExitCode::FAILURE
        }
    }
}

fn run_calibrate(a: &CalibrateArgs, verbosity: Verbosity) -> Result<(), String> {
    let start = std::time::Instant::now();
    // Found before the fit, not after it.
    for dir in [&a.plots, &a.output].into_iter().flatten() {
        // It, or the nearest of its parents that exists (a directory to
        // create it in).
        let existing = dir
            .ancestors()
            .find(|p| p.as_os_str().is_empty() || p.exists());
        if let Some(p) = existing.filter(|p| !p.as_os_str().is_empty() && !p.is_dir()) {
            let what = if p == dir.as_path() {
                String::new()
            } else {
                format!("{} ", p.display())
            };
            return Err(format!(
                "{}: {what}exists and is not a directory",
                dir.display()
            ));
        }
    }
    let job = Job::load(&a.setup).map_err(|e| e.to_string())?;
    let max_bytes = a.max_data_mib.saturating_mul(1 << 20);
    let data = job
        .read_measurements_limited(&a.data, max_bytes)
        .map_err(|e| e.to_string())?;
    for w in &data.warnings {
        if verbosity != Verbosity::Quiet {
            eprintln!("robcal: warning: {w}");
        }
    }
    let validation_data = match &a.validate {
        Some(v) => Some(
            job.read_measurements_limited(v, max_bytes)
                .map_err(|e| e.to_string())?,
        ),
        None => None,
    };
    let settings = Settings {
        method: match a.method {
            MethodArg::Irls => Method::Irls,
            MethodArg::Wls => Method::Wls,
            MethodArg::Ols => Method::Ols,
        },
        lambda: a.lambda,
        max_iterations: a.max_iter,
        diagnose: !a.no_diagnose,
        deflection_model: if a.linear {
            DeflectionModel::Linear
        } else {
            DeflectionModel::Exact
        },
        leave_out_outliers: a.leave_out_outliers,
        robust: a.robust,
        policy: robcal::calibrate::Policy {
            max_held_design_rows: max_held_design_rows()?,
            ..Default::default()
        },
        ..Settings::default()
    };
    // On a terminal, a spinner with the current step once the run has
    // taken a second; elsewhere (a pipe, a log) one line per step.
    let spinner = (verbosity == Verbosity::Normal && std::io::stderr().is_terminal()).then(|| {
        indicatif::ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden()).with_style(
            ProgressStyle::with_template("{spinner} {msg} [{elapsed}]")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        )
    });
    let mut progress = |m: &str| match (verbosity, &spinner) {
        (Verbosity::Quiet, _) => {}
        (Verbosity::Normal, Some(bar)) => {
            if bar.is_hidden() && start.elapsed().as_secs_f64() >= 1.0 {
                bar.set_draw_target(ProgressDrawTarget::stderr());
                bar.enable_steady_tick(std::time::Duration::from_millis(120));
            }
            bar.set_message(format!("robcal: {m}"));
        }
        (Verbosity::Normal, None) => eprintln!("robcal: {m}"),
        (Verbosity::Verbose, _) => {
            eprintln!("robcal: [{:7.2} s] {m}", start.elapsed().as_secs_f64());
        }
    };
    let result = calibrate::calibrate_owned(&job, data, &settings, &mut progress);
    if let Some(bar) = &spinner {
        bar.finish_and_clear();
    }
    let mut report = result.map_err(|e| e.to_string())?;
    if let Some(v) = &validation_data {
        let v = calibrate::validate_with(&report.model, &job, v, a.reregister)
            .map_err(|e| e.to_string())?;
        report.set_validation(v);
    }
    // Every file of --plots and --output in one all-or-nothing write: a
    // failure of one writes neither.
    let robot_path = job.setup.robot_path(&job.setup_path);
    let mut inputs = vec![a.setup.as_path(), a.data.as_path(), robot_path.as_path()];
    inputs.extend(a.validate.as_deref());
    let mut dirs: Vec<(&Path, robcal::io::atomic::Files)> = Vec::new();
    if let Some(dir) = &a.plots {
        // The report's figures (`--output` has them too).
        let files = files::figures(&report)?
            .into_iter()
            .map(|f| (dir.join(f.file), f.svg.into_bytes()))
            .collect();
        dirs.push((dir, files));
    }
    if let Some(dir) = &a.output {
        let info = JobInfo {
            job: &job,
            data: &a.data,
            validate: a.validate.as_deref(),
            lambda: a.lambda.unwrap_or(job.setup.noise.lambda),
        };
        let options = calibrate::export::UrdfOptions {
            keep_nominal_markers: a.keep_nominal_markers,
        };
        let files = files::OutputFiles::of(&report, &info, options)?.into_files(dir);
        dirs.push((dir, files));
    }
    robcal::io::atomic::write_dirs(dirs, &inputs)?;
    let out = if a.json {
        files::report_json(&report)?
    } else {
        report.to_string()
    };
    std::io::stdout()
        .write_all(out.as_bytes())
        .map_err(|e| format!("cannot write the report: {e}"))?;
    match &report.failure {
        Some(why) if !a.accept_unconverged => Err(format!(
            "not a calibration: {why}; the report is written for inspection \
             (--accept-unconverged accepts it)"
        )),
        _ => Ok(()),
    }
}

/// `ROBCAL_MAX_HELD_DESIGN_ROWS`: a design of more rows does not hold its
/// columns but computes them again where a pass reads them
/// (`Policy::max_held_design_rows`: the same report, less memory, more
/// time); unset, the policy's default.
fn max_held_design_rows() -> Result<usize, String> {
    match std::env::var("ROBCAL_MAX_HELD_DESIGN_ROWS") {
        Err(std::env::VarError::NotPresent) => {
            Ok(robcal::calibrate::Policy::default().max_held_design_rows)
        }
        Ok(v) => v
            .trim()
            .parse()
            .map_err(|_| format!("ROBCAL_MAX_HELD_DESIGN_ROWS={v:?}: expected a number of rows")),
        Err(e) => Err(format!("ROBCAL_MAX_HELD_DESIGN_ROWS: {e}")),
    }
}
