//! A file read a block at a time is the file read whole: the same
//! measurements (every observation with its line, the deflections, the
//! warnings), whatever the block size and the threads; and every file the
//! blocks cannot read is left to the whole file's reading.

use crate::io::measurements::stream::Blocks;
use crate::io::measurements::{parse_measurements, Measurements, WrittenCells};
use crate::io::setup::Setup;
use crate::io::urdf::Robot;

/// `m` without its joint cells as written (the blocks keep none).
fn without_cells(m: &Measurements) -> Measurements {
    let mut m = m.clone();
    for o in &mut m.observations {
        o.q_written = WrittenCells::default();
    }
    m.cells_in_file = None;
    m
}

/// Three revolute joints limited to ±1 rad.
fn robot() -> Robot {
    let joint = |name: &str, parent: &str, child: &str| {
        format!(
            "<joint name=\"{name}\" type=\"revolute\"><parent link=\"{parent}\"/>\
             <child link=\"{child}\"/><origin xyz=\"0 0 0.5\" rpy=\"0.3 0 0\"/>\
             <axis xyz=\"0 1 0\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" \
             velocity=\"1\"/></joint>"
        )
    };
    let urdf = format!(
        "<robot name=\"r\"><link name=\"base\"/><link name=\"a\"/><link name=\"b\"/>\
         <link name=\"c\"/>{}{}{}</robot>",
        joint("j1", "base", "a"),
        joint("j2", "a", "b"),
        joint("j3", "b", "c"),
    );
    Robot::parse(&urdf, "r.urdf", Some("base"), Some("c")).expect("a valid URDF")
}

fn setup() -> Setup {
    Setup::parse(
        "robot = \"r.urdf\"\nbase_link = \"base\"\ntip_link = \"c\"\n\
         [units]\nangle = \"rad\"\nlength = \"m\"\n\
         [[marker]]\nid = 1\nxyz = [0.0, 0.0, 0.05]\n\
         [[marker]]\nid = 7\nxyz = [0.02, 0.0, 0.05]\n\
         [load]\ncom = [0.0, 0.0, 0.1]\n",
        "s.toml",
    )
    .expect("a valid setup")
}

/// A file of `configs` configurations, two markers each, every third one
/// loaded (10 kg, its joints moved a little: warnings), some joints beyond
/// their limits (warnings), a time column, line ends `\n`, `\r\n` and a
/// lone `\r`, blank lines and cells with spaces.
fn file(configs: usize) -> String {
    let mut s = String::from("config, rep ,marker,load_kg,j1,j2,j3,x,y,z,t\n");
    let v = |i: usize, k: usize| ((i * 7919 + k * 104_729) % 2000) as f64 / 1000.0 - 1.0;
    for i in 0..configs {
        let q = [v(i, 0) * 1.5, v(i, 1), v(i, 2)];
        for (m, marker) in [1, 7].into_iter().enumerate() {
            let end = match (i + m) % 17 {
                0 => "\r\n",
                5 => "\r",
                9 => "\n\n",
                _ => "\n",
            };
            let p = [v(i, 3 + m), v(i, 5 + m), v(i, 7 + m)];
            s += &format!(
                "{i},1, {marker} ,0,{},{},{},{},{},{},{}{end}",
                q[0],
                q[1],
                q[2],
                p[0],
                p[1],
                p[2],
                i as f64 * 0.5
            );
            if i % 3 == 0 {
                let dq = if i % 9 == 0 { 0.01 } else { 0.0 };
                s += &format!(
                    "{i},1,{marker},10,{},{},{},{},{},{},{}\n",
                    q[0] + dq,
                    q[1],
                    q[2],
                    p[0] + 1e-4,
                    p[1],
                    p[2] - 2e-4,
                    i as f64 * 0.5 + 0.25
                );
            }
        }
    }
    s
}

fn blocks(block: usize, threads: usize, limit: u64, len: usize) -> Blocks {
    Blocks {
        file: "d.csv".into(),
        len: len as u64,
        limit,
        threads,
        block,
    }
}

#[test]
fn blocks_read_what_the_whole_file_reads() {
    let (robot, setup) = (robot(), setup());
    let text = file(700);
    let whole = parse_measurements(text.as_bytes(), "d.csv", &robot, &setup).expect("valid");
    assert!(whole.observations.len() > 1800 && whole.deflections.len() > 400);
    assert!(whole.warnings.len() >= 2, "{:?}", whole.warnings);
    assert!(whole
        .observations
        .iter()
        .any(|o| o.line > text.lines().count() / 2));
    for block in [400, 997, 4096, 65_536, 1 << 20] {
        for threads in [1, 2, 3] {
            let read = blocks(block, threads, u64::MAX, text.len())
                .read(text.as_bytes(), &robot, &setup)
                .unwrap_or_else(|| panic!("block {block}, threads {threads}: not read"))
                .expect("valid");
            assert!(read.cells_in_file.is_some());
            let read = without_cells(&read);
            assert_eq!(
                read,
                without_cells(&whole),
                "block {block}, threads {threads}"
            );
            assert!(read.observations.iter().all(|o| o.q_written.is_empty()));
        }
    }
}

#[test]
fn what_the_blocks_cannot_read_is_left_to_the_whole_file() {
    let (robot, setup) = (robot(), setup());
    let text = file(300);
    let len = text.len();
    let none = |text: &str, block: usize, limit: u64| {
        blocks(block, 2, limit, text.len())
            .read(text.as_bytes(), &robot, &setup)
            .is_none()
    };
    // An error in a record far from the first block.
    let bad = text.replacen("299,1, 7 ,0,", "299,1, 7 ,0,x", 1);
    assert!(parse_measurements(bad.as_bytes(), "d.csv", &robot, &setup).is_err());
    assert!(none(&bad, 4096, u64::MAX));
    // A quote; a line longer than a block; more than the limit.
    assert!(none(
        &text.replacen("150,1,", "\"150\",1,", 1),
        4096,
        u64::MAX
    ));
    assert!(none(&text, 40, u64::MAX));
    assert!(none(&text, 4096, len as u64 - 1));
    // An unknown column.
    assert!(none(
        &text.replacen("config,", "configs,", 1),
        4096,
        u64::MAX
    ));
    // And what is read otherwise is read (the limit is the file's size).
    assert!(!none(&text, 4096, len as u64));
}

/// A pairing error is the whole file's own error (the blocks give it).
#[test]
fn a_pairing_error_is_the_whole_files() {
    let (robot, setup) = (robot(), setup());
    let text = file(300).replacen("150,1, 1 ,0,", "150,1, 1 ,5,", 1);
    let whole = parse_measurements(text.as_bytes(), "d.csv", &robot, &setup).unwrap_err();
    let read = blocks(4096, 2, u64::MAX, text.len())
        .read(text.as_bytes(), &robot, &setup)
        .expect("read in blocks")
        .unwrap_err();
    assert_eq!(read.to_string(), whole.to_string());
}

/// A file is read in blocks when it is a regular file within the sizes;
/// read so, it is what the whole file's reading gives.
#[test]
fn a_file_is_read_in_blocks_only_within_its_sizes() {
    let (robot, setup) = (robot(), setup());
    let dir = std::env::temp_dir().join(format!("robcal-stream-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let path = dir.join("d.csv");
    let text = file(3000);
    std::fs::write(&path, &text).expect("written");
    let len = text.len() as u64;
    assert!(len > crate::io::measurements::stream::BLOCK_BYTES as u64 / 16);
    let of = |limit, threads, from| Blocks::of(&path, limit, threads, from).is_some();
    assert!(of(len, 2, len));
    assert!(!of(len - 1, 2, 0), "larger than the limit");
    assert!(!of(len, 2, len + 1), "smaller than where blocks start");
    assert!(of(len, 1, 0), "one thread");
    assert!(Blocks::of(&dir, u64::MAX, 2, 0).is_none(), "a directory");
    let mut blocks = Blocks::of(&path, len, 2, 0).expect("read in blocks");
    blocks.block = 8192;
    let read = blocks
        .read(std::fs::File::open(&path).expect("open"), &robot, &setup)
        .expect("read in blocks")
        .expect("valid");
    let whole = parse_measurements(text.as_bytes(), &path, &robot, &setup).expect("valid");
    assert_eq!(without_cells(&read), without_cells(&whole));
    // Every cell as written, read again from the file (some lines: all of
    // them would be a test of the line ends alone), is the whole file's.
    let wanted: Vec<_> = (read.observations.iter())
        .step_by(7)
        .flat_map(|o| (0..3).map(move |j| (o, j)))
        .collect();
    let own: Vec<_> = (whole.observations.iter())
        .step_by(7)
        .flat_map(|o| (0..3).map(move |j| o.q_written.get(j).map(|c| c.trim().to_string())))
        .collect();
    assert!(own.iter().all(Option::is_some) && own.len() > 1000);
    assert_eq!(read.written_cells(&wanted).expect("read again"), own);
    // A block smaller than a line, and blocks across line ends.
    let lines: Vec<usize> = whole.observations.iter().map(|o| o.line).collect();
    let all = lines_of_text(&text);
    let own: Vec<String> = lines.iter().map(|&l| all[l - 1].clone()).collect();
    for block in [7, 64, 1000] {
        let got = crate::io::measurements::stream::lines_of(&path, &lines, block).expect("read");
        let bad = (got.iter().zip(&own)).position(|(g, o)| g != o);
        assert!(
            bad.is_none() && got.len() == own.len(),
            "block {block}: line {:?}: {:?} against {:?}",
            bad.map(|k| lines[k]),
            bad.map(|k| &got[k]),
            bad.map(|k| &own[k])
        );
    }
    // A file changed since: an error naming the line, not another name.
    let o = &read.observations[100];
    let cell = whole.observations[100]
        .q_written
        .get(1)
        .expect("a cell")
        .trim()
        .to_string();
    let line = all[o.line - 1].clone();
    let changed = line.replacen(&cell, "0.123456", 1);
    assert_ne!(changed, line);
    std::fs::write(&path, text.replacen(&line, &changed, 1)).expect("written");
    let e = read.written_cells(&[(o, 1)]).expect_err("changed");
    assert_eq!(e.line, Some(o.line), "{e}");
    assert!(e.to_string().contains("changed"), "{e}");
    std::fs::remove_dir_all(&dir).expect("removed");
    // Nothing wanted, nothing read: the file may be gone.
    assert_eq!(read.written_cells(&[]).expect("nothing to read"), []);
    assert!(read.written_cells(&[(o, 1)]).is_err());
}

/// The lines of `text` (the header's first), their line ends `\n`,
/// `\r\n` or a lone `\r` (as [`crate::io::measurements::stream::line_ends`] counts them).
fn lines_of_text(text: &str) -> Vec<String> {
    let (mut out, mut after_cr) = (Vec::new(), false);
    for s in text.split_inclusive(['\n', '\r']) {
        // `\r\n` is one line end: the `\n` after a `\r` ends no line.
        let skip = s == "\n" && after_cr;
        after_cr = s.ends_with('\r');
        if !skip {
            out.push(s.trim_end_matches(['\r', '\n']).to_string());
        }
    }
    out
}
