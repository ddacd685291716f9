//! The records of a measurement file after its header: one row into an
//! [`Observation`] ([`Layout::observation`]), and the rows of a large file
//! in chunks on worker threads ([`chunked`]).

use std::path::Path;

use crate::io::cells::{parse_int, parse_real, parse_real_written, Scale};
use crate::io::measurements::{
    Col, Observation, Scalar, Stats, WrittenCells, MAX_LOAD_KG, MAX_POSITION_M, MAX_SIGMA_RAD,
    MAX_TEMPERATURE_C, MAX_TIME_S, MIN_TEMPERATURE_C,
};
use crate::io::setup::{AngleUnit, LengthUnit, Setup};
use crate::io::urdf::{Robot, UrdfJointKind};
use crate::io::{error::ErrorKind, error::InputError};

/// Fewest bytes of records a chunk is made for: smaller files are read by
/// one reader.
const MIN_CHUNK_BYTES: usize = 1 << 20;

/// What a record's cells are: the file's header as read.
pub(super) struct Layout<'a> {
    /// The file, for errors.
    pub(super) file: &'a Path,
    /// The robot the joint columns are of.
    pub(super) robot: &'a Robot,
    /// Units, markers and load.
    pub(super) setup: &'a Setup,
    /// The header's cells (the columns' names).
    pub(super) header: &'a csv::StringRecord,
    /// Each field's column.
    pub(super) cols: &'a [Col],
    /// Each joint's field.
    pub(super) joint_field: &'a [Option<usize>],
    /// The setup's marker ids.
    pub(super) markers: Vec<u32>,
}

impl Layout<'_> {
    /// The record on `line` as an observation; `stats` takes its joint
    /// values and positions (limits, units); its joint cells as written go
    /// to the batch text `written` ([`Batch`]), when there is one.
    ///
    /// # Errors
    /// The first of its cells that is rejected (module [`super`]), with the
    /// line and the column.
    pub(super) fn observation(
        &self,
        record: &[&str],
        line: usize,
        stats: &mut Stats,
        written: Option<&mut String>,
    ) -> Result<Observation, InputError> {
        let mut o = Observation {
            q: smallvec::smallvec![0.0; self.robot.dof()],
            line,
            rep: 1,
            marker: self.markers.first().copied().unwrap_or(1),
            ..Observation::default()
        };
        // Empty orientation cells: all of a row's (a point without its
        // orientation) or none.
        let (mut empty_rot, mut empty_sigma_rot) = (Vec::new(), Vec::new());
        // Empty point cells (a plane contact's or a distance's row has
        // none), and the cells of those rows.
        let (mut empty_point, mut point_cells) = (Vec::new(), Vec::new());
        let (mut plane, mut anchor, mut distance, mut sd) = (None, None, None, None);
        for ((&cell, &col), name) in record.iter().zip(self.cols).zip(self.header.iter()) {
            let cerr = |kind, message: String| {
                InputError::new(self.file, kind, message)
                    .at_line(line)
                    .in_column(name)
            };
            if col == Col::Ignored {
                continue;
            }
            if cell.is_empty() {
                match col {
                    Col::Rot(_) => empty_rot.push(name),
                    Col::SigmaRot(_) => empty_sigma_rot.push(name),
                    Col::Pos(_) | Col::Sigma(_) => empty_point.push(name),
                    Col::Plane | Col::Anchor | Col::Distance | Col::SigmaScalar => {}
                    _ => return Err(cerr(ErrorKind::Syntax, "empty cell".into())),
                }
                continue;
            }
            if matches!(
                col,
                Col::Pos(_) | Col::Sigma(_) | Col::Rot(_) | Col::SigmaRot(_)
            ) {
                point_cells.push(name);
            }
            match col {
                Col::Ignored => {}
                Col::Config => {
                    o.config = parse_int(cell).map_err(|m| cerr(ErrorKind::Syntax, m))?
                }
                Col::Rep => o.rep = parse_int(cell).map_err(|m| cerr(ErrorKind::Syntax, m))?,
                Col::Marker => {
                    o.marker = cell.parse().map_err(|_| {
                        cerr(
                            ErrorKind::Syntax,
                            format!("'{cell}' is not a marker id (integer 0 to {})", u32::MAX),
                        )
                    })?;
                    if !self.markers.contains(&o.marker) {
                        return Err(cerr(
                            ErrorKind::UnknownMarker,
                            format!("marker {} is not declared in the setup", o.marker),
                        ));
                    }
                }
                Col::Load => {
                    o.load_kg = parse_real(cell, Scale::One).map_err(|(k, m)| cerr(k, m))?;
                    if o.load_kg < 0.0 {
                        return Err(cerr(
                            ErrorKind::InvalidValue,
                            format!("negative load {} kg", o.load_kg),
                        ));
                    }
                    if o.load_kg > MAX_LOAD_KG {
                        return Err(cerr(
                            ErrorKind::InvalidValue,
                            format!(
                                "load {:?} kg is more than {MAX_LOAD_KG:?} kg: no robot carries it \
                                 (another unit, or an overflow?)",
                                o.load_kg
                            ),
                        ));
                    }
                    if o.load_kg > 0.0 && self.setup.load.is_none() {
                        return Err(cerr(
                            ErrorKind::InvalidValue,
                            "loaded row, but the setup has no [load] saying where the load acts"
                                .into(),
                        ));
                    }
                }
                Col::Joint(j) => {
                    let kind = self.robot.joint_kinds[j];
                    let scale = if kind.is_angular() {
                        Scale::Angle(self.setup.units.angle)
                    } else {
                        Scale::Length(self.setup.units.length)
                    };
                    let (written, v) =
                        parse_real_written(cell, scale).map_err(|(k, m)| cerr(k, m))?;
                    if kind.is_angular() {
                        stats.max_angle_written = stats.max_angle_written.max(written.abs());
                    }
                    if let (UrdfJointKind::Revolute, AngleUnit::Rad, Some(l)) =
                        (kind, self.setup.units.angle, self.robot.limits[j])
                    {
                        let tau = std::f64::consts::TAU;
                        if v.abs() > tau && l.lower >= -tau && l.upper <= tau {
                            return Err(cerr(
                                ErrorKind::Units,
                                format!(
                                    "{v} rad is beyond ±2π for a joint limited to [{}, {}] rad: \
                                     is the column in degrees? ([units] angle = \"rad\")",
                                    l.lower, l.upper
                                ),
                            ));
                        }
                    }
                    if let Some(l) = self.robot.limits[j] {
                        let margin = 0.1 * (l.upper - l.lower);
                        if v < l.lower - margin || v > l.upper + margin {
                            let (count, _) = stats.outside[j].get_or_insert((0, line));
                            *count += 1;
                        }
                    }
                    o.q[j] = v;
                }
                Col::Pos(k) => {
                    let (written, v) =
                        parse_real_written(cell, Scale::Length(self.setup.units.length))
                            .map_err(|(k, m)| cerr(k, m))?;
                    if v.abs() > MAX_POSITION_M {
                        return Err(cerr(
                            ErrorKind::InvalidValue,
                            format!(
                                "{v:?} m is more than {MAX_POSITION_M:?} m from the origin \
                                 (another unit, or an overflow?)"
                            ),
                        ));
                    }
                    if self.setup.units.length == LengthUnit::M && v.abs() > 100.0 {
                        return Err(cerr(
                            ErrorKind::Units,
                            format!(
                                "{v} m is more than 100 m from the origin: is the column in \
                                 millimetres? ([units] length = \"m\")"
                            ),
                        ));
                    }
                    stats.max_pos_written = stats.max_pos_written.max(written.abs());
                    o.p_m[k] = v;
                }
                Col::Time => {
                    let t = parse_real(cell, Scale::One).map_err(|(k, m)| cerr(k, m))?;
                    if t.abs() > MAX_TIME_S {
                        return Err(cerr(
                            ErrorKind::InvalidValue,
                            format!(
                                "{t:?} s is more than {MAX_TIME_S:?} s from 0 (milliseconds, \
                                 or an overflow?)"
                            ),
                        ));
                    }
                    o.t_s = Some(t);
                }
                Col::Temperature => {
                    let t = parse_real(cell, Scale::One).map_err(|(k, m)| cerr(k, m))?;
                    if !(MIN_TEMPERATURE_C..=MAX_TEMPERATURE_C).contains(&t) {
                        return Err(cerr(
                            ErrorKind::InvalidValue,
                            format!(
                                "{t:?} °C is outside [{MIN_TEMPERATURE_C}, {MAX_TEMPERATURE_C}] \
                                 °C (kelvin or °F?)"
                            ),
                        ));
                    }
                    o.temp_c = Some(t);
                }
                Col::Sigma(k) => {
                    let v = parse_real(cell, Scale::Length(self.setup.units.length))
                        .map_err(|(k, m)| cerr(k, m))?;
                    if !(0.0..=MAX_POSITION_M).contains(&v) {
                        return Err(cerr(
                            ErrorKind::InvalidValue,
                            format!(
                                "σ {v:?} m: the instrument's standard deviation is a length \
                                 from 0 to {MAX_POSITION_M:?} m"
                            ),
                        ));
                    }
                    o.sigma_m.get_or_insert([0.0; 3])[k] = v;
                }
                Col::Rot(k) => {
                    let (written, v) =
                        parse_real_written(cell, Scale::Angle(self.setup.units.angle))
                            .map_err(|(k, m)| cerr(k, m))?;
                    stats.max_rot_written = stats.max_rot_written.max(written.abs());
                    o.r_rad.get_or_insert([0.0; 3])[k] = v;
                }
                Col::SigmaRot(k) => {
                    let v = parse_real(cell, Scale::Angle(self.setup.units.angle))
                        .map_err(|(k, m)| cerr(k, m))?;
                    if !(0.0..=MAX_SIGMA_RAD).contains(&v) {
                        return Err(cerr(
                            ErrorKind::InvalidValue,
                            format!(
                                "σ {v:?} rad: the instrument's standard deviation of an \
                                 orientation is an angle from 0 to {MAX_SIGMA_RAD:?} rad"
                            ),
                        ));
                    }
                    o.sigma_rad.get_or_insert([0.0; 3])[k] = v;
                }
                Col::Plane | Col::Anchor => {
                    let id: u32 = cell.parse().map_err(|_| {
                        cerr(
                            ErrorKind::Syntax,
                            format!("'{cell}' is not an id (integer 0 to {})", u32::MAX),
                        )
                    })?;
                    if col == Col::Plane {
                        plane = Some((id, name));
                    } else {
                        anchor = Some((id, name));
                    }
                }
                Col::Distance | Col::SigmaScalar => {
                    let (written, v) =
                        parse_real_written(cell, Scale::Length(self.setup.units.length))
                            .map_err(|(k, m)| cerr(k, m))?;
                    let what = if col == Col::Distance {
                        "distance"
                    } else {
                        "σ"
                    };
                    if v.abs() > MAX_POSITION_M {
                        return Err(cerr(
                            ErrorKind::InvalidValue,
                            format!(
                                "{what} {v:?} m is more than {MAX_POSITION_M:?} m (another \
                                 unit, or an overflow?)"
                            ),
                        ));
                    }
                    if self.setup.units.length == LengthUnit::M && v.abs() > 100.0 {
                        return Err(cerr(
                            ErrorKind::Units,
                            format!(
                                "{what} {v} m is more than 100 m: is the column in \
                                 millimetres? ([units] length = \"m\")"
                            ),
                        ));
                    }
                    if col == Col::Distance {
                        stats.max_pos_written = stats.max_pos_written.max(written.abs());
                        distance = Some((v, name));
                    } else {
                        if v < 0.0 {
                            return Err(cerr(
                                ErrorKind::InvalidValue,
                                format!("σ {v:?} m: a standard deviation is not negative"),
                            ));
                        }
                        sd = Some(v);
                    }
                }
            }
        }
        o.scalar = self.scalar(&o, plane, anchor, distance, sd, &point_cells, line)?;
        if o.scalar.is_some() {
            o.sigma_m = sd.map(|s| [s, 0.0, 0.0]);
        } else if let Some(&name) = empty_point.first() {
            return Err(InputError::new(self.file, ErrorKind::Syntax, "empty cell")
                .at_line(line)
                .in_column(name));
        }
        if let Some(&name) = empty_rot.first().filter(|_| o.r_rad.is_some()) {
            return Err(InputError::new(
                self.file,
                ErrorKind::Syntax,
                "empty cell: a row's rx, ry, rz are all given (a pose) or all empty (a point)",
            )
            .at_line(line)
            .in_column(name));
        }
        let sigma_empty = empty_sigma_rot.first();
        if let Some(&name) = sigma_empty.filter(|_| o.r_rad.is_some() || o.sigma_rad.is_some()) {
            return Err(InputError::new(
                self.file,
                ErrorKind::Syntax,
                "empty cell: srx, sry, srz go with an orientation, all three",
            )
            .at_line(line)
            .in_column(name));
        }
        if o.r_rad.is_none() && o.sigma_rad.is_some() {
            let srx = (self.header.iter()).position(|h| h.trim() == "srx");
            return Err(InputError::new(
                self.file,
                ErrorKind::Syntax,
                "srx, sry, srz without an orientation (rx, ry, rz empty)",
            )
            .at_line(line)
            .in_column(srx.and_then(|k| self.header.get(k)).unwrap_or("srx")));
        }
        if let Some(r) = o.r_rad {
            let err = |kind, message: String| {
                let rx = (self.header.iter()).position(|h| h.trim() == "rx");
                InputError::new(self.file, kind, message)
                    .at_line(line)
                    .in_column(rx.and_then(|k| self.header.get(k)).unwrap_or("rx"))
            };
            let angle = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
            if angle > std::f64::consts::PI + 1e-9 {
                let hint = match self.setup.units.angle {
                    AngleUnit::Rad => "degrees with [units] angle = \"rad\"?",
                    AngleUnit::Deg => "not a rotation vector (axis times angle)?",
                };
                return Err(err(
                    ErrorKind::Units,
                    format!(
                        "the rotation vector (rx, ry, rz) turns by {angle:.6} rad, more than π: {hint}"
                    ),
                ));
            }
            if !o.is_unloaded() {
                return Err(err(
                    ErrorKind::InvalidValue,
                    "an orientation on a loaded row: a deflection is of positions only \
                     (leave rx, ry, rz to the unloaded rows, in a file of their own)"
                        .into(),
                ));
            }
        }
        // Every joint has its column (checked with the header).
        if let Some(written) = written {
            o.q_written = WrittenCells::pending(
                written,
                self.joint_field
                    .iter()
                    .map(|&f| f.and_then(|f| record.get(f).copied()).unwrap_or("")),
            );
        }
        Ok(o)
    }
}

impl Layout<'_> {
    /// The row's plane contact or distance, from its `plane`, `anchor`,
    /// `distance` and `sd` cells (none given: `None`, a point); `point`
    /// names its non-empty point and orientation cells, which such a row
    /// may not have.
    ///
    /// # Errors
    /// A plane or an anchor the setup does not declare, both on one row, an
    /// anchor without a distance (or the reverse), a negative distance
    /// from an anchor, point cells on the row, a loaded row.
    #[allow(clippy::too_many_arguments)]
    fn scalar(
        &self,
        o: &Observation,
        plane: Option<(u32, &str)>,
        anchor: Option<(u32, &str)>,
        distance: Option<(f64, &str)>,
        sd: Option<f64>,
        point: &[&str],
        line: usize,
    ) -> Result<Option<Scalar>, InputError> {
        let err = |kind, column: &str, message: String| {
            InputError::new(self.file, kind, message)
                .at_line(line)
                .in_column(column)
        };
        let scalar = match (plane, anchor) {
            (None, None) => {
                if let Some((_, name)) = distance {
                    return Err(err(
                        ErrorKind::InvalidValue,
                        name,
                        "a distance without an anchor (or a plane) it is from".into(),
                    ));
                }
                if sd.is_some() {
                    return Err(err(
                        ErrorKind::InvalidValue,
                        "sd",
                        "sd without a plane contact or a distance on the row".into(),
                    ));
                }
                return Ok(None);
            }
            (Some(_), Some((_, name))) => {
                return Err(err(
                    ErrorKind::InvalidValue,
                    name,
                    "a row touches a plane or measures a distance from an anchor, not both".into(),
                ))
            }
            (Some((id, name)), None) => {
                let Some(p) = self.setup.planes.iter().find(|p| p.id == id) else {
                    return Err(err(
                        ErrorKind::InvalidValue,
                        name,
                        format!("plane {id} is not declared in the setup ([[plane]])"),
                    ));
                };
                Scalar::Plane {
                    id,
                    normal: p.unit_normal(),
                    offset_m: p.offset_m,
                    value_m: distance.map_or(0.0, |(v, _)| v),
                }
            }
            (None, Some((id, name))) => {
                let Some(a) = self.setup.anchors.iter().find(|a| a.id == id) else {
                    return Err(err(
                        ErrorKind::InvalidValue,
                        name,
                        format!("anchor {id} is not declared in the setup ([[anchor]])"),
                    ));
                };
                let Some((value_m, column)) = distance else {
                    return Err(err(
                        ErrorKind::Syntax,
                        "distance",
                        "empty cell: a row with an anchor measures a distance".into(),
                    ));
                };
                if value_m < 0.0 {
                    return Err(err(
                        ErrorKind::InvalidValue,
                        column,
                        format!("a distance of {value_m:?} m: a distance is not negative"),
                    ));
                }
                Scalar::Distance {
                    id,
                    anchor_m: a.xyz,
                    value_m,
                }
            }
        };
        if let Some(&name) = point.first() {
            return Err(err(
                ErrorKind::InvalidValue,
                name,
                "a plane contact or a distance measures one number, not a point: its x, y, z \
                 (and sx, sy, sz, rx, ry, rz) are empty"
                    .into(),
            ));
        }
        if !o.is_unloaded() {
            return Err(err(
                ErrorKind::InvalidValue,
                "load_kg",
                "a plane contact or a distance on a loaded row: a deflection is of points only"
                    .into(),
            ));
        }
        Ok(Some(scalar))
    }
}

/// Bytes of joint cells as written after which a [`Batch`] gives its text
/// to its rows.
const BATCH_BYTES: usize = 1 << 20;

/// Observations read in order, their joint cells as written in one text
/// per ~[`BATCH_BYTES`] ([`crate::io::measurements::WrittenCells`]).
pub(super) struct Batch {
    /// The observations.
    pub(super) out: Vec<Observation>,
    /// The cells of `out[first..]`, not yet attached.
    text: String,
    /// The first observation whose cells are in `text`.
    first: usize,
    /// Bytes of `text` past which it is attached.
    limit: usize,
    /// Whether the cells are kept (else `text` stays empty:
    /// [`Read::without_cells`]).
    cells: bool,
}

impl Default for Batch {
    fn default() -> Self {
        Self {
            out: Vec::new(),
            text: String::new(),
            first: 0,
            limit: BATCH_BYTES,
            cells: true,
        }
    }
}

impl Batch {
    /// An empty batch in `out` (emptied) with room for `rows`
    /// observations, whose text is not attached (up to
    /// [`WrittenCells::JOINED_BYTES`]) but given to the caller with them
    /// ([`Batch::pending`]).
    pub(super) fn into(mut out: Vec<Observation>, rows: usize, cells: bool) -> Self {
        out.clear();
        out.reserve(rows);
        Self {
            out,
            limit: WrittenCells::JOINED_BYTES,
            cells,
            ..Self::default()
        }
    }

    /// Reads `record` (its cells, trimmed) on `line` into the next
    /// observation.
    ///
    /// # Errors
    /// As [`Layout::observation`] (nothing added).
    pub(super) fn read(
        &mut self,
        layout: &Layout<'_>,
        record: &[&str],
        line: usize,
        stats: &mut Stats,
    ) -> Result<(), InputError> {
        let o = layout.observation(record, line, stats, self.cells.then_some(&mut self.text))?;
        self.out.push(o);
        if self.text.len() >= self.limit {
            self.attach();
        }
        Ok(())
    }

    /// Gives the text to the observations it holds the cells of.
    fn attach(&mut self) {
        let rows = self.out[self.first..].iter_mut().map(|o| &mut o.q_written);
        WrittenCells::attach(&mut self.text, rows);
        self.first = self.out.len();
    }

    /// The observations, every one's cells attached.
    pub(super) fn finish(mut self) -> Vec<Observation> {
        self.attach();
        self.out
    }

    /// The observations, the text of the cells not attached, and the
    /// first observation whose cells are in it.
    pub(super) fn pending(self) -> (Vec<Observation>, String, usize) {
        (self.out, self.text, self.first)
    }
}

/// Where the lines of `bytes[range]` end (`\n`, `\r\n` or a lone `\r`,
/// as the csv crate's records do), positions in `bytes`.
/// (`memchr`'s SIMD search: a byte at a time was a tenth of a million
/// rows' run.)
pub(super) fn line_ends(bytes: &[u8], range: std::ops::Range<usize>) -> Vec<usize> {
    let from = range.start;
    memchr::memchr2_iter(b'\n', b'\r', &bytes[range])
        .map(|k| from + k)
        .filter(|&i| bytes[i] == b'\n' || bytes.get(i + 1) != Some(&b'\n'))
        .collect()
}

/// The line of a record at byte `at` of `bytes` (past any line end there),
/// with `newlines` every line end of `bytes` ([`line_ends`]).
pub(super) fn line_at(bytes: &[u8], newlines: &[usize], mut at: usize) -> usize {
    while at < bytes.len() && matches!(bytes[at], b'\r' | b'\n') {
        at += 1;
    }
    newlines.partition_point(|&n| n < at) + 1
}

/// `f(at, record)` for each record of `text` (a file's text past its
/// header, without quotes) in order, `at` its first byte: the runs of bytes
/// between line ends, as the csv crate reads them (`\r` and `\n` end a
/// record, and a run of them is one end: no empty record); stops at the
/// first `None`. (The csv crate's reader, with its record trimmed into a
/// new allocation, was two-thirds of the parse at 10⁶ rows.)
pub(super) fn each_record<'t>(
    text: &'t str,
    mut f: impl FnMut(usize, &'t str) -> Option<()>,
) -> Option<()> {
    let mut start = 0;
    let ends = memchr::memchr2_iter(b'\n', b'\r', text.as_bytes());
    for end in ends.chain(std::iter::once(text.len())) {
        if end > start {
            f(start, &text[start..end])?;
        }
        start = end + 1;
    }
    Some(())
}

/// The records from byte `start` of `bytes` (past the header), read in
/// chunks that end at line ends, on up to `threads` threads, and joined in
/// file order: the observations and stats one reader makes. `None` when the
/// file is small, has quotes (a quoted cell may hold a line end), or any
/// chunk has an error: the caller then reads the file with one reader,
/// which gives the error with the file's own record numbers.
pub(super) fn chunked(
    bytes: &[u8],
    start: usize,
    newlines: &[usize],
    layout: &Layout<'_>,
    threads: usize,
) -> Option<(Vec<Observation>, Stats)> {
    let data = bytes.get(start..)?;
    if threads < 2 || data.len() < 2 * MIN_CHUNK_BYTES || data.contains(&b'"') {
        return None;
    }
    // Many more chunks than threads: the threads take them in turn, and the
    // last one still parsed is the only work left (at 10⁶ rows a chunk in
    // four per thread was ~0.15 s of one thread alone at the end).
    let chunks = (16 * threads).min(data.len() / MIN_CHUNK_BYTES);
    let mut read = Read::new(layout.robot.dof(), false);
    in_chunks(
        bytes,
        start,
        newlines,
        0,
        layout,
        (threads, chunks),
        &mut read,
    )?;
    Some(read.finish())
}

/// Where [`in_chunks`] puts what it reads.
pub(super) struct Read {
    /// The observations read so far, in file order.
    pub(super) observations: Vec<Observation>,
    /// Their stats.
    pub(super) stats: Stats,
    /// Each chunk's observations before they are joined, kept (empty) for
    /// the next call: a file read a block at a time ([`crate::io::measurements::stream`])
    /// then allocates them once, not once a block. (Allocated and freed
    /// again in every block, they left memory to the threads' allocator:
    /// the peak of a run of 10⁶ rows was 842–851 MiB, against 816–824 MiB
    /// with the whole file read at once and 825–828 MiB now.)
    parts: Vec<Vec<Observation>>,
    /// Whether `parts` are kept (else each is freed once joined: the file
    /// read at once has one call, and its parts kept to its end would
    /// double its rows' memory there).
    keep: bool,
    /// The joint cells as written of `observations[first..]`, not yet
    /// attached: the chunks' texts joined, one allocation that grows in
    /// place and is given back whole when freed (the chunks' own, of a
    /// few MiB each, are freed as they are joined, and reused by the next
    /// chunks: at 10⁶ rows ~115 MB of texts of ~1 MiB stayed with the
    /// threads' allocator once the rows were built).
    text: String,
    /// The first observation whose cells are in `text`.
    first: usize,
    /// Bytes of `text` past which it is attached
    /// ([`WrittenCells::JOINED_BYTES`]; fewer in tests).
    joined: usize,
    /// Whether the joint cells as written are kept ([`Read::without_cells`]).
    cells: bool,
}

impl Read {
    /// Nothing read yet, for a robot of `dof` joints; `keep`: whether the
    /// chunks' vectors are kept for the next call.
    pub(super) fn new(dof: usize, keep: bool) -> Self {
        Self {
            observations: Vec::new(),
            stats: Stats::new(dof),
            parts: Vec::new(),
            keep,
            text: String::new(),
            first: 0,
            joined: WrittenCells::JOINED_BYTES,
            cells: true,
        }
    }

    /// The same, keeping no joint cell as written (the observations'
    /// [`Observation::q_written`] empty): a large file's are read again
    /// where needed ([`crate::io::measurements::Measurements::written_cells`]).
    pub(super) fn without_cells(self) -> Self {
        Self {
            cells: false,
            ..self
        }
    }

    /// Appends a chunk's observations `obs` (taken), whose cells from
    /// `obs[first..]` on are in `text` (the others attached).
    fn join(&mut self, obs: &mut Vec<Observation>, text: &str, first: usize) {
        let at = self.observations.len();
        if first > 0 || self.text.len() + text.len() > self.joined {
            self.attach(at);
            self.first = at + first;
        }
        let by = u32::try_from(self.text.len()).unwrap_or(u32::MAX);
        for o in &mut obs[first..] {
            o.q_written.shift(by);
        }
        self.text.push_str(text);
        self.observations.append(obs);
    }

    /// Gives `text` to `observations[first..end]`.
    fn attach(&mut self, end: usize) {
        let rows = self.observations[self.first..end]
            .iter_mut()
            .map(|o| &mut o.q_written);
        WrittenCells::attach(&mut self.text, rows);
        self.first = end;
    }

    /// The observations read, every one's cells attached, and their stats.
    pub(super) fn finish(mut self) -> (Vec<Observation>, Stats) {
        self.attach(self.observations.len());
        (self.observations, self.stats)
    }
}

/// [`chunked`]'s reading of `bytes[start..]` (records without quotes), of
/// any size, into `read`: `bytes` a piece of a file that ends at a line
/// end or at the file's end, `newlines` its line ends ([`line_ends`]),
/// `line0` the line ends of the file before it (its first line is line
/// `line0 + 1`). In at most `chunks` chunks (at least one). `None` when a
/// record has an error (`read` then holds some of the piece's rows).
pub(super) fn in_chunks(
    bytes: &[u8],
    start: usize,
    newlines: &[usize],
    line0: usize,
    layout: &Layout<'_>,
    (threads, chunks): (usize, usize),
    read: &mut Read,
) -> Option<()> {
    let data = bytes.get(start..)?;
    let chunks = chunks.max(1);
    // Chunk `k` ends after the first `\n` at or past its share.
    let mut ends = Vec::with_capacity(chunks);
    for k in 1..chunks {
        let from = (start + k * data.len() / chunks).max(ends.last().copied().unwrap_or(start));
        match bytes[from..].iter().position(|&b| b == b'\n') {
            Some(p) => ends.push(from + p + 1),
            None => break,
        }
    }
    ends.push(bytes.len());
    ends.dedup();
    let bounds: Vec<(usize, usize)> = ends
        .iter()
        .scan(start, |lo, &hi| {
            let b = (*lo, hi);
            *lo = hi;
            Some(b)
        })
        .collect();
    read.parts
        .resize_with(read.parts.len().max(bounds.len()), Vec::new);
    let slots: Vec<std::sync::Mutex<Vec<Observation>>> = read.parts[..bounds.len()]
        .iter_mut()
        .map(|p| std::sync::Mutex::new(std::mem::take(p)))
        .collect();
    let parts = crate::parallel::map_until(
        bounds.len(),
        threads,
        |k| {
            let part = std::mem::take(
                &mut *slots[k]
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner),
            );
            let (lo, hi) = bounds[k];
            // The chunk's text (a chunk ends at a line end: no character is
            // cut; invalid UTF-8 is the one reader's error).
            let text = std::str::from_utf8(&bytes[lo..hi]).ok()?;
            let mut stats = Stats::new(layout.robot.dof());
            // At most one record per line (no slack to copy at the join).
            let first_line = newlines.partition_point(|&n| n < lo);
            let lines = newlines.partition_point(|&n| n < hi) - first_line;
            let mut out = Batch::into(part, lines + 1, read.cells);
            let mut cells = Vec::with_capacity(layout.header.len());
            // Line ends before the record: its line is one more.
            let mut before = first_line;
            let done = each_record(text, |at, record| {
                cells.clear();
                cells.extend(record.split(',').map(str::trim));
                if cells.len() != layout.header.len() {
                    return None;
                }
                while newlines.get(before).is_some_and(|&n| n < lo + at) {
                    before += 1;
                }
                out.read(layout, &cells, line0 + before + 1, &mut stats)
                    .ok()
            });
            done.map(|()| (out.pending(), stats))
        },
        Option::is_none,
    );
    read.observations
        .reserve(parts.iter().flatten().map(|p| p.0 .0.len()).sum());
    let mut slots = std::mem::take(&mut read.parts);
    for (part, slot) in parts.into_iter().zip(&mut slots) {
        let ((mut obs, text, first), s) = part?;
        read.join(&mut obs, &text, first);
        read.stats.merge(s);
        if read.keep {
            *slot = obs;
        }
    }
    read.parts = slots;
    Some(())
}

#[cfg(test)]
mod tests;
