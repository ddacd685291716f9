//! Regression tests of the parser fuzz findings (issue 8), and a replay of
//! the kept parser corpora (`fuzz/corpus/{csv_measurements,setup_toml,urdf,figaroh_mocap}`)
//! on stable. The invariants are `host_tests::fuzz_io`'s: no panic, an
//! error names the file (and a line inside it), a success is finite and
//! its shapes agree.
//!
//! `tests/fuzz_regressions/<target>-<name>.bin` is a fuzz input of that
//! target (`urdf-…`: `base\0tip\0text`; `csv-…`: setup selector byte, then
//! the CSV). What each one found is written next to its test.

use std::time::{Duration, Instant};

use host_tests::fuzz_io::{
    csv_robot, run_csv, run_mocap, run_poses, run_setup, run_urdf, URDF_FILE,
};
use robcal::io::{parse_measurements, ErrorKind, Robot};

/// Runs `f` on a thread and fails if it takes longer than `limit` (the
/// cycle findings were infinite loops).
fn within(limit: Duration, f: impl FnOnce() + Send + 'static) {
    let start = Instant::now();
    let handle = std::thread::spawn(f);
    while !handle.is_finished() {
        assert!(start.elapsed() < limit, "still running after {limit:?}");
        std::thread::sleep(Duration::from_millis(5));
    }
    handle.join().unwrap();
}

fn urdf_err(bytes: &'static [u8]) -> robcal::io::InputError {
    let s = std::str::from_utf8(bytes).unwrap();
    let mut p = s.splitn(3, '\0');
    let (b, t, text) = (p.next().unwrap(), p.next().unwrap(), p.next().unwrap());
    let opt = |x: &'static str| (!x.is_empty()).then_some(x);
    let e = Robot::parse(text, URDF_FILE, opt(b), opt(t)).expect_err("must be rejected");
    run_urdf(bytes);
    e
}

/// A link that is (through a fixed joint) its own ancestor: `default_tip`,
/// the subtree-mass walk and the moving-body walk looped forever (out of
/// memory). Now a `Robot` error naming the joint that closes the loop.
#[test]
fn urdf_cycle_is_an_error_not_a_hang() {
    within(Duration::from_secs(10), || {
        let e = urdf_err(include_bytes!("fuzz_regressions/urdf-cycle.bin"));
        assert_eq!(e.kind, ErrorKind::Robot);
        assert!(e.to_string().contains("loop"), "{e}");
    });
}

/// Two fixed origins of 1e308 m compose to +∞: the chain held a non-finite
/// joint origin and the parse succeeded. (Since, an origin beyond 1e4 m is
/// refused on its own, before any composition.)
#[test]
fn urdf_origin_overflow_is_rejected() {
    let e = urdf_err(include_bytes!("fuzz_regressions/urdf-origin-overflow.bin"));
    assert_eq!(e.kind, ErrorKind::InvalidValue);
    assert!(e.to_string().contains("beyond 1e4 m"), "{e}");
    // The first of the two, a fixed joint before `j`.
    assert_eq!(e.line, Some(2), "{e}");
    assert!(e.to_string().contains("joint 'f'"), "{e}");
}

/// An axis of `1e300 1e300 0` is a valid direction, but its norm overflows
/// and the "unit" axis came out as `(0, 0, 0)`. Now normalized after scaling
/// by its largest component.
#[test]
fn urdf_huge_axis_is_normalized() {
    let bytes: &[u8] = include_bytes!("fuzz_regressions/urdf-huge-axis.bin");
    run_urdf(bytes);
    let text = std::str::from_utf8(&bytes[2..]).unwrap();
    let r = Robot::parse(text, URDF_FILE, None, None).unwrap();
    let a = r.chain.joints()[0].axis;
    let h = std::f64::consts::FRAC_1_SQRT_2;
    assert!(
        (a.x - h).abs() < 1e-15 && (a.y - h).abs() < 1e-15 && a.z == 0.0,
        "{a:?}"
    );
}

/// A link of 1e300 kg with its centre of mass at 1e10 m: the mass moment
/// overflowed and the link inertia's centre of mass was ∞.
#[test]
fn urdf_mass_moment_overflow_is_rejected() {
    let e = urdf_err(include_bytes!("fuzz_regressions/urdf-mass-overflow.bin"));
    assert_eq!(e.kind, ErrorKind::NonFinite);
    assert!(e.to_string().contains("link 'b'"), "{e}");
}

/// Two joints named `j`: the CSV needs one column per joint name, so the
/// second joint's values could never be read (silently 0). Now an error.
#[test]
fn urdf_duplicate_joint_name_is_rejected() {
    let e = urdf_err(include_bytes!("fuzz_regressions/urdf-duplicate-joint.bin"));
    assert_eq!(e.kind, ErrorKind::Robot);
    assert_eq!(e.line, Some(3), "the second one: {e}");
    assert!(e.to_string().contains("defined twice"), "{e}");
}

/// `<t xmlns="i" :=""/>` (found by the 30-minute `urdf` run of issue 18):
/// an attribute with an empty namespace prefix under a default namespace
/// made RustyXML 0.3 (urdf-rs's XML parser) panic ("No namespace prefix
/// bound"): `robcal calibrate` aborted with a backtrace. Now refused by the
/// pre-scan with its line; a panic of the parser is an error in any case.
#[test]
fn urdf_empty_namespace_prefix_is_an_error_not_a_panic() {
    let bytes: &[u8] = include_bytes!("fuzz_regressions/urdf-empty-prefix-panic.bin");
    run_urdf(bytes);
    let e = urdf_err(bytes);
    assert_eq!(e.kind, ErrorKind::Syntax);
    assert_eq!(e.line, Some(1));
    assert!(e.to_string().contains("empty namespace prefix"), "{e}");
    // The second form (the run after the fix): an element named `"` with a
    // default namespace, `<" xmlns="\0":m=""/>`.
    let bytes: &[u8] = include_bytes!("fuzz_regressions/urdf-quote-name-panic.bin");
    let e = urdf_err(bytes);
    assert!(
        e.to_string().contains("element name starting with a quote"),
        "{e}"
    );
    // Spread over lines and inside a real tag.
    let e = urdf_err(b"\0\0<robot name=\"r\" xmlns=\"u\">\n<link name=\"a\"\n  :x=\"1\"/></robot>");
    assert_eq!(e.line, Some(3), "{e}");
}

/// A CSV with old-Mac `\r` line ends: the csv crate splits records at `\r`,
/// but lines were counted at `\n` only, so every row and every error said
/// line 1.
#[test]
fn csv_cr_line_ends_count_lines() {
    let bytes: &[u8] = include_bytes!("fuzz_regressions/csv-cr-line-ends.bin");
    let robot = csv_robot();
    run_csv(&robot, bytes);
    let setup = host_tests::fuzz_io::csv_setup(bytes[0]);
    let m = parse_measurements(&bytes[1..], "cr.csv", &robot, &setup).unwrap();
    let lines: Vec<usize> = m.observations.iter().map(|o| o.line).collect();
    assert_eq!(lines, [2, 3]);
    let bad = b"config,rep,marker,load_kg,a1,a2,d3,x,y,z\r1,0,1,0,1,0,0.1,0.5,0,0\r1,0,9,0,1,0,0.1,0.5,0,0\r";
    let e = parse_measurements(&bad[..], "cr.csv", &robot, &setup).unwrap_err();
    assert_eq!(e.line, Some(3), "{e}");
}

/// Every kept parser corpus entry and every `urdf-`/`csv-`/`toml-`
/// regression input.
#[test]
fn replay_parser_corpora() {
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
    let robot = csv_robot();
    let mut n = 0;
    let mut replay = |target: &str, bytes: &[u8]| {
        match target {
            "csv_measurements" | "csv" => run_csv(&robot, bytes),
            "setup_toml" | "toml" => run_setup(bytes),
            "urdf" => run_urdf(bytes),
            "figaroh_mocap" | "mocap" => run_mocap(bytes),
            "poses" => run_poses(bytes),
            _ => return,
        }
        n += 1;
    };
    for target in [
        "csv_measurements",
        "setup_toml",
        "urdf",
        "figaroh_mocap",
        "poses",
    ] {
        let Ok(dir) = std::fs::read_dir(format!("{root}/fuzz/corpus/{target}")) else {
            continue;
        };
        for entry in dir.flatten() {
            replay(target, &std::fs::read(entry.path()).unwrap());
        }
    }
    for entry in std::fs::read_dir(format!("{root}/host-tests/tests/fuzz_regressions"))
        .unwrap()
        .flatten()
    {
        let name = entry.file_name().to_string_lossy().into_owned();
        if let Some((target, _)) = name.split_once('-') {
            replay(target, &std::fs::read(entry.path()).unwrap());
        }
    }
    println!("replayed {n} parser inputs");
    assert!(n > 0);
}

/// Structured random pose files: headers drawn from the layout's own
/// column kinds (and near misses), cells drawn from numbers, empties,
/// garbage and non-finite text, so that the importer's branches are
/// reached, not only its first check (libFuzzer's `poses` target takes
/// arbitrary bytes).
#[test]
fn structured_pose_files_keep_the_invariants() {
    let mut rng = host_tests::Rng::new(7);
    let names = [
        "pose_id", "split", "test_set", "a_rad", "b_rad", "slide_m", "_rad", "x1_m", "y1_m",
        "z1_m", "x2_m", "y2_m", "z2_m", "ux1_m", "uy1_m", "uz1_m", "std_x2_m", "std_y2_m",
        "std_z2_m", "u1_m", "x0_m", "x1", "a_rad", "",
    ];
    let cells = [
        "0", "1", "2", "-0.5", "1e-3", "", "", "cal", "test", "nan", "inf", "x", "1e400", "\"1\"",
        "7",
    ];
    let valid = [
        "pose_id", "split", "a_rad", "slide_m", "x1_m", "y1_m", "z1_m", "ux1_m", "uy1_m", "uz1_m",
    ];
    let numbers = ["0", "1", "2", "-0.5", "1e-3", "3", "0.25"];
    let (mut ok, mut err) = (0, 0);
    for _ in 0..4000 {
        let pick = |rng: &mut host_tests::Rng, n: usize| (rng.next_u64() % n as u64) as usize;
        // A valid header, then up to two mutations: a column dropped, or
        // one of the layout's names (or a near miss) added.
        let mut header: Vec<&str> = valid.to_vec();
        for _ in 0..pick(&mut rng, 3) {
            if rng.next_u64().is_multiple_of(2) {
                let at = pick(&mut rng, header.len());
                header.remove(at);
            } else {
                header.push(names[pick(&mut rng, names.len())]);
            }
        }
        let k = header.len();
        let mut text = header.join(",");
        text.push('\n');
        for _ in 0..(1 + rng.next_u64() % 4) {
            let width = if rng.next_u64().is_multiple_of(20) {
                k + 1
            } else {
                k
            };
            let row: Vec<&str> = (0..width)
                .map(|_| {
                    if rng.next_u64().is_multiple_of(8) {
                        cells[pick(&mut rng, cells.len())]
                    } else {
                        numbers[pick(&mut rng, numbers.len())]
                    }
                })
                .collect();
            text.push_str(&row.join(","));
            text.push('\n');
        }
        run_poses(text.as_bytes());
        let options = robcal::io::poses::ImportOptions::default();
        match robcal::io::poses::convert_poses(&text, "f.csv", &options) {
            Ok(_) => ok += 1,
            Err(_) => err += 1,
        }
    }
    // Both outcomes are reached.
    assert!(ok > 20 && err > 20, "ok {ok}, err {err}");
}
