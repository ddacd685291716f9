//! TIAGo motion-capture calibration with robcal's core (issue 7): shared by
//! the host tests `tiago_*.rs` and `examples/tiago.rs` (which includes this
//! file with `#[path]`).
//!
//! Data flow: FIGAROH's CSV ─`io::figaroh::import_mocap`→ contract CSV
//! ─`Job::read_measurements`→ [`Posture`]s. A [`Model`] is the robot's chain
//! with the base pose folded into the first joint's origin (so every frame
//! is in the measurement frame), the four points on the hand, and the values
//! of the non-geometric effects. [`fit`] is Gauss–Newton: rows
//! `Δp = measured − predicted` [m] and `B` from `Layout::fill` (+ the effect
//! columns of [`Extra`]) are accumulated, `solve_active` gives the step in
//! layout units (mm, mrad, µrad/(N·m)), the step is applied to the chain
//! (`origin_j ← origin_j · E`, base `origin_0 ← E · origin_0`), markers and
//! effects, and the rows are recomputed, until the step is below 1e-9
//! units.
#![allow(dead_code)]
// Index loops over joints and points mirror the formulas (as in the crate).
#![allow(clippy::needless_range_loop)]

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};
use robcal::diagnose::nested_test;
use robcal::io::{Job, Observation, Robot, MAX_JOINTS};
use robcal::layout::{identifiability, IdentifiabilitySettings, Layout, Marker, Param};
use robcal::{Accumulator, Block, Chain, JointKind};

/// Columns of the layout (geometry, compliance, effects).
pub const N: usize = 112;
/// Movable joints: torso_lift_joint, arm_1_joint … arm_7_joint.
pub const DOF: usize = 8;
/// Tracked points: BL, BR, TR, TL (marker ids 1..=4).
pub const POINTS: usize = 4;
/// Point BL (marker 1): FIGAROH's reported point.
pub const BL: usize = 0;
/// Chain index of arm_5_joint / arm_6_joint.
pub const ARM5: usize = 5;
pub const ARM6: usize = 6;

pub const JOINT_NAMES: [&str; DOF] = [
    "torso_lift_joint",
    "arm_1_joint",
    "arm_2_joint",
    "arm_3_joint",
    "arm_4_joint",
    "arm_5_joint",
    "arm_6_joint",
    "arm_7_joint",
];

pub const TRAIN: &str = "qualisys_2021-11-30_static_postures.csv";
pub const VALID: &str = "qualisys_2021-11-26_static_postures.csv";
pub const URDF: &str = "tiago_48_schunk.urdf";

/// The repository root (this file is `host-tests/tests/tiago_common/mod.rs`
/// or included from `examples/tiago.rs`; both know the root at compile time).
pub fn repo_root() -> PathBuf {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    if here.join("data/tiago/setup.toml").exists() {
        here.to_path_buf()
    } else {
        here.parent()
            .expect("host-tests has a parent")
            .to_path_buf()
    }
}

/// `shared/datasets/tiago-mocap`: beside the repository (`X/../shared`, as
/// in CI), else in the nearest ancestor directory that has it (a git
/// worktree nested deeper), else `$ROBCAL_TIAGO_DATA`.
pub fn data_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("ROBCAL_TIAGO_DATA") {
        return PathBuf::from(dir);
    }
    let root = repo_root();
    for a in root.ancestors().skip(1) {
        let d = a.join("shared/datasets/tiago-mocap");
        if d.join(URDF).exists() {
            return d;
        }
    }
    panic!(
        "shared/datasets/tiago-mocap not found beside {}",
        root.display()
    );
}

/// The job of `data/tiago/setup.toml`, its robot read from [`data_dir`]
/// (the setup's relative `robot` path is right when `shared/` is beside
/// the repository, which [`setup_robot_path_resolves`] checks).
pub fn job() -> Job {
    let setup_path = repo_root().join("data/tiago/setup.toml");
    let setup = robcal::io::Setup::load(&setup_path).expect("setup");
    let robot = Robot::load(
        data_dir().join(URDF),
        setup.base_link.as_deref(),
        setup.tip_link.as_deref(),
    )
    .expect("robot");
    setup
        .check_robot(&robot, &setup_path)
        .expect("setup fits robot");
    Job {
        setup_path,
        setup,
        robot,
    }
}

/// Whether the setup's `robot` path, resolved against the setup file,
/// names the shared URDF (true when `shared/` is beside the repository).
pub fn setup_robot_path_resolves(job: &Job) -> bool {
    let p = job.setup.robot_path(&job.setup_path);
    p.exists() && p.canonicalize().ok() == data_dir().join(URDF).canonicalize().ok()
}

/// Imports a FIGAROH file into `dir` and reads it back with the job.
pub fn import(job: &Job, name: &str, dir: &Path) -> Vec<Observation> {
    let out = dir.join(name.replace(".csv", ".contract.csv"));
    robcal::io::figaroh::import_mocap(data_dir().join(name), &out, Some(&job.robot))
        .expect("import");
    job.read_measurements(&out).expect("read back").observations
}

/// A temporary directory unique to this process and `tag`.
pub fn temp_dir(tag: &str) -> PathBuf {
    static COUNT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = COUNT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let d = std::env::temp_dir().join(format!("robcal-tiago-{tag}-{}-{n}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// One static posture.
#[derive(Debug, Clone)]
pub struct Posture {
    pub config: i64,
    /// Joint values [rad, m], chain order.
    pub q: [f64; DOF],
    /// Measured points [m], measurement frame, BL BR TR TL.
    pub p: [Vector3<f64>; POINTS],
    /// Hours since the first posture of the file.
    pub t_h: f64,
    /// Gravity torques of the nominal robot at `q` [N·m, N] (URDF inertias,
    /// gravity −z of base_link).
    pub tau: [f64; DOF],
}

/// Groups contract rows (markers 1..=4 per config) into postures.
pub fn postures(obs: &[Observation], robot: &Robot) -> Vec<Posture> {
    let mut out: Vec<Posture> = Vec::new();
    let t0 = obs
        .iter()
        .filter_map(|o| o.t_s)
        .fold(f64::INFINITY, f64::min);
    for o in obs {
        let k = o.marker as usize - 1;
        if !matches!(out.last(), Some(p) if p.config == o.config) {
            let mut q = [0.0; DOF];
            q.copy_from_slice(&o.q);
            let frames = robot.chain.frames(&o.q).unwrap();
            let mut tau = [0.0; MAX_JOINTS];
            robcal::elastostatic::gravity_torques(
                &robot.chain,
                &frames,
                &Vector3::new(0.0, 0.0, -9.80665),
                &mut tau,
            )
            .unwrap();
            let mut t = [0.0; DOF];
            t.copy_from_slice(&tau[..DOF]);
            out.push(Posture {
                config: o.config,
                q,
                p: [Vector3::zeros(); POINTS],
                t_h: o.t_s.map_or(0.0, |t| (t - t0) / 3600.0),
                tau: t,
            });
        }
        let last = out.last_mut().unwrap();
        assert_eq!(last.q.as_slice(), o.q.as_slice(), "one posture per config");
        last.p[k] = Vector3::from(o.p_m);
    }
    out
}

/// An effect column that `Layout` has no `Param` for. Each acts on the
/// joint values (`q_j += x · f(posture)`) except drift.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Extra {
    /// `Δq_j = b · sign(τ_j)` [mrad]: free play, resting on the side the
    /// gravity torque pushes.
    Backlash { joint: usize },
    /// `Δq_j = a · sin(h q_j)` or `a · cos(h q_j)` [mrad].
    Cyclic {
        joint: usize,
        harmonic: u8,
        cos: bool,
    },
    /// `Δp_axis = v · t` [mm/h]: the measurement drifts with time.
    Drift { axis: usize },
}

impl Extra {
    pub fn name(&self) -> String {
        match *self {
            Extra::Backlash { joint } => format!("backlash_{}", JOINT_NAMES[joint]),
            Extra::Cyclic {
                joint,
                harmonic,
                cos,
            } => format!(
                "gear_cyclic_{}.{}{harmonic}",
                JOINT_NAMES[joint],
                if cos { "cos" } else { "sin" }
            ),
            Extra::Drift { axis } => format!("drift.{}", ["x", "y", "z"][axis]),
        }
    }
}

/// Every column: `Layout` parameters first (base, markers, joint offsets,
/// the other joint-frame errors, compliances), then the extras.
#[derive(Debug, Clone)]
pub struct Columns {
    pub layout: Layout<N>,
    pub extras: Vec<Extra>,
}

impl Columns {
    pub fn new(chain: &Chain<f64, MAX_JOINTS>) -> Self {
        let mut layout = Layout::<N>::new();
        let mut add = |p: Param| {
            layout.push(chain, p).unwrap();
        };
        for axis in 0..6 {
            add(Param::Base { axis });
        }
        for id in 1..=POINTS as u8 {
            for axis in 0..3 {
                add(Param::Marker { id, axis });
            }
        }
        for joint in 0..DOF as u8 {
            add(Param::JointOffset { joint });
        }
        // Joint-frame errors other than the offset (every axis here is the
        // joint frame's z: rz duplicates a revolute offset, tz a prismatic one).
        for joint in 0..DOF as u8 {
            let offset_axis = match chain.joints()[usize::from(joint)].kind {
                JointKind::Revolute => 5,
                JointKind::Prismatic => 2,
            };
            for axis in (0..6).filter(|&a| a != offset_axis) {
                add(Param::JointFrame { joint, axis });
            }
        }
        for joint in 0..DOF as u8 {
            add(Param::Compliance { joint });
        }
        let mut extras = vec![Extra::Backlash { joint: ARM6 }];
        for joint in 1..DOF {
            for harmonic in 1..=2 {
                for cos in [false, true] {
                    extras.push(Extra::Cyclic {
                        joint,
                        harmonic,
                        cos,
                    });
                }
            }
        }
        for axis in 0..3 {
            extras.push(Extra::Drift { axis });
        }
        assert!(layout.len() + extras.len() <= N);
        Self { layout, extras }
    }

    pub fn len(&self) -> usize {
        self.layout.len() + self.extras.len()
    }

    pub fn param(&self, i: usize) -> Option<Param> {
        self.layout.columns().get(i).map(|c| c.param)
    }

    pub fn extra(&self, i: usize) -> Option<Extra> {
        i.checked_sub(self.layout.len())
            .and_then(|e| self.extras.get(e).copied())
    }

    pub fn index(&self, p: Param) -> usize {
        self.layout.index_of(&p).unwrap()
    }

    pub fn extra_index(&self, e: Extra) -> usize {
        self.layout.len() + self.extras.iter().position(|x| *x == e).unwrap()
    }

    pub fn name(&self, i: usize) -> String {
        match (self.param(i), self.extra(i)) {
            (Some(Param::JointOffset { joint }), _) => {
                format!("{}.offset", JOINT_NAMES[usize::from(joint)])
            }
            (Some(Param::JointFrame { joint, axis }), _) => format!(
                "{}.{}",
                JOINT_NAMES[usize::from(joint)],
                ["tx", "ty", "tz", "rx", "ry", "rz"][usize::from(axis)]
            ),
            (Some(Param::Compliance { joint }), _) => {
                format!("k_{}", JOINT_NAMES[usize::from(joint)])
            }
            (Some(p), _) => p.to_string(),
            (None, Some(e)) => e.name(),
            _ => format!("col{i}"),
        }
    }

    pub fn unit(&self, i: usize) -> &'static str {
        match (self.layout.columns().get(i), self.extra(i)) {
            (Some(c), _) => c.unit,
            (None, Some(Extra::Drift { .. })) => "mm/h",
            _ => "mrad",
        }
    }

    /// Base (6) and the markers of `points`.
    pub fn registration(&self, points: &[usize]) -> [bool; N] {
        let mut m = [false; N];
        for axis in 0..6 {
            m[self.index(Param::Base { axis })] = true;
        }
        for &k in points {
            for axis in 0..3 {
                m[self.index(Param::Marker {
                    id: k as u8 + 1,
                    axis,
                })] = true;
            }
        }
        m
    }

    /// Columns of a joint's offset / its other frame errors.
    pub fn is_offset(&self, i: usize) -> bool {
        matches!(self.param(i), Some(Param::JointOffset { .. }))
    }
    pub fn is_frame(&self, i: usize) -> bool {
        matches!(self.param(i), Some(Param::JointFrame { .. }))
    }
}

/// The calibrated robot: chain (base folded into joint 0's origin), the
/// points on the hand, and the value of every non-geometric column (layout
/// units; geometric ones are applied to the chain and stay 0 here).
#[derive(Debug, Clone)]
pub struct Model {
    pub chain: Chain<f64, MAX_JOINTS>,
    pub markers: [Vector3<f64>; POINTS],
    pub effect: [f64; N],
    /// Sum of the applied steps of every column (layout units): each
    /// parameter's estimate relative to the start (geometric ones to first
    /// order, as their steps compose on the chain).
    pub total: [f64; N],
}

fn small_pose(t: [f64; 3], r: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_scaled_axis(Vector3::new(r[0], r[1], r[2])),
    )
}

impl Model {
    /// Joint values with the effects applied.
    fn q_eff(&self, cols: &Columns, post: &Posture) -> [f64; DOF] {
        let mut q = post.q;
        for i in 0..cols.len() {
            let x = self.effect[i];
            if x == 0.0 {
                continue;
            }
            match (cols.param(i), cols.extra(i)) {
                (Some(Param::Compliance { joint }), _) => {
                    let j = usize::from(joint);
                    q[j] += x * 1e-6 * post.tau[j];
                }
                (_, Some(Extra::Backlash { joint })) => {
                    q[joint] += x * 1e-3 * post.tau[joint].signum();
                }
                (
                    _,
                    Some(Extra::Cyclic {
                        joint,
                        harmonic,
                        cos,
                    }),
                ) => {
                    let a = f64::from(harmonic) * post.q[joint];
                    q[joint] += x * 1e-3 * if cos { a.cos() } else { a.sin() };
                }
                _ => {}
            }
        }
        q
    }

    fn drift(&self, cols: &Columns, post: &Posture) -> Vector3<f64> {
        let mut d = Vector3::zeros();
        for axis in 0..3 {
            let i = cols.extra_index(Extra::Drift { axis });
            d[axis] += self.effect[i] * 1e-3 * post.t_h;
        }
        d
    }

    /// Predicted position [m] of point `k` in `post`.
    pub fn predict(&self, cols: &Columns, post: &Posture, k: usize) -> Vector3<f64> {
        let q = self.q_eff(cols, post);
        self.chain.frames(&q).unwrap().point_m(&self.markers[k]) + self.drift(cols, post)
    }

    /// Residual `measured − predicted` [m] and the 3 rows of `B` (layout
    /// units) of point `k` in `post`.
    pub fn rows(
        &self,
        cols: &Columns,
        post: &Posture,
        k: usize,
    ) -> (Vector3<f64>, nalgebra::SMatrix<f64, 3, N>) {
        let q = self.q_eff(cols, post);
        let frames = self.chain.frames(&q).unwrap();
        let marker = Marker {
            id: k as u8 + 1,
            xyz_m: self.markers[k],
        };
        let mut b = nalgebra::SMatrix::<f64, 3, N>::zeros();
        cols.layout
            .fill(&frames, &marker, &post.tau, &mut b)
            .unwrap();
        let p = frames.point_m(&self.markers[k]);
        for (e, extra) in cols.extras.iter().enumerate() {
            let col = match *extra {
                Extra::Backlash { joint } => {
                    frames.joint(joint).unwrap().twist_column(&p)
                        * (1e-3 * post.tau[joint].signum())
                }
                Extra::Cyclic {
                    joint,
                    harmonic,
                    cos,
                } => {
                    let a = f64::from(harmonic) * post.q[joint];
                    frames.joint(joint).unwrap().twist_column(&p)
                        * (1e-3 * if cos { a.cos() } else { a.sin() })
                }
                Extra::Drift { axis } => {
                    let mut v = Vector3::zeros();
                    v[axis] = 1e-3 * post.t_h;
                    v
                }
            };
            b.set_column(cols.layout.len() + e, &col);
        }
        (post.p[k] - p - self.drift(cols, post), b)
    }

    /// Applies a step `x` (layout units) of the active columns.
    pub fn apply(&mut self, cols: &Columns, x: &nalgebra::SVector<f64, N>) {
        let mut base = [[0.0; 3]; 2];
        let mut frame = [[[0.0; 3]; 2]; DOF];
        for i in 0..cols.len() {
            let v = x[i];
            if v == 0.0 {
                continue;
            }
            self.total[i] += v;
            match cols.param(i) {
                Some(Param::Base { axis }) => {
                    let a = usize::from(axis);
                    base[a / 3][a % 3] = v * 1e-3;
                }
                Some(Param::Marker { id, axis }) => {
                    self.markers[usize::from(id) - 1][usize::from(axis)] += v * 1e-3;
                }
                Some(Param::JointOffset { joint }) => {
                    let j = usize::from(joint);
                    let jt = &mut self.chain.joints_mut()[j];
                    let motion = match jt.kind {
                        JointKind::Revolute => Isometry3::from_parts(
                            Translation3::identity(),
                            UnitQuaternion::from_axis_angle(&jt.axis, v * 1e-3),
                        ),
                        JointKind::Prismatic => Isometry3::from_parts(
                            Translation3::from(jt.axis.into_inner() * (v * 1e-3)),
                            UnitQuaternion::identity(),
                        ),
                    };
                    jt.origin *= motion;
                }
                Some(Param::JointFrame { joint, axis }) => {
                    let a = usize::from(axis);
                    frame[usize::from(joint)][a / 3][a % 3] = v * 1e-3;
                }
                _ => self.effect[i] += v,
            }
        }
        for (j, f) in frame.iter().enumerate() {
            if f != &[[0.0; 3]; 2] {
                let jt = &mut self.chain.joints_mut()[j];
                jt.origin *= small_pose(f[0], f[1]);
            }
        }
        if base != [[0.0; 3]; 2] {
            let jt = &mut self.chain.joints_mut()[0];
            jt.origin = small_pose(base[0], base[1]) * jt.origin;
        }
    }

    /// Norm RMSE [mm] of point `k` over `data`: `√(mean ‖e‖²)`.
    pub fn rmse_mm(&self, cols: &Columns, data: &[Posture], k: usize) -> f64 {
        let s: f64 = data
            .iter()
            .map(|p| (p.p[k] - self.predict(cols, p, k)).norm_squared())
            .sum();
        (s / data.len() as f64).sqrt() * 1e3
    }

    /// Norm RMSE [mm] over every point of every posture.
    pub fn rmse_all_mm(&self, cols: &Columns, data: &[Posture]) -> f64 {
        let s: f64 = (0..POINTS)
            .map(|k| self.rmse_mm(cols, data, k).powi(2))
            .sum();
        (s / POINTS as f64).sqrt()
    }
}

/// The nominal model with the base placed by a rigid registration (Kabsch)
/// of the nominal point positions onto the measured ones.
pub fn initial_model(robot: &Robot, markers: [Vector3<f64>; POINTS], data: &[Posture]) -> Model {
    let mut m = Model {
        chain: robot.chain.clone(),
        markers,
        effect: [0.0; N],
        total: [0.0; N],
    };
    let mut a = Vec::new();
    let mut b = Vec::new();
    for post in data {
        let frames = m.chain.frames(&post.q).unwrap();
        for k in 0..POINTS {
            a.push(frames.point_m(&markers[k]));
            b.push(post.p[k]);
        }
    }
    let n = a.len() as f64;
    let ca = a.iter().sum::<Vector3<f64>>() / n;
    let cb = b.iter().sum::<Vector3<f64>>() / n;
    let mut h = Matrix3::zeros();
    for (x, y) in a.iter().zip(&b) {
        h += (x - ca) * (y - cb).transpose();
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
    let mut d = Matrix3::identity();
    if (vt.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = vt.transpose() * d * u.transpose();
    let rot = UnitQuaternion::from_matrix(&r);
    let t = cb - rot * ca;
    let base = Isometry3::from_parts(Translation3::from(t), rot);
    let j0 = &mut m.chain.joints_mut()[0];
    j0.origin = base * j0.origin;
    m
}

/// A converged fit.
#[derive(Debug, Clone)]
pub struct Fitted {
    pub model: Model,
    /// Accumulator at the converged linearisation (its solution is ~0).
    pub acc: Accumulator<f64, N>,
    pub solution: robcal::Solution<f64, N>,
    pub iterations: usize,
}

/// Accumulates unit-weight rows of `points` over `data`.
pub fn accumulate(
    model: &Model,
    cols: &Columns,
    data: &[Posture],
    points: &[usize],
) -> Accumulator<f64, N> {
    let mut acc = Accumulator::new();
    for post in data {
        for &k in points {
            let (dp, b) = model.rows(cols, post, k);
            acc.update(&Block::new(b, dp)).unwrap();
        }
    }
    acc
}

/// Gauss–Newton on the `active` columns from `start`.
pub fn fit(
    start: &Model,
    cols: &Columns,
    data: &[Posture],
    points: &[usize],
    active: &[bool; N],
) -> Result<Fitted, robcal::Error> {
    let mut model = start.clone();
    for it in 0..100 {
        let acc = accumulate(&model, cols, data, points);
        let solution = acc.solve_active(active)?;
        let step = solution.x.amax();
        if step < 1e-9 {
            return Ok(Fitted {
                model,
                acc,
                solution,
                iterations: it,
            });
        }
        model.apply(cols, &solution.x);
    }
    Err(robcal::Error::Mismatch {
        what: "Gauss-Newton did not converge",
    })
}

/// The identifiable subset of `base + markers(points) + offsets + joint
/// frames` at `model` (`identifiability` in layout order: base and markers
/// first, then offsets, then the other frame errors).
pub fn identifiable_geometry(
    model: &Model,
    cols: &Columns,
    data: &[Posture],
    points: &[usize],
) -> robcal::layout::Identifiability<f64, N> {
    let acc = accumulate(model, cols, data, points);
    let mut cand = cols.registration(points);
    for i in 0..cols.len() {
        if cols.is_offset(i) || cols.is_frame(i) {
            cand[i] = true;
        }
    }
    identifiability(
        &acc.information(),
        &cand,
        &IdentifiabilitySettings::default(),
    )
    .unwrap()
}

/// Leave-one-posture-out prediction RMSE [mm] of point BL: each posture
/// predicted by the model fitted on the others (Gauss–Newton from `fitted`).
pub fn lopo_bl_mm(
    fitted: &Model,
    cols: &Columns,
    data: &[Posture],
    points: &[usize],
    active: &[bool; N],
) -> f64 {
    let mut s = 0.0;
    for i in 0..data.len() {
        let rest: Vec<Posture> = data
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .map(|(_, p)| p.clone())
            .collect();
        let m = fit(fitted, cols, &rest, points, active)
            .map(|f| f.model)
            .unwrap_or_else(|_| fitted.clone());
        s += (data[i].p[BL] - m.predict(cols, &data[i], BL)).norm_squared();
    }
    (s / data.len() as f64).sqrt() * 1e3
}

/// A candidate effect: a named group of columns.
#[derive(Debug, Clone)]
pub struct Candidate {
    pub name: String,
    pub columns: Vec<usize>,
}

/// The effect library on this robot: per joint its offset, its other
/// (identifiable) frame errors, its gravity compliance, its cyclic error
/// (1st and 2nd harmonic), arm_6 backlash, drift.
pub fn candidates(cols: &Columns, identifiable: &[bool; N]) -> Vec<Candidate> {
    let mut out = Vec::new();
    for j in 0..DOF {
        let off = cols.index(Param::JointOffset { joint: j as u8 });
        if identifiable[off] {
            out.push(Candidate {
                name: format!("joint_offset {}", JOINT_NAMES[j]),
                columns: vec![off],
            });
        }
        let frame: Vec<usize> = (0..cols.len())
            .filter(|&i| {
                identifiable[i]
                    && matches!(cols.param(i), Some(Param::JointFrame { joint, .. }) if usize::from(joint) == j)
            })
            .collect();
        if !frame.is_empty() {
            out.push(Candidate {
                name: format!("geometry {}", JOINT_NAMES[j]),
                columns: frame,
            });
        }
    }
    for j in 0..DOF {
        out.push(Candidate {
            name: format!("joint_compliance {}", JOINT_NAMES[j]),
            columns: vec![cols.index(Param::Compliance { joint: j as u8 })],
        });
    }
    out.push(Candidate {
        name: format!("backlash {}", JOINT_NAMES[ARM6]),
        columns: vec![cols.extra_index(Extra::Backlash { joint: ARM6 })],
    });
    for j in 1..DOF {
        for h in 1..=2u8 {
            out.push(Candidate {
                name: format!("gear_cyclic {} h{h}", JOINT_NAMES[j]),
                columns: [false, true]
                    .iter()
                    .map(|&cos| {
                        cols.extra_index(Extra::Cyclic {
                            joint: j,
                            harmonic: h,
                            cos,
                        })
                    })
                    .collect(),
            });
        }
    }
    out.push(Candidate {
        name: "drift".into(),
        columns: (0..3)
            .map(|axis| cols.extra_index(Extra::Drift { axis }))
            .collect(),
    });
    out
}

/// One step of the closed loop.
#[derive(Debug, Clone)]
pub struct Step {
    pub effect: String,
    pub p_value: f64,
    pub params: usize,
    pub train_before_mm: f64,
    pub train_after_mm: f64,
    pub cv_before_mm: f64,
    pub cv_after_mm: f64,
    pub valid_before_mm: f64,
    pub valid_after_mm: f64,
}

/// Largest admissible gear cyclic error amplitude [mrad] (per harmonic).
pub const MAX_CYCLIC_MRAD: f64 = 10.0;
/// Largest admissible drift [mm/h].
pub const MAX_DRIFT_MM_PER_H: f64 = 5.0;

/// Why the active effects of `model` are not physical, if they are not: a
/// negative compliance, a backlash against the gravity torque, a cyclic
/// error above [`MAX_CYCLIC_MRAD`], a drift above [`MAX_DRIFT_MM_PER_H`].
pub fn inadmissible(model: &Model, cols: &Columns, active: &[bool; N]) -> Option<String> {
    let x = &model.effect;
    for i in (0..cols.len()).filter(|&i| active[i]) {
        let bad = match (cols.param(i), cols.extra(i)) {
            (Some(Param::Compliance { .. }), _) => x[i] < 0.0,
            (_, Some(Extra::Backlash { .. })) => x[i] < 0.0,
            (
                _,
                Some(Extra::Cyclic {
                    joint,
                    harmonic,
                    cos: false,
                }),
            ) => {
                let c = cols.extra_index(Extra::Cyclic {
                    joint,
                    harmonic,
                    cos: true,
                });
                x[i].hypot(x[c]) > MAX_CYCLIC_MRAD
            }
            (_, Some(Extra::Drift { axis: 0 })) => {
                let v: f64 = (0..3)
                    .map(|a| x[cols.extra_index(Extra::Drift { axis: a })].powi(2))
                    .sum();
                v.sqrt() > MAX_DRIFT_MM_PER_H
            }
            _ => false,
        };
        if bad {
            return Some(format!("{} = {:.3} {}", cols.name(i), x[i], cols.unit(i)));
        }
    }
    None
}

/// The outcome of the closed loop.
#[derive(Debug, Clone)]
pub struct Loop {
    pub steps: Vec<Step>,
    /// Candidates significant on training that cross-validation rejected.
    pub rejected: Vec<(String, f64, f64)>,
    pub active: [bool; N],
    pub fitted: Fitted,
}

/// Significance level of the nested test (Bonferroni over the candidates
/// tried in a step).
pub const ALPHA: f64 = 0.01;

/// The closed loop on the training set: nested F test of every candidate
/// (`nested_test` from the converged accumulator), the most significant
/// first; a candidate is added when it passes Bonferroni at [`ALPHA`] *and*
/// lowers the leave-one-posture-out RMSE of BL. `valid` is only evaluated
/// (reported), never fitted.
pub fn closed_loop(
    start: &Fitted,
    start_active: &[bool; N],
    cols: &Columns,
    train: &[Posture],
    valid: &[Posture],
    points: &[usize],
    library: &[Candidate],
) -> Loop {
    let mut active = *start_active;
    let mut fitted = start.clone();
    let mut cv = lopo_bl_mm(&fitted.model, cols, train, points, &active);
    let mut steps = Vec::new();
    let mut rejected = Vec::new();
    let mut tried_out: Vec<String> = Vec::new();
    loop {
        let mut tests: Vec<(f64, &Candidate)> = Vec::new();
        for c in library {
            if c.columns.iter().any(|&i| active[i]) || tried_out.contains(&c.name) {
                continue;
            }
            let mut cand = [false; N];
            for &i in &c.columns {
                cand[i] = true;
            }
            if let Ok(t) = nested_test(&fitted.acc, &active, &fitted.solution, &cand) {
                tests.push((t.p_value, c));
            }
        }
        let m = tests.len().max(1) as f64;
        tests.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut added = false;
        for (p, c) in tests {
            if p * m >= ALPHA {
                break;
            }
            let mut next = active;
            for &i in &c.columns {
                next[i] = true;
            }
            let Ok(f) = fit(&fitted.model, cols, train, points, &next) else {
                tried_out.push(c.name.clone());
                continue;
            };
            if let Some(why) = inadmissible(&f.model, cols, &next) {
                rejected.push((format!("{} ({why})", c.name), p, f64::NAN));
                tried_out.push(c.name.clone());
                continue;
            }
            let cv_after = lopo_bl_mm(&f.model, cols, train, points, &next);
            if cv_after < cv {
                steps.push(Step {
                    effect: c.name.clone(),
                    p_value: p,
                    params: next.iter().filter(|a| **a).count(),
                    train_before_mm: fitted.model.rmse_mm(cols, train, BL),
                    train_after_mm: f.model.rmse_mm(cols, train, BL),
                    cv_before_mm: cv,
                    cv_after_mm: cv_after,
                    valid_before_mm: fitted.model.rmse_mm(cols, valid, BL),
                    valid_after_mm: f.model.rmse_mm(cols, valid, BL),
                });
                active = next;
                fitted = f;
                cv = cv_after;
                added = true;
                break;
            }
            rejected.push((c.name.clone(), p, cv_after));
            tried_out.push(c.name.clone());
        }
        if !added {
            break;
        }
    }
    Loop {
        steps,
        rejected,
        active,
        fitted,
    }
}

/// The three FIGAROH models fitted on `train` with `points`.
#[derive(Debug, Clone)]
pub struct Table {
    pub registration: Fitted,
    pub registration_active: [bool; N],
    pub offsets: Fitted,
    pub offsets_active: [bool; N],
    pub full: Fitted,
    pub full_active: [bool; N],
}

/// Registration (base + points), + identifiable joint offsets, + identifiable
/// joint-frame errors; each Gauss–Newton from the previous.
pub fn table(
    robot: &Robot,
    markers: [Vector3<f64>; POINTS],
    cols: &Columns,
    train: &[Posture],
    points: &[usize],
) -> Table {
    let m0 = initial_model(robot, markers, train);
    let reg_active = cols.registration(points);
    let reg = fit(&m0, cols, train, points, &reg_active).unwrap();
    let id = identifiable_geometry(&reg.model, cols, train, points);
    let mut off_active = reg_active;
    let mut full_active = reg_active;
    for i in 0..cols.len() {
        if id.kept[i] && cols.is_offset(i) {
            off_active[i] = true;
        }
        if id.kept[i] {
            full_active[i] = true;
        }
    }
    let off = fit(&reg.model, cols, train, points, &off_active).unwrap();
    let full = fit(&off.model, cols, train, points, &full_active).unwrap();
    Table {
        registration: reg,
        registration_active: reg_active,
        offsets: off,
        offsets_active: off_active,
        full,
        full_active,
    }
}

pub fn count(active: &[bool; N]) -> usize {
    active.iter().filter(|a| **a).count()
}

/// Runs `f` on a thread with a large stack (the `N × N` matrices of the
/// accumulator, solver and tests live on the stack).
pub fn with_stack<R: Send + 'static>(f: impl FnOnce() -> R + Send + 'static) -> R {
    std::thread::Builder::new()
        .stack_size(256 << 20)
        .spawn(f)
        .unwrap()
        .join()
        .unwrap()
}

/// One row of the FIGAROH table.
#[derive(Debug, Clone)]
pub struct Row {
    pub model: &'static str,
    /// "BL" or "BL+BR+TR+TL".
    pub points: &'static str,
    pub params: usize,
    pub train_bl_mm: f64,
    pub valid_bl_mm: f64,
    pub train_all_mm: f64,
    pub valid_all_mm: f64,
}

/// Everything issue 7 reports.
#[derive(Debug, Clone)]
pub struct Report {
    pub train_postures: usize,
    pub valid_postures: usize,
    pub rows: Vec<Row>,
    /// (points, start, loop result, its LOPO CV of BL).
    pub loops: Vec<(&'static str, &'static str, Loop, f64)>,
    /// Index in `loops` of the model chosen by training CV.
    pub chosen: usize,
    pub cols: Columns,
}

/// Runs the table and the closed loops. `valid` is evaluated only.
pub fn report(job: &Job, train: &[Posture], valid: &[Posture]) -> Report {
    let cols = Columns::new(&job.robot.chain);
    let m: Vec<Vector3<f64>> = job
        .setup
        .markers
        .iter()
        .map(|m| Vector3::from(m.xyz))
        .collect();
    let markers = [m[0], m[1], m[2], m[3]];
    let mut rows = Vec::new();
    let mut loops = Vec::new();
    for (label, points) in [("BL", vec![BL]), ("BL+BR+TR+TL", vec![0, 1, 2, 3])] {
        let t = table(&job.robot, markers, &cols, train, &points);
        for (model, f, a) in [
            (
                "registration (base + points)",
                &t.registration,
                &t.registration_active,
            ),
            ("+ joint offsets", &t.offsets, &t.offsets_active),
            ("+ joint-frame errors (full)", &t.full, &t.full_active),
        ] {
            rows.push(Row {
                model,
                points: label,
                params: count(a),
                train_bl_mm: f.model.rmse_mm(&cols, train, BL),
                valid_bl_mm: f.model.rmse_mm(&cols, valid, BL),
                train_all_mm: f.model.rmse_all_mm(&cols, train),
                valid_all_mm: f.model.rmse_all_mm(&cols, valid),
            });
        }
        let id = identifiable_geometry(&t.registration.model, &cols, train, &points);
        let library = candidates(&cols, &id.kept);
        let effects_only: Vec<Candidate> = library
            .iter()
            .filter(|c| !c.name.starts_with("joint_offset") && !c.name.starts_with("geometry"))
            .cloned()
            .collect();
        for (start, fitted, active, lib) in [
            (
                "registration",
                &t.registration,
                &t.registration_active,
                &library,
            ),
            ("full", &t.full, &t.full_active, &effects_only),
        ] {
            let l = closed_loop(fitted, active, &cols, train, valid, &points, lib);
            let cv = l.steps.last().map_or_else(
                || lopo_bl_mm(&l.fitted.model, &cols, train, &points, &l.active),
                |s| s.cv_after_mm,
            );
            loops.push((label, start, l, cv));
        }
    }
    let chosen = (0..loops.len())
        .min_by(|&a, &b| loops[a].3.total_cmp(&loops[b].3))
        .unwrap();
    Report {
        train_postures: train.len(),
        valid_postures: valid.len(),
        rows,
        loops,
        chosen,
        cols,
    }
}

impl Report {
    /// The report as Markdown (docs/tiago.md quotes it).
    pub fn markdown(&self, train: &[Posture], valid: &[Posture]) -> String {
        use std::fmt::Write as _;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "Training {} postures, validation {} postures. Norm RMSE in mm.\n",
            self.train_postures, self.valid_postures
        );
        let _ = writeln!(s, "| model | points fitted | params | BL train | BL valid | all points train | all points valid | FIGAROH (BL train / valid, params) |");
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|");
        let figaroh = ["3.37 / 4.87 (9)", "2.88 / 4.23 (14)", "1.64 / 3.07 (31)"];
        for (i, r) in self.rows.iter().enumerate() {
            // Fitted on BL alone, the other points are not identified.
            let all = |v: f64| {
                if r.points == "BL" {
                    "—".to_string()
                } else {
                    format!("{v:.2}")
                }
            };
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.2} | {:.2} | {} | {} | {} |",
                r.model,
                r.points,
                r.params,
                r.train_bl_mm,
                r.valid_bl_mm,
                all(r.train_all_mm),
                all(r.valid_all_mm),
                figaroh[i % 3]
            );
        }
        for (i, (points, start, l, cv)) in self.loops.iter().enumerate() {
            let _ =
                writeln!(
                s,
                "\nClosed loop, points {points}, from {start}{}: final LOPO CV of BL {cv:.2} mm\n",
                if i == self.chosen { " (**chosen**: lowest training CV)" } else { "" }
            );
            let _ = writeln!(
                s,
                "| step | effect added | p (F test) | params | BL train | BL LOPO CV | BL valid |"
            );
            let _ = writeln!(s, "|---|---|---|---|---|---|---|");
            if let Some(first) = l.steps.first() {
                let _ = writeln!(
                    s,
                    "| 0 | (start) | | {} | {:.2} | {:.2} | {:.2} |",
                    first.params - 1,
                    first.train_before_mm,
                    first.cv_before_mm,
                    first.valid_before_mm
                );
            }
            for (k, st) in l.steps.iter().enumerate() {
                let _ = writeln!(
                    s,
                    "| {} | {} | {:.1e} | {} | {:.2} | {:.2} | {:.2} |",
                    k + 1,
                    st.effect,
                    st.p_value,
                    st.params,
                    st.train_after_mm,
                    st.cv_after_mm,
                    st.valid_after_mm
                );
            }
            if !l.rejected.is_empty() {
                let _ = writeln!(s, "\nSignificant on training but not added:");
                for (name, p, cv) in &l.rejected {
                    let why = if cv.is_nan() {
                        "inadmissible estimate".to_string()
                    } else {
                        format!("LOPO CV {cv:.2} mm, no better")
                    };
                    let _ = writeln!(s, "- {name}: p = {p:.1e}, {why}");
                }
            }
            if i == self.chosen {
                let _ = writeln!(
                    s,
                    "\nParameters of the chosen model beyond base and points (estimate ± 1σ, OLS):\n"
                );
                let sd = robcal::solve::std_devs(&l.fitted.solution.cov_iid());
                for c in (18..self.cols.len()).filter(|&c| l.active[c]) {
                    let _ = writeln!(
                        s,
                        "- {} = {:.2} ± {:.2} {}",
                        self.cols.name(c),
                        l.fitted.model.total[c],
                        sd[c],
                        self.cols.unit(c)
                    );
                }
                for c in (18..self.cols.len()).filter(|&c| l.active[c]) {
                    if let Some(Param::Compliance { joint }) = self.cols.param(c) {
                        let j = usize::from(joint);
                        let (lo, hi) = train.iter().fold((f64::MAX, f64::MIN), |(a, b), p| {
                            (a.min(p.tau[j]), b.max(p.tau[j]))
                        });
                        let k = l.fitted.model.effect[c] * 1e-3; // mrad per N·m
                        let _ = writeln!(
                            s,
                            "\n{}: gravity torque {lo:.2} … {hi:.2} N·m on training, so k·τ spans {:.1} … {:.1} mrad.",
                            JOINT_NAMES[j],
                            k * lo,
                            k * hi
                        );
                    }
                }
                let _ = writeln!(
                    s,
                    "\nChosen model: BL train {:.2} mm, BL valid {:.2} mm (FIGAROH's best: 3.07 mm).",
                    l.fitted.model.rmse_mm(&self.cols, train, BL),
                    l.fitted.model.rmse_mm(&self.cols, valid, BL)
                );
            }
        }
        s
    }
}
