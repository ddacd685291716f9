//! The measurements as rows of the identification problem, evaluated at
//! the current model.
//!
//! A row is one measured point (three equations): a **deflection**
//! (loaded minus unloaded position of a marker at one pose; only the load's
//! torques enter, eq. 3) or an **absolute** position (the unloaded
//! position against the forward kinematics of the current model, loaded by
//! the robot's own weight, eq. 2). Absolute rows are used when the declared
//! model identifies geometry, the base or the markers, or when there is no
//! load. The configurations are the groups of the per-axis noise estimate
//! (eq. 14).

use nalgebra::Vector3;

use crate::calibrate::params::geometry::{Geometry, J};
use crate::calibrate::params::linearisation::Linearisation;
use crate::calibrate::params::names::Names;
use crate::calibrate::settings::CalibrationError;
use crate::error::Error;
use crate::model::Sample;
use crate::robot::{
    equilibrium, gravity_moments, Chain, EquilibriumSettings, Frames, JointKind, JointLaw, Loading,
    PointLoad, Wrench,
};

mod build;
mod noise;
pub mod orientation;
mod points;
mod runs;
pub mod scalar;
mod values;
pub use noise::{noise_scale, row_scale, scaled_y};
pub(crate) use points::{lhs, marker_m};
pub use runs::run_length;
pub use scalar::Scalar;
use values::Values;

/// Which kinds of rows there are: the core's, for its candidate rule.
pub use crate::model::effect::DataKinds;

/// When a row's equilibrium has settled: the next Newton step below
/// 1e-13 rad (or m); 50 steps at most (an industrial robot needs 2 or 3).
/// [`Row::tau`] of a row that stored none.
static ZERO_TORQUES: [f64; J] = [0.0; J];

const EQUILIBRIUM: EquilibriumSettings<f64> = EquilibriumSettings {
    tolerance: 1e-13,
    max_iterations: 50,
};

/// What one row of the problem is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowKind {
    /// Loaded minus unloaded position of one marker (elastostatic, eq. 3).
    Deflection,
    /// Unloaded position minus its forward kinematics (geometric, eq. 2).
    Absolute,
}

/// One row (three equations) of the identification problem.
///
/// 112 B (a 7-joint arm's joint values inline): what every row has. What
/// only some have is boxed ([`RowExtra`]), and what follows from the rest
/// is computed where read: the configuration id (`Rows::configs[group]`),
/// the predicted point ([`Rows::point_m`]) and the left-hand side
/// ([`Rows::y`]), from the frames. At 10⁶ rows the row was 224 B.
#[derive(Debug, Clone)]
pub struct Row {
    /// Deflection or absolute position.
    pub kind: RowKind,
    /// Marker index (into [`Names::markers`]).
    pub marker: u8,
    /// Whether the row is the orientation of a measured pose (an absolute
    /// row): `measured` is then the rotation vector of the marker's link
    /// frame \[rad\], the row's `y` the rotation `log(R_meas R_predᵀ)` and
    /// its columns `∂θ/∂x`, the turn of that frame (module
    /// [`orientation`]).
    pub orientation: bool,
    /// Index into [`Rows::chains`] of the chain the row's frames are on
    /// (see [`Rows::frames`]; a `u32`: 8 B a row fewer).
    chain: u32,
    /// Index of the configuration ([`Row::group`]).
    group: u32,
    /// Joint values \[rad or m\] (inline up to [`crate::io::measurements::INLINE_JOINTS`]).
    pub q: crate::io::measurements::JointValues,
    /// What was measured \[m\]: the position (absolute rows, measurement
    /// frame) or the deflection.
    pub measured: Vector3<f64>,
    /// CSV line ([`Row::line`]).
    line: u32,
    /// What only some rows have ([`RowExtra`]), boxed: absent (8 B) for an
    /// absolute row without time, instrument σ, weight of its own or the
    /// exact model's equilibrium (at 10⁶ such rows, ~200 MB fewer).
    pub extra: Option<Box<RowExtra>>,
}

/// The fields of a [`Row`] that only some rows have; each read through
/// [`Row`]'s accessor of the same name (none, zero or empty without it).
#[derive(Debug, Clone, Default)]
pub struct RowExtra {
    /// Load \[kg\] (deflection rows; 0 for absolute rows).
    pub load_kg: f64,
    /// Time \[s\] relative to the data's mean time (absolute rows) or between
    /// the unloaded and the loaded measurement (deflection rows).
    pub dt: Option<f64>,
    /// Temperature \[K\] relative to the data's mean temperature
    /// ([`Rows::temperature_ref_c`], absolute rows) or between the loaded
    /// and the unloaded measurement (deflection rows), when the setup
    /// names a temperature column.
    pub dtemp_k: Option<f64>,
    /// The instrument's σ of what was measured, per axis \[m\] (data
    /// contract 7.2): the point's, or for a deflection the root sum of
    /// squares of its two points'.
    pub sigma: Option<Vector3<f64>>,
    /// The load's wrench at the row's frames (deflection rows).
    pub load: Option<Wrench<f64>>,
    /// Joint torques behind the row at its frames: the load's (deflection
    /// rows) or the links' own weight (absolute rows) \[N·m or N\]; none
    /// when every one is `+0.0` (no load and no link mass). Read through
    /// [`Row::tau`].
    tau: Values,
    /// The joint values \[rad or m\] the row's frames are at, with the
    /// exact deflection model: its equilibrium (the loaded one for a
    /// deflection); none for the row's own `q`. Read through
    /// [`Row::theta`].
    theta: Values,
    /// With the exact model, the column of each joint's yield at the
    /// equilibrium ([`crate::robot::Equilibrium::twist_column`]); empty for
    /// the first-order columns at the row's frames.
    pub twists: Vec<Vector3<f64>>,
    /// Per joint, the components of the gravity direction on its basis at
    /// the commanded pose `q` ([`Linearisation::gravity_at`]): an absolute
    /// row's, when the exact model's law has a gravity compliance (its
    /// frames are then at the equilibrium, not at `q`); else empty.
    pub gravity_q: Vec<[f64; 2]>,
    /// Per joint, the moment \[N·m, measurement frame\] about its origin of
    /// the robot's own weight it carries, at the row's frames: an absolute
    /// row's, with a mass model (what bends the links,
    /// [`crate::model::Param::LinkCompliance`]); empty without one. Read
    /// through [`Row::weight_moments_nm`].
    weight_moments_nm: Vec<Vector3<f64>>,
    /// With the exact model, the row's left-hand side \[m\] ([`Rows::y`]),
    /// which its frames alone do not give; `None` for the first-order
    /// model's.
    pub y: Option<Vector3<f64>>,
    /// What the row measures when it is a plane contact or a distance (one
    /// number, on axis 0 of `measured`: module [`scalar`]); `None`: a
    /// point or an orientation.
    pub scalar: Option<Scalar>,
    /// The factor `√w` the row enters the design with, from a robust loss
    /// ([`crate::calibrate::robust`]; `w` its weight in `(0, 1]`), on top
    /// of the kind's ([`noise_scale`]); none: 1.
    pub robust: Option<f64>,
}

/// A run of rows in [`Rows::relinearise_with`], with its state and its
/// first error from `then`.
type Run<'a, S> = (&'a mut [Row], Option<S>, Result<(), Error>);

impl Row {
    /// Index of the configuration (the group of the noise estimate); its
    /// `config` as in the CSV is `Rows::configs[group]`. (Held as a `u32`,
    /// as [`Row::line`]: 8 B a row fewer.)
    pub fn group(&self) -> usize {
        self.group as usize
    }

    /// CSV line (of the loaded row for deflections; `u32::MAX` past it).
    pub fn line(&self) -> usize {
        self.line as usize
    }

    /// [`RowExtra::load_kg`] (0 without it).
    pub fn load_kg(&self) -> f64 {
        self.extra.as_ref().map_or(0.0, |e| e.load_kg)
    }

    /// [`RowExtra::dt`].
    pub fn dt(&self) -> Option<f64> {
        self.extra.as_ref().and_then(|e| e.dt)
    }

    /// [`RowExtra::dtemp_k`].
    pub fn dtemp_k(&self) -> Option<f64> {
        self.extra.as_ref().and_then(|e| e.dtemp_k)
    }

    /// [`RowExtra::sigma`].
    pub fn sigma(&self) -> Option<Vector3<f64>> {
        self.extra.as_ref().and_then(|e| e.sigma)
    }

    /// [`RowExtra::robust`] (1 without it).
    pub fn robust(&self) -> f64 {
        self.extra.as_ref().and_then(|e| e.robust).unwrap_or(1.0)
    }

    /// [`RowExtra::load`].
    pub fn load(&self) -> Option<Wrench<f64>> {
        self.extra.as_ref().and_then(|e| e.load)
    }

    /// [`RowExtra::scalar`].
    pub fn scalar(&self) -> Option<&Scalar> {
        self.extra.as_ref().and_then(|e| e.scalar.as_ref())
    }

    /// Which of the row's three axes are equations: all three, or axis 0
    /// alone for a plane contact or a distance
    /// ([`crate::calibrate::design::Design::live`]).
    pub fn live(&self) -> [f64; 3] {
        if self.scalar().is_some() {
            scalar::LIVE
        } else {
            [1.0; 3]
        }
    }

    /// [`RowExtra::twists`].
    pub fn twists(&self) -> &[Vector3<f64>] {
        self.extra.as_ref().map_or(&[], |e| &e.twists)
    }

    /// With the exact model, what joint `j`'s yield does to the row per
    /// unit: the point's twist column, or a pose orientation's turn
    /// ([`crate::model::turn`] of its twists at the point and its probes).
    pub fn joint_column(&self, j: usize) -> Vector3<f64> {
        let t = self.twists();
        if self.orientation {
            let n = t.len() / 3;
            match (t.get(j), t.get(n + j), t.get(2 * n + j)) {
                (Some(a), Some(b), Some(c)) => crate::model::turn(a, b, c),
                _ => Vector3::zeros(),
            }
        } else {
            t.get(j).copied().unwrap_or_default()
        }
    }

    /// [`RowExtra::gravity_q`].
    pub fn gravity_q(&self) -> &[[f64; 2]] {
        self.extra.as_ref().map_or(&[], |e| &e.gravity_q)
    }

    /// Per joint, the moment of the robot's own weight about its origin
    /// \[N·m, measurement frame\], with a mass model (what bends the
    /// links, [`crate::model::Param::LinkCompliance`]); empty: none.
    pub fn weight_moments_nm(&self) -> &[Vector3<f64>] {
        self.extra
            .as_ref()
            .map_or(&[][..], |e| &e.weight_moments_nm[..])
    }

    /// The joint values the row's frames are at: its equilibrium's `θ`
    /// (the exact deflection model), or empty for the row's own `q`
    /// ([`Rows::frames`]).
    pub fn theta(&self) -> &[f64] {
        self.extra.as_ref().map_or(&[], |e| e.theta.as_slice())
    }

    /// The joint torques behind the row \[N·m or N\], one per joint (zeros
    /// when none was stored).
    pub fn tau(&self) -> &[f64] {
        match self.extra.as_ref().map(|e| e.tau.as_slice()) {
            Some(t) if !t.is_empty() => t,
            _ => &ZERO_TORQUES[..self.q.len().min(J)],
        }
    }

    /// Stores the joint torques `tau` (nothing when every one is `+0.0`:
    /// [`Row::tau`] then gives the same bits).
    fn set_tau(&mut self, tau: &[f64]) {
        if tau.iter().all(|t| t.to_bits() == 0) {
            if let Some(e) = &mut self.extra {
                e.tau.clear();
            }
        } else {
            self.extra_mut().tau.set(tau);
        }
    }

    /// Stores the own weight's moments about the joints of an absolute row
    /// at `frames` on `chain` under `gravity` \[m/s², measurement frame\]
    /// when the chain has a mass model (`weighs`); clears them otherwise.
    fn set_weight_moments(
        &mut self,
        weighs: bool,
        chain: &Chain<f64, J>,
        frames: &Frames<f64, J>,
        gravity: &Vector3<f64>,
    ) -> Result<(), Error> {
        if !(weighs && self.kind == RowKind::Absolute) {
            if let Some(e) = &mut self.extra {
                e.weight_moments_nm.clear();
            }
            return Ok(());
        }
        let mut m = [Vector3::zeros(); J];
        let m = &mut m[..frames.dof()];
        gravity_moments(chain, frames, gravity, m)?;
        let e = self.extra_mut();
        e.weight_moments_nm.clear();
        e.weight_moments_nm.extend_from_slice(m);
        Ok(())
    }

    /// Stores the frames' joint values `theta` (none: the row's own `q`).
    fn set_theta(&mut self, theta: &[f64]) {
        if theta.is_empty() {
            if let Some(e) = &mut self.extra {
                e.theta.clear();
            }
        } else {
            self.extra_mut().theta.set(theta);
        }
    }

    /// Index into [`Rows::chains`] of the chain the row's frames are on.
    pub fn chain_index(&self) -> usize {
        usize::try_from(self.chain).unwrap_or(usize::MAX)
    }

    /// The row's [`RowExtra`], made (empty) when it has none.
    fn extra_mut(&mut self) -> &mut RowExtra {
        self.extra.get_or_insert_with(Box::default)
    }

    /// Sets [`RowExtra::load`] (no [`RowExtra`] made for `None`).
    fn set_load(&mut self, load: Option<Wrench<f64>>) {
        match (load, &mut self.extra) {
            (None, None) => {}
            (None, Some(e)) => e.load = None,
            (Some(l), _) => self.extra_mut().load = Some(l),
        }
    }

    /// The row as a [`Sample`] for the columns at `frames` (the row's own,
    /// [`Rows::frames`]) and its predicted point there `point_m` \[m,
    /// measurement frame\] ([`Rows::point_m`]), with the effective
    /// compliance of each joint
    /// (may be empty) and the unit direction of gravity \[measurement
    /// frame\] ([`Rows::gravity_unit`]; an absolute row's only: for a
    /// deflection the robot's weight is the same loaded and unloaded).
    pub fn sample<'a>(
        &'a self,
        frames: &'a Frames<f64, J>,
        point_m: Vector3<f64>,
        compliance: &'a [f64],
        gravity_unit: Vector3<f64>,
    ) -> Sample<'a, f64, J> {
        self.sample_probe(frames, point_m, 0, compliance, gravity_unit)
    }

    /// [`Row::sample`] at `point_m` with the joints' twists of probe
    /// `probe` (a pose's orientation keeps them at its point, 0, and at
    /// [`orientation::PROBES`], 1 and 2; other rows only the first).
    pub fn sample_probe<'a>(
        &'a self,
        frames: &'a Frames<f64, J>,
        point_m: Vector3<f64>,
        probe: usize,
        compliance: &'a [f64],
        gravity_unit: Vector3<f64>,
    ) -> Sample<'a, f64, J> {
        let absolute = self.kind == RowKind::Absolute;
        let twists = self.twists();
        let twists = if self.orientation && !twists.is_empty() {
            let n = twists.len() / 3;
            twists.get(probe * n..(probe + 1) * n).unwrap_or(&[])
        } else {
            twists
        };
        Sample {
            frames,
            q: &self.q,
            twists,
            point_m,
            marker: self.marker,
            tau: self.tau(),
            load: self.load(),
            absolute,
            dt_s: self.dt().unwrap_or(0.0),
            dtemp_k: self.dtemp_k().unwrap_or(0.0),
            compliance,
            gravity: if absolute {
                gravity_unit
            } else {
                Vector3::zeros()
            },
            gravity_q: self.gravity_q(),
            weight_moments_nm: self.weight_moments_nm(),
        }
    }
}

/// Every row of a data set, its configurations, and the angle bins of its
/// joints.
#[derive(Debug, Clone)]
pub struct Rows {
    /// The rows: deflections first, then absolute positions, in file order.
    pub rows: Vec<Row>,
    /// Configuration ids, one per group: the positions' groups, sorted,
    /// then the plane contacts' and distances' (module [`scalar`]), sorted,
    /// then the poses' orientations' groups, sorted (a configuration with
    /// a measured orientation is listed twice: module [`orientation`]).
    pub configs: Vec<i64>,
    /// How many of the last [`Rows::configs`] are the orientations' groups.
    pub orientation_groups: usize,
    /// How many of [`Rows::configs`], before the orientations', are the
    /// plane contacts' and distances' groups ([`Rows::scalar_range`]).
    pub scalar_groups: usize,
    /// What kinds of rows there are.
    pub kinds: DataKinds,
    /// Distinct angles \[µrad\] of each joint, in order of first appearance
    /// (empty when the joint takes more than [`crate::calibrate::settings::Policy::max_bins`]).
    pub bins: Vec<Vec<i32>>,
    /// Whether each joint's bins make a compensator candidate.
    pub compensator_ok: Vec<bool>,
    /// Gravity \[m/s², robot base frame\].
    pub gravity: Vector3<f64>,
    /// The load's centre of mass \[m, tip frame\].
    pub com: Vector3<f64>,
    /// The measurement file (for errors).
    pub file: String,
    /// The temperature column's name and the data's mean temperature
    /// \[°C\]: the reference of every row's [`Row::dtemp_k`] and of
    /// [`crate::model::Param::ThermalExpansion`]; `None` without a
    /// temperature column.
    pub temperature_ref_c: Option<(String, f64)>,
    /// The chains of the markers' links placed at the geometry of the last
    /// [`Rows::relinearise`] ([`Geometry::placed_chains`]); empty before.
    pub chains: Vec<Chain<f64, J>>,
    /// The markers' positions on their links \[m\] at the geometry of the
    /// last [`Rows::relinearise`] ([`Geometry::markers`]; empty before):
    /// with a row's frames, its predicted point ([`Rows::point_m`]).
    pub markers: Vec<Vector3<f64>>,
    /// The tool frame's rotation at the geometry of the last
    /// [`Rows::relinearise`] ([`Geometry::tool_rotation`]): a measured
    /// pose's frame is the tip's turned by it.
    pub tool_rotation: nalgebra::Rotation3<f64>,
    /// The unit direction of gravity \[measurement frame\] at the geometry
    /// of the last [`Rows::relinearise`] (zero before, and without
    /// gravity).
    pub gravity_unit: Vector3<f64>,
    /// The geometry and joint law of the last [`Rows::relinearise`], when
    /// it completed (`None` before, and after one that failed part way).
    pub at: Option<(Geometry, Linearisation)>,
}

impl Rows {
    /// Recomputes every row at `geometry` and `lin` (see
    /// [`crate::calibrate::params::linearisation`]): frames, predicted position, torques, the
    /// columns' joint twists and the left-hand side `y`.
    ///
    /// # Errors
    /// [`CalibrationError::Core`] when the forward kinematics fails;
    /// [`CalibrationError::Data`] when a loaded robot has no equilibrium
    /// near its measured pose under the current joint law.
    pub fn relinearise(
        &mut self,
        geometry: &Geometry,
        lin: &Linearisation,
    ) -> Result<(), CalibrationError> {
        let threads = crate::parallel::for_rows(self.rows.len());
        self.relinearise_on(geometry, lin, threads)
    }

    /// [`Rows::relinearise`] on `threads` threads ([`crate::parallel`]):
    /// the same rows whatever their number.
    ///
    /// # Errors
    /// As [`Rows::relinearise`] (the first row's error in row order).
    pub fn relinearise_on(
        &mut self,
        geometry: &Geometry,
        lin: &Linearisation,
        threads: usize,
    ) -> Result<(), CalibrationError> {
        self.relinearise_with(geometry, lin, threads, Vec::<()>::new(), |_, _, _, _, _| {
            Ok(())
        })
        .map(|_| ())
    }

    /// [`Rows::relinearise_on`], handing each row, once it is computed, to
    /// `then(state, k, row, frames, gravity_unit)` with the row's frames
    /// (those [`Rows::frames`] recomputes, bit for bit), `k` its index in
    /// its run: the rows are split in runs of [`run_length`] rows, and
    /// `states` holds one state per run (none: `then` is not called). A design built here needs no second forward
    /// kinematics per row ([`crate::calibrate::design::Design::relinearised`]).
    /// `then`'s first error (in row order) does not stop the rows: it is
    /// returned when they are all computed.
    ///
    /// # Errors
    /// As [`Rows::relinearise`] (the first row's error in row order).
    pub fn relinearise_with<S: Send>(
        &mut self,
        geometry: &Geometry,
        lin: &Linearisation,
        threads: usize,
        states: Vec<S>,
        then: impl Fn(&mut S, usize, &Row, &Frames<f64, J>, Vector3<f64>) -> Result<(), Error> + Sync,
    ) -> Result<Result<(), Error>, CalibrationError> {
        self.at = None;
        self.chains = geometry.placed_chains();
        self.markers.clone_from(&geometry.markers);
        self.tool_rotation = geometry.tool_rotation.to_rotation_matrix();
        let chains = &self.chains;
        // Whether each chain has a mass model (its links' own weight).
        let weighs: Vec<bool> = chains
            .iter()
            .map(|c| c.joints().iter().any(|j| j.link.is_some()))
            .collect();
        let weighs = &weighs;
        // The frames are in the measurement frame, gravity is given in the
        // robot's base frame.
        let gravity = geometry.base.rotation * self.gravity;
        let g_unit = gravity.try_normalize(0.0).unwrap_or_else(Vector3::zeros);
        self.gravity_unit = g_unit;
        let com = self.com;
        let file: &str = &self.file;
        // With several threads, a run after the first row that fails may
        // already have moved its rows' equilibria, the starting points of
        // the next relinearisation (a damped step retries from them); the
        // serial loop stops at that row: their starting points are put back,
        // so that the retry is the same on any number of threads. (Only the
        // exact model starts from them.)
        let before: Option<Vec<Vec<f64>>> = (threads > 1
            && lin.model == crate::calibrate::params::linearisation::DeflectionModel::Exact)
            .then(|| self.rows.iter().map(|r| r.theta().to_vec()).collect());
        // A measured pose's frame: the tip's turned by the tool's rotation.
        let tool = geometry.tool_rotation.to_rotation_matrix();
        // `rigid`: the run's frames of a rigid row, filled in place; `sink`
        // gets the row and its frames.
        let one = |row: &mut Row,
                   rigid: &mut Frames<f64, J>,
                   sink: &mut dyn FnMut(&Row, &Frames<f64, J>)|
         -> Result<(), CalibrationError> {
            let m = marker_m(&geometry.markers, row);
            let absolute = row.kind == RowKind::Absolute;
            // The chain of the row's marker's link (one end but for a tree).
            let end = geometry.end_of(row.marker).min(chains.len() - 1);
            let chain = &chains[end];
            row.chain = u32::try_from(end).unwrap_or(u32::MAX);
            let loading = Loading {
                load: (!absolute).then_some(PointLoad {
                    mass_kg: row.load_kg(),
                    com_m: com,
                    gravity_mps2: gravity,
                }),
                own_weight_mps2: absolute.then_some(gravity),
            };
            // (Borrows the file's name: a copy per call was two allocations
            // per row and relinearisation.)
            let line = row.line;
            let core = |what: &'static str| {
                move |e: Error| match e {
                    Error::NotConverged { .. }
                    | Error::NotIdentifiable { .. }
                    | Error::NonFinite {
                        what: "equilibrium",
                    } => CalibrationError::NoEquilibrium(format!(
                        "{file}:{line}: the loaded robot has no equilibrium near the \
                         measured pose under the current joint law ({e})"
                    )),
                    e => CalibrationError::Core(what, e),
                }
            };
            if let Some(e) = &mut row.extra {
                e.gravity_q.clear();
            }
            if absolute
                && lin.model == crate::calibrate::params::linearisation::DeflectionModel::Exact
                && lin.needs_gravity()
            {
                // The gravity compliance's deflection at the commanded pose.
                let at_q = chain.frames(&row.q).map_err(core("forward kinematics"))?;
                let g = lin.gravity_at(&at_q, &g_unit);
                if !g.is_empty() || row.extra.is_some() {
                    row.extra_mut().gravity_q = g;
                }
            }
            match lin.law(&row.q, absolute, row.gravity_q()) {
                None => {
                    chain
                        .frames_into(&row.q, rigid)
                        .map_err(core("forward kinematics"))?;
                    let mut tau = [0.0; J];
                    let tau = &mut tau[..row.q.len().min(J)];
                    loading
                        .torques(chain, rigid, tau)
                        .map_err(core("torques"))?;
                    row.set_tau(tau);
                    row.set_weight_moments(weighs[end], chain, rigid, &gravity)
                        .map_err(core("torques"))?;
                    row.set_load(loading.load.map(|l| l.wrench(rigid)));
                    row.set_theta(&[]);
                    if let Some(e) = &mut row.extra {
                        e.twists.clear();
                    }
                    if let Some(e) = &mut row.extra {
                        e.y = None;
                    }
                    sink(row, rigid);
                }
                Some(law) => {
                    // The rigid robot's point: only a deflection row
                    // subtracts it.
                    let p_rigid = if absolute {
                        Vector3::zeros()
                    } else {
                        chain
                            .frames(&row.q)
                            .map_err(core("forward kinematics"))?
                            .point_m(&m)
                    };
                    // From the last equilibrium of this row when there is
                    // one (the law moves little between relinearisations).
                    let guess: Vec<f64> = if row.theta().len() == row.q.len() {
                        row.theta().to_vec()
                    } else {
                        row.q.to_vec()
                    };
                    let eq = equilibrium(chain, &row.q, &guess, &loading, &law, &EQUILIBRIUM)
                        .or_else(|_| {
                            equilibrium(chain, &row.q, &row.q, &loading, &law, &EQUILIBRIUM)
                        })
                        .map_err(core("equilibrium"))?;
                    let dof = row.q.len();
                    // A joint that softens under torque (nonlinear stiffness)
                    // until its stiffness turns negative has no stable
                    // equilibrium there.
                    if let Some(j) = (0..dof)
                        .find(|&j| law.quadratic[j] != 0.0 && law.deflection(j, eq.tau[j]).1 < 0.0)
                    {
                        return Err(CalibrationError::NoEquilibrium(format!(
                            "{file}:{}: joint {} would have a negative stiffness at its \
                             torque of {:.3} (nonlinear stiffness)",
                            row.line,
                            j + 1,
                            eq.tau[j]
                        )));
                    }
                    let p = eq.frames.point_m(&m);
                    // A pose's orientation: the twists at the point and
                    // at its probes, one block each (module `orientation`).
                    let probes: &[Vector3<f64>] = if row.orientation {
                        &[
                            Vector3::new(0.0, 0.0, 0.0),
                            orientation::PROBES[0],
                            orientation::PROBES[1],
                        ]
                    } else {
                        &[Vector3::new(0.0, 0.0, 0.0)]
                    };
                    let twists: Vec<Vector3<f64>> = probes
                        .iter()
                        .flat_map(|d| (0..dof).map(move |j| (j, p + d)))
                        .map(|(j, at)| eq.twist_column(j, &at))
                        .collect::<Result<_, _>>()
                        .map_err(core("equilibrium"))?;
                    if !twists.is_empty() || row.extra.is_some() {
                        row.extra_mut().twists = twists;
                    }
                    let linear: Vector3<f64> = (0..dof)
                        .zip(&eq.deflection)
                        .map(|(j, d)| row.joint_column(j) * *d)
                        .sum();
                    row.set_tau(&eq.tau[..dof]);
                    row.set_weight_moments(weighs[end], chain, &eq.frames, &gravity)
                        .map_err(core("torques"))?;
                    row.set_load(loading.load.map(|l| l.wrench(&eq.frames)));
                    row.extra_mut().y = Some(if row.orientation {
                        orientation::residual(
                            &row.measured,
                            &(eq.frames.tip().rotation.to_rotation_matrix() * tool),
                        ) + linear
                    } else if let Some(s) = row.scalar() {
                        s.lhs(&p, &linear)
                    } else if absolute {
                        row.measured - p + linear
                    } else {
                        row.measured - (p - p_rigid) + linear
                    });
                    row.set_theta(eq.frames.q());
                    sink(row, &eq.frames);
                }
            }
            Ok(())
        };
        // One item per run ([`run_length`]), with its state and `then`'s
        // first error; the threads take the runs in turn.
        let per = run_length(self.rows.len(), threads);
        let mut states = states.into_iter();
        let mut runs: Vec<Run<'_, S>> = self
            .rows
            .chunks_mut(per)
            .map(|run| (run, states.next(), Ok(())))
            .collect();
        let done = crate::parallel::for_each_mut(&mut runs, threads, |r, (run, state, failed)| {
            let mut rigid = Frames::empty();
            for (k, row) in run.iter_mut().enumerate() {
                let mut sink = |row: &Row, frames: &Frames<f64, J>| {
                    if let (Some(state), Ok(())) = (state.as_mut(), &*failed) {
                        *failed = then(state, k, row, frames, g_unit);
                    }
                };
                one(row, &mut rigid, &mut sink).map_err(|e| (r * per + k, e))?;
            }
            Ok(())
        });
        let then_failed = runs.into_iter().try_for_each(|(_, _, f)| f);
        if let Err((at, e)) = done {
            if let Some(before) = before {
                for (row, theta) in self.rows.iter_mut().zip(before).skip(at + 1) {
                    row.set_theta(&theta);
                }
            }
            return Err(e);
        }
        self.at = Some((geometry.clone(), lin.clone()));
        Ok(then_failed)
    }

    /// Where each row's next equilibrium starts: the `θ` of its last one
    /// (empty where it has none), for [`Rows::start_from`].
    pub fn start_points(&self) -> Vec<Vec<f64>> {
        self.rows.iter().map(|r| r.theta().to_vec()).collect()
    }

    /// Makes `start` ([`Rows::start_points`] of these rows) the starting
    /// points of the next relinearisation. Relinearised at the law and
    /// geometry they were taken at, the rows are those of then, bit for
    /// bit: Newton's method from an equilibrium takes no step, and the
    /// frames are the forward kinematics at its `θ`.
    pub fn start_from(&mut self, start: &[Vec<f64>]) {
        for (row, theta) in self.rows.iter_mut().zip(start) {
            row.set_theta(theta);
        }
    }

    /// Rows per configuration.
    pub fn per_group(&self) -> Vec<usize> {
        let mut n = vec![0usize; self.configs.len()];
        for r in &self.rows {
            n[r.group()] += 1;
        }
        n
    }
}

/// Whether a joint is revolute in `names`.
pub(crate) fn revolute(names: &Names, j: usize) -> bool {
    names.kinds.get(j) == Some(&JointKind::Revolute)
}

impl Rows {
    /// The rows of points (deflections and absolute positions): the first
    /// ones, before every plane contact, distance (module [`scalar`]) and
    /// pose's orientation (module [`orientation`]).
    pub fn positions(&self) -> usize {
        if self.orientation_groups == 0 && self.scalar_groups == 0 {
            return self.rows.len();
        }
        self.rows
            .iter()
            .position(|r| r.orientation || r.scalar().is_some())
            .unwrap_or(self.rows.len())
    }

    /// The configurations of points: the groups before the plane
    /// contacts' and distances', and the orientations'.
    pub fn position_groups(&self) -> usize {
        self.configs.len() - self.orientation_groups - self.scalar_groups
    }

    /// The first rows, whose errors are reported in µm (RMS, held-out,
    /// per row): the points, or in data of plane contacts and distances
    /// alone, those (module [`scalar`]; then the first rows).
    pub fn error_rows(&self) -> usize {
        match self.positions() {
            0 => self.scalar_rows().end,
            n => n,
        }
    }

    /// The groups of [`Rows::error_rows`]: the first ones.
    pub fn error_groups(&self) -> usize {
        match self.position_groups() {
            0 => self.scalar_groups,
            n => n,
        }
    }

    /// Whether the points are a pivot's: at least three absolute points,
    /// each marker's all measured at one place
    /// ([`crate::calibrate::params::geometry::PIVOT_M`]) — a point held
    /// still while the robot turns about it.
    pub fn pivot(&self) -> bool {
        let mut first: Vec<Option<Vector3<f64>>> = vec![None; usize::from(u8::MAX) + 1];
        let mut n = 0;
        for r in (self.rows[..self.positions()].iter()).filter(|r| r.kind == RowKind::Absolute) {
            let f = first[usize::from(r.marker)].get_or_insert(r.measured);
            if (r.measured - *f).norm() >= crate::calibrate::params::geometry::PIVOT_M {
                return false;
            }
            n += 1;
        }
        n >= 3
    }

    /// The groups of the plane contacts and distances (module [`scalar`]):
    /// after the points', before the orientations'.
    pub fn scalar_range(&self) -> std::ops::Range<usize> {
        let start = self.position_groups();
        start..start + self.scalar_groups
    }

    /// The runs of groups of one quantity, whose σ pool apart
    /// ([`crate::calibrate::design::Design::pools`]): the points', the
    /// plane contacts' and distances', the orientations' (those there are).
    pub fn pools(&self) -> Vec<std::ops::Range<usize>> {
        let s = self.scalar_range();
        [0..s.start, s.clone(), s.end..self.configs.len()]
            .into_iter()
            .filter(|r| !r.is_empty())
            .collect()
    }

    /// The equations of the rows: three a row, one a plane contact or a
    /// distance (module [`scalar`]).
    pub fn equations(&self) -> usize {
        3 * self.rows.len() - 2 * self.scalar_rows().len()
    }

    /// The rows of the plane contacts and distances: after the points,
    /// before the orientations.
    pub fn scalar_rows(&self) -> std::ops::Range<usize> {
        let start = self.positions();
        let n = self.rows[start..]
            .iter()
            .take_while(|r| r.scalar().is_some())
            .count();
        start..start + n
    }

    /// The groups a configuration left out takes with it (the held-out
    /// error's folds, [`crate::calibrate::engine::Engine::heldout`]): its points'
    /// group `g` and, when it is a measured pose, its orientations' group —
    /// the same configuration, measured by the same instrument in the same
    /// pose. A group past the points' is its own fold.
    pub fn fold(&self, g: usize) -> Vec<usize> {
        let (points, scalars) = (self.position_groups(), self.scalar_range());
        let Some(c) = (g < points).then(|| self.configs.get(g)).flatten() else {
            return vec![g];
        };
        let found = |r: std::ops::Range<usize>| {
            let start = r.start;
            self.configs[r].binary_search(c).ok().map(|k| start + k)
        };
        core::iter::once(g)
            .chain(found(scalars.clone()))
            .chain(found(scalars.end..self.configs.len()))
            .collect()
    }
}
