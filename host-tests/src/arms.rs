//! Synthetic arms measured by a tracker, for the identifiability tests
//! (issue 20): random serial chains written as URDF text, a "true" robot
//! that differs from the nominal one (joint origins, joint zeros, the
//! tracker's frame, the markers), and its measurements as a CSV of the data
//! contract (units m and rad).
//!
//! The measurements come from [`super::exact::Fk`] on the *true* URDF text
//! (urdf-rs, 4 × 4 matrices): nothing here calls robcal's kinematics,
//! columns or engine. The UR10 generator ([`ur10_csv`]) remakes the
//! reproduction of `shared/repro/ur10-offsets` at any number of poses.

use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt::Write as _;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use robcal_paper::rng::SplitMix64;

use super::exact::Fk;

/// A joint of a [`Chain`].
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    /// `j<k>` (movable) or `f<k>` (fixed).
    pub name: String,
    /// `revolute`, `prismatic` or `fixed`.
    pub kind: &'static str,
    /// Origin translation \[m\].
    pub xyz: [f64; 3],
    /// Origin roll, pitch, yaw \[rad\].
    pub rpy: [f64; 3],
    /// Axis (unit).
    pub axis: [f64; 3],
}

/// A serial chain from `base` to `tip` (links `l0` … `lN`).
#[derive(Debug, Clone, PartialEq)]
pub struct Chain {
    /// Joints from the base.
    pub joints: Vec<Joint>,
}

fn pick(rng: &mut SplitMix64, n: usize) -> usize {
    ((rng.uniform() * n as f64) as usize).min(n - 1)
}

/// A coordinate that is often exactly 0 (as in DH-built URDFs, where the
/// exact dependences live).
fn coordinate(rng: &mut SplitMix64, scale: f64) -> f64 {
    if rng.uniform() < 0.4 {
        0.0
    } else {
        rng.range(-scale, scale)
    }
}

/// An angle that is often 0 or ±π/2.
fn angle(rng: &mut SplitMix64) -> f64 {
    match pick(rng, 5) {
        0 | 1 => 0.0,
        2 => FRAC_PI_2,
        3 => -FRAC_PI_2,
        _ => rng.range(-PI, PI),
    }
}

impl Chain {
    /// A random chain of 2–7 movable joints (≈ 15 % prismatic) and up to
    /// two fixed ones, axes mostly along a frame axis, origins often with
    /// zero coordinates and right angles.
    pub fn random(rng: &mut SplitMix64) -> Self {
        let movable = 2 + pick(rng, 6);
        let fixed = pick(rng, 3);
        let mut kinds: Vec<&'static str> = (0..movable)
            .map(|_| {
                if rng.uniform() < 0.15 {
                    "prismatic"
                } else {
                    "revolute"
                }
            })
            .collect();
        for _ in 0..fixed {
            let at = pick(rng, kinds.len() + 1);
            kinds.insert(at, "fixed");
        }
        let joints = kinds
            .into_iter()
            .enumerate()
            .map(|(k, kind)| {
                let axis = if rng.uniform() < 0.8 {
                    let mut a = [0.0; 3];
                    a[pick(rng, 3)] = if rng.uniform() < 0.5 { 1.0 } else { -1.0 };
                    a
                } else {
                    let v = Vector3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
                    [v.x, v.y, v.z]
                };
                Joint {
                    name: format!("{}{k}", if kind == "fixed" { "f" } else { "j" }),
                    kind,
                    xyz: [0; 3].map(|_| coordinate(rng, 0.4)),
                    rpy: [0; 3].map(|_| angle(rng)),
                    axis,
                }
            })
            .collect();
        Self { joints }
    }

    /// Names of the movable joints, in order.
    pub fn movable(&self) -> Vec<String> {
        self.joints
            .iter()
            .filter(|j| j.kind != "fixed")
            .map(|j| j.name.clone())
            .collect()
    }

    /// The chain with every joint origin moved by up to `lin` \[m\] and
    /// turned by up to `ang` \[rad\] per coordinate.
    pub fn perturbed(&self, rng: &mut SplitMix64, lin: f64, ang: f64) -> Self {
        let mut c = self.clone();
        for j in &mut c.joints {
            for v in &mut j.xyz {
                *v += rng.range(-lin, lin);
            }
            for v in &mut j.rpy {
                *v += rng.range(-ang, ang);
            }
        }
        c
    }

    /// URDF text: links `l0` (base) … `lN` (tip), no inertias.
    pub fn urdf(&self) -> String {
        let mut s =
            String::from("<?xml version=\"1.0\"?>\n<robot name=\"arm\">\n  <link name=\"l0\"/>\n");
        for (k, j) in self.joints.iter().enumerate() {
            let _ = write!(
                s,
                "  <link name=\"l{}\"/>\n  <joint name=\"{}\" type=\"{}\">\n    \
                 <parent link=\"l{k}\"/>\n    <child link=\"l{}\"/>\n    \
                 <origin xyz=\"{:?} {:?} {:?}\" rpy=\"{:?} {:?} {:?}\"/>\n    \
                 <axis xyz=\"{:?} {:?} {:?}\"/>\n",
                k + 1,
                j.name,
                j.kind,
                k + 1,
                j.xyz[0],
                j.xyz[1],
                j.xyz[2],
                j.rpy[0],
                j.rpy[1],
                j.rpy[2],
                j.axis[0],
                j.axis[1],
                j.axis[2],
            );
            if j.kind != "fixed" {
                s.push_str("    <limit lower=\"-10\" upper=\"10\" effort=\"0\" velocity=\"0\"/>\n");
            }
            s.push_str("  </joint>\n");
        }
        s.push_str("</robot>\n");
        s
    }

    /// The tip link's name.
    pub fn tip(&self) -> String {
        format!("l{}", self.joints.len())
    }

    /// The setup text (data contract §2, m and rad, σ0 20 µm) of this
    /// chain's URDF as `arm.urdf` (base `l0`, tip [`Chain::tip`]), its
    /// `[model]` with `geometry`, `base_frame` and `markers` (`identify` or
    /// `nominal`), and one `[[marker]]` per point of `at` \[m, tip frame\],
    /// ids from 1.
    pub fn setup(
        &self,
        geometry: &str,
        base_frame: bool,
        markers: &str,
        at: &[Vector3<f64>],
    ) -> String {
        let mut setup = format!(
            "robot = \"arm.urdf\"\nbase_link = \"l0\"\ntip_link = \"{}\"\n[units]\nangle = \"rad\"\n\
             length = \"m\"\n[noise]\nsigma0_um = 20.0\n[model]\ngeometry = \"{geometry}\"\n\
             base_frame = {base_frame}\nmarkers = \"{markers}\"\n",
            self.tip(),
        );
        for (i, m) in at.iter().enumerate() {
            let _ = write!(
                setup,
                "[[marker]]\nid = {}\nxyz = [{:?}, {:?}, {:?}]\n",
                i + 1,
                m.x,
                m.y,
                m.z
            );
        }
        setup
    }

    /// The job of this chain's URDF (base `l0`, tip [`Chain::tip`]) with the
    /// setup text `setup` (files named `arm.toml`, `arm.urdf`), and the
    /// measurements `csv` read for it.
    ///
    /// # Errors
    /// The readers' errors, as text.
    pub fn job(
        &self,
        setup: &str,
        csv: &str,
    ) -> Result<(robcal::io::Job, robcal::io::Measurements), String> {
        use robcal::io::{parse_measurements, Job, Robot, Setup};
        let setup = Setup::parse(setup, "arm.toml").map_err(|e| e.to_string())?;
        let robot = Robot::parse(&self.urdf(), "arm.urdf", Some("l0"), Some(&self.tip()))
            .map_err(|e| e.to_string())?;
        setup
            .check_robot(&robot, std::path::Path::new("arm.toml"))
            .map_err(|e| e.to_string())?;
        let m = parse_measurements(csv.as_bytes(), "arm.csv", &robot, &setup)
            .map_err(|e| e.to_string())?;
        let job = Job {
            setup_path: "arm.toml".into(),
            setup,
            robot,
            urdf_text: Some(self.urdf()),
        };
        Ok((job, m))
    }

    /// Random joint values of a movable joint of this kind: revolute
    /// [-π, π] rad, prismatic [-0.3, 0.3] m.
    pub fn random_q(&self, rng: &mut SplitMix64) -> Vec<f64> {
        self.joints
            .iter()
            .filter(|j| j.kind != "fixed")
            .map(|j| {
                if j.kind == "prismatic" {
                    rng.range(-0.3, 0.3)
                } else {
                    rng.range(-PI, PI)
                }
            })
            .collect()
    }
}

/// What the tracker really sees.
#[derive(Debug, Clone)]
pub struct Truth {
    /// The true robot's forward kinematics.
    pub fk: Fk,
    /// Joint zero errors, added to the commanded values \[rad or m\].
    pub offsets: Vec<f64>,
    /// The tracker frame's pose in the robot base frame's terms: a point
    /// `p` of the base frame is measured at `base * p`.
    pub base: Isometry3<f64>,
    /// Marker positions in the tip frame \[m\].
    pub markers: Vec<Vector3<f64>>,
    /// Noise σ per axis \[m\].
    pub noise_m: f64,
}

impl Truth {
    /// The measurement file (data contract §3, m and rad) of `poses`
    /// (commanded joint values), one row per pose and marker, no load.
    pub fn csv(&self, joints: &[String], poses: &[Vec<f64>], rng: &mut SplitMix64) -> String {
        let mut out = format!("config,rep,marker,load_kg,{},x,y,z\n", joints.join(","));
        for (c, q) in poses.iter().enumerate() {
            let theta: Vec<f64> = q.iter().zip(&self.offsets).map(|(a, b)| a + b).collect();
            let pose = self.fk.pose(&theta);
            let qs: Vec<String> = q.iter().map(|v| format!("{v:?}")).collect();
            for (m, marker) in self.markers.iter().enumerate() {
                let p = self.base * nalgebra::Point3::from(pose.point(marker))
                    + Vector3::from_fn(|_, _| rng.normal() * self.noise_m);
                let _ = writeln!(
                    out,
                    "{},1,{},0,{},{:?},{:?},{:?}",
                    c + 1,
                    m + 1,
                    qs.join(","),
                    p.x,
                    p.y,
                    p.z
                );
            }
        }
        out
    }
}

/// A tracker frame far from the robot's: turned by `angle` \[rad\] about a
/// random axis and moved by `shift` \[m\].
pub fn tracker_frame(rng: &mut SplitMix64, angle: f64, shift: Vector3<f64>) -> Isometry3<f64> {
    let axis = Vector3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
    Isometry3::from_parts(
        Translation3::from(shift),
        UnitQuaternion::from_scaled_axis(axis * angle),
    )
}

/// The UR10 of `shared/repro/ur10-offsets` measured at `poses` random
/// poses (every joint in [-π, π]): one reflector 0.1 m from the flange, the
/// tracker turned by 0.7 rad about a random axis and moved by
/// (2, −1, 0.3) m, true offsets +2 mrad on `elbow_joint` and −1 mrad on
/// `wrist_2_joint`, 20 µm noise per axis. `urdf` is the path of
/// `ur10.urdf`.
pub fn ur10_csv(urdf: &std::path::Path, poses: usize, seed: u64) -> String {
    ur10_csv_within(urdf, poses, seed, PI)
}

/// The UR10's movable joints (`shared/repro/ur10-offsets/ur10.urdf`), in
/// chain order.
pub const UR10_JOINTS: [&str; 6] = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
];

/// As [`ur10_csv`], every joint within `[-range, range]` rad of its zero.
pub fn ur10_csv_within(urdf: &std::path::Path, poses: usize, seed: u64, range: f64) -> String {
    let mut rng = SplitMix64::new(seed);
    let fk = Fk::new(urdf, "base_link", "flange");
    let joints: Vec<String> = UR10_JOINTS.map(String::from).to_vec();
    let truth = Truth {
        fk,
        offsets: vec![0.0, 0.0, 2e-3, 0.0, -1e-3, 0.0],
        base: tracker_frame(&mut rng, 0.7, Vector3::new(2.0, -1.0, 0.3)),
        markers: vec![Vector3::new(0.0, 0.0, 0.1)],
        noise_m: 20e-6,
    };
    let q: Vec<Vec<f64>> = (0..poses)
        .map(|_| (0..6).map(|_| rng.range(-range, range)).collect())
        .collect();
    truth.csv(&joints, &q, &mut rng)
}
