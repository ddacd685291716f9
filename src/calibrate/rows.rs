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

use std::collections::BTreeMap;

use nalgebra::Vector3;

use super::geometry::{Geometry, J};
use super::names::Names;
use super::settings::{CalibrationError, Policy};
use crate::io::{Job, Measurements};
use crate::model::{angle_urad, Param, Sample, BIN_TOLERANCE_RAD};
use crate::robot::{gravity_torques, joint_torques, Frames, JointKind, PointLoad, Wrench};
use crate::Error;

/// What one row of the problem is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowKind {
    /// Loaded minus unloaded position of one marker (elastostatic, eq. 3).
    Deflection,
    /// Unloaded position minus its forward kinematics (geometric, eq. 2).
    Absolute,
}

/// One row (three equations) of the identification problem.
#[derive(Debug, Clone)]
pub struct Row {
    /// Deflection or absolute position.
    pub kind: RowKind,
    /// Index of the configuration (the group of the noise estimate).
    pub group: usize,
    /// `config` as in the CSV.
    pub config: i64,
    /// Marker index (into [`Names::markers`]).
    pub marker: u8,
    /// Load \[kg\] (0 for absolute rows).
    pub load_kg: f64,
    /// Joint values \[rad or m\].
    pub q: Vec<f64>,
    /// Time \[s\] relative to the data's mean time (absolute rows) or between
    /// the unloaded and the loaded measurement (deflection rows).
    pub dt: Option<f64>,
    /// What was measured \[m\]: the position (absolute rows, measurement
    /// frame) or the deflection.
    pub measured: Vector3<f64>,
    /// CSV line (of the loaded row for deflections).
    pub line: usize,
    /// Frames at `q` in the current model, in the measurement frame.
    pub frames: Frames<f64, J>,
    /// Predicted marker position \[m, measurement frame\] at `q`.
    pub p: Vector3<f64>,
    /// Joint torques behind the row: the load's (deflection rows) or the
    /// links' own weight (absolute rows) \[N·m or N\].
    pub tau: Vec<f64>,
    /// The load's wrench (deflection rows).
    pub load: Option<Wrench<f64>>,
    /// `Δp` \[m\]: measured minus predicted at the current model (absolute
    /// rows), or the measured deflection.
    pub y: Vector3<f64>,
}

impl Row {
    /// The row as a [`Sample`] for the columns, with the effective
    /// compliance of each joint (may be empty).
    pub fn sample<'a>(&'a self, compliance: &'a [f64]) -> Sample<'a, f64, J> {
        Sample {
            frames: &self.frames,
            point_m: self.p,
            marker: self.marker,
            tau: &self.tau,
            load: self.load,
            absolute: self.kind == RowKind::Absolute,
            dt_s: self.dt.unwrap_or(0.0),
            compliance,
        }
    }
}

/// Which kinds of rows there are (what the data can show).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DataKinds {
    /// Deflection rows (a load).
    pub deflections: bool,
    /// Absolute rows (geometric calibration).
    pub absolute: bool,
    /// A time column.
    pub time: bool,
}

/// Every row of a data set, its configurations, and the angle bins of its
/// joints.
#[derive(Debug, Clone)]
pub struct Rows {
    /// The rows: deflections first, then absolute positions, in file order.
    pub rows: Vec<Row>,
    /// Configuration ids, one per group, sorted.
    pub configs: Vec<i64>,
    /// What kinds of rows there are.
    pub kinds: DataKinds,
    /// Distinct angles \[µrad\] of each joint, in order of first appearance
    /// (empty when the joint takes more than [`Policy::max_bins`]).
    pub bins: Vec<Vec<i32>>,
    /// Whether each joint's bins make a compensator candidate.
    pub compensator_ok: Vec<bool>,
    /// Gravity \[m/s², robot base frame\].
    pub gravity: Vector3<f64>,
    /// The load's centre of mass \[m, tip frame\].
    pub com: Vector3<f64>,
}

/// Values within `tol` of a running cluster mean, merged; the cluster
/// means, sorted.
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

impl Rows {
    /// The rows of `data`: its deflections, and its absolute positions when
    /// `absolute` (or when there is no deflection). Frames, torques and the
    /// absolute rows' `Δp` are computed by [`Rows::relinearise`].
    ///
    /// # Errors
    /// [`CalibrationError::Data`] when there is no row;
    /// [`CalibrationError::Core`] when the forward kinematics fails.
    pub fn new(
        job: &Job,
        data: &Measurements,
        absolute: bool,
        names: &mut Names,
        policy: &Policy,
    ) -> Result<Self, CalibrationError> {
        let setup = &job.setup;
        let chain = &job.robot.chain;
        let dof = job.robot.dof();
        let use_absolute = absolute || data.deflections.is_empty();
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

        // Angle bins per joint, from the rows that enter the problem, in
        // order of first appearance in the file (k21, k22, … of the paper).
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
            let mut centres = cluster(&values, BIN_TOLERANCE_RAD);
            let first = |c: f64| {
                values
                    .iter()
                    .position(|v| (v - c).abs() <= BIN_TOLERANCE_RAD)
            };
            centres.sort_by_key(|&c| first(c));
            let mut jb = Vec::new();
            let mut counts = Vec::new();
            if centres.len() <= policy.max_bins {
                for c in &centres {
                    let near = |v: &&(f64, &str, i64)| (v.0 - c).abs() <= BIN_TOLERANCE_RAD;
                    let written = qs
                        .iter()
                        .find(near)
                        .map_or_else(|| format!("{c}"), |v| v.1.trim().to_string());
                    let mut cfgs: Vec<i64> = qs.iter().filter(near).map(|v| v.2).collect();
                    cfgs.sort_unstable();
                    cfgs.dedup();
                    counts.push(cfgs.len());
                    let a = angle_urad(*c);
                    names.bins.insert((j as u8, a), written);
                    jb.push(a);
                }
            }
            compensator_ok.push(policy.compensator_eligible(&counts));
            bins.push(jb);
        }

        let index_of = |id: u32| names.marker_index(id).unwrap_or(0);
        let core = |what: &'static str| move |e: Error| CalibrationError::Core(what, e);
        let mut rows = Vec::new();
        let mut row = |kind, config, marker, load_kg, q: &[f64], dt, measured: [f64; 3], line| {
            rows.push(Row {
                kind,
                group: group_of(config),
                config,
                marker: index_of(marker),
                load_kg,
                q: q.to_vec(),
                dt,
                measured: Vector3::from(measured),
                line,
                frames: chain.frames(q).map_err(core("forward kinematics"))?,
                p: Vector3::zeros(),
                tau: vec![0.0; dof],
                load: None,
                y: Vector3::from(measured),
            });
            Ok::<(), CalibrationError>(())
        };
        for d in &data.deflections {
            let (loaded, unloaded) = (&data.observations[d.rows[0]], &data.observations[d.rows[1]]);
            let dt = loaded.t_s.zip(unloaded.t_s).map(|(a, b)| a - b);
            row(
                RowKind::Deflection,
                d.config,
                d.marker,
                d.load_kg,
                &d.q,
                dt,
                d.dp_m,
                d.lines[0],
            )?;
        }
        if use_absolute {
            for o in data.unloaded() {
                let dt = o.t_s.map(|t| t - t_mean);
                row(
                    RowKind::Absolute,
                    o.config,
                    o.marker,
                    0.0,
                    &o.q,
                    dt,
                    o.p_m,
                    o.line,
                )?;
            }
        }
        if rows.is_empty() {
            return Err(CalibrationError::Data(format!(
                "{}: no rows to calibrate from",
                data.file.display()
            )));
        }
        let kinds = DataKinds {
            deflections: rows.iter().any(|r| r.kind == RowKind::Deflection),
            absolute: rows.iter().any(|r| r.kind == RowKind::Absolute),
            time: data.has_time,
        };
        Ok(Self {
            rows,
            configs,
            kinds,
            bins,
            compensator_ok,
            gravity,
            com,
        })
    }

    /// Recomputes every row at `geometry`: frames, predicted position and
    /// torques, and `Δp` of the absolute rows (a deflection row's `Δp` is
    /// what was measured; its columns move with the model, e.g. into the
    /// measurement frame once the base is placed).
    ///
    /// # Errors
    /// [`CalibrationError::Core`] when the forward kinematics fails.
    pub fn relinearise(&mut self, geometry: &Geometry) -> Result<(), CalibrationError> {
        let chain = geometry.placed_chain();
        // The frames are in the measurement frame, gravity is given in the
        // robot's base frame.
        let gravity = geometry.base.rotation * self.gravity;
        let core = |what: &'static str| move |e: Error| CalibrationError::Core(what, e);
        for row in &mut self.rows {
            let m = geometry
                .markers
                .get(usize::from(row.marker))
                .copied()
                .unwrap_or_default();
            row.frames = chain.frames(&row.q).map_err(core("forward kinematics"))?;
            row.p = row.frames.point_m(&m);
            match row.kind {
                RowKind::Absolute => {
                    gravity_torques(&chain, &row.frames, &gravity, &mut row.tau)
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
                    joint_torques(&row.frames, &wrench, &mut row.tau)
                        .map_err(core("load torques"))?;
                    row.load = Some(wrench);
                }
            }
        }
        Ok(())
    }

    /// Rows per configuration.
    pub fn per_group(&self) -> Vec<usize> {
        let mut n = vec![0usize; self.configs.len()];
        for r in &self.rows {
            n[r.group] += 1;
        }
        n
    }
}

/// The current compliance estimate, about which the linearised effects
/// (`load_com`) are taken: the SI value of every compliance parameter.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Compliances(BTreeMap<Param, f64>);

impl Compliances {
    /// The compliances of a fit of `params` with estimate `x` (reported
    /// units).
    pub fn of(params: &[Param], x: &[f64], names: &Names) -> Self {
        Self(
            params
                .iter()
                .zip(x)
                .filter(|(p, _)| p.is_compliance())
                .map(|(p, v)| (*p, v * names.unit(p).si))
                .collect(),
        )
    }

    /// The effective compliance of every joint at `row` \[rad/(N·m) or
    /// m/N\]: its constant compliance plus that of the bin it is in.
    pub fn at(&self, row: &Row) -> Vec<f64> {
        let mut k = vec![0.0; row.q.len()];
        for (p, &v) in &self.0 {
            match *p {
                Param::Compliance { joint } => k[usize::from(joint)] += v,
                Param::ComplianceAt { joint, angle_urad }
                    if crate::model::in_bin(angle_urad, row.q[usize::from(joint)]) =>
                {
                    k[usize::from(joint)] += v;
                }
                _ => {}
            }
        }
        k
    }

    /// Whether any compliance moved by more than `rel` of its value from
    /// `other`'s.
    pub fn moved(&self, other: &Self, rel: f64) -> bool {
        self.0.len() != other.0.len()
            || self
                .0
                .iter()
                .zip(&other.0)
                .any(|((p, a), (q, b))| p != q || (a - b).abs() > rel * b.abs().max(1e-12))
    }
}

/// Whether a joint is revolute in `names`.
pub(crate) fn revolute(names: &Names, j: usize) -> bool {
    names.kinds.get(j) == Some(&JointKind::Revolute)
}
