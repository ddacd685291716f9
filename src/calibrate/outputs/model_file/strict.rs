//! What a read `predictor` must hold beyond its types: the units robcal
//! writes (it reads no other: a unit changed by hand would otherwise be
//! ignored, and the value read in SI), and each joint's law, table angle
//! and bending once (two records of one joint were summed, two entries of
//! one angle overwrote each other).

use std::collections::BTreeMap;

use crate::calibrate::outputs::model_file::ModelFile;
use crate::model::angle_urad;
use crate::robot::JointKind;

/// The unit of each term of a joint's law as written (SI).
pub(super) fn units(kind: JointKind) -> BTreeMap<String, String> {
    let (k, c, b) = match kind {
        JointKind::Revolute => ("rad/(N*m)", "rad/(N*m)^2", "rad"),
        JointKind::Prismatic => ("m/N", "m/N^2", "m"),
    };
    [
        ("compliance", k),
        ("nonlinear_stiffness", c),
        ("backlash", b),
        ("gear_cyclic", b),
    ]
    .into_iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect()
}

/// [`ModelFile::predictor`]'s checks of units and repetitions.
///
/// # Errors
/// One line naming the record and what is wrong.
pub(super) fn check(file: &ModelFile) -> Result<(), String> {
    if let Some(kg) = file.heaviest_payload_kg {
        if !(0.0..=crate::io::measurements::MAX_LOAD_KG).contains(&kg) {
            // (1e300 in full is 301 digits.)
            let kg = if kg.abs() < 1e6 {
                format!("{kg}")
            } else {
                format!("{kg:e}")
            };
            return Err(format!("heaviest_payload_kg: {kg} kg is not a payload"));
        }
    }
    for (i, r) in file.joint_law.iter().enumerate() {
        let what = format!("joint_law of '{}'", r.joint);
        if file.joint_law[..i].iter().any(|o| o.joint == r.joint) {
            return Err(format!("{what}: listed twice"));
        }
        // An unknown joint is the predictor's own error.
        let Some(joint) = file.joints.iter().find(|j| j.name == r.joint) else {
            continue;
        };
        let kind = match joint.kind.as_str() {
            "prismatic" => JointKind::Prismatic,
            _ => JointKind::Revolute,
        };
        let mut expected = units(kind);
        let gravity = r.gravity_compliance_a != 0.0 || r.gravity_compliance_b != 0.0;
        if gravity || r.units.contains_key("gravity_compliance") {
            let unit = expected["gear_cyclic"].clone();
            expected.insert("gravity_compliance".into(), unit);
        }
        for (term, unit) in &expected {
            match r.units.get(term) {
                Some(u) if u == unit => {}
                Some(u) => {
                    return Err(format!(
                        "{what}: unit of {term} '{u}', where robcal writes and reads '{unit}'"
                    ))
                }
                None => return Err(format!("{what}: no unit for {term} (it is '{unit}')")),
            }
        }
        if let Some(term) = r.units.keys().find(|t| !expected.contains_key(*t)) {
            return Err(format!("{what}: a unit for '{term}', which is not a term"));
        }
        for (k, e) in r.compliance_table.iter().enumerate() {
            let at = angle_urad(e.angle_rad);
            if r.compliance_table[..k]
                .iter()
                .any(|o| angle_urad(o.angle_rad) == at)
            {
                return Err(format!(
                    "{what}: table angle {} rad listed twice",
                    e.angle_rad
                ));
            }
        }
    }
    for (i, b) in file.link_compliance.iter().enumerate() {
        let what = format!("link_compliance of '{}'", b.joint);
        if file.link_compliance[..i].iter().any(|o| o.joint == b.joint) {
            return Err(format!("{what}: listed twice"));
        }
        if b.unit != "rad/(N*m)" {
            return Err(format!(
                "{what}: unit '{}', where robcal writes and reads 'rad/(N*m)'",
                b.unit
            ));
        }
    }
    Ok(())
}
