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
//!   ([`crate::calibrate::params::geometry`]);
//! - a new root link `measurement_frame` and a fixed joint
//!   `measurement_frame_joint` to the URDF's root link, placed so that
//!   `base_link` sits where the calibration put it (the base pose in the
//!   measurement frame; the identity when the base frame is not declared).
//!   A URDF robcal wrote (a recalibration from its own output) already has
//!   that root above `base_link`: its joint is placed again instead;
//! - each marker as a fixed link `marker_<id>` on its link (`tip_link`
//!   by default; joint `marker_<id>_joint`) at its calibrated position.
//!   When the URDF already has `marker_<id>` as a leaf on a fixed joint
//!   from that link or one fixed to it (a maker's reflector, or the marker
//!   an earlier `--output` wrote), that joint's origin takes the calibrated
//!   position (its rotation kept) and nothing is added; when it has a
//!   `marker_<id>` elsewhere (on another body, or with links below it),
//!   the new link is `marker_<id>_calibrated` ([`marker_link`]). The
//!   nominal marker is gone unless asked for
//!   ([`UrdfOptions::keep_nominal_markers`]: `marker_<id>_nominal`, where
//!   it was).
//!
//! Forward kinematics of this file alone, from `measurement_frame` to
//! `marker_<id>`, give the prediction of that marker by the geometric model
//! it is made from (joint compliances and other non-geometric effects are
//! in `model.json`). The last Gauss–Newton step, not yet applied to the
//! geometry when the fit stopped, is applied here.
//!
//! Which geometric model: the final model's, when all its parameters are
//! geometric; else its geometric parameters refitted as a rigid robot
//! (`rigid_urdf`, [`crate::calibrate::report::Report::urdf_model`]), since the parameters a
//! URDF cannot hold absorbed part of the geometry while fitted with it (on
//! TIAGo that geometry alone predicted its training points at 16.5 mm RMS,
//! the nominal robot at 4.1 mm, the refit at 2.2 mm).

use nalgebra::Isometry3;

use crate::calibrate::engine::{Engine, Fitted};
use crate::calibrate::fit::residuals::SquareSum;
use crate::calibrate::params::geometry::Geometry;
use crate::calibrate::params::linearisation::Linearisation;
use crate::calibrate::report::calibrated::CalibratedModel;
pub use crate::calibrate::report::RigidUrdf;
use crate::calibrate::rows::RowKind;
use crate::calibrate::settings::CalibrationError;
use crate::io::job::Job;
use crate::model::Param;

/// Name of the new root link.
pub use crate::io::urdf::MEASUREMENT_FRAME;

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

/// Where marker `id`, fixed to link `on`, goes in the calibrated URDF.
#[derive(Debug, Clone, PartialEq)]
pub enum MarkerLink {
    /// A new fixed link of this name (`marker_<id>`, or
    /// `marker_<id>_calibrated` when the URDF has a link `marker_<id>`
    /// that is not a leaf on a fixed joint from `on`'s rigid body).
    New(String),
    /// The URDF's own `marker_<id>`, a leaf on this fixed joint from a link
    /// rigidly fixed to `on` (`on` itself, or one joined to it by fixed
    /// joints only: a reflector modelled by its maker, as in the data sets
    /// of `../shared`, or the marker robcal wrote): the joint's origin takes
    /// the calibrated position, its rotation kept, and the link keeps its
    /// name.
    Existing {
        /// The fixed joint that holds the marker.
        joint: String,
        /// The pose of that joint's parent link in `on`'s frame.
        parent_in_on: Isometry3<f64>,
    },
}

/// The top of `link`'s rigid body, up through fixed joints: the pose of
/// `link` in the top link's frame, the top link, and the fixed joint that
/// hangs from it on the way (`None` when `link` is the top).
fn rigid_top<'a>(
    urdf: &'a urdf_rs::Robot,
    link: &'a str,
) -> (Isometry3<f64>, &'a str, Option<&'a urdf_rs::Joint>) {
    let mut at = Isometry3::identity();
    let (mut top, mut below) = (link, None);
    // At most one parent joint per link; a loop cannot outlast the joints.
    for _ in 0..=urdf.joints.len() {
        match urdf.joints.iter().find(|j| j.child.link == top) {
            Some(j) if j.joint_type == urdf_rs::JointType::Fixed => {
                at = pose(&j.origin) * at;
                top = &j.parent.link;
                below = Some(j);
            }
            _ => break,
        }
    }
    (at, top, below)
}

/// Where marker `id` on link `on` goes (see [`MarkerLink`]).
pub fn marker_link(urdf: &urdf_rs::Robot, id: u32, on: &str) -> MarkerLink {
    leaf_link(urdf, &format!("marker_{id}"), on)
}

/// Where a point named `name` fixed to link `on` goes: [`marker_link`]'s
/// rule for any leaf (the marker's nominal copy,
/// [`UrdfOptions::keep_nominal_markers`], too).
fn leaf_link(urdf: &urdf_rs::Robot, name: &str, on: &str) -> MarkerLink {
    let name = name.to_string();
    // A leaf: moving its joint moves nothing else.
    let leaf = !urdf.joints.iter().any(|j| j.parent.link == name);
    if let Some(j) = urdf.joints.iter().find(|j| j.child.link == name) {
        if leaf && j.joint_type == urdf_rs::JointType::Fixed {
            let (parent_at, parent_top, _) = rigid_top(urdf, &j.parent.link);
            let (on_at, on_top, _) = rigid_top(urdf, on);
            if parent_top == on_top {
                return MarkerLink::Existing {
                    joint: j.name.clone(),
                    parent_in_on: on_at.inverse() * parent_at,
                };
            }
        }
    }
    if urdf.links.iter().any(|l| l.name == name) {
        MarkerLink::New(format!("{name}_calibrated"))
    } else {
        MarkerLink::New(name)
    }
}

/// The geometry of `model` with its last, unapplied step applied.
pub fn final_geometry(model: &CalibratedModel) -> Geometry {
    let mut g = model.geometry.clone();
    g.apply(&model.params, &model.x);
    g
}

/// RMS \[µm\] of `residuals` over the absolute rows of `e` whose errors
/// are reported ([`crate::calibrate::rows::Rows::error_rows`]).
fn absolute_rms_um(e: &Engine<'_>, residuals: &[nalgebra::Vector3<f64>]) -> f64 {
    let mut sum = SquareSum::default();
    let rows = &e.rows.rows[..e.rows.error_rows()];
    for (r, res) in rows.iter().zip(residuals) {
        if r.kind == RowKind::Absolute && !r.orientation {
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
pub(in crate::calibrate) fn rigid_urdf(
    e: &mut Engine<'_>,
    f: &Fitted,
    model: &CalibratedModel,
) -> Option<RigidUrdf> {
    // A thermal expansion is zero at the data's mean temperature, where
    // the model's geometry holds: a URDF of that geometry is the robot
    // there, with nothing to refit.
    let held = |p: &Param| p.is_geometric() || matches!(p, Param::ThermalExpansion);
    if f.params.iter().all(held) || !e.rows.kinds.absolute {
        return None;
    }
    e.geometry = final_geometry(model);
    e.lin = Linearisation::nominal(e.lin.model);
    e.relinearise().ok()?;
    let own = e.rows.lhs().ok()?;
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

/// What [`calibrated_urdf_with`] writes besides the calibrated robot.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct UrdfOptions {
    /// Keep each marker's nominal position too, as a fixed leaf
    /// `marker_<id>_nominal` (joint `marker_<id>_nominal_joint`) on the
    /// same link: where the input URDF's `marker_<id>` was, or the setup's
    /// `xyz` when it had none. (A `marker_<id>_nominal` the input already
    /// has, a leaf on a fixed joint from the marker's rigid body, is moved
    /// there.) Off: `marker_<id>` is the calibrated marker, and the nominal
    /// one is gone (`robcal calibrate --keep-nominal-markers`).
    pub keep_nominal_markers: bool,
}

/// The calibrated URDF of `model` for the robot of `job` (see the module
/// docs), as text: [`calibrated_urdf_with`] and the default options.
///
/// # Errors
/// As [`calibrated_urdf_with`].
pub fn calibrated_urdf(model: &CalibratedModel, job: &Job) -> Result<String, CalibrationError> {
    calibrated_urdf_with(model, job, UrdfOptions::default())
}

/// The calibrated URDF of `model` for the robot of `job` (see the module
/// docs), as text, with `options`.
///
/// # Errors
/// [`CalibrationError::Data`] when the URDF cannot be read again, already
/// has a link of a name this adds, or has a movable joint between its root
/// and `base_link` (the measurement frame could not be placed by a fixed
/// joint).
pub fn calibrated_urdf_with(
    model: &CalibratedModel,
    job: &Job,
    options: UrdfOptions,
) -> Result<String, CalibrationError> {
    let path = job.setup.robot_path(&job.setup_path);
    let data = |m: String| CalibrationError::Data(format!("{}: {m}", path.display()));
    let text = match &job.urdf_text {
        Some(text) => text.clone(),
        None => crate::io::input::read_text(&path, "the URDF", crate::io::input::MAX_URDF_BYTES)
            .map_err(|e| CalibrationError::Data(e.to_string()))?,
    };
    let urdf = crate::io::urdf::read_urdf(&text).map_err(data)?;
    let g = final_geometry(model);
    let robot = &job.robot;
    let nominal = robot.chain.joints();
    let calibrated = g.chain.joints();
    let mut origins = Vec::new();
    for (j, name) in robot.joint_names.iter().enumerate() {
        let d = nominal[j].origin.inverse() * calibrated[j].origin;
        let joint = urdf
            .joints
            .iter()
            .find(|u| &u.name == name)
            .ok_or_else(|| data(format!("joint '{name}' not found again")))?;
        origins.push((name.clone(), pose(&joint.origin) * d));
    }
    // base_link in the URDF's root frame, through fixed joints only; the
    // joint that hangs from the root on the way.
    let (root_to_base, root, from_root) = rigid_top(&urdf, &robot.base_link);
    if let Some(j) = urdf.joints.iter().find(|j| j.child.link == root) {
        return Err(data(format!(
            "joint '{}' between the root and base_link '{}' is not fixed: the \
             measurement frame cannot be placed",
            j.name, robot.base_link
        )));
    }
    // robcal's own output as the nominal robot (a recalibration): its
    // measurement frame is the root above base_link, and this calibration
    // places it again (the joint below it moved) instead of adding one.
    let own_frame = match from_root {
        Some(j) if root == MEASUREMENT_FRAME => Some(j),
        _ => None,
    };
    if own_frame.is_none() && urdf.links.iter().any(|l| l.name == MEASUREMENT_FRAME) {
        return Err(data(format!(
            "already has a link '{MEASUREMENT_FRAME}' that is not the root above base_link '{}'",
            robot.base_link
        )));
    }
    // A new link and the fixed joint that places it or hangs from it.
    let fixed = |link: &str, name: &str, parent: &str, child: &str, origin: &Isometry3<f64>| {
        format!(
            "  <link name=\"{l}\"/>\n  <joint name=\"{n}\" type=\"fixed\">\n    \
             <parent link=\"{p}\"/>\n    <child link=\"{c}\"/>\n    {o}\n  </joint>\n",
            l = escape(link),
            n = escape(name),
            p = escape(parent),
            c = escape(child),
            o = origin_element(origin)
        )
    };
    let mut added = String::new();
    match own_frame {
        // measurement_frame → base_link is `O · rest`, `O` the joint's own
        // origin: `O' · rest` = the calibrated base.
        Some(j) => origins.push((
            j.name.clone(),
            g.base * root_to_base.inverse() * pose(&j.origin),
        )),
        None => added.push_str(&fixed(
            MEASUREMENT_FRAME,
            &format!("{MEASUREMENT_FRAME}_joint"),
            MEASUREMENT_FRAME,
            root,
            &(g.base * root_to_base.inverse()),
        )),
    }
    for (m, (id, _)) in model.names.markers.iter().enumerate() {
        let p = g.markers[m];
        // The marker's own link (data contract 7.1), tip_link by default.
        let on = job
            .setup
            .markers
            .get(m)
            .and_then(|s| s.link.as_deref())
            .unwrap_or(&robot.tip_link);
        // The point `p` (in `on`'s frame) at `link`: its joint's origin
        // moved there, or a new leaf; where the link was before, in `on`'s
        // frame (`None` when it is new).
        let mut place = |link: MarkerLink, p: nalgebra::Vector3<f64>| match link {
            MarkerLink::Existing {
                joint,
                parent_in_on,
            } => {
                let origin = urdf
                    .joints
                    .iter()
                    .find(|j| j.name == joint)
                    .map_or_else(Isometry3::identity, |j| pose(&j.origin));
                // The point in the parent link's frame.
                let q = parent_in_on.inverse_transform_point(&nalgebra::Point3::from(p));
                let at = Isometry3::from_parts(
                    nalgebra::Translation3::new(q.x, q.y, q.z),
                    origin.rotation,
                );
                origins.push((joint, at));
                Some((parent_in_on * origin).translation.vector)
            }
            MarkerLink::New(name) => {
                let at = Isometry3::translation(p.x, p.y, p.z);
                added.push_str(&fixed(&name, &format!("{name}_joint"), on, &name, &at));
                None
            }
        };
        let before = place(marker_link(&urdf, *id, on), p);
        if options.keep_nominal_markers {
            let nominal = before.unwrap_or_else(|| {
                job.setup
                    .markers
                    .get(m)
                    .map_or(nalgebra::Vector3::zeros(), |s| {
                        nalgebra::Vector3::from(s.xyz)
                    })
            });
            place(
                leaf_link(&urdf, &format!("marker_{id}_nominal"), on),
                nominal,
            );
        }
    }
    splice(&text, &origins, &added).map_err(data)
}

/// `name` escaped for an XML attribute.
fn escape(name: &str) -> String {
    quick_xml::escape::escape(name).into_owned()
}

/// `<origin xyz=".." rpy=".."/>` of `t` (each number the shortest text
/// that reads back to the same `f64`).
fn origin_element(t: &Isometry3<f64>) -> String {
    let p = to_pose(t);
    // (`+ 0.0`: no "-0".)
    let [x, y, z] = p.xyz.0.map(|v| v + 0.0);
    let [r, q, w] = p.rpy.0.map(|v| v + 0.0);
    format!("<origin xyz=\"{x} {y} {z}\" rpy=\"{r} {q} {w}\"/>")
}

/// `text` (a URDF) with the `<origin>` of each joint of `origins` replaced
/// (or added, for a joint without one) and `added` put before `</robot>`;
/// every other byte of `text` kept (comments, `<gazebo>`, `<transmission>`,
/// formatting), and no element added that the input did not have.
///
/// # Errors
/// The XML reader's error, or a joint of `origins` not in `text`.
fn splice(text: &str, origins: &[(String, Isometry3<f64>)], added: &str) -> Result<String, String> {
    use quick_xml::events::Event;
    // A byte-order mark is kept, and not counted in the reader's positions.
    let (bom, text) = match text.strip_prefix('\u{feff}') {
        Some(rest) => ("\u{feff}", rest),
        None => ("", text),
    };
    // The file's own line ends in what is added.
    let nl = if text.contains("\r\n") { "\r\n" } else { "\n" };
    let added = added.replace('\n', nl);
    let mut reader = quick_xml::Reader::from_str(text);
    // (start, end, replacement) byte ranges of `text`, in order.
    let mut edits: Vec<(usize, usize, String)> = Vec::new();
    let mut done = vec![false; origins.len()];
    // The joint being read: its index in `origins`, the end of its start
    // tag, its depth; and where an `<origin>` with children started.
    let mut joint: Option<(usize, usize, usize)> = None;
    let mut open_origin: Option<usize> = None;
    let (mut depth, mut robot_end) = (0_usize, None);
    let name_of = |e: &quick_xml::events::BytesStart<'_>| -> Option<String> {
        let a = e.try_get_attribute("name").ok()??;
        a.unescape_value().ok().map(|v| v.into_owned())
    };
    loop {
        let before = usize::try_from(reader.buffer_position()).map_err(|e| e.to_string())?;
        let event = reader
            .read_event()
            .map_err(|e| format!("cannot read the URDF again: {e}"))?;
        let after = usize::try_from(reader.buffer_position()).map_err(|e| e.to_string())?;
        match event {
            Event::Start(e) => {
                depth += 1;
                // Local names, as urdf-rs reads them (`<u:origin>` is an
                // origin).
                let tag = e.local_name();
                if tag.as_ref() == b"joint" && depth == 2 {
                    let k = name_of(&e).and_then(|n| origins.iter().position(|o| o.0 == n));
                    joint = k.map(|k| (k, after, depth));
                } else if tag.as_ref() == b"origin"
                    && joint.is_some_and(|j| depth == j.2 + 1 && !done[j.0])
                {
                    open_origin = Some(before);
                }
            }
            Event::Empty(e) => {
                if let Some((k, _, _)) = joint.filter(|j| depth == j.2 && !done[j.0]) {
                    if e.local_name().as_ref() == b"origin" {
                        edits.push((before, after, origin_element(&origins[k].1)));
                        done[k] = true;
                    }
                }
            }
            Event::End(e) => {
                let tag = e.local_name();
                if tag.as_ref() == b"origin" {
                    if let (Some(start), Some((k, _, _))) = (open_origin.take(), joint) {
                        edits.push((start, after, origin_element(&origins[k].1)));
                        done[k] = true;
                    }
                } else if tag.as_ref() == b"joint" {
                    if let Some((k, start_tag, _)) = joint.filter(|j| j.2 == depth) {
                        if !done[k] {
                            // No origin: the identity, now the calibrated one.
                            let o = format!("{nl}    {}", origin_element(&origins[k].1));
                            edits.push((start_tag, start_tag, o));
                            done[k] = true;
                        }
                        joint = None;
                    }
                } else if tag.as_ref() == b"robot" && depth == 1 {
                    robot_end = Some(before);
                }
                depth = depth.saturating_sub(1);
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if let Some(k) = done.iter().position(|d| !d) {
        return Err(format!("joint '{}' not found again", origins[k].0));
    }
    let end = robot_end.ok_or("no </robot> to add the links before")?;
    edits.push((end, end, added));
    edits.sort_by_key(|e| e.0);
    let mut out = String::with_capacity(bom.len() + text.len() + 4096);
    out.push_str(bom);
    let mut at = 0;
    for (start, stop, with) in edits {
        out.push_str(&text[at..start]);
        out.push_str(&with);
        at = stop;
    }
    out.push_str(&text[at..]);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use crate::calibrate::outputs::export::*;

    /// Only the chain joints' origins change and the new links are added:
    /// comments, unknown elements, a joint without `<limit>`, a link
    /// without `<inertial>` and the formatting stay as they were; an
    /// origin with children and a missing origin are handled.
    #[test]
    fn the_urdf_keeps_every_byte_but_the_origins_it_changes() {
        let text = "<?xml version=\"1.0\"?>\n<robot name=\"r\">\n  <!-- kept -->\n  \
            <link name=\"a\"/>\n  <link name=\"b\"/>\n  <link name=\"c\"/>\n  <link name=\"d\"/>\n  \
            <joint name=\"j1\" type=\"continuous\">\n    <parent link=\"a\"/>\n    \
            <child link=\"b\"/>\n    <origin xyz=\"1 2 3\" rpy=\"0 0 0\"/>\n  </joint>\n  \
            <joint name=\"j2\" type=\"revolute\">\n    <parent link=\"b\"/>\n    \
            <child link=\"c\"/>\n    <origin xyz=\"0 0 1\"></origin>\n    \
            <limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/>\n  </joint>\n  \
            <joint name=\"j3\" type=\"revolute\">\n    <parent link=\"c\"/>\n    \
            <child link=\"d\"/>\n  </joint>\n  <gazebo reference=\"a\"><x/></gazebo>\n</robot>\n";
        let t = |x: f64| Isometry3::translation(x, 0.0, 0.0);
        let origins = vec![
            ("j1".into(), t(0.5)),
            ("j2".into(), t(-0.25)),
            ("j3".into(), t(2.0)),
        ];
        let out = splice(text, &origins, "  <link name=\"new\"/>\n").expect("spliced");
        let expect = text
            .replace(
                "<origin xyz=\"1 2 3\" rpy=\"0 0 0\"/>",
                "<origin xyz=\"0.5 0 0\" rpy=\"0 0 0\"/>",
            )
            .replace(
                "<origin xyz=\"0 0 1\"></origin>",
                "<origin xyz=\"-0.25 0 0\" rpy=\"0 0 0\"/>",
            )
            .replace(
                "<joint name=\"j3\" type=\"revolute\">",
                "<joint name=\"j3\" type=\"revolute\">\n    <origin xyz=\"2 0 0\" rpy=\"0 0 0\"/>",
            )
            .replace("</robot>", "  <link name=\"new\"/>\n</robot>");
        assert_eq!(out, expect);
        // A joint it should change and cannot find is an error.
        let missing = vec![("j9".to_string(), t(1.0))];
        let e = splice(text, &missing, "").expect_err("no j9");
        assert!(e.contains("joint 'j9' not found again"), "{e}");
    }

    /// A byte-order mark stays and is not counted in the positions; a
    /// file's CRLF line ends are those of what is added; a prefixed
    /// `<u:origin>` is the joint's origin, as urdf-rs reads it (a second
    /// reading found each written wrong, with exit 0).
    #[test]
    fn a_bom_crlf_and_prefixed_names_are_kept_as_the_file_has_them() {
        let text = "\u{feff}<robot name=\"r\" xmlns:u=\"http://u\">\r\n  <link name=\"a\"/>\r\n  \
            <u:joint name=\"j1\" type=\"revolute\">\r\n    <u:origin xyz=\"1 2 3\"/>\r\n  \
            </u:joint>\r\n  <joint name=\"j2\" type=\"revolute\">\r\n  </joint>\r\n</robot>\r\n";
        let t = |x: f64| Isometry3::translation(x, 0.0, 0.0);
        let origins = vec![("j1".into(), t(0.5)), ("j2".into(), t(2.0))];
        let out = splice(text, &origins, "  <link name=\"new\"/>\n").expect("spliced");
        let expect = text
            .replace("<u:origin xyz=\"1 2 3\"/>", "<origin xyz=\"0.5 0 0\" rpy=\"0 0 0\"/>")
            .replace(
                "<joint name=\"j2\" type=\"revolute\">",
                "<joint name=\"j2\" type=\"revolute\">\r\n    <origin xyz=\"2 0 0\" rpy=\"0 0 0\"/>",
            )
            .replace("</robot>", "  <link name=\"new\"/>\r\n</robot>");
        assert_eq!(out, expect);
    }
}
