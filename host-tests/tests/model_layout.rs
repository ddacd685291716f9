//! Parameter layout, the combined row `B` (eq. 4) and the identifiability
//! report, on the KR-270 with the paper's 15 configurations (Table 2).

use crate::model_common;

use model_common::*;
use nalgebra::{Const, SMatrix, SVector, Vector3, U1};
use robcal::estimate::{
    identifiability, identifiability_excluding, IdentifiabilitySettings, Pivoting,
};
use robcal::model::{angle_urad, compliance_columns, Layout, Marker, Param, Sample};
use robcal::robot::{joint_torques, PointLoad};
use robcal::{Accumulator, Block, Chain, Error, Solution};

const Q2_BINS_DEG: [f64; 5] = [-0.01, -25.24, -56.9, -99.85, -140.0];

fn load(mass_kg: f64) -> PointLoad<f64> {
    PointLoad {
        mass_kg,
        com_m: v(LOAD_COM),
        gravity_mps2: Vector3::new(0.0, 0.0, -9.80665),
    }
}

fn markers() -> Vec<Marker<f64>> {
    tool_markers()
        .iter()
        .enumerate()
        .map(|(i, m)| Marker {
            index: i as u8,
            xyz_m: v(*m),
        })
        .collect()
}

/// The paper's model: k21…k25 (A2 by angle), k3…k6.
fn paper_layout(chain: &Chain<f64, 6>) -> Layout<9> {
    let mut l = Layout::new();
    for q2 in Q2_BINS_DEG {
        l.push(
            chain,
            Param::ComplianceAt {
                joint: 1,
                angle_urad: angle_urad(q2.to_radians()),
            },
        )
        .unwrap();
    }
    for joint in 2..6 {
        l.push(chain, Param::Compliance { joint }).unwrap();
    }
    l
}

/// Gravity \[m/s²\] in the base frame.
const G: [f64; 3] = [0.0, 0.0, -9.80665];

/// `B` of an absolute position measurement (geometric calibration, eq. 2)
/// of marker `m` at `q`: every parameter acts, the joints carry the robot's
/// own weight. (`Layout::block` builds a deflection: loaded minus unloaded
/// position at the same pose, where geometric parameters cancel.)
fn absolute_block<const N: usize, const M: usize>(
    layout: &Layout<N>,
    chain: &Chain<f64, 6>,
    q: &[f64],
    m: &Marker<f64>,
) -> SMatrix<f64, 3, M> {
    layout.absolute_block(chain, q, m, &v(G)).unwrap()
}

/// Λ of a layout over the paper's configurations and markers: deflections
/// under `load`, or absolute positions without one.
fn information<const N: usize>(
    layout: &Layout<N>,
    chain: &Chain<f64, 6>,
    load: Option<&PointLoad<f64>>,
) -> SMatrix<f64, N, N> {
    let mut acc = Accumulator::<f64, Const<N>>::new();
    for q in PAPER_Q_DEG.iter().map(|q| rad(q)) {
        for m in markers() {
            let b = match load {
                Some(l) => layout.block(chain, &q, &m, Some(l)).unwrap(),
                None => absolute_block(layout, chain, &q, &m),
            };
            acc.update(&Block::new(b, Vector3::zeros())).unwrap();
        }
    }
    acc.information()
}

#[test]
fn paper_experiment_rows_recover_the_compliances() {
    let chain: Chain<f64, 6> = kr270().chain();
    let layout = paper_layout(&chain);
    assert_eq!(layout.columns()[0].unit.name, "urad/(N*m)");
    assert_eq!(layout.columns()[0].unit.si, 1e-6);
    // Table 3, WLS, µrad/(N·m).
    let k = SVector::<f64, 9>::from_column_slice(&[
        0.287, 0.277, 0.302, 0.293, 0.246, 0.416, 2.786, 3.483, 2.074,
    ]);
    let load = load(270.0);
    let mut acc = Accumulator::<f64, Const<9>>::new();
    for (c, q) in PAPER_Q_DEG.iter().map(|q| rad(q)).enumerate() {
        let frames = chain.frames(&q).unwrap();
        let mut tau = [0.0; 6];
        joint_torques(&frames, &load.wrench(&frames), &mut tau).unwrap();
        for m in markers() {
            let b: SMatrix<f64, 3, 9> = layout.block(&chain, &q, &m, Some(&load)).unwrap();
            // The layout's columns are the SI columns times 1e-6 (µrad).
            let p = frames.point_m(&m.xyz_m);
            let mut si = [Vector3::zeros(); 6];
            compliance_columns(&frames, &p, &tau, &mut si).unwrap();
            let bin = c / 3; // three configurations per q2 value
            for i in 0..5 {
                let want = if i == bin {
                    si[1] * 1e-6
                } else {
                    Vector3::zeros()
                };
                assert_close(b.column(i).into_owned(), want, 1e-15, "k2 bin column");
            }
            for (j, col) in si.iter().enumerate().skip(2) {
                assert_close(b.column(3 + j).into_owned(), col * 1e-6, 1e-15, "k column");
            }
            acc.update(&Block::new(b, b * k)).unwrap();
        }
    }
    let sol = acc.solve().unwrap();
    assert!((sol.x - k).norm() < 1e-9 * k.norm(), "{:?}", sol.x);
    let report = identifiability(&acc.information(), &[true; 9], &Default::default()).unwrap();
    assert_eq!(report.rank(), 9);
    assert_eq!(report.left_out().count(), 0);
}

#[test]
fn vertical_load_leaves_a1_compliance_unidentifiable() {
    let chain: Chain<f64, 6> = kr270().chain();
    let mut layout = Layout::<6>::new();
    for joint in 0..6 {
        layout.push(&chain, Param::Compliance { joint }).unwrap();
    }
    let lambda = information(&layout, &chain, Some(&load(270.0)));
    for pivoting in [Pivoting::LayoutOrder, Pivoting::Largest] {
        let settings = IdentifiabilitySettings {
            pivoting,
            ..Default::default()
        };
        let report = identifiability(&lambda, &[true; 6], &settings).unwrap();
        assert_eq!(
            report.kept.as_slice(),
            [false, true, true, true, true, true]
        );
        assert!(report.is_left_out(0));
        assert!(
            report.absorbed_by(0).is_empty(),
            "no information, nothing absorbs it"
        );
        assert_eq!(report.residual(0), 0.0);
        assert_eq!(report.left_out().collect::<Vec<_>>(), [0]);
    }
    // And the solve on the kept set works.
    let report = identifiability(&lambda, &[true; 6], &Default::default()).unwrap();
    assert!(Solution::new(&lambda, &SVector::zeros(), 0.0, 270, report.kept.as_slice()).is_ok());
}

#[test]
fn a1_offset_is_absorbed_by_base_yaw() {
    let chain: Chain<f64, 6> = kr270().chain();
    let mut layout = Layout::<12>::new();
    for axis in 0..6 {
        layout.push(&chain, Param::Base { axis }).unwrap();
    }
    for joint in 0..6 {
        layout.push(&chain, Param::JointOffset { joint }).unwrap();
    }
    let yaw = layout.index_of(&Param::Base { axis: 5 }).unwrap();
    let a1 = layout.index_of(&Param::JointOffset { joint: 0 }).unwrap();
    let lambda = information(&layout, &chain, None);
    // Layout order: the base comes first, so a1's offset is the one dropped.
    let report = identifiability(&lambda, &[true; 12], &Default::default()).unwrap();
    assert_eq!(report.rank(), 11);
    assert!(report.is_left_out(a1));
    assert!(report.residual(a1) < 1e-10);
    // a1's axis is −z through the base origin: its offset column is minus
    // the base yaw column, both in mrad.
    let absorbed = report.absorbed_by(a1);
    let top = absorbed[0];
    assert_eq!(top.param, yaw);
    assert!((top.coefficient + 1.0).abs() < 1e-8, "{top:?}");
    assert_eq!(absorbed.len(), 1, "{absorbed:?}");
    // Largest-pivot order drops one of the two and names the other.
    let s = IdentifiabilitySettings {
        pivoting: Pivoting::Largest,
        ..Default::default()
    };
    let report = identifiability(&lambda, &[true; 12], &s).unwrap();
    assert_eq!(report.rank(), 11);
    let left: Vec<usize> = report.left_out().collect();
    assert_eq!(left.len(), 1);
    let d = left[0];
    let other = if d == a1 { yaw } else { a1 };
    assert!(d == a1 || d == yaw);
    let absorbed = report.absorbed_by(d);
    assert_eq!(absorbed[0].param, other);
    assert!((absorbed[0].scaled + 1.0).abs() < 1e-8);
    // Without the base yaw among the candidates the offset is identifiable.
    let mut cand = [true; 12];
    cand[yaw] = false;
    let report = identifiability(&lambda, &cand, &Default::default()).unwrap();
    assert_eq!(report.rank(), 11);
    assert_eq!(report.left_out().count(), 0);
    assert!(!report.kept[yaw]);
    assert!(
        !report.is_left_out(yaw),
        "not a candidate: neither kept nor left out"
    );
}

#[test]
fn marker_columns_only_for_their_marker_and_bins_must_match() {
    let chain: Chain<f64, 6> = kr270().chain();
    let mut layout = Layout::<4>::new();
    // The second marker (indices count from 0).
    layout
        .push(&chain, Param::Marker { marker: 1, axis: 0 })
        .unwrap();
    layout
        .push(
            &chain,
            Param::ComplianceAt {
                joint: 1,
                angle_urad: angle_urad(-0.01f64.to_radians()),
            },
        )
        .unwrap();
    let q = rad(&PAPER_Q_DEG[0]);
    let ms = markers();
    // Absolute positions: the marker parameter acts on its own marker, the
    // compliance under the robot's own weight.
    let b1: SMatrix<f64, 3, 4> = absolute_block(&layout, &chain, &q, &ms[0]);
    let b2: SMatrix<f64, 3, 4> = absolute_block(&layout, &chain, &q, &ms[1]);
    assert_eq!(b1.column(0).norm(), 0.0);
    assert!(
        (b2.column(0).norm() - 1e-3).abs() < 1e-15,
        "a mm of marker moves it a mm"
    );
    assert!(b1.column(1).norm() > 0.0);
    assert_eq!(
        b1.column(2).norm() + b1.column(3).norm(),
        0.0,
        "columns past the layout"
    );
    // Deflections under a load: the marker's position cancels, the
    // compliance under the load acts.
    let l = load(100.0);
    let d2: SMatrix<f64, 3, 4> = layout.block(&chain, &q, &ms[1], Some(&l)).unwrap();
    assert_eq!(d2.column(0).norm(), 0.0, "geometry cancels in a deflection");
    assert!(d2.column(1).norm() > 0.0);
    // q2 = −25.24°: no bin of joint 1 matches.
    let q4 = rad(&PAPER_Q_DEG[3]);
    let mut b = SMatrix::<f64, 3, 4>::repeat(7.0);
    let frames = chain.frames(&q4).unwrap();
    let sample = Sample::deflection(
        &frames,
        frames.point_m(&ms[0].xyz_m),
        ms[0].index,
        &[0.0; 6],
        None,
    );
    assert!(matches!(
        layout.fill(&sample, &mut b),
        Err(Error::Mismatch { .. })
    ));
    assert_eq!(b, SMatrix::<f64, 3, 4>::repeat(7.0), "unchanged on error");
    // A layout wider than B.
    assert!(layout
        .block::<f64, 6, U1>(&chain, &q, &ms[0], None)
        .is_err());
}

#[test]
fn push_validates() {
    let chain: Chain<f64, 6> = kr270().chain();
    let mut layout = Layout::<2>::new();
    assert!(matches!(
        layout.push(&chain, Param::JointOffset { joint: 6 }),
        Err(Error::OutOfRange { .. })
    ));
    assert!(matches!(
        layout.push(&chain, Param::Base { axis: 6 }),
        Err(Error::OutOfRange { .. })
    ));
    assert!(matches!(
        layout.push(&chain, Param::Marker { marker: 0, axis: 3 }),
        Err(Error::OutOfRange { .. })
    ));
    assert_eq!(
        layout.push(&chain, Param::JointFrame { joint: 2, axis: 4 }),
        Ok(0)
    );
    assert_eq!(layout.columns()[0].unit.name, "mrad");
    assert_eq!(layout.columns()[0].unit.si, 1e-3);
    assert!(matches!(
        layout.push(&chain, Param::JointFrame { joint: 2, axis: 4 }),
        Err(Error::Mismatch { .. })
    ));
    assert_eq!(layout.push(&chain, Param::Compliance { joint: 5 }), Ok(1));
    assert!(matches!(
        layout.push(&chain, Param::Base { axis: 0 }),
        Err(Error::CapacityExceeded { .. })
    ));
    assert_eq!(layout.len(), 2);
    // Generic names with joint indices (the host names them after the
    // URDF's joints instead).
    assert_eq!(format!("{}", layout.columns()[0].param), "j2.ry");
    assert_eq!(format!("{}", layout.columns()[1].param), "k_j5");
    assert_eq!(
        format!(
            "{}",
            Param::ComplianceAt {
                joint: 1,
                angle_urad: angle_urad(-25.24f64.to_radians())
            }
        ),
        "k_j1@-25.24deg"
    );
    // Prismatic joints get length units.
    let arm: Chain<f64, 7> = arm7().chain();
    let mut l = Layout::<2>::new();
    l.push(&arm, Param::JointOffset { joint: 1 }).unwrap();
    l.push(&arm, Param::Compliance { joint: 1 }).unwrap();
    assert_eq!(
        (l.columns()[0].unit.name, l.columns()[1].unit.name),
        ("mm", "um/N")
    );
}

#[test]
fn identifiability_rejects_non_finite_information() {
    let mut lambda = SMatrix::<f64, 2, 2>::identity();
    lambda[(0, 1)] = f64::NAN;
    assert!(identifiability(&lambda, &[true; 2], &Default::default()).is_err());
}

/// The default tolerance of the identifiability test is
/// `independence_tolerance()` = 1e-6 in f64, a margin of ~64 over the
/// solver's `√ε` (1.5e-8): a parameter whose column is explained to
/// `1 − R²` = 1e-7 by the others is left out by default, though the solver
/// would still take it. Candidates not passed are ignored; a mask of the
/// wrong length is a `Mismatch`.
#[test]
fn identifiability_tolerance_has_a_margin_over_the_solver() {
    use robcal::estimate::{independence_tolerance, pivot_tolerance};
    assert_eq!(independence_tolerance::<f64>(), 1e-6);
    let settings = IdentifiabilitySettings::<f64>::default();
    assert_eq!(settings.tolerance, 1e-6);
    assert_eq!(settings.negligible, f64::EPSILON * f64::EPSILON);
    // Columns with correlation c, 1 − c² = 1e-7 (scaled: unit diagonal).
    let c = (1.0 - 1e-7f64).sqrt();
    let lambda = SMatrix::<f64, 3, 3>::new(1.0, c, 0.0, c, 1.0, 0.0, 0.0, 0.0, 4.0);
    let r = identifiability(&lambda, &[true; 3], &settings).unwrap();
    assert_eq!(r.kept.as_slice(), [true, false, true]);
    assert!((r.residual(1) - 1e-7).abs() < 1e-12, "{}", r.residual(1));
    assert_eq!(r.absorbed_by(1)[0].param, 0);
    // At the solver's own tolerance it is kept, and the solver takes it.
    let at_solver = IdentifiabilitySettings {
        tolerance: pivot_tolerance::<f64>(),
        ..settings
    };
    let r = identifiability(&lambda, &[true; 3], &at_solver).unwrap();
    assert_eq!(r.rank(), 3);
    assert!(Solution::new(&lambda, &SVector::zeros(), 0.0, 9, &[true; 3]).is_ok());
    // Not a candidate: neither kept nor left out.
    let r = identifiability(&lambda, &[true, false, true], &settings).unwrap();
    assert_eq!(r.kept.as_slice(), [true, false, true]);
    assert!(!r.is_left_out(1));
    assert!(matches!(
        identifiability(&lambda, &[true; 2], &settings),
        Err(Error::Mismatch { .. })
    ));
}

#[test]
fn f32_rows_agree_with_f64() {
    let chain64: Chain<f64, 6> = kr270().chain();
    let mut chain32 = Chain::<f32, 6>::new();
    for j in chain64.joints() {
        let mut jj = robcal::Joint::from_urdf(
            j.origin.translation.vector.cast::<f32>(),
            Vector3::zeros(),
            j.axis.into_inner().cast::<f32>(),
            j.kind,
        )
        .unwrap();
        jj.link = None;
        chain32.push(jj).unwrap();
    }
    chain32.set_tip(chain64.tip().cast::<f32>());
    let layout = paper_layout(&chain64);
    let l32 = PointLoad {
        mass_kg: 270.0f32,
        com_m: v(LOAD_COM).cast(),
        gravity_mps2: Vector3::new(0.0, 0.0, -9.80665f32),
    };
    let m = markers()[0];
    let m32 = Marker {
        index: m.index,
        xyz_m: m.xyz_m.cast::<f32>(),
    };
    let q = rad(&PAPER_Q_DEG[7]);
    let q32: Vec<f32> = q.iter().map(|&x| x as f32).collect();
    let b64: SMatrix<f64, 3, 9> = layout.block(&chain64, &q, &m, Some(&load(270.0))).unwrap();
    let b32: SMatrix<f32, 3, 9> = layout.block(&chain32, &q32, &m32, Some(&l32)).unwrap();
    // f32 rounding, relative ~1e-6 on columns of ~1e-2 m.
    assert!((b32.cast::<f64>() - b64).norm() < 1e-5 * b64.norm());
    let mut acc = Accumulator::<f32, Const<9>>::new();
    acc.update(&Block::new(b32, Vector3::zeros())).unwrap();
    let r = identifiability(&acc.information(), &[true; 9], &Default::default()).unwrap();
    assert!(r.rank() <= 3, "one marker, three rows");
}

#[test]
fn frame_rotation_about_the_joint_axis_is_absorbed_by_the_offset() {
    // Offsets first, then the six frame errors of every joint: 42 candidates.
    let robot = kr270();
    let chain: Chain<f64, 6> = robot.chain();
    let mut layout = Layout::<42>::new();
    for joint in 0..6 {
        layout.push(&chain, Param::JointOffset { joint }).unwrap();
    }
    for joint in 0..6 {
        for axis in 0..6 {
            layout
                .push(&chain, Param::JointFrame { joint, axis })
                .unwrap();
        }
    }
    let lambda = information(&layout, &chain, None);
    let report = identifiability(&lambda, &[true; 42], &Default::default()).unwrap();
    assert!(report.rank() < 42);
    for (j, rj) in robot.joints.iter().enumerate() {
        // Every KR-270 axis is ± a coordinate axis of its joint frame.
        let (k, sign) = rj
            .axis
            .iter()
            .enumerate()
            .find(|(_, a)| **a != 0.0)
            .map(|(k, a)| (k, a.signum()))
            .unwrap();
        let rot = layout
            .index_of(&Param::JointFrame {
                joint: j as u8,
                axis: 3 + k as u8,
            })
            .unwrap();
        assert!(report.is_left_out(rot), "joint {j} rotation kept");
        assert!(report.residual(rot) < 1e-10);
        // Rotating the frame about its axis by δ is the offset δ·sign.
        let absorbed = report.absorbed_by(rot);
        assert_eq!(absorbed.len(), 1, "{absorbed:?}");
        assert_eq!(absorbed[0].param, j);
        assert!((absorbed[0].coefficient - sign).abs() < 1e-8);
    }
}

#[test]
fn linear_model_under_the_full_paper_load() {
    // Not a tolerance of the library but a fact for users: at the paper's
    // 270 kg the exact deflection p(q + kτ) − p(q) differs from the linear
    // model (eq. 3) by second-order terms in the joint deflections kτ (a few
    // mrad).
    let robot = kr270();
    let chain: Chain<f64, 6> = robot.chain();
    let k = [0.5e-6, 0.287e-6, 0.416e-6, 2.786e-6, 3.483e-6, 2.074e-6];
    let zero = Perturb::zero(6);
    let l = load(270.0);
    let mut worst: f64 = 0.0;
    for q in PAPER_Q_DEG.iter().map(|q| rad(q)) {
        let frames = chain.frames(&q).unwrap();
        let mut tau = [0.0; 6];
        joint_torques(&frames, &l.wrench(&frames), &mut tau).unwrap();
        for m in tool_markers() {
            let p = frames.point_m(&v(m));
            let lin = robcal::model::deflection_m(&frames, &p, &tau, &k).unwrap();
            let qd: Vec<f64> = q
                .iter()
                .zip(&tau)
                .zip(&k)
                .map(|((q, t), k)| q + k * t)
                .collect();
            let exact = robot.point(&qd, &zero, m) - robot.point(&q, &zero, m);
            worst = worst.max((lin - exact).norm() / exact.norm());
        }
    }
    // Observed 0.26 %; bounded at 1 % so a real regression still shows.
    assert!(worst < 0.01, "worst relative linearisation error {worst}");
    eprintln!("worst relative linearisation error at 270 kg: {worst:.2e}");
}

#[test]
fn an_excluded_column_is_left_out_with_its_absorbers() {
    // Column 2 is columns 0 and 1 summed plus 1 % of its own: a pivot of
    // ~1e-4, kept by Λ; a caller whose test of the columns themselves found
    // it dependent excludes it, and it is reported left out, absorbed by
    // the two it leans on, the others kept.
    let cols = [
        [1.0, 0.2, 0.0, 0.3],
        [0.1, 1.0, 0.4, 0.0],
        [1.1, 1.2, 0.41, 0.3],
    ];
    let mut b = SMatrix::<f64, 4, 3>::zeros();
    for (j, c) in cols.iter().enumerate() {
        for (i, v) in c.iter().enumerate() {
            b[(i, j)] = *v;
        }
    }
    b[(3, 2)] += 0.01;
    let lambda = b.transpose() * b;
    let s = IdentifiabilitySettings::default();
    let plain = identifiability(&lambda, &[true; 3], &s).unwrap();
    assert_eq!(plain.rank(), 3);
    let none = identifiability_excluding(&lambda, &[true; 3], &[], &s).unwrap();
    assert_eq!(none, plain);
    let r = identifiability_excluding(&lambda, &[true; 3], &[false, false, true], &s).unwrap();
    assert_eq!(r.rank(), 2);
    assert_eq!(r.left_out().collect::<Vec<_>>(), [2]);
    let by: Vec<usize> = r.absorbed_by(2).iter().map(|a| a.param).collect();
    assert!(by.contains(&0) && by.contains(&1), "{by:?}");
    assert!(matches!(
        identifiability_excluding(&lambda, &[true; 3], &[true], &s),
        Err(Error::Mismatch { .. })
    ));
}

/// The rotation of the tip frame of `robot` at `q` under `pert`, with the
/// tool's small rotation `tool_rad` (tip frame) after it.
fn tip_rotation(
    robot: &RefRobot,
    q: &[f64],
    pert: &Perturb,
    tool_rad: Vector3<f64>,
) -> nalgebra::Matrix3<f64> {
    let (_, tip) = robot.frames(q, pert);
    tip.fixed_view::<3, 3>(0, 0).into_owned()
        * nalgebra::Rotation3::from_scaled_axis(tool_rad).into_inner()
}

/// The turn `ω` [rad per unit] of the frame `r(h)` at `h = 0`, by central
/// differences: `[ω]× = ṙ rᵀ`.
fn turn_fd(r: impl Fn(f64) -> nalgebra::Matrix3<f64>) -> Vector3<f64> {
    const H: f64 = 1e-6;
    vee(&((r(H) - r(-H)) / (2.0 * H) * r(0.0).transpose()))
}

fn orientation_case<const J: usize>(robot: &RefRobot, poses: &[Vec<f64>]) {
    let chain: Chain<f64, J> = robot.chain();
    let n = robot.joints.len();
    let mut layout = Layout::<32>::new();
    for joint in 0..n as u8 {
        layout.push(&chain, Param::JointOffset { joint }).unwrap();
    }
    for axis in 0..6 {
        layout
            .push(&chain, Param::JointFrame { joint: 1, axis })
            .unwrap();
        layout.push(&chain, Param::Base { axis }).unwrap();
        layout.push(&chain, Param::Tool { axis }).unwrap();
    }
    for axis in 0..3 {
        layout
            .push(&chain, Param::Marker { marker: 0, axis })
            .unwrap();
    }
    layout.push(&chain, Param::Compliance { joint: 2 }).unwrap();
    let marker = Marker {
        index: 0,
        xyz_m: Vector3::new(0.12, -0.07, 0.2),
    };
    let zero = Perturb::zero(n);
    for q in poses {
        let b: SMatrix<f64, 3, 32> = layout.orientation_block(&chain, q, &marker, &v(G)).unwrap();
        let frames = chain.frames(q).unwrap();
        let mut tau = [0.0; J];
        robcal::robot::gravity_torques(&chain, &frames, &v(G), &mut tau).unwrap();
        let offset = |j: usize| {
            turn_fd(|h| {
                let mut qq = q.clone();
                qq[j] += h;
                tip_rotation(robot, &qq, &zero, Vector3::zeros())
            })
        };
        for (i, c) in layout.columns().iter().enumerate() {
            let perturbed = |f: &dyn Fn(&mut Perturb, f64)| {
                turn_fd(|h| {
                    let mut pert = Perturb::zero(n);
                    f(&mut pert, h);
                    tip_rotation(robot, q, &pert, Vector3::zeros())
                })
            };
            let want = match c.param {
                Param::JointOffset { joint } => offset(usize::from(joint)),
                Param::JointFrame { joint, axis } => perturbed(&|p, h| {
                    p.frame[usize::from(joint)][usize::from(axis)] = h;
                }),
                Param::Base { axis } => perturbed(&|p, h| p.base[usize::from(axis)] = h),
                Param::Tool { axis } if axis >= 3 => turn_fd(|h| {
                    let mut w = Vector3::zeros();
                    w[usize::from(axis) - 3] = h;
                    tip_rotation(robot, q, &zero, w)
                }),
                Param::Tool { .. } | Param::Marker { .. } => Vector3::zeros(),
                // δqⱼ = kⱼ τⱼ (eq. 3): the offset's turn per unit of yield.
                Param::Compliance { joint } => offset(usize::from(joint)) * tau[usize::from(joint)],
                p => panic!("no reference for {p:?}"),
            } * c.unit.si;
            let got = b.column(i).into_owned();
            assert!(
                (got - want).norm() <= 1e-8 * want.norm().max(c.unit.si),
                "{:?} at {q:?}: {got} vs {want}",
                c.param
            );
        }
    }
}

/// A 6-D pose's orientation rows on the device (`Layout::orientation_block`)
/// are the turn of the tip frame (turned by the tool's) per unit of each
/// parameter, against central differences of the independent 4×4 model:
/// joint offsets, a joint's frame errors, the base, the tool's rotation, a
/// compliance's yield under the own weight; a marker's position and the
/// tool's translation turn nothing. KR-270 at the paper's configurations,
/// and a 7-joint arm.
#[test]
fn orientation_rows_are_the_turn_of_the_frame() {
    orientation_case::<6>(
        &kr270(),
        &PAPER_Q_DEG.iter().map(|q| rad(q)).collect::<Vec<_>>(),
    );
    orientation_case::<7>(&arm7(), &arm7_poses());
}
