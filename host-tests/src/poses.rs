//! Arms measured as 6-D poses (data contract extension `rx, ry, rz`): a
//! true robot whose joint zeros and tool frame are off, seen by an
//! instrument that gives a point and an orientation per pose, with its σ.
//! Nothing here calls robcal's kinematics, columns or engine: the forward
//! kinematics is [`super::exact::Fk`] (urdf-rs, 4 × 4 matrices), the
//! orientation's noise a rotation `Exp(n)` of the true frame in the
//! measurement frame, the rotation vector nalgebra's.

use std::path::Path;

use nalgebra::{Matrix3, Rotation3, Vector3};
use robcal_paper::rng::SplitMix64;

use super::exact::Fk;

/// An arm: its URDF chain, joint names and the ranges poses are drawn
/// from \[rad\], the probe's origin on the tip link \[m\].
#[derive(Debug, Clone)]
pub struct Arm {
    /// The chain from the base link to the tip link.
    pub fk: Fk,
    /// Movable joints, in chain order.
    pub joints: Vec<String>,
    /// Each joint's range \[rad\].
    pub ranges: Vec<(f64, f64)>,
    /// The probe's origin on the tip link \[m\] (the setup's marker).
    pub marker_m: Vector3<f64>,
}

impl Arm {
    /// The UR10 of `shared/repro/ur10-offsets` (`ur10.urdf` in `dir`),
    /// base to flange, every joint within ±3 rad, the probe 0.1 m out.
    pub fn ur10(dir: &Path) -> Self {
        Self {
            fk: Fk::new(&dir.join("ur10.urdf"), "base_link", "flange"),
            joints: super::arms::UR10_JOINTS.map(String::from).to_vec(),
            ranges: vec![(-3.0, 3.0); 6],
            marker_m: Vector3::new(0.0, 0.0, 0.1),
        }
    }

    /// The KR-270 of `data/kr270` (`kr270.urdf` in `dir`), base to
    /// `tool0`, within its limits, the probe at marker 1's position.
    pub fn kr270(dir: &Path) -> Self {
        Self {
            fk: Fk::new(&dir.join("kr270.urdf"), "base_link", "tool0"),
            joints: ["a1", "a2", "a3", "a4", "a5", "a6"]
                .map(String::from)
                .to_vec(),
            ranges: vec![
                (-3.0, 3.0),
                (-2.3, -0.2),
                (-1.9, 2.7),
                (-3.0, 3.0),
                (-2.0, 2.0),
                (-3.0, 3.0),
            ],
            marker_m: Vector3::new(0.0, 0.30, 0.20),
        }
    }
}

/// The truth of one job: joint zeros \[rad\] and the tool frame's error
/// (translation \[m\], rotation vector \[rad\], in the tip frame: every
/// point on the tip link `r ← t + R r`).
#[derive(Debug, Clone)]
pub struct Truth {
    /// Joint zeros \[rad\]: added to the commanded values.
    pub offsets: Vec<f64>,
    /// The tool frame's translation \[m\].
    pub tool_t: Vector3<f64>,
    /// The tool frame's rotation vector \[rad\].
    pub tool_r: Vector3<f64>,
}

impl Truth {
    /// Joint zeros within ±1 mrad, but the last joint's (the tool frame's
    /// turn about its axis, which data cannot tell from it: 0), the tool
    /// within ±0.5 mm and ±0.5 mrad.
    pub fn draw(rng: &mut SplitMix64, dof: usize) -> Self {
        Self {
            offsets: (0..dof)
                .map(|j| {
                    if j + 1 == dof {
                        0.0
                    } else {
                        rng.range(-1e-3, 1e-3)
                    }
                })
                .collect(),
            tool_t: Vector3::from_fn(|_, _| rng.range(-0.5e-3, 0.5e-3)),
            tool_r: Vector3::from_fn(|_, _| rng.range(-0.5e-3, 0.5e-3)),
        }
    }

    /// The truth of a parameter by its report name (`<joint>.offset`,
    /// `tool.tx` … `tool.rz`) in the report's units (mrad, mm).
    pub fn value(&self, arm: &Arm, name: &str) -> Option<f64> {
        if let Some(j) = name.strip_suffix(".offset") {
            let k = arm.joints.iter().position(|n| n == j)?;
            return Some(self.offsets[k] * 1e3);
        }
        let axis = |s: &str| ["x", "y", "z"].iter().position(|&a| a == s);
        if let Some(a) = name.strip_prefix("tool.t") {
            return Some(self.tool_t[axis(a)?] * 1e3);
        }
        if let Some(a) = name.strip_prefix("tool.r") {
            return Some(self.tool_r[axis(a)?] * 1e3);
        }
        None
    }
}

/// The instrument: σ of a point per axis \[m\] and of an orientation per
/// axis \[rad\].
#[derive(Debug, Clone, Copy)]
pub struct Instrument {
    /// A point's σ per axis \[m\].
    pub sigma_m: f64,
    /// An orientation's σ per axis \[rad\].
    pub sigma_rad: f64,
}

/// `n` poses of the true robot as a measurement CSV (units m and rad, the
/// robot's base frame): each the probe's point with `sx, sy, sz` and, with
/// `orientation`, the tip frame's orientation turned by the tool's with
/// `rx, ry, rz` and `srx, sry, srz`.
pub fn csv(
    arm: &Arm,
    truth: &Truth,
    instrument: Instrument,
    n: usize,
    orientation: bool,
    rng: &mut SplitMix64,
) -> String {
    let mut out = header(arm, orientation);
    for c in 0..n {
        let q: Vec<f64> = arm
            .ranges
            .iter()
            .map(|&(lo, hi)| rng.range(lo, hi))
            .collect();
        out += &line(arm, truth, instrument, c + 1, &q, orientation, rng);
    }
    out
}

/// [`csv`] at the joint values `poses` \[rad\], one configuration each.
pub fn csv_at(
    arm: &Arm,
    truth: &Truth,
    instrument: Instrument,
    poses: &[Vec<f64>],
    orientation: bool,
    rng: &mut SplitMix64,
) -> String {
    let mut out = header(arm, orientation);
    for (c, q) in poses.iter().enumerate() {
        out += &line(arm, truth, instrument, c + 1, q, orientation, rng);
    }
    out
}

/// [`csv`]'s header.
fn header(arm: &Arm, orientation: bool) -> String {
    let mut out = format!("config,{},x,y,z,sx,sy,sz", arm.joints.join(","));
    if orientation {
        out += ",rx,ry,rz,srx,sry,srz";
    }
    out.push('\n');
    out
}

/// [`csv`]'s line of configuration `config` at joint values `q`.
fn line(
    arm: &Arm,
    truth: &Truth,
    instrument: Instrument,
    config: usize,
    q: &[f64],
    orientation: bool,
    rng: &mut SplitMix64,
) -> String {
    let (sm, sr) = (instrument.sigma_m, instrument.sigma_rad);
    let tool = Rotation3::new(truth.tool_r);
    let theta: Vec<f64> = q.iter().zip(&truth.offsets).map(|(q, o)| q + o).collect();
    let pose = arm.fk.pose(&theta);
    let r_tip = Rotation3::from_matrix_unchecked(Matrix3::from(pose.tip.fixed_view::<3, 3>(0, 0)));
    let p_tip = pose.tip.fixed_view::<3, 1>(0, 3).into_owned();
    let p = p_tip + r_tip * (truth.tool_t + tool * arm.marker_m);
    let p = p + Vector3::from_fn(|_, _| rng.normal() * sm);
    let qs: Vec<String> = q.iter().map(|v| format!("{v:.9}")).collect();
    let mut out = format!(
        "{config},{},{:.9},{:.9},{:.9},{sm},{sm},{sm}",
        qs.join(","),
        p.x,
        p.y,
        p.z
    );
    if orientation {
        let noise = Rotation3::new(Vector3::from_fn(|_, _| rng.normal() * sr));
        let r = (noise * r_tip * tool).scaled_axis();
        out += &format!(",{:.12},{:.12},{:.12},{sr},{sr},{sr}", r.x, r.y, r.z);
    }
    out.push('\n');
    out
}
