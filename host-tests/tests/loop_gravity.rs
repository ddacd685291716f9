//! The closed loop (`robcal::calibrate`) and the lumped gravity compliance
//! (`gravity_compliance`, `Param::GravityCompliance`): a robot whose URDF
//! has no link masses (so `joint_compliance` columns, compliance times the
//! gravity torque of eq. 3, are zero) and whose elbow bends under the
//! weight of everything outboard of it.
//!
//! The generator shares no code with the estimator's columns or joint law:
//! it composes joint `j`'s rotation `Rⱼ` itself from the URDF origins and
//! axes at the commanded pose, bends the joint by the physical law
//! `δqⱼ = v · (Rⱼᵀĝ × ẑⱼ)` (`v = kⱼ m |g| u`, the lumped vector, brief of
//! the effect), and measures the markers at the bent joint values through
//! the chain's forward kinematics, in a measurement frame placed away from
//! the base, with noise of 10–30 µm per axis.
//!
//! The UR-like elbow turns about its frame's `y`: its basis is `a = x`,
//! `b = ẑ × a = y × x = −z` (`robcal::model::gravity_basis`), and
//! `δq = v · (g × ẑ) = gₐ v·(a × ẑ) + g_b v·(b × ẑ) = gₐ v_z + g_b v_x`:
//! the parameters are `x_a = v_z`, `x_b = v_x`.

use nalgebra::{UnitQuaternion, Vector3};
use robcal::calibrate::Report;
use robcal::io::Job;

use crate::ur_like_common as ur_like;

const ELBOW: usize = 2;

/// A massless UR-like arm measured in `configs` poses (two repetitions,
/// [`ur_like::measure`]); the elbow bends by `v` \[rad\] (zero: a rigid
/// robot). The declared model: the base frame, the markers at their
/// nominal positions, no compliance.
fn simulate(v: Vector3<f64>, configs: usize, seed: u64) -> (Job, robcal::io::Measurements) {
    let mut job = ur_like::job();
    for j in job.robot.chain.joints_mut() {
        j.link = None;
    }
    let chain = job.robot.chain.clone();
    let joints = chain.joints().to_vec();
    let g = Vector3::from(job.setup.load.expect("fixture has a load").gravity).normalize();
    let data = ur_like::measure(&job, configs, seed, None, |_, q| {
        // Rⱼ at the commanded pose, its own rotation included.
        let mut r = UnitQuaternion::identity();
        for (joint, &qi) in joints.iter().zip(q).take(ELBOW + 1) {
            r = r * joint.origin.rotation * UnitQuaternion::from_axis_angle(&joint.axis, qi);
        }
        let z = joints[ELBOW].axis.into_inner();
        let mut q_true = q.to_vec();
        q_true[ELBOW] += v.dot(&r.inverse_transform_vector(&g).cross(&z));
        let frames = chain.frames(&q_true).unwrap();
        (job.setup.markers.iter())
            .map(|m| frames.point_m(&Vector3::from(m.xyz)))
            .collect()
    });
    (job, data)
}

fn run(v: Vector3<f64>, configs: usize, seed: u64, heldout: bool) -> Report {
    let (job, data) = simulate(v, configs, seed);
    ur_like::calibrate(&job, &data, heldout)
}

/// The loop names the elbow's gravity compliance first, both errors drop
/// to the noise, and the estimate is the truth within 3 σ (the sandwich σ
/// of the final model).
#[test]
fn gravity_compliance_is_found_and_recovered() {
    // |v⊥| = 5 mrad: the elbow sags up to 5 mrad (3 mm at the wrist).
    let v = Vector3::new(3.0e-3, 0.0, -4.0e-3);
    let truth = [("a", v.z * 1e3), ("b", v.x * 1e3)];
    for seed in [31, 32, 33] {
        let r = run(v, 30, seed, true);
        let what = host_tests::loop_summary(&r);
        let first = r
            .effects
            .first()
            .unwrap_or_else(|| panic!("nothing added: {what}"));
        assert_eq!(first.effect.name(), "gravity_compliance", "{what}");
        assert_eq!(first.joint.as_deref(), Some("elbow"), "{what}");
        let (hb, ha) = (
            first.heldout_rms_um_before.unwrap(),
            first.heldout_rms_um_after.unwrap(),
        );
        assert!(
            ha < hb && first.rms_um_after < first.rms_um_before,
            "{what}"
        );
        // Noise only after: norm RMS ≈ √3 · 21 µm ≈ 36 µm (σ 10–30 µm per
        // axis), less the fitted dof; 34 to 40 µm over the seeds.
        assert!(r.rms_um < 45.0, "{} um: {what}", r.rms_um);
        for (c, x) in truth {
            let name = format!("gravity_compliance_elbow.{c}");
            let p = r
                .parameters
                .iter()
                .find(|p| p.name == name)
                .unwrap_or_else(|| panic!("{name} not in the model: {what}"));
            assert_eq!(p.unit, "mrad");
            let z = (p.value - x) / p.std;
            eprintln!(
                "seed {seed}: {name} = {:.4} ± {:.4} mrad (truth {x:.4}, {z:+.2} σ); \
                 RMS {:.1} -> {:.1} um, held out {hb:.1} -> {ha:.1} um",
                p.value, p.std, first.rms_um_before, first.rms_um_after
            );
            assert!(z.abs() < 3.0, "{name}: {} ± {} vs {x}", p.value, p.std);
        }
    }
}

/// A rigid robot (the same poses, no bending) never gets a gravity
/// compliance, in 20 seeded runs; and the loop adds nothing in at least
/// 19 of them (the library's false-alarm rate, `loop_effects`).
#[test]
fn rigid_robot_gets_no_gravity_compliance() {
    let mut added = Vec::new();
    for seed in 0..20 {
        let r = run(Vector3::zeros(), 20, 2000 + seed, false);
        assert!(
            r.effects
                .iter()
                .all(|e| e.effect.name() != "gravity_compliance"),
            "seed {seed}: {}",
            host_tests::loop_summary(&r)
        );
        if !r.effects.is_empty() {
            added.push(format!("seed {seed}: {}", host_tests::loop_summary(&r)));
        }
    }
    eprintln!("false alarms: {} of 20: {added:?}", added.len());
    assert!(added.len() <= 1, "{added:#?}");
}

/// The calibrated robot applies the gravity compliance where it predicts
/// (`--validate`, `robcal predict`/`compensate`, `model.json`): other
/// poses of the same bent robot are predicted to the noise, and the model
/// file's predictor is the calibration's.
#[test]
fn the_prediction_applies_the_gravity_compliance() {
    use robcal::calibrate::ModelFile;
    use robcal::calibrate::Predictor;
    let v = Vector3::new(3.0e-3, 0.0, -4.0e-3);
    let (job, data) = simulate(v, 30, 41);
    let r = ur_like::calibrate(&job, &data, true);
    assert!(
        r.parameters
            .iter()
            .any(|p| p.name == "gravity_compliance_elbow.a"),
        "{}",
        host_tests::loop_summary(&r)
    );
    let (_, other) = simulate(v, 30, 42);
    let val = robcal::calibrate::validate(&r.model, &job, &other).unwrap();
    // Noise (σ 10–30 µm per axis): ≈ 0.036 mm; without the effect the
    // elbow's 5 mrad would leave millimetres.
    eprintln!("other poses: RMS {:.4} mm", val.rms_mm);
    assert!(val.rms_mm < 0.045, "{}", val.rms_mm);
    let p = Predictor::new(&r.model, &job);
    let file = ModelFile::of(&p);
    let law = &file.joint_law;
    assert!(
        law.iter()
            .any(|l| l.joint == "elbow" && l.gravity_compliance_a != 0.0),
        "{law:?}"
    );
    let back = file.predictor().unwrap();
    let q = [0.3, -1.2, 1.4, -0.5, 0.8, 0.2];
    for m in 0..3 {
        let (a, b) = (
            p.predict_marker(m, &q, None).unwrap(),
            back.predict_marker(m, &q, None).unwrap(),
        );
        assert!((a - b).norm() < 1e-12, "{a} vs {b}");
    }
}
