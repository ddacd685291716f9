//! What the parameters are called in the report and the JSON (data
//! contract §5): the URDF's joint names, the setup's marker ids, and the
//! angles of a compensator as the CSV wrote them.

use std::collections::BTreeMap;

use nalgebra::Vector3;

use crate::model::{Param, Unit};
use crate::robot::JointKind;

/// The names of a job's joints and markers, and the labels of its angle
/// bins.
#[derive(Debug, Clone, PartialEq)]
pub struct Names {
    /// Movable joint names, chain order.
    pub joints: Vec<String>,
    /// Joint kinds, chain order.
    pub kinds: Vec<JointKind>,
    /// Marker ids (as in the CSV) and nominal positions \[m, tip frame\], in
    /// setup order: [`Param::Marker`]'s index points into it.
    pub markers: Vec<(u32, Vector3<f64>)>,
    /// The angle of each compensator bin as the CSV wrote it, by joint and
    /// bin angle \[µrad\].
    pub bins: BTreeMap<(u8, i32), String>,
}

impl Names {
    /// Joint `j`'s name (`?` past the chain).
    pub fn joint(&self, j: u8) -> &str {
        self.joints.get(usize::from(j)).map_or("?", String::as_str)
    }

    /// The index of marker `id`.
    pub fn marker_index(&self, id: u32) -> Option<u8> {
        self.markers
            .iter()
            .position(|m| m.0 == id)
            .and_then(|i| u8::try_from(i).ok())
    }

    /// The id of marker index `m`.
    pub fn marker_id(&self, m: u8) -> u32 {
        self.markers.get(usize::from(m)).map_or(0, |m| m.0)
    }

    /// The kind of `p`'s joint (revolute for a parameter without one).
    pub fn kind(&self, p: &Param) -> JointKind {
        p.joint()
            .and_then(|j| self.kinds.get(usize::from(j)).copied())
            .unwrap_or(JointKind::Revolute)
    }

    /// The unit `p` is estimated and reported in.
    pub fn unit(&self, p: &Param) -> Unit {
        p.unit(self.kind(p))
    }

    /// The parameter's name (data contract §5): `k_<joint>`,
    /// `k_<joint>@<angle as written>`, `<joint>.offset`, `<joint>.tx`…,
    /// `base.tx`…, `tool.tx`…, `marker<id>.x`…, `<effect>_<joint>`, `load_com_x`…,
    /// `drift_x`…, `gear_cyclic_<joint>.sin`/`.cos`,
    /// `gravity_compliance_<joint>.a`/`.b`, `link_mass_<joint>`,
    /// `thermal_expansion`.
    pub fn name(&self, p: &Param) -> String {
        let c = p.component();
        match *p {
            Param::Compliance { joint } => format!("k_{}", self.joint(joint)),
            Param::ComplianceAt { joint, angle_urad } => {
                let angle = self
                    .bins
                    .get(&(joint, angle_urad))
                    .cloned()
                    .unwrap_or_else(|| format!("{}", f64::from(angle_urad) * 1e-6));
                format!("k_{}@{angle}", self.joint(joint))
            }
            Param::NonlinearStiffness { joint } => {
                format!("nonlinear_stiffness_{}", self.joint(joint))
            }
            Param::Backlash { joint } => format!("backlash_{}", self.joint(joint)),
            Param::LinkCompliance { joint } => format!("link_compliance_{}", self.joint(joint)),
            Param::LoadCom { .. } => format!("load_com_{c}"),
            Param::Drift { .. } => format!("drift_{c}"),
            Param::JointOffset { joint } | Param::JointFrame { joint, .. } => {
                format!("{}.{c}", self.joint(joint))
            }
            Param::Base { .. } => format!("base.{c}"),
            Param::Tool { .. } => format!("tool.{c}"),
            Param::Marker { marker, .. } => format!("marker{}.{c}", self.marker_id(marker)),
            Param::GearCyclic { joint, .. } => format!("gear_cyclic_{}.{c}", self.joint(joint)),
            Param::GravityCompliance { joint, .. } => {
                format!("gravity_compliance_{}.{c}", self.joint(joint))
            }
            Param::LinkMass { joint } => format!("link_mass_{}", self.joint(joint)),
            Param::ThermalExpansion => "thermal_expansion".into(),
        }
    }
}
