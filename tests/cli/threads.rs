//! The engine's worker threads change no answer (issue 16): `robcal
//! calibrate` with `ROBCAL_THREADS=1` (everything on the calling thread)
//! and with more threads writes the same report, byte for byte, and the
//! same progress messages in the same order. On TIAGo this covers the
//! candidates' trials side by side (`calibrate::trial`: several rejected
//! before one is added), which give the serial loop's answers only because
//! every trial starts from the current model's rows bit for bit.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn robcal(threads: usize, args: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_robcal"))
        .current_dir(root())
        .env("ROBCAL_THREADS", threads.to_string())
        .args(args)
        .output()
        .expect("run robcal");
    assert!(
        out.status.success(),
        "robcal failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The same stdout and stderr with 1, 2 and 3 threads.
fn same_with_threads(args: &[&str]) {
    let serial = robcal(1, args);
    for threads in [2, 3] {
        let out = robcal(threads, args);
        assert!(
            out.stdout == serial.stdout,
            "{threads} threads: another report"
        );
        assert_eq!(
            String::from_utf8_lossy(&out.stderr),
            String::from_utf8_lossy(&serial.stderr),
            "{threads} threads: other progress messages"
        );
    }
}

#[test]
fn kr270_irls_is_the_same_on_any_number_of_threads() {
    same_with_threads(&[
        "calibrate",
        "--json",
        "--setup",
        "data/kr270/setup.toml",
        "--data",
        "data/kr270/measurements.csv",
        "--method",
        "irls",
    ]);
}

/// `shared/datasets/tiago-mocap` beside the repository, else in the
/// nearest ancestor that has it (a nested git worktree).
fn tiago_data() -> Option<PathBuf> {
    root()
        .ancestors()
        .skip(1)
        .map(|a| a.join("shared/datasets/tiago-mocap"))
        .find(|d| d.join("tiago_48_schunk.urdf").exists())
}

/// `data/tiago/<name>` naming the URDF found by [`tiago_data`], in `dir`.
fn tiago_setup(dir: &Path, data: &Path, name: &str) -> PathBuf {
    let text = std::fs::read_to_string(root().join("data/tiago").join(name)).unwrap();
    let text = text.replace(
        "../../../shared/datasets/tiago-mocap/tiago_48_schunk.urdf",
        &data.join("tiago_48_schunk.urdf").to_string_lossy(),
    );
    let copy = dir.join(name);
    std::fs::write(&copy, text).unwrap();
    copy
}

#[test]
fn tiago_closed_loop_is_the_same_on_any_number_of_threads() {
    let Some(data) = tiago_data() else {
        if std::env::var_os("ROBCAL_REQUIRE_SHARED").is_some_and(|v| v == "1") {
            panic!("shared/datasets/tiago-mocap not found, and ROBCAL_REQUIRE_SHARED=1 (CI) requires it");
        }
        use std::io::Write as _;
        let _ = writeln!(
            std::io::stderr(),
            "skipped tiago_closed_loop_is_the_same_on_any_number_of_threads: \
             shared/datasets/tiago-mocap not found beside the repository (CI has it)"
        );
        return;
    };
    let dir = std::env::temp_dir().join(format!("robcal-cli-threads-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("d30.csv");
    let input = data.join("qualisys_2021-11-30_static_postures.csv");
    robcal(
        1,
        &[
            "import",
            "figaroh-mocap",
            input.to_str().unwrap(),
            csv.to_str().unwrap(),
        ],
    );
    // The select setup: rounds with several candidates rejected before one
    // is added, by the estimate and by the held-out RMS.
    let setup = tiago_setup(&dir, &data, "setup-select.toml");
    same_with_threads(&[
        "calibrate",
        "--json",
        "--setup",
        setup.to_str().unwrap(),
        "--data",
        csv.to_str().unwrap(),
        "--method",
        "irls",
    ]);
    let _ = std::fs::remove_dir_all(&dir);
}
