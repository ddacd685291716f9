//! The device's closed loop (issue 17: `examples/firmware_diagnose/
//! closed_loop.rs` on `robcal::estimate::screen`, one pass of
//! cross-products, no rows kept) against the host's (`robcal::calibrate`
//! with the first-order deflection model, `robcal calibrate --linear`: the
//! rows the device computes) on the same data: the same effects added in
//! the same order, the same F statistics, p-values, Bonferroni counts and
//! RMS before and after.
//!
//! - the KR-270 data with the naive model (`data/kr270/setup-naive.toml`):
//!   both add the compensator on a2, and nothing else;
//! - synthetic KR-270 data with a backlash on a5 and a drift of the
//!   tracker: both add both, in the same order.
//!
//! Tolerances: the device's loop follows the host's arithmetic on the
//! same sums, in another summation order (the host sums rows per candidate,
//! the device once for all, and streams the model's residuals in place of
//! `Δp`). In f64, F and the RMS within 1e-6 relative and p within 1e-4
//! (measured: F 1e-11, RMS equal to the printed digits); in f32, what the
//! device runs, the same decision, F within 1e-3 (measured 1e-4), p within
//! 2 %, RMS within 1e-4, and at most one candidate fewer tried (one whose
//! column f32 cannot tell from the model's).

use crate::{closed_loop, table};

use std::path::PathBuf;

use closed_loop::{Data, Meas, J};
use nalgebra::{RealField, Vector3};
use robcal::calibrate::{self, DeflectionModel, Report, Settings};
use robcal::estimate::screen::Rule;
use robcal::estimate::RobustWeight;
use robcal::io::{parse_measurements, Job, Measurements};
use robcal::model::{Marker, Param};
use robcal::robot::PointLoad;
use robcal::{Chain, Error, IrlsSettings};
use robcal_paper::rng::SplitMix64 as Rng;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/kr270")
}

/// A measurement file as the device's stream: configurations in sorted
/// order of their ids, markers by their index in the setup.
struct FileData<T: RealField + Copy> {
    chain: Chain<T, J>,
    q: Vec<[T; J]>,
    load_kg: Vec<T>,
    com: Vector3<T>,
    gravity: Vector3<T>,
    markers: Vec<Marker<T>>,
    meas: Vec<(usize, Meas<T>)>,
    time: bool,
}

fn c<T: RealField + Copy>(v: f64) -> T {
    nalgebra::convert(v)
}

impl<T: RealField + Copy> FileData<T> {
    fn new(job: &Job, data: &Measurements) -> Self {
        let big = &job.robot.chain;
        let mut chain = Chain::new();
        for jt in big.joints().iter().take(J) {
            let jt: robcal::Joint<T> = robcal::Joint {
                origin: nalgebra::convert(jt.origin),
                axis: nalgebra::Unit::new_unchecked(nalgebra::convert(jt.axis.into_inner())),
                kind: jt.kind,
                link: None,
            };
            chain.push(jt).unwrap();
        }
        chain.set_tip(nalgebra::convert(*big.tip()));
        let mut configs: Vec<i64> = data.deflections.iter().map(|d| d.config).collect();
        configs.sort_unstable();
        configs.dedup();
        let mut q = vec![[T::zero(); J]; configs.len()];
        let mut load_kg = vec![T::zero(); configs.len()];
        let mut meas = Vec::new();
        let mut time = false;
        for d in &data.deflections {
            let g = configs.binary_search(&d.config).unwrap();
            q[g] = std::array::from_fn(|j| c(d.q[j]));
            load_kg[g] = c(d.load_kg);
            let marker = job
                .setup
                .markers
                .iter()
                .position(|m| m.id == d.marker)
                .unwrap() as u8;
            let [u, l] = d.rows.map(|r| data.observations[r].t_s);
            time |= u.is_some();
            let dt = l.zip(u).map_or(0.0, |(l, u)| l - u);
            meas.push((
                g,
                Meas {
                    group: g,
                    marker,
                    dt_s: c(dt),
                    dp: Vector3::from_fn(|a, _| c(d.dp_m[a])),
                },
            ));
        }
        // Stable: file order within a configuration.
        meas.sort_by_key(|m| m.0);
        let load = job.setup.load.unwrap();
        let v = |a: [f64; 3]| Vector3::new(c(a[0]), c(a[1]), c(a[2]));
        Self {
            chain,
            q,
            load_kg,
            com: v(load.com),
            gravity: v(load.gravity),
            markers: job
                .setup
                .markers
                .iter()
                .enumerate()
                .map(|(i, m)| Marker {
                    index: i as u8,
                    xyz_m: v(m.xyz),
                })
                .collect(),
            meas,
            time,
        }
    }
}

impl<T: RealField + Copy> Data<T> for FileData<T> {
    fn chain(&self) -> &Chain<T, J> {
        &self.chain
    }
    fn groups(&self) -> usize {
        self.q.len()
    }
    fn q(&self, g: usize) -> [T; J] {
        self.q[g]
    }
    fn load(&self, g: usize) -> PointLoad<T> {
        PointLoad {
            mass_kg: self.load_kg[g],
            com_m: self.com,
            gravity_mps2: self.gravity,
        }
    }
    fn marker(&self, m: u8) -> Option<Marker<T>> {
        self.markers.get(usize::from(m)).copied()
    }
    fn time(&self) -> bool {
        self.time
    }
    fn for_each(&self, f: &mut dyn FnMut(&Meas<T>) -> Result<(), Error>) -> Result<(), Error> {
        self.meas.iter().try_for_each(|(_, m)| f(m))
    }
}

/// The host's loop with the device's rows (first-order deflections), its
/// held-out check off (the device does not run it).
fn host(job: &Job, data: &Measurements) -> Report {
    let settings = Settings {
        deflection_model: DeflectionModel::Linear,
        heldout: false,
        ..Settings::default()
    };
    calibrate::calibrate(job, data, &settings, &mut |_| {}).expect("host calibration")
}

/// The declared compliances of the job as the device's model.
fn declared(job: &Job) -> Vec<Param> {
    let names = &job.robot.joint_names;
    job.setup
        .model
        .compliance
        .iter()
        .map(|n| Param::Compliance {
            joint: names.iter().position(|j| j == n).unwrap() as u8,
        })
        .collect()
}

fn device<T: RealField + Copy>(job: &Job, data: &Measurements) -> closed_loop::Outcome<T> {
    let d = FileData::<T>::new(job, data);
    let settings = IrlsSettings::new(
        RobustWeight::new(
            c(job.setup.noise.sigma0_um * 1e-6),
            c(job.setup.noise.lambda),
        )
        .unwrap(),
    );
    closed_loop::run(&d, &declared(job), &settings, &Rule::default(), |_| {}).expect("device loop")
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(f64::MIN_POSITIVE)
}

/// Device (f64 and f32) = host: effects, joints, F, p, tried, RMS.
fn compare(job: &Job, data: &Measurements, expect: &[(&str, &str)]) {
    let h = host(job, data);
    let names = &job.robot.joint_names;
    let got: Vec<(String, String)> = h
        .effects
        .iter()
        .map(|s| (s.effect.to_string(), s.joint.clone().unwrap_or_default()))
        .collect();
    let want: Vec<(String, String)> = expect
        .iter()
        .map(|(e, j)| (e.to_string(), j.to_string()))
        .collect();
    assert_eq!(got, want, "the host's decision");
    // The host's held-out check (which the device does not run) agrees.
    let full = calibrate::calibrate(
        job,
        data,
        &Settings {
            deflection_model: DeflectionModel::Linear,
            ..Settings::default()
        },
        &mut |_| {},
    )
    .expect("host calibration with held-out");
    let with_heldout: Vec<(String, String)> = full
        .effects
        .iter()
        .map(|s| (s.effect.to_string(), s.joint.clone().unwrap_or_default()))
        .collect();
    assert_eq!(
        with_heldout, want,
        "the host's decision with its held-out check"
    );
    let d64 = device::<f64>(job, data);
    let d32 = device::<f32>(job, data);
    for (d, tol_f, tol_p, tol_rms, what) in [
        (&d64.steps, 1e-6, 1e-4, 1e-6, "f64"),
        (&d32.steps, 1e-3, 0.02, 1e-4, "f32"),
    ] {
        let dev: Vec<(String, String)> = d
            .iter()
            .map(|s| {
                (
                    s.effect.to_string(),
                    s.joint
                        .map(|j| names[usize::from(j)].clone())
                        .unwrap_or_default(),
                )
            })
            .collect();
        assert_eq!(dev, want, "device ({what}) decision");
        for (s, hs) in d.iter().zip(&h.effects) {
            let (f, p) = (s.test.f, s.test.p_value);
            println!(
                "{what}: {} F {f:.6} (host {:.6}, rel {:.1e}), p {p:.4e} (host {:.4e}), tried {} (host {}), rms {:.3} -> {:.3} um (host {:.3} -> {:.3})",
                s.effect, hs.f, rel(f, hs.f), hs.p_value, s.tried, hs.tried,
                s.rms_um.0, s.rms_um.1, hs.rms_um_before, hs.rms_um_after
            );
            if what == "f64" {
                assert_eq!(s.tried, hs.tried, "{what}: candidates tried");
            } else {
                // In f32 the core leaves out a column more than 97.8 %
                // explained by the model's (`rank::independence_tolerance`:
                // 64 √ε, 0.022 on 1 − R²; 1e-6 in f64): f32 cannot estimate
                // it. Measured: the nonlinear stiffness of a5 once the
                // backlash of a5 is in the model (F = 0.05 in f64); with
                // the compensator on a2, the nonlinear stiffness of a2 and
                // the link compliance of a1. Up to two fewer tried, the
                // same decision.
                assert!(
                    s.tried <= hs.tried && s.tried + 2 >= hs.tried,
                    "{what}: candidates tried"
                );
            }
            assert!(rel(f, hs.f) < tol_f, "{what}: F {f} vs host {}", hs.f);
            assert!(
                rel(p, hs.p_value) < tol_p,
                "{what}: p {p} vs host {}",
                hs.p_value
            );
            assert!(
                rel(s.rms_um.0, hs.rms_um_before) < tol_rms,
                "{what}: rms before"
            );
            assert!(
                rel(s.rms_um.1, hs.rms_um_after) < tol_rms,
                "{what}: rms after"
            );
        }
    }
    assert!(rel(d64.last.rms_um, h.rms_um) < 1e-6, "final rms");
}

#[test]
fn kr270_naive_model_adds_the_compensator_on_a2() {
    let job = Job::load(root().join("setup-naive.toml")).unwrap();
    let data = job
        .read_measurements(root().join("measurements.csv"))
        .unwrap();
    compare(&job, &data, &[("compensator", "a2")]);
}

/// KR-270 data simulated at first order (the device's and the host's
/// `--linear` rows): the naive model's compliances, a backlash of 0.2 mrad
/// on a5 and a tracker drift of 0.5 mm/h; 12 configurations, 4
/// repetitions, 3 markers, σ 20 µm.
fn synthetic(seed: u64) -> (Job, Measurements) {
    let job = Job::load(root().join("setup-naive.toml")).unwrap();
    let chain = &job.robot.chain;
    let names = &job.robot.joint_names;
    let load = job.setup.load.unwrap();
    let gravity = Vector3::from(load.gravity);
    let k = [0.0, 0.29e-6, 0.42e-6, 2.8e-6, 3.5e-6, 2.1e-6];
    let backlash = (4usize, 2e-4);
    let drift = Vector3::new(0.5, -0.3, 0.2) * (0.5e-3 / 3600.0) / 0.616;
    let ranges = [
        (-60.0, 60.0),
        (-140.0, -5.0),
        (-20.0, 60.0),
        (-90.0, 90.0),
        (-100.0, 100.0),
        (-90.0, 90.0),
    ];
    let mut rng = Rng::new(seed);
    let mut csv = String::from("config,rep,marker,load_kg,");
    csv += &names.join(",");
    csv += ",x,y,z,t\n";
    let mut time = 0.0;
    for cfg in 0..12 {
        let q: Vec<f64> = ranges
            .iter()
            .map(|&(lo, hi)| (rng.range(lo, hi) * 100.0).round() / 100.0)
            .collect();
        let q_rad: Vec<f64> = q.iter().map(|d| d.to_radians()).collect();
        let load_kg = 255.8;
        let frames = chain.frames(&q_rad).unwrap();
        let pl = PointLoad {
            mass_kg: load_kg,
            com_m: Vector3::from(load.com),
            gravity_mps2: gravity,
        };
        let wrench = pl.wrench(&frames);
        let mut tau = [0.0; 16];
        robcal::robot::joint_torques(&frames, &wrench, &mut tau[..6]).unwrap();
        let q_loaded: Vec<f64> = (0..6)
            .map(|j| {
                let mut d = k[j] * tau[j];
                if j == backlash.0 {
                    d += backlash.1 * tau[j].signum();
                }
                q_rad[j] + d
            })
            .collect();
        let f1 = chain.frames(&q_loaded).unwrap();
        for (state, fr) in [(0, &frames), (1, &f1)] {
            if state == 1 {
                time += 120.0;
            }
            for rep in 1..=4 {
                for m in &job.setup.markers {
                    let mut p = fr.point_m(&Vector3::from(m.xyz)) + drift * time;
                    p += Vector3::from_fn(|_, _| rng.normal() * 20e-6 / 2f64.sqrt());
                    csv += &format!(
                        "{},{},{},{},{},{},{},{},{}\n",
                        cfg + 1,
                        rep,
                        m.id,
                        if state == 1 { load_kg } else { 0.0 },
                        q.iter()
                            .map(|v| format!("{v}"))
                            .collect::<Vec<_>>()
                            .join(","),
                        p.x * 1e3,
                        p.y * 1e3,
                        p.z * 1e3,
                        time
                    );
                    time += 5.0;
                }
            }
        }
        time += 60.0;
    }
    let data = parse_measurements(csv.as_bytes(), "synthetic.csv", &job.robot, &job.setup)
        .expect("synthetic data");
    (job, data)
}

#[test]
fn synthetic_backlash_and_drift_same_decision() {
    let (job, data) = synthetic(17);
    let h = host(&job, &data);
    let steps: Vec<(String, String)> = h
        .effects
        .iter()
        .map(|s| (s.effect.to_string(), s.joint.clone().unwrap_or_default()))
        .collect();
    println!("host: {steps:?}");
    let expect: Vec<(&str, &str)> = steps
        .iter()
        .map(|(e, j)| (e.as_str(), j.as_str()))
        .collect();
    assert!(
        expect.contains(&("backlash", "a5")),
        "host names the backlash: {expect:?}"
    );
    assert!(
        expect.contains(&("drift", "")),
        "host names the drift: {expect:?}"
    );
    compare(&job, &data, &expect);
}

/// The firmware's second case (`examples/firmware_diagnose/table.rs`): the
/// KR-270 data with a backlash of 0.3 mrad on a5 injected into the loaded
/// positions (forward kinematics of the pose with a5 turned by
/// `b · sign(τ5)`). The host, on the CSV so changed, decides as the device
/// on its flash table with the same injection: compensator on a2, then
/// backlash on a5.
#[test]
fn kr270_with_injected_backlash_same_decision() {
    let job = Job::load(root().join("setup-naive.toml")).unwrap();
    let text = std::fs::read_to_string(root().join("measurements.csv")).unwrap();
    let t = table::Table::<f64>::new(true).unwrap();
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        let mut f: Vec<String> = line.split(',').map(str::to_string).collect();
        if i > 0 && f[3].parse::<f64>().unwrap() > 0.0 {
            let g = f[0].parse::<usize>().unwrap() - 1;
            let m = f[2].parse::<usize>().unwrap() - 1;
            let d = t.injected(g).unwrap()[m];
            for a in 0..3 {
                let v: f64 = f[10 + a].parse().unwrap();
                f[10 + a] = format!("{}", v + d[a] * 1e3);
            }
        }
        out += &f.join(",");
        out.push('\n');
    }
    let data = parse_measurements(out.as_bytes(), "injected.csv", &job.robot, &job.setup).unwrap();
    compare(&job, &data, &[("compensator", "a2"), ("backlash", "a5")]);
    // The device's own table (the flash table, quantised to 1 nm) decides
    // the same.
    let d = table::Table::<f32>::new(true).unwrap();
    let out = closed_loop::run(
        &d,
        &table::naive_model(),
        &table::settings().unwrap(),
        &Rule::default(),
        |_| {},
    )
    .unwrap();
    let got: Vec<_> = out
        .steps
        .iter()
        .map(|s| (s.effect.name(), s.joint))
        .collect();
    assert_eq!(got, [("compensator", Some(1)), ("backlash", Some(4))]);
}

/// `Augmented`: a wrong `L` is refused; a bad row (non-finite, negative
/// weight) is refused with the state unchanged; the sub-problem of some
/// columns is the accumulator of those columns streamed alone.
#[test]
fn augmented_sums_are_the_accumulator_of_the_columns() {
    use nalgebra::{Dyn, OMatrix, SMatrix, U3};
    use robcal::estimate::screen::{Augmented, PureError};
    use robcal::{Accumulator, Block};

    assert!(Augmented::<f64, 4, 9>::new().is_err());
    let mut aug = Augmented::<f64, 4, 10>::new().unwrap();
    let cols = [3usize, 0, 2];
    let mut direct = Accumulator::<f64, Dyn>::zeros(Dyn(3));
    let mut rng = Rng::new(5);
    for i in 0..40 {
        let b = SMatrix::<f64, 3, 4>::from_fn(|_, _| rng.normal());
        let dp = Vector3::from_fn(|_, _| rng.normal());
        let w = Vector3::new(1.0, 0.5 + 0.01 * i as f64, 2.0);
        aug.update(&b, &dp, &w).unwrap();
        let sub = OMatrix::<f64, U3, Dyn>::from_fn(3, |a, k| b[(a, cols[k])]);
        direct.update(&Block::new(sub, dp).with_weights(w)).unwrap();
    }
    let before = aug.clone();
    let bad = SMatrix::<f64, 3, 4>::from_element(f64::NAN);
    assert!(aug
        .update(&bad, &Vector3::zeros(), &Vector3::repeat(1.0))
        .is_err());
    let b = SMatrix::<f64, 3, 4>::from_element(1.0);
    assert!(aug
        .update(&b, &Vector3::zeros(), &Vector3::new(1.0, -1.0, 1.0))
        .is_err());
    assert_eq!(aug, before, "state unchanged on error");
    let sel = aug.select(&cols, Dyn(3), true).unwrap();
    assert_eq!(sel.equations(), direct.equations());
    let (a, d) = (sel.information(), direct.information());
    assert!((&a - &d).abs().max() <= 1e-12 * d.abs().max());
    assert!((sel.eta() - direct.eta()).abs().max() <= 1e-12 * direct.eta().abs().max());
    assert!(
        aug.select(&[4], Dyn(1), true).is_err(),
        "column out of range"
    );
    assert!(aug.select(&cols, Dyn(2), true).is_err(), "too many columns");

    let mut pe = PureError::<f64, 1>::new();
    pe.update(0, 0, &Vector3::repeat(1.0)).unwrap();
    let before = pe.clone();
    assert!(pe.update(0, 1, &Vector3::repeat(1.0)).is_err(), "capacity");
    assert!(pe.update(0, 0, &Vector3::repeat(f64::NAN)).is_err());
    assert_eq!(pe, before, "state unchanged on error");
}

/// The device's lean test (`Augmented::solve_model` once, then
/// `test_fitted` per candidate) is `Augmented::test` bit for bit: the same
/// sums in the same order, at a fixed size (`Const`, the device's) and at
/// the host's (`Dyn`), in f64 and f32, with candidate columns that are
/// informative, absorbed by the model, or empty.
#[test]
fn lean_test_is_the_test_bit_for_bit() {
    use nalgebra::{Const, Dim, Dyn, SMatrix};
    use robcal::estimate::screen::Augmented;

    fn check<T: RealField + Copy, D: Dim + Copy>(dim: D)
    where
        nalgebra::DefaultAllocator: robcal::estimate::Alloc<D>,
    {
        let mut aug = Augmented::<T, 8, 36>::new().unwrap();
        let mut rng = Rng::new(11);
        for i in 0..60 {
            let mut b = SMatrix::<T, 3, 8>::from_fn(|_, _| c(rng.normal()));
            // Column 6 is column 0 plus a little (nearly absorbed), 7 zero.
            for a in 0..3 {
                b[(a, 6)] = b[(a, 0)] + c::<T>(1e-3 * rng.normal());
                b[(a, 7)] = T::zero();
            }
            let dp = Vector3::from_fn(|a, _| b[(a, 4)] * c(0.3) + c(0.1 * rng.normal()));
            let w = Vector3::new(c(1.0), c(0.5 + 0.01 * i as f64), c(2.0));
            aug.update(&b, &dp, &w).unwrap();
        }
        let model = [0usize, 1, 2];
        let fit = aug.solve_model(&model, dim).unwrap();
        let candidates: [&[usize]; 6] = [&[3], &[4], &[3, 4, 5], &[6], &[7], &[7, 4]];
        for cand in candidates {
            let old = aug.test(&model, cand, dim).unwrap();
            let new = aug.test_fitted(&model, &fit, cand, dim).unwrap();
            assert_eq!(
                old.map(|t| (t.delta_rss.to_bits(), t.f.to_bits(), t.p_value.to_bits())),
                new.map(|t| (t.delta_rss.to_bits(), t.f.to_bits(), t.p_value.to_bits())),
                "candidate {cand:?}"
            );
            assert_eq!(old, new, "candidate {cand:?}");
        }
        let other = aug.solve_model(&[0, 1], dim).unwrap();
        assert!(aug.test_fitted(&model, &other, &[3], dim).is_err());
    }
    check::<f64, _>(Const::<8>);
    check::<f64, _>(Dyn(8));
    check::<f32, _>(Const::<8>);
    check::<f32, _>(Dyn(8));
}
