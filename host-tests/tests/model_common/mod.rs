//! Independent reference model for the model tests: plain 4×4 homogeneous
//! matrices built from URDF xyz/rpy, Rodrigues rotations written out by
//! hand. Nothing here calls robcal's kinematics.
#![allow(dead_code)]

use nalgebra::{Matrix3, Matrix4, Vector3};
use robcal::{Chain, Joint, JointKind, LinkInertia};

/// One joint as URDF data.
#[derive(Clone, Copy, Debug)]
pub struct RefJoint {
    pub xyz: [f64; 3],
    pub rpy: [f64; 3],
    pub axis: [f64; 3],
    pub prismatic: bool,
    /// (mass kg, com in the joint frame m)
    pub link: Option<(f64, [f64; 3])>,
}

/// A serial robot as URDF data.
#[derive(Clone, Debug)]
pub struct RefRobot {
    pub joints: Vec<RefJoint>,
    pub tip_xyz: [f64; 3],
    pub tip_rpy: [f64; 3],
}

/// Errors applied in the reference model (all zero = nominal).
#[derive(Clone, Debug)]
pub struct Perturb {
    /// Per joint: (tx, ty, tz, rx, ry, rz) right-multiplying the origin.
    pub frame: Vec<[f64; 6]>,
    /// Base pose in the measurement frame (tx, ty, tz, rx, ry, rz).
    pub base: [f64; 6],
    /// Marker offset in the tip frame.
    pub marker: [f64; 3],
}

impl Perturb {
    pub fn zero(n: usize) -> Self {
        Self {
            frame: vec![[0.0; 6]; n],
            base: [0.0; 6],
            marker: [0.0; 3],
        }
    }
}

pub fn rot_x(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}
pub fn rot_y(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}
pub fn rot_z(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}
/// URDF rpy: `R = Rz(y) Ry(p) Rx(r)`.
pub fn rpy(r: [f64; 3]) -> Matrix3<f64> {
    rot_z(r[2]) * rot_y(r[1]) * rot_x(r[0])
}
/// Rodrigues: `R = I cos q + sin q [k]× + (1 − cos q) k kᵀ`.
pub fn axis_angle(k: Vector3<f64>, q: f64) -> Matrix3<f64> {
    let k = k / k.norm();
    let kx = Matrix3::new(0.0, -k.z, k.y, k.z, 0.0, -k.x, -k.y, k.x, 0.0);
    Matrix3::identity() * q.cos() + kx * q.sin() + k * k.transpose() * (1.0 - q.cos())
}
pub fn hom(r: Matrix3<f64>, t: Vector3<f64>) -> Matrix4<f64> {
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&t);
    m
}
pub fn v(a: [f64; 3]) -> Vector3<f64> {
    Vector3::new(a[0], a[1], a[2])
}
pub fn apply(m: &Matrix4<f64>, p: Vector3<f64>) -> Vector3<f64> {
    m.fixed_view::<3, 3>(0, 0) * p + m.fixed_view::<3, 1>(0, 3)
}
/// Small error transform `Trans(t) · Rz Ry Rx` (first order: any order).
pub fn err6(e: [f64; 6]) -> Matrix4<f64> {
    hom(rpy([e[3], e[4], e[5]]), Vector3::new(e[0], e[1], e[2]))
}

impl RefRobot {
    /// Joint frames `T_j` (after motion) and the tip frame, in the
    /// measurement frame.
    pub fn frames(&self, q: &[f64], pert: &Perturb) -> (Vec<Matrix4<f64>>, Matrix4<f64>) {
        let mut t = err6(pert.base);
        let mut out = Vec::new();
        for (j, (joint, &qj)) in self.joints.iter().zip(q).enumerate() {
            let origin = hom(rpy(joint.rpy), v(joint.xyz)) * err6(pert.frame[j]);
            let axis = v(joint.axis) / v(joint.axis).norm();
            let motion = if joint.prismatic {
                hom(Matrix3::identity(), axis * qj)
            } else {
                hom(axis_angle(axis, qj), Vector3::zeros())
            };
            t = t * origin * motion;
            out.push(t);
        }
        let tip = t * hom(rpy(self.tip_rpy), v(self.tip_xyz));
        (out, tip)
    }

    /// Marker position (marker in the tip frame, plus the perturbation).
    pub fn point(&self, q: &[f64], pert: &Perturb, marker: [f64; 3]) -> Vector3<f64> {
        let (_, tip) = self.frames(q, pert);
        apply(&tip, v(marker) + v(pert.marker))
    }

    /// The same robot as a robcal chain.
    pub fn chain<const J: usize>(&self) -> Chain<f64, J> {
        let mut c = Chain::new();
        for j in &self.joints {
            let kind = if j.prismatic {
                JointKind::Prismatic
            } else {
                JointKind::Revolute
            };
            let mut joint = Joint::from_urdf(v(j.xyz), v(j.rpy), v(j.axis), kind).unwrap();
            joint.link = j.link.map(|(m, c)| LinkInertia {
                mass_kg: m,
                com_m: v(c),
            });
            c.push(joint).unwrap();
        }
        c.set_tip(nalgebra::Isometry3::from_parts(
            v(self.tip_xyz).into(),
            nalgebra::UnitQuaternion::from_euler_angles(
                self.tip_rpy[0],
                self.tip_rpy[1],
                self.tip_rpy[2],
            ),
        ));
        c
    }
}

fn rj(xyz: [f64; 3], axis: [f64; 3], link: (f64, [f64; 3])) -> RefJoint {
    RefJoint {
        xyz,
        rpy: [0.0; 3],
        axis,
        prismatic: false,
        link: Some(link),
    }
}

/// The KR 270 R2700 ultra of `data/kr270/kr270.urdf` (tip = `tool0`),
/// typed in from the table of issue 3 (and the file's approximate masses).
pub fn kr270() -> RefRobot {
    RefRobot {
        joints: vec![
            rj(
                [0.0, 0.0, 0.675],
                [0.0, 0.0, -1.0],
                (330.0, [0.12, 0.0, -0.15]),
            ),
            rj(
                [0.350, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                (200.0, [0.55, 0.0, 0.05]),
            ),
            rj(
                [1.150, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                (160.0, [0.2, 0.0, -0.05]),
            ),
            rj(
                [1.200, 0.0, -0.041],
                [-1.0, 0.0, 0.0],
                (55.0, [-0.45, 0.0, 0.0]),
            ),
            rj([0.0, 0.0, 0.0], [0.0, 1.0, 0.0], (22.0, [0.1, 0.0, 0.0])),
            rj([0.240, 0.0, 0.0], [-1.0, 0.0, 0.0], (3.0, [0.01, 0.0, 0.0])),
        ],
        tip_xyz: [0.0; 3],
        tip_rpy: [0.0, std::f64::consts::FRAC_PI_2, 0.0],
    }
}

/// A 7-joint arm with a prismatic second joint and non-zero rpy everywhere.
pub fn arm7() -> RefRobot {
    let j = |xyz, rpy, axis, prismatic, m: f64| RefJoint {
        xyz,
        rpy,
        axis,
        prismatic,
        link: Some((m, [0.05, -0.02, 0.1])),
    };
    RefRobot {
        joints: vec![
            j(
                [0.0, 0.0, 0.3],
                [0.0, 0.0, 0.0],
                [0.0, 0.0, 1.0],
                false,
                8.0,
            ),
            j(
                [0.0, 0.0, 0.2],
                [0.1, -0.2, 0.3],
                [0.0, 0.0, 1.0],
                true,
                6.0,
            ),
            j(
                [0.1, 0.05, 0.4],
                [std::f64::consts::FRAC_PI_2, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                false,
                5.0,
            ),
            j(
                [0.0, 0.0, 0.35],
                [-std::f64::consts::FRAC_PI_2, 0.3, 0.0],
                [1.0, 1.0, 0.0],
                false,
                4.0,
            ),
            j(
                [0.02, 0.0, 0.3],
                [0.0, 0.0, 0.785],
                [0.0, 0.0, 1.0],
                false,
                3.0,
            ),
            j(
                [0.0, 0.1, 0.1],
                [0.2, 0.1, -0.4],
                [0.0, 1.0, 0.0],
                false,
                2.0,
            ),
            j(
                [0.0, 0.0, 0.12],
                [0.0, 0.0, 0.0],
                [0.0, 0.0, -1.0],
                false,
                1.0,
            ),
        ],
        tip_xyz: [0.01, 0.02, 0.1],
        tip_rpy: [0.1, 0.2, 0.3],
    }
}

/// The paper's 15 configurations (Table 2), degrees (data, shared with the
/// crate: not code under test).
pub const PAPER_Q_DEG: [[f64; 6]; 15] = robcal_paper::kr270::CONFIGURATIONS_DEG;

pub fn rad(q_deg: &[f64]) -> Vec<f64> {
    q_deg.iter().map(|d| d.to_radians()).collect()
}

/// Markers of our calibration tool (issue 3, our choice): on a 0.30 m circle
/// at z = 0.20 m in tool0, at 90°, 210°, 330°.
pub fn tool_markers() -> [[f64; 3]; 3] {
    let m = |deg: f64| {
        let a = deg.to_radians();
        [0.30 * a.cos(), 0.30 * a.sin(), 0.20]
    };
    [m(90.0), m(210.0), m(330.0)]
}

/// Load centre of mass in tool0 (issue 3, our choice).
pub const LOAD_COM: [f64; 3] = [0.25, 0.0, 0.30];

/// Arbitrary test poses for the 7-joint arm (prismatic joint in m).
pub fn arm7_poses() -> Vec<Vec<f64>> {
    vec![
        vec![0.3, 0.15, -0.7, 1.1, 0.4, -0.9, 2.0],
        vec![-1.2, 0.05, 0.9, -0.4, -1.3, 0.6, -0.5],
        vec![2.5, 0.3, 0.2, 0.8, 2.2, -1.7, 0.1],
    ]
}

pub fn assert_close(a: Vector3<f64>, b: Vector3<f64>, tol: f64, what: &str) {
    assert!(
        (a - b).norm() <= tol,
        "{what}: {a:?} vs {b:?} (|diff| = {:e}, tol {tol:e})",
        (a - b).norm()
    );
}

/// The vector `ω` of the skew part of `w` (`[ω]×` for a skew `w`).
pub fn vee(w: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(
        w[(2, 1)] - w[(1, 2)],
        w[(0, 2)] - w[(2, 0)],
        w[(1, 0)] - w[(0, 1)],
    ) * 0.5
}
