//! A fit that wanders off never leaves as a calibration (issue 58).
//!
//! Random serial chains measured by a tracker far from the robot, a true
//! robot that holds more than the declared model (every joint origin off
//! by up to 1 mm / 1 mrad, joint zeros off by up to 2 mrad, the markers
//! off by up to 1 mm), and every `geometry` of the setup (`none`,
//! `joint_offsets`, `select`, `full`). Whatever the fit does, a run that
//! would exit 0 (`Report::failure` is `None`) has a model that
//!
//! - predicts its own training data as the report says: the error of the
//!   model as written (the exact prediction `--validate` and `predict`
//!   make, [`calibrate::validate`]) within 1 % of the reported RMS;
//! - predicts them no worse than the nominal robot (with the base
//!   registered) by more than 1 %.
//!
//! The data come from `host_tests::arms` (forward kinematics of the true
//! URDF text by urdf-rs and 4 × 4 matrices), never from robcal's model.
//! And the reproduction of `shared/repro/ur5-joint-offsets`: no absurd
//! model with exit 0.

use host_tests::arms::{self, Chain, Truth};
use host_tests::exact::Fk;
use nalgebra::{Isometry3, Vector3};
use proptest::prelude::*;
use robcal::calibrate::{self, Method, Report, Settings};
use robcal::io::{Job, Measurements};
use robcal_paper::rng::SplitMix64;

const GEOMETRIES: [&str; 4] = ["none", "joint_offsets", "select", "full"];

/// One random robot, its nominal markers and its data.
struct Case {
    chain: Chain,
    markers: Vec<Vector3<f64>>,
    csv: String,
}

impl Case {
    /// The setup declaring `geometry`, the base frame and the markers.
    fn setup(&self, geometry: &str) -> String {
        self.chain.setup(geometry, true, "identify", &self.markers)
    }
}

fn case(seed: u64) -> Case {
    let mut rng = SplitMix64::new(seed);
    let chain = Chain::random(&mut rng);
    let joints = chain.movable();
    let markers: Vec<Vector3<f64>> = (0..1 + (rng.uniform() * 3.0) as usize % 3)
        .map(|_| Vector3::from_fn(|_, _| rng.range(-0.2, 0.2)))
        .collect();
    let true_chain = chain.perturbed(&mut rng, 1e-3, 1e-3);
    let angle = rng.range(0.0, 3.0);
    let shift = Vector3::from_fn(|_, _| rng.range(-3.0, 3.0));
    let base: Isometry3<f64> = arms::tracker_frame(&mut rng, angle, shift);
    let offsets: Vec<f64> = joints.iter().map(|_| rng.range(-2e-3, 2e-3)).collect();
    let true_markers: Vec<Vector3<f64>> = markers
        .iter()
        .map(|m| m + Vector3::from_fn(|_, _| rng.range(-1e-3, 1e-3)))
        .collect();
    let truth = Truth {
        fk: Fk::parse(&true_chain.urdf(), "l0", &true_chain.tip()),
        offsets,
        base,
        markers: true_markers,
        noise_m: 20e-6,
    };
    let configs = 15 + (rng.uniform() * 26.0) as usize;
    let poses: Vec<Vec<f64>> = (0..configs).map(|_| chain.random_q(&mut rng)).collect();
    let csv = truth.csv(&joints, &poses, &mut rng);
    Case {
        chain,
        markers,
        csv,
    }
}

fn job_and_data(c: &Case, geometry: &str) -> Result<(Job, Measurements), String> {
    c.chain.job(&c.setup(geometry), &c.csv)
}

/// The rule of the issue on one run: `Ok` when the run is refused, or
/// marked as not a calibration, or its model is what the report says.
fn check(report: &Report, job: &Job, data: &Measurements) -> Result<(), String> {
    if report.failure.is_some() {
        return Ok(());
    }
    let own_um = calibrate::validate(&report.model, job, data)
        .map_err(|e| format!("the model cannot predict its own data: {e}"))?
        .rms_mm
        * 1e3;
    if own_um.is_nan() || own_um > 1.01 * report.rms_um {
        return Err(format!(
            "exit 0, but the model predicts its own data at {own_um} um, reported {} um",
            report.rms_um
        ));
    }
    if own_um > 1.01 * report.nominal.rms_um {
        return Err(format!(
            "exit 0, but the model ({own_um} um) is worse than the nominal robot ({} um)",
            report.nominal.rms_um
        ));
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 500, ..ProptestConfig::default() })]

    #[test]
    fn no_wandering_fit_exits_zero(seed in any::<u64>()) {
        let c = case(seed);
        for (k, geometry) in GEOMETRIES.iter().enumerate() {
            let (job, data) = job_and_data(&c, geometry).map_err(TestCaseError::fail)?;
            // Both estimators, alternately; the loop where it adds the
            // geometry (`select`) and on one case in four otherwise.
            let settings = Settings {
                method: if (seed as usize + k).is_multiple_of(2) { Method::Ols } else { Method::Irls },
                diagnose: *geometry == "select" || seed % 4 == 0,
                heldout: false,
                ..Settings::default()
            };
            let Ok(report) = calibrate::calibrate(&job, &data, &settings, &mut |_| {}) else {
                // Refused, with an error: never a wrong answer.
                continue;
            };
            check(&report, &job, &data).map_err(|e| {
                TestCaseError::fail(format!(
                    "seed {seed}, geometry {geometry}: {e}\n{}\n{}",
                    c.setup(geometry),
                    c.chain.urdf()
                ))
            })?;
        }
    }
}

/// The reproduction of the issue: the closed loop on a UR5 whose data hold
/// link-length errors and a compliance the setup does not declare. Before,
/// exit 0 with offsets of ±49.65 rad and an RMS of 44.5 µm that its own
/// model missed by 9.6 mm. Now a trial that does not settle is rejected, a
/// candidate keeps only the columns the data determine
/// (`Policy::max_candidate_inflation`: no shoulder and elbow offsets that
/// trade against `elbow_joint.tx` along a curved direction of equivalent
/// robots, where they settled at ∓1.29 rad and −1.05 m), and the result is
/// the model's own: the reported RMS is what the model predicts of its
/// training data (to 1e-6), every parameter is of the size of the errors
/// the data hold (offsets of mrad, lengths below a millimetre), and the
/// validation poses are within 1.5× the noise (20 µm per axis: 34.6 µm per
/// point). The loop leaves structure it cannot explain and says so.
#[test]
fn ur5_joint_offsets_does_not_wander() {
    let Some(dir) = host_tests::shared_or_skip(
        "repro/ur5-joint-offsets",
        "train.csv",
        "ur5_joint_offsets_does_not_wander",
    ) else {
        return;
    };
    let job = Job::load(dir.join("setup.toml")).unwrap();
    let train = job.read_measurements(dir.join("train.csv")).unwrap();
    let validate = job.read_measurements(dir.join("validate.csv")).unwrap();
    let report = calibrate::calibrate(&job, &train, &Settings::default(), &mut |_| {}).unwrap();
    assert!(report.failure.is_none(), "{:?}", report.failure);
    check(&report, &job, &train).unwrap();
    let own = calibrate::validate(&report.model, &job, &train).unwrap();
    let rel = (own.rms_mm * 1e3 - report.rms_um).abs() / report.rms_um;
    assert!(
        rel < 1e-6,
        "own {} mm, reported {} um",
        own.rms_mm,
        report.rms_um
    );
    let v = calibrate::validate(&report.model, &job, &validate).unwrap();
    assert!(v.rms_mm < 1.5 * 0.0346, "validation {} mm", v.rms_mm);
    for p in &report.parameters {
        let bound = match p.unit.as_str() {
            "mrad" if p.name.starts_with("base.") => continue,
            "mm" if p.name.starts_with("base.") => continue,
            "mrad" => 10.0,
            "mm" => 2.0,
            _ => continue,
        };
        assert!(p.value.abs() < bound, "{p:?}");
    }
    assert!(report.unexplained.is_some() || report.lack_of_fit.is_some());
}
