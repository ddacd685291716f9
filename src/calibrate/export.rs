//! The calibrated robot as a URDF (data contract 7.4, `DIR/robot.urdf`).
//!
//! The input URDF with the calibrated geometry folded in, exactly:
//!
//! - each movable joint `j` of the chain: its `<origin>` `Oⱼ` becomes
//!   `Oⱼ · Dⱼ`, where `Dⱼ = Nⱼ⁻¹ Cⱼ` is the change of the chain's origin
//!   from nominal `Nⱼ` to calibrated `Cⱼ` (fixed joints before `j` are folded
//!   into both, so they cancel). A joint offset is `motionⱼ(δq)` on the
//!   right of the origin (a rotation about the joint axis for a revolute
//!   joint, exact); a frame error is `E(δt, δr)` on the right
//!   ([`super::geometry`]);
//! - a new root link `measurement_frame` and a fixed joint
//!   `measurement_frame_joint` to the URDF's root link, placed so that
//!   `base_link` sits where the calibration put it (the base pose in the
//!   measurement frame; the identity when the base frame is not declared);
//! - each marker as a fixed link `marker_<id>` on `tip_link`
//!   (joint `marker_<id>_joint`) at its calibrated position;
//!   `marker_<id>_calibrated` when the URDF already has a `marker_<id>`.
//!
//! Forward kinematics of this file alone, from `measurement_frame` to
//! `marker_<id>`, give the prediction of that marker by the geometric model
//! it is made from (joint compliances and other non-geometric effects are
//! in `model.json`). The last Gauss–Newton step, not yet applied to the
//! geometry when the fit stopped, is applied here.
//!
//! Which geometric model: the final model's, when all its parameters are
//! geometric; else its geometric parameters refitted as a rigid robot
//! (`rigid_urdf`, [`super::Report::urdf_model`]), since the parameters a
//! URDF cannot hold absorbed part of the geometry while fitted with it (on
//! TIAGo that geometry alone predicted its training points at 16.5 mm RMS,
//! the nominal robot at 4.1 mm, the refit at 2.2 mm).

use nalgebra::Isometry3;

use super::calibrated::CalibratedModel;
use super::engine::{Engine, Fitted};
use super::geometry::Geometry;
use super::linearisation::Linearisation;
use super::residuals::SquareSum;
use super::rows::RowKind;
use super::settings::CalibrationError;
use crate::io::Job;
use crate::model::Param;

/// Name of the new root link.
pub const MEASUREMENT_FRAME: &str = "measurement_frame";

fn pose(p: &urdf_rs::Pose) -> Isometry3<f64> {
    Isometry3::from_parts(
        nalgebra::Translation3::new(p.xyz[0], p.xyz[1], p.xyz[2]),
        nalgebra::UnitQuaternion::from_euler_angles(p.rpy[0], p.rpy[1], p.rpy[2]),
    )
}

fn to_pose(t: &Isometry3<f64>) -> urdf_rs::Pose {
    let (r, p, y) = t.rotation.euler_angles();
    let v = t.translation.vector;
    urdf_rs::Pose {
        xyz: urdf_rs::Vec3([v.x, v.y, v.z]),
        rpy: urdf_rs::Vec3([r, p, y]),
    }
}

/// The link name of marker `id`: `marker_<id>`, or `marker_<id>_calibrated`
/// when the URDF already has a link `marker_<id>` (a reflector modelled by
/// its maker, say).
pub fn marker_link(urdf: &urdf_rs::Robot, id: u32) -> String {
    let name = format!("marker_{id}");
    if urdf.links.iter().any(|l| l.name == name) {
        format!("{name}_calibrated")
    } else {
        name
    }
}

/// The geometry of `model` with its last, unapplied step applied.
pub fn final_geometry(model: &CalibratedModel) -> Geometry {
    let mut g = model.geometry.clone();
    g.apply(&model.params, &model.x);
    g
}

/// What `robot.urdf` holds for a model with parameters a URDF cannot hold
/// (compliances, backlash, gear cyclic errors, drift, …; `rigid_urdf`).
#[derive(Debug, Clone)]
pub struct RigidUrdf {
    /// The model's geometric parameters refitted as a rigid robot (none of
    /// the others), when that fit succeeded; else the URDF holds the
    /// model's own geometry.
    pub refit: Option<CalibratedModel>,
    /// RMS \[µm\] over the absolute rows of what the URDF holds.
    pub rms_um: f64,
    /// RMS \[µm\] over the absolute rows of the model's own geometry alone.
    pub own_rms_um: f64,
}

/// RMS \[µm\] of `residuals` over the absolute rows of `e`.
fn absolute_rms_um(e: &Engine<'_>, residuals: &[nalgebra::Vector3<f64>]) -> f64 {
    let mut sum = SquareSum::default();
    for (r, res) in e.rows.rows.iter().zip(residuals) {
        if r.kind == RowKind::Absolute {
            sum.extend(&[*res]);
        }
    }
    sum.rms_um()
}

/// `robot.urdf` of the final model `f` (`model` its calibrated model) when
/// it has parameters a URDF cannot hold: fitted with them, its geometry
/// alone may predict the points worse than the nominal robot (they absorb
/// part of it: TIAGo 16.5 mm against the nominal 4.1 mm), so the URDF gets
/// its geometric parameters refitted as a rigid robot, from its geometry,
/// by the same engine and method. `None` when every parameter is geometric
/// (the URDF then predicts what the model does), or without absolute rows
/// or when they cannot be evaluated at the model's geometry. Leaves `e` at
/// the rigid robot: for the engine's last use.
pub(super) fn rigid_urdf(
    e: &mut Engine<'_>,
    f: &Fitted,
    model: &CalibratedModel,
) -> Option<RigidUrdf> {
    if f.params.iter().all(Param::is_geometric) || !e.rows.kinds.absolute {
        return None;
    }
    e.geometry = final_geometry(model);
    e.lin = Linearisation::nominal(e.lin.model);
    e.relinearise().ok()?;
    let own: Vec<_> = e.rows.rows.iter().map(|r| r.y).collect();
    let own_rms_um = absolute_rms_um(e, &own);
    let geometric: Vec<Param> = f
        .params
        .iter()
        .copied()
        .filter(Param::is_geometric)
        .collect();
    let refit = (!geometric.is_empty())
        .then(|| e.fit(&geometric).ok())
        .flatten()
        .filter(|r| r.converged);
    Some(match refit {
        Some(r) => RigidUrdf {
            rms_um: absolute_rms_um(e, &r.residuals),
            refit: Some(e.calibrated(&r)),
            own_rms_um,
        },
        None => RigidUrdf {
            refit: None,
            rms_um: own_rms_um,
            own_rms_um,
        },
    })
}

/// The calibrated URDF of `model` for the robot of `job` (see the module
/// docs), as text.
///
/// # Errors
/// [`CalibrationError::Data`] when the URDF cannot be read again, already
/// has a link of a name this adds, or has a movable joint between its root
/// and `base_link` (the measurement frame could not be placed by a fixed
/// joint).
pub fn calibrated_urdf(model: &CalibratedModel, job: &Job) -> Result<String, CalibrationError> {
    let path = job.setup.robot_path(&job.setup_path);
    let data = |m: String| CalibrationError::Data(format!("{}: {m}", path.display()));
    let text = crate::io::input::read_text(&path, "the URDF", crate::io::input::MAX_URDF_BYTES)
        .map_err(|e| CalibrationError::Data(e.to_string()))?;
    let mut urdf = crate::io::urdf::read_urdf(&text).map_err(data)?;
    let g = final_geometry(model);
    let robot = &job.robot;
    let nominal = robot.chain.joints();
    let calibrated = g.chain.joints();
    for (j, name) in robot.joint_names.iter().enumerate() {
        let d = nominal[j].origin.inverse() * calibrated[j].origin;
        let joint = urdf
            .joints
            .iter_mut()
            .find(|u| &u.name == name)
            .ok_or_else(|| data(format!("joint '{name}' not found again")))?;
        joint.origin = to_pose(&(pose(&joint.origin) * d));
    }
    if urdf.links.iter().any(|l| l.name == MEASUREMENT_FRAME) {
        return Err(data(format!("already has a link '{MEASUREMENT_FRAME}'")));
    }
    let marker_links: Vec<String> = model
        .names
        .markers
        .iter()
        .map(|(id, _)| marker_link(&urdf, *id))
        .collect();
    // base_link in the URDF's root frame, through fixed joints only.
    let mut root_to_base = Isometry3::identity();
    let mut link = robot.base_link.clone();
    while let Some(j) = urdf.joints.iter().find(|j| j.child.link == link) {
        if j.joint_type != urdf_rs::JointType::Fixed {
            return Err(data(format!(
                "joint '{}' between the root and base_link '{}' is not fixed: the \
                 measurement frame cannot be placed",
                j.name, robot.base_link
            )));
        }
        root_to_base = pose(&j.origin) * root_to_base;
        link = j.parent.link.clone();
    }
    let root = link;
    let fixed = |name: String, parent: &str, child: &str, origin: urdf_rs::Pose| urdf_rs::Joint {
        name,
        joint_type: urdf_rs::JointType::Fixed,
        origin,
        parent: urdf_rs::LinkName {
            link: parent.into(),
        },
        child: urdf_rs::LinkName { link: child.into() },
        axis: urdf_rs::Axis::default(),
        limit: urdf_rs::JointLimit::default(),
        calibration: None,
        dynamics: None,
        mimic: None,
        safety_controller: None,
    };
    let link = |name: &str| urdf_rs::Link {
        name: name.into(),
        inertial: urdf_rs::Inertial::default(),
        visual: Vec::new(),
        collision: Vec::new(),
    };
    urdf.links.push(link(MEASUREMENT_FRAME));
    urdf.joints.push(fixed(
        format!("{MEASUREMENT_FRAME}_joint"),
        MEASUREMENT_FRAME,
        &root,
        to_pose(&(g.base * root_to_base.inverse())),
    ));
    for (m, name) in marker_links.iter().enumerate() {
        urdf.links.push(link(name));
        let p = g.markers[m];
        // The marker's own link (data contract 7.1), tip_link by default.
        let on = job
            .setup
            .markers
            .get(m)
            .and_then(|s| s.link.as_deref())
            .unwrap_or(&robot.tip_link);
        urdf.joints.push(fixed(
            format!("{name}_joint"),
            on,
            name,
            urdf_rs::Pose {
                xyz: urdf_rs::Vec3([p.x, p.y, p.z]),
                rpy: urdf_rs::Vec3([0.0; 3]),
            },
        ));
    }
    urdf_rs::write_to_string(&urdf).map_err(|e| data(format!("cannot write the URDF: {e}")))
}
