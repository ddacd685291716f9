//! Exploration (draft).

use std::path::PathBuf;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use robcal::calibrate::{self, Report, Settings};
use robcal::io::{parse_measurements, Job, MarkerModel};
use robcal_paper::rng::SplitMix64 as Rng;

fn setup() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/loop/ur_like.toml")
}

/// Extra point mass on wrist_3's body: (kg, com in its frame).
type Tool = Option<(f64, Vector3<f64>)>;

fn simulate(
    bend: Option<(usize, f64)>,
    tilt: Option<(usize, Vector3<f64>)>,
    tool: Tool,
    configs: usize,
    seed: u64,
) -> (Job, robcal::io::Measurements, Vec<[f64; 6]>) {
    let mut job = Job::load(setup()).expect("fixture setup");
    if let Some((m, c)) = tool {
        let l = job.robot.chain.joints_mut()[5].link.as_mut().unwrap();
        let total = l.mass_kg + m;
        l.com_m = (l.com_m * l.mass_kg + c * m) / total;
        l.mass_kg = total;
    }
    job.setup.model.compliance = vec![];
    job.setup.model.base_frame = true;
    job.setup.model.markers = MarkerModel::Nominal;
    let chain = job.robot.chain.clone();
    let joints = chain.joints().to_vec();
    let g = Vector3::from(job.setup.load.expect("fixture has a load").gravity);
    let base = Isometry3::from_parts(
        Translation3::new(1.5, -0.4, 0.2),
        UnitQuaternion::from_scaled_axis(Vector3::new(0.02, -0.01, 0.7)),
    );
    let ranges = [
        (-180.0, 180.0),
        (-160.0, -20.0),
        (-150.0, 150.0),
        (-180.0, 180.0),
        (-150.0, 150.0),
        (-180.0, 180.0),
    ];
    let names = job.robot.joint_names.clone();
    let mut rng = Rng::new(seed);
    let mut csv = format!("config,rep,marker,load_kg,{},x,y,z\n", names.join(","));
    let mut mperp = Vec::new();
    for c in 0..configs {
        let q_deg: Vec<f64> = ranges
            .iter()
            .map(|&(lo, hi)| (rng.range(lo, hi) * 100.0).round() / 100.0)
            .collect();
        let q: Vec<f64> = q_deg.iter().map(|d| d.to_radians()).collect();
        let mut t = Isometry3::identity();
        let frames: Vec<Isometry3<f64>> = joints
            .iter()
            .zip(&q)
            .map(|(joint, &qi)| {
                let tl = match tilt {
                    Some((tj, v)) if std::ptr::eq(joint, &joints[tj]) => {
                        UnitQuaternion::from_scaled_axis(v)
                    }
                    _ => UnitQuaternion::identity(),
                };
                t = t
                    * joint.origin
                    * tl
                    * Isometry3::from_parts(
                        Translation3::identity(),
                        UnitQuaternion::from_axis_angle(&joint.axis, qi),
                    );
                t
            })
            .collect();
        let tip = t * chain.tip();
        let m_perp = |j: usize| {
            let o = frames[j].translation.vector;
            let z = frames[j].rotation * joints[j].axis.into_inner();
            let m: Vector3<f64> = joints[j..]
                .iter()
                .zip(&frames[j..])
                .filter_map(|(jt, f)| {
                    jt.link.map(|l| {
                        (f.transform_point(&Point3::from(l.com_m)).coords - o)
                            .cross(&(g * l.mass_kg))
                    })
                })
                .sum();
            (o, m - z * z.dot(&m))
        };
        mperp.push(std::array::from_fn(|j| m_perp(j).1.norm()));
        let sigma = Vector3::from_fn(|_, _| rng.range(10.0, 30.0) * 1e-6);
        for rep in 1..=2 {
            for m in &job.setup.markers {
                let mut p = tip.transform_point(&Point3::from(m.xyz)).coords;
                if let Some((j, k)) = bend {
                    let (o, mp) = m_perp(j);
                    p = o + UnitQuaternion::from_scaled_axis(mp * k) * (p - o);
                }
                let p = base.transform_point(&p.into());
                let p = p.coords + Vector3::from_fn(|a, _| rng.normal() * sigma[a]);
                let qs: Vec<String> = q_deg.iter().map(|v| format!("{v}")).collect();
                csv += &format!(
                    "{},{rep},{},0,{},{},{},{}\n",
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
    let data = parse_measurements(csv.as_bytes(), "synthetic.csv", &job.robot, &job.setup)
        .expect("synthetic data parse");
    (job, data, mperp)
}

fn run(bend: Option<(usize, f64)>, tool: Tool, configs: usize, seed: u64, heldout: bool) -> Report {
    let (job, data, _) = simulate(bend, None, tool, configs, seed);
    let settings = Settings {
        heldout,
        ..Settings::default()
    };
    calibrate::calibrate(&job, &data, &settings, &mut |_| {}).expect("calibration")
}

#[test]
fn explore() {
    let tools: [Tool; 2] = [None, Some((2.0, Vector3::new(0.0, 0.15, 0.0)))];
    for tool in tools {
        let (_, _, mp) = simulate(None, None, tool, 40, 1);
        for j in 0..6 {
            let v: Vec<f64> = mp.iter().map(|a| a[j]).collect();
            let mn = v.iter().cloned().fold(f64::MAX, f64::min);
            let mx = v.iter().cloned().fold(0.0, f64::max);
            eprintln!("tool {tool:?} joint {j}: |m_perp| {mn:.3} .. {mx:.3} N m");
        }
        for (j, k) in [(1usize, 150e-6), (2, 800e-6)] {
            for seed in [31, 32, 33] {
                let r = run(Some((j, k)), tool, 36, seed, true);
                let p: Vec<String> = r
                    .parameters
                    .iter()
                    .filter(|p| p.name.starts_with("link"))
                    .map(|p| format!("{} = {:.2} ± {:.2}", p.name, p.value, p.std))
                    .collect();
                eprintln!(
                    "tool {:?} j {j} k {:.0} seed {seed}: {} | rms {:.1} declared {:.1} | {p:?}",
                    tool.map(|t| t.0),
                    k * 1e6,
                    host_tests::loop_summary(&r),
                    r.rms_um,
                    r.declared_rms_um
                );
            }
        }
    }
}

fn run_tilt(j: usize, v: Vector3<f64>, tool: Tool, seed: u64) -> Report {
    let (job, data, _) = simulate(None, Some((j, v)), tool, 36, seed);
    calibrate::calibrate(&job, &data, &Settings::default(), &mut |_| {}).expect("calibration")
}

#[test]
fn explore_tilt() {
    let tools: [Tool; 2] = [None, Some((2.0, Vector3::new(0.0, 0.15, 0.0)))];
    for tool in tools {
        for j in [1usize, 2, 3] {
            for v in [Vector3::new(1.5e-3, 0.0, 0.0), Vector3::new(0.0, 0.0, 1.5e-3)] {
                let r = run_tilt(j, v, tool, 31);
                eprintln!(
                    "tool {:?} tilt j {j} {v:?}: {} | rms {:.1} declared {:.1}",
                    tool.map(|t| t.0),
                    host_tests::loop_summary(&r),
                    r.rms_um,
                    r.declared_rms_um
                );
            }
        }
    }
}
