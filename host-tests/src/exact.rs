//! An independent model of a loaded robot, for generating data and for
//! checking robcal against it: forward kinematics straight from the URDF
//! text (`urdf-rs`, 4×4 matrices), the joint torques of a hanging mass,
//! and the equilibrium of the deflected robot by successive substitution.
//! Nothing here calls robcal's kinematics, loads, equilibrium or engine.
//!
//! The physics ("as a real robot behaves"): rigid links, one linear spring
//! per joint (`δqⱼ = kⱼ τⱼ`); the mass acts on the **deflected** robot, so
//! the loaded pose is the fixed point `θ = q + K τ(θ)`; a marker's measured
//! deflection is `p(θ) − p(q)`. The robot's own weight is not modelled: it
//! is the same loaded and unloaded.
//!
//! [`Kr270::csv`] makes one measurement file of the paper's KR-270
//! experiment (section 5) in the units of `data/kr270/setup.toml`: Table 2's
//! configurations, Table 3's compliances, a mass of 250–280 kg per
//! configuration, three markers, six repetitions, Gaussian noise with
//! Table 1's σ per configuration and axis times a factor, half of the
//! variance on the unloaded and half on the loaded position.

use std::fmt::Write as _;
use std::path::Path;

use nalgebra::{Matrix4, Rotation3, Unit, Vector3, Vector4};
use robcal_paper::kr270;
use robcal_paper::rng::SplitMix64;

/// A homogeneous transform from URDF `xyz` and `rpy` (R = Rz·Ry·Rx).
fn transform(xyz: [f64; 3], rpy: [f64; 3]) -> Matrix4<f64> {
    let r = Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]);
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(r.matrix());
    m.fixed_view_mut::<3, 1>(0, 3)
        .copy_from(&Vector3::from(xyz));
    m
}

/// A joint's motion: its axis and whether it is prismatic (`None`: fixed).
type Motion = Option<(Vector3<f64>, bool)>;

/// The chain from `base` to `tip` of a URDF: each joint's origin and
/// motion, fixed joints included.
#[derive(Debug, Clone)]
pub struct Fk(Vec<(Matrix4<f64>, Motion)>);

/// A posed chain: every movable joint's origin and unit axis \[base frame\]
/// and the tip frame.
pub struct Pose {
    /// `(oⱼ, zⱼ, prismatic)` per movable joint.
    pub joints: Vec<(Vector3<f64>, Vector3<f64>, bool)>,
    /// The tip frame.
    pub tip: Matrix4<f64>,
}

impl Pose {
    /// A point given in the tip frame, in the base frame.
    pub fn point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        (self.tip * Vector4::new(p.x, p.y, p.z, 1.0)).xyz()
    }

    /// `τⱼ = zⱼ·((c − oⱼ) × F)` (revolute) or `zⱼ·F` (prismatic) of a force
    /// `f` \[N\] at a point `c` \[m, base\] carried by the tip.
    pub fn torques(&self, f: &Vector3<f64>, c: &Vector3<f64>) -> Vec<f64> {
        self.joints
            .iter()
            .map(|(o, z, prismatic)| {
                if *prismatic {
                    z.dot(f)
                } else {
                    z.dot(&(c - o).cross(f))
                }
            })
            .collect()
    }
}

impl Fk {
    /// The chain from `base` to `tip` of the URDF at `path`.
    ///
    /// # Panics
    /// When the file cannot be read or has no chain from `base` to `tip`.
    pub fn new(path: &Path, base: &str, tip: &str) -> Self {
        Self::from_urdf(&urdf_rs::read_file(path).expect("urdf"), base, tip)
    }

    /// The chain from `base` to `tip` of URDF text.
    ///
    /// # Panics
    /// When the text is not a URDF or has no chain from `base` to `tip`.
    pub fn parse(text: &str, base: &str, tip: &str) -> Self {
        Self::from_urdf(&urdf_rs::read_from_string(text).expect("urdf"), base, tip)
    }

    fn from_urdf(urdf: &urdf_rs::Robot, base: &str, tip: &str) -> Self {
        let mut chain = Vec::new();
        let mut link = tip.to_string();
        while link != base {
            let j = urdf
                .joints
                .iter()
                .find(|j| j.child.link == link)
                .expect("a joint into every link of the chain");
            let o = transform(j.origin.xyz.0, j.origin.rpy.0);
            let axis = Vector3::from(j.axis.xyz.0);
            let motion = match j.joint_type {
                urdf_rs::JointType::Fixed => None,
                urdf_rs::JointType::Prismatic => Some((axis, true)),
                _ => Some((axis, false)),
            };
            chain.push((o, motion));
            link = j.parent.link.clone();
        }
        chain.reverse();
        Self(chain)
    }

    /// Number of movable joints.
    pub fn dof(&self) -> usize {
        self.0.iter().filter(|(_, m)| m.is_some()).count()
    }

    /// The chain posed at joint values `q` (movable joints in chain order).
    pub fn pose(&self, q: &[f64]) -> Pose {
        let mut t = Matrix4::identity();
        let mut joints = Vec::new();
        let mut k = 0;
        for (o, m) in &self.0 {
            t *= o;
            if let Some((axis, prismatic)) = m {
                let unit = Unit::new_normalize(*axis);
                let z = t.fixed_view::<3, 3>(0, 0) * unit.into_inner();
                joints.push((t.fixed_view::<3, 1>(0, 3).into_owned(), z, *prismatic));
                let mut mj = Matrix4::identity();
                if *prismatic {
                    mj.fixed_view_mut::<3, 1>(0, 3)
                        .copy_from(&(unit.into_inner() * q[k]));
                } else {
                    let r = Rotation3::from_axis_angle(&unit, q[k]);
                    mj.fixed_view_mut::<3, 3>(0, 0).copy_from(r.matrix());
                }
                t *= mj;
                k += 1;
            }
        }
        Pose { joints, tip: t }
    }

    /// Position \[m, base\] of a point `p` \[m, tip frame\] at joint values
    /// `q` (movable joints in chain order).
    pub fn point(&self, q: &[f64], p: &Vector3<f64>) -> Vector3<f64> {
        self.pose(q).point(p)
    }

    /// The loaded pose `θ = q + K τ(θ)` of the chain commanded to `q` with a
    /// mass `mass_kg` at `com` \[m, tip frame\] under gravity `g` \[m/s²,
    /// base\], joint `j` yielding by `k[j] τⱼ`: successive substitution until
    /// no joint moves by 1e-15 rad (or m).
    ///
    /// # Panics
    /// When 100 substitutions do not settle.
    pub fn loaded(
        &self,
        q: &[f64],
        k: &[f64],
        mass_kg: f64,
        com: &Vector3<f64>,
        g: &Vector3<f64>,
    ) -> Vec<f64> {
        let f = g * mass_kg;
        let mut theta = q.to_vec();
        for _ in 0..100 {
            let pose = self.pose(&theta);
            let tau = pose.torques(&f, &pose.point(com));
            let next: Vec<f64> = (0..q.len()).map(|j| q[j] + k[j] * tau[j]).collect();
            let step = next
                .iter()
                .zip(&theta)
                .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
            theta = next;
            if step < 1e-15 {
                return theta;
            }
        }
        panic!("the loaded robot did not settle");
    }
}

/// The paper's experiment as [`Kr270::csv`] builds it: the chain of
/// `data/kr270/kr270.urdf`, its markers and load centre of mass.
pub struct Kr270 {
    fk: Fk,
}

impl Default for Kr270 {
    fn default() -> Self {
        Self::new()
    }
}

impl Kr270 {
    /// Reads `data/kr270/kr270.urdf` (base `base_link`, tip `tool0`).
    pub fn new() -> Self {
        let urdf = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/kr270/kr270.urdf");
        Self {
            fk: Fk::new(&urdf, "base_link", "tool0"),
        }
    }

    /// The forward kinematics.
    pub fn fk(&self) -> &Fk {
        &self.fk
    }

    /// True compliance \[rad/(N·m)\] of a1…a6 in configuration `c` (0-based):
    /// Table 3's WLS values, A2's by its angle group, a1 rigid.
    pub fn compliance(c: usize) -> [f64; 6] {
        let group = kr270::q2_group(kr270::CONFIGURATIONS_DEG[c][1]).expect("a Table 2 angle");
        let v = kr270::WLS_VALUE;
        [0.0, v[group], v[5], v[6], v[7], v[8]].map(|k| k * 1e-6)
    }

    /// One measurement file of the experiment (the CSV text, units deg and
    /// mm as `data/kr270/setup.toml`), noise `noise` × Table 1, random
    /// numbers from `rng` in file order: per configuration the load, then
    /// per repetition and marker the unloaded and the loaded position (x, y,
    /// z each).
    pub fn csv(&self, rng: &mut SplitMix64, noise: f64) -> String {
        let mut out = String::from("config,rep,marker,load_kg,a1,a2,a3,a4,a5,a6,x,y,z\n");
        let com = Vector3::from(kr270::LOAD_COM_M);
        let g = Vector3::new(0.0, 0.0, -9.80665);
        for c in 0..kr270::CONFIGS {
            let q_deg = kr270::CONFIGURATIONS_DEG[c];
            let q: Vec<f64> = q_deg.iter().map(|d| d.to_radians()).collect();
            let (lo, hi) = kr270::LOAD_KG_RANGE;
            let load_kg = ((lo + (hi - lo) * rng.uniform()) * 10.0).round() / 10.0;
            let theta = self.fk.loaded(&q, &Self::compliance(c), load_kg, &com, &g);
            let (unloaded, loaded) = (self.fk.pose(&q), self.fk.pose(&theta));
            let sigma_m = Vector3::from(kr270::SIGMA_UM[c]) * (1e-6 * noise / 2f64.sqrt());
            let q_text: Vec<String> = q_deg.iter().map(|d| format!("{d}")).collect();
            for rep in 1..=kr270::REPS {
                for (mi, m) in kr270::MARKERS_M.iter().enumerate() {
                    let m = Vector3::from(*m);
                    for (mass, pose) in [(0.0, &unloaded), (load_kg, &loaded)] {
                        let p = pose.point(&m) + Vector3::from_fn(|a, _| rng.normal() * sigma_m[a]);
                        let _ = writeln!(
                            out,
                            "{},{rep},{},{mass},{},{:?},{:?},{:?}",
                            c + 1,
                            mi + 1,
                            q_text.join(","),
                            p.x * 1e3,
                            p.y * 1e3,
                            p.z * 1e3
                        );
                    }
                }
            }
        }
        out
    }
}
