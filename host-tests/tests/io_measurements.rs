//! Measurement CSV (`robcal::io::measurements`): units, pairing, every error
//! path with file/line/column, warnings, and the writer round trip.

use std::path::{Path, PathBuf};

use host_tests::Rng;
use robcal::io::{
    parse_measurements, read_measurements, write_measurements, AngleUnit, ErrorKind, InputError,
    Job, LengthUnit, Measurements, Observation, Units,
};

fn job() -> Job {
    let setup = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/io_setup.toml");
    Job::load(setup).unwrap()
}

/// Parses `text` as `d.csv` with the fixture job (deg, mm; markers 1 and 7; a load).
fn read(job: &Job, text: &str) -> Result<Measurements, InputError> {
    parse_measurements(text.as_bytes(), "d.csv", &job.robot, &job.setup)
}

fn read_err(job: &Job, text: &str) -> InputError {
    read(job, text).unwrap_err()
}

const HEADER: &str = "config,rep,marker,load_kg,j1,j2,j3,x,y,z";

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("robcal-io-csv-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn units_are_converted_to_si() {
    let job = job();
    let m = read(
        &job,
        "j3, z ,config,rep,marker,load_kg,j1,j2,x,y\n150,1e3,1,0,7,0,90,-45.5,1234.5,-0.25\n",
    )
    .unwrap();
    assert_eq!(m.file, Path::new("d.csv"));
    let o = &m.observations[0];
    assert_eq!(
        (o.config, o.rep, o.marker, o.load_kg, o.line),
        (1, 0, 7, 0.0, 2)
    );
    // deg: f64::to_radians; mm: the decimal point moved (correctly rounded).
    assert_eq!(
        o.q.as_slice(),
        [90f64.to_radians(), (-45.5f64).to_radians(), 0.15]
    );
    assert_eq!(
        o.q_written.iter().collect::<Vec<_>>(),
        ["90", "-45.5", "150"]
    );
    assert_eq!(o.p_m, [1.2345, -0.00025, 1.0]);
    assert_eq!(o.t_s, None);
    assert!(!m.has_time);
    assert!(m.deflections.is_empty());
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
    assert_eq!(m.unloaded().count(), 1);
}

#[test]
fn loaded_rows_pair_with_unloaded_rows() {
    let job = job();
    let text = format!(
        "{HEADER},t\n\
         1,0,1,0,10,20,100,1000,0,500,0.5\n\
         1,0,1,25,10,20,100,1000,-1.5,499,1.5\n\
         1,0,7,0,10,20,100,1020,0,500,2\n\
         1,0,1,50,10,20,100,1000,-3,498,3\n\
         2,0,1,0,30,20,100,900,0,500,4\n\
         1,1,1,0,10,20,100,1000,0.002,500,5\n\
         1,1,1,25,10.01,20,100,1000,-1.5,499,6\n"
    );
    let m = read(&job, &text).unwrap();
    assert!(m.has_time);
    assert_eq!(m.observations.len(), 7);
    assert_eq!(m.observations[1].t_s, Some(1.5));
    let unloaded: Vec<usize> = m.unloaded().map(|o| o.line).collect();
    assert_eq!(unloaded, [2, 4, 6, 7]);
    assert_eq!(m.deflections.len(), 3);
    let d = &m.deflections[0];
    assert_eq!((d.config, d.rep, d.marker, d.load_kg), (1, 0, 1, 25.0));
    assert_eq!(d.lines, [3, 2]);
    assert_eq!(d.rows, [1, 0]);
    assert_eq!(d.q, m.observations[0].q);
    assert_eq!(d.dp_m, [0.0, -0.0015, 0.499 - 0.5]);
    // Two load levels on one unloaded row.
    assert_eq!(
        (m.deflections[1].load_kg, m.deflections[1].lines),
        (50.0, [5, 2])
    );
    // The second repetition pairs with its own unloaded row; its joint
    // moved by 0.01° = 0.17 mrad: below the warning threshold.
    assert_eq!(m.deflections[2].lines, [8, 7]);
    // The two load levels share line 2's noise: said, once.
    assert_eq!(m.warnings.len(), 1, "{:?}", m.warnings);
    assert_eq!(m.warnings[0].line, Some(2));
    assert!(
        m.warnings[0]
            .message
            .starts_with("1 unloaded row(s) are each the reference of several loaded rows (first: line 2, for lines 3 and 5)"),
        "{:?}",
        m.warnings
    );
}

/// `Measurements::without` (`--leave-out-outliers`): a dropped deflection
/// takes its loaded row with it; a dropped unloaded row takes every
/// deflection it is the reference of; the rest keep their lines, and the
/// deflections point at their rows again.
#[test]
fn without_drops_rows_and_the_deflections_they_pair() {
    let job = job();
    let text = format!(
        "{HEADER}\n\
         1,0,1,0,10,20,100,1000,0,500\n\
         1,0,1,25,10,20,100,1000,-1.5,499\n\
         1,0,7,0,10,20,100,1020,0,500\n\
         1,0,1,50,10,20,100,1000,-3,498\n\
         2,0,1,0,30,20,100,900,0,500\n\
         2,0,1,25,30,20,100,900,-1,499\n"
    );
    let m = read(&job, &text).unwrap();
    assert_eq!(m.deflections.len(), 3);
    // The 50 kg deflection of config 1: its loaded row (line 5) goes.
    let a = m.without(|_| false, |d| d.config == 1 && d.load_kg == 50.0);
    let lines: Vec<usize> = a.observations.iter().map(|o| o.line).collect();
    assert_eq!(lines, [2, 3, 4, 6, 7]);
    assert_eq!(a.deflections.len(), 2);
    for d in &a.deflections {
        assert_eq!(d.lines, d.rows.map(|r| a.observations[r].line));
    }
    // Config 1's unloaded row of marker 1 (line 2): both its deflections go.
    let b = m.without(|o| o.line == 2, |_| false);
    assert_eq!(b.observations.len(), 5);
    assert_eq!(b.deflections.len(), 1);
    assert_eq!(b.deflections[0].lines, [7, 6]);
    assert_eq!(
        b.deflections[0].lines,
        b.deflections[0].rows.map(|r| b.observations[r].line)
    );
}

#[test]
fn every_malformed_input_names_file_line_and_column() {
    let job = job();
    let ok = "1,0,1,0,10,20,100,1000,0,500";
    let cases: Vec<(String, ErrorKind, usize, Option<&str>, &str)> = vec![
        (
            format!("config,rep,marker,load_kg,j1,j2,j3,x,y\n{ok}\n"),
            ErrorKind::MissingColumn,
            1,
            Some("z"),
            "missing column",
        ),
        (
            format!("config,rep,marker,load_kg,j1,j2,x,y,z\n{ok}\n"),
            ErrorKind::MissingColumn,
            1,
            Some("j3"),
            "missing column",
        ),
        (
            format!("{HEADER},j9\n{ok},1\n"),
            ErrorKind::UnknownColumn,
            1,
            Some("j9"),
            "neither a fixed column nor a movable joint",
        ),
        (
            format!("{HEADER},mount\n{ok},1\n"),
            ErrorKind::UnknownColumn,
            1,
            Some("mount"),
            "joints: j1, j2, j3",
        ),
        (
            format!("{HEADER},j2\n{ok},1\n"),
            ErrorKind::DuplicateColumn,
            1,
            Some("j2"),
            "twice",
        ),
        (
            format!("{HEADER}\n{ok}\n1,0,3,0,10,20,100,1000,0,500\n"),
            ErrorKind::UnknownMarker,
            3,
            Some("marker"),
            "marker 3 is not declared",
        ),
        (
            format!("{HEADER}\n{ok}\n2,0,1,10,10,20,100,1000,0,500\n"),
            ErrorKind::Unpaired,
            3,
            Some("load_kg"),
            "no unloaded row",
        ),
        (
            format!(
                "{HEADER}\n{ok}\n1,0,1,10,10,20,100,1000,0,500\n1,1,7,10,10,20,100,1000,0,500\n"
            ),
            ErrorKind::Unpaired,
            4,
            Some("load_kg"),
            "config 1, rep 1, marker 7",
        ),
        (
            format!("{HEADER}\n{ok}\n1,0,1,0,10,20,100,NaN,0,500\n"),
            ErrorKind::NonFinite,
            3,
            Some("x"),
            "non-finite value 'NaN'",
        ),
        (
            format!("{HEADER}\n{ok}\n1,0,1,0,inf,20,100,1,0,500\n"),
            ErrorKind::NonFinite,
            3,
            Some("j1"),
            "non-finite",
        ),
        (
            format!("{HEADER}\n1,0,1,-inf,10,20,100,1,0,500\n"),
            ErrorKind::NonFinite,
            2,
            Some("load_kg"),
            "non-finite",
        ),
        (
            format!("{HEADER}\n{ok}\n1,0,1,0,10,20,1O0,1,0,500\n"),
            ErrorKind::Syntax,
            3,
            Some("j3"),
            "'1O0' is not a number",
        ),
        (
            format!("{HEADER}\n1.5,0,1,0,10,20,100,1,0,500\n"),
            ErrorKind::Syntax,
            2,
            Some("config"),
            "'1.5' is not an integer",
        ),
        (
            format!("{HEADER}\n1,0,-1,0,10,20,100,1,0,500\n"),
            ErrorKind::Syntax,
            2,
            Some("marker"),
            "not a marker id",
        ),
        (
            format!("{HEADER}\n1,0,1,0,10,,100,1,0,500\n"),
            ErrorKind::Syntax,
            2,
            Some("j2"),
            "empty cell",
        ),
        (
            format!("{HEADER}\n{ok}\n1,0,1,0,10,20,100,1,0\n"),
            ErrorKind::Syntax,
            3,
            None,
            "row has 9 fields, the header has 10",
        ),
        (
            format!("{HEADER}\n{ok}\n1,0,1,-2,10,20,100,1,0,500\n"),
            ErrorKind::InvalidValue,
            3,
            Some("load_kg"),
            "negative load",
        ),
        (
            format!("{HEADER}\n{ok}\n{ok}\n"),
            ErrorKind::Duplicate,
            3,
            None,
            "already at line 2",
        ),
        (
            // The first row in file order whose key came before (config 2
            // at line 4), against that earlier row; not the first key in
            // sorted order (config 1, again at line 5).
            format!(
                "{HEADER}\n2,0,1,0,10,20,100,1000,0,500\n{ok}\n\
                 2,0,1,0,10,20,100,1000,0,500\n{ok}\n{ok}\n"
            ),
            ErrorKind::Duplicate,
            4,
            None,
            "config 2, rep 0, marker 1, load 0 kg already at line 2",
        ),
        (
            format!("{HEADER}\n{ok}\n1,0,1,5,1,2,3,4,5,6\n1,0,1,5,1,2,3,4,5,6\n"),
            ErrorKind::Duplicate,
            4,
            None,
            "load 5 kg already at line 3",
        ),
        (
            format!("{HEADER}\n"),
            ErrorKind::InvalidValue,
            1,
            None,
            "no measurement rows",
        ),
        (String::new(), ErrorKind::Syntax, 1, None, "no header"),
    ];
    for (text, kind, line, column, needle) in cases {
        let e = read_err(&job, &text);
        assert_eq!(e.kind, kind, "{text}\n{e}");
        assert_eq!(e.file, Path::new("d.csv"));
        assert_eq!(e.line, Some(line), "{text}\n{e}");
        assert_eq!(e.column.as_deref(), column, "{text}\n{e}");
        assert!(e.message.contains(needle), "{text}\n{e}");
        let prefix = match column {
            Some(c) => format!("d.csv:{line}: column '{c}': "),
            None => format!("d.csv:{line}: "),
        };
        assert!(e.to_string().starts_with(&prefix), "{e}");
    }
}

#[test]
fn loaded_rows_need_a_load_section() {
    let mut job = job();
    job.setup.load = None;
    let e = read_err(
        &job,
        &format!("{HEADER}\n1,0,1,0,1,2,3,4,5,6\n1,0,1,5,1,2,3,4,5,6\n"),
    );
    assert_eq!(
        (e.kind, e.line, e.column.as_deref()),
        (ErrorKind::InvalidValue, Some(3), Some("load_kg"))
    );
    assert!(e.message.contains("no [load]"), "{e}");
}

#[test]
fn implausible_units() {
    let mut job = job();
    // deg, but every angle within ±π: a warning (the file may be in rad).
    let m = read(
        &job,
        &format!("{HEADER}\n1,0,1,0,1.2,-3,100,1000,0,500\n2,0,1,0,0.5,2,100,1000,0,500\n"),
    )
    .unwrap();
    assert_eq!(m.warnings.len(), 1, "{:?}", m.warnings);
    assert!(
        m.warnings[0].message.contains("in radians?"),
        "{}",
        m.warnings[0]
    );
    // mm, but every position within ±10: a warning.
    let m = read(&job, &format!("{HEADER}\n1,0,1,0,30,20,100,1.2,0.1,0.5\n")).unwrap();
    assert!(
        m.warnings[0].message.contains("in metres?"),
        "{}",
        m.warnings[0]
    );
    // Outside the URDF limits by more than 10 % of the range: one warning per
    // column, at the first line. j1: ±2.5 rad ≈ ±143°; j3: 0..300 mm.
    let m = read(
        &job,
        &format!("{HEADER}\n1,0,1,0,175,20,100,1000,0,500\n2,0,1,0,30,20,100,1000,0,500\n3,0,1,0,-175,20,340,1000,0,500\n"),
    )
    .unwrap();
    let w: Vec<(Option<usize>, Option<&str>)> = m
        .warnings
        .iter()
        .map(|w| (w.line, w.column.as_deref()))
        .collect();
    assert_eq!(w, [(Some(2), Some("j1")), (Some(4), Some("j3"))]);
    assert!(
        m.warnings[0]
            .to_string()
            .starts_with("d.csv:2: column 'j1': 2 value(s) outside the URDF limits"),
        "{}",
        m.warnings[0]
    );
    // Loaded and unloaded rows in different poses: a warning.
    let m = read(
        &job,
        &format!("{HEADER}\n1,0,1,0,30,20,100,1000,0,500\n1,0,1,5,31,20,100,1000,0,500\n"),
    )
    .unwrap();
    assert!(
        m.warnings[0]
            .message
            .contains("differ from their unloaded row"),
        "{}",
        m.warnings[0]
    );
    assert_eq!(m.warnings[0].line, Some(3));

    // rad, but a limited revolute joint beyond ±2π: an error.
    job.setup.units = Units {
        angle: AngleUnit::Rad,
        length: LengthUnit::Mm,
    };
    let e = read_err(
        &job,
        &format!("{HEADER}\n1,0,1,0,1,2,100,1000,0,500\n1,0,1,0,45,2,100,1000,0,500\n"),
    );
    assert_eq!(
        (e.kind, e.line, e.column.as_deref()),
        (ErrorKind::Units, Some(3), Some("j1"))
    );
    assert!(e.message.contains("in degrees?"), "{e}");
    // ... but not a continuous joint (j2): multi-turn values are fine.
    assert!(read(&job, &format!("{HEADER}\n1,0,1,0,1,20,100,1000,0,500\n")).is_ok());
    // m, but a position beyond 100 m: an error.
    job.setup.units = Units::SI;
    let e = read_err(
        &job,
        &format!("{HEADER}\n1,0,1,0,1,2,0.1,1,1,1\n1,0,7,0,1,2,0.1,1,-1500,1\n"),
    );
    assert_eq!(
        (e.kind, e.line, e.column.as_deref()),
        (ErrorKind::Units, Some(3), Some("y"))
    );
}

#[test]
fn read_from_file_and_missing_file() {
    let job = job();
    let path = temp("plain.csv");
    std::fs::write(&path, format!("{HEADER}\n1,0,1,0,10,20,100,1000,0,500\n")).unwrap();
    let m = read_measurements(&path, &job.robot, &job.setup).unwrap();
    assert_eq!(m.file, path);
    assert_eq!(job.read_measurements(&path).unwrap(), m);
    let e = read_measurements(temp("none.csv"), &job.robot, &job.setup).unwrap_err();
    assert_eq!((e.kind, e.file), (ErrorKind::Io, temp("none.csv")));
}

fn rows(n: usize, time: bool) -> Vec<Observation> {
    // The project's one seeded generator: deterministic test values.
    let mut rng = Rng::new(0x9e37_79b9_7f4a_7c15);
    let mut out = Vec::new();
    for i in 0..n {
        let q = vec![
            rng.range(-2.4, 2.4),
            rng.range(-9.0, 9.0),
            rng.range(0.0, 0.3),
        ];
        let p = [
            rng.range(-3.0, 3.0),
            rng.range(-3.0, 3.0),
            rng.range(-1e-3, 3.0),
        ];
        let unloaded = Observation {
            config: i as i64 - 3,
            rep: (i % 2) as i64,
            marker: if i % 3 == 0 { 7 } else { 1 },
            load_kg: 0.0,
            q: q.as_slice().into(),
            p_m: p,
            t_s: time.then(|| rng.range(0.0, 1e9)),
            ..Observation::default()
        };
        let loaded = Observation {
            load_kg: rng.range(0.0, 300.0),
            p_m: p.map(|v| v + rng.range(-1e-3, 1e-3)),
            t_s: time.then(|| rng.range(0.0, 1e9)),
            ..unloaded.clone()
        };
        out.push(unloaded);
        out.push(loaded);
    }
    // Edge values.
    out[0].q[1] = -0.0;
    out[0].p_m = [1e-300, -99.123456789, 5e-324];
    out
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn writer_round_trips_bit_exactly() {
    let mut job = job();
    for (units, time) in [
        (Units::SI, false),
        (
            Units {
                angle: AngleUnit::Rad,
                length: LengthUnit::Mm,
            },
            true,
        ),
        (
            Units {
                angle: AngleUnit::Deg,
                length: LengthUnit::Mm,
            },
            false,
        ),
    ] {
        job.setup.units = units;
        let written = rows(200, time);
        let path = temp(&format!("rt-{units:?}.csv").replace([' ', '{', '}', ':', ','], ""));
        write_measurements(&path, &job.robot, units, &written).unwrap();
        let m = job
            .read_measurements(&path)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(m.has_time, time);
        assert_eq!(m.observations.len(), written.len());
        assert_eq!(m.deflections.len(), written.len() / 2);
        let mut inexact = 0;
        for (i, (r, w)) in m.observations.iter().zip(&written).enumerate() {
            assert_eq!(r.line, i + 2);
            assert_eq!((r.config, r.rep, r.marker), (w.config, w.rep, w.marker));
            assert_eq!(r.load_kg.to_bits(), w.load_kg.to_bits());
            assert_eq!(bits(&r.p_m), bits(&w.p_m), "{units:?} row {i}");
            assert_eq!(r.t_s.map(f64::to_bits), w.t_s.map(f64::to_bits));
            // The prismatic joint is a length: exact in mm too.
            assert_eq!(r.q[2].to_bits(), w.q[2].to_bits());
            for k in 0..2 {
                if units.angle == AngleUnit::Rad {
                    assert_eq!(r.q[k].to_bits(), w.q[k].to_bits(), "{units:?} row {i}");
                } else if r.q[k].to_bits() != w.q[k].to_bits() {
                    // deg: exact unless no decimal degree value maps back
                    // under to_radians; then the nearest, within 1 ulp.
                    inexact += 1;
                    let ulp = f64::EPSILON * w.q[k].abs();
                    assert!((r.q[k] - w.q[k]).abs() <= ulp, "{} vs {}", r.q[k], w.q[k]);
                }
            }
        }
        // Where ulp(deg) = 64 ulp(rad) > 180/π ulp(rad), about 1 − 57.3/64 ≈ 10 %
        // of the radian values have no decimal degree value of their own.
        assert!(
            inexact * 100 < 15 * 2 * written.len(),
            "deg: {inexact} inexact of {}",
            2 * written.len()
        );
        // Writing what was read gives the same file.
        let again = temp("again.csv");
        write_measurements(&again, &job.robot, units, &m.observations).unwrap();
        assert_eq!(
            std::fs::read(&again).unwrap(),
            std::fs::read(&path).unwrap()
        );
    }
    // What the file looks like.
    let path = temp("look.csv");
    let row = Observation {
        config: 3,
        rep: 1,
        marker: 7,
        load_kg: 12.5,
        q: [std::f64::consts::FRAC_PI_2, -0.5, 0.125][..].into(),
        p_m: [1.2345, -0.0001, 0.0],
        ..Observation::default()
    };
    let mut base = row.clone();
    base.load_kg = 0.0;
    let units = Units {
        angle: AngleUnit::Deg,
        length: LengthUnit::Mm,
    };
    write_measurements(&path, &job.robot, units, &[base, row]).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("config,rep,marker,load_kg,j1,j2,j3,x,y,z")
    );
    assert_eq!(
        lines.next(),
        Some("3,1,7,0,90,-28.64788975654116,125,1234.5,-0.1,0")
    );
    assert_eq!(
        lines.next(),
        Some("3,1,7,12.5,90,-28.64788975654116,125,1234.5,-0.1,0")
    );
}

#[test]
fn writer_rejects_bad_rows_and_leaves_the_file_alone() {
    let job = job();
    let path = temp("keep.csv");
    std::fs::write(&path, "old content").unwrap();
    let good = rows(2, false);
    let cases: Vec<(Vec<Observation>, ErrorKind, &str)> = vec![
        (
            {
                let mut r = good.clone();
                r[1].q.pop();
                r
            },
            ErrorKind::InvalidValue,
            "2 joint values for 3 joints",
        ),
        (
            {
                let mut r = good.clone();
                r[2].p_m[1] = f64::NAN;
                r
            },
            ErrorKind::NonFinite,
            "non-finite",
        ),
        (
            {
                let mut r = good.clone();
                r[0].load_kg = -1.0;
                r
            },
            ErrorKind::InvalidValue,
            "negative load",
        ),
        (
            {
                let mut r = good.clone();
                r[3].t_s = Some(1.0);
                r
            },
            ErrorKind::InvalidValue,
            "some rows have a time",
        ),
    ];
    for (rows, kind, needle) in cases {
        let e = write_measurements(&path, &job.robot, Units::SI, &rows).unwrap_err();
        assert_eq!((e.kind, e.file.as_path()), (kind, path.as_path()), "{e}");
        assert!(e.message.contains(needle), "{e}");
        assert!(e.line.is_some());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old content");
    }
    let leftovers: Vec<_> = std::fs::read_dir(path.parent().unwrap())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(".keep.csv.tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // Unwritable place: an Io error, nothing created.
    let e = write_measurements(temp("no/such/dir.csv"), &job.robot, Units::SI, &good).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Io);
}

#[test]
fn bom_and_crlf_line_ends_are_accepted() {
    let job = job();
    let text = format!(
        "\u{feff}{HEADER}\r\n1,0,1,0,10,20,100,1000,0,500\r\n\r\n2,0,1,0,10,20,100,1000,0,500\r\n"
    );
    let m = read(&job, &text).unwrap();
    let lines: Vec<usize> = m.observations.iter().map(|o| o.line).collect();
    assert_eq!(lines, [2, 4], "a blank line is skipped but counted");
    // Errors too: line 5 after a blank line, with CRLF.
    let e = read_err(&job, &format!("{text}1,0,9,0,10,20,100,1000,0,500\r\n"));
    assert_eq!((e.line, e.column.as_deref()), (Some(5), Some("marker")));
    let e = read_err(&job, &format!("{text}\r\n1,0,1,0,10,20,100\r\n"));
    assert_eq!((e.kind, e.line), (ErrorKind::Syntax, Some(6)));
}

/// Data contract 7.2: `rep`, `marker`, `load_kg` may be left out where the
/// setup makes them unambiguous; `ignore_columns` skips a tracker export's
/// extra columns (empty cells too); anything else stays an error.
#[test]
fn optional_columns_and_ignored_columns() {
    let mut job = job();
    // The fixture has two markers and a load: marker and load_kg needed.
    let e = read_err(&job, "config,j1,j2,j3,x,y,z\n1,10,20,100,1000,0,500\n");
    assert_eq!(e.kind, ErrorKind::MissingColumn);
    assert_eq!(e.column.as_deref(), Some("marker"));
    assert!(e.message.contains("more than one marker"), "{e}");
    let e = read_err(
        &job,
        "config,marker,j1,j2,j3,x,y,z\n1,1,10,20,100,1000,0,500\n",
    );
    assert_eq!(e.column.as_deref(), Some("load_kg"));
    assert!(e.message.contains("[load]"), "{e}");
    // One marker, no load: only config, the joints and x, y, z.
    job.setup.markers.truncate(1);
    job.setup.load = None;
    let m = read(
        &job,
        "config,j1,j2,j3,x,y,z\n1,10,20,100,1000,0,500\n2,11,20,100,1000,0,501\n",
    )
    .expect("reads");
    assert_eq!(m.observations.len(), 2);
    for o in &m.observations {
        assert_eq!(
            (o.rep, o.marker, o.load_kg),
            (1, job.setup.markers[0].id, 0.0)
        );
    }
    // Extra columns: an error naming the key that skips them ...
    let text = "config,temperature,j1,j2,j3,x,y,z,note\n1,21.5,10,20,100,1000,0,500,\n";
    let e = read_err(&job, text);
    assert_eq!(e.kind, ErrorKind::UnknownColumn);
    assert!(e.message.contains("ignore_columns"), "{e}");
    // ... and skipped, empty cells too, once named.
    job.setup.ignore_columns = vec!["temperature".into(), "note".into()];
    let m = read(&job, text).expect("reads");
    assert_eq!(m.observations[0].p_m, [1.0, 0.0, 0.5]);
}

/// `sx, sy, sz` (data contract 7.2): the instrument's σ per axis, in the
/// length unit (mm here), three columns or none, each a length ≥ 0.
#[test]
fn instrument_sigma_columns() {
    let job = job();
    let m = read(
        &job,
        &format!("{HEADER},sx,sy,sz\n1,0,7,0,90,-45,150,1234.5,-0.25,1000,0.01,0.02,0\n"),
    )
    .unwrap();
    assert_eq!(m.observations[0].sigma_m, Some([1e-5, 2e-5, 0.0]));
    let m = read(
        &job,
        &format!("{HEADER}\n1,0,7,0,90,-45,150,1234.5,-0.25,1000\n"),
    )
    .unwrap();
    assert_eq!(m.observations[0].sigma_m, None);
    let e = read_err(
        &job,
        &format!("{HEADER},sx,sz\n1,0,7,0,90,-45,150,1234.5,-0.25,1000,0.01,0\n"),
    );
    assert_eq!(
        e.to_string(),
        "d.csv:1: column 'sy': the instrument's σ comes as three columns sx, sy, sz or none"
    );
    let e = read_err(
        &job,
        &format!("{HEADER},sx,sy,sz\n1,0,7,0,90,-45,150,1234.5,-0.25,1000,0.01,-0.02,0\n"),
    );
    assert_eq!(e.kind, ErrorKind::InvalidValue);
    assert_eq!(e.column.as_deref(), Some("sy"));
    // The writer writes them back, bit for bit.
    let path = temp("sigma.csv");
    let mut rows = m.observations.clone();
    rows[0].sigma_m = Some([1e-5, 2.5e-5, 3e-6]);
    write_measurements(&path, &job.robot, job.setup.units, &rows).unwrap();
    let back = read_measurements(&path, &job.robot, &job.setup).unwrap();
    assert_eq!(back.observations[0].sigma_m, rows[0].sigma_m);
}

/// `[model] temperature_column`: the named column is each point's
/// temperature in °C, from −50 to 150; declared, it must be there, and it
/// cannot be a fixed column or a joint.
#[test]
fn temperature_column() {
    let mut job = job();
    job.setup.model.temperature_column = Some("air_c".into());
    let m = read(
        &job,
        &format!("{HEADER},air_c\n1,0,7,0,90,-45,150,1234.5,-0.25,1000,21.25\n"),
    )
    .unwrap();
    assert_eq!(m.observations[0].temp_c, Some(21.25));
    let e = read_err(
        &job,
        &format!("{HEADER}\n1,0,7,0,90,-45,150,1234.5,-0.25,1000\n"),
    );
    assert_eq!(
        e.to_string(),
        "d.csv:1: column 'air_c': missing column (the setup's temperature_column)"
    );
    // Kelvin, below −50 °C, empty, not a number: one error each, at the cell.
    for cell in ["294.4", "-60", "", "warm"] {
        let e = read_err(
            &job,
            &format!("{HEADER},air_c\n1,0,7,0,90,-45,150,1234.5,-0.25,1000,{cell}\n"),
        );
        assert_eq!(e.column.as_deref(), Some("air_c"), "{cell}: {e}");
        assert_eq!(e.line, Some(2), "{cell}: {e}");
        if cell == "294.4" {
            assert!(e.message.contains("kelvin"), "{e}");
        }
    }
    // The job's writer writes them back in its column, bit for bit; the
    // plain writer, which has no column for them, refuses.
    let path = temp("temperature.csv");
    let mut rows = m.observations.clone();
    rows[0].temp_c = Some(-12.375);
    job.write_measurements(&path, &rows).unwrap();
    let back = job.read_measurements(&path).unwrap();
    assert_eq!(back.observations[0].temp_c, Some(-12.375));
    let e = write_measurements(&path, &job.robot, job.setup.units, &rows).unwrap_err();
    assert!(e.message.contains("temperature_column"), "{e}");
    job.setup.model.temperature_column = Some("j2".into());
    let e = read_err(
        &job,
        &format!("{HEADER}\n1,0,7,0,90,-45,150,1234.5,-0.25,1000\n"),
    );
    assert_eq!(e.kind, ErrorKind::DuplicateColumn, "{e}");
}

/// A file of more than a few MB is read in chunks on worker threads
/// (`io::measurements`, issue 16) when the machine has more than one: every
/// row, line number, warning and error must be what one reader gives. The
/// expected values come from the generator here, not from the reader.
#[test]
fn large_files_read_in_chunks_keep_lines_values_and_errors() {
    let job = job();
    let mut rng = Rng::new(16);
    // CRLF and LF lines, blank lines, a time column; ~4 MB.
    let mut text = format!("{HEADER},t\n");
    let mut line = 1;
    let mut expected = Vec::new();
    let mut first_outside = None;
    let mut outside = 0;
    for k in 0..60_000_i64 {
        if k % 997 == 0 {
            text.push_str(if k % 2 == 0 { "\r\n" } else { "\n" });
            line += 1;
        }
        // j1 in degrees, every 5000th row beyond its limits (±2.5 rad) by
        // more than 10 % of the range.
        let j1 = if k % 5000 == 4999 {
            200.0
        } else {
            (rng.uniform() - 0.5) * 200.0
        };
        if j1 > 171.0 {
            outside += 1;
            first_outside.get_or_insert(line + 1);
        }
        // Exact in binary: the reader's decimal shift is then x / 1000.
        let x = (k % 2000) as f64 + 0.25;
        let end = if k % 3 == 0 { "\r\n" } else { "\n" };
        text.push_str(&format!(
            "{},0,1,0,{j1},20,100,{x},1.5,-2,{}{end}",
            k + 1,
            k
        ));
        line += 1;
        expected.push((line, j1.to_radians(), x / 1000.0, k as f64));
    }
    assert!(text.len() > 3 << 20, "large enough to be chunked");
    let m = read(&job, &text).unwrap();
    assert_eq!(m.observations.len(), expected.len());
    for (o, &(line, q1, x, t)) in m.observations.iter().zip(&expected) {
        assert_eq!((o.line, o.q[0], o.p_m[0], o.t_s), (line, q1, x, Some(t)));
    }
    let w: Vec<String> = m.warnings.iter().map(ToString::to_string).collect();
    let first = first_outside.unwrap();
    assert!(
        w.iter().any(|w| w.starts_with(&format!(
            "d.csv:{first}: column 'j1': {outside} value(s) outside the URDF limits"
        ))),
        "{w:?}"
    );
    // An error deep in the file: its line and column, as one reader says.
    let bad_line = expected[45_000].0;
    let mut lines: Vec<&str> = text.split('\n').collect();
    let bad = lines[bad_line - 1].replacen(",1,0,", ",9,0,", 1);
    lines[bad_line - 1] = &bad;
    let e = read_err(&job, &lines.join("\n"));
    assert_eq!(
        (e.kind, e.line, e.column.as_deref()),
        (ErrorKind::UnknownMarker, Some(bad_line), Some("marker"))
    );
    // A short row deep in the file: the csv reader's error, its line.
    let short = format!("{}\n1,0,1\n", text.trim_end());
    let e = read_err(&job, &short);
    assert_eq!((e.kind, e.line), (ErrorKind::Syntax, Some(line + 1)));
    assert!(
        e.to_string()
            .contains("row has 3 fields, the header has 11"),
        "{e}"
    );
}
