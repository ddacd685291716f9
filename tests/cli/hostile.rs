//! Hostile and odd files (issue 18), generated here: each case gets a
//! one-line error and a non-zero exit, and writes nothing; no case aborts
//! or hangs (a case that has not ended after `HANG_GUARD` fails instead of
//! blocking the suite; it is a guard, not a speed measurement).

use crate::common::Scratch;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const HANG_GUARD: Duration = Duration::from_secs(60);

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

struct Run {
    code: Option<i32>,
    stdout: String,
    stderr: String,
}

fn robcal(dir: &Path, args: &[&str]) -> Run {
    let mut child = Command::new(env!("CARGO_BIN_EXE_robcal"))
        .current_dir(dir)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run robcal");
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break s;
        }
        if start.elapsed() > HANG_GUARD {
            let _ = child.kill();
            panic!("robcal {args:?} still running after {HANG_GUARD:?}: a hang");
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let mut stdout = String::new();
    let mut stderr = String::new();
    child
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut stdout)
        .unwrap();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    Run {
        code: status.code(),
        stdout,
        stderr,
    }
}

/// The last stderr line of a refused run: exit 1, no abort, one short line
/// naming `file`.
fn refused(r: &Run, file: &str) -> String {
    assert_eq!(r.code, Some(1), "stderr: {}", r.stderr);
    assert!(r.stdout.is_empty(), "stdout: {}", r.stdout);
    let line = r.stderr.lines().last().unwrap_or_default().to_owned();
    assert!(line.starts_with("robcal: error: "), "{line}");
    assert!(line.contains(file), "{line} should name {file}");
    assert!(line.chars().count() < 400, "{} chars", line.chars().count());
    line
}

/// A fresh directory for test `name`, removed when dropped.
fn dir(name: &str) -> Scratch {
    Scratch::new(&format!("robcal-hostile-{name}"))
}

/// The KR-270 setup in `d` with `robot = ROBOT`.
fn setup(d: &Path, robot: &Path) -> PathBuf {
    let text = std::fs::read_to_string(root().join("data/kr270/setup.toml")).unwrap();
    let text = text.replace(
        "robot = \"kr270.urdf\"",
        &format!("robot = {:?}", robot.to_str().unwrap()),
    );
    let p = d.join("setup.toml");
    std::fs::write(&p, text).unwrap();
    p
}

fn kr270_urdf() -> PathBuf {
    root().join("data/kr270/kr270.urdf")
}

fn kr270_data() -> String {
    root()
        .join("data/kr270/measurements.csv")
        .to_str()
        .unwrap()
        .to_owned()
}

/// The files in `d`, names sorted.
fn listing(d: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// A URDF: the KR-270's with `extra` before `</robot>`.
fn urdf_with(d: &Path, name: &str, extra: &str) -> PathBuf {
    let text = std::fs::read_to_string(kr270_urdf()).unwrap();
    let p = d.join(name);
    std::fs::write(&p, text.replace("</robot>", &format!("{extra}</robot>"))).unwrap();
    p
}

#[test]
fn deep_urdf_nesting_is_an_error_not_an_abort() {
    let d = dir("deep");
    let u = urdf_with(
        &d,
        "deep.urdf",
        &("<x>".repeat(15_000) + &"</x>".repeat(15_000)),
    );
    let s = setup(&d, &u);
    let r = robcal(
        &d,
        &[
            "calibrate",
            "--setup",
            s.to_str().unwrap(),
            "--data",
            &kr270_data(),
        ],
    );
    let line = refused(&r, "deep.urdf:");
    assert!(line.contains("nested more than 64 deep"), "{line}");
}

#[test]
fn large_urdfs_are_refused_early_and_large_valid_ones_parse_in_linear_time() {
    let d = dir("large");
    // 30,000 fixed links in a chain below the tool: too many elements.
    let chain: String = (0..30_000)
        .map(|i| {
            let parent = if i == 0 { "tool0".to_owned() } else { format!("e{}", i - 1) };
            format!(
                "<link name=\"e{i}\"/><joint name=\"f{i}\" type=\"fixed\"><parent link=\"{parent}\"/>\
                 <child link=\"e{i}\"/></joint>\n"
            )
        })
        .collect();
    let u = urdf_with(&d, "chain.urdf", &chain);
    let s = setup(&d, &u);
    let r = robcal(
        &d,
        &[
            "calibrate",
            "--setup",
            s.to_str().unwrap(),
            "--data",
            &kr270_data(),
        ],
    );
    let line = refused(&r, "chain.urdf:");
    assert!(line.contains("more than 100000 XML elements"), "{line}");
    // Over the size limit: refused before reading.
    let big = d.join("big.urdf");
    let f = std::fs::File::create(&big).unwrap();
    f.set_len(17 << 20).unwrap();
    let s = setup(&d, &big);
    let r = robcal(
        &d,
        &[
            "calibrate",
            "--setup",
            s.to_str().unwrap(),
            "--data",
            &kr270_data(),
        ],
    );
    let line = refused(&r, "big.urdf");
    assert!(line.contains("more than the limit"), "{line}");
    // 20,000 side links (80,000 elements) are a valid robot: the checks
    // are linear, the calibration runs (the old pairwise scans took
    // minutes at this size).
    let side: String = (0..20_000)
        .map(|i| {
            format!(
                "<link name=\"s{i}\"/><joint name=\"g{i}\" type=\"fixed\"><parent link=\"base_link\"/>\
                 <child link=\"s{i}\"/></joint>\n"
            )
        })
        .collect();
    let u = urdf_with(&d, "side.urdf", &side);
    let s = setup(&d, &u);
    let r = robcal(
        &d,
        &[
            "calibrate",
            "--setup",
            s.to_str().unwrap(),
            "--data",
            &kr270_data(),
            "--no-diagnose",
        ],
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
}

#[cfg(unix)]
#[test]
fn fifos_devices_and_directories_are_not_read() {
    let d = dir("fifo");
    let fifo = d.join("fifo");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let f = fifo.to_str().unwrap();
    let good = setup(&d, &kr270_urdf());
    let g = good.to_str().unwrap();
    let data = kr270_data();
    for (args, file, what) in [
        (
            vec!["calibrate", "--setup", g, "--data", f],
            "fifo",
            "a FIFO",
        ),
        (
            vec!["calibrate", "--setup", g, "--data", "/dev/zero"],
            "/dev/zero",
            "a device",
        ),
        (
            vec!["calibrate", "--setup", g, "--data", "/tmp"],
            "/tmp",
            "a directory",
        ),
        (
            vec!["calibrate", "--setup", g, "--data", &data, "--validate", f],
            "fifo",
            "a FIFO",
        ),
        (
            vec!["calibrate", "--setup", f, "--data", &data],
            "fifo",
            "a FIFO",
        ),
        (
            vec!["import", "figaroh-mocap", f, "out.csv"],
            "fifo",
            "a FIFO",
        ),
        (
            vec!["import", "figaroh-mocap", "/dev/zero", "out.csv"],
            "/dev/zero",
            "a device",
        ),
        (vec!["import", "poses", f, "out.csv"], "fifo", "a FIFO"),
        (
            vec!["import", "poses", "/dev/zero", "out.csv"],
            "/dev/zero",
            "a device",
        ),
    ] {
        let line = refused(&robcal(&d, &args), file);
        assert!(line.contains(what), "{args:?}: {line}");
    }
    for robot in [fifo.clone(), PathBuf::from("/dev/zero")] {
        let s = setup(&d, &robot);
        let r = robcal(
            &d,
            &["calibrate", "--setup", s.to_str().unwrap(), "--data", &data],
        );
        let line = refused(&r, robot.to_str().unwrap());
        assert!(line.contains("not a regular file"), "{line}");
    }
    assert!(!d.join("out.csv").exists());
}

#[test]
fn a_data_file_over_the_limit_is_refused_before_reading() {
    let d = dir("limit");
    let good = setup(&d, &kr270_urdf());
    let r = robcal(
        &d,
        &[
            "calibrate",
            "--setup",
            good.to_str().unwrap(),
            "--data",
            &kr270_data(),
            "--max-data-mib",
            "0",
        ],
    );
    let line = refused(&r, "measurements.csv");
    assert!(line.contains("more than the limit of 0 bytes"), "{line}");
}

#[cfg(unix)]
#[test]
fn outputs_never_replace_inputs_links_fifos_or_devices() {
    let d = dir("outputs");
    let mocap = d.join("in.csv");
    std::fs::write(
        &mocap,
        "x1,y1,z1,x2,y2,z2,x3,y3,z3,x4,y4,z4,j1,j2,t_start_robot,t_end_robot\n\
         1,2,3,4,5,6,7,8,9,10,11,12,0.5,-0.25,100,101\n",
    )
    .unwrap();
    let before = std::fs::read(&mocap).unwrap();
    std::os::unix::fs::symlink(&mocap, d.join("link.csv")).unwrap();
    assert!(Command::new("mkfifo")
        .arg(d.join("ofifo"))
        .status()
        .unwrap()
        .success());
    for (out, says) in [
        (
            "in.csv",
            "in.csv: cannot write: is an input of this command",
        ),
        ("./in.csv", "./in.csv: cannot write: is the input in.csv"),
        ("link.csv", "symbolic link"),
        ("ofifo", "refusing to replace"),
        ("/dev/full", "refusing to replace"),
    ] {
        let line = refused(
            &robcal(&d, &["import", "figaroh-mocap", "in.csv", out]),
            out,
        );
        assert!(line.contains(says), "{out}: {line}");
    }
    assert_eq!(std::fs::read(&mocap).unwrap(), before);
    assert!(std::fs::symlink_metadata(d.join("link.csv"))
        .unwrap()
        .file_type()
        .is_symlink());
    assert_eq!(
        listing(&d),
        ["in.csv", "link.csv", "ofifo"],
        "no temporary file left"
    );
}

#[test]
fn plots_are_all_or_nothing() {
    let d = dir("plots");
    let plots = d.join("plots");
    // The closed loop on the naive model draws 01_compensator_a2.svg; a
    // directory of that name is in the way.
    std::fs::create_dir_all(plots.join("01_compensator_a2.svg")).unwrap();
    let r = robcal(
        &root(),
        &[
            "calibrate",
            "--setup",
            "data/kr270/setup-naive.toml",
            "--data",
            "data/kr270/measurements.csv",
            "--plots",
            plots.to_str().unwrap(),
        ],
    );
    assert_eq!(r.code, Some(1), "{}", r.stderr);
    assert!(r
        .stderr
        .lines()
        .last()
        .unwrap()
        .contains("refusing to replace"));
    assert_eq!(listing(&plots), ["01_compensator_a2.svg"]);
    // A new directory that cannot be completed is removed again: the
    // plots onto an input file.
    let r = robcal(
        &root(),
        &[
            "calibrate",
            "--setup",
            "data/kr270/setup-naive.toml",
            "--data",
            "data/kr270/measurements.csv",
            "--plots",
            "data/kr270/measurements.csv",
        ],
    );
    assert_eq!(r.code, Some(1), "{}", r.stderr);
    assert!(root().join("data/kr270/measurements.csv").is_file());
}

#[test]
fn errors_quote_little_and_say_where() {
    let d = dir("quote");
    let good = setup(&d, &kr270_urdf());
    let text = std::fs::read_to_string(kr270_data()).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let mut cells: Vec<String> = lines[1].split(',').map(str::to_owned).collect();
    let x = lines[0].split(',').position(|c| c == "x").unwrap();
    cells[x] = "7".repeat(1_000_000);
    lines[1] = cells.join(",");
    let big = d.join("cell.csv");
    std::fs::write(&big, lines.join("\n") + "\n").unwrap();
    let r = robcal(
        &d,
        &[
            "calibrate",
            "--setup",
            good.to_str().unwrap(),
            "--data",
            big.to_str().unwrap(),
        ],
    );
    let line = refused(&r, "cell.csv:2: column 'x'");
    assert!(line.len() < 300, "{line}");
    // Times beyond any clock: located, not a failure deep in a fit.
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    lines[0].push_str(",t");
    for (i, l) in lines.iter_mut().enumerate().skip(1) {
        l.push_str(if i == 3 { ",1.7e308" } else { ",0" });
    }
    let t = d.join("t.csv");
    std::fs::write(&t, lines.join("\n") + "\n").unwrap();
    let r = robcal(
        &d,
        &[
            "calibrate",
            "--setup",
            good.to_str().unwrap(),
            "--data",
            t.to_str().unwrap(),
        ],
    );
    let line = refused(&r, "t.csv:4: column 't'");
    assert!(line.contains("from 0"), "{line}");
}
