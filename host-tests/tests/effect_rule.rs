//! The effect library's one rule (`robcal::model::effect::candidates`):
//! which effects a model lacks under which data, on which parameters, in
//! which order; and the two lists built on it — the host's
//! (`calibrate::effects::candidates`) and the device's
//! (`model::effect::stream_candidates`) — list the same candidates for a
//! stream of deflections.

use crate::model_common;

use std::collections::BTreeMap;

use model_common::kr270;
use nalgebra::Vector3;
use robcal::calibrate::effects::candidates;
use robcal::calibrate::Names;
use robcal::calibrate::{DataKinds, Effect};
use robcal::model::effect::{joint_bins, stream_candidates, JointBins};
use robcal::model::{Layout, Param};
use robcal::robot::JointKind;
use robcal::Chain;

fn names(kinds: &[JointKind], markers: usize) -> Names {
    Names {
        joints: (0..kinds.len()).map(|j| format!("j{j}")).collect(),
        kinds: kinds.to_vec(),
        markers: (0..markers)
            .map(|m| (m as u32 + 10, Vector3::zeros()))
            .collect(),
        bins: BTreeMap::new(),
    }
}

/// Bins of every joint: three angles, each in two configurations.
fn bins(dof: usize) -> Vec<Vec<i32>> {
    (0..dof)
        .map(|j| vec![0, 100_000 * (j as i32 + 1), -200_000])
        .collect()
}

#[test]
fn the_rule_lists_what_the_model_lacks_in_its_order() {
    use Effect::*;
    use JointKind::{Prismatic, Revolute};
    let n = names(&[Revolute, Revolute, Prismatic], 2);
    let all = DataKinds {
        deflections: true,
        absolute: true,
        time: true,
        own_weight: false,
        temperature: false,
    };
    let b = bins(3);
    let model = [Param::Compliance { joint: 0 }];
    let c = candidates(&n, &model, all, &b, &[true, true, false]);
    let got: Vec<(Effect, Option<usize>, Option<u8>)> =
        c.iter().map(|c| (c.effect, c.joint, c.marker)).collect();
    let j = |effect, j| (effect, Some(j), None);
    let expected = vec![
        j(Compensator, 0),
        j(NonlinearStiffness, 0),
        j(Backlash, 0),
        j(LinkCompliance, 0),
        j(JointOffset, 0),
        // No frame error on the first joint: that is the base's.
        j(GearCyclic, 0),
        j(Compensator, 1),
        j(JointCompliance, 1),
        j(Backlash, 1),
        j(LinkCompliance, 1),
        j(JointOffset, 1),
        j(Geometry, 1),
        j(GearCyclic, 1),
        // Joint 0 has a compliance: its weight loads it through the masses;
        // joint 1 has none.
        j(GravityCompliance, 1),
        // Prismatic, no compensator bins: no link compliance, no gear, no
        // gravity compliance.
        j(JointCompliance, 2),
        j(Backlash, 2),
        j(JointOffset, 2),
        j(Geometry, 2),
        (LoadCom, None, None),
        (Drift, None, None),
        (Marker, None, Some(0)),
        (Marker, None, Some(1)),
        (BaseFrame, None, None),
    ];
    assert_eq!(got, expected);
    // The compensator on a joint with a constant compliance: the bins minus
    // one tested, the constant replaced by the bins.
    let bins0: Vec<Param> = b[0]
        .iter()
        .map(|&angle_urad| Param::ComplianceAt {
            joint: 0,
            angle_urad,
        })
        .collect();
    assert_eq!(c[0].test, bins0[1..]);
    assert_eq!(c[0].remove, vec![Param::Compliance { joint: 0 }]);
    assert_eq!(c[0].add, bins0);
    // Without one, every bin is tested and nothing removed.
    assert_eq!(c[6].test, c[6].add);
    assert!(c[6].remove.is_empty());
    assert_eq!(c[11].add.len(), 6);
    let gravity = [false, true].map(|b| Param::GravityCompliance { joint: 1, b });
    assert_eq!(c[13].add, gravity);
    assert_eq!(c[13].test, gravity);

    // Deflections only: no geometric candidate; no time: no drift; no
    // compliance in the model: no load centre of mass.
    let defl = DataKinds {
        deflections: true,
        absolute: false,
        time: false,
        own_weight: false,
        temperature: false,
    };
    let c = candidates(&n, &[], defl, &b, &[false; 3]);
    assert!(c
        .iter()
        .all(|c| matches!(c.effect, JointCompliance | Backlash | LinkCompliance)));
    assert_eq!(c.len(), 3 + 3 + 2);
}

#[test]
fn the_device_lists_the_hosts_candidates_for_deflections() {
    let chain: Chain<f64, 6> = kr270().chain();
    let n = names(&[JointKind::Revolute; 6], 1);
    // Joint 1 (a2) takes three angles twice each; the others one.
    let mut device_bins: Vec<JointBins<8>> = Vec::new();
    let (mut host_bins, mut ok) = (Vec::new(), Vec::new());
    for j in 0..6 {
        let angles: Vec<f64> = if j == 1 {
            vec![0.0, -0.5, -1.0, 0.0, -0.5, -1.0]
        } else {
            vec![0.3; 6]
        };
        let jb = joint_bins::<f64, 8>(&angles).unwrap();
        host_bins.push(jb.angles_urad.to_vec());
        ok.push(jb.compensator_ok);
        device_bins.push(jb);
    }
    assert_eq!(ok, [false, true, false, false, false, false]);
    let models: [&[Param]; 3] = [
        &[],
        &[
            Param::Compliance { joint: 1 },
            Param::Compliance { joint: 2 },
        ],
        &[
            Param::Compliance { joint: 1 },
            Param::Backlash { joint: 4 },
            Param::LoadCom { axis: 0 },
            Param::LoadCom { axis: 1 },
            Param::LoadCom { axis: 2 },
        ],
    ];
    for model in models {
        for time in [false, true] {
            let kinds = DataKinds {
                deflections: true,
                absolute: false,
                time,
                own_weight: false,
                temperature: false,
            };
            let host = candidates(&n, model, kinds, &host_bins, &ok);
            let (layout, device) =
                stream_candidates::<f64, 6, 64, 40, 8>(&chain, model, &device_bins, time).unwrap();
            let mask = |l: &Layout<64>, ps: &[Param]| {
                ps.iter()
                    .map(|p| 1u64 << l.index_of(p).expect("in the layout"))
                    .fold(0, |a, b| a | b)
            };
            assert_eq!(host.len(), device.len(), "{model:?}, time {time}");
            for (h, d) in host.iter().zip(&device) {
                assert_eq!(h.effect, d.effect);
                assert_eq!(h.joint, d.joint.map(usize::from));
                assert_eq!(mask(&layout, &h.test), d.test);
                assert_eq!(mask(&layout, &h.remove), d.remove);
                assert_eq!(mask(&layout, &h.add), d.add);
            }
            // The model's columns first, in its order.
            for (i, p) in model.iter().enumerate() {
                assert_eq!(layout.index_of(p), Some(i));
            }
        }
    }
}

#[test]
fn host_and_device_judge_estimates_alike() {
    use robcal::calibrate::Policy;
    let n = names(&[JointKind::Revolute; 2], 1);
    let policy = Policy::default();
    let drift = [0, 1, 2].map(|axis| Param::Drift { axis });
    let limit = policy.max_drift_mm_per_h / 3.6;
    let judge = |v: [f64; 3]| {
        let host = robcal::calibrate::effects::inadmissible(&n, &policy, &drift, &v, &drift);
        let device =
            robcal::model::effect::inadmissible(&drift, &v, &drift, policy.max_drift_mm_per_h);
        assert_eq!(host.is_some(), device.is_some(), "{v:?}");
        device.is_some()
    };
    // To the last bit either side of the limit, along an axis and not.
    for ulps in -40i64..=40 {
        let x = f64::from_bits((limit.to_bits() as i64 + ulps) as u64);
        judge([x, 0.0, 0.0]);
        judge([0.0, 0.0, -x]);
        judge([x * 0.6, x * 0.8, 0.0]);
    }
    assert!(!judge([limit * 0.99, 0.0, 0.0]));
    assert!(judge([limit * 0.6, limit * 0.81, 0.0]));
    for p in [Param::Compliance { joint: 1 }, Param::Backlash { joint: 0 }] {
        for v in [-1e-300, 0.0, 1e-300] {
            let host = robcal::calibrate::effects::inadmissible(&n, &policy, &[p], &[v], &[p]);
            let device = robcal::model::effect::inadmissible(&[p], &[v], &[p], 1.0);
            assert_eq!(host.is_some(), device.is_some());
            assert_eq!(device, (v < 0.0).then_some(p));
        }
    }
}
