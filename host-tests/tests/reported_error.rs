//! The reported error is the model's error (issue 58): on every bundled
//! job, with the product's defaults (IRLS, the closed loop), the model as
//! it is written (`calibrate::validate`: the exact prediction that
//! `robcal predict` and `--validate` make from `model.json`'s model) predicts
//! the training rows themselves at the RMS the report gives, to 1e-6
//! relative — never the residuals of a linearised step it did not take.

mod tiago_common;

use std::path::{Path, PathBuf};

use robcal::calibrate::{self, Settings};
use robcal::io::{Job, Measurements};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The report's RMS against the model's own error on its training rows.
fn assert_own(job: &Job, data: &Measurements, what: &str) {
    assert_own_with(job, data, what, &Settings::default());
}

fn assert_own_with(job: &Job, data: &Measurements, what: &str, settings: &Settings) {
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

#[test]
fn justin() {
    real_set("justin", "dlr_justin", "train", "setup.toml");
}

#[test]
fn justin_with_masses() {
    real_set(
        "justin_with_masses",
        "dlr_justin",
        "train",
        "setup-masses.toml",
    );
}
