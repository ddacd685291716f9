//! The declared model on varied poses: which of the parameters the data
//! leave out other poses would identify.
//!
//! A declared parameter that the independence test leaves out
//! ([`crate::estimate::rank`]) keeps its nominal value. When the dependence
//! is the model's own — the first joint's offset and the base's turn about
//! z, the same motion at every pose — the kept parameters absorb it
//! exactly, everywhere, and nothing is lost. When it is the data's — a
//! tool's length measured in a narrow range of orientations — they absorb
//! it only at poses like the measured ones: elsewhere an error in the
//! nominal value shows (a real recording: a tool 16 mm off its nominal
//! length, left out, missed another session by 2.7 mm with no warning).
//!
//! This module tells the two apart. The declared geometric parameters are
//! tested again, at the nominal robot, on [`Policy::varied_poses`]
//! configurations drawn within the joint limits (the URDF's; a joint
//! without limits: a revolute over a turn, a prismatic over the data's
//! range) with every marker, unloaded, measured as the data are (points;
//! or in data of plane contacts and distances alone, each of their planes
//! and anchors). A parameter left out on the data
//! but kept there is the data's dependence: a warning names it and how far
//! off its nominal value could show — each unit of error, with the
//! absorbing parameters' share taken as the data take it, moves the points
//! of the varied poses by up to that many mm
//! ([`crate::calibrate::report::plausibility`]).
//!
//! [`Policy::varied_poses`]: crate::calibrate::settings::Policy::varied_poses

use std::borrow::Cow;
use std::sync::Arc;

use crate::calibrate::design::Design;
use crate::calibrate::engine::Engine;
use crate::calibrate::params::linearisation::Linearisation;
use crate::calibrate::report::LeftOut;
use crate::calibrate::rows::Rows;
use crate::calibrate::settings::CalibrationError;
use crate::io::job::Job;
use crate::io::measurements::{Measurements, Observation};
use crate::model::Param;
use crate::robot::JointKind;

/// The declared geometric parameters on varied poses: which are kept there,
/// and their columns.
pub struct Varied {
    /// The declared geometric parameters, in the declared order.
    params: Vec<Param>,
    /// Whether each is kept on the varied poses.
    kept: Vec<bool>,
    /// Their columns at the varied poses (`3·rows × params`, m per
    /// reported unit).
    design: Arc<Design>,
    /// Their names.
    names: Vec<String>,
    /// Their units.
    units: Vec<String>,
    /// The joints the data hold still (within a thousandth of their
    /// range).
    still: Vec<String>,
}

/// Uniform values in [0, 1) from `seed` (a linear congruential generator:
/// the same poses on every machine).
fn uniform(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed;
    move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The declared geometric parameters of `model` tested on varied poses of
/// `job`'s robot; `data` is the engine of the data (their rows give the
/// range of a joint without limits; its names, settings and policy are
/// used). `None` when `model` has no geometric parameter.
///
/// # Errors
/// As [`Rows::from_measurements`] and [`Engine::design`].
pub fn varied(
    job: &Job,
    data: &Engine<'_>,
    model: &[Param],
) -> Result<Option<Varied>, CalibrationError> {
    let (rows, names, policy) = (&*data.rows, &data.names, &data.policy);
    let params: Vec<Param> = model.iter().copied().filter(Param::is_geometric).collect();
    // (A pivot's points cannot be measured at varied poses: a pivot holds
    // the robot's point still.)
    if params.is_empty() || policy.varied_poses == 0 || rows.pivot() {
        return Ok(None);
    }
    let chain = &job.robot.chain;
    let dof = job.robot.dof();
    // Each joint's values in the data.
    let seen: Vec<(f64, f64)> = (0..dof)
        .map(|j| {
            let (lo, hi) = rows.rows.iter().fold((f64::MAX, f64::MIN), |(lo, hi), r| {
                let q = r.q.get(j).copied().unwrap_or(0.0);
                (lo.min(q), hi.max(q))
            });
            if lo <= hi {
                (lo, hi)
            } else {
                (0.0, 0.0)
            }
        })
        .collect();
    // Each joint's range: its limits, else a turn (revolute) or the data's.
    let range: Vec<(f64, f64)> = (0..dof)
        .map(|j| {
            if let Some(Some(l)) = job.robot.limits.get(j) {
                return (l.lower, l.upper);
            }
            if chain.joints()[j].kind == JointKind::Revolute {
                return (-core::f64::consts::PI, core::f64::consts::PI);
            }
            seen[j]
        })
        .collect();
    // The joints the data hold still: within a thousandth of their range.
    let still: Vec<String> = (0..dof)
        .filter(|&j| {
            let (lo, hi) = seen[j];
            let (a, b) = range[j];
            hi - lo <= 1e-3 * (b - a) && b > a
        })
        .map(|j| names.joint(j as u8).to_string())
        .collect();
    // Measured as the data are: points, or in data of plane contacts and
    // distances alone, those of each of the data's planes and anchors (a
    // plane never tells a shift along it, whatever the pose).
    let mut targets: Vec<Option<crate::io::measurements::Scalar>> = Vec::new();
    if rows.positions() == 0 {
        for r in &rows.rows {
            let t = r.scalar().copied().map(|mut t| {
                match &mut t {
                    crate::io::measurements::Scalar::Plane { value_m, .. }
                    | crate::io::measurements::Scalar::Distance { value_m, .. } => *value_m = 0.0,
                }
                t
            });
            if t.is_some() && !targets.contains(&t) {
                targets.push(t);
            }
        }
    }
    if targets.is_empty() {
        targets.push(None);
    }
    let mut next = uniform(0x5eed_0f7a_21ed);
    let mut observations = Vec::new();
    for config in 0..policy.varied_poses {
        let q: crate::io::measurements::JointValues = range
            .iter()
            .map(|&(lo, hi)| lo + (hi - lo) * next())
            .collect();
        for m in &job.setup.markers {
            for &scalar in &targets {
                observations.push(Observation {
                    config: config as i64,
                    rep: 1,
                    marker: m.id,
                    q: q.clone(),
                    scalar,
                    ..Observation::default()
                });
            }
        }
    }
    let poses = Measurements {
        file: "varied poses".into(),
        observations,
        deflections: Vec::new(),
        has_time: false,
        warnings: Vec::new(),
        cells_in_file: None,
    };
    let mut names = names.clone();
    let rows = Rows::build(job, Cow::Owned(poses), true, &mut names, policy)?;
    let mut quiet = |_: &str| {};
    let mut e = Engine::nominal(
        job,
        rows,
        names,
        Linearisation::nominal(data.lin.model),
        data.fit_settings,
        *policy,
        &mut quiet,
    );
    e.relinearise_for(&params)?;
    let design = e.design(&params)?;
    let all: Vec<usize> = (0..params.len()).collect();
    let kept = match design.identifiability(&[], &all) {
        Some(rank) => (0..params.len()).map(|i| rank.kept[i]).collect(),
        None => vec![false; params.len()],
    };
    let names = params.iter().map(|p| e.names.name(p)).collect();
    let units = params
        .iter()
        .map(|p| e.names.unit(p).name.to_string())
        .collect();
    Ok(Some(Varied {
        params,
        kept,
        design,
        names,
        units,
        still,
    }))
}

/// A declared parameter the data leave out that the varied poses
/// identify.
#[derive(Debug, Clone, PartialEq)]
pub struct DataDependence {
    /// Its name.
    pub name: String,
    /// Its unit.
    pub unit: String,
    /// The kept parameters that absorb it on the data.
    pub absorbed_by: Vec<String>,
    /// The largest displacement \[mm\] of a marker at the varied poses per
    /// unit of error in it, the absorbers' share (their coefficients on
    /// the data) taken off.
    pub mm_per_unit: f64,
    /// The joints the data hold still.
    pub still: Vec<String>,
}

impl Varied {
    /// Which of `left_out` (the report's) the varied poses identify, with
    /// how far an error in each shows there.
    pub fn data_dependences(&self, left_out: &[LeftOut]) -> Vec<DataDependence> {
        let index = |name: &str| self.names.iter().position(|n| n == name);
        let b = self.design.held();
        let rows = self.design.rows();
        left_out
            .iter()
            .filter_map(|l| {
                let i = index(&l.name)?;
                if !self.kept[i] {
                    return None;
                }
                // Its column less the absorbers' share on the data.
                let terms: Vec<(usize, f64)> = l
                    .absorbed_by
                    .iter()
                    .filter_map(|a| Some((index(&a.name)?, a.coefficient)))
                    .collect();
                let worst = (0..rows)
                    .map(|r| {
                        let d = nalgebra::Vector3::from_fn(|a, _| {
                            let row = 3 * r + a;
                            b[(row, i)] - terms.iter().map(|&(k, c)| c * b[(row, k)]).sum::<f64>()
                        });
                        d.norm()
                    })
                    .fold(0.0, f64::max);
                Some(DataDependence {
                    name: l.name.clone(),
                    unit: self.units[i].clone(),
                    absorbed_by: l.absorbed_by.iter().map(|a| a.name.clone()).collect(),
                    mm_per_unit: worst * 1e3,
                    still: self.still.clone(),
                })
            })
            .collect()
    }

    /// The declared geometric parameters, in order.
    pub fn params(&self) -> &[Param] {
        &self.params
    }
}

impl DataDependence {
    /// The report's warning.
    pub fn warning(&self) -> String {
        let why = if self.absorbed_by.is_empty() {
            "these poses do not move the markers with it".to_string()
        } else {
            format!(
                "these poses cannot tell it from {}",
                self.absorbed_by.join(", ")
            )
        };
        let vary = if self.still.is_empty() {
            "other orientations of the tool, other joint values".to_string()
        } else {
            format!("the data hold {} still", self.still.join(", "))
        };
        format!(
            "{} is left out ({why}), but poses varied within the joint limits would identify \
             it: it keeps its nominal value, and each {} it is off moves other poses' points \
             by up to {:.2} mm; measure poses that vary more ({vary}), or remove it from \
             [model]",
            self.name, self.unit, self.mm_per_unit
        )
    }
}
