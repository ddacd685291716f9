//! The `predictor` section of `DIR/model.json` (data contract 7.4:
//! "everything needed to predict and to compensate"): the calibrated robot
//! as a [`Predictor`] holds it, in SI units, so that `robcal predict` and
//! `robcal compensate` (or a controller's build step) work from the file
//! alone, without the calibration's URDF, setup or measurements.
//!
//! ```json
//! "predictor": {
//!   "frame": "measurement_frame",
//!   "deflection_model": "exact",
//!   "gravity_mps2": [gx, gy, gz],                 // measurement frame
//!   "joints": [{"name": "a1", "type": "revolute",
//!               "origin_xyz_m": [..], "origin_quaternion_xyzw": [..],
//!               "axis": [..], "link_mass_kg": m, "link_com_m": [..]}, ..],
//!   "tip_xyz_m": [..], "tip_quaternion_xyzw": [..],
//!   "markers": [{"id": 1, "xyz_m": [..]}, ..],    // tip frame
//!   // a tree (data contract 7.1): each joint's "parent" (joint name, ""
//!   // for the measurement frame), "tip_joint", and a marker on another
//!   // link: "link": {"joint": .., "xyz_m": [..], "quaternion_xyzw": [..]}
//!   "load_com_shift_m": [..],                     // tip frame
//!   "joint_law": [{"joint": "a2", "units": {..}, "compliance": k,
//!                  "compliance_table": [{"angle_rad": a, "compliance": k}, ..],
//!                  "nonlinear_stiffness": c, "backlash": b,
//!                  "gear_cyclic_sin": s, "gear_cyclic_cos": c,
//!                  "gravity_compliance_a": x_a, "gravity_compliance_b": x_b}, ..],
//!   "link_compliance": [{"joint": "a3", "value": k, "unit": "rad/(N*m)"}],
//!   "link_compliance_own_weight": true,   // with link_compliance: the own weight bends them too
//!   "thermal_expansion": {"alpha_per_k": a, "reference_c": t}, // when identified
//!   "tool_quaternion_xyzw": [..]  // the tool frame's rotation, when identified
//! }
//! ```
//!
//! Each joint's origin is the calibrated one with the fixed joints before
//! it folded in, the first one placed in the measurement frame: forward
//! kinematics is `T = Π originⱼ · motionⱼ(qⱼ) · tip` (a revolute joint turns
//! about `axis`, a prismatic one slides along it). The joint law is
//! `δⱼ = kⱼ(qⱼ) τⱼ + cⱼ τⱼ|τⱼ| + bⱼ sign τⱼ + sⱼ sin qⱼ + c'ⱼ cos qⱼ +
//! x_a gₐ + x_b g_b`, with `kⱼ(qⱼ)` the constant compliance plus the
//! compensator table at `qⱼ` (linear between its angles, held at its ends)
//! and `(gₐ, g_b)` the components of the unit gravity direction
//! (`gravity_mps2` normalised) on the joint's basis in its frame at the
//! commanded pose ([`crate::model::gravity_components`]; the gravity
//! compliance, written only when not zero). With `thermal_expansion`,
//! the lengths are the robot's at `reference_c` \[°C\]; at `T` every
//! point `p` on it is at `o₁ + (1 + α (T − reference_c))(p − o₁)`, `o₁` the
//! first joint's origin ([`Predictor::at_temperature`]).

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Quaternion, Translation3, Unit, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::calibrate::outputs::predict::Predictor;
use crate::calibrate::params::geometry::J;
use crate::calibrate::params::linearisation::{DeflectionModel, Linearisation};
use crate::model::{angle_urad, Param};
use crate::robot::{Chain, End, Joint, JointKind, LinkInertia};

mod strict;
use strict::units;

/// One movable joint of the calibrated chain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointRecord {
    /// The URDF joint name.
    pub name: String,
    /// `"revolute"` or `"prismatic"`.
    #[serde(rename = "type")]
    pub kind: String,
    /// Origin translation \[m\] from the previous joint frame.
    pub origin_xyz_m: [f64; 3],
    /// Origin rotation, unit quaternion `[x, y, z, w]`.
    pub origin_quaternion_xyzw: [f64; 4],
    /// Unit axis in the joint frame.
    pub axis: [f64; 3],
    /// The child link's mass \[kg\] (its own weight), when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_mass_kg: Option<f64>,
    /// The child link's centre of mass \[m, joint frame\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_com_m: Option<[f64; 3]>,
    /// A tree's joint (data contract 7.1): the joint whose frame this one
    /// hangs from, `""` for the measurement frame. Absent: the joint before
    /// it (a serial chain's, written for none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parent: Option<String>,
}

/// A marker (tool point) on the tip link, or on another link of a tree.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MarkerRecord {
    /// Its id in the measurement CSV.
    pub id: u32,
    /// Calibrated position \[m, tip frame, or the frame of `link`\].
    pub xyz_m: [f64; 3],
    /// The marker's link when it is not the tip's (a tree, data contract
    /// 7.1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<LinkRecord>,
}

/// Where a marker's link is fixed: a joint's frame and the transform from
/// it, as the tip is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkRecord {
    /// The joint whose frame the link is fixed to, `""` for the measurement
    /// frame.
    pub joint: String,
    /// Translation \[m\] from that frame.
    pub xyz_m: [f64; 3],
    /// Rotation from that frame, unit quaternion `[x, y, z, w]`.
    pub quaternion_xyzw: [f64; 4],
}

/// One angle of a compensator table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableEntry {
    /// The calibrated joint angle \[rad\].
    pub angle_rad: f64,
    /// The compliance there, added to the constant one (unit of
    /// `units.compliance`).
    pub compliance: f64,
}

/// The joint law of one joint (SI units, named in `units`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LawRecord {
    /// The joint's name.
    pub joint: String,
    /// The unit of each term.
    pub units: BTreeMap<String, String>,
    /// Constant compliance `kⱼ`.
    #[serde(default)]
    pub compliance: f64,
    /// The compensator table (empty: none).
    #[serde(default)]
    pub compliance_table: Vec<TableEntry>,
    /// `cⱼ` of `cⱼ τⱼ|τⱼ|`.
    #[serde(default)]
    pub nonlinear_stiffness: f64,
    /// Backlash `bⱼ`, in the direction of the torque.
    #[serde(default)]
    pub backlash: f64,
    /// Gear cyclic error: the sine's amplitude.
    #[serde(default)]
    pub gear_cyclic_sin: f64,
    /// Gear cyclic error: the cosine's amplitude.
    #[serde(default)]
    pub gear_cyclic_cos: f64,
    /// Gravity compliance: the deflection with gravity along the joint
    /// frame's `a` axis ([`crate::model::gravity_basis`]).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub gravity_compliance_a: f64,
    /// Gravity compliance: the deflection with gravity along `b`.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub gravity_compliance_b: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// A link's bending under the payload (first order).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BendingRecord {
    /// The joint whose link bends.
    pub joint: String,
    /// The compliance.
    pub value: f64,
    /// Its unit.
    pub unit: String,
}

/// The links' thermal expansion ([`Param::ThermalExpansion`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThermalRecord {
    /// The coefficient `α` \[1/K\].
    pub alpha_per_k: f64,
    /// The temperature \[°C\] the file's lengths hold at (the calibration
    /// data's mean).
    pub reference_c: f64,
}

/// The `predictor` section of `model.json` (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelFile {
    /// The frame positions are given in: `"measurement_frame"`.
    pub frame: String,
    /// `"exact"` or `"linear"`: the deflection model of the fit (a
    /// prediction always solves the exact equilibrium).
    pub deflection_model: String,
    /// Gravity \[m/s², measurement frame\].
    pub gravity_mps2: [f64; 3],
    /// The movable joints, base to tip.
    pub joints: Vec<JointRecord>,
    /// The tip frame from the last joint frame: translation \[m\].
    pub tip_xyz_m: [f64; 3],
    /// The tip frame's rotation, `[x, y, z, w]`.
    pub tip_quaternion_xyzw: [f64; 4],
    /// The joint the tip frame is fixed to when it is not the last one (a
    /// tree, data contract 7.1; `""`: the measurement frame).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tip_joint: Option<String>,
    /// The markers.
    pub markers: Vec<MarkerRecord>,
    /// The fitted shift of the calibration load's centre of mass \[m, tip
    /// frame\] (zero without `load_com`).
    pub load_com_shift_m: [f64; 3],
    /// The joint law, one record per joint with any term.
    pub joint_law: Vec<LawRecord>,
    /// The links' bending.
    #[serde(default)]
    pub link_compliance: Vec<BendingRecord>,
    /// Whether the links bend under the robot's own weight too (written
    /// with `link_compliance`; absent in a file written before: under the
    /// payload alone, as that calibration fitted them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_compliance_own_weight: Option<bool>,
    /// The heaviest payload of the calibration \[kg\] (0: none; absent in a
    /// file written before it was recorded; [`crate::calibrate::outputs::predict::payload`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heaviest_payload_kg: Option<f64>,
    /// The links' thermal expansion (absent without one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thermal_expansion: Option<ThermalRecord>,
    /// The identified tool frame's rotation, `[x, y, z, w]`: a 6-D
    /// instrument's measured frame is the marker's link frame turned by it
    /// (absent when none was identified: the identity).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tool_quaternion_xyzw: Option<[f64; 4]>,
}

fn quat(q: &UnitQuaternion<f64>) -> [f64; 4] {
    let c = q.coords;
    [c.x, c.y, c.z, c.w]
}

impl ModelFile {
    /// The file of a predictor.
    pub fn of(p: &Predictor) -> Self {
        let chain = p.chain();
        let names = p.joint_names();
        let serial = chain.is_serial();
        let name_of = |j: Option<usize>| j.and_then(|j| names.get(j)).cloned().unwrap_or_default();
        let joints = chain
            .joints()
            .iter()
            .zip(names)
            .enumerate()
            .map(|(index, (j, name))| JointRecord {
                parent: (!serial).then(|| name_of(chain.parent(index))),
                name: name.clone(),
                kind: match j.kind {
                    JointKind::Revolute => "revolute",
                    JointKind::Prismatic => "prismatic",
                }
                .into(),
                origin_xyz_m: j.origin.translation.vector.into(),
                origin_quaternion_xyzw: quat(&j.origin.rotation),
                axis: j.axis.into_inner().into(),
                link_mass_kg: j.link.map(|l| l.mass_kg),
                link_com_m: j.link.map(|l| l.com_m.into()),
            })
            .collect();
        let mut law: BTreeMap<usize, LawRecord> = BTreeMap::new();
        for (param, &v) in p.joint_law().values() {
            let Some(j) = param.joint().map(usize::from) else {
                continue;
            };
            let kind = chain
                .joints()
                .get(j)
                .map_or(JointKind::Revolute, |x| x.kind);
            let r = law.entry(j).or_insert_with(|| LawRecord {
                joint: names.get(j).cloned().unwrap_or_default(),
                units: units(kind),
                compliance: 0.0,
                compliance_table: Vec::new(),
                nonlinear_stiffness: 0.0,
                backlash: 0.0,
                gear_cyclic_sin: 0.0,
                gear_cyclic_cos: 0.0,
                gravity_compliance_a: 0.0,
                gravity_compliance_b: 0.0,
            });
            match *param {
                Param::Compliance { .. } => r.compliance += v,
                Param::ComplianceAt { angle_urad, .. } => r.compliance_table.push(TableEntry {
                    angle_rad: f64::from(angle_urad) * 1e-6,
                    compliance: v,
                }),
                Param::NonlinearStiffness { .. } => r.nonlinear_stiffness += v,
                Param::Backlash { .. } => r.backlash += v,
                Param::GearCyclic { cos: false, .. } => r.gear_cyclic_sin += v,
                Param::GearCyclic { cos: true, .. } => r.gear_cyclic_cos += v,
                Param::GravityCompliance { b, .. } => {
                    let unit = r.units["gear_cyclic"].clone();
                    r.units.insert("gravity_compliance".into(), unit);
                    *if b {
                        &mut r.gravity_compliance_b
                    } else {
                        &mut r.gravity_compliance_a
                    } += v;
                }
                _ => {}
            }
        }
        Self {
            frame: "measurement_frame".into(),
            deflection_model: p.joint_law().model.name().into(),
            gravity_mps2: p.gravity_mps2().into(),
            joints,
            tip_xyz_m: chain.tip().translation.vector.into(),
            tip_quaternion_xyzw: quat(&chain.tip().rotation),
            tip_joint: (chain.tip_joint().is_none_or(|t| t + 1 != chain.dof()))
                .then(|| name_of(chain.tip_joint())),
            markers: {
                let (ends, marker_ends) = p.ends();
                p.markers()
                    .enumerate()
                    .map(|(i, (id, m))| MarkerRecord {
                        id,
                        xyz_m: m.into(),
                        link: marker_ends
                            .get(i)
                            .and_then(|&k| k.checked_sub(1))
                            .and_then(|k| ends.get(k))
                            .map(|e| LinkRecord {
                                joint: name_of(e.joint),
                                xyz_m: e.origin.translation.vector.into(),
                                quaternion_xyzw: quat(&e.origin.rotation),
                            }),
                    })
                    .collect()
            },
            load_com_shift_m: p.load_com_shift_m().into(),
            joint_law: law.into_values().collect(),
            link_compliance: p
                .bending()
                .iter()
                .filter_map(|(param, v)| {
                    let j = usize::from(param.joint()?);
                    Some(BendingRecord {
                        joint: names.get(j).cloned().unwrap_or_default(),
                        value: v * 1e-6,
                        unit: "rad/(N*m)".into(),
                    })
                })
                .collect(),
            link_compliance_own_weight: (!p.bending().is_empty()).then(|| p.bending_own_weight()),
            heaviest_payload_kg: p.heaviest_payload_kg(),
            thermal_expansion: p.thermal_expansion().map(|(alpha_per_k, reference_c)| {
                ThermalRecord {
                    alpha_per_k,
                    reference_c,
                }
            }),
            tool_quaternion_xyzw: (*p.tool_rotation() != nalgebra::Rotation3::identity())
                .then(|| quat(&UnitQuaternion::from_rotation_matrix(p.tool_rotation()))),
        }
    }

    /// The predictor of this file.
    ///
    /// # Errors
    /// One line saying what is wrong: a non-finite number, an unknown
    /// joint type or joint name, a rotation that is not a unit quaternion,
    /// a zero axis, a negative mass, a repeated marker id, more than
    /// [`crate::io::urdf::MAX_JOINTS`] joints, a unit other than the one written
    /// or a joint's law or bending listed twice (`model_file/strict.rs`). (An unknown
    /// key is the reader's error: serde's `deny_unknown_fields`.)
    pub fn predictor(&self) -> Result<Predictor, String> {
        strict::check(self)?;
        let finite = |what: &str, v: &[f64]| {
            if v.iter().all(|x| x.is_finite()) {
                Ok(())
            } else {
                Err(format!("{what}: non-finite value"))
            }
        };
        let rotation = |what: &str, q: &[f64; 4]| {
            finite(what, q)?;
            let q = Quaternion::new(q[3], q[0], q[1], q[2]);
            if (q.norm() - 1.0).abs() > 1e-6 {
                return Err(format!(
                    "{what}: not a unit quaternion (norm {:.6})",
                    q.norm()
                ));
            }
            Ok(UnitQuaternion::from_quaternion(q))
        };
        let model = match self.deflection_model.as_str() {
            "exact" => DeflectionModel::Exact,
            "linear" => DeflectionModel::Linear,
            m => {
                return Err(format!(
                    "deflection_model: '{m}' is not 'exact' or 'linear'"
                ))
            }
        };
        if self.frame != "measurement_frame" {
            return Err(format!(
                "frame: '{}' is not 'measurement_frame'",
                self.frame
            ));
        }
        finite("gravity_mps2", &self.gravity_mps2)?;
        if self.joints.len() > J {
            return Err(format!(
                "joints: {} joints, at most {J} are supported",
                self.joints.len()
            ));
        }
        let mut chain = Chain::<f64, J>::new();
        let mut names = Vec::new();
        for r in &self.joints {
            let what = format!("joint '{}'", r.name);
            let kind = match r.kind.as_str() {
                "revolute" => JointKind::Revolute,
                "prismatic" => JointKind::Prismatic,
                k => return Err(format!("{what}: type '{k}' is not revolute or prismatic")),
            };
            finite(&what, &r.origin_xyz_m)?;
            finite(&what, &r.axis)?;
            let axis = Unit::try_new(Vector3::from(r.axis), 1e-12)
                .ok_or_else(|| format!("{what}: zero axis"))?;
            let link = match (r.link_mass_kg, r.link_com_m) {
                (Some(m), com) => {
                    finite(&what, &[m])?;
                    if m < 0.0 {
                        return Err(format!("{what}: negative link mass {m} kg"));
                    }
                    let com = com.unwrap_or_default();
                    finite(&what, &com)?;
                    Some(LinkInertia {
                        mass_kg: m,
                        com_m: Vector3::from(com),
                    })
                }
                (None, _) => None,
            };
            let parent = match r.parent.as_deref() {
                None => chain.dof().checked_sub(1),
                Some("") => None,
                Some(p) => Some(names.iter().position(|n| n == p).ok_or_else(|| {
                    format!("{what}: parent '{p}' is not a joint listed before it")
                })?),
            };
            chain
                .push_child(
                    Joint {
                        origin: Isometry3::from_parts(
                            Translation3::from(Vector3::from(r.origin_xyz_m)),
                            rotation(&what, &r.origin_quaternion_xyzw)?,
                        ),
                        axis,
                        kind,
                        link,
                    },
                    parent,
                )
                .map_err(|e| format!("{what}: {e}"))?;
            if names.contains(&r.name) {
                return Err(format!("{what}: named twice"));
            }
            names.push(r.name.clone());
        }
        finite("tip_xyz_m", &self.tip_xyz_m)?;
        // The tip hangs from the last joint unless `tip_joint` names one.
        let tip_joint = match self.tip_joint.as_deref() {
            None => chain.dof().checked_sub(1),
            Some("") => None,
            Some(t) => Some(
                names
                    .iter()
                    .position(|n| n == t)
                    .ok_or_else(|| format!("tip_joint: '{t}' is not a joint"))?,
            ),
        };
        let chain = chain
            .with_tip(&End {
                joint: tip_joint,
                origin: Isometry3::from_parts(
                    Translation3::from(Vector3::from(self.tip_xyz_m)),
                    rotation("tip_quaternion_xyzw", &self.tip_quaternion_xyzw)?,
                ),
            })
            .map_err(|e| format!("tip: {e}"))?;
        let mut markers = Vec::new();
        let mut ends = Vec::new();
        let mut marker_ends = Vec::new();
        for m in &self.markers {
            finite(&format!("marker {}", m.id), &m.xyz_m)?;
            if markers.iter().any(|(id, _)| *id == m.id) {
                return Err(format!("marker {}: listed twice", m.id));
            }
            markers.push((m.id, Vector3::from(m.xyz_m)));
            marker_ends.push(match &m.link {
                None => 0,
                Some(l) => {
                    let what = format!("marker {} link", m.id);
                    finite(&what, &l.xyz_m)?;
                    let joint = match l.joint.as_str() {
                        "" => None,
                        j => Some(
                            names
                                .iter()
                                .position(|n| n == j)
                                .ok_or_else(|| format!("{what}: '{j}' is not a joint"))?,
                        ),
                    };
                    let end = End {
                        joint,
                        origin: Isometry3::from_parts(
                            Translation3::from(Vector3::from(l.xyz_m)),
                            rotation(&what, &l.quaternion_xyzw)?,
                        ),
                    };
                    match ends.iter().position(|e| *e == end) {
                        Some(k) => k + 1,
                        None => {
                            ends.push(end);
                            ends.len()
                        }
                    }
                }
            });
        }
        finite("load_com_shift_m", &self.load_com_shift_m)?;
        let tool_rotation = match &self.tool_quaternion_xyzw {
            Some(q) => Some(rotation("tool_quaternion_xyzw", q)?.to_rotation_matrix()),
            None => None,
        };
        let joint = |name: &str| {
            names
                .iter()
                .position(|n| n == name)
                .and_then(|j| u8::try_from(j).ok())
                .ok_or_else(|| format!("joint_law: no joint '{name}' in joints"))
        };
        let mut values = BTreeMap::new();
        for r in &self.joint_law {
            let j = joint(&r.joint)?;
            let what = format!("joint_law of '{}'", r.joint);
            finite(
                &what,
                &[
                    r.compliance,
                    r.nonlinear_stiffness,
                    r.backlash,
                    r.gear_cyclic_sin,
                    r.gear_cyclic_cos,
                    r.gravity_compliance_a,
                    r.gravity_compliance_b,
                ],
            )?;
            if (r.gravity_compliance_a, r.gravity_compliance_b) != (0.0, 0.0)
                && self.gravity_mps2 == [0.0; 3]
            {
                return Err(format!(
                    "{what}: a gravity compliance with zero gravity_mps2"
                ));
            }
            let mut put = |p: Param, v: f64| {
                if v != 0.0 {
                    *values.entry(p).or_insert(0.0) += v;
                }
            };
            put(Param::Compliance { joint: j }, r.compliance);
            put(
                Param::NonlinearStiffness { joint: j },
                r.nonlinear_stiffness,
            );
            put(Param::Backlash { joint: j }, r.backlash);
            put(
                Param::GearCyclic {
                    joint: j,
                    cos: false,
                },
                r.gear_cyclic_sin,
            );
            put(
                Param::GearCyclic {
                    joint: j,
                    cos: true,
                },
                r.gear_cyclic_cos,
            );
            for (b, v) in [
                (false, r.gravity_compliance_a),
                (true, r.gravity_compliance_b),
            ] {
                put(Param::GravityCompliance { joint: j, b }, v);
            }
            for e in &r.compliance_table {
                finite(&what, &[e.angle_rad, e.compliance])?;
                if e.angle_rad.abs() > 1e3 {
                    return Err(format!("{what}: table angle {} rad", e.angle_rad));
                }
                values.insert(
                    Param::ComplianceAt {
                        joint: j,
                        angle_urad: angle_urad(e.angle_rad),
                    },
                    e.compliance,
                );
            }
        }
        let mut bending = Vec::new();
        for b in &self.link_compliance {
            finite(&format!("link_compliance of '{}'", b.joint), &[b.value])?;
            bending.push((
                Param::LinkCompliance {
                    joint: joint(&b.joint)?,
                },
                b.value * 1e6,
            ));
        }
        if let Some(t) = &self.thermal_expansion {
            finite("thermal_expansion", &[t.alpha_per_k, t.reference_c])?;
            let range = crate::io::units::MIN_TEMPERATURE_C..=crate::io::units::MAX_TEMPERATURE_C;
            // (50e-6 is the loop's bound; a file may hold what a calibration
            // with another policy admitted, not a length that turns inside out.)
            if t.alpha_per_k.abs() > 1e-3 {
                return Err(format!(
                    "thermal_expansion: alpha_per_k {:e} 1/K is not a thermal expansion",
                    t.alpha_per_k
                ));
            }
            if !range.contains(&t.reference_c) {
                return Err(format!(
                    "thermal_expansion: reference_c {} degC is outside [{}, {}] degC",
                    t.reference_c,
                    range.start(),
                    range.end()
                ));
            }
        }
        Predictor::from_parts(
            chain,
            markers,
            Vector3::from(self.gravity_mps2),
            Linearisation::from_values(model, values),
            bending,
            Vector3::from(self.load_com_shift_m),
            names,
        )
        .with_ends(&ends, marker_ends)
        .map(|p| p.with_heaviest_payload_kg(self.heaviest_payload_kg))
        .map(|p| p.with_bending_own_weight(self.link_compliance_own_weight.unwrap_or(false)))
        .map(|p| match &self.thermal_expansion {
            Some(t) => p.with_thermal_expansion(t.alpha_per_k, t.reference_c),
            None => p,
        })
        .map(|p| match tool_rotation {
            Some(r) => p.with_tool_rotation(r),
            None => p,
        })
        .map_err(|e| format!("markers: {e}"))
    }
}
