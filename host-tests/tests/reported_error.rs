//! The reported error is the model's error (issue 58): on every bundled
//! job, with the product's defaults (IRLS, the closed loop), the model as
//! it is written (`calibrate::validate`: the exact prediction that
//! `robcal predict` and `--validate` make from `model.json`'s model) predicts
//! the training rows themselves at the RMS the report gives, to 1e-6
//! relative — never the residuals of a linearised step it did not take.

use crate::tiago_common;

use std::path::{Path, PathBuf};

use robcal::calibrate::{self, Settings};
use robcal::io::{Job, Measurements};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The report's RMS against the model's own error on its training rows.
fn assert_own(job: &Job, data: &Measurements, what: &str) -> calibrate::Report {
    assert_own_with(job, data, what, &Settings::default())
}

fn assert_own_with(
    job: &Job,
    data: &Measurements,
    what: &str,
    settings: &Settings,
) -> calibrate::Report {
    let r = calibrate::calibrate(job, data, settings, &mut |_| {})
        .unwrap_or_else(|e| panic!("{what}: {e}"));
    let own_um = calibrate::validate(&r.model, job, data)
        .unwrap_or_else(|e| panic!("{what}: {e}"))
        .rms_mm
        * 1e3;
    let rel = (own_um - r.rms_um).abs() / r.rms_um;
    assert!(
        rel < 1e-6,
        "{what}: the model predicts its training rows at {own_um} um, the report says {} um",
        r.rms_um
    );
    assert!(r.failure.is_none(), "{what}: {:?}", r.failure);
    r
}

#[test]
fn kr270_both_setups() {
    for setup in ["setup.toml", "setup-naive.toml"] {
        let job = Job::load(root().join("data/kr270").join(setup)).unwrap();
        let data = job
            .read_measurements(root().join("data/kr270/measurements.csv"))
            .unwrap();
        assert_own(&job, &data, setup);
    }
}

#[test]
fn tiago_both_setups() {
    let Some(data) = tiago_common::data_or_skip("tiago_both_setups") else {
        return;
    };
    for setup in ["setup.toml", "setup-select.toml"] {
        let job = tiago_common::job(&data, setup);
        let m = tiago_common::import(&job, &data, tiago_common::TRAIN);
        assert_own(&job, &m, setup);
    }
}

/// The training split of a real data set, imported as `robcal import
/// poses` does, for `data/<set>/<setup>`.
fn real(data: &Path, set: &str, split: &str, setup: &str) -> (Job, Measurements) {
    let dir = tiago_common::temp_dir(set);
    let out = dir.join(format!("{set}-{split}.csv"));
    let options = robcal::io::poses::ImportOptions {
        split: Some(split.to_owned()),
        ..Default::default()
    };
    robcal::io::poses::import_poses(data.join(set).join(format!("{set}.csv")), &out, &options)
        .unwrap();
    let job = Job::load(root().join("data").join(set).join(setup)).unwrap();
    let m = job.read_measurements(&out).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    (job, m)
}

fn real_set(test: &str, set: &str, split: &str, setup: &str) {
    let Some(data) = host_tests::shared_or_skip("datasets", "abb_irb120/abb_irb120.csv", test)
    else {
        return;
    };
    let (job, m) = real(&data, set, split, setup);
    assert_own(&job, &m, &format!("{set}/{setup}"));
}

#[test]
fn abb() {
    real_set("abb", "abb_irb120", "cal", "setup.toml");
}

#[test]
fn motoman() {
    real_set("motoman", "ctu_motoman", "train", "setup.toml");
    real_set("motoman", "ctu_motoman", "train", "setup-instrument.toml");
}

/// DLR's Justin with `data/dlr_justin/<setup>` (a tree: a marker on each
/// hand, the torso shared) calibrated with the closed loop on the 300
/// training poses, validated on the 200 test poses as `--validate` does:
/// the model's own error, the effects added in order, and the pinned
/// numbers of docs/real-data.md \[mm\] (train RMS, test RMS, mean and max
/// per marker).
fn justin_pinned(
    test: &str,
    setup: &str,
    effects: &[(&str, &str)],
    want: [f64; 6],
) -> Option<calibrate::Report> {
    let data = host_tests::shared_or_skip("datasets", "dlr_justin/dlr_justin.csv", test)?;
    let (job, train) = real(&data, "dlr_justin", "train", setup);
    let (_, test_rows) = real(&data, "dlr_justin", "test", setup);
    let r = assert_own(&job, &train, &format!("dlr_justin/{setup}"));
    let added: Vec<(String, String)> = r
        .effects
        .iter()
        .map(|e| (e.effect.to_string(), e.joint.clone().unwrap_or_default()))
        .collect();
    let want_added: Vec<(String, String)> = effects
        .iter()
        .map(|(e, j)| (e.to_string(), j.to_string()))
        .collect();
    assert_eq!(added, want_added, "{setup}");
    let v = calibrate::validate(&r.model, &job, &test_rows).unwrap();
    assert_eq!(v.points, 400);
    let got = [
        r.rms_um / 1e3,
        v.rms_mm,
        v.per_marker_mean_mm["1"],
        v.per_marker_mean_mm["2"],
        v.per_marker_max_mm["1"],
        v.per_marker_max_mm["2"],
    ];
    let what = ["train rms", "rms", "mean 1", "mean 2", "max 1", "max 2"];
    for ((what, got), want) in what.iter().zip(got).zip(want) {
        assert!(
            (got - want).abs() < 1e-4,
            "{setup}: {what}: {got}, want {want}"
        );
    }
    Some(r)
}

/// The protocol of docs/real-data.md for DLR's Justin, pinned (evaluation
/// 4): `setup.toml`, the URDF without masses. The loop adds the lumped sag
/// under the robot's weight of both shoulders and the torso tilt, in this
/// order.
#[test]
fn justin() {
    justin_pinned(
        "justin",
        "setup.toml",
        &[
            ("gravity_compliance", "right_1"),
            ("gravity_compliance", "left_1"),
            ("gravity_compliance", "torso_2"),
            ("gravity_compliance", "torso_1"),
        ],
        [
            9.582442, 10.391965, 9.398570, 8.698781, 29.942461, 33.038176,
        ],
    );
}

/// Evaluation 6 of docs/real-data.md, pinned: `setup-masses.toml`, an
/// assumed mass model (`assumed_link_mass_kg`), under which the loop adds
/// the joints' compliances and the links' bending under the robot's own
/// weight; the report says the mass model was assumed.
#[test]
fn justin_with_masses() {
    let Some(r) = justin_pinned(
        "justin_with_masses",
        "setup-masses.toml",
        &[
            ("joint_compliance", "torso_1"),
            ("joint_compliance", "right_1"),
            ("joint_compliance", "left_1"),
            ("link_compliance", "right_1"),
            ("link_compliance", "left_1"),
            ("joint_compliance", "torso_3"),
            ("link_compliance", "torso_2"),
            ("gravity_compliance", "torso_2"),
        ],
        [4.405118, 4.729378, 4.316039, 4.212066, 10.400775, 13.119662],
    ) else {
        return;
    };
    let note = &r.notes[0];
    assert!(
        note.starts_with("assumed mass model") && note.contains("2 kg"),
        "{note}"
    );
}
