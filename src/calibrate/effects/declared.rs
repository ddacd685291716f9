//! The declared model: the parameters the setup's `[model]` asks for, in
//! the order that decides which of two dependent ones is kept.

use std::path::Path;

use crate::calibrate::params::names::Names;
use crate::calibrate::rows::Rows;
use crate::calibrate::settings::CalibrationError;
use crate::io::{job::Job, setup::GeometryModel, setup::MarkerModel};
use crate::model::Param;

/// Whether the declared model needs the absolute positions (geometric
/// rows): it identifies geometry, the base or the markers.
pub fn needs_absolute(job: &Job) -> bool {
    let m = &job.setup.model;
    m.geometry != GeometryModel::None
        || m.base_frame
        || m.tool_frame
        || m.markers == MarkerModel::Identify
}

/// The parameters of the setup's `[model]`, in order: compliances by angle
/// (one per bin of the joint), compliances, the base, the markers, the
/// joint geometry. Base and markers come before the joints: where a joint
/// parameter and the base (or a marker) are the same motion (the first
/// joint's frame error, the last joint's offset), the joint's is the one
/// left out.
///
/// # Errors
/// [`CalibrationError::Data`] for a joint the chain does not have, or a
/// compliance by angle of a joint that takes too many distinct angles.
pub fn declared(
    job: &Job,
    file: &Path,
    rows: &Rows,
    names: &Names,
) -> Result<Vec<Param>, CalibrationError> {
    let m = &job.setup.model;
    let joint = |name: &str| {
        job.robot
            .joint_index(name)
            .map(|j| j as u8)
            .ok_or_else(|| CalibrationError::Data(format!("[model] names unknown joint '{name}'")))
    };
    let mut model = Vec::new();
    for name in &m.compliance_by_angle {
        let j = joint(name)?;
        let bins = &rows.bins[usize::from(j)];
        if bins.is_empty() {
            return Err(CalibrationError::Data(format!(
                "{}: joint '{name}' takes too many distinct angles for compliance_by_angle",
                file.display()
            )));
        }
        model.extend(bins.iter().map(|&angle_urad| Param::ComplianceAt {
            joint: j,
            angle_urad,
        }));
    }
    for name in &m.compliance {
        if !m.compliance_by_angle.contains(name) {
            model.push(Param::Compliance {
                joint: joint(name)?,
            });
        }
    }
    if m.base_frame {
        model.extend((0..6).map(|axis| Param::Base { axis }));
    }
    if m.tool_frame {
        model.extend((0..6).map(|axis| Param::Tool { axis }));
    }
    if m.markers == MarkerModel::Identify {
        for marker in 0..names.markers.len() as u8 {
            model.extend((0..3).map(|axis| Param::Marker { marker, axis }));
        }
    }
    let dof = names.joints.len() as u8;
    match m.geometry {
        // `select`: offered to the loop as candidates (`effects`).
        GeometryModel::None | GeometryModel::Select => {}
        GeometryModel::JointOffsets => {
            model.extend((0..dof).map(|joint| Param::JointOffset { joint }))
        }
        GeometryModel::Full => {
            for joint in 0..dof {
                model.extend((0..6).map(|axis| Param::JointFrame { joint, axis }));
            }
        }
    }
    Ok(model)
}
