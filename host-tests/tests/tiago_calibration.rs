//! TIAGo motion-capture calibration against FIGAROH's published results
//! (issue 7, docs/tiago.md) through the product, reading
//! `shared/datasets/tiago-mocap` beside the repository (skipped, with the
//! reason, when it is absent).
//!
//! - FIGAROH's table: registration, joint offsets and full joint-frame
//!   errors, fitted by `robcal::calibrate` (OLS, no diagnosis) on point BL
//!   and on all four points, evaluated by `robcal::calibrate::validate` on
//!   both days. Registration and joint offsets on BL reproduce FIGAROH's
//!   published numbers to their printed 0.01 mm.
//! - The registration against the oracle: forward kinematics from the
//!   URDF text and a rigid registration by SVD (no robcal code) give the
//!   product's registration-only error to 1 nm.
//!
//! The closed loop's protocol run is pinned in `tests/cli/tiago.rs`.
//! Everything is deterministic (Gauss–Newton to a 1 nm / 1 µrad step), so
//! the pinned numbers have a rounding tolerance only: [`TOL_MM`].

use crate::tiago_common;

use host_tests::exact::Fk;
use nalgebra::Vector3;
use robcal::io::{GeometryModel, MarkerModel};
use tiago_common::*;

/// Rounding tolerance of the pinned RMSE values [mm]: they are pinned to
/// three decimals.
const TOL_MM: f64 = 0.0015;

fn near(what: &str, got: f64, want: f64, tol: f64) {
    assert!(
        (got - want).abs() <= tol,
        "{what}: {got:.4} mm, expected {want} ± {tol}"
    );
}

/// (model, points, parameters, BL train, BL valid, all train, all valid) [mm].
type Line = (Model, &'static [u32], usize, f64, f64, f64, f64);

const TABLE: [Line; 6] = [
    (
        Model::Registration,
        &[1],
        9,
        3.368,
        4.875,
        f64::NAN,
        f64::NAN,
    ),
    (Model::Offsets, &[1], 14, 2.876, 4.229, f64::NAN, f64::NAN),
    (Model::Full, &[1], 33, 1.591, 4.172, f64::NAN, f64::NAN),
    (
        Model::Registration,
        &[1, 2, 3, 4],
        18,
        3.528,
        4.971,
        4.086,
        6.388,
    ),
    (
        Model::Offsets,
        &[1, 2, 3, 4],
        23,
        2.916,
        4.116,
        3.234,
        4.845,
    ),
    (Model::Full, &[1, 2, 3, 4], 42, 1.842, 3.610, 2.187, 4.201),
];

/// FIGAROH's published BL norm RMSE (training, validation) [mm]:
/// registration (9 parameters), joint offsets (14), full (31).
const FIGAROH: [(f64, f64); 3] = [(3.37, 4.87), (2.88, 4.23), (1.64, 3.07)];

#[test]
fn figaroh_table_through_the_product() {
    let Some(data) = data_or_skip("figaroh_table_through_the_product") else {
        return;
    };
    let job = job(&data, "setup.toml");
    let train = import(&job, &data, TRAIN);
    let valid = import(&job, &data, VALID);
    let bl = BL.to_string();
    for (k, &(model, points, params, tr, va, tra, vaa)) in TABLE.iter().enumerate() {
        let what = format!("{} [{points:?}]", model.name());
        let j = variant(&job, model, points);
        let (t, v) = (only(&train, points), only(&valid, points));
        let r = fit_ols(&j, &t);
        println!(
            "{what}: {} parameters, left out {:?}",
            r.parameters.len(),
            r.left_out.iter().map(|l| l.line()).collect::<Vec<_>>()
        );
        assert_eq!(r.parameters.len(), params, "{what}");
        let (ptr, atr) = rmse_mm(&r, &j, &t);
        let (pva, ava) = rmse_mm(&r, &j, &v);
        near(&format!("{what} BL train"), ptr[&bl], tr, TOL_MM);
        near(&format!("{what} BL valid"), pva[&bl], va, TOL_MM);
        if points.len() > 1 {
            near(&format!("{what} all train"), atr, tra, TOL_MM);
            near(&format!("{what} all valid"), ava, vaa, TOL_MM);
        }
        // Same data, same models: registration and joint offsets on BL
        // reproduce FIGAROH's numbers (printed to 0.01 mm).
        if k < 2 {
            near("FIGAROH training", ptr[&bl], FIGAROH[k].0, 0.005 + 1e-9);
            near("FIGAROH validation", pva[&bl], FIGAROH[k].1, 0.005 + 1e-9);
        }
    }
}

/// The registration of the nominal robot (base frame only, points as
/// declared): the product's Gauss–Newton against the oracle's forward
/// kinematics and closed-form rigid registration.
#[test]
fn registration_matches_the_oracle() {
    let Some(data) = data_or_skip("registration_matches_the_oracle") else {
        return;
    };
    let mut job = job(&data, "setup.toml");
    job.setup.model.geometry = GeometryModel::None;
    job.setup.model.markers = MarkerModel::Nominal;
    job.setup.model.base_frame = true;
    let train = import(&job, &data, TRAIN);
    let r = fit_ols(&job, &train);
    assert_eq!(r.parameters.len(), 6);

    let fk = Fk::new(&data.join(URDF), "base_link", "wrist_ft_tool_link");
    let markers: Vec<(u32, Vector3<f64>)> = job
        .setup
        .markers
        .iter()
        .map(|m| (m.id, Vector3::from(m.xyz)))
        .collect();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for o in &train.observations {
        let m = markers.iter().find(|m| m.0 == o.marker).unwrap().1;
        a.push(fk.point(&o.q, &m));
        b.push(Vector3::from(o.p_m));
    }
    let (rot, t) = kabsch(&a, &b);
    let ss: f64 = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (rot * x + t - y).norm_squared())
        .sum();
    let oracle_um = (ss / a.len() as f64).sqrt() * 1e6;
    println!(
        "registration RMS: product {:.6} um, oracle {oracle_um:.6} um",
        r.rms_um
    );
    assert!(
        (r.rms_um - oracle_um).abs() < 1e-3,
        "{} vs {oracle_um}",
        r.rms_um
    );
    // With the points as declared (rounded to the millimetre): 4.122 mm.
    near(
        "registration, nominal points, training",
        r.rms_um * 1e-3,
        4.122,
        TOL_MM,
    );
}
