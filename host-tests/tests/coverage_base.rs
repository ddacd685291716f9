//! Is the base's σ that of its reported pose? A geometric calibration of the
//! KR-270 (absolute rows only, joint offsets and the base frame declared)
//! from points the test computes itself: forward kinematics from the URDF
//! text (`host_tests::exact::Fk`, no code shared with the estimator), put in
//! a tracker frame 2.8 m away and turned 0.65 rad, with noise of 20 µm per
//! axis. The base is reported as its translation and rotation vector in the
//! measurement frame; its σ was that of the fit's last step, which acts
//! about the tracker's origin: for the translation 2–4 times too large
//! (z's standard deviation 0.3–0.6). `Geometry::reported_covariance`
//! propagates it to the pose.
//!
//! For OLS, 300 jobs: each base parameter's z has a mean within ±0.25 and a
//! standard deviation within 0.85–1.15 (about 3.5 standard errors at 300
//! jobs), and the 95 % intervals of the six cover 95 % ± 3 standard errors
//! of 300 jobs.

use std::fmt::Write as _;
use std::path::Path;

use nalgebra::{Rotation3, Vector3};
use robcal::calibrate::{self, Method, Settings};
use robcal::io::{parse_measurements, Job};
use robcal_paper::kr270;
use robcal_paper::rng::SplitMix64;

use host_tests::coverage::in_parallel;
use host_tests::exact::Kr270;

const JOBS: usize = 300;
const CONFIGS: usize = 40;
const SIGMA_M: f64 = 20e-6;
/// The base in the tracker's frame: translation \[m\], rotation vector
/// \[rad\].
const T_M: [f64; 3] = [2.5, -1.2, 0.4];
const R_RAD: [f64; 3] = [0.1, -0.2, 0.6];

fn seed(i: usize) -> u64 {
    0x6261_7365_5f63_6f76 ^ (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
}

/// The job: KR-270's robot and markers, offsets and base declared.
fn job() -> Job {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/kr270");
    let dir = std::env::temp_dir().join(format!("robcal-coverage-base-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let mut setup = String::from(
        "robot = \"kr270.urdf\"\nbase_link = \"base_link\"\ntip_link = \"tool0\"\n\
         [units]\nangle = \"rad\"\nlength = \"m\"\n",
    );
    for (i, m) in kr270::MARKERS_M.iter().enumerate() {
        let _ = write!(setup, "[[marker]]\nid = {}\nxyz = {m:?}\n", i + 1);
    }
    setup +=
        "[noise]\nsigma0_um = 20.0\n[model]\ngeometry = \"joint_offsets\"\nbase_frame = true\n";
    std::fs::write(dir.join("setup.toml"), setup).expect("write");
    std::fs::copy(data.join("kr270.urdf"), dir.join("kr270.urdf")).expect("copy");
    let job = Job::load(dir.join("setup.toml")).expect("the setup reads");
    std::fs::remove_dir_all(&dir).ok();
    job
}

/// One file: `CONFIGS` random poses, 2 repetitions, the three markers.
fn csv(model: &Kr270, rng: &mut SplitMix64) -> String {
    let rot = Rotation3::from_scaled_axis(Vector3::from(R_RAD));
    let t = Vector3::from(T_M);
    let mut out = String::from("config,rep,marker,load_kg,a1,a2,a3,a4,a5,a6,x,y,z\n");
    for c in 0..CONFIGS {
        let q: Vec<f64> = (0..6).map(|_| rng.range(-1.2, 1.2)).collect();
        let pose = model.fk().pose(&q);
        let cells: Vec<String> = q.iter().map(|v| format!("{v:?}")).collect();
        for rep in 1..=2 {
            for (mi, m) in kr270::MARKERS_M.iter().enumerate() {
                let p = rot * pose.point(&Vector3::from(*m))
                    + t
                    + Vector3::from_fn(|_, _| rng.normal() * SIGMA_M);
                let _ = writeln!(
                    out,
                    "{},{rep},{},0,{},{:?},{:?},{:?}",
                    c + 1,
                    mi + 1,
                    cells.join(","),
                    p.x,
                    p.y,
                    p.z
                );
            }
        }
    }
    out
}

#[test]
fn the_bases_intervals_are_its_poses() {
    let job = job();
    let model = Kr270::new();
    let settings = Settings {
        method: Method::Ols,
        diagnose: false,
        heldout: false,
        ..Settings::default()
    };
    let truth = [T_M.map(|v| v * 1e3), R_RAD.map(|v| v * 1e3)].concat();
    let names = [
        "base.tx", "base.ty", "base.tz", "base.rx", "base.ry", "base.rz",
    ];
    let one = |i: usize| {
        let text = csv(&model, &mut SplitMix64::new(seed(i)));
        let data = parse_measurements(text.as_bytes(), "base.csv", &job.robot, &job.setup)
            .expect("the generated file reads");
        let r = calibrate::calibrate(&job, &data, &settings, &mut |_| {})
            .unwrap_or_else(|e| panic!("job {i}: {e}"));
        names.map(|n| {
            let p = r.parameters.iter().find(|p| p.name == n).expect(n);
            (p.value - truth[names.iter().position(|m| *m == n).unwrap_or(0)]) / p.std
        })
    };
    let z: Vec<[f64; 6]> = in_parallel(JOBS, one);
    let mut table = String::new();
    let mut fails = Vec::new();
    let mut inside = 0;
    for (k, name) in names.iter().enumerate() {
        let v: Vec<f64> = z.iter().map(|z| z[k]).collect();
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let std = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        inside += v.iter().filter(|x| x.abs() <= 1.959_964).count();
        let _ = writeln!(table, "{name}: mean z {mean:+.3}, std z {std:.3}");
        if mean.abs() > 0.25 || !(0.85..=1.15).contains(&std) {
            fails.push(*name);
        }
    }
    let cover = inside as f64 / (6 * z.len()) as f64;
    let _ = writeln!(table, "95 % intervals cover {:.1} %", 100.0 * cover);
    println!("{table}");
    assert_eq!(z.len(), JOBS);
    assert!(fails.is_empty(), "{fails:?}\n{table}");
    assert!(
        (cover - 0.95).abs() <= 3.0 * (0.95 * 0.05 / JOBS as f64).sqrt(),
        "{table}"
    );
}
