//! A payload asked of the calibrated robot against the payloads its
//! compliances were identified with.
//!
//! The joint law is identified over the torques of the calibration's
//! loads; a payload far heavier than any of them is a prediction by
//! extrapolation (or a payload in the wrong unit), and a model without a
//! compliance predicts the same point with or without a payload. Neither
//! is an error — the prediction is the model's — but both are reported,
//! by one rule ([`Predictor::payload_warning`], `docs/apply.md`), as a
//! warning of `robcal predict` and `robcal compensate`.

use crate::calibrate::outputs::predict::Predictor;
use crate::calibrate::report::plausibility::follows_torque;

/// A payload more than this many times the calibration's heaviest is
/// warned about: twice, so that a payload given in pounds where kilograms
/// are read (×2.2) is.
pub const EXTRAPOLATION_RATIO: f64 = 2.0;

impl Predictor {
    /// This predictor with the heaviest payload of its calibration \[kg\]
    /// (`None`: not known, as in a model file written before it was
    /// recorded; no payload is then warned about).
    #[must_use]
    pub fn with_heaviest_payload_kg(mut self, kg: Option<f64>) -> Self {
        self.heaviest_payload_kg = kg;
        self
    }

    /// The heaviest payload of the calibration \[kg\] (0: none was loaded),
    /// when known.
    pub fn heaviest_payload_kg(&self) -> Option<f64> {
        self.heaviest_payload_kg
    }

    /// Whether a payload changes what the robot predicts: a joint-law term
    /// that follows the joint's torque (a compliance, a compensator's
    /// table, nonlinear stiffness, backlash) or a link's bending. A gravity
    /// compliance follows the direction of gravity, not the load.
    pub fn responds_to_payload(&self) -> bool {
        !self.bending.is_empty() || self.lin.values().keys().any(follows_torque)
    }

    /// The warning for predictions at the payloads `loads` (`(line, kg)`
    /// each, 0 for none), by the rule of the [module docs](self):
    /// - a model that does not [respond](Self::responds_to_payload) to a
    ///   payload, and rows that carry one;
    /// - a calibration without a loaded row, and rows that carry a payload
    ///   (the compliances were identified under the robot's own weight);
    /// - rows whose payload is more than [`EXTRAPOLATION_RATIO`] times the
    ///   calibration's heaviest.
    ///
    /// `None` when no row is in one of these, or when the calibration's
    /// heaviest payload is not known. The warning counts the rows and
    /// names the heaviest payload and its line.
    pub fn payload_warning(&self, loads: &[(usize, f64)]) -> Option<String> {
        let heaviest = self.heaviest_payload_kg?;
        let responds = self.responds_to_payload();
        let limit = if responds && heaviest > 0.0 {
            heaviest * EXTRAPOLATION_RATIO
        } else {
            0.0
        };
        let over: Vec<&(usize, f64)> = loads.iter().filter(|(_, kg)| *kg > limit).collect();
        let (line, most) =
            over.iter()
                .copied()
                .fold(None, |m: Option<(usize, f64)>, &(l, kg)| match m {
                    Some((_, k)) if k >= kg => m,
                    _ => Some((l, kg)),
                })?;
        let (n, m) = (over.len(), loads.len());
        let most = format!("up to {most} kg (line {line})");
        Some(if !responds {
            format!(
                "{n} of {m} rows carry a payload, {most}, but the model has no compliance: \
                 a payload does not change where it puts a point"
            )
        } else if heaviest == 0.0 {
            format!(
                "{n} of {m} rows carry a payload, {most}, but the calibration had none: its \
                 compliances were identified under the robot's own weight, and a payload's \
                 deflection is extrapolated from them"
            )
        } else {
            format!(
                "{n} of {m} rows carry a payload more than {EXTRAPOLATION_RATIO} times the \
                 heaviest of the calibration ({heaviest} kg), {most}: their deflection is \
                 extrapolated beyond the loads the compliances were identified with (is \
                 load_kg in kilograms?)"
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use crate::calibrate::outputs::predict::payload::*;
    use crate::calibrate::params::linearisation::{DeflectionModel, Linearisation};
    use crate::model::Param;
    use crate::robot::{Chain, Joint, JointKind};
    use nalgebra::{Isometry3, Vector3};
    use std::collections::BTreeMap;

    fn robot(law: &[(Param, f64)], heaviest: Option<f64>) -> Predictor {
        let mut chain = Chain::new();
        chain
            .push(Joint {
                origin: Isometry3::identity(),
                axis: Vector3::z_axis(),
                kind: JointKind::Revolute,
                link: None,
            })
            .expect("joint");
        Predictor::from_parts(
            chain,
            vec![(1, Vector3::x())],
            Vector3::new(0.0, 0.0, -9.81),
            Linearisation::from_values(
                DeflectionModel::Exact,
                law.iter().copied().collect::<BTreeMap<_, _>>(),
            ),
            Vec::new(),
            Vector3::zeros(),
            vec!["a1".into()],
        )
        .with_heaviest_payload_kg(heaviest)
    }

    const K: Param = Param::Compliance { joint: 0 };

    #[test]
    fn a_payload_beyond_twice_the_heaviest_is_warned_about_with_its_line() {
        let r = robot(&[(K, 1e-6)], Some(250.0));
        assert_eq!(r.payload_warning(&[(2, 0.0), (3, 250.0), (4, 500.0)]), None);
        let w = r
            .payload_warning(&[(2, 0.0), (3, 600.0), (4, 501.0), (5, 20.0)])
            .expect("warned");
        assert!(
            w.starts_with("2 of 4 rows carry a payload more than 2 times the heaviest"),
            "{w}"
        );
        assert!(w.contains("(250 kg), up to 600 kg (line 3):"), "{w}");
    }

    #[test]
    fn a_payload_the_model_cannot_feel_or_was_not_calibrated_with_is_warned_about() {
        let gravity_only = robot(
            &[(Param::GravityCompliance { joint: 0, b: false }, 1e-6)],
            Some(5.0),
        );
        assert!(!gravity_only.responds_to_payload());
        let w = gravity_only.payload_warning(&[(2, 1.0)]).expect("warned");
        assert!(w.contains("no compliance"), "{w}");
        assert_eq!(gravity_only.payload_warning(&[(2, 0.0)]), None);

        let own_weight = robot(&[(K, 1e-6)], Some(0.0));
        let w = own_weight.payload_warning(&[(7, 0.5)]).expect("warned");
        assert!(w.contains("line 7") && w.contains("own weight"), "{w}");
    }

    #[test]
    fn nothing_is_warned_about_when_the_calibrations_payloads_are_not_known() {
        assert_eq!(robot(&[(K, 1e-6)], None).payload_warning(&[(2, 1e4)]), None);
        assert_eq!(robot(&[], None).payload_warning(&[(2, 1e4)]), None);
    }
}
