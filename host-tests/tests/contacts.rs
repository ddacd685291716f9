//! Plane contacts and distances (issue 53, item 2): a KR-270 whose joint
//! zeros are off, measured without a tracker — its probe touching planes
//! fixed in the world, or its distance from an anchor read by a draw-wire
//! sensor. The generator (`host_tests::contacts`) shares no code with the
//! estimator.

use host_tests::contacts::{csv, Target};
use host_tests::poses::{Arm, Truth};
use nalgebra::Vector3;
use robcal::calibrate::{self, Report, Settings};
use robcal::io::{parse_measurements, Job};
use robcal_paper::rng::SplitMix64 as Rng;

/// A touch probe's or a draw-wire sensor's σ \[m\].
const SIGMA_M: f64 = 10e-6;

/// The KR-270 of `data/kr270`, its probe as the one marker, the setup's
/// planes and anchors `targets`; joint zeros and the base frame declared.
fn kr270(targets: &[Target]) -> (Arm, Job) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/kr270");
    let arm = Arm::kr270(&dir);
    let m = arm.marker_m;
    let mut text = format!(
        "robot = {:?}\nbase_link = \"base_link\"\ntip_link = \"tool0\"\n\
         [units]\nangle = \"rad\"\nlength = \"m\"\n\
         [[marker]]\nid = 1\nxyz = [{}, {}, {}]\n",
        dir.join("kr270.urdf").display().to_string(),
        m.x,
        m.y,
        m.z
    );
    for t in targets {
        text += &match t {
            Target::Plane(id, n, d) => format!(
                "[[plane]]\nid = {id}\nnormal = [{}, {}, {}]\noffset_m = {d}\n",
                n.x, n.y, n.z
            ),
            Target::Anchor(id, c) => {
                format!("[[anchor]]\nid = {id}\nxyz = [{}, {}, {}]\n", c.x, c.y, c.z)
            }
        };
    }
    text += "[noise]\nsigma0_um = 10.0\n[model]\ngeometry = \"joint_offsets\"\nbase_frame = true\n";
    // One file per call: the tests run side by side in one process.
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let k = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path =
        std::env::temp_dir().join(format!("robcal-contacts-{}-{k}.toml", std::process::id()));
    std::fs::write(&path, text).expect("setup");
    let job = Job::load(&path).expect("setup");
    let _ = std::fs::remove_file(&path);
    (arm, job)
}

/// Joint zeros within ±1 mrad but the first and the last joints' (0: the
/// first turns the robot about the base's z axis, as the base's turn does,
/// and the model leaves it out, whatever the data; the last, the probe's
/// turn about the flange's axis, is `Truth::draw`'s 0), no tool error.
fn truth(rng: &mut Rng) -> Truth {
    let mut t = Truth::draw(rng, 6);
    t.offsets[0] = 0.0;
    t.tool_t = Vector3::zeros();
    t.tool_r = Vector3::zeros();
    t
}

fn fit(job: &Job, text: &str) -> Report {
    let data =
        parse_measurements(text.as_bytes(), "contacts.csv", &job.robot, &job.setup).expect("parse");
    let settings = Settings {
        diagnose: false,
        heldout: false,
        ..Settings::default()
    };
    calibrate::calibrate(job, &data, &settings, &mut |_| {}).expect("calibrate")
}

/// The truth of a reported parameter: a joint zero \[mrad\], or the base
/// frame's pose (the planes and anchors are given where they are: 0).
fn truth_of(arm: &Arm, truth: &Truth, name: &str) -> f64 {
    if name.starts_with("base.") {
        return 0.0;
    }
    truth
        .value(arm, name)
        .unwrap_or_else(|| panic!("no truth for {name}"))
}

/// The estimates of many jobs against their truths.
#[derive(Default)]
struct Tally {
    /// Estimates within ±3 σ of the truth.
    inside: usize,
    /// Estimates.
    total: usize,
    /// Σ ((estimate − truth)/σ)².
    z2: f64,
}

impl Tally {
    /// Adds the estimates of `r`, a job of the truth `truth`.
    fn add(&mut self, arm: &Arm, truth: &Truth, r: &Report) {
        assert!(r.failure.is_none(), "{:?}", r.failure);
        for p in &r.parameters {
            let z = (p.value - truth_of(arm, truth, &p.name)) / p.std;
            self.z2 += z * z;
            self.total += 1;
            self.inside += usize::from(z.abs() <= 3.0);
        }
    }

    /// The share within ±3 σ and the RMS of (estimate − truth)/σ.
    fn of(&self) -> (f64, f64) {
        let n = self.total as f64;
        (self.inside as f64 / n, (self.z2 / n).sqrt())
    }
}

/// Over `jobs` jobs of `n` rows: the share of estimates within ±3 σ of
/// the truth, the RMS of (estimate − truth)/σ, and the last job's report.
fn coverage(targets: &[Target], n: usize, jobs: usize, seed: u64) -> (f64, f64, Report) {
    let (arm, job) = kr270(targets);
    let mut rng = Rng::new(seed);
    let mut tally = Tally::default();
    let mut last = None;
    for _ in 0..jobs {
        let truth = truth(&mut rng);
        let r = fit(&job, &csv(&arm, &truth, targets, SIGMA_M, n, &mut rng));
        tally.add(&arm, &truth, &r);
        last = Some(r);
    }
    let (share, rms_z) = tally.of();
    (share, rms_z, last.expect("a job"))
}

/// The floor and two walls of a corner.
fn corner() -> [Target; 3] {
    [
        Target::Plane(1, Vector3::z(), 0.4),
        Target::Plane(2, Vector3::x(), 1.6),
        Target::Plane(3, Vector3::y(), 1.0),
    ]
}

/// One file of the points of `points` (`host_tests::poses::csv`, without
/// orientations) and the first `contacts` rows of `text` (`csv`): a
/// point's contact cells empty, a contact's point cells empty, the
/// contacts' configurations after the points'.
fn beside_points(arm: &Arm, points: &str, text: &str, contacts: usize) -> String {
    let mut out = format!(
        "config,{},x,y,z,sx,sy,sz,plane,anchor,distance,sd\n",
        arm.joints.join(",")
    );
    for line in points.lines().skip(1) {
        out += &format!("{line},,,,\n");
    }
    for line in text.lines().skip(1).take(contacts) {
        let (config, rest) = line.split_once(',').expect("config");
        let cells: Vec<&str> = rest.split(',').collect();
        let (q, contact) = cells.split_at(6);
        let config: usize = config.parse().expect("config");
        out += &format!(
            "{},{},,,,,,,{}\n",
            config + 100,
            q.join(","),
            contact.join(",")
        );
    }
    out
}

fn left_out(r: &Report) -> Vec<String> {
    let mut v: Vec<String> = r.left_out.iter().map(|l| l.name.clone()).collect();
    v.sort();
    v
}

/// Over 500 jobs of 60 rows each: a KR-270's probe touching a floor, a
/// corner of three planes, or its distance from an anchor (a draw-wire
/// sensor), 10 µm. Every estimate within ±3 σ of the truth in ≥ 99 % of
/// the cases, the σ neither optimistic nor pessimistic; the report names
/// what each cannot tell (a plane nothing of a shift along it or a turn
/// about its normal, an anchor nothing of a turn about it; the first
/// joint's zero is the base's turn about z in every case), and does not
/// claim that other poses would tell it.
#[test]
fn contacts_and_distances_cover_the_truth_and_name_what_they_cannot_tell() {
    let floor = Target::Plane(1, Vector3::z(), 0.4);
    let wall = Target::Plane(2, Vector3::x(), 1.6);
    let side = Target::Plane(3, Vector3::y(), 1.0);
    let anchor = Target::Anchor(1, Vector3::new(1.5, 0.5, 0.3));
    let cases: [(&str, Vec<Target>, &[&str]); 3] = [
        (
            "floor",
            vec![floor],
            &["a1.offset", "base.rz", "base.tx", "base.ty"],
        ),
        ("corner", vec![floor, wall, side], &["a1.offset"]),
        (
            "anchor",
            vec![anchor],
            &["a1.offset", "base.rx", "base.ry", "base.rz"],
        ),
    ];
    for (what, targets, cannot) in cases {
        let (share, rms_z, r) = coverage(&targets, 60, 500, 0x636f_6e74);
        eprintln!(
            "contacts: {what}: {:.2} % of the estimates within 3 sigma over 500 jobs, RMS of \
             (est - truth)/sigma {rms_z:.3}; left out {:?}",
            share * 100.0,
            left_out(&r)
        );
        assert!(share >= 0.99, "{what}: {share}");
        assert!((0.9..1.1).contains(&rms_z), "{what}: {rms_z}");
        assert_eq!(left_out(&r), cannot, "{what}");
        assert!(
            r.warnings.iter().all(|w| !w.contains("would identify")),
            "{what}: {:?}",
            r.warnings
        );
        let s = r.scalars.as_ref().expect("the contacts' errors");
        assert_eq!(s.rows, 60);
        assert_eq!(r.equations, 60, "{what}: one equation a row");
        assert!((5.0..20.0).contains(&s.rms_um), "{what}: {s:?}");
        assert_eq!(
            r.rms_um, s.rms_um,
            "{what}: no points: their errors are the RMS"
        );
    }
}

/// The held-out error of distances alone (OLS and the default method):
/// each configuration's distance predicted by a calibration without it —
/// its model's point (`Predictor`) at the row's joint values, its distance
/// from the anchor against the measured one.
#[test]
fn heldout_of_distances_is_the_refits_without_each() {
    let c = Vector3::new(1.5, 0.5, 0.3);
    let targets = [Target::Anchor(1, c)];
    let (arm, job) = kr270(&targets);
    let mut rng = Rng::new(0x686f_6c64);
    let truth = truth(&mut rng);
    let text = csv(&arm, &truth, &targets, SIGMA_M, 16, &mut rng);
    let (header, body) = text.split_once('\n').expect("header");
    let rows: Vec<&str> = body.lines().collect();
    let read = |keep: &dyn Fn(usize) -> bool| {
        let mut t = format!("{header}\n");
        for (_, line) in rows.iter().enumerate().filter(|(k, _)| keep(*k)) {
            t += line;
            t.push('\n');
        }
        parse_measurements(t.as_bytes(), "contacts.csv", &job.robot, &job.setup).expect("parse")
    };
    for method in [calibrate::Method::Ols, Settings::default().method] {
        let settings = Settings {
            method,
            diagnose: false,
            heldout: true,
            ..Settings::default()
        };
        let all = calibrate::calibrate(&job, &read(&|_| true), &settings, &mut |_| {})
            .expect("calibrate");
        let heldout = all.heldout_rms_um.expect("held-out RMS");
        let refit = Settings {
            heldout: false,
            ..settings
        };
        let mut sq = 0.0;
        for (k, line) in rows.iter().enumerate() {
            let others = calibrate::calibrate(&job, &read(&|i| i != k), &refit, &mut |_| {})
                .expect("calibrate without one row");
            let cells: Vec<f64> = line
                .split(',')
                .map(|c| c.parse().unwrap_or(f64::NAN))
                .collect();
            let q = &cells[1..7];
            let measured = cells[9];
            let robot = robcal::calibrate::outputs::predict::Predictor::new(&others.model, &job);
            let p = robot.predict_marker(0, q, None).expect("predict");
            sq += ((p - c).norm() - measured).powi(2);
        }
        let reference = (sq / rows.len() as f64).sqrt() * 1e6;
        eprintln!(
            "contacts: held-out RMS ({method:?}) {heldout:.3} um, by refits without each row \
             {reference:.3} um, fit {:.3} um",
            all.rms_um
        );
        assert!(
            (heldout / reference - 1.0).abs() < 0.001,
            "{method:?}: {heldout} vs {reference}"
        );
        assert!(heldout > all.rms_um, "{method:?}");
    }
}

/// Plane contacts beside tracker points (one file, each row one or the
/// other): over 200 jobs of 15 points and 45 contacts with a corner of
/// three planes, the estimates cover the truth; the points' errors are of
/// the points, the contacts' reported apart.
#[test]
fn contacts_mixed_with_points_cover_the_truth() {
    let targets = corner();
    let (arm, job) = kr270(&targets);
    let mut rng = Rng::new(0x6d69_7865);
    let instrument = host_tests::poses::Instrument {
        sigma_m: 20e-6,
        sigma_rad: 0.0,
    };
    let mut tally = Tally::default();
    let mut last = None;
    for _ in 0..200 {
        let truth = truth(&mut rng);
        let points = host_tests::poses::csv(&arm, &truth, instrument, 15, false, &mut rng);
        let contacts = csv(&arm, &truth, &targets, SIGMA_M, 45, &mut rng);
        let r = fit(&job, &beside_points(&arm, &points, &contacts, 45));
        tally.add(&arm, &truth, &r);
        last = Some(r);
    }
    let (share, rms_z) = tally.of();
    let r = last.expect("a job");
    eprintln!(
        "contacts: with points: {:.2} % within 3 sigma over 200 jobs, RMS z {rms_z:.3}; {} \
         configurations of points, RMS {:.1} um; contacts {:?}",
        share * 100.0,
        r.configurations,
        r.rms_um,
        r.scalars
    );
    assert!(share >= 0.99, "{share}");
    assert!((0.9..1.1).contains(&rms_z), "{rms_z}");
    assert_eq!(r.configurations, 15);
    assert_eq!(r.equations, 15 * 3 + 45);
    assert_eq!(r.scalars.as_ref().map(|s| s.rows), Some(45));
    assert_eq!(left_out(&r), ["a1.offset"]);
}

/// Hostile plane-contact and distance files and setups: each a one-line
/// error naming the line and the column (or the setup's key).
#[test]
fn hostile_contact_files() {
    let targets = [
        Target::Plane(1, Vector3::z(), 0.4),
        Target::Anchor(2, Vector3::new(1.5, 0.5, 0.3)),
    ];
    let (arm, job) = kr270(&targets);
    let q = "0.1,-1.2,1.0,-0.5,1.4,0.3";
    let head = format!("config,{}", arm.joints.join(","));
    let parse = |text: &str| parse_measurements(text.as_bytes(), "c.csv", &job.robot, &job.setup);
    let err = |text: String| parse(&text).expect_err("rejected").to_string();
    // Read: a contact, a distance, a point, each its own.
    let m = parse(&format!(
        "{head},x,y,z,plane,anchor,distance,sd\n1,{q},,,,1,,,1e-5\n2,{q},,,,,2,1.25,1e-5\n\
         3,{q},1.0,0.2,0.9,,,,\n"
    ))
    .expect("read");
    let kinds: Vec<Option<f64>> = (m.observations.iter())
        .map(|o| o.scalar.map(|s| s.value_m()))
        .collect();
    assert_eq!(kinds, [Some(0.0), Some(1.25), None]);
    assert_eq!(m.observations[1].sigma_m, Some([1e-5, 0.0, 0.0]));
    for (text, want) in [
        (
            format!("{head},plane\n1,{q},9\n"),
            ["plane 9 is not declared", "'plane'"],
        ),
        (
            format!("{head},anchor,distance\n1,{q},7,1.0\n"),
            ["anchor 7 is not declared", "'anchor'"],
        ),
        (
            format!("{head},anchor,distance\n1,{q},2,\n"),
            ["empty cell", "'distance'"],
        ),
        (
            format!("{head},anchor,distance\n1,{q},2,-0.5\n"),
            ["not negative", ":2"],
        ),
        (
            format!("{head},anchor,distance\n1,{q},2,1250\n"),
            ["millimetres", "'distance'"],
        ),
        (
            format!("{head},plane,anchor,distance\n1,{q},1,2,1.0\n"),
            ["not both", ":2"],
        ),
        (
            format!("{head},x,y,z,plane\n1,{q},1.0,0.2,0.9,1\n"),
            ["one number, not a point", "'x'"],
        ),
        (
            format!("{head},x,y,z,plane\n1,{q},,,,\n"),
            ["empty cell", "'x'"],
        ),
        (
            format!("{head},anchor\n1,{q},2\n"),
            ["distance is missing", "distance"],
        ),
        (
            format!("{head},x,y,z,distance\n1,{q},1.0,0.2,0.9,2\n"),
            ["anchor is missing", "anchor"],
        ),
        (
            format!("{head},x,y,z,sd\n1,{q},1.0,0.2,0.9,1e-5\n"),
            ["plane and anchor are missing", "sd"],
        ),
        (
            format!("{head},x,y,plane\n1,{q},1.0,0.2,1\n"),
            ["three columns x, y, z", "'z'"],
        ),
        (
            format!("{head},plane,distance,anchor\n1,{q},,0.1,\n"),
            ["without an anchor", "'distance'"],
        ),
    ] {
        let e = err(text);
        assert!(want.iter().all(|w| e.contains(w)), "{want:?}: {e}");
        assert_eq!(e.lines().count(), 1, "{e}");
    }
    // Fewer numbers than parameters: each contact is one equation.
    let truth = truth(&mut Rng::new(3));
    let few = csv(&arm, &truth, &targets[..1], SIGMA_M, 8, &mut Rng::new(4));
    let data = parse(&few).expect("read");
    let e = calibrate::calibrate(&job, &data, &Settings::default(), &mut |_| {})
        .expect_err("too few")
        .to_string();
    assert!(e.contains("8 row(s) give 8 equations"), "{e}");
    // The setup's planes and anchors.
    for (extra, want) in [
        ("[[plane]]\nid = 1\nnormal = [0.0, 0.0, 0.0]\n", "has no direction"),
        (
            "[[plane]]\nid = 1\nnormal = [0.0, 0.0, 1.0]\n[[plane]]\nid = 1\nnormal = [1.0, 0.0, 0.0]\n",
            "also plane[0]",
        ),
        ("[[anchor]]\nid = 1\nxyz = [nan, 0.0, 0.0]\n", "anchor"),
        ("[[plane]]\nid = 1\n", "normal"),
    ] {
        let text = format!("robot = \"r.urdf\"\n{extra}");
        let e = robcal::io::Setup::parse(&text, "s.toml")
            .expect_err("rejected")
            .to_string();
        assert!(e.contains(want), "{want}: {e}");
    }
}

/// `--validate` on plane contacts: the calibrated model's point's number
/// against each measured one. On the calibration's own contacts it gives
/// the report's error; on 200 new contacts of the same robot, the
/// instrument's noise (10 µm) and what the estimates' σ add; in a file
/// with points, the points are the validation's errors and the contacts
/// apart.
#[test]
fn validation_of_contacts() {
    let targets = corner();
    let (arm, job) = kr270(&targets);
    let mut rng = Rng::new(0x7661_6c69);
    let truth = truth(&mut rng);
    let parse = |text: &str| {
        parse_measurements(text.as_bytes(), "contacts.csv", &job.robot, &job.setup).expect("parse")
    };
    let training = csv(&arm, &truth, &targets, SIGMA_M, 60, &mut rng);
    let r = fit(&job, &training);
    let fitted = r.scalars.as_ref().expect("the contacts' errors").rms_um;
    let own = calibrate::validate(&r.model, &job, &parse(&training)).expect("validate");
    let s = own.scalars.expect("contacts validated");
    eprintln!("contacts: validation on the training contacts {s:?}, the fit's RMS {fitted:.3} um");
    assert_eq!((s.rows, own.points), (60, 60));
    assert!(
        (s.rms_um / fitted - 1.0).abs() < 0.01,
        "{} vs {fitted}",
        s.rms_um
    );
    assert!(
        (own.rms_mm * 1e3 - s.rms_um).abs() < 1e-9,
        "no points: they are the errors"
    );
    assert!(own.reregistration.is_none());
    let new = csv(&arm, &truth, &targets, SIGMA_M, 200, &mut rng);
    let v = calibrate::validate(&r.model, &job, &parse(&new)).expect("validate");
    let s = v.scalars.expect("contacts validated");
    eprintln!("contacts: validation on 200 new contacts {s:?}");
    assert_eq!(s.rows, 200);
    assert!((9.0..13.0).contains(&s.rms_um), "{s:?}");
    // Beside points: the points are the errors, the contacts apart.
    let instrument = host_tests::poses::Instrument {
        sigma_m: 20e-6,
        sigma_rad: 0.0,
    };
    let points = host_tests::poses::csv(&arm, &truth, instrument, 10, false, &mut rng);
    let text = beside_points(&arm, &points, &new, 20);
    let v = calibrate::validate(&r.model, &job, &parse(&text)).expect("validate");
    assert_eq!(v.points, 10);
    assert_eq!(v.scalars.map(|s| s.rows), Some(20));
    assert!(v.rms_mm > 0.015 && v.rms_mm < 0.06, "{}", v.rms_mm);
}

/// `--robust` with plane contacts: of 60 corner contacts, the 12th's
/// probe fired 1 mm off the plane (100 σ). The robust loss weights that
/// contact down, on its one axis, and leaves the others; every estimate
/// is then within 3 σ of the truth, with σ less than half the plain
/// fit's, which the misfire widens.
#[test]
fn the_robust_loss_weighs_a_misfired_contact_down() {
    let targets = corner();
    let (arm, job) = kr270(&targets);
    let mut rng = Rng::new(0x6d69_7366);
    let truth = truth(&mut rng);
    let text = csv(&arm, &truth, &targets, SIGMA_M, 60, &mut rng);
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let mut cells: Vec<String> = lines[12].split(',').map(String::from).collect();
    let distance = cells.len() - 2;
    cells[distance] = "0.001".into();
    let config = cells[0].clone();
    lines[12] = cells.join(",");
    let data = parse_measurements(
        (lines.join("\n") + "\n").as_bytes(),
        "contacts.csv",
        &job.robot,
        &job.setup,
    )
    .expect("parse");
    let worst = |r: &Report| {
        (r.parameters.iter())
            .map(|p| ((p.value - truth_of(&arm, &truth, &p.name)) / p.std).abs())
            .fold(0.0, f64::max)
    };
    let mut fits = Vec::new();
    for robust in [false, true] {
        let settings = Settings {
            diagnose: false,
            heldout: false,
            robust,
            ..Settings::default()
        };
        let r = calibrate::calibrate(&job, &data, &settings, &mut |_| {}).expect("calibrate");
        eprintln!(
            "contacts: robust {robust}: largest |z| {:.2}; {:?}",
            worst(&r),
            r.notes.iter().find(|n| n.starts_with("robust loss"))
        );
        fits.push(r);
    }
    // The plain fit's σ take the misfire in (the sandwich's middle term):
    // its estimates are pulled, and its σ wide; the robust fit's are
    // neither.
    let spread = |r: &Report| r.parameters.iter().map(|p| p.std).sum::<f64>();
    let (plain, robust) = (spread(&fits[0]), spread(&fits[1]));
    eprintln!("contacts: sum of sigma plain {plain:.4}, robust {robust:.4}");
    assert!(robust < 0.5 * plain, "{robust} vs {plain}");
    assert!(worst(&fits[1]) < 3.0, "the robust fit is not pulled");
    let note = (fits[1].notes.iter())
        .find(|n| n.starts_with("robust loss"))
        .expect("the robust note");
    assert!(
        note.contains(&format!("config {config} marker 1 (contact or distance")),
        "{note}"
    );
    assert!(note.contains("1 of 60 row(s) weighted down"), "{note}");
}

/// A pivot (a ball held in a fixed cup while the robot turns about it),
/// written as points all at the pivot: over 200 jobs of 40 rows (10 µm)
/// the estimates cover the truth; the base's turn about the pivot is not
/// fitted and reported left out, the first joint's zero with it, and
/// nothing says other poses would identify them or that the points barely
/// move.
#[test]
fn a_pivot_identifies_the_joint_zeros_and_where_the_robot_is() {
    let c = Vector3::new(1.8, 0.4, 0.6);
    let (arm, job) = kr270(&[]);
    let mut rng = Rng::new(0x7069_766f);
    let mut tally = Tally::default();
    let mut last = None;
    for _ in 0..200 {
        let truth = truth(&mut rng);
        let text = host_tests::contacts::pivot_csv(&arm, &truth, c, SIGMA_M, 40, &mut rng);
        let r = fit(&job, &text);
        tally.add(&arm, &truth, &r);
        last = Some(r);
    }
    let (share, rms_z) = tally.of();
    let r = last.expect("a job");
    eprintln!(
        "contacts: pivot: {:.2} % within 3 sigma over 200 jobs, RMS z {rms_z:.3}; left out {:?}; \
         warnings {:?}",
        share * 100.0,
        left_out(&r),
        r.warnings
    );
    assert!(share >= 0.99, "{share}");
    assert!((0.9..1.1).contains(&rms_z), "{rms_z}");
    assert_eq!(left_out(&r), ["a1.offset", "base.rx", "base.ry", "base.rz"]);
    assert!(
        r.warnings
            .iter()
            .all(|w| !w.contains("would identify") && !w.contains("barely")),
        "{:?}",
        r.warnings
    );
}
