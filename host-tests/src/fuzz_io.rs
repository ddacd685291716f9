//! Invariants of the data-contract readers under arbitrary input, shared by
//! the cargo-fuzz targets `csv_measurements`, `setup_toml`, `urdf`, `figaroh_mocap`,
//! `poses` and the
//! stable replay `tests/fuzz_io_regressions.rs`.
//!
//! For every input: no panic; an error names the file the reader was given
//! (and, for the CSV, a line within the file, 1 ≤ line ≤ lines + 1); a
//! success has every number finite and shapes that agree (`q.len() == dof`,
//! one joint name, kind and limit per chain joint, unit axes, deflections
//! that point at a loaded and an unloaded row of the same key).

use std::path::Path;

pub use robcal::io::Robot;
use robcal::io::{parse_measurements, InputError, Setup};

/// The file name every fuzzed reader is given.
pub const CSV_FILE: &str = "fuzz.csv";
/// The file name every fuzzed reader is given.
pub const TOML_FILE: &str = "fuzz.toml";
/// The file name every fuzzed reader is given.
pub const URDF_FILE: &str = "fuzz.urdf";
/// The file name the pose importer is given.
pub const POSES_FILE: &str = "fuzz-poses.csv";

/// The fixed robot of the CSV target: a 3-joint chain (revolute with
/// limits, continuous, prismatic with limits).
pub const CSV_URDF: &str = r#"<robot name="fz">
  <link name="base"/> <link name="l1"><inertial><mass value="2"/><origin xyz="0 0 0.1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="l2"/> <link name="flange"/>
  <joint name="a1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="a2" type="continuous"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.5"/><axis xyz="0 1 0"/></joint>
  <joint name="d3" type="prismatic"><parent link="l2"/><child link="flange"/><origin xyz="0.4 0 0"/><axis xyz="1 0 0"/><limit lower="0" upper="0.2" effort="1" velocity="1"/></joint>
</robot>"#;

/// The robot of [`CSV_URDF`].
pub fn csv_robot() -> Robot {
    Robot::parse(CSV_URDF, "fz.urdf", Some("base"), Some("flange")).expect("fixed robot")
}

/// The setups of the CSV target, chosen by the first input byte: every
/// combination of units, with and without `[load]`, markers 1 and 2.
pub fn csv_setup(selector: u8) -> Setup {
    let angle = if selector & 1 == 0 { "deg" } else { "rad" };
    let length = if selector & 2 == 0 { "mm" } else { "m" };
    let load = if selector & 4 == 0 {
        "[load]\ncom = [0.1, 0, 0]\n"
    } else {
        ""
    };
    let text = format!(
        "robot = \"fz.urdf\"\n[units]\nangle = \"{angle}\"\nlength = \"{length}\"\n\
         [[marker]]\nid = 1\n[[marker]]\nid = 2\nxyz = [0.1, 0, 0]\n{load}"
    );
    Setup::parse(&text, "fz.toml").expect("fixed setup")
}

/// Lines of `text`: ends at `\n`, `\r\n` or a lone `\r` (as the CSV
/// reader counts them; an upper bound for the TOML and URDF readers).
pub fn line_count(text: &[u8]) -> usize {
    let ends = text
        .iter()
        .enumerate()
        .filter(|&(i, &b)| b == b'\n' || (b == b'\r' && text.get(i + 1) != Some(&b'\n')))
        .count();
    ends + 1
}

fn check_err(e: &InputError, file: &str, text: Option<&[u8]>) {
    assert_eq!(e.file, Path::new(file), "error does not name the file: {e}");
    let shown = e.to_string();
    assert!(
        shown.starts_with(file),
        "Display does not start with the file: {shown}"
    );
    assert!(!e.message.is_empty(), "empty message: {e:?}");
    if let (Some(line), Some(text)) = (e.line, text) {
        let lines = line_count(text);
        assert!(
            line >= 1 && line <= lines + 1,
            "line {line} of {lines}: {e}"
        );
    }
}

fn all_finite<'a>(v: impl IntoIterator<Item = &'a f64>) -> bool {
    v.into_iter().all(|x| x.is_finite())
}

/// Checks a parsed robot's invariants.
pub fn check_robot(r: &Robot) {
    let dof = r.dof();
    assert!((1..=robcal::io::MAX_JOINTS).contains(&dof));
    assert_eq!(r.chain.dof(), dof);
    assert_eq!(r.joint_kinds.len(), dof);
    assert_eq!(r.limits.len(), dof);
    for (i, n) in r.joint_names.iter().enumerate() {
        assert!(
            !r.joint_names[..i].contains(n),
            "joint name '{n}' twice in the chain"
        );
    }
    for j in r.chain.joints() {
        let o = &j.origin;
        assert!(all_finite(o.translation.vector.iter()), "origin {o:?}");
        assert!(all_finite(o.rotation.coords.iter()), "rotation {o:?}");
        assert!(all_finite(j.axis.iter()), "axis {:?}", j.axis);
        assert!(
            (j.axis.norm() - 1.0).abs() < 1e-9,
            "axis not unit: {:?}",
            j.axis
        );
        if let Some(l) = &j.link {
            assert!(l.mass_kg.is_finite() && l.mass_kg > 0.0, "mass {l:?}");
            assert!(all_finite(l.com_m.iter()), "com {l:?}");
        }
    }
    let t = r.chain.tip();
    assert!(all_finite(t.translation.vector.iter()) && all_finite(t.rotation.coords.iter()));
    for l in r.limits.iter().flatten() {
        assert!(l.lower.is_finite() && l.upper.is_finite() && l.lower < l.upper);
    }
    for b in &r.off_chain {
        assert!(b.mass_kg.is_finite() && b.mass_kg >= 0.0, "{b:?}");
        assert!(b.chain_joint < dof);
    }
}

/// The `urdf` target: `data` = base name, tip name, URDF text (split at the
/// first two NUL bytes; a missing name means `None`).
pub fn run_urdf(data: &[u8]) {
    let Ok(s) = std::str::from_utf8(data) else {
        return;
    };
    let mut parts = s.splitn(3, '\0');
    let (a, b, text) = (parts.next(), parts.next(), parts.next());
    let (base, tip, text) = match (a, b, text) {
        (Some(a), Some(b), Some(t)) => (
            (!a.is_empty()).then_some(a),
            (!b.is_empty()).then_some(b),
            t,
        ),
        _ => (None, None, s),
    };
    match Robot::parse(text, URDF_FILE, base, tip) {
        Ok(r) => check_robot(&r),
        Err(e) => check_err(&e, URDF_FILE, Some(text.as_bytes())),
    }
}

/// The `setup_toml` target: `data` is the TOML text.
pub fn run_setup(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match Setup::parse(text, TOML_FILE) {
        Ok(s) => {
            assert!(!s.markers.is_empty());
            for m in &s.markers {
                assert!(all_finite(&m.xyz));
            }
            if let Some(l) = &s.load {
                assert!(all_finite(&l.com) && all_finite(&l.gravity));
            }
            assert!(s.noise.sigma0_um.is_finite() && s.noise.sigma0_um > 0.0);
            assert!(s.noise.lambda.is_finite() && s.noise.lambda >= 0.0);
            // The writer's text reads back to an equal setup.
            let again = Setup::parse(&s.to_toml(), TOML_FILE).expect("to_toml reads back");
            assert_eq!(again, s);
        }
        Err(e) => check_err(&e, TOML_FILE, Some(data)),
    }
}

/// The `csv_measurements` target: first byte selects the setup
/// ([`csv_setup`]), the rest is the CSV file.
pub fn run_csv(robot: &Robot, data: &[u8]) {
    let Some((&sel, csv)) = data.split_first() else {
        return;
    };
    let setup = csv_setup(sel);
    match parse_measurements(csv, CSV_FILE, robot, &setup) {
        Ok(m) => {
            let dof = robot.dof();
            assert!(!m.observations.is_empty());
            let lines = line_count(csv);
            for o in &m.observations {
                assert_eq!(o.q.len(), dof);
                assert_eq!(o.q_written.len(), dof);
                assert!(all_finite(&o.q) && all_finite(&o.p_m), "{o:?}");
                assert!(o.load_kg.is_finite() && o.load_kg >= 0.0);
                assert!(o.t_s.is_none_or(f64::is_finite));
                assert_eq!(o.t_s.is_some(), m.has_time);
                assert!(setup.markers.iter().any(|mk| mk.id == o.marker));
                assert!(o.line >= 2 && o.line <= lines, "line {} of {lines}", o.line);
            }
            for d in &m.deflections {
                let (l, u) = (&m.observations[d.rows[0]], &m.observations[d.rows[1]]);
                assert!(l.load_kg > 0.0 && u.load_kg == 0.0);
                assert_eq!((l.config, l.rep, l.marker), (u.config, u.rep, u.marker));
                assert_eq!(d.q.len(), dof);
                assert!(all_finite(&d.dp_m), "{d:?}");
            }
            let loaded = m.observations.iter().filter(|o| o.load_kg > 0.0).count();
            assert_eq!(loaded, m.deflections.len());
            for w in &m.warnings {
                assert_eq!(w.file, Path::new(CSV_FILE));
            }
        }
        Err(e) => check_err(&e, CSV_FILE, Some(csv)),
    }
}

/// The file name the `figaroh_mocap` target's errors must carry.
pub const MOCAP_FILE: &str = "fuzz-mocap.csv";

/// The `figaroh_mocap` target (`robcal import figaroh-mocap`'s reader):
/// `data` is the FIGAROH mocap CSV text. A success gives four finite rows
/// per posture with one value per joint column.
pub fn run_mocap(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match robcal::io::figaroh::parse_mocap(text, MOCAP_FILE) {
        Ok(m) => match m.observations(None) {
            Ok(rows) => {
                assert_eq!(rows.len(), 4 * m.postures.len());
                for o in &rows {
                    assert_eq!(o.q.len(), m.joint_names.len());
                    assert!(all_finite(&o.q) && all_finite(&o.p_m), "{o:?}");
                    assert!(o.t_s.is_none_or(f64::is_finite));
                }
            }
            Err(e) => check_err(&e, MOCAP_FILE, Some(data)),
        },
        Err(e) => check_err(&e, MOCAP_FILE, Some(data)),
    }
}

/// Arbitrary text as a wide pose file (`robcal import poses`, data contract
/// 7.3), with and without `--split cal`: no panic; an error names the file
/// (and a line inside it); a success is a measurement CSV whose every row
/// has the header's cells, integers in `config, rep, marker, load_kg` and
/// finite numbers elsewhere, one row per reported point.
pub fn run_poses(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    for split in [None, Some("cal".to_owned())] {
        let options = robcal::io::poses::ImportOptions { split, euler: None };
        match robcal::io::poses::convert_poses(text, POSES_FILE, &options) {
            Ok((csv, summary)) => {
                let mut lines = csv.lines();
                let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
                assert_eq!(&header[..4], ["config", "rep", "marker", "load_kg"]);
                assert_eq!(
                    header.len(),
                    4 + summary.joints.len() + 3 + if summary.has_sigma { 3 } else { 0 }
                );
                let mut rows = 0;
                for line in lines {
                    let cells: Vec<&str> = line.split(',').collect();
                    assert_eq!(cells.len(), header.len(), "{line}");
                    for c in &cells[..3] {
                        assert!(c.parse::<i64>().is_ok(), "{line}");
                    }
                    for c in &cells[3..] {
                        let v: f64 = c.parse().unwrap_or(f64::NAN);
                        assert!(v.is_finite(), "{line}");
                    }
                    rows += 1;
                }
                assert_eq!(rows, summary.rows);
                assert!(rows > 0 && summary.poses > 0 && summary.poses <= rows);
            }
            Err(e) => check_err(&e, POSES_FILE, Some(data)),
        }
    }
}
