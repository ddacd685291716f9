//! The UR-like arm of the closed-loop tests on synthetic data
//! (`tests/fixtures/loop/ur_like.toml`: its URDF's link masses, three
//! markers on the tool), seen by a tracker: random poses, two repetitions,
//! noise of 10–30 µm per axis, the measurement frame placed away from the
//! base. Each test's generator says where the markers are at a pose;
//! this module draws the poses, adds the noise and writes the measurement
//! file. It shares no code with the estimator: the forward kinematics
//! here ([`frames`]) is composed from the URDF's origins and axes.

use std::path::PathBuf;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use robcal::calibrate::{self, Report, Settings};
use robcal::io::{parse_measurements, Job, MarkerModel, Measurements};
use robcal::robot::Joint;
use robcal_paper::rng::SplitMix64 as Rng;

/// The fixture's job with the declared model of these tests: the base
/// frame, the markers at their nominal positions, no compliance.
pub fn job() -> Job {
    let setup = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/loop/ur_like.toml");
    let mut job = Job::load(setup).expect("fixture setup");
    job.setup.model.compliance = vec![];
    job.setup.model.base_frame = true;
    job.setup.model.markers = MarkerModel::Nominal;
    job
}

/// The robot's base in the measurement frame.
pub fn base() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(1.5, -0.4, 0.2),
        UnitQuaternion::from_scaled_axis(Vector3::new(0.02, -0.01, 0.7)),
    )
}

/// Each joint's range the poses are drawn from \[deg\].
const RANGES_DEG: [(f64, f64); 6] = [
    (-180.0, 180.0),
    (-160.0, -20.0),
    (-150.0, 150.0),
    (-180.0, 180.0),
    (-150.0, 150.0),
    (-180.0, 180.0),
];

/// Joint `j`'s frame `Tⱼ = Tⱼ₋₁ · originⱼ · rot(axisⱼ, θⱼ)` (robot base
/// frame), every joint.
pub fn frames(joints: &[Joint<f64>], theta: &[f64]) -> Vec<Isometry3<f64>> {
    let mut t = Isometry3::identity();
    joints
        .iter()
        .zip(theta)
        .map(|(joint, &v)| {
            let turn = UnitQuaternion::from_axis_angle(&joint.axis, v);
            t = t * joint.origin * Isometry3::from_parts(Translation3::identity(), turn);
            t
        })
        .collect()
}

/// A measurement column besides the contract's: its name and its value in
/// configuration `c` (0-based).
pub type Extra<'a> = (&'a str, &'a dyn Fn(usize) -> f64);

/// `configs` poses drawn from `seed` (to 0.01°), each measured twice:
/// `markers(c, q)` gives where the setup's markers are, in its order, at
/// configuration `c` commanded to `q` \[rad\] (robot base frame, m); the
/// tracker sees them from [`base`] with noise of 10–30 µm per axis (drawn
/// per configuration), no load. `extra`, a column after `x, y, z`.
pub fn measure(
    job: &Job,
    configs: usize,
    seed: u64,
    extra: Option<Extra<'_>>,
    mut markers: impl FnMut(usize, &[f64]) -> Vec<Vector3<f64>>,
) -> Measurements {
    let base = base();
    let mut rng = Rng::new(seed);
    let mut csv = format!(
        "config,rep,marker,load_kg,{},x,y,z",
        job.robot.joint_names.join(",")
    );
    if let Some((name, _)) = extra {
        csv += &format!(",{name}");
    }
    csv.push('\n');
    for c in 0..configs {
        let q_deg: Vec<f64> = RANGES_DEG
            .iter()
            .map(|&(lo, hi)| (rng.range(lo, hi) * 100.0).round() / 100.0)
            .collect();
        let q: Vec<f64> = q_deg.iter().map(|d| d.to_radians()).collect();
        let points = markers(c, &q);
        let sigma = Vector3::from_fn(|_, _| rng.range(10.0, 30.0) * 1e-6);
        let qs: Vec<String> = q_deg.iter().map(|v| format!("{v}")).collect();
        let tail = extra.map(|(_, v)| format!(",{}", v(c))).unwrap_or_default();
        for rep in 1..=2 {
            for (m, p) in job.setup.markers.iter().zip(&points) {
                let p = base.transform_point(&Point3::from(*p));
                let p = p.coords + Vector3::from_fn(|a, _| rng.normal() * sigma[a]);
                csv += &format!(
                    "{},{rep},{},0,{},{},{},{}{tail}\n",
                    c + 1,
                    m.id,
                    qs.join(","),
                    p.x * 1e3,
                    p.y * 1e3,
                    p.z * 1e3
                );
            }
        }
    }
    parse_measurements(csv.as_bytes(), "synthetic.csv", &job.robot, &job.setup)
        .expect("synthetic data parse")
}

/// The closed loop with the default settings, the held-out error at every
/// step when `heldout`.
pub fn calibrate(job: &Job, data: &Measurements, heldout: bool) -> Report {
    let settings = Settings {
        heldout,
        ..Settings::default()
    };
    calibrate::calibrate(job, data, &settings, &mut |_| {}).expect("calibration")
}
