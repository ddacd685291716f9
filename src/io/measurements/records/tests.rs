//! Tests of the records and of the chunks joined.

use crate::io::measurements::records::{each_record, line_ends, Observation, Read, WrittenCells};

/// Chunks' observations joined keep their cells as written: with the
/// texts joined whole, attached past the limit, and after a chunk that
/// attached some of its own.
#[test]
fn joined_chunks_keep_their_cells() {
    let cells = |i: usize| [format!("{i}.0"), format!("-{i}e-3"), " ".repeat(i % 3)];
    // A chunk of `n` observations from `i0`, the first `attached`
    // of them with a text of their own.
    let chunk = |i0: usize, n: usize, attached: usize| {
        let mut text = String::new();
        let mut obs: Vec<Observation> = (i0..i0 + n)
            .map(|i| Observation {
                q_written: WrittenCells::pending(&mut text, cells(i).iter().map(String::as_str)),
                line: i,
                ..Observation::default()
            })
            .collect();
        if attached > 0 {
            let mut own = String::new();
            for (o, i) in obs[..attached].iter_mut().zip(i0..) {
                o.q_written = WrittenCells::pending(&mut own, cells(i).iter().map(String::as_str));
            }
            WrittenCells::attach(
                &mut own,
                obs[..attached].iter_mut().map(|o| &mut o.q_written),
            );
            text.clear();
            for (o, i) in obs[attached..].iter_mut().zip(i0 + attached..) {
                o.q_written = WrittenCells::pending(&mut text, cells(i).iter().map(String::as_str));
            }
        }
        (obs, text, attached)
    };
    for joined in [usize::MAX, 0, 40, 200] {
        let mut read = Read::new(3, false);
        read.joined = joined;
        let mut i0 = 0;
        for (n, attached) in [(5, 0), (0, 0), (7, 3), (4, 0), (1, 1), (9, 0)] {
            let (mut obs, text, first) = chunk(i0, n, attached);
            read.join(&mut obs, &text, first);
            i0 += n;
        }
        let (obs, _) = read.finish();
        assert_eq!(obs.len(), i0);
        for (i, o) in obs.iter().enumerate() {
            assert_eq!(o.line, i);
            let got: Vec<&str> = o.q_written.iter().collect();
            assert_eq!(got, cells(i), "observation {i}, joined at {joined}");
        }
    }
}

/// The records and trimmed cells [`each_record`] finds are the csv
/// crate's (the reader the chunks had before, and the one reader of
/// every other file), and start where its records do (past a line end
/// the reader's position may be on: the same line).
#[test]
fn records_are_the_csv_readers() {
    let texts = [
        "",
        "\n\r\n\r",
        "a,b\nc,d",
        "a,b\r\nc,d\r\n",
        "\r\n\r\na, b \r\r\n\n\t c ,d\t\n",
        " 1 , 2 ,3\r4,5,6\r\r7,,8",
        "x,\u{a0}y\u{a0},z\u{2003}\n\u{3000}\n,\n, ,\u{b}\u{c}\n",
        "1.5e3,-0,+2\n\n\n3,4\n",
    ];
    for text in texts {
        let mut rdr = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .trim(csv::Trim::All)
            .from_reader(text.as_bytes());
        let want: Vec<(usize, Vec<String>)> = rdr
            .records()
            .map(|r| {
                let r = r.unwrap();
                // The reader's position may be on the line end before
                // the record (`line_at` skips it).
                let mut at = r.position().unwrap().byte() as usize;
                while matches!(text.as_bytes().get(at), Some(b'\r' | b'\n')) {
                    at += 1;
                }
                (at, r.iter().map(String::from).collect())
            })
            .collect();
        let mut got = Vec::new();
        each_record(text, |at, record| {
            got.push((
                at,
                record.split(',').map(|c| c.trim().to_string()).collect(),
            ));
            Some(())
        });
        assert_eq!(got, want, "{text:?}");
    }
    // It stops at the first `None`.
    let mut seen = 0;
    assert!(each_record("a\nb\nc", |_, _| {
        seen += 1;
        (seen < 2).then_some(())
    })
    .is_none());
    assert_eq!(seen, 2);
}

#[test]
fn line_ends_are_lf_crlf_and_a_lone_cr_in_any_range() {
    let bytes = b"a,b\nc\r\nd\re\r\r\n\n\rf\r";
    // A byte at a time (the reference).
    let want: Vec<usize> = (0..bytes.len())
        .filter(|&i| bytes[i] == b'\n' || (bytes[i] == b'\r' && bytes.get(i + 1) != Some(&b'\n')))
        .collect();
    assert_eq!(want, [3, 6, 8, 10, 12, 13, 14, 16]);
    for split in 0..=bytes.len() {
        let mut got = line_ends(bytes, 0..split);
        got.extend(line_ends(bytes, split..bytes.len()));
        assert_eq!(got, want, "split at {split}");
    }
}
