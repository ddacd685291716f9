//! Compensation (issue 14): the joint command whose loaded, deflected robot
//! reaches a desired point, on data with known truth.
//!
//! The true robot is the KR-270 of `data/kr270` (link masses removed: the
//! generator does not model the robot's own weight) with a zero error on
//! every joint, its base 3 m away in a tracker frame turned by 0.5 rad, and
//! the paper's joint compliances. It is measured, unloaded and under a
//! 250 kg tool, at 40 random configurations by a tracker with 10 µm noise
//! per axis; robcal calibrates joint offsets, the base frame and the
//! compliances of a2…a6. Then 100 random targets across the workspace,
//! each the point the nominal robot would reach at a random command `q₀`
//! in the tracker frame, with a 200 kg payload:
//!
//! - uncompensated: the true robot commanded to `q₀`;
//! - geometry only: commanded to the compensation without the payload (a
//!   controller that corrects the geometry and ignores the load);
//! - compensated: commanded to `Predictor::compensate`'s `q` (from `q₀`);
//! - floor: `√trace Σₚ` of `Predictor::predict_covariance` at `q`, the
//!   error the calibration's parameter uncertainty leaves.
//!
//! The truth is `host_tests::exact` (urdf-rs, 4 × 4 matrices, successive
//! substitution for the loaded pose); nothing of robcal's model makes it.
//! `cargo test -p host-tests --release --test compensate -- --nocapture`
//! prints the table of `docs/apply.md`.

use std::fmt::Write as _;
use std::path::PathBuf;

use host_tests::arms::tracker_frame;
use host_tests::exact::Fk;
use nalgebra::{Isometry3, Point3, Rotation3, UnitQuaternion, Vector3};
use robcal::calibrate::ModelFile;
use robcal::calibrate::{self, Method, Settings};
use robcal::calibrate::{Payload, Predictor};
use robcal::io::Job;
use robcal::robot::{
    compensate, CompensateSettings, Compliances, EquilibriumSettings, Loading, PointLoad,
};
use robcal::{Chain, Error, Joint, JointKind};
use robcal_paper::rng::SplitMix64;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The KR-270 URDF without its `<inertial>` elements.
fn massless_kr270() -> String {
    let mut text = std::fs::read_to_string(root().join("data/kr270/kr270.urdf")).expect("urdf");
    while let Some(a) = text.find("<inertial>") {
        let b = text[a..].find("</inertial>").expect("closed") + a + "</inertial>".len();
        text.replace_range(a..b, "");
    }
    text
}

const MARKERS: [[f64; 3]; 3] = [
    [0.0, 0.30, 0.20],
    [-0.2598076211353315, -0.15, 0.20],
    [0.2598076211353315, -0.15, 0.20],
];
const COM: [f64; 3] = [0.25, 0.0, 0.30];
/// True compliances \[rad/(N·m)\]: Table 3 of the paper (A2 its first group).
const K: [f64; 6] = [0.0, 0.231e-6, 0.383e-6, 2.67e-6, 3.16e-6, 3.29e-6];

struct Truth {
    fk: Fk,
    offsets: Vec<f64>,
    base: Isometry3<f64>,
}

impl Truth {
    /// The true point of `marker` \[m, tip frame\] in the tracker frame when
    /// commanded to `q` with `mass_kg` at `COM`.
    fn point(&self, q: &[f64], mass_kg: f64, marker: &Vector3<f64>) -> Vector3<f64> {
        let theta: Vec<f64> = q.iter().zip(&self.offsets).map(|(a, b)| a + b).collect();
        let g = Vector3::new(0.0, 0.0, -9.80665);
        let loaded = if mass_kg > 0.0 {
            self.fk.loaded(&theta, &K, mass_kg, &Vector3::from(COM), &g)
        } else {
            theta
        };
        (self.base * Point3::from(self.fk.point(&loaded, marker))).coords
    }

    /// The true orientation of the tip frame in the tracker frame.
    fn rotation(&self, q: &[f64], mass_kg: f64) -> Rotation3<f64> {
        let theta: Vec<f64> = q.iter().zip(&self.offsets).map(|(a, b)| a + b).collect();
        let g = Vector3::new(0.0, 0.0, -9.80665);
        let loaded = if mass_kg > 0.0 {
            self.fk.loaded(&theta, &K, mass_kg, &Vector3::from(COM), &g)
        } else {
            theta
        };
        let tip = self.fk.pose(&loaded).tip;
        self.base.rotation.to_rotation_matrix()
            * Rotation3::from_matrix_unchecked(tip.fixed_view::<3, 3>(0, 0).into_owned())
    }
}

fn random_q(rng: &mut SplitMix64) -> Vec<f64> {
    vec![
        rng.range(-1.5, 1.5),
        rng.range(-1.9, -0.6),
        rng.range(-0.2, 1.8),
        rng.range(-2.0, 2.0),
        rng.range(-1.8, 1.8),
        rng.range(-3.0, 3.0),
    ]
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// One calibration and 100 compensated targets; returns the errors \[µm\]
/// (uncompensated, geometry only, compensated, floor) per target, then for
/// pose targets (position error µm, orientation error µrad uncompensated,
/// compensated).
fn run(seed: u64) -> [Vec<f64>; 7] {
    let mut rng = SplitMix64::new(seed);
    let dir = std::env::temp_dir().join(format!("robcal-compensate-{seed}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let urdf = massless_kr270();
    std::fs::write(dir.join("robot.urdf"), &urdf).expect("write");
    let mut setup = String::from(
        "robot = \"robot.urdf\"\nbase_link = \"base_link\"\ntip_link = \"tool0\"\n\
         [units]\nangle = \"rad\"\nlength = \"m\"\n",
    );
    for (i, m) in MARKERS.iter().enumerate() {
        let _ = writeln!(setup, "[[marker]]\nid = {}\nxyz = {m:?}", i + 1);
    }
    let _ = writeln!(
        setup,
        "[load]\ncom = {COM:?}\n[noise]\nsigma0_um = 10.0\n[model]\n\
         compliance = [\"a2\", \"a3\", \"a4\", \"a5\", \"a6\"]\n\
         geometry = \"joint_offsets\"\nbase_frame = true"
    );
    std::fs::write(dir.join("setup.toml"), setup).expect("write");

    let truth = Truth {
        fk: Fk::parse(&urdf, "base_link", "tool0"),
        offsets: (0..6).map(|_| rng.normal() * 1e-3).collect(),
        base: tracker_frame(&mut rng, 0.5, Vector3::new(3.0, -1.0, 0.5)),
    };
    let mut csv = String::from("config,rep,marker,load_kg,a1,a2,a3,a4,a5,a6,x,y,z\n");
    for c in 1..=40 {
        let q = random_q(&mut rng);
        let qs: Vec<String> = q.iter().map(|v| format!("{v:?}")).collect();
        for (m, marker) in MARKERS.iter().enumerate() {
            for mass in [0.0, 250.0] {
                let p = truth.point(&q, mass, &Vector3::from(*marker))
                    + Vector3::from_fn(|_, _| rng.normal() * 10e-6);
                let _ = writeln!(
                    csv,
                    "{c},1,{},{mass},{},{:?},{:?},{:?}",
                    m + 1,
                    qs.join(","),
                    p.x,
                    p.y,
                    p.z
                );
            }
        }
    }
    std::fs::write(dir.join("data.csv"), csv).expect("write");
    let job = Job::load(dir.join("setup.toml")).expect("setup");
    let data = job.read_measurements(dir.join("data.csv")).expect("data");
    let settings = Settings {
        method: Method::Ols,
        diagnose: false,
        heldout: false,
        ..Settings::default()
    };
    let report = calibrate::calibrate(&job, &data, &settings, &mut |_| {}).expect("calibrates");
    assert!(report.converged);
    let _ = std::fs::remove_dir_all(&dir);

    let nominal = Fk::parse(&urdf, "base_link", "tool0");
    let robot = Predictor::new(&report.model, &job);
    let tool = robot.marker_m(1).expect("marker 1");
    let payload = Payload {
        mass_kg: 200.0,
        com_m: Vector3::from(COM),
    };
    let m1 = Vector3::from(MARKERS[0]);
    // model.json's `predictor`, written and read back: the same robot.
    let file = ModelFile::of(&robot);
    let text = serde_json::to_string_pretty(&file).expect("json");
    let back: ModelFile = serde_json::from_str(&text).expect("reads");
    assert_eq!(back, file);
    let read = back.predictor().expect("a predictor");
    let (mut before, mut geometric, mut after, mut floor) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut pose_um, mut rot_before, mut rot_after) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..100 {
        let q0 = random_q(&mut rng);
        let target = (truth.base * Point3::from(nominal.point(&q0, &m1))).coords;
        let c = robot
            .compensate(
                &tool,
                &target,
                &q0,
                Some(&payload),
                &CompensateSettings::new(),
            )
            .expect("compensates");
        assert!(c.error_m <= 1e-7 && c.iterations <= 6, "{c:?}");
        let q = &c.q[..6];
        let (p, cov) = robot
            .predict_covariance(&tool, q, Some(&payload))
            .expect("predicts");
        assert!((p - target).norm() < 1e-7, "the model reaches the target");
        let again = read
            .predict(&read.marker_m(1).expect("marker 1"), q, Some(&payload))
            .expect("predicts");
        assert!((again - p).norm() < 1e-12, "model file: {again} vs {p}");
        before.push((truth.point(&q0, 200.0, &m1) - target).norm() * 1e6);
        let g = robot
            .compensate(&tool, &target, &q0, None, &CompensateSettings::new())
            .expect("compensates");
        geometric.push((truth.point(&g.q[..6], 200.0, &m1) - target).norm() * 1e6);
        after.push((truth.point(q, 200.0, &m1) - target).norm() * 1e6);
        floor.push(cov.trace().sqrt() * 1e6);
        // The pose: marker 1 there, the tip frame turned as the nominal
        // robot would turn it.
        let r_nominal = Rotation3::from_matrix_unchecked(
            nominal.pose(&q0).tip.fixed_view::<3, 3>(0, 0).into_owned(),
        );
        let r_target = truth.base.rotation.to_rotation_matrix() * r_nominal;
        let target_rot = UnitQuaternion::from_rotation_matrix(&r_target);
        let c = robot
            .compensate_pose(
                &tool,
                &target,
                &target_rot,
                &q0,
                Some(&payload),
                &CompensateSettings::new(),
            )
            .expect("compensates the pose");
        assert!(
            c.error_m <= 1e-7 && c.error_rad <= 1e-7 && c.iterations <= 6,
            "{c:?}"
        );
        let angle = |r: Rotation3<f64>| (r_target * r.inverse()).angle() * 1e6;
        pose_um.push((truth.point(&c.q[..6], 200.0, &m1) - target).norm() * 1e6);
        rot_before.push(angle(truth.rotation(&q0, 200.0)));
        rot_after.push(angle(truth.rotation(&c.q[..6], 200.0)));
    }
    [
        before, geometric, after, floor, pose_um, rot_before, rot_after,
    ]
}

#[test]
fn compensation_reaches_the_floor_set_by_the_parameter_uncertainty() {
    let (mut b, mut a, mut f) = (Vec::new(), Vec::new(), Vec::new());
    let (mut pu, mut rb_, mut ra_) = (Vec::new(), Vec::new(), Vec::new());
    println!("| calibration | uncompensated | geometry only | geometry + deflection | floor |");
    println!("|---|---|---|---|---|");
    for seed in 1..=4 {
        let [before, geometric, after, floor, pose_um, rot_before, rot_after] = run(seed);
        let stat = |v: &[f64]| {
            format!(
                "{:.1} / {:.1}",
                v.iter().sum::<f64>() / v.len() as f64,
                v.iter().copied().fold(0.0, f64::max)
            )
        };
        println!(
            "| seed {seed} | {} | {} | {} | {} |",
            stat(&before),
            stat(&geometric),
            stat(&after),
            stat(&floor)
        );
        assert!(rms(&geometric) >= 5.0 * rms(&after), "the payload matters");
        b.extend(before);
        a.extend(after);
        f.extend(floor);
        pu.extend(pose_um);
        rb_.extend(rot_before);
        ra_.extend(rot_after);
    }
    println!(
        "pose targets: position RMS {:.1} µm; orientation RMS {:.1} µrad uncompensated, {:.2} µrad compensated",
        rms(&pu),
        rms(&rb_),
        rms(&ra_)
    );
    assert!(rms(&pu) <= 2.0 * rms(&f), "pose position {} µm", rms(&pu));
    assert!(
        rms(&ra_) * 20.0 <= rms(&rb_),
        "orientation: {} vs {} µrad",
        rms(&ra_),
        rms(&rb_)
    );
    let (rb, ra, rf) = (rms(&b), rms(&a), rms(&f));
    println!(
        "RMS over 400 targets: uncompensated {rb:.0} µm, compensated {ra:.1} µm, floor {rf:.1} µm"
    );
    assert!(ra <= 2.0 * rf, "compensated {ra} µm vs floor {rf} µm");
    assert!(
        ra >= 0.3 * rf,
        "the floor {rf} µm is not inflated ({ra} µm)"
    );
    assert!(rb >= 20.0 * ra, "compensation matters: {rb} vs {ra} µm");
}

/// A planar 2R arm in the vertical plane (links 1 m, joint axes along y):
/// the core's compensation against the closed form of its equilibrium.
fn planar() -> Chain<f64, 3> {
    let mut c = Chain::new();
    let y = Vector3::y();
    c.push(Joint::from_urdf(Vector3::zeros(), Vector3::zeros(), y, JointKind::Revolute).unwrap())
        .unwrap();
    c.push(Joint::from_urdf(Vector3::x(), Vector3::zeros(), y, JointKind::Revolute).unwrap())
        .unwrap();
    c.set_tip(Isometry3::translation(1.0, 0.0, 0.0));
    c
}

#[test]
fn core_compensation_errors_leave_nothing_and_say_why() {
    let chain = planar();
    let loading = Loading {
        load: Some(PointLoad {
            mass_kg: 10.0,
            com_m: Vector3::zeros(),
            gravity_mps2: Vector3::new(0.0, 0.0, -9.81),
        }),
        own_weight_mps2: None,
    };
    let law = |_: &[f64]| Compliances {
        k: [1e-3, 2e-3, 0.0],
    };
    let s = CompensateSettings::new();
    let tool = Vector3::zeros();
    // A reachable point: the deflected arm reaches it, and by a closed
    // form: θ = q + k τ(θ), τ₂ = m g cos(θ₁ + θ₂)·1 m (the axes are y, the
    // tip moves in x–z).
    let target = Vector3::new(1.2, 0.0, 0.9);
    let c = compensate(&chain, &tool, &target, &[-0.3, -0.5], &loading, law, &s).expect("reaches");
    let th = c.equilibrium.frames.q();
    let p = Vector3::new(
        th[0].cos() + (th[0] + th[1]).cos(),
        0.0,
        -(th[0].sin() + (th[0] + th[1]).sin()),
    );
    assert!((p - target).norm() < 1e-7, "{p} vs {target}");
    let f = 10.0 * 9.81;
    let tau2 = f * (th[0] + th[1]).cos();
    let tau1 = tau2 + f * th[0].cos();
    assert!((th[0] - c.q[0] - 1e-3 * tau1).abs() < 1e-12);
    assert!((th[1] - c.q[1] - 2e-3 * tau2).abs() < 1e-12);

    let cases: [(Vector3<f64>, Vec<f64>, Error); 4] = [
        (
            Vector3::new(f64::NAN, 0.0, 0.0),
            vec![0.0, 0.0],
            Error::NonFinite { what: "target" },
        ),
        (
            target,
            vec![0.0],
            Error::Mismatch {
                what: "compensation start length differs from the chain's dof",
            },
        ),
        (
            target,
            vec![f64::INFINITY, 0.0],
            Error::NonFinite { what: "q_start" },
        ),
        // 3 m away from a 2 m arm.
        (
            Vector3::new(3.0, 0.0, 0.0),
            vec![0.1, 0.1],
            Error::NotConverged { iterations: 20 },
        ),
    ];
    for (t, q, e) in cases {
        let r = compensate(&chain, &tool, &t, &q, &loading, law, &s);
        assert_eq!(r.err(), Some(e), "{t} {q:?}");
    }
    // The planar arm cannot move its tip along y: the step is finite, the
    // target is not reached.
    let r = compensate(
        &chain,
        &tool,
        &Vector3::new(1.2, 0.3, 0.9),
        &[-0.3, -0.5],
        &loading,
        law,
        &s,
    );
    assert_eq!(r.err(), Some(Error::NotConverged { iterations: 20 }));
    // An equilibrium that cannot settle in its steps is the equilibrium's
    // error.
    let tight = CompensateSettings {
        equilibrium: EquilibriumSettings {
            tolerance: 0.0,
            max_iterations: 0,
        },
        ..s
    };
    let r = compensate(&chain, &tool, &target, &[-0.3, -0.5], &loading, law, &tight);
    assert_eq!(r.err(), Some(Error::NotConverged { iterations: 0 }));
}

/// A compensator table answers at any angle: the bin's value within the
/// bin tolerance, linear between two calibrated angles, held at its ends.
#[test]
fn compensator_table_interpolates_between_its_angles() {
    use robcal::calibrate::{DeflectionModel, Linearisation, Names};
    use robcal::model::{angle_urad, Param};
    let names = Names {
        joints: vec!["a1".into(), "a2".into()],
        kinds: vec![JointKind::Revolute; 2],
        markers: vec![(1, Vector3::zeros())],
        bins: Default::default(),
    };
    let at = |deg: f64| Param::ComplianceAt {
        joint: 1,
        angle_urad: angle_urad(deg.to_radians()),
    };
    // 1 and 3 urad/(N*m) at -90 and -30 degrees, a constant 0.5 on top.
    let params = [Param::Compliance { joint: 1 }, at(-90.0), at(-30.0)];
    let lin = Linearisation::of(DeflectionModel::Exact, &params, &[0.5, 1.0, 3.0], &names);
    let k = |deg: f64| lin.compliance_at(&[0.0, deg.to_radians()])[1] * 1e6;
    // Bin angles are kept in whole µrad.
    let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
    assert!(close(k(-90.0), 1.5) && close(k(-30.0), 3.5));
    assert!(
        close(k(-90.0 + 0.05), 1.5),
        "within the bin tolerance: the bin"
    );
    assert!(
        close(k(-60.0), 2.5) && close(k(-45.0), 3.0),
        "linear between: {} {}",
        k(-60.0),
        k(-45.0)
    );
    assert!(
        close(k(-120.0), 1.5) && close(k(10.0), 3.5),
        "held at the ends"
    );
    assert!(lin.interpolated(&[0.0, (-90f64).to_radians()]).is_empty());
    assert_eq!(lin.interpolated(&[0.0, (-60f64).to_radians()]), vec![1]);
}
