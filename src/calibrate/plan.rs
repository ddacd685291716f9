//! Choosing the poses before measuring (`robcal plan`): of a pool of
//! candidate configurations (random within the joint limits, or the
//! user's), the `K` whose rows make the declared model best determined.
//!
//! Each candidate is a configuration and a payload mass: its rows are the
//! ones a measurement there gives the declared model — every marker's
//! absolute position when the model needs them, and every marker's
//! deflection under the payload when the mass is not zero; with a 6-D
//! instrument ([`PlanSettings::orientation_sigma_urad`]) every absolute
//! position's orientation too — built by the engine's own rows and design
//! at the nominal robot ([`crate::calibrate::varied`] does the same for its
//! poses). Each row is weighted by the instrument's σ (the setup's `σ0`; a
//! deflection's by `√2 σ0`; an orientation's by the 6-D instrument's σ in
//! rad), and each parameter's column is scaled to unit root mean
//! square over the pool, so that the criteria compare parameters of
//! different units. With `Λ` the information of the chosen candidates:
//!
//! | criterion | maximises | |
//! |---|---|---|
//! | `d` (default) | `ln det Λ` | the volume of the confidence ellipsoid; invariant to the parameters' units |
//! | `a` | `−trace Λ⁻¹` | the sum of the (scaled) variances |
//! | `i` | `−trace(W Λ⁻¹)`, `W` the mean `bᵀb` over the pool's rows | the mean variance of the calibrated model's prediction over the pool: the predicted error after calibration, squared |
//! | `e` | `λmin(Λ)` | the worst-determined direction |
//! | `condition` | `−√(λmax / λmin)` | the condition number of the weighted, scaled design (the usual "observability index" of calibration tools) |
//!
//! Selection is greedy (each step takes the candidate that improves the
//! criterion most; for `d` by the determinant lemma of the core,
//! [`crate::estimate::plan::gain`], the step a controller takes), then
//! refined by exchange: each chosen candidate is replaced by the best one
//! not chosen while that improves the criterion, for at most
//! [`PlanSettings::exchange_passes`] passes. Before the chosen rows
//! identify every parameter a prior keeps `Λ` invertible: `10⁻⁶` of one
//! candidate's mean information per parameter
//! ([`crate::estimate::plan::prior`]), times the candidates chosen so far;
//! the scores reported are without it. A controller choosing as it
//! measures takes the same steps ([`crate::estimate::plan::next_best`]).
//!
//! A parameter that no candidate of the pool determines (the independence
//! test on the whole pool, [`crate::estimate::rank`]) is left out and named:
//! no choice of these poses identifies it. A compliance by angle
//! (`compliance_by_angle`) keeps its bins when the candidates' angles make
//! them (a pool at the compensator's angles); random candidates take too
//! many angles, and it is then planned as one compliance per joint.

use std::borrow::Cow;

use nalgebra::{DMatrix, DVector, Dyn, OMatrix, Vector3};

use crate::calibrate::effects::declared;
use crate::calibrate::engine::Engine;
use crate::calibrate::params::linearisation::{DeflectionModel, Linearisation};
use crate::calibrate::params::names::Names;
use crate::calibrate::rows::{RowKind, Rows};
use crate::calibrate::settings::{CalibrationError, Policy};
use crate::estimate::Block;
use crate::io::error::InputError;
use crate::io::job::Job;
use crate::io::measurements::{Deflection, JointValues, Measurements, Observation};
use crate::model::Param;
use crate::robot::JointKind;

/// Candidates a pool holds at most: 100 000 (a greedy step weighs every
/// candidate: at 10⁵ candidates, K = 60 and 25 parameters a plan takes
/// about 23 s on two cores).
pub const MAX_CANDIDATES: usize = 100_000;

/// What [`choose`] maximises (the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Criterion {
    /// `ln det Λ` (D-optimal).
    D,
    /// `−trace Λ⁻¹` (A-optimal).
    A,
    /// `−trace(W Λ⁻¹)`, `W` the mean `bᵀb` of the pool's rows (I-optimal):
    /// the mean variance of the calibrated model's prediction over the
    /// pool, [`Scores::predicted_um`] squared.
    I,
    /// `λmin(Λ)` (E-optimal).
    E,
    /// `−√(λmax/λmin)`: the condition number of the weighted design.
    Condition,
}

impl Criterion {
    /// Its name on the command line and in the JSON.
    pub fn name(self) -> &'static str {
        match self {
            Criterion::D => "d",
            Criterion::A => "a",
            Criterion::I => "i",
            Criterion::E => "e",
            Criterion::Condition => "condition",
        }
    }
}

/// How a plan is made.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanSettings {
    /// Configurations to choose, `K`.
    pub poses: usize,
    /// Random candidates to draw (without a pool of the user's).
    pub candidates: usize,
    /// What to maximise.
    pub criterion: Criterion,
    /// Seed of the random candidates.
    pub seed: u64,
    /// Payload masses \[kg\] a candidate may carry (a compliance needs one
    /// above zero); none: unloaded only.
    pub loads_kg: Vec<f64>,
    /// Joint limits tighter than the URDF's: name, lower, upper \[rad or
    /// m\].
    pub limits: Vec<(String, f64, f64)>,
    /// Exchange passes at most after the greedy selection. 0: greedy only.
    pub exchange_passes: usize,
    /// A 6-D instrument's σ of an orientation per axis \[µrad\]: each
    /// candidate's absolute positions are measured as poses, their
    /// orientations' rows beside the points'. `None`: points only.
    pub orientation_sigma_urad: Option<f64>,
}

impl Default for PlanSettings {
    fn default() -> Self {
        Self {
            poses: 30,
            candidates: 1000,
            criterion: Criterion::D,
            seed: 0x706c_616e,
            loads_kg: Vec::new(),
            limits: Vec::new(),
            exchange_passes: 10,
            orientation_sigma_urad: None,
        }
    }
}

/// A candidate measurement: a configuration and a payload.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// Joint values \[rad or m\], chain order.
    pub q: Vec<f64>,
    /// Payload mass \[kg\] (0: unloaded).
    pub load_kg: f64,
}

/// How well a selection determines the model (without the prior): the
/// criteria of the module docs on the scaled information `Λ`, and what
/// they predict.
#[derive(Debug, Clone, PartialEq)]
pub struct Scores {
    /// `ln det Λ` (−∞ when singular).
    pub log_det: f64,
    /// `trace Λ⁻¹` (scaled variances; ∞ when singular).
    pub trace: f64,
    /// `λmin(Λ)`.
    pub min_eigen: f64,
    /// `√(λmax/λmin)`.
    pub condition: f64,
    /// Predicted σ of each parameter, reported units (∞ when singular).
    pub std: Vec<f64>,
    /// Predicted error of the calibrated model's prediction after
    /// calibration, over every row of the pool \[µm\]: the root mean square
    /// of `√trace(B Σ Bᵀ)` (`Σ = Λ⁻¹` unscaled), the noise of the
    /// measurements not included.
    pub predicted_um: f64,
}

/// The pool's rows as blocks, per candidate, on the identifiable
/// parameters.
pub struct Pool {
    /// The mean `bᵀb` of the pool's rows (scaled, unweighted): the `W` of
    /// criterion `i`.
    w: DMatrix<f64>,
    /// The candidates.
    pub candidates: Vec<Candidate>,
    /// Each candidate's blocks: one per row (marker), `B` scaled per
    /// column, `w = 1/σ`.
    blocks: Vec<Vec<Block<f64, Dyn>>>,
    /// Each parameter's scale: the root mean square of its column over the
    /// pool's rows \[m per reported unit\].
    scale: Vec<f64>,
    /// The parameters kept (determinable from the pool).
    pub params: Vec<String>,
    /// Their units.
    pub units: Vec<String>,
    /// The declared parameters no candidate of the pool determines.
    pub left_out: Vec<String>,
    /// Notes: what the plan assumed.
    pub notes: Vec<String>,
}

/// A plan: the chosen candidates and what they predict.
pub struct Planned {
    /// The criterion.
    pub criterion: Criterion,
    /// Indices into [`Pool::candidates`], in the order chosen.
    pub chosen: Vec<usize>,
    /// Their scores.
    pub scores: Scores,
    /// Greedy steps and exchanges made.
    pub exchanges: usize,
}

/// Uniform values in [0, 1) from `seed` (a linear congruential generator:
/// the same candidates on every machine).
fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed ^ 0x9e37_79b9_7f4a_7c15;
    move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Each joint's range for random candidates: `limits` by name, else the
/// URDF's, else a turn for a revolute joint.
///
/// # Errors
/// [`CalibrationError::Data`] for a limit naming no joint, one outside the
/// URDF's or empty, or a prismatic joint without limits.
fn ranges(job: &Job, limits: &[(String, f64, f64)]) -> Result<Vec<(f64, f64)>, CalibrationError> {
    let chain = &job.robot.chain;
    let mut out = Vec::with_capacity(job.robot.dof());
    for j in 0..job.robot.dof() {
        let urdf = job.robot.limits.get(j).copied().flatten();
        let name = &job.robot.joint_names[j];
        let mut r = match (urdf, chain.joints()[j].kind) {
            (Some(l), _) => (l.lower, l.upper),
            (None, JointKind::Revolute) => (-core::f64::consts::PI, core::f64::consts::PI),
            (None, JointKind::Prismatic) => {
                if let Some((_, lo, hi)) = limits.iter().find(|l| &l.0 == name) {
                    (*lo, *hi)
                } else {
                    return Err(CalibrationError::Data(format!(
                        "prismatic joint '{name}' has no limits in the URDF: give them (--limit {name}=LO:HI)"
                    )));
                }
            }
        };
        if let Some((_, lo, hi)) = limits.iter().find(|l| &l.0 == name) {
            if lo >= hi || *lo < r.0 - 1e-12 || *hi > r.1 + 1e-12 {
                return Err(CalibrationError::Data(format!(
                    "--limit {name}={lo}:{hi}: not a range within the URDF's [{}, {}]",
                    r.0, r.1
                )));
            }
            r = (*lo, *hi);
        }
        out.push(r);
    }
    for (name, _, _) in limits {
        if !job.robot.joint_names.iter().any(|n| n == name) {
            return Err(CalibrationError::Data(format!(
                "--limit names unknown joint '{name}' (joints: {})",
                job.robot.joint_names.join(", ")
            )));
        }
    }
    Ok(out)
}

/// `n` random candidates of `job`'s robot within the joint ranges (the
/// URDF's limits, tighter ones of `s.limits`), each configuration with
/// every mass of `s.loads_kg` (0 when none is given; a zero mass left out
/// when the model needs no absolute position).
///
/// # Errors
/// [`CalibrationError::Data`] for a limit naming no joint, one outside the
/// URDF's or empty, a prismatic joint without limits, or a model of
/// compliances alone without a payload mass above zero.
pub fn random_candidates(job: &Job, s: &PlanSettings) -> Result<Vec<Candidate>, CalibrationError> {
    let range = ranges(job, &s.limits)?;
    let absolute = declared::needs_absolute(job);
    let mut loads: Vec<f64> = if s.loads_kg.is_empty() {
        vec![0.0]
    } else {
        s.loads_kg.clone()
    };
    if !absolute {
        loads.retain(|&m| m > 0.0);
        if loads.is_empty() {
            return Err(CalibrationError::Data(
                "the model has compliances alone: a candidate needs a payload; give its mass \
                 (--load-kg)"
                    .into(),
            ));
        }
    }
    let mut next = uniform(s.seed);
    let mut out = Vec::with_capacity(s.candidates);
    'draw: loop {
        let q: Vec<f64> = range
            .iter()
            .map(|&(lo, hi)| lo + (hi - lo) * next())
            .collect();
        for &m in &loads {
            if out.len() == s.candidates {
                break 'draw;
            }
            out.push(Candidate {
                q: q.clone(),
                load_kg: m,
            });
        }
        if loads.is_empty() {
            break;
        }
    }
    Ok(out)
}

/// Candidates of the user's: the points CSV at `path` (`robcal plan
/// --pool`; `<joint>_rad`/`_m` per joint, optional `load_kg`; `marker`,
/// `id` and the centre of mass ignored: the setup's is planned for).
///
/// # Errors
/// The file cannot be read, or a row is not one of the points CSV
/// ([`crate::io::points::parse_points`]): its line and column.
pub fn read_pool(job: &Job, path: &std::path::Path) -> Result<Vec<Candidate>, InputError> {
    let text = crate::io::input::read_text(
        path,
        "the candidate poses",
        crate::io::input::MAX_DATA_BYTES,
    )?;
    let joints: Vec<_> = (job.robot.joint_names.iter().cloned())
        .zip(job.robot.chain.joints().iter().map(|j| j.kind))
        .collect();
    Ok(
        crate::io::points::parse_points(&text, path, &joints, false)?
            .into_iter()
            .map(|r| Candidate {
                q: r.q,
                load_kg: r.load_kg,
            })
            .collect(),
    )
}

/// A plan made as `robcal plan` makes it: `settings.candidates` random
/// candidates ([`random_candidates`]) unless `pool` gives them, their
/// [`Pool`], the choice ([`choose`]), and the scores of the first `K`
/// random candidates as drawn (what measuring without a plan gives; `None`
/// for a pool of the user's).
///
/// # Errors
/// As [`random_candidates`], [`pool`] and [`choose`].
pub fn make(
    job: &Job,
    settings: &PlanSettings,
    pool_candidates: Option<Vec<Candidate>>,
    policy: &Policy,
) -> Result<(Pool, Planned, Option<Scores>), CalibrationError> {
    let random = pool_candidates.is_none();
    let candidates = match pool_candidates {
        Some(c) => c,
        None => random_candidates(job, settings)?,
    };
    let pool = pool(job, candidates, settings.orientation_sigma_urad, policy)?;
    let planned = choose(
        &pool,
        settings.poses,
        settings.criterion,
        settings.exchange_passes,
    )?;
    let baseline = random.then(|| {
        let first: Vec<usize> = (0..settings.poses.min(pool.candidates.len())).collect();
        pool.scores(&first)
    });
    Ok((pool, planned, baseline))
}

/// The candidates `chosen` of `pool` as the points CSV of `robcal
/// predict` (what `robcal plan --output` writes): `id` (`plan1`, …),
/// `load_kg`, the setup's payload centre of mass (the plan's), one column
/// per joint in rad or m; numbers as Rust writes them back exactly.
pub fn points_csv(job: &Job, pool: &Pool, chosen: &[usize]) -> String {
    use std::fmt::Write as _;
    let com = job.setup.load.map_or([0.0; 3], |l| l.com);
    let mut csv = String::from("id,load_kg,com_x_m,com_y_m,com_z_m");
    for (name, j) in job.robot.joint_names.iter().zip(job.robot.chain.joints()) {
        csv.push(',');
        csv += &crate::io::points::joint_column(name, j.kind);
    }
    csv.push('\n');
    for (k, &c) in chosen.iter().enumerate() {
        let cand = &pool.candidates[c];
        let _ = write!(
            csv,
            "plan{},{},{:?},{:?},{:?}",
            k + 1,
            cand.load_kg,
            com[0],
            com[1],
            com[2]
        );
        for v in &cand.q {
            let _ = write!(csv, ",{v:?}");
        }
        csv.push('\n');
    }
    csv
}

/// The rows of `candidates` for `job`'s declared model, as a [`Pool`].
///
/// # Errors
/// [`CalibrationError::Data`] for more than [`MAX_CANDIDATES`]
/// candidates, when none gives a row (unloaded ones for a model of
/// compliances alone), when the model has a compliance
/// and no candidate a payload, or when no parameter is determinable;
/// as [`Rows::from_measurements`] and [`Engine::design`].
pub fn pool(
    job: &Job,
    candidates: Vec<Candidate>,
    orientation_sigma_urad: Option<f64>,
    policy: &Policy,
) -> Result<Pool, CalibrationError> {
    if let Some(s) = orientation_sigma_urad {
        if !(s.is_finite() && s > 0.0) {
            return Err(CalibrationError::Data(format!(
                "the orientation's sigma: {s} urad, not a positive number"
            )));
        }
    }
    if candidates.is_empty() {
        return Err(CalibrationError::Data(
            "no candidate pose to choose from".into(),
        ));
    }
    if candidates.len() > MAX_CANDIDATES {
        return Err(CalibrationError::Data(format!(
            "{} candidate poses: at most {MAX_CANDIDATES} are planned from",
            candidates.len()
        )));
    }
    let mut notes = Vec::new();
    let mut job = job.clone();
    let absolute = declared::needs_absolute(&job);
    let compliance = !job.setup.model.compliance.is_empty();
    if compliance && !candidates.iter().any(|c| c.load_kg > 0.0) {
        return Err(CalibrationError::Data(
            "the model has compliances and no candidate carries a payload: give its mass (--load-kg)"
                .into(),
        ));
    }
    // Candidates that repeat one another, or give no row (unloaded, for a
    // model of compliances alone), are not candidates.
    let given = candidates.len();
    let mut candidates = candidates;
    let mut seen = std::collections::HashSet::new();
    candidates.retain(|c| {
        let key: Vec<u64> = (c.q.iter().chain([&c.load_kg]))
            .map(|v| v.to_bits())
            .collect();
        seen.insert(key)
    });
    let repeated = given - candidates.len();
    if !absolute {
        candidates.retain(|c| c.load_kg > 0.0);
    }
    let unloaded = given - repeated - candidates.len();
    if repeated > 0 || unloaded > 0 {
        notes.push(format!(
            "{} of {given} candidates: {repeated} repeated another, {unloaded} unloaded (the \
             model needs deflections)",
            candidates.len()
        ));
    }
    if candidates.is_empty() {
        return Err(CalibrationError::Data(
            "no candidate gives a row for the declared model (a model of compliances alone \
             needs candidates with a payload)"
                .into(),
        ));
    }
    if orientation_sigma_urad.is_some() && !absolute {
        notes.push(
            "orientations: none planned (the model is of deflections alone, and a \
             deflection's turn is not a row)"
                .into(),
        );
    }
    let dof = job.robot.dof();
    let mut observations = Vec::new();
    let mut deflections = Vec::new();
    for (c, cand) in candidates.iter().enumerate() {
        if cand.q.len() != dof {
            return Err(CalibrationError::Data(format!(
                "candidate {}: {} joint values for {dof} joints",
                c + 1,
                cand.q.len()
            )));
        }
        let q: JointValues = cand.q.iter().copied().collect();
        for m in &job.setup.markers {
            let unloaded = observations.len();
            observations.push(Observation {
                config: c as i64,
                rep: 1,
                marker: m.id,
                q: q.clone(),
                // A pose's orientation: its value is not read (the rows'
                // columns are), the turn rows are made.
                r_rad: orientation_sigma_urad.map(|_| [0.0; 3]),
                ..Observation::default()
            });
            if cand.load_kg > 0.0 {
                deflections.push(Deflection {
                    config: c as i64,
                    rep: 1,
                    marker: m.id,
                    load_kg: cand.load_kg,
                    q: q.clone(),
                    dp_m: [0.0; 3],
                    lines: [0, 0],
                    rows: [unloaded, unloaded],
                });
            }
        }
    }
    let poses = Measurements {
        file: "candidate poses".into(),
        observations,
        deflections,
        has_time: false,
        warnings: Vec::new(),
        cells_in_file: None,
    };
    let mut names = Names {
        joints: job.robot.joint_names.clone(),
        kinds: job.robot.chain.joints().iter().map(|j| j.kind).collect(),
        markers: (job.setup.markers.iter())
            .map(|m| (m.id, Vector3::from(m.xyz)))
            .collect(),
        bins: Default::default(),
    };
    let rows = Rows::build(&job, Cow::Borrowed(&poses), absolute, &mut names, policy)?;
    // A compliance by angle keeps its bins when the candidates' angles
    // make them (a pool of the user's at a compensator's angles); else it
    // is planned as one compliance per joint.
    let binned = |rows: &Rows| {
        (job.setup.model.compliance_by_angle.iter()).all(|name| {
            job.robot
                .joint_index(name)
                .is_some_and(|j| rows.bins.get(j).is_some_and(|b| !b.is_empty()))
        })
    };
    let rows = if binned(&rows) {
        rows
    } else {
        notes.push(format!(
            "compliance_by_angle ({}) planned as one compliance per joint: the candidates take \
             too many angles for its bins (give a pool at the compensator's angles to plan them)",
            job.setup.model.compliance_by_angle.join(", ")
        ));
        for name in std::mem::take(&mut job.setup.model.compliance_by_angle) {
            if !job.setup.model.compliance.contains(&name) {
                job.setup.model.compliance.push(name);
            }
        }
        names.bins.clear();
        Rows::build(&job, Cow::Owned(poses), absolute, &mut names, policy)?
    };
    let model = declared::declared(&job, std::path::Path::new("candidate poses"), &rows, &names)?;
    let mut quiet = |_: &str| {};
    let mut e = Engine::nominal(
        &job,
        rows,
        names,
        Linearisation::nominal(DeflectionModel::Exact),
        crate::calibrate::fit::FitSettings {
            method: crate::calibrate::settings::Method::Ols,
            weight: crate::estimate::RobustWeight::new(1.0, 0.0)
                .map_err(|e| CalibrationError::Core("noise settings", e))?,
            max_iterations: 1,
            tolerance: policy.irls_tolerance,
            weighting: crate::calibrate::fit::Weighting::Estimated,
        },
        *policy,
        &mut quiet,
    );
    e.relinearise_for(&model)?;
    let design = e.design(&model)?;
    let all: Vec<usize> = (0..model.len()).collect();
    let kept: Vec<bool> = match design.identifiability(&[], &all) {
        Some(rank) => (0..model.len()).map(|i| rank.kept[i]).collect(),
        None => vec![false; model.len()],
    };
    let cols: Vec<usize> = (0..model.len()).filter(|&i| kept[i]).collect();
    if cols.is_empty() {
        return Err(CalibrationError::Data(
            "no parameter of the declared model is determinable from these candidates".into(),
        ));
    }
    let name = |p: &Param| e.names.name(p);
    let left_out: Vec<String> = (0..model.len())
        .filter(|&i| !kept[i])
        .map(|i| name(&model[i]))
        .collect();
    let params: Vec<String> = cols.iter().map(|&i| name(&model[i])).collect();
    let units: Vec<String> = (cols.iter())
        .map(|&i| e.names.unit(&model[i]).name.to_string())
        .collect();
    // Each row's columns and weight.
    let sigma0 = job.setup.noise.sigma0_um * 1e-6;
    let mixed = e.rows.mixed();
    let n = cols.len();
    let mut per_row: Vec<(usize, OMatrix<f64, nalgebra::U3, Dyn>, f64)> =
        Vec::with_capacity(e.rows.rows.len());
    let mut buf = Vec::new();
    for (i, row) in e.rows.rows.iter().enumerate() {
        design.rows_into(&[i], &cols, &mut buf);
        let b = OMatrix::<f64, nalgebra::U3, Dyn>::from_fn_generic(nalgebra::U3, Dyn(n), |a, k| {
            buf[a * n + k]
        });
        // A deflection is two points: √2 σ0. (With rows of both kinds the
        // design holds it over √2: its columns back to the deflection's,
        // for the predictions.)
        let root2 = std::f64::consts::SQRT_2;
        let (b, sigma) = match (row.kind, orientation_sigma_urad) {
            (RowKind::Absolute, Some(s)) if row.orientation => (b, s * 1e-6),
            (RowKind::Deflection, _) if mixed => (b * root2, sigma0 * root2),
            (RowKind::Deflection, _) => (b, sigma0 * root2),
            (RowKind::Absolute, _) => (b, sigma0),
        };
        per_row.push((row.group(), b, 1.0 / sigma));
    }
    let mut scale = vec![0.0; n];
    for (_, b, _) in &per_row {
        for k in 0..n {
            scale[k] += b.column(k).norm_squared();
        }
    }
    for s in &mut scale {
        *s = (*s / per_row.len().max(1) as f64).sqrt();
        if *s <= 0.0 || !s.is_finite() {
            *s = 1.0;
        }
    }
    let configs = &e.rows.configs;
    let mut blocks: Vec<Vec<Block<f64, Dyn>>> = vec![Vec::new(); candidates.len()];
    for (g, mut b, w) in per_row {
        for k in 0..n {
            let s = scale[k];
            b.column_mut(k).unscale_mut(s);
        }
        let c = usize::try_from(configs[g]).unwrap_or(usize::MAX);
        if let Some(list) = blocks.get_mut(c) {
            list.push(Block::new(b, Vector3::zeros()).with_weights(Vector3::repeat(w)));
        }
    }
    if let Some(c) = blocks.iter().position(Vec::is_empty) {
        return Err(CalibrationError::Data(format!(
            "candidate {}: gives no row for the declared model",
            c + 1
        )));
    }
    let mut w = DMatrix::zeros(n, n);
    let mut count = 0usize;
    for list in &blocks {
        for b in list {
            for a in 0..b.rows {
                let r = b.b.row(a).transpose();
                w.ger(1.0, &r, &r, 1.0);
            }
            count += 1;
        }
    }
    w /= count.max(1) as f64;
    Ok(Pool {
        w,
        candidates,
        blocks,
        scale,
        params,
        units,
        left_out,
        notes,
    })
}

impl Pool {
    /// Number of (kept) parameters.
    pub fn parameters(&self) -> usize {
        self.scale.len()
    }

    /// `Σ GᵀG` of a candidate's rows added to `lambda`, times `sign`.
    fn add(&self, lambda: &mut DMatrix<f64>, c: usize, sign: f64) {
        for b in &self.blocks[c] {
            for a in 0..b.rows {
                let w2 = b.w[a] * b.w[a] * sign;
                let r = b.b.row(a);
                lambda.ger(w2, &r.transpose(), &r.transpose(), 1.0);
            }
        }
    }

    /// The scaled information of the candidates `chosen`.
    pub fn information(&self, chosen: &[usize]) -> DMatrix<f64> {
        let n = self.parameters();
        let mut l = DMatrix::zeros(n, n);
        for &c in chosen {
            self.add(&mut l, c, 1.0);
        }
        l
    }

    /// Candidate `c`'s rows as the core's blocks (`B` scaled per column,
    /// `w = 1/σ`): what [`crate::estimate::plan::gain`] reads.
    pub fn blocks(&self, c: usize) -> &[Block<f64, Dyn>] {
        self.blocks.get(c).map_or(&[], Vec::as_slice)
    }

    /// The prior `Λ₀` of the first choice (module docs): the core's
    /// ([`crate::estimate::plan::prior`]), 10⁻⁶ of one candidate's mean
    /// information per parameter.
    pub fn prior(&self) -> DVector<f64> {
        let mut p = DVector::zeros(self.parameters());
        if crate::estimate::plan::prior(&self.blocks, &mut p).is_err() {
            p.fill(1e-6);
        }
        p
    }

    /// The criterion's value of the information `lambda` (larger is
    /// better): `ln det`, `−trace Λ⁻¹`, `λmin`, `−√(λmax/λmin)`.
    fn value(&self, criterion: Criterion, lambda: &DMatrix<f64>) -> f64 {
        match criterion {
            Criterion::I => match lambda.clone().cholesky() {
                Some(c) => -(&self.w * c.inverse()).trace(),
                None => f64::NEG_INFINITY,
            },
            Criterion::D => match lambda.clone().cholesky() {
                Some(c) => 2.0 * c.l_dirty().diagonal().iter().map(|d| d.ln()).sum::<f64>(),
                None => f64::NEG_INFINITY,
            },
            Criterion::A => match lambda.clone().cholesky() {
                Some(c) => -c.inverse().trace(),
                None => f64::NEG_INFINITY,
            },
            Criterion::E | Criterion::Condition => {
                let ev = lambda.clone().symmetric_eigenvalues();
                let (lo, hi) = ev.iter().fold((f64::INFINITY, 0.0_f64), |(lo, hi), &v| {
                    (lo.min(v), hi.max(v))
                });
                match criterion {
                    Criterion::E => lo,
                    _ if lo > 0.0 => -(hi / lo).sqrt(),
                    _ => f64::NEG_INFINITY,
                }
            }
        }
    }

    /// Each candidate's improvement of the criterion over `lambda` (with
    /// the prior), `NEG_INFINITY` for those `skip`ped.
    fn gains(
        &self,
        criterion: Criterion,
        lambda: &DMatrix<f64>,
        prior: &DVector<f64>,
        skip: &[bool],
    ) -> Result<Vec<f64>, CalibrationError> {
        let n = self.parameters();
        let core = |e| CalibrationError::Core("plan", e);
        // (Worker threads for a pool worth them: a gain is ~n² flops.)
        let threads = if self.blocks.len() * n * n >= 1 << 16 {
            crate::parallel::threads()
        } else {
            1
        };
        match criterion {
            Criterion::D => {
                let f = crate::estimate::plan::with_prior(lambda, prior, &vec![true; n])
                    .map_err(core)?;
                let g = crate::parallel::map(self.blocks.len(), threads, |c| {
                    if skip[c] {
                        Ok(f64::NEG_INFINITY)
                    } else if self.blocks[c].len() <= crate::estimate::plan::MAX_BLOCKS {
                        crate::estimate::plan::gain(&f, &self.blocks[c])
                    } else {
                        Ok(many_blocks_gain(&f, &self.blocks[c]))
                    }
                });
                g.into_iter().collect::<Result<Vec<_>, _>>().map_err(core)
            }
            Criterion::A | Criterion::I => {
                // The reduction of trace(W Λ⁻¹) by the candidate's rows G
                // (Woodbury): trace(S⁻¹ Yᵀ W Y), Y = Λ⁻¹Gᵀ, S = I + G Y
                // (W = I for `a`).
                let f = crate::estimate::plan::with_prior(lambda, prior, &vec![true; n])
                    .map_err(core)?;
                let w = (criterion == Criterion::I).then_some(&self.w);
                Ok(crate::parallel::map(self.blocks.len(), threads, |c| {
                    if skip[c] {
                        return f64::NEG_INFINITY;
                    }
                    let rows: Vec<DVector<f64>> = (self.blocks[c].iter())
                        .flat_map(|b| (0..b.rows).map(move |a| b.b.row(a).transpose() * b.w[a]))
                        .collect();
                    let r = rows.len();
                    let y: Vec<DVector<f64>> = rows.iter().map(|g| f.solve(g)).collect();
                    let s = DMatrix::from_fn(r, r, |i, j| {
                        f64::from(u8::from(i == j)) + rows[i].dot(&y[j])
                    });
                    let wy: Vec<DVector<f64>> = match w {
                        Some(w) => y.iter().map(|v| w * v).collect(),
                        None => y.clone(),
                    };
                    let m = DMatrix::from_fn(r, r, |i, j| y[i].dot(&wy[j]));
                    match s.cholesky() {
                        Some(ch) => ch.solve(&m).trace(),
                        None => f64::NEG_INFINITY,
                    }
                }))
            }
            Criterion::E | Criterion::Condition => {
                let mut base = lambda.clone();
                for j in 0..n {
                    base[(j, j)] += prior[j];
                }
                let now = self.value(criterion, &base);
                Ok(crate::parallel::map(self.blocks.len(), threads, |c| {
                    if skip[c] {
                        return f64::NEG_INFINITY;
                    }
                    let mut l = base.clone();
                    self.add(&mut l, c, 1.0);
                    self.value(criterion, &l) - now
                }))
            }
        }
    }

    /// The scores of the candidates `chosen` (module docs).
    pub fn scores(&self, chosen: &[usize]) -> Scores {
        let n = self.parameters();
        let lambda = self.information(chosen);
        let ev = lambda.clone().symmetric_eigenvalues();
        let (lo, hi) = ev.iter().fold((f64::INFINITY, 0.0_f64), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
        let chol = lambda.clone().cholesky();
        let (log_det, inv) = match &chol {
            Some(c) => (
                2.0 * c.l_dirty().diagonal().iter().map(|d| d.ln()).sum::<f64>(),
                Some(c.inverse()),
            ),
            None => (f64::NEG_INFINITY, None),
        };
        let (trace, std, predicted_um) = match &inv {
            Some(inv) => {
                let std = (0..n)
                    .map(|k| inv[(k, k)].max(0.0).sqrt() / self.scale[k])
                    .collect();
                let (mut sum, mut rows) = (0.0, 0usize);
                for list in &self.blocks {
                    for b in list {
                        for a in 0..b.rows {
                            let r = b.b.row(a);
                            sum += (r * inv * r.transpose())[(0, 0)];
                        }
                        rows += 1;
                    }
                }
                (
                    inv.trace(),
                    std,
                    (sum / rows.max(1) as f64).max(0.0).sqrt() * 1e6,
                )
            }
            None => (f64::INFINITY, vec![f64::INFINITY; n], f64::INFINITY),
        };
        Scores {
            log_det,
            trace,
            min_eigen: lo,
            condition: if lo > 0.0 {
                (hi / lo).sqrt()
            } else {
                f64::INFINITY
            },
            std,
            predicted_um,
        }
    }
}

/// [`crate::estimate::plan::gain`] of a candidate with more blocks than
/// the core takes (markers × kinds beyond four): the same
/// `ln det(I + XᵀX)`, `X` the rows whitened by the factor, at the host's
/// size.
fn many_blocks_gain(f: &crate::estimate::Factor<f64, Dyn>, blocks: &[Block<f64, Dyn>]) -> f64 {
    let x: Vec<DVector<f64>> = (blocks.iter())
        .flat_map(|b| (0..b.rows).map(move |a| f.whiten(&(b.b.row(a).transpose() * b.w[a]))))
        .collect();
    let r = x.len();
    let s = DMatrix::from_fn(r, r, |i, j| f64::from(u8::from(i == j)) + x[i].dot(&x[j]));
    match s.cholesky() {
        Some(c) => 2.0 * c.l_dirty().diagonal().iter().map(|d| d.ln()).sum::<f64>(),
        None => f64::NEG_INFINITY,
    }
}

/// `poses` candidates of `pool` chosen by `criterion`: greedy, then at
/// most `exchange_passes` passes of exchange (module docs).
///
/// # Errors
/// [`CalibrationError::Data`] when the pool has fewer candidates than
/// `poses`; the core's errors of a gain.
pub fn choose(
    pool: &Pool,
    poses: usize,
    criterion: Criterion,
    exchange_passes: usize,
) -> Result<Planned, CalibrationError> {
    let total = pool.candidates.len();
    if poses == 0 || poses > total {
        return Err(CalibrationError::Data(format!(
            "{poses} poses to choose from {total} candidates: choose between 1 and {total}"
        )));
    }
    let prior = pool.prior();
    let n = pool.parameters();
    let mut lambda = DMatrix::zeros(n, n);
    let mut taken = vec![false; total];
    let mut chosen = Vec::with_capacity(poses);
    let best = |g: &[f64]| -> Option<(usize, f64)> {
        g.iter()
            .copied()
            .enumerate()
            .filter(|(_, v)| v.is_finite())
            .fold(None, |b: Option<(usize, f64)>, (i, v)| match b {
                Some((_, bv)) if bv >= v => b,
                _ => Some((i, v)),
            })
    };
    // (The prior grows with the candidates chosen, so that a direction
    // they leave undetermined keeps a pivot of ~10⁻⁶, not one the
    // factor refuses.)
    let at = |k: usize| &prior * (k.max(1) as f64);
    for k in 0..poses {
        let g = pool.gains(criterion, &lambda, &at(k), &taken)?;
        let Some((c, _)) = best(&g) else { break };
        taken[c] = true;
        chosen.push(c);
        pool.add(&mut lambda, c, 1.0);
    }
    let mut exchanges = 0;
    for _ in 0..exchange_passes {
        let mut improved = false;
        for slot in 0..chosen.len() {
            let out = chosen[slot];
            pool.add(&mut lambda, out, -1.0);
            let mut skip = taken.clone();
            skip[out] = false;
            let g = pool.gains(criterion, &lambda, &at(chosen.len()), &skip)?;
            let keep = g[out];
            match best(&g) {
                Some((c, v)) if c != out && v > keep + 1e-9 * keep.abs().max(1.0) => {
                    taken[out] = false;
                    taken[c] = true;
                    chosen[slot] = c;
                    pool.add(&mut lambda, c, 1.0);
                    exchanges += 1;
                    improved = true;
                }
                _ => pool.add(&mut lambda, out, 1.0),
            }
        }
        if !improved {
            break;
        }
    }
    let scores = pool.scores(&chosen);
    Ok(Planned {
        criterion,
        chosen,
        scores,
        exchanges,
    })
}
