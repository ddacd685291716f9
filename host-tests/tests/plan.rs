//! `robcal plan` measured (issue 54): the UR10 of `shared/repro` in a cell
//! of ±0.5 rad per joint, full geometry, 20 µm tracker noise.
//!
//! The poses are robcal's plan (D-optimal from 1 000 random candidates);
//! the measurements come from `arms::Truth` (its own forward kinematics on
//! the URDF text, every joint's zero off and the tracker elsewhere) and the
//! random poses from this file's own draws: nothing of the comparison is
//! robcal's but the plan and the calibration it judges. Over six
//! recordings per design, the planned `K` poses against `K` and `2K`
//! random ones: the trace of the reported covariance and the error of the
//! calibrated model on 300 noise-free poses of the cell.

use std::path::PathBuf;

use host_tests::arms::UR10_JOINTS as JOINTS;
use nalgebra::Vector3;
use robcal::calibrate::outputs::validate::validate;
use robcal::calibrate::plan::{choose, pool, random_candidates, Criterion, PlanSettings};
use robcal::calibrate::{self, Method, Settings};
use robcal::io::{parse_measurements, Job};
use robcal_paper::rng::SplitMix64;

const RANGE: f64 = 0.5;
const REPS: u64 = 20;
const TEST_POSES: usize = 300;

fn shared() -> Option<PathBuf> {
    let s = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared");
    if s.is_dir() {
        return Some(s);
    }
    if std::env::var_os("ROBCAL_REQUIRE_SHARED").is_some_and(|v| v == "1") {
        panic!("shared/ not found, and ROBCAL_REQUIRE_SHARED=1 (CI) requires it");
    }
    None
}

/// Trace of the reported covariance (Σ σ², reported units) and the error
/// of the calibrated model on the test poses \[µm\], of a recording at
/// `poses` (seed `seed`).
fn judge(
    job: &Job,
    truth: &host_tests::arms::Truth,
    poses: &[Vec<f64>],
    test: &str,
    seed: u64,
) -> (f64, f64, Vec<String>) {
    let joints: Vec<String> = JOINTS.map(String::from).to_vec();
    let mut rng = SplitMix64::new(seed);
    let csv = truth.csv(&joints, poses, &mut rng);
    let data = parse_measurements(csv.as_bytes(), "recording.csv", &job.robot, &job.setup).unwrap();
    let settings = Settings {
        method: Method::Ols,
        diagnose: false,
        heldout: false,
        ..Settings::default()
    };
    let r = calibrate::calibrate(job, &data, &settings, &mut |_| {}).expect("calibrate");
    let test = parse_measurements(test.as_bytes(), "test.csv", &job.robot, &job.setup).unwrap();
    let v = validate(&r.model, job, &test).expect("validate");
    let trace = r.parameters.iter().map(|p| p.std * p.std).sum();
    let names = r.parameters.iter().map(|p| p.name.clone()).collect();
    (trace, v.rms_mm * 1e3, names)
}

#[test]
fn planned_poses_determine_the_ur10_as_well_as_twice_as_many_random_ones() {
    let Some(shared) = shared() else {
        eprintln!("skipped: shared/repro is not beside the repository");
        return;
    };
    let dir = shared.join("repro/ur10-offsets");
    let job = Job::load(dir.join("setup-full.toml")).expect("setup");
    let mut rng = SplitMix64::new(0x706c_616e_5552);
    let truth = host_tests::arms::Truth {
        fk: host_tests::exact::Fk::new(&dir.join("ur10.urdf"), "base_link", "flange"),
        offsets: (0..6).map(|_| rng.range(-2e-3, 2e-3)).collect(),
        base: host_tests::arms::tracker_frame(&mut rng, 0.7, Vector3::new(2.0, -1.0, 0.3)),
        markers: vec![Vector3::new(0.0, 0.0, 0.1)],
        noise_m: 20e-6,
    };
    let draw = |rng: &mut SplitMix64, n: usize| -> Vec<Vec<f64>> {
        (0..n)
            .map(|_| (0..6).map(|_| rng.range(-RANGE, RANGE)).collect())
            .collect()
    };
    let test = {
        let exact = host_tests::arms::Truth {
            noise_m: 0.0,
            fk: host_tests::exact::Fk::new(&dir.join("ur10.urdf"), "base_link", "flange"),
            offsets: truth.offsets.clone(),
            base: truth.base,
            markers: truth.markers.clone(),
        };
        let q = draw(&mut rng, TEST_POSES);
        exact.csv(&JOINTS.map(String::from), &q, &mut rng)
    };
    let settings = PlanSettings {
        limits: JOINTS
            .iter()
            .map(|j| (j.to_string(), -RANGE, RANGE))
            .collect(),
        ..PlanSettings::default()
    };
    let candidates = random_candidates(&job, &settings).unwrap();
    let p = pool(&job, candidates, None, &Default::default()).unwrap();
    let mut table = String::from(
        "| K | trace: D plan | I plan | condition plan | K random | 2K random | error µm: D plan | I plan | condition plan | K random | 2K random |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut ratios = Vec::new();
    for k in [15, 30, 60] {
        let q_of = |c: Criterion| -> Vec<Vec<f64>> {
            let planned = choose(&p, k, c, 10).unwrap();
            (planned.chosen.iter())
                .map(|&c| p.candidates[c].q.clone())
                .collect()
        };
        let (plan_q, i_q, condition_q) = (
            q_of(Criterion::D),
            q_of(Criterion::I),
            q_of(Criterion::Condition),
        );
        let mut sums = [[0.0; 2]; 5];
        for rep in 0..REPS {
            let seed = 1000 * k as u64 + rep;
            let mut own = SplitMix64::new(seed ^ 0xdead_beef);
            let designs = [
                plan_q.clone(),
                i_q.clone(),
                condition_q.clone(),
                draw(&mut own, k),
                draw(&mut own, 2 * k),
            ];
            let mut names = None;
            for (i, q) in designs.iter().enumerate() {
                let (trace, err, n) = judge(&job, &truth, q, &test, seed);
                // The same parameters in every design, or the traces do
                // not compare.
                assert_eq!(names.get_or_insert(n.clone()), &n, "K {k}, design {i}");
                sums[i][0] += trace / REPS as f64;
                sums[i][1] += err / REPS as f64;
            }
        }
        table += &format!(
            "| {k} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |\n",
            sums[0][0],
            sums[1][0],
            sums[2][0],
            sums[3][0],
            sums[4][0],
            sums[0][1],
            sums[1][1],
            sums[2][1],
            sums[3][1],
            sums[4][1]
        );
        ratios.push((k, sums));
    }
    println!("{table}");
    // Columns: 0 D plan, 1 I plan, 2 condition plan, 3 K random, 4 2K
    // random; [trace, error].
    for (k, s) in ratios {
        assert!(
            s[0][1] < 0.8 * s[3][1],
            "K {k}: D plan against K random\n{table}"
        );
        assert!(
            s[0][1] < s[2][1],
            "K {k}: D plan against the condition number's\n{table}"
        );
        if k <= 30 {
            assert!(
                s[0][1] <= 1.05 * s[4][1],
                "K {k}: D plan against 2K random\n{table}"
            );
        }
    }
}

/// The KR-270's compliances (the paper's model, A2's as one: a plan does
/// not know the angles a compensator's bins will be) under a 250 kg
/// payload, 10 µm noise per axis, three markers. The deflections come from
/// `exact::Fk::loaded` (the load on the deflected robot, its own
/// equilibrium solve) at robcal's planned configurations and at this
/// file's random ones within the URDF's limits; the error is that of the
/// calibrated model's deflections at 300 noise-free random configurations.
#[test]
fn planned_payload_poses_determine_the_kr270_compliances_as_well_as_twice_as_many_random_ones() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let text = std::fs::read_to_string(root.join("data/kr270/setup.toml")).unwrap();
    assert!(text.contains("compliance_by_angle = [\"a2\"]\n"));
    let text = text
        .replace("compliance_by_angle = [\"a2\"]\n", "")
        .replace(
            "robot = \"kr270.urdf\"",
            &format!(
                "robot = {:?}",
                root.join("data/kr270/kr270.urdf").display().to_string()
            ),
        );
    let d = std::env::temp_dir().join(format!("robcal-plan-kr270-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    std::fs::write(d.join("setup.toml"), text).unwrap();
    let job = Job::load(d.join("setup.toml")).expect("setup");
    let kr = host_tests::exact::Kr270::new();
    // Table 3's WLS compliances of the first configuration, one per joint.
    let k = host_tests::exact::Kr270::compliance(0);
    let markers: Vec<Vector3<f64>> = job
        .setup
        .markers
        .iter()
        .map(|m| Vector3::from(m.xyz))
        .collect();
    let com = Vector3::from(job.setup.load.unwrap().com);
    let g = Vector3::new(0.0, 0.0, -9.80665);
    const LOAD_KG: f64 = 250.0;
    let csv = |poses: &[Vec<f64>], rng: &mut SplitMix64, sigma_m: f64| -> String {
        let mut out = String::from("config,rep,marker,load_kg,a1,a2,a3,a4,a5,a6,x,y,z\n");
        for (c, q) in poses.iter().enumerate() {
            let theta = kr.fk().loaded(q, &k, LOAD_KG, &com, &g);
            let (unloaded, loaded) = (kr.fk().pose(q), kr.fk().pose(&theta));
            let q_deg: Vec<String> = q.iter().map(|v| format!("{:?}", v.to_degrees())).collect();
            for (mi, m) in markers.iter().enumerate() {
                for (mass, pose) in [(0.0, &unloaded), (LOAD_KG, &loaded)] {
                    let p = pose.point(m) + Vector3::from_fn(|_, _| rng.normal() * sigma_m);
                    out += &format!(
                        "{},1,{},{mass},{},{:?},{:?},{:?}\n",
                        c + 1,
                        mi + 1,
                        q_deg.join(","),
                        p.x * 1e3,
                        p.y * 1e3,
                        p.z * 1e3
                    );
                }
            }
        }
        out
    };
    let limits: Vec<(f64, f64)> = job
        .robot
        .limits
        .iter()
        .map(|l| l.map(|l| (l.lower, l.upper)).expect("the KR-270's limits"))
        .collect();
    let draw = |rng: &mut SplitMix64, n: usize| -> Vec<Vec<f64>> {
        (0..n)
            .map(|_| limits.iter().map(|&(lo, hi)| rng.range(lo, hi)).collect())
            .collect()
    };
    let mut rng = SplitMix64::new(0x006b_7232_3730);
    let test = csv(&draw(&mut rng, TEST_POSES), &mut rng, 0.0);
    let test = parse_measurements(test.as_bytes(), "test.csv", &job.robot, &job.setup).unwrap();
    let settings = PlanSettings {
        loads_kg: vec![LOAD_KG],
        ..PlanSettings::default()
    };
    let p = pool(
        &job,
        random_candidates(&job, &settings).unwrap(),
        None,
        &Default::default(),
    )
    .unwrap();
    let judge = |poses: &[Vec<f64>], seed: u64| -> (f64, f64) {
        let text = csv(poses, &mut SplitMix64::new(seed), 10e-6);
        let data =
            parse_measurements(text.as_bytes(), "recording.csv", &job.robot, &job.setup).unwrap();
        let s = Settings {
            diagnose: false,
            heldout: false,
            ..Settings::default()
        };
        let r = calibrate::calibrate(&job, &data, &s, &mut |_| {}).expect("calibrate");
        assert_eq!(r.parameters.len(), 5);
        let v = validate(&r.model, &job, &test).expect("validate");
        (
            r.parameters.iter().map(|p| p.std * p.std).sum(),
            v.rms_mm * 1e3,
        )
    };
    let mut table = String::from(
        "| K | trace: D plan | I plan | condition plan | K random | 2K random | error µm: D plan | I plan | condition plan | K random | 2K random |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut all = Vec::new();
    for kk in [15usize, 30, 60] {
        let q_of = |c: Criterion| -> Vec<Vec<f64>> {
            let planned = choose(&p, kk, c, 10).unwrap();
            (planned.chosen.iter())
                .map(|&c| p.candidates[c].q.clone())
                .collect()
        };
        let (plan_q, i_q, condition_q) = (
            q_of(Criterion::D),
            q_of(Criterion::I),
            q_of(Criterion::Condition),
        );
        let mut sums = [[0.0; 2]; 5];
        for rep in 0..REPS {
            let seed = 7000 * kk as u64 + rep;
            let mut own = SplitMix64::new(seed ^ 0x0bad_cafe);
            let designs = [
                plan_q.clone(),
                i_q.clone(),
                condition_q.clone(),
                draw(&mut own, kk),
                draw(&mut own, 2 * kk),
            ];
            for (i, q) in designs.iter().enumerate() {
                let (trace, err) = judge(q, seed);
                sums[i][0] += trace / REPS as f64;
                sums[i][1] += err / REPS as f64;
            }
        }
        table += &format!(
            "| {kk} | {:.3e} | {:.3e} | {:.3e} | {:.3e} | {:.3e} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |\n",
            sums[0][0],
            sums[1][0],
            sums[2][0],
            sums[3][0],
            sums[4][0],
            sums[0][1],
            sums[1][1],
            sums[2][1],
            sums[3][1],
            sums[4][1]
        );
        all.push((kk, sums));
    }
    println!("{table}");
    let _ = std::fs::remove_dir_all(&d);
    for (kk, s) in all {
        assert!(
            s[0][0] <= s[4][0],
            "K {kk}: D plan's trace against 2K random\n{table}"
        );
        assert!(
            s[0][1] < s[3][1],
            "K {kk}: D plan against K random\n{table}"
        );
        assert!(
            s[0][0] < 0.2 * s[2][0],
            "K {kk}: D plan against the condition number's\n{table}"
        );
        assert!(
            s[0][1] < 0.6 * s[2][1],
            "K {kk}: D plan against the condition number's\n{table}"
        );
    }
}

/// The controller's choices (`examples/firmware_plan`: the core's
/// `next_best` one configuration at a time, in f32 and f64) are the host's
/// (`robcal plan`'s greedy `choose` on the same 15 configurations of the
/// KR-270 under their payloads, the setup's model with A2's compliance by
/// angle), and the sequence the firmware checks against is theirs.
#[test]
fn the_controllers_choices_are_the_hosts() {
    use crate::kr270::{q_rad, Kr270, G, LOAD_DKG};
    use crate::plan_sequence::{sequence, table, PICKS};
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let job = Job::load(root.join("data/kr270/setup.toml")).expect("setup");
    let candidates: Vec<robcal::calibrate::plan::Candidate> = (0..G)
        .map(|g| robcal::calibrate::plan::Candidate {
            q: q_rad::<f64>(g).to_vec(),
            load_kg: f64::from(LOAD_DKG[g]) * 0.1,
        })
        .collect();
    let p = pool(&job, candidates, None, &Default::default()).unwrap();
    assert_eq!(p.parameters(), 9, "{:?} {:?}", p.params, p.notes);
    let host = choose(&p, PICKS, Criterion::D, 0).unwrap().chosen;
    let (c64, _) = sequence(&table(&Kr270::<f64>::new().unwrap()).unwrap()).unwrap();
    let (c32, _) = sequence(&table(&Kr270::<f32>::new().unwrap()).unwrap()).unwrap();
    println!("host {host:?}, device f64 {c64:?}, f32 {c32:?}");
    assert_eq!(host, c64.to_vec());
    assert_eq!(host, c32.to_vec());
    assert_eq!(
        host,
        firmware_plan_sequence().to_vec(),
        "examples/firmware_plan/main.rs: HOST_SEQUENCE"
    );
}

/// `HOST_SEQUENCE` as written in `examples/firmware_plan/main.rs`.
fn firmware_plan_sequence() -> Vec<usize> {
    let text = include_str!("../../examples/firmware_plan/main.rs");
    let line = text
        .lines()
        .find(|l| l.starts_with("pub const HOST_SEQUENCE"))
        .expect("HOST_SEQUENCE");
    let list = &line[line.rfind('[').unwrap() + 1..line.rfind(']').unwrap()];
    list.split(',').map(|v| v.trim().parse().unwrap()).collect()
}
