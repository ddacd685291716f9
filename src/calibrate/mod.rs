//! The closed loop on the host (`std`): fit the declared model, find the
//! structure left in the residuals, trace it to an effect the model lacks,
//! add it, refit, and report the error before and after each step.
//!
//! ```text
//!   Job + Measurements ──rows──► Problem (rows in memory, IRLS groups = configurations)
//!        │
//!        ├─ fit the declared model (OLS | WLS | IRLS, eq. 6, 10, 14), iterated
//!        │     Gauss–Newton on the geometric terms (`geometry`)
//!        ├─ residual analysis: lack of fit from the repetitions (pure error)
//!        ├─ every effect of the library the model lacks (`effects`):
//!        │     nested F test from the cross-products (`crate::diagnose`)
//!        ├─ in order of p, the first with p · (candidates tried) < α (Bonferroni),
//!        │     a physical estimate and a lower leave-one-configuration-out
//!        │     RMS → add it, refit, repeat
//!        └─ RMS and leave-one-configuration-out RMS before and after each step
//! ```
//!
//! Rows: the **deflections** (loaded − unloaded, only the load's torques),
//! and, when the declared model identifies geometry, the base or the markers
//! (or there is no load), the **absolute** unloaded positions against the
//! forward kinematics of the current model, loaded by the robot's own
//! weight. The current model starts nominal, with the base placed by a
//! rigid registration when the base frame is identified, and moves with
//! each fit of the geometric terms until they settle (Gauss–Newton,
//! [`Geometry`]): the geometric parameters are reported as their values
//! in that model (the base as its pose in the measurement frame), with the
//! σ of the last linearisation.
//!
//! Decisions, stated once:
//! - α = 0.01 for the Bonferroni-corrected effect test (`p · tried < α`) and
//!   for the lack-of-fit test;
//! - an effect is added only if it passes that test **and**, when the lack
//!   of fit is significant, explains at least [`Settings::min_share`] of the
//!   lack-of-fit sum of squares above its noise expectation: an effect that
//!   only nibbles at a structure it does not describe is not named;
//! - and only if its estimate is physical ([`inadmissible`]) **and** the
//!   leave-one-configuration-out RMS drops with it (when it is computed,
//!   [`Settings::heldout`]): a significant effect that predicts unseen
//!   configurations worse is fitting this data set, not the robot. The
//!   candidates are tried in order of p-value until one passes;
//! - RMS is the RMS of the norm of the 3-D position residual of each row
//!   (µm, unweighted); held-out RMS is the same over the predictions of
//!   each configuration from a fit without it (same method);
//! - nonlinear effects are linearised about the current estimate: `load_com`
//!   uses the current compliances, re-evaluated after every refit;
//! - deflection rows carry only the load's torques (as the paper's
//!   elastostatic experiment): `nonlinear_stiffness` (`τ|τ|`) and
//!   `backlash` (`sign τ`) act on the load torque, without the robot's own
//!   weight as a preload; `link_compliance` and `load_com` are seen in the
//!   deflections only, the geometric effects (`joint_offset`, `geometry`,
//!   `gear_cyclic`, `marker`, `base_frame`) in the absolute rows only;
//! - a compensator candidate needs 2–8 distinct angles of its joint, each
//!   in at least two configurations; with a constant `kⱼ` in the model it is
//!   tested as the bins minus one (the constant stays), and on acceptance
//!   `kⱼ` is replaced by one compliance per bin (`k_<joint>@<angle>`);
//! - candidate and declared columns that the data cannot tell from the
//!   model's are dropped (greedy Gram–Schmidt) before a test or a fit;
//! - the work runs on a thread with a 256 MB stack (reserved, not
//!   committed): a 128-column problem's fixed-size matrices are 131 kB each.

mod effects;
mod geometry;
mod problem;
mod report;
mod terms;

use std::collections::BTreeMap;

use nalgebra::Vector3;

pub use effects::{Candidate, DataKinds, EFFECTS};
pub use geometry::{is_geometric, Geometry};
pub use problem::{Design, FitOut, FitSettings, Method, MAX_COLUMNS, MAX_GROUPS};
pub use report::{EffectStep, Parameter, PlotSeries, Report, Unexplained, Validation};
pub use terms::{Bin, Context, Row, RowKind, Term};

use crate::elastostatic::{self, PointLoad};
use crate::io::{GeometryModel, Job, MarkerModel, Measurements};
use crate::stats;
use crate::weights::RobustWeight;
use crate::Error;

/// Settings of a calibration run (what the CLI flags set).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// OLS, WLS or IRLS.
    pub method: Method,
    /// λ of eq. 14; `None`: the setup's.
    pub lambda: Option<f64>,
    /// IRLS iterations at most.
    pub max_iterations: usize,
    /// Run the diagnosis loop.
    pub diagnose: bool,
    /// Compute the leave-one-configuration-out RMS, and add an effect only
    /// when it lowers it.
    pub heldout: bool,
    /// Significance level (Bonferroni over the candidates tried).
    pub alpha: f64,
    /// Share of the excess lack-of-fit an effect must explain to be named.
    pub min_share: f64,
    /// At most this many effects are added.
    pub max_effects: usize,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            method: Method::Irls,
            lambda: None,
            max_iterations: 100,
            diagnose: true,
            heldout: true,
            alpha: 0.01,
            min_share: 0.1,
            max_effects: 8,
        }
    }
}

/// Why a calibration failed.
#[derive(Debug, Clone, PartialEq)]
pub enum CalibrationError {
    /// The data cannot support the model (one line for the user).
    Data(String),
    /// A numerical error of the core, with what was being done.
    Core(&'static str, Error),
}

impl core::fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            CalibrationError::Data(s) => write!(f, "{s}"),
            CalibrationError::Core(what, e) => write!(f, "{what}: {e}"),
        }
    }
}

impl std::error::Error for CalibrationError {}

/// Half-width \[rad\] of an angle bin (as [`crate::layout::Layout::angle_tolerance_rad`]).
pub const BIN_TOLERANCE_RAD: f64 = 1e-3;

/// The prepared problem: rows, context, the declared model.
#[derive(Debug, Clone)]
pub struct Problem {
    /// Column context (names, bins, current compliances).
    pub ctx: Context,
    /// Rows.
    pub rows: Vec<Row>,
    /// Configuration ids, one per group.
    pub configs: Vec<i64>,
    /// What kinds of rows there are.
    pub kinds: DataKinds,
    /// Whether each joint's bins make a compensator candidate.
    pub compensator_ok: Vec<bool>,
    /// The declared model's terms (identifiable subset).
    pub model: Vec<Term>,
    /// Declared terms the data cannot identify (dropped).
    pub dropped: Vec<Term>,
    /// Gravity \[m/s², base frame\].
    pub gravity: Vector3<f64>,
    /// Load's centre of mass \[m, tip frame\].
    pub com: Vector3<f64>,
    /// Mean time of the data \[s\] (absolute rows' time origin).
    pub t_mean: f64,
    /// σ0 \[m\], λ.
    pub weight: RobustWeight<f64>,
    /// The model the absolute rows are linearised at (Gauss–Newton).
    pub geometry: Geometry,
}

fn cluster(values: &[f64], tol: f64) -> Vec<f64> {
    let mut v: Vec<f64> = values.to_vec();
    v.sort_by(f64::total_cmp);
    let mut out: Vec<(f64, usize)> = Vec::new();
    for x in v {
        match out.last_mut() {
            Some((c, n)) if (x - *c / *n as f64).abs() <= tol => {
                *c += x;
                *n += 1;
            }
            _ => out.push((x, 1)),
        }
    }
    out.into_iter().map(|(c, n)| c / n as f64).collect()
}

impl Problem {
    /// Builds the rows of `data` for `job`'s declared model.
    ///
    /// # Errors
    /// [`CalibrationError::Data`] when the data has no usable row for the
    /// model, a declared angle-dependent joint has no angle bins, or the
    /// model exceeds [`MAX_COLUMNS`].
    pub fn new(
        job: &Job,
        data: &Measurements,
        lambda: Option<f64>,
    ) -> Result<Self, CalibrationError> {
        let setup = &job.setup;
        let robot = &job.robot;
        let dof = robot.dof();
        let joint_index = |n: &str| robot.joint_index(n);
        let model_decl = &setup.model;
        let geometric = model_decl.geometry != GeometryModel::None
            || model_decl.base_frame
            || model_decl.markers == MarkerModel::Identify;
        let use_absolute = geometric || data.deflections.is_empty();
        let markers: Vec<(u32, Vector3<f64>)> = setup
            .markers
            .iter()
            .map(|m| (m.id, Vector3::from(m.xyz)))
            .collect();
        let joint_kinds = robot.chain.joints().iter().map(|j| j.kind).collect();
        let gravity = setup.load.map_or(Vector3::new(0.0, 0.0, -9.80665), |l| {
            Vector3::from(l.gravity)
        });
        let com = setup
            .load
            .map_or(Vector3::zeros(), |l| Vector3::from(l.com));
        let mut configs: Vec<i64> = data.observations.iter().map(|o| o.config).collect();
        configs.sort_unstable();
        configs.dedup();
        let group_of = |c: i64| configs.binary_search(&c).unwrap_or(0);
        let times: Vec<f64> = data.observations.iter().filter_map(|o| o.t_s).collect();
        let t_mean = if times.is_empty() {
            0.0
        } else {
            times.iter().sum::<f64>() / times.len() as f64
        };
        let sigma0 = setup.noise.sigma0_um * 1e-6;
        let weight = RobustWeight::new(sigma0, lambda.unwrap_or(setup.noise.lambda))
            .map_err(|e| CalibrationError::Core("noise settings", e))?;

        // Angle bins per joint, from the rows that enter the problem.
        let mut bins = Vec::with_capacity(dof);
        let mut compensator_ok = Vec::with_capacity(dof);
        for j in 0..dof {
            let qs: Vec<(f64, &str, i64)> = if use_absolute {
                data.unloaded()
                    .map(|o| (o.q[j], o.q_written[j].as_str(), o.config))
                    .collect()
            } else {
                data.deflections
                    .iter()
                    .map(|d| {
                        let o = &data.observations[d.rows[1]];
                        (o.q[j], o.q_written[j].as_str(), o.config)
                    })
                    .collect()
            };
            let values: Vec<f64> = qs.iter().map(|v| v.0).collect();
            // Bins in order of first appearance in the file (k21, k22, … of
            // the paper).
            let mut centres = cluster(&values, BIN_TOLERANCE_RAD);
            let first = |c: f64| {
                values
                    .iter()
                    .position(|v| (v - c).abs() <= BIN_TOLERANCE_RAD)
            };
            centres.sort_by_key(|&c| first(c));
            let mut jb = Vec::new();
            let mut counts = Vec::new();
            if centres.len() <= 32 {
                for c in &centres {
                    let written = qs
                        .iter()
                        .find(|v| (v.0 - c).abs() <= BIN_TOLERANCE_RAD)
                        .map_or_else(|| format!("{c}"), |v| v.1.trim().to_string());
                    let mut cfgs: Vec<i64> = qs
                        .iter()
                        .filter(|v| (v.0 - c).abs() <= BIN_TOLERANCE_RAD)
                        .map(|v| v.2)
                        .collect();
                    cfgs.sort_unstable();
                    cfgs.dedup();
                    counts.push(cfgs.len());
                    jb.push(Bin { angle: *c, written });
                }
            }
            compensator_ok.push(effects::compensator_eligible(&counts));
            bins.push(jb);
        }
        let ctx = Context {
            joint_names: robot.joint_names.clone(),
            joint_kinds,
            markers: markers.clone(),
            bins,
            bin_tolerance: BIN_TOLERANCE_RAD,
            k: vec![0.0; dof],
            k_bins: vec![Vec::new(); dof],
        };

        // Rows: what was measured; frames, positions, torques and the
        // absolute rows' `Δp` come from `relinearise` at the nominal model
        // below.
        let chain = &robot.chain;
        let core = |what: &'static str| move |e: Error| CalibrationError::Core(what, e);
        let mut rows = Vec::new();
        let mut row = |kind, config, marker, load_kg, q: &[f64], dt, measured: [f64; 3], line| {
            let frames = chain.frames(q).map_err(core("forward kinematics"))?;
            let measured = Vector3::from(measured);
            rows.push(Row {
                kind,
                group: group_of(config),
                config,
                marker,
                load_kg,
                q: q.to_vec(),
                frames,
                p: Vector3::zeros(),
                tau: vec![0.0; dof],
                load_force: None,
                dt,
                y: measured,
                measured,
                line,
            });
            Ok::<(), CalibrationError>(())
        };
        for d in &data.deflections {
            let (loaded, unloaded) = (&data.observations[d.rows[0]], &data.observations[d.rows[1]]);
            let dt = match (loaded.t_s, unloaded.t_s) {
                (Some(a), Some(b)) => Some(a - b),
                _ => None,
            };
            let kind = RowKind::Deflection;
            row(
                kind, d.config, d.marker, d.load_kg, &d.q, dt, d.dp_m, d.lines[0],
            )?;
        }
        if use_absolute {
            for o in data.unloaded() {
                let dt = o.t_s.map(|t| t - t_mean);
                let kind = RowKind::Absolute;
                row(kind, o.config, o.marker, 0.0, &o.q, dt, o.p_m, o.line)?;
            }
        }
        if rows.is_empty() {
            return Err(CalibrationError::Data(format!(
                "{}: no rows to calibrate from",
                data.file.display()
            )));
        }
        if configs.len() > MAX_GROUPS {
            return Err(CalibrationError::Data(format!(
                "{}: {} configurations, at most {MAX_GROUPS} are supported",
                data.file.display(),
                configs.len()
            )));
        }
        let kinds = DataKinds {
            deflections: rows.iter().any(|r| r.kind == RowKind::Deflection),
            absolute: rows.iter().any(|r| r.kind == RowKind::Absolute),
            time: data.has_time,
        };

        // The declared model.
        let mut model = Vec::new();
        for name in &model_decl.compliance_by_angle {
            let j = joint_index(name).ok_or_else(|| {
                CalibrationError::Data(format!("[model] names unknown joint '{name}'"))
            })?;
            if ctx.bins[j].is_empty() {
                return Err(CalibrationError::Data(format!(
                    "{}: joint '{name}' takes too many distinct angles for compliance_by_angle",
                    data.file.display()
                )));
            }
            model.extend((0..ctx.bins[j].len()).map(|b| Term::ComplianceAt(j, b)));
        }
        for name in &model_decl.compliance {
            let j = joint_index(name).ok_or_else(|| {
                CalibrationError::Data(format!("[model] names unknown joint '{name}'"))
            })?;
            if !model_decl.compliance_by_angle.contains(name) {
                model.push(Term::Compliance(j));
            }
        }
        // Base and markers before the joints: where a joint parameter and
        // the base (or a marker) are the same motion (the first joint's
        // frame error, the last joint's offset), the joint's is dropped.
        if model_decl.base_frame {
            model.extend((0..6).map(Term::Base));
        }
        if model_decl.markers == MarkerModel::Identify {
            for m in 0..markers.len() {
                model.extend((0..3).map(|a| Term::Marker(m, a)));
            }
        }
        match model_decl.geometry {
            // `select`: offered to the loop as candidates (`effects`).
            GeometryModel::None | GeometryModel::Select => {}
            GeometryModel::JointOffsets => model.extend((0..dof).map(Term::JointOffset)),
            GeometryModel::Full => {
                for j in 0..dof {
                    model.extend((0..6).map(|a| Term::JointFrame(j, a)));
                }
            }
        }
        let mut p = Self {
            ctx,
            rows,
            configs,
            kinds,
            compensator_ok,
            model: Vec::new(),
            dropped: Vec::new(),
            gravity,
            com,
            t_mean,
            weight,
            geometry: Geometry::nominal(chain, &markers),
        };
        p.relinearise()?;
        let d = p.design(&model);
        let all: Vec<usize> = (0..model.len()).collect();
        let kept = problem::independent(&d, &[], &all);
        p.dropped = (0..model.len())
            .filter(|i| !kept.contains(i))
            .map(|i| model[i])
            .collect();
        p.model = kept.iter().map(|&i| model[i]).collect();
        // A declared compliance the data cannot identify is too few
        // configurations (or markers, or a load that does not load the
        // joint) for the declared model: an error naming the parameters,
        // not a fit that silently leaves them out. (Geometric parameters
        // that another declared one absorbs, e.g. a1's offset and the base
        // yaw, are a property of the model, not of the data: left out and
        // reported in `Report::dropped`.)
        let missing: Vec<String> = p
            .dropped
            .iter()
            .filter(|t| matches!(t, Term::Compliance(_) | Term::ComplianceAt(..)))
            .map(|t| p.ctx.name(t))
            .collect();
        if !missing.is_empty() {
            let deflections = p
                .rows
                .iter()
                .filter(|r| r.kind == RowKind::Deflection)
                .count();
            return Err(CalibrationError::Data(format!(
                "{}: too few configurations for the declared model: {} cannot be identified \
                 from {} configuration(s) and {} deflection(s) ({} equations for {} declared \
                 parameters); measure more configurations (or markers), or remove them from \
                 [model]",
                data.file.display(),
                missing.join(", "),
                p.configs.len(),
                deflections,
                3 * deflections,
                model.len()
            )));
        }
        if p.model.is_empty() {
            return Err(CalibrationError::Data(
                "the declared model has no parameter these data can identify".into(),
            ));
        }
        if p.model.len() > MAX_COLUMNS {
            return Err(CalibrationError::Data(format!(
                "the declared model has {} parameters, at most {MAX_COLUMNS} are supported",
                p.model.len()
            )));
        }
        Ok(p)
    }

    /// The design of `terms` at every row with the current context.
    pub fn design(&self, terms: &[Term]) -> Design {
        Design::new(&self.ctx, &self.rows, terms, self.configs.len())
    }

    /// Recomputes the rows at [`Problem::geometry`]: frames, predicted
    /// position and torques of every row, and `Δp` of the absolute rows
    /// (a deflection row's `Δp` is what was measured; its columns move with
    /// the model, e.g. into the measurement frame once the base is placed).
    ///
    /// # Errors
    /// [`CalibrationError::Core`] when the forward kinematics fails.
    pub fn relinearise(&mut self) -> Result<(), CalibrationError> {
        let chain = self.geometry.placed_chain();
        // The frames are in the measurement frame, gravity is given in the
        // robot's base frame.
        let gravity = self.geometry.base.rotation * self.gravity;
        let core = |what: &'static str| move |e: Error| CalibrationError::Core(what, e);
        for row in &mut self.rows {
            let m = self
                .geometry
                .markers
                .iter()
                .find(|m| m.0 == row.marker)
                .map(|m| m.1)
                .unwrap_or_default();
            row.frames = chain.frames(&row.q).map_err(core("forward kinematics"))?;
            row.p = row.frames.point_m(&m);
            match row.kind {
                RowKind::Absolute => {
                    elastostatic::gravity_torques(&chain, &row.frames, &gravity, &mut row.tau)
                        .map_err(core("gravity torques"))?;
                    row.y = row.measured - row.p;
                }
                RowKind::Deflection => {
                    let load = PointLoad {
                        mass_kg: row.load_kg,
                        com_m: self.com,
                        gravity_mps2: gravity,
                    };
                    let wrench = load.wrench(&row.frames);
                    elastostatic::joint_torques(&row.frames, &wrench, &mut row.tau)
                        .map_err(core("load torques"))?;
                    row.load_force = Some((wrench.point_m, wrench.force_n));
                }
            }
        }
        Ok(())
    }

    /// Places the base by a rigid registration of the predicted marker
    /// positions onto the measured ones ([`Geometry::register`]), when the
    /// model identifies the base and there are absolute rows.
    ///
    /// # Errors
    /// As [`Problem::relinearise`].
    pub fn register_base(&mut self) -> Result<(), CalibrationError> {
        let absolute: Vec<&Row> = self
            .rows
            .iter()
            .filter(|r| r.kind == RowKind::Absolute)
            .collect();
        if !self.model.iter().any(|t| matches!(t, Term::Base(_))) || absolute.len() < 3 {
            return Ok(());
        }
        let predicted: Vec<Vector3<f64>> = absolute.iter().map(|r| r.p).collect();
        let measured: Vec<Vector3<f64>> = absolute.iter().map(|r| r.measured).collect();
        self.geometry.register(&predicted, &measured);
        self.relinearise()
    }

    /// Sets the compliances the linearised effects use from a fit.
    fn set_estimate(&mut self, terms: &[Term], x: &[f64]) {
        let dof = self.ctx.joint_names.len();
        self.ctx.k = vec![0.0; dof];
        self.ctx.k_bins = self.ctx.bins.iter().map(|b| vec![0.0; b.len()]).collect();
        for (t, v) in terms.iter().zip(x) {
            match *t {
                Term::Compliance(j) => self.ctx.k[j] = v * 1e-6,
                Term::ComplianceAt(j, b) => self.ctx.k_bins[j][b] = v * 1e-6,
                _ => {}
            }
        }
    }
}

/// A fitted model: its terms, estimate and errors.
#[derive(Debug, Clone)]
struct Fitted {
    terms: Vec<Term>,
    fit: FitOut,
    /// The model the fit is linearised at (its geometric steps are below
    /// [`geometry::STEP_TOLERANCE`]).
    geometry: Geometry,
    /// Gauss–Newton relinearisations.
    relinearisations: usize,
    rms_um: f64,
    heldout_rms_um: Option<f64>,
    residuals: Vec<Vector3<f64>>,
}

fn rms_um(res: &[Vector3<f64>]) -> f64 {
    if res.is_empty() {
        return 0.0;
    }
    (res.iter().map(|r| r.norm_squared()).sum::<f64>() / res.len() as f64).sqrt() * 1e6
}

/// Lack of fit from the repetitions: rows with the same configuration,
/// marker and kind have the same regressors, so the scatter within such a
/// cell is pure error and the cell means carry the model's lack of fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LackOfFit {
    /// `F = (SS_lof / df_lof) / (SS_pe / df_pe)`.
    pub f: f64,
    /// Its p-value.
    pub p_value: f64,
    /// Between-cell weighted sum of squares.
    pub ss_lof: f64,
    /// Its degrees of freedom (cells · 3 − parameters).
    pub df_lof: usize,
    /// Within-cell weighted sum of squares.
    pub ss_pe: f64,
    /// Its degrees of freedom.
    pub df_pe: usize,
}

impl LackOfFit {
    /// `SS_lof` above its expectation under noise alone.
    pub fn excess(&self) -> f64 {
        (self.ss_lof - self.df_lof as f64 * self.ss_pe / self.df_pe.max(1) as f64).max(0.0)
    }
}

fn lack_of_fit(p: &Problem, fitted: &Fitted) -> Option<LackOfFit> {
    let mut cells: BTreeMap<(usize, u32, bool), Vec<Vector3<f64>>> = BTreeMap::new();
    for (row, r) in p.rows.iter().zip(&fitted.residuals) {
        let w = fitted.fit.weights[row.group];
        cells
            .entry((row.group, row.marker, row.kind == RowKind::Deflection))
            .or_default()
            .push(r.component_mul(&w));
    }
    let (mut ss_lof, mut ss_pe, mut df_pe, mut n_cells) = (0.0, 0.0, 0usize, 0usize);
    for v in cells.values() {
        let n = v.len() as f64;
        let mean = v.iter().sum::<Vector3<f64>>() / n;
        ss_lof += n * mean.norm_squared();
        ss_pe += v.iter().map(|r| (r - mean).norm_squared()).sum::<f64>();
        df_pe += 3 * (v.len() - 1);
        n_cells += 1;
    }
    let df_lof = (3 * n_cells).checked_sub(fitted.terms.len())?;
    if df_lof == 0 || df_pe == 0 || ss_pe <= 0.0 {
        return None;
    }
    let f = (ss_lof / df_lof as f64) / (ss_pe / df_pe as f64);
    Some(LackOfFit {
        f,
        p_value: stats::f_sf(f, df_lof, df_pe),
        ss_lof,
        df_lof,
        ss_pe,
        df_pe,
    })
}

/// A variable the residuals may follow: its name, its value per row, and
/// whether it is an angle (then it is expanded in harmonics, else in powers).
struct Variable {
    name: String,
    values: Vec<f64>,
    angle: bool,
}

/// Variables the residuals may follow, per row.
fn variables(p: &Problem) -> Vec<Variable> {
    let var = |name: String, values: Vec<f64>, angle: bool| Variable {
        name,
        values,
        angle,
    };
    let mut out = Vec::new();
    for (j, name) in p.ctx.joint_names.iter().enumerate() {
        let angle = p.ctx.joint_kinds[j] == crate::chain::JointKind::Revolute;
        out.push(var(
            format!("q_{name}"),
            p.rows.iter().map(|r| r.q[j]).collect(),
            angle,
        ));
    }
    for (j, name) in p.ctx.joint_names.iter().enumerate() {
        out.push(var(
            format!("tau_{name}"),
            p.rows.iter().map(|r| r.tau[j]).collect(),
            false,
        ));
    }
    if p.kinds.deflections {
        out.push(var(
            "load_kg".into(),
            p.rows.iter().map(|r| r.load_kg).collect(),
            false,
        ));
    }
    if p.kinds.time {
        out.push(var(
            "t".into(),
            p.rows.iter().map(|r| r.dt.unwrap_or(0.0)).collect(),
            false,
        ));
    }
    if p.ctx.markers.len() > 1 {
        out.push(var(
            "marker".into(),
            p.rows.iter().map(|r| f64::from(r.marker)).collect(),
            false,
        ));
    }
    out
}

/// How strongly the weighted residuals follow `v`: the p-value of the F
/// test of regressing each residual axis on smooth functions of `v`
/// (harmonics 1–3 for an angle, powers 1–3 otherwise), pooled over the
/// three axes. Smaller is stronger.
fn follow_p_value(v: &Variable, res: &[Vector3<f64>]) -> f64 {
    let n = v.values.len();
    let mean = v.values.iter().sum::<f64>() / n.max(1) as f64;
    let sd = (v.values.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n.max(1) as f64).sqrt();
    if n < 8 || sd == 0.0 {
        return 1.0;
    }
    let features: Vec<Vec<f64>> = if v.angle {
        (1..=3)
            .flat_map(|h| {
                let h = f64::from(h);
                [
                    v.values.iter().map(|x| (h * x).sin()).collect::<Vec<f64>>(),
                    v.values.iter().map(|x| (h * x).cos()).collect(),
                ]
            })
            .collect()
    } else {
        (1..=3)
            .map(|k| v.values.iter().map(|x| ((x - mean) / sd).powi(k)).collect())
            .collect()
    };
    // Orthonormal basis of [1, features] (dependent ones dropped).
    let mut basis: Vec<Vec<f64>> = vec![vec![1.0 / (n as f64).sqrt(); n]];
    for mut f in features {
        let n0 = f.iter().map(|x| x * x).sum::<f64>().sqrt();
        for _ in 0..2 {
            for u in &basis {
                let d: f64 = u.iter().zip(&f).map(|(a, b)| a * b).sum();
                f.iter_mut().zip(u).for_each(|(x, ui)| *x -= d * ui);
            }
        }
        let nf = f.iter().map(|x| x * x).sum::<f64>().sqrt();
        if nf > 1e-8 * n0 {
            f.iter_mut().for_each(|x| *x /= nf);
            basis.push(f);
        }
    }
    let k = basis.len() - 1;
    if k == 0 || n <= k + 1 {
        return 1.0;
    }
    let (mut explained, mut left) = (0.0, 0.0);
    for a in 0..3 {
        let y: Vec<f64> = res.iter().map(|r| r[a]).collect();
        let ym = y.iter().sum::<f64>() / n as f64;
        let tss: f64 = y.iter().map(|v| (v - ym).powi(2)).sum();
        let ess: f64 = basis[1..]
            .iter()
            .map(|u| u.iter().zip(&y).map(|(a, b)| a * b).sum::<f64>().powi(2))
            .sum();
        explained += ess;
        left += (tss - ess).max(0.0);
    }
    if left <= 0.0 {
        return 0.0;
    }
    let (d1, d2) = (3 * k, 3 * (n - k - 1));
    stats::f_sf((explained / d1 as f64) / (left / d2 as f64), d1, d2)
}

/// The variable the residuals follow most, and its p-value. Rows that
/// repeat one another (same configuration, marker, kind) are averaged
/// first: they share their regressors, so counting them as independent
/// would let a many-harmonic fit look significant.
fn most_followed(p: &Problem, fitted: &Fitted) -> (String, f64) {
    let mut cell_of: BTreeMap<(usize, u32, bool), usize> = BTreeMap::new();
    let cell: Vec<usize> = p
        .rows
        .iter()
        .map(|r| {
            let n = cell_of.len();
            *cell_of
                .entry((r.group, r.marker, r.kind == RowKind::Deflection))
                .or_insert(n)
        })
        .collect();
    let cells = cell_of.len();
    let mut count = vec![0.0; cells];
    let mut res = vec![Vector3::<f64>::zeros(); cells];
    for ((row, r), &c) in p.rows.iter().zip(&fitted.residuals).zip(&cell) {
        res[c] += r.component_mul(&fitted.fit.weights[row.group]);
        count[c] += 1.0;
    }
    for (r, n) in res.iter_mut().zip(&count) {
        *r /= *n;
    }
    variables(p)
        .into_iter()
        .map(|v| {
            let mut values = vec![0.0; cells];
            for (&x, &c) in v.values.iter().zip(&cell) {
                values[c] += x / count[c];
            }
            let v = Variable { values, ..v };
            let s = follow_p_value(&v, &res);
            (v.name, s)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or_else(|| ("none".into(), 1.0))
}

/// Values of the variable an effect is traced by, per row, for plots.
fn traced_variable(p: &Problem, c: &Candidate) -> (String, Vec<f64>) {
    let j = c.joint;
    let deg = |j: usize| {
        let scale = if p.ctx.joint_kinds[j] == crate::chain::JointKind::Revolute {
            180.0 / std::f64::consts::PI
        } else {
            1000.0
        };
        p.rows.iter().map(|r| r.q[j] * scale).collect::<Vec<f64>>()
    };
    match (c.effect, j) {
        ("compensator" | "joint_offset" | "gear_cyclic" | "geometry", Some(j)) => {
            (format!("q_{} [deg]", p.ctx.joint_names[j]), deg(j))
        }
        (_, Some(j)) => (
            format!("tau_{} [N*m]", p.ctx.joint_names[j]),
            p.rows.iter().map(|r| r.tau[j]).collect(),
        ),
        ("drift", None) => (
            "t [s]".into(),
            p.rows.iter().map(|r| r.dt.unwrap_or(0.0)).collect(),
        ),
        ("load_com", None) => ("load_kg".into(), p.rows.iter().map(|r| r.load_kg).collect()),
        _ => (
            "config".into(),
            p.rows.iter().map(|r| r.config as f64).collect(),
        ),
    }
}

fn variable_values(p: &Problem, name: &str) -> Vec<f64> {
    variables(p)
        .into_iter()
        .find(|v| v.name == name)
        .map(|v| v.values)
        .unwrap_or_else(|| p.rows.iter().map(|r| r.config as f64).collect())
}

/// Progress messages (stderr in the CLI).
pub type Progress<'a> = &'a mut dyn FnMut(&str);

struct Engine<'a> {
    p: Problem,
    s: FitSettings,
    settings: Settings,
    progress: Progress<'a>,
}

impl Engine<'_> {
    fn fit(&mut self, terms: &[Term]) -> Result<Fitted, CalibrationError> {
        // Linearised effects: evaluate about the estimate, refit until the
        // compliances settle (one or two passes). Geometric terms of
        // absolute rows: Gauss–Newton (`geometry`), refit at the moved
        // model until its step is below the tolerance.
        let linearised = terms.iter().any(|t| matches!(t, Term::LoadCom(_)));
        let geometric = self.p.kinds.absolute && terms.iter().any(is_geometric);
        let mut passes: u32 = if linearised { 5 } else { 1 };
        let mut relinearisations = 0;
        loop {
            let d = self.p.design(terms);
            let cols: Vec<usize> = (0..terms.len()).collect();
            let fit = problem::fit(&d, &cols, None, &self.s)
                .map_err(|e| CalibrationError::Core("fit", e))?;
            let before = self.p.ctx.k.clone();
            self.p.set_estimate(terms, &fit.x);
            passes = passes.saturating_sub(1);
            let moved = before
                .iter()
                .zip(&self.p.ctx.k)
                .any(|(a, b)| (a - b).abs() > 1e-6 * b.abs().max(1e-12));
            let step = terms
                .iter()
                .zip(&fit.x)
                .filter(|(t, _)| is_geometric(t))
                .fold(0.0_f64, |m, (_, v)| m.max(v.abs()));
            let relinearise = geometric
                && step > geometry::STEP_TOLERANCE
                && relinearisations < geometry::MAX_STEPS;
            if relinearise {
                self.p.geometry.apply(terms, &fit.x);
                self.p.relinearise()?;
                relinearisations += 1;
                continue;
            }
            if passes == 0 || !moved {
                let residuals: Vec<Vector3<f64>> = (0..d.rows())
                    .map(|i| d.residual(&cols, &fit.x, i))
                    .collect();
                return Ok(Fitted {
                    terms: terms.to_vec(),
                    rms_um: rms_um(&residuals),
                    fit,
                    geometry: self.p.geometry.clone(),
                    relinearisations,
                    heldout_rms_um: None,
                    residuals,
                });
            }
        }
    }

    /// Puts the problem back at `f`'s model: its compliances for the
    /// linearised effects, its geometry for the absolute rows.
    fn restore(&mut self, f: &Fitted) -> Result<(), CalibrationError> {
        self.p.set_estimate(&f.terms, &f.fit.x);
        self.p.geometry = f.geometry.clone();
        self.p.relinearise()
    }

    /// Leave-one-configuration-out prediction RMS \[µm\].
    fn heldout(&mut self, fitted: &Fitted) -> Result<Option<f64>, CalibrationError> {
        if !self.settings.heldout || self.p.configs.len() < 2 {
            return Ok(None);
        }
        self.restore(fitted)?;
        let d = self.p.design(&fitted.terms);
        let cols: Vec<usize> = (0..fitted.terms.len()).collect();
        let mut res = Vec::with_capacity(d.rows());
        (self.progress)(&format!(
            "held-out RMS: {} fits, one without each configuration",
            self.p.configs.len()
        ));
        for g in 0..self.p.configs.len() {
            // Parameters the other configurations cannot identify are held
            // at zero (their error then shows in the prediction).
            let mut use_cols = cols.clone();
            let fit = loop {
                match problem::fit(&d, &use_cols, Some(g), &self.s) {
                    Ok(f) => break Some(f),
                    Err(Error::NotIdentifiable { column, .. }) if column < use_cols.len() => {
                        use_cols.remove(column);
                    }
                    Err(Error::TooFewEquations { .. }) => break None,
                    Err(e) => return Err(CalibrationError::Core("held-out fit", e)),
                }
            };
            let Some(fit) = fit else { return Ok(None) };
            for i in 0..d.rows() {
                if d.group[i] == g {
                    res.push(d.residual(&use_cols, &fit.x, i));
                }
            }
        }
        self.restore(fitted)?;
        Ok(Some(rms_um(&res)))
    }

    fn with_heldout(&mut self, mut f: Fitted) -> Result<Fitted, CalibrationError> {
        f.heldout_rms_um = self.heldout(&f)?;
        Ok(f)
    }

    fn parameters(&self, f: &Fitted) -> Vec<Parameter> {
        f.terms
            .iter()
            .zip(f.fit.x.iter().zip(&f.fit.std))
            .map(|(t, (&x, &std))| {
                let (unit, _) = self.p.ctx.unit(t);
                let value = if is_geometric(t) {
                    f.geometry.value(t, x)
                } else {
                    x
                };
                Parameter {
                    name: self.p.ctx.name(t),
                    value,
                    std,
                    unit: unit.to_string(),
                }
            })
            .collect()
    }
}

/// One candidate's test in a diagnosis round.
#[derive(Debug, Clone, PartialEq)]
pub struct Tested {
    /// Effect name.
    pub effect: &'static str,
    /// Joint or marker it is about.
    pub about: Option<String>,
    /// Columns tested.
    pub q: usize,
    /// F statistic.
    pub f: f64,
    /// p-value.
    pub p_value: f64,
    /// Drop of the weighted RSS.
    pub delta_rss: f64,
}

/// Runs the calibration: the declared model, then (unless
/// `settings.diagnose` is off) the diagnosis loop. `progress` receives one
/// line per long step.
///
/// The work runs on a thread with a large stack: the fixed-capacity
/// matrices of a 128-column problem are hundreds of kB each.
///
/// # Errors
/// [`CalibrationError`] when the data cannot support the model.
pub fn calibrate(
    job: &Job,
    data: &Measurements,
    settings: &Settings,
    progress: Progress<'_>,
) -> Result<Report, CalibrationError> {
    let problem = Problem::new(job, data, settings.lambda)?;
    let settings = *settings;
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    std::thread::scope(|scope| {
        let worker = std::thread::Builder::new()
            .stack_size(256 << 20)
            .spawn_scoped(scope, move || {
                let mut send = |m: &str| {
                    let _ = tx.send(m.to_string());
                };
                run(problem, &settings, &mut send)
            })
            .map_err(|e| CalibrationError::Data(format!("cannot start the worker: {e}")))?;
        for m in rx {
            progress(&m);
        }
        worker
            .join()
            .unwrap_or_else(|_| Err(CalibrationError::Data("calibration worker panicked".into())))
    })
}

fn run(
    problem: Problem,
    settings: &Settings,
    progress: Progress<'_>,
) -> Result<Report, CalibrationError> {
    let mut notes = Vec::new();
    let mut settings = *settings;
    if let Some(note) = weighting_fallback(&problem, settings.method) {
        (progress)(&note);
        notes.push(note);
        settings.method = Method::Ols;
    }
    let settings = &settings;
    let s = FitSettings {
        method: settings.method,
        weight: problem.weight,
        max_iterations: settings.max_iterations,
    };
    let mut e = Engine {
        p: problem,
        s,
        settings: *settings,
        progress,
    };
    let declared = e.p.model.clone();
    e.p.register_base()?;
    (e.progress)("fitting the declared model");
    let first = e.fit(&declared)?;
    let mut current = e.with_heldout(first)?;
    let declared_rms = (current.rms_um, current.heldout_rms_um);
    let declared_structure = lack_of_fit(&e.p, &current).map(|l| {
        let (variable, _) = most_followed(&e.p, &current);
        Unexplained {
            variable,
            statistic: l.f,
            p_value: l.p_value,
        }
    });
    let mut steps: Vec<EffectStep> = Vec::new();
    let mut unexplained = None;
    let mut last_round: Vec<Tested> = Vec::new();
    let mut plots: Vec<PlotSeries> = Vec::new();
    let mut rejected: Vec<String> = Vec::new();
    if settings.diagnose {
        loop {
            let lof = lack_of_fit(&e.p, &current);
            let cands =
                effects::candidates(&e.p.ctx, &current.terms, e.p.kinds, &e.p.compensator_ok);
            // Every term any candidate may test, after the model.
            let mut terms = current.terms.clone();
            for c in &cands {
                for t in &c.test {
                    if !terms.contains(t) {
                        terms.push(*t);
                    }
                }
            }
            e.restore(&current)?;
            let d = e.p.design(&terms);
            let model_cols: Vec<usize> = (0..current.terms.len()).collect();
            let mut tested: Vec<(usize, Tested)> = Vec::new();
            for (ci, c) in cands.iter().enumerate() {
                let cols: Vec<usize> = c.test.iter().filter_map(|t| d.index(t)).collect();
                let cols = problem::independent(&d, &model_cols, &cols);
                if cols.is_empty() || model_cols.len() + cols.len() > MAX_COLUMNS {
                    continue;
                }
                match problem::test(&d, &model_cols, &cols, &current.fit.weights) {
                    Ok(t) => tested.push((
                        ci,
                        Tested {
                            effect: c.effect,
                            about: about(&e.p.ctx, c),
                            q: t.dof_num,
                            f: t.f,
                            p_value: t.p_value,
                            delta_rss: t.delta_rss,
                        },
                    )),
                    Err(Error::NotIdentifiable { .. } | Error::TooFewEquations { .. }) => {}
                    Err(err) => return Err(CalibrationError::Core("effect test", err)),
                }
            }
            tested.sort_by(|a, b| {
                a.1.p_value
                    .total_cmp(&b.1.p_value)
                    .then(b.1.f.total_cmp(&a.1.f))
            });
            last_round = tested.iter().map(|t| t.1.clone()).collect();
            let tried = tested.len().max(1) as f64;
            let lof_significant = lof.is_some_and(|l| l.p_value < settings.alpha);
            let eligible: Vec<&(usize, Tested)> = tested
                .iter()
                .filter(|(_, t)| {
                    let significant = t.p_value * tried < settings.alpha;
                    let share_ok = match lof {
                        Some(l) if lof_significant && l.excess() > 0.0 => {
                            t.delta_rss >= settings.min_share * l.excess()
                        }
                        _ => true,
                    };
                    significant && share_ok
                })
                .collect();
            if !eligible.is_empty() && steps.len() >= settings.max_effects {
                break;
            }
            // The most significant candidate whose estimate is physical
            // (`inadmissible`) and that lowers the leave-one-configuration-
            // out RMS; one that fails is rejected (a note the first time) and
            // the next is tried.
            let mut accepted = None;
            for (ci, t) in eligible {
                let c = &cands[*ci];
                let on = t
                    .about
                    .as_deref()
                    .map(|a| format!(" on {a}"))
                    .unwrap_or_default();
                let new_terms = extended(&e.p, &current.terms, c);
                let next = e.fit(&new_terms)?;
                let why = match inadmissible(&e.p.ctx, &next.terms, &next.fit.x, &c.add) {
                    Some(why) => Some(format!("rejected: its estimate is not physical ({why})")),
                    None => {
                        // Cross-validation: the effect must also predict the
                        // configurations it was not fitted to better.
                        let next = e.with_heldout(next)?;
                        match (current.heldout_rms_um, next.heldout_rms_um) {
                            (Some(before), Some(after)) if after >= before => Some(format!(
                                "not added: significant (p = {:.1e}) but the \
                                 leave-one-configuration-out RMS does not drop \
                                 ({before:.1} -> {after:.1} um)",
                                t.p_value
                            )),
                            _ => {
                                accepted = Some((*ci, t.clone(), next));
                                break;
                            }
                        }
                    }
                };
                if let Some(why) = why {
                    let key = format!("{}{on}", c.effect);
                    if !rejected.contains(&key) {
                        let note = format!("{key} {why} (step {})", steps.len() + 1);
                        (e.progress)(&note);
                        notes.push(note);
                        rejected.push(key);
                    }
                    e.restore(&current)?;
                }
            }
            let Some((ci, t, next)) = accepted else {
                if lof_significant {
                    let l = lof.unwrap_or(LackOfFit {
                        f: 0.0,
                        p_value: 1.0,
                        ss_lof: 0.0,
                        df_lof: 0,
                        ss_pe: 0.0,
                        df_pe: 0,
                    });
                    let (variable, _) = most_followed(&e.p, &current);
                    unexplained = Some(Unexplained {
                        variable,
                        statistic: l.f,
                        p_value: l.p_value,
                    });
                }
                break;
            };
            let c = &cands[ci];
            (e.progress)(&format!(
                "adding {}{} (p = {:.3e})",
                c.effect,
                t.about
                    .as_deref()
                    .map(|a| format!(" on {a}"))
                    .unwrap_or_default(),
                t.p_value
            ));
            let (var, x) = traced_variable(&e.p, c);
            plots.push(PlotSeries {
                title: format!(
                    "{}{}",
                    c.effect,
                    t.about
                        .as_deref()
                        .map(|a| format!(" {a}"))
                        .unwrap_or_default()
                ),
                variable: var,
                x,
                before_um: current.residuals.iter().map(|r| r * 1e6).collect(),
                after_um: next.residuals.iter().map(|r| r * 1e6).collect(),
            });
            steps.push(EffectStep {
                effect: c.effect.to_string(),
                joint: c.joint.map(|j| e.p.ctx.joint_names[j].clone()),
                marker: c.marker.map(|m| e.p.ctx.markers[m].0),
                p_value: t.p_value,
                f: t.f,
                tried: tested.len(),
                rms_um_before: current.rms_um,
                rms_um_after: next.rms_um,
                heldout_rms_um_before: current.heldout_rms_um,
                heldout_rms_um_after: next.heldout_rms_um,
                parameters_before: e.parameters(&current),
                parameters_after: e.parameters(&next),
            });
            current = next;
        }
    }
    let final_lof = lack_of_fit(&e.p, &current);
    if let Some(u) = &unexplained {
        let x = variable_values(&e.p, &u.variable);
        plots.push(PlotSeries {
            title: format!("unexplained: {}", u.variable),
            variable: u.variable.clone(),
            x,
            before_um: current.residuals.iter().map(|r| r * 1e6).collect(),
            after_um: Vec::new(),
        });
    }
    e.restore(&current)?;
    Ok(Report {
        method: settings.method.name(),
        iterations: current.fit.iterations,
        relinearisations: current.relinearisations,
        converged: current.fit.converged,
        parameters: e.parameters(&current),
        rms_um: current.rms_um,
        heldout_rms_um: current.heldout_rms_um,
        declared_rms_um: declared_rms.0,
        declared_heldout_rms_um: declared_rms.1,
        declared_structure,
        effects: steps,
        unexplained,
        lack_of_fit: final_lof,
        validation: None,
        last_round,
        dropped: e.p.dropped.iter().map(|t| e.p.ctx.name(t)).collect(),
        rows: e.p.rows.len(),
        configurations: e.p.configs.len(),
        plots,
        model: current.terms.clone(),
        x: current.fit.x.clone(),
        problem: e.p,
        notes,
    })
}

/// Fewest rows per configuration for IRLS/WLS: each configuration's σ per
/// axis is estimated from its own rows' residuals, so a configuration with
/// a single row (one marker, no repetition) has no scatter to weight by.
pub const MIN_ROWS_PER_GROUP: usize = 2;

/// When IRLS/WLS cannot estimate a σ per configuration and axis (a
/// configuration with fewer than [`MIN_ROWS_PER_GROUP`] rows), the fit
/// falls back to OLS; the reason, for the report.
fn weighting_fallback(p: &Problem, method: Method) -> Option<String> {
    if method == Method::Ols {
        return None;
    }
    let mut n = vec![0usize; p.configs.len()];
    for r in &p.rows {
        n[r.group] += 1;
    }
    let (g, &fewest) = n.iter().enumerate().min_by_key(|(_, &c)| c)?;
    (fewest < MIN_ROWS_PER_GROUP).then(|| {
        format!(
            "{} needs a scatter per configuration to weight by, and configuration {} has {fewest} row(s) \
             (at least {MIN_ROWS_PER_GROUP}): fitted by OLS instead",
            method.name(),
            p.configs[g]
        )
    })
}

/// The model `terms` with candidate `c` added: its terms go where the terms
/// they replace were, else at the end; then the identifiable subset.
fn extended(p: &Problem, terms: &[Term], c: &Candidate) -> Vec<Term> {
    let at = terms
        .iter()
        .position(|t| c.remove.contains(t))
        .unwrap_or(terms.len());
    let mut new_terms: Vec<Term> = terms[..at]
        .iter()
        .filter(|t| !c.remove.contains(t))
        .copied()
        .collect();
    new_terms.extend(c.add.iter().filter(|a| !terms.contains(a)));
    new_terms.extend(terms[at..].iter().filter(|t| !c.remove.contains(t)));
    let d2 = p.design(&new_terms);
    let all: Vec<usize> = (0..new_terms.len()).collect();
    let keep = problem::independent(&d2, &[], &all);
    keep.iter().map(|&i| new_terms[i]).collect()
}

/// Largest admissible first-harmonic gear cyclic error amplitude \[mrad\]
/// (`hypot(sin, cos)`): a gear's transmission error is a fraction of a
/// milliradian to a few; 10 mrad (0.6°) would be a broken gear.
pub const MAX_CYCLIC_MRAD: f64 = 10.0;
/// Largest admissible measurement drift \[mm/h\] (norm over x, y, z): a
/// thermal drift of a tracker or of the robot's base is a fraction of a
/// millimetre per hour; 5 mm/h is not a drift but a moving base.
pub const MAX_DRIFT_MM_PER_H: f64 = 5.0;

/// Why the estimate `x` of `terms` is not physical for the effect terms
/// `added`, if it is not. Physics, not tuning:
/// - a compliance (`k_<joint>`, `k_<joint>@<angle>`) is ≥ 0: a joint
///   yields in the direction of its torque;
/// - a backlash (`δq = b · sign τ`) is ≥ 0: the joint rests on the side of
///   its play that its torque pushes it to;
/// - a gear cyclic error is at most [`MAX_CYCLIC_MRAD`];
/// - a drift is at most [`MAX_DRIFT_MM_PER_H`].
pub fn inadmissible(ctx: &Context, terms: &[Term], x: &[f64], added: &[Term]) -> Option<String> {
    let value = |t: &Term| terms.iter().position(|u| u == t).map(|i| x[i]);
    for t in added {
        let Some(v) = value(t) else { continue };
        let (unit, _) = ctx.unit(t);
        let bad = match *t {
            Term::Compliance(_) | Term::ComplianceAt(..) | Term::Backlash(_) => {
                (v < 0.0).then(|| format!("{} = {v:.3} {unit} < 0", ctx.name(t)))
            }
            Term::GearCyclic(j, false) => {
                let c = value(&Term::GearCyclic(j, true)).unwrap_or(0.0);
                let amp = v.hypot(c);
                (amp > MAX_CYCLIC_MRAD).then(|| {
                    format!(
                        "gear_cyclic_{} amplitude {amp:.3} mrad > {MAX_CYCLIC_MRAD} mrad",
                        ctx.joint_names[j]
                    )
                })
            }
            Term::Drift(0) => {
                // µm/s → mm/h.
                let norm = (0..3)
                    .map(|a| value(&Term::Drift(a)).unwrap_or(0.0).powi(2))
                    .sum::<f64>()
                    .sqrt()
                    * 3.6;
                (norm > MAX_DRIFT_MM_PER_H)
                    .then(|| format!("drift {norm:.3} mm/h > {MAX_DRIFT_MM_PER_H} mm/h"))
            }
            _ => None,
        };
        if bad.is_some() {
            return bad;
        }
    }
    None
}

fn about(ctx: &Context, c: &Candidate) -> Option<String> {
    if let Some(j) = c.joint {
        return Some(ctx.joint_names[j].clone());
    }
    c.marker.map(|m| format!("marker {}", ctx.markers[m].0))
}

/// Evaluates a calibration's final model on another measurement file of the
/// same job without re-estimating anything (`--validate`): the norm RMSE
/// of each marker's position error \[mm\].
///
/// # Errors
/// [`CalibrationError::Data`] when a row cannot be predicted (an angle
/// outside every compensator bin of the calibration).
pub fn validate(
    report: &Report,
    job: &Job,
    data: &Measurements,
) -> Result<Validation, CalibrationError> {
    let p0 = &report.problem;
    let mut p = Problem::new(job, data, None)?;
    p.ctx = p0.ctx.clone();
    // The calibrated model, nothing re-estimated on these data.
    p.geometry = p0.geometry.clone();
    p.relinearise()?;
    // Rows of the kinds the calibration used.
    p.rows.retain(|r| match r.kind {
        RowKind::Deflection => p0.kinds.deflections,
        RowKind::Absolute => p0.kinds.absolute,
    });
    for row in &p.rows {
        for t in &report.model {
            if let Term::ComplianceAt(j, _) = *t {
                if p.ctx.bin_of(j, row.q[j]).is_none() {
                    return Err(CalibrationError::Data(format!(
                        "{}:{}: joint '{}' is at an angle the calibration has no compliance for",
                        data.file.display(),
                        row.line,
                        p.ctx.joint_names[j]
                    )));
                }
            }
        }
    }
    let d = Design::new(&p.ctx, &p.rows, &report.model, p.configs.len());
    let cols: Vec<usize> = (0..report.model.len()).collect();
    let mut all = Vec::new();
    let mut per: BTreeMap<u32, Vec<Vector3<f64>>> = BTreeMap::new();
    for i in 0..d.rows() {
        let r = d.residual(&cols, &report.x, i);
        all.push(r);
        per.entry(p.rows[i].marker).or_default().push(r);
    }
    Ok(Validation {
        rms_mm: rms_um(&all) * 1e-3,
        per_marker_rms_mm: per
            .into_iter()
            .map(|(m, v)| (m.to_string(), rms_um(&v) * 1e-3))
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chain::JointKind;

    fn ctx() -> Context {
        Context {
            joint_names: vec!["a1".into(), "a2".into()],
            joint_kinds: vec![JointKind::Revolute; 2],
            markers: vec![(1, Vector3::zeros())],
            bins: vec![Vec::new(); 2],
            bin_tolerance: BIN_TOLERANCE_RAD,
            k: vec![0.0; 2],
            k_bins: vec![Vec::new(); 2],
        }
    }

    #[test]
    fn physical_limits_reject_impossible_estimates() {
        let c = ctx();
        let k = [Term::Compliance(1)];
        assert!(inadmissible(&c, &k, &[0.5], &k).is_none());
        assert!(inadmissible(&c, &k, &[-0.5], &k).unwrap().contains("< 0"));
        let b = [Term::Backlash(0)];
        assert!(inadmissible(&c, &b, &[-1.0], &b).is_some());
        assert!(inadmissible(&c, &b, &[1.0], &b).is_none());
        // A negative compliance already in the model is not the candidate's.
        let terms = [Term::Compliance(0), Term::Backlash(1)];
        assert!(inadmissible(&c, &terms, &[-1.0, 1.0], &[Term::Backlash(1)]).is_none());
        let cyc = [Term::GearCyclic(0, false), Term::GearCyclic(0, true)];
        assert!(inadmissible(&c, &cyc, &[6.0, 8.0], &cyc).is_none()); // 10 mrad
        assert!(inadmissible(&c, &cyc, &[6.0, 8.1], &cyc).is_some());
        let drift = [Term::Drift(0), Term::Drift(1), Term::Drift(2)];
        // 1 µm/s = 3.6 mm/h.
        assert!(inadmissible(&c, &drift, &[1.0, 0.0, 0.0], &drift).is_none());
        assert!(inadmissible(&c, &drift, &[1.0, 1.0, 0.0], &drift).is_some());
    }
}
