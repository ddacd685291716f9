//! A design that does not hold its columns (`Policy::max_held_design_rows`
//! below the rows: each pass that reads them computes them again from the
//! rows) gives the report of one that holds them, bit for bit: the closed
//! loop on the KR-270 (IRLS, deflections under load, the held-out error of
//! weighted fits) and on the TIAGo (effects tried on threads and added,
//! the exact deflection model), and OLS on 10 000 UR10 poses (blocks of the
//! views, several threads, the closed-form held-out error).

use std::path::{Path, PathBuf};

use crate::tiago_common;

use robcal::calibrate::{self, Method, Policy, Settings};
use robcal::io::Job;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The reports of `settings` with the designs held and not held, as text
/// (`{:?}` of every `f64` is its shortest round trip: the same text is the
/// same bits).
fn both(job: &Job, data: &robcal::io::Measurements, settings: Settings) -> (String, String) {
    let run = |max_held_design_rows| {
        let settings = Settings {
            policy: Policy {
                max_held_design_rows,
                ..settings.policy
            },
            ..settings
        };
        let r = calibrate::calibrate(job, data, &settings, &mut |_| {}).expect("calibration");
        // (The models carry the policy they were made with.)
        let text = format!("{r:?}");
        let policy = |n: usize| format!("max_held_design_rows: {n},");
        text.replace(&policy(max_held_design_rows), &policy(usize::MAX))
    };
    (run(usize::MAX), run(0))
}

/// Asserts that the reports are the same text, showing where they part.
fn same(held: &str, computed: &str) {
    if let Some(at) = held.bytes().zip(computed.bytes()).position(|(a, b)| a != b) {
        let from = at.saturating_sub(200);
        let part = |s: &str| {
            s.get(from..(at + 200).min(s.len()))
                .unwrap_or("")
                .to_string()
        };
        panic!("held: …{}…\nnot held: …{}…", part(held), part(computed));
    }
    assert_eq!(held.len(), computed.len());
}

#[test]
fn the_kr270_closed_loop_is_the_same() {
    let dir = root().join("data/kr270");
    let job = Job::load(dir.join("setup.toml")).expect("setup");
    let data = job
        .read_measurements(dir.join("measurements.csv"))
        .expect("measurements");
    let (held, computed) = both(&job, &data, Settings::default());
    assert!(held.contains("method: \"irls\"") && held.contains("heldout_rms_um: Some("));
    same(&held, &computed);
}

#[test]
fn the_tiago_closed_loop_is_the_same() {
    let Some(dir) = tiago_common::data_or_skip("the_tiago_closed_loop_is_the_same") else {
        return;
    };
    let job = tiago_common::job(&dir, "setup.toml");
    let data = tiago_common::import(&job, &dir, tiago_common::TRAIN);
    let (held, computed) = both(&job, &data, Settings::default());
    assert!(held.contains("effects: [") && !held.contains("effects: []"));
    same(&held, &computed);
}

#[test]
fn ten_thousand_ur10_poses_by_ols_are_the_same() {
    let shared = root().join("../shared/repro/ur10-offsets");
    if !shared.exists() {
        assert!(
            std::env::var_os("ROBCAL_REQUIRE_SHARED").is_none_or(|v| v != "1"),
            "shared/repro not found, and ROBCAL_REQUIRE_SHARED=1 (CI) requires it"
        );
        eprintln!("skipped: shared/repro is not beside the repository");
        return;
    }
    let csv = host_tests::arms::ur10_csv(&shared.join("ur10.urdf"), 10_000, 0x5552_3130);
    let file = std::env::temp_dir().join(format!("robcal-not-held-{}.csv", std::process::id()));
    std::fs::write(&file, csv).expect("write the poses");
    let job = Job::load(shared.join("setup-joint_offsets.toml")).expect("setup");
    let data = job
        .read_measurements(Path::new(&file))
        .expect("measurements");
    let _ = std::fs::remove_file(&file);
    let settings = Settings {
        method: Method::Ols,
        diagnose: false,
        ..Settings::default()
    };
    let (held, computed) = both(&job, &data, settings);
    assert!(held.contains("heldout_rms_um: Some("));
    same(&held, &computed);
}
