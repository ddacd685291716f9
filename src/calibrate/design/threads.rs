//! The rows and designs built on worker threads ([`crate::parallel`]) are
//! the serial ones, bit for bit.

use crate::calibrate::design::Design;
use crate::calibrate::effects::declared;
use crate::calibrate::{
    params::geometry::Geometry, params::linearisation::DeflectionModel,
    params::linearisation::Linearisation, params::names::Names, rows::Rows,
};
use crate::parallel::map;
use nalgebra::Vector3;

/// The KR-270 job and its measurements (`data/kr270`).
fn kr270() -> (crate::io::job::Job, crate::io::measurements::Measurements) {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/data/kr270");
    let job = crate::io::job::Job::load(format!("{dir}/setup.toml")).expect("job");
    let data = crate::io::measurements::read_measurements(
        format!("{dir}/measurements.csv"),
        &job.robot,
        &job.setup,
    )
    .expect("data");
    (job, data)
}

/// The contract names of `job` (no angle bins yet).
fn names_of(job: &crate::io::job::Job) -> Names {
    Names {
        joints: job.robot.joint_names.clone(),
        kinds: job.robot.chain.joints().iter().map(|j| j.kind).collect(),
        markers: job
            .setup
            .markers
            .iter()
            .map(|m| (m.id, Vector3::from(m.xyz)))
            .collect(),
        bins: Default::default(),
    }
}

/// The KR-270 job's rows (loaded: the exact model's equilibria) and its
/// declared design, relinearised and built on 1 and on 3 threads at a
/// joint law with every compliance at 1 (the reported unit): the same
/// bits.
#[test]
fn rows_and_design_do_not_depend_on_the_threads() {
    let (job, data) = kr270();
    let mut names = names_of(&job);
    let policy = crate::calibrate::settings::Policy::default();
    let mut rows = Rows::new(
        &job,
        &data,
        declared::needs_absolute(&job),
        &mut names,
        &policy,
    )
    .expect("rows");
    let params = declared::declared(&job, &data.file, &rows, &names).expect("model");
    let markers: Vec<Vector3<f64>> = names.markers.iter().map(|m| m.1).collect();
    let geometry = Geometry::nominal_tree(
        &job.robot.chain,
        &job.robot.ends,
        &markers,
        &job.marker_ends(),
    );
    let x = vec![1.0; params.len()];
    let lin = Linearisation::of(DeflectionModel::Exact, &params, &x, &names);
    let mut at = |threads: usize| {
        rows.relinearise_on(&geometry, &lin, threads)
            .expect("relinearise");
        let d = Design::new_on(&rows, &params, &lin, &names, threads).expect("design");
        let state = |rows: &Rows| -> Vec<_> {
            rows.rows
                .iter()
                .map(|r| {
                    let f = rows.frames(r).expect("frames");
                    let (y, p) = (rows.y(r, &f), rows.point_m(r, &f));
                    (y, p, r.tau().to_vec(), r.twists().to_vec())
                })
                .collect()
        };
        let r = state(&rows);
        // Again with the design built in the relinearisation's pass
        // (from the equilibria just found: the same rows), into the
        // storage of another design: the same rows and design.
        let old = Design::new_on(&rows, &params[..1], &lin, &names, 1).expect("design");
        let fused = Design::relinearised_on(
            &mut rows,
            &geometry,
            &lin,
            &params,
            &names,
            Some(old.into_storage()),
            threads,
            true,
        )
        .expect("relinearise")
        .expect("columns");
        let bits = |v: &[f64]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(
            bits(fused.held().as_slice()),
            bits(d.held().as_slice()),
            "{threads} threads"
        );
        assert_eq!(bits(&fused.y), bits(&d.y));
        // And not held: the columns computed where read from the same
        // rows are the held ones, and so are the unit-weight sums.
        let computed = Design::relinearised_on(
            &mut rows, &geometry, &lin, &params, &names, None, threads, false,
        )
        .expect("relinearise")
        .expect("columns")
        .reading(&std::sync::Arc::new(rows.clone()));
        assert!(!computed.is_held());
        assert_eq!(
            bits(computed.held().as_slice()),
            bits(d.held().as_slice()),
            "{threads} threads, computed"
        );
        let both = |d: &Design| {
            d.unit_sums
                .as_ref()
                .map(|s| bits(s.information().as_slice()))
        };
        assert_eq!(both(&computed), both(&fused));
        let mut block = (Vec::new(), Vec::new());
        let some: Vec<usize> = (0..rows.rows.len()).step_by(3).collect();
        let cols = [2, 0, 2];
        computed.rows_into(&some, &cols, &mut block.0);
        d.rows_into(&some, &cols, &mut block.1);
        assert_eq!(bits(&block.0), bits(&block.1));
        computed.columns_into(1, rows.rows.len() - 2, &cols, &mut block.0);
        d.columns_into(1, rows.rows.len() - 2, &cols, &mut block.1);
        assert_eq!(bits(&block.0), bits(&block.1));
        // Its unit-weight sums, when the pass made them (runs of whole
        // blocks, or one run), are the view's of the design.
        assert_eq!(fused.unit_sums.is_some(), threads == 1);
        if let Some(sums) = &fused.unit_sums {
            let cols: Vec<usize> = (0..params.len()).collect();
            let view = crate::calibrate::design::view::View::new(&d, &cols, &[], None)
                .information()
                .expect("finite");
            assert_eq!(
                bits(sums.information().as_slice()),
                bits(view.information().as_slice())
            );
            assert_eq!(bits(sums.eta().as_slice()), bits(view.eta().as_slice()));
            assert_eq!(sums.weighted_yy().to_bits(), view.weighted_yy().to_bits());
        }
        assert_eq!(
            (fused.held().shape(), &fused.group),
            (d.held().shape(), &d.group)
        );
        assert!(state(&rows) == r, "{threads} threads");
        (r, d.held().into_owned(), d.y)
    };
    let one = at(1);
    assert!(one.0.iter().any(|r| !r.3.is_empty()), "equilibria");
    for threads in [2, 3, 7] {
        assert!(one == at(threads), "{threads} threads");
    }

    // A relinearisation that fails part way (compliances so large that
    // the heavier loads have no equilibrium near the measured pose),
    // then another from the starting points it left: the same rows and
    // the same error on 1 and 3 threads.
    let first_line = rows.rows[0].line();
    let mut part_way = 0;
    for scale in [100.0, 300.0, 1e3, 3e3, 1e4, 3e4] {
        let bad = Linearisation::of(
            DeflectionModel::Exact,
            &params,
            &vec![scale; x.len()],
            &names,
        );
        let after = Linearisation::of(DeflectionModel::Exact, &params, &vec![1.5; x.len()], &names);
        let run = |threads: usize| {
            let mut r = rows.clone();
            let e = r
                .relinearise_on(&geometry, &bad, threads)
                .err()
                .map(|e| e.to_string());
            r.relinearise_on(&geometry, &after, threads)
                .expect("relinearise");
            let state: Vec<_> = r
                .rows
                .iter()
                .map(|row| {
                    let f = r.frames(row).expect("frames");
                    let (y, p) = (r.y(row, &f), r.point_m(row, &f));
                    (y, p, row.tau().to_vec(), row.theta().to_vec())
                })
                .collect();
            (e, state)
        };
        let serial = run(1);
        assert!(serial == run(3), "scale {scale}");
        if let Some(e) = &serial.0 {
            if !e.contains(&format!(":{first_line}:")) {
                part_way += 1;
            }
        }
    }
    assert!(part_way > 0, "no relinearisation failed part way");
}

/// Rows built on worker threads (more rows than one thread takes) are
/// the rows built on one (inside a worker), in the same order: the
/// KR-270's data sixteen times, each copy its own configurations, every
/// other copy's in decreasing order (the group hints then miss).
#[test]
fn rows_built_on_threads_are_the_serial_ones() {
    let (job, data) = kr270();
    let n = data.observations.len();
    let mut big = data.clone();
    let config = |c: i64, r: i64| {
        if r % 2 == 0 {
            c + 1000 * r
        } else {
            1_000_000 - c - 1000 * r
        }
    };
    for r in 1..16 {
        for o in &data.observations {
            let mut o = o.clone();
            o.config = config(o.config, r);
            big.observations.push(o);
        }
        for d in &data.deflections {
            let mut d = d.clone();
            d.config = config(d.config, r);
            d.rows = d.rows.map(|i| i + r as usize * n);
            big.deflections.push(d);
        }
    }
    let build = || {
        let mut names = names_of(&job);
        let policy = crate::calibrate::settings::Policy::default();
        let rows = Rows::new(&job, &big, true, &mut names, &policy).expect("rows");
        rows.rows
            .iter()
            .map(|r| {
                (
                    r.kind,
                    r.group(),
                    rows.configs[r.group()],
                    r.marker,
                    r.q.clone(),
                    r.measured,
                    r.line(),
                    r.extra.as_ref().map(|e| (e.dt, e.sigma, e.load_kg)),
                )
            })
            .collect::<Vec<_>>()
    };
    let threads = build();
    assert!(
        threads.len() >= 2 * crate::parallel::MIN_ROWS_PER_THREAD,
        "{} rows",
        threads.len()
    );
    let serial = map(2, 2, |k| (k == 0).then(build))
        .into_iter()
        .flatten()
        .next()
        .expect("serial");
    assert!(threads == serial);
}

/// Rows built from taken measurements (the absolute rows from the last
/// observation back, a chunk at a time, each chunk freed) are the rows
/// built from borrowed ones, with their bins and the names of the bins:
/// the KR-270's data (loaded and unloaded rows, each with a time and an
/// instrument σ) copied into more observations than two chunks hold,
/// with absolute rows and without.
#[test]
fn rows_of_taken_measurements_are_those_of_borrowed_ones() {
    let (job, data) = kr270();
    let n = data.observations.len();
    let copies = 70_000 / n + 1;
    let mut big = data.clone();
    big.observations.clear();
    big.deflections.clear();
    big.has_time = true;
    for r in 0..copies {
        for o in &data.observations {
            let mut o = o.clone();
            o.config += 1000 * r as i64;
            o.line += 10 * r * n;
            o.t_s = Some(0.25 * o.line as f64);
            o.sigma_m = Some([1e-5, 2e-5, 3e-5 * (1 + r % 3) as f64]);
            big.observations.push(o);
        }
        for d in &data.deflections {
            let mut d = d.clone();
            d.config += 1000 * r as i64;
            d.rows = d.rows.map(|i| i + r * n);
            d.lines = d.lines.map(|l| l + 10 * r * n);
            big.deflections.push(d);
        }
    }
    assert!(big.observations.len() > 70_000 && !big.deflections.is_empty());
    let policy = crate::calibrate::settings::Policy::default();
    for absolute in [true, false] {
        let mut names = names_of(&job);
        let borrowed = Rows::new(&job, &big, absolute, &mut names, &policy).expect("rows");
        let mut taken_names = names_of(&job);
        let taken = Rows::from_measurements(&job, big.clone(), absolute, &mut taken_names, &policy)
            .expect("rows");
        assert_eq!(borrowed.rows.len(), taken.rows.len());
        assert!(borrowed.rows.len() > if absolute { 70_000 } else { 0 });
        // The deflections, then the absolute rows in file order.
        let d = big.deflections.len();
        assert!(taken.rows[..d]
            .iter()
            .all(|r| r.kind == crate::calibrate::rows::RowKind::Deflection));
        assert!(taken.rows[d..]
            .iter()
            .all(|r| r.kind == crate::calibrate::rows::RowKind::Absolute));
        assert!(taken.rows[d..]
            .windows(2)
            .all(|w| w[0].line() < w[1].line()));
        for (k, (a, b)) in borrowed.rows.iter().zip(&taken.rows).enumerate() {
            assert_eq!(format!("{a:?}"), format!("{b:?}"), "row {k}");
        }
        let rest = |r: &Rows| {
            format!(
                "{:?} {:?} {:?} {:?} {}",
                r.configs, r.kinds, r.bins, r.compensator_ok, r.file
            )
        };
        assert_eq!(rest(&borrowed), rest(&taken));
        assert_eq!(names.bins, taken_names.bins);
        assert!(!names.bins.is_empty(), "the KR-270's joints have bins");
    }
}

/// The rows' left-hand sides at the nominal robot (no joint law: first
/// order) computed again from its geometry once the rows are elsewhere
/// ([`Rows::rigid_lhs_at`]: the report's nominal error per row) are the
/// ones the relinearisation there gave, bit for bit.
#[test]
fn the_nominal_left_hand_sides_come_back_from_the_geometry() {
    let (job, data) = kr270();
    let mut names = names_of(&job);
    let policy = crate::calibrate::settings::Policy::default();
    let mut rows = Rows::new(&job, &data, true, &mut names, &policy).expect("rows");
    assert!(rows.kinds.absolute && rows.kinds.deflections);
    let markers: Vec<Vector3<f64>> = names.markers.iter().map(|m| m.1).collect();
    let nominal = Geometry::nominal_tree(
        &job.robot.chain,
        &job.robot.ends,
        &markers,
        &job.marker_ends(),
    );
    let lin = Linearisation::nominal(DeflectionModel::Exact);
    rows.relinearise_on(&nominal, &lin, 2).expect("relinearise");
    assert!(rows
        .rows
        .iter()
        .all(|r| r.extra.as_ref().is_none_or(|e| e.y.is_none())));
    let bits = |v: &[Vector3<f64>]| -> Vec<[u64; 3]> {
        v.iter()
            .map(|y| [y.x, y.y, y.z].map(f64::to_bits))
            .collect()
    };
    let there = rows.lhs().expect("frames");
    assert_eq!(
        bits(&rows.rigid_lhs_at(&nominal).expect("frames")),
        bits(&there)
    );
    let mut moved = nominal.clone();
    moved.base.translation.vector.x += 1e-3;
    rows.relinearise_on(&moved, &lin, 2).expect("relinearise");
    assert_ne!(bits(&rows.lhs().expect("frames")), bits(&there));
    assert_eq!(
        bits(&rows.rigid_lhs_at(&nominal).expect("frames")),
        bits(&there)
    );
}
