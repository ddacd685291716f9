//! 6-D poses (data contract extension `rx, ry, rz`): a UR10 whose joint
//! zeros and tool frame are off, measured as poses (point and orientation)
//! by a 6-D instrument. The generator shares no code with the estimator:
//! the forward kinematics is `host_tests::exact::Fk` (urdf-rs, 4 × 4
//! matrices), the orientation noise a rotation `Exp(n)` of the true frame
//! in the measurement frame, the rotation vector written by nalgebra.

use nalgebra::{Matrix3, Rotation3, Vector3};
use robcal::calibrate::{self, Report, Settings};
use robcal::io::{parse_measurements, Job};
use robcal_paper::rng::SplitMix64 as Rng;

const JOINTS: [&str; 6] = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
];

/// The instrument's σ per axis: a point's \[m\] and an orientation's
/// \[rad\].
const SIGMA_M: f64 = 20e-6;
const SIGMA_RAD: f64 = 30e-6;

/// The marker (the probe's origin) on the flange \[m\].
const MARKER_M: [f64; 3] = [0.0, 0.0, 0.1];

/// The truth of one job: joint zeros \[rad\], the tool frame's error
/// (translation \[m\], rotation vector \[rad\], in the flange frame).
struct Truth {
    offsets: [f64; 6],
    tool_t: Vector3<f64>,
    tool_r: Vector3<f64>,
}

impl Truth {
    fn draw(rng: &mut Rng) -> Self {
        Self {
            // The last joint's zero is the tool frame's turn about its
            // axis (the data cannot tell them apart: identifiability leaves
            // it out): 0, so that the tool's truth is its own.
            offsets: [0, 1, 2, 3, 4, 5].map(|j| if j == 5 { 0.0 } else { rng.range(-1e-3, 1e-3) }),
            tool_t: Vector3::from_fn(|_, _| rng.range(-0.5e-3, 0.5e-3)),
            tool_r: Vector3::from_fn(|_, _| rng.range(-0.5e-3, 0.5e-3)),
        }
    }

    /// The truth in the report's names and units (mrad, mm).
    fn value(&self, name: &str) -> Option<f64> {
        if let Some(j) = name.strip_suffix(".offset") {
            let k = JOINTS.iter().position(|&n| n == j)?;
            return Some(self.offsets[k] * 1e3);
        }
        let axis = |s: &str| ["x", "y", "z"].iter().position(|&a| a == s);
        if let Some(a) = name.strip_prefix("tool.t") {
            return Some(self.tool_t[axis(a)?] * 1e3);
        }
        if let Some(a) = name.strip_prefix("tool.r") {
            return Some(self.tool_r[axis(a)?] * 1e3);
        }
        None
    }
}

fn job(dir: &std::path::Path, tag: &str) -> Job {
    let text = format!(
        "robot = \"{}\"\nbase_link = \"base_link\"\ntip_link = \"flange\"\n\
         [units]\nangle = \"rad\"\nlength = \"m\"\n\
         [[marker]]\nid = 1\nxyz = [{}, {}, {}]\n\
         [noise]\nsigma0_um = 20.0\n\
         [model]\ngeometry = \"joint_offsets\"\ntool_frame = true\n",
        dir.join("ur10.urdf").display(),
        MARKER_M[0],
        MARKER_M[1],
        MARKER_M[2]
    );
    let path = std::env::temp_dir().join(format!("robcal-poses-{}-{tag}.toml", std::process::id()));
    std::fs::write(&path, text).expect("setup");
    let job = Job::load(&path).expect("setup");
    let _ = std::fs::remove_file(&path);
    job
}

/// `n` poses of the true robot: each a point and, with `orientation`, the
/// flange's orientation, with the instrument's noise and σ columns.
fn csv(
    fk: &host_tests::exact::Fk,
    truth: &Truth,
    n: usize,
    orientation: bool,
    rng: &mut Rng,
) -> String {
    let mut out = format!("config,{},x,y,z,sx,sy,sz", JOINTS.join(","));
    if orientation {
        out += ",rx,ry,rz,srx,sry,srz";
    }
    out.push('\n');
    let tool = Rotation3::new(truth.tool_r);
    for c in 0..n {
        let q: Vec<f64> = (0..6).map(|_| rng.range(-3.0, 3.0)).collect();
        let theta: Vec<f64> = q.iter().zip(&truth.offsets).map(|(q, o)| q + o).collect();
        let pose = fk.pose(&theta);
        let r_tip =
            Rotation3::from_matrix_unchecked(Matrix3::from(pose.tip.fixed_view::<3, 3>(0, 0)));
        let p_tip = pose.tip.fixed_view::<3, 1>(0, 3).into_owned();
        // Everything on the flange turned and moved by the tool's error.
        let p = p_tip + r_tip * (truth.tool_t + tool * Vector3::from(MARKER_M));
        let p = p + Vector3::from_fn(|_, _| rng.normal() * SIGMA_M);
        let qs: Vec<String> = q.iter().map(|v| format!("{v:.9}")).collect();
        out += &format!(
            "{},{},{:.9},{:.9},{:.9},{SIGMA_M},{SIGMA_M},{SIGMA_M}",
            c + 1,
            qs.join(","),
            p.x,
            p.y,
            p.z
        );
        if orientation {
            let noise = Rotation3::new(Vector3::from_fn(|_, _| rng.normal() * SIGMA_RAD));
            let r = (noise * r_tip * tool).scaled_axis();
            out += &format!(
                ",{:.12},{:.12},{:.12},{SIGMA_RAD},{SIGMA_RAD},{SIGMA_RAD}",
                r.x, r.y, r.z
            );
        }
        out.push('\n');
    }
    out
}

fn fit(job: &Job, text: &str) -> Report {
    let data =
        parse_measurements(text.as_bytes(), "poses.csv", &job.robot, &job.setup).expect("parse");
    let settings = Settings {
        diagnose: false,
        heldout: false,
        ..Settings::default()
    };
    calibrate::calibrate(job, &data, &settings, &mut |_| {}).expect("calibrate")
}

/// Over 500 jobs of 20 poses, every estimate (joint zeros, tool frame)
/// within ±3 σ of the truth in ≥ 99 % of the cases; the orientation's
/// residual at the noise.
#[test]
fn pose_estimates_cover_the_truth() {
    let Some(dir) = host_tests::shared_or_skip(
        "repro/ur10-offsets",
        "ur10.urdf",
        "pose_estimates_cover_the_truth",
    ) else {
        return;
    };
    let fk = host_tests::exact::Fk::new(&dir.join("ur10.urdf"), "base_link", "flange");
    let job = job(&dir, "cover");
    let mut rng = Rng::new(0x706f_7365_7336);
    let (mut inside, mut total) = (0usize, 0usize);
    let mut z2 = 0.0;
    let mut turn = Vec::new();
    for _ in 0..500 {
        let truth = Truth::draw(&mut rng);
        let r = fit(&job, &csv(&fk, &truth, 20, true, &mut rng));
        assert!(r.failure.is_none(), "{:?}", r.failure);
        for p in &r.parameters {
            let t = truth
                .value(&p.name)
                .unwrap_or_else(|| panic!("no truth for {}", p.name));
            let z = (p.value - t) / p.std;
            z2 += z * z;
            total += 1;
            inside += usize::from(z.abs() <= 3.0);
        }
        turn.push(r.orientation.expect("orientation errors").rms_urad);
    }
    let share = inside as f64 / total as f64;
    let rms_z = (z2 / total as f64).sqrt();
    let turn_mean = turn.iter().sum::<f64>() / turn.len() as f64;
    eprintln!(
        "poses: {inside}/{total} estimates within 3 sigma ({:.2} %), RMS of (est - truth)/sigma {rms_z:.3}, orientation RMS {turn_mean:.1} urad (noise {:.1} urad)",
        share * 100.0,
        SIGMA_RAD * 3f64.sqrt() * 1e6
    );
    assert!(share >= 0.99, "{share}");
    assert!((0.85..1.15).contains(&rms_z), "{rms_z}");
}

/// The trace of the covariance of the parameters points determine (the
/// joint zeros, the tool's translation): 30 poses determine them better
/// than 60 points, and the tool's rotation besides, which points on its
/// axis leave out.
#[test]
fn poses_need_half_the_configurations_points_need() {
    let Some(dir) = host_tests::shared_or_skip(
        "repro/ur10-offsets",
        "ur10.urdf",
        "poses_need_half_the_configurations_points_need",
    ) else {
        return;
    };
    let fk = host_tests::exact::Fk::new(&dir.join("ur10.urdf"), "base_link", "flange");
    let job = job(&dir, "half");
    let mut rng = Rng::new(0x6861_6c66);
    let truth = Truth::draw(&mut rng);
    let points = fit(&job, &csv(&fk, &truth, 60, false, &mut rng));
    let poses = fit(&job, &csv(&fk, &truth, 30, true, &mut rng));
    let named = |r: &Report| {
        r.parameters
            .iter()
            .map(|p| p.name.clone())
            .collect::<Vec<_>>()
    };
    let trace = |r: &Report| {
        (r.parameters.iter())
            .filter(|p| named(&points).contains(&p.name))
            .map(|p| p.std * p.std)
            .sum::<f64>()
    };
    eprintln!(
        "poses: trace of the covariance of what points determine, 60 points {:.4e}, 30 poses {:.4e}; points keep {:?}, poses keep {:?}",
        trace(&points),
        trace(&poses),
        named(&points),
        named(&poses)
    );
    for name in named(&points) {
        assert!(named(&poses).contains(&name), "{name}");
    }
    for name in ["tool.rx", "tool.ry", "tool.rz"] {
        assert!(named(&poses).contains(&name.to_string()), "{name}");
        assert!(!named(&points).contains(&name.to_string()), "{name}");
    }
    assert!(
        trace(&poses) <= trace(&points),
        "{} > {}",
        trace(&poses),
        trace(&points)
    );
}

/// The closed loop and the held-out error take poses: nothing is added to
/// data the declared model explains; the errors of the points (µm) leave
/// the orientations out, which are reported apart (µrad).
#[test]
fn the_closed_loop_takes_poses() {
    let Some(dir) = host_tests::shared_or_skip(
        "repro/ur10-offsets",
        "ur10.urdf",
        "the_closed_loop_takes_poses",
    ) else {
        return;
    };
    let fk = host_tests::exact::Fk::new(&dir.join("ur10.urdf"), "base_link", "flange");
    let job = job(&dir, "loop");
    let mut rng = Rng::new(0x6c6f_6f70);
    let truth = Truth::draw(&mut rng);
    let data = csv(&fk, &truth, 40, true, &mut rng);
    let data =
        parse_measurements(data.as_bytes(), "poses.csv", &job.robot, &job.setup).expect("parse");
    let r =
        calibrate::calibrate(&job, &data, &Settings::default(), &mut |_| {}).expect("calibrate");
    let o = r.orientation.expect("orientation errors");
    eprintln!(
        "poses: closed loop: {} effects, RMS {:.1} um, held-out {:?} um, orientation {o}",
        r.effects.len(),
        r.rms_um,
        r.heldout_rms_um
    );
    assert!(r.failure.is_none(), "{:?}", r.failure);
    assert_eq!(o.poses, 40);
    assert!(r.effects.is_empty(), "{:?}", r.effects.len());
    assert_eq!(r.configurations, 40);
    // The points' RMS is a point's noise (√3 · 20 µm), not mixed with rad.
    assert!((20.0..45.0).contains(&r.rms_um), "{}", r.rms_um);
    assert!(
        r.heldout_rms_um.is_some_and(|h| h > r.rms_um && h < 60.0),
        "{:?}",
        r.heldout_rms_um
    );
    assert!(o.rms_urad < 70.0 && o.nominal_rms_urad > 200.0, "{o}");
}

/// A pose file's hostile cells: a rotation vector longer than π (degrees
/// read as radians), an orientation's σ without it, two of its three
/// columns; radians read as degrees is a warning.
#[test]
fn hostile_pose_files() {
    let Some(dir) =
        host_tests::shared_or_skip("repro/ur10-offsets", "ur10.urdf", "hostile_pose_files")
    else {
        return;
    };
    let job = job(&dir, "hostile");
    let head = format!("config,{},x,y,z", JOINTS.join(","));
    let q = "0.1,-1.2,1.0,-0.5,1.4,0.3";
    let parse = |text: &str, job: &Job| {
        parse_measurements(text.as_bytes(), "poses.csv", &job.robot, &job.setup)
    };
    let err = |text: String| parse(&text, &job).expect_err("rejected").to_string();
    let e = err(format!(
        "{head},rx,ry,rz\n1,{q},1.0,0.2,0.9,90.0,10.0,-5.0\n"
    ));
    assert!(
        e.contains("more than π") && e.contains(":2") && e.contains("degrees"),
        "{e}"
    );
    let e = err(format!(
        "{head},srx,sry,srz\n1,{q},1.0,0.2,0.9,1e-5,1e-5,1e-5\n"
    ));
    assert!(e.contains("rx, ry, rz are missing"), "{e}");
    let e = err(format!("{head},rx,ry\n1,{q},1.0,0.2,0.9,0.1,0.2\n"));
    assert!(e.contains("rz") && e.contains("three columns"), "{e}");
    let e = err(format!("{head},rx,ry,rz\n1,{q},1.0,0.2,0.9,0.1,,0.2\n"));
    assert!(e.contains("empty cell"), "{e}");
    // Radians in a file whose setup says degrees: a warning, read as given.
    let mut deg = job.clone();
    deg.setup.units.angle = robcal::io::AngleUnit::Deg;
    let text =
        format!("{head},rx,ry,rz\n1,5.7,-68.8,57.3,-28.6,80.2,17.2,1.0,0.2,0.9,0.1,0.4,-0.2\n");
    let m = parse(&text, &deg).expect("read");
    assert!(
        m.warnings
            .iter()
            .any(|w| w.to_string().contains("orientations in radians")),
        "{:?}",
        m.warnings
    );
}
