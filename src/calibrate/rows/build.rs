//! Building the rows from a job's measurements ([`Rows::new`]): one row
//! per measured point, grouped by configuration, with the joints' angle
//! bins; [`Rows::relinearise`] then evaluates them.

use std::borrow::Cow;

use nalgebra::Vector3;

use crate::calibrate::params::names::Names;
use crate::calibrate::rows::{DataKinds, Row, RowExtra, RowKind, Rows, Scalar};
use crate::calibrate::settings::{CalibrationError, Policy};
use crate::io::{job::Job, measurements::Measurements};
use crate::model::bins::{by_first_appearance, clusters};
use crate::model::{angle_urad, BIN_TOLERANCE_RAD};

impl Rows {
    /// The rows of `data`: its deflections, and its absolute positions when
    /// `absolute` (or when there is no deflection). Frames, torques and the
    /// absolute rows' `Δp` are computed by [`Rows::relinearise`].
    ///
    /// # Errors
    /// [`CalibrationError::Data`] when there is no row;
    /// [`CalibrationError::Core`] when the forward kinematics fails.
    pub fn new(
        job: &Job,
        data: &Measurements,
        absolute: bool,
        names: &mut Names,
        policy: &Policy,
    ) -> Result<Self, CalibrationError> {
        Self::build(job, Cow::Borrowed(data), absolute, names, policy)
    }

    /// [`Rows::new`], taking the measurements: the absolute rows are built
    /// from the last observation back, a chunk at a time, each chunk of
    /// observations freed once its rows are made (and every joint cell as
    /// written once the bins are named). At 10⁶ rows the parsed
    /// observations (~230 MB) and their cells (~115 MB) were held whole
    /// while the rows (~224 MB) were built: that was the peak memory of a
    /// calibration. The rows are the same, bit for bit.
    ///
    /// # Errors
    /// As [`Rows::new`].
    pub fn from_measurements(
        job: &Job,
        data: Measurements,
        absolute: bool,
        names: &mut Names,
        policy: &Policy,
    ) -> Result<Self, CalibrationError> {
        Self::build(job, Cow::Owned(data), absolute, names, policy)
    }

    /// [`Rows::new`] (`data` borrowed) and [`Rows::from_measurements`]
    /// (taken).
    pub(crate) fn build(
        job: &Job,
        mut source: Cow<'_, Measurements>,
        absolute: bool,
        names: &mut Names,
        policy: &Policy,
    ) -> Result<Self, CalibrationError> {
        let data = &*source;
        let setup = &job.setup;
        let dof = job.robot.dof();
        let use_absolute = absolute || data.deflections.is_empty();
        let gravity = setup.load.map_or(Vector3::new(0.0, 0.0, -9.80665), |l| {
            Vector3::from(l.gravity)
        });
        let com = setup
            .load
            .map_or(Vector3::zeros(), |l| Vector3::from(l.com));
        // The points' configurations (a plane contact's or a distance's
        // are groups of their own: module `scalar`).
        let mut configs: Vec<i64> = (data.observations.iter())
            .filter(|o| o.scalar.is_none())
            .map(|o| o.config)
            .collect();
        configs.sort_unstable();
        configs.dedup();
        // The configurations with a plane contact or a distance: each its
        // group after every position group.
        let mut scalared: Vec<i64> = if use_absolute {
            (data.observations.iter())
                .filter(|o| o.scalar.is_some() && o.is_unloaded())
                .map(|o| o.config)
                .collect()
        } else {
            Vec::new()
        };
        scalared.sort_unstable();
        scalared.dedup();
        // The configurations with a measured orientation: each its group
        // after every position group (module `orientation`).
        let mut oriented: Vec<i64> = if use_absolute {
            data.observations
                .iter()
                .filter(|o| o.r_rad.is_some() && o.is_unloaded())
                .map(|o| o.config)
                .collect()
        } else {
            Vec::new()
        };
        oriented.sort_unstable();
        oriented.dedup();
        // The temperature's reference: the mean over every point.
        let temps: Vec<f64> = data.observations.iter().filter_map(|o| o.temp_c).collect();
        let temp_mean = (!temps.is_empty()).then(|| temps.iter().sum::<f64>() / temps.len() as f64);
        let times: Vec<f64> = data.observations.iter().filter_map(|o| o.t_s).collect();
        let t_mean = if times.is_empty() {
            0.0
        } else {
            times.iter().sum::<f64>() / times.len() as f64
        };

        // Angle bins per joint, from the rows that enter the problem, in
        // order of first appearance in the file (k21, k22, … of the paper).
        // The joints are independent (each sorts every value: on worker
        // threads with many rows); a joint's cells as written are read only
        // for its bins' centres.
        let entering: Vec<&crate::io::measurements::Observation> = if use_absolute {
            data.unloaded().collect()
        } else {
            data.deflections
                .iter()
                .map(|d| &data.observations[d.rows[1]])
                .collect()
        };
        let threads = crate::parallel::for_rows(entering.len()).min(dof);
        let per_joint = crate::parallel::map(dof, threads, |j| {
            let values: Vec<f64> = entering.iter().map(|o| o.q[j]).collect();
            let mut jb = Vec::new();
            let mut counts = Vec::new();
            // Each bin's centre and the first row in it (whose cell as
            // written names it).
            let mut firsts = Vec::new();
            if let Some(mut centres) = clusters_at_most(&values, policy.max_bins) {
                // (Only here: with many distinct values, e.g. random poses,
                // the key's scan of every value made this sort quadratic
                // for bins that are then not used.)
                by_first_appearance(&mut centres, &values);
                for c in &centres {
                    let near = |v: f64| (v - c).abs() <= BIN_TOLERANCE_RAD;
                    let mut cfgs: Vec<i64> = entering
                        .iter()
                        .filter(|o| near(o.q[j]))
                        .map(|o| o.config)
                        .collect();
                    cfgs.sort_unstable();
                    cfgs.dedup();
                    counts.push(cfgs.len());
                    jb.push(angle_urad(*c));
                    firsts.push((*c, entering.iter().position(|o| near(o.q[j]))));
                }
            }
            (jb, policy.compensator_eligible(&counts), firsts)
        });
        // The bins' names: the cells as written of their first rows.
        let rows_in = &entering;
        let wanted: Vec<(&crate::io::measurements::Observation, usize)> =
            (per_joint.iter().enumerate())
                .flat_map(|(j, (_, _, firsts))| {
                    firsts
                        .iter()
                        .filter_map(move |&(_, first)| Some((*rows_in.get(first?)?, j)))
                })
                .collect();
        let mut written = data
            .written_cells(&wanted)
            .map_err(|e| CalibrationError::Data(e.to_string()))?
            .into_iter();
        drop((wanted, entering));
        let mut bins = Vec::with_capacity(dof);
        let mut compensator_ok = Vec::with_capacity(dof);
        for (j, (jb, ok, firsts)) in per_joint.into_iter().enumerate() {
            for (&a, (c, first)) in jb.iter().zip(firsts) {
                let cell = first.and_then(|_| written.next().flatten());
                let name = cell.unwrap_or_else(|| format!("{c}"));
                names.bins.insert((j as u8, a), name);
            }
            compensator_ok.push(ok);
            bins.push(jb);
        }
        // The cells as written were read for the bins' names only.
        forget_cells(&mut source);
        let data = &*source;

        let index_of = |id: u32| names.marker_index(id).unwrap_or(0);
        let deflections = data.deflections.len();
        let row = |kind,
                   config,
                   marker,
                   load_kg: f64,
                   q: &[f64],
                   dt: Option<f64>,
                   dtemp_k: Option<f64>,
                   measured: [f64; 3],
                   line: usize,
                   sigma: Option<[f64; 3]>,
                   orientation: bool,
                   scalar: Option<Scalar>,
                   hint: &mut usize| Row {
            kind,
            marker: index_of(marker),
            orientation,
            chain: 0,
            group: u32::try_from(if orientation {
                configs.len() + scalared.len() + group_of(&oriented, config, hint)
            } else if scalar.is_some() {
                configs.len() + group_of(&scalared, config, hint)
            } else {
                group_of(&configs, config, hint)
            })
            .unwrap_or(u32::MAX),
            q: q.into(),
            measured: Vector3::from(measured),
            line: u32::try_from(line).unwrap_or(u32::MAX),
            extra: (load_kg != 0.0
                || dt.is_some()
                || dtemp_k.is_some()
                || sigma.is_some()
                || scalar.is_some())
            .then(|| {
                Box::new(RowExtra {
                    load_kg,
                    dt,
                    dtemp_k,
                    sigma: sigma.map(Vector3::from),
                    scalar,
                    ..RowExtra::default()
                })
            }),
        };
        // An unloaded observation's row: its point (`measured` the point,
        // `sigma` the point's σ) or a pose's orientation (the rotation
        // vector and its σ, module `orientation`).
        let observed = |o: &crate::io::measurements::Observation,
                        measured: [f64; 3],
                        sigma: Option<[f64; 3]>,
                        orientation: bool,
                        scalar: Option<Scalar>,
                        hint: &mut usize| {
            row(
                RowKind::Absolute,
                o.config,
                o.marker,
                0.0,
                &o.q,
                o.t_s.map(|t| t - t_mean),
                o.temp_c.zip(temp_mean).map(|(t, m)| t - m),
                measured,
                o.line,
                sigma,
                orientation,
                scalar,
                hint,
            )
        };
        let absolute_row = |o: &crate::io::measurements::Observation, hint: &mut usize| {
            observed(o, o.p_m, o.sigma_m, false, None, hint)
        };
        let orientation_row = |o: &crate::io::measurements::Observation, hint: &mut usize| {
            observed(
                o,
                o.r_rad.unwrap_or_default(),
                o.sigma_rad,
                true,
                None,
                hint,
            )
        };
        // A plane contact's or a distance's row: its number on axis 0
        // (module `scalar`).
        let scalar_row = |o: &crate::io::measurements::Observation, hint: &mut usize| {
            let value = o.scalar.map_or(0.0, |s| s.value_m());
            observed(o, [value, 0.0, 0.0], o.sigma_m, false, o.scalar, hint)
        };
        // The deflections first: runs of rows on worker threads, joined in
        // order (one thread built a million rows in 0.3 s).
        let deflection_row = |k: usize, hint: &mut usize| {
            let d = &data.deflections[k];
            let (loaded, unloaded) = (&data.observations[d.rows[0]], &data.observations[d.rows[1]]);
            let dt = loaded.t_s.zip(unloaded.t_s).map(|(a, b)| a - b);
            row(
                RowKind::Deflection,
                d.config,
                d.marker,
                d.load_kg,
                &d.q,
                dt,
                loaded.temp_c.zip(unloaded.temp_c).map(|(a, b)| a - b),
                d.dp_m,
                d.lines[0],
                loaded
                    .sigma_m
                    .zip(unloaded.sigma_m)
                    .map(|(a, b)| [0, 1, 2].map(|k| a[k].hypot(b[k]))),
                false,
                None,
                hint,
            )
        };
        let point =
            |o: &crate::io::measurements::Observation| o.is_unloaded() && o.scalar.is_none();
        let unloaded = if use_absolute {
            data.observations.iter().filter(|o| point(o)).count()
        } else {
            0
        };
        let total = deflections + unloaded;
        let mut rows = Vec::with_capacity(total);
        let threads = crate::parallel::for_rows(deflections);
        let per = deflections.div_ceil(threads).max(1);
        for run in crate::parallel::map(deflections.div_ceil(per), threads, |t| {
            let mut hint = 0;
            (t * per..((t + 1) * per).min(deflections))
                .map(|k| deflection_row(k, &mut hint))
                .collect::<Vec<Row>>()
        }) {
            rows.extend(run);
        }
        // Then the absolute positions, from the last observation back, a
        // chunk at a time (its runs on worker threads), each chunk's rows
        // appended in reverse and the whole reversed at the end; with the
        // observations taken, each chunk is freed once its rows are made.
        let threads = crate::parallel::for_rows(unloaded);
        let mut orientations: Vec<Row> = Vec::new();
        let mut scalars: Vec<Row> = Vec::new();
        let mut end = if use_absolute {
            data.observations.len()
        } else {
            0
        };
        while end > 0 {
            let start = end.saturating_sub(CHUNK);
            let chunk = &source.observations[start..end];
            let per = chunk.len().div_ceil(threads).max(1);
            let runs = crate::parallel::map(chunk.len().div_ceil(per), threads, |t| {
                let mut hint = 0;
                chunk[t * per..((t + 1) * per).min(chunk.len())]
                    .iter()
                    .filter(|o| point(o))
                    .map(|o| absolute_row(o, &mut hint))
                    .collect::<Vec<Row>>()
            });
            for run in runs.into_iter().rev() {
                rows.extend(run.into_iter().rev());
            }
            if !oriented.is_empty() {
                let mut hint = 0;
                orientations.extend(
                    chunk
                        .iter()
                        .rev()
                        .filter(|o| o.is_unloaded() && o.r_rad.is_some())
                        .map(|o| orientation_row(o, &mut hint)),
                );
            }
            if !scalared.is_empty() {
                let mut hint = 0;
                scalars.extend(
                    chunk
                        .iter()
                        .rev()
                        .filter(|o| o.is_unloaded() && o.scalar.is_some())
                        .map(|o| scalar_row(o, &mut hint)),
                );
            }
            release_from(&mut source, start);
            end = start;
        }
        rows[deflections..].reverse();
        // The plane contacts and distances after every position, then the
        // orientations, each in file order.
        scalars.reverse();
        rows.append(&mut scalars);
        orientations.reverse();
        rows.append(&mut orientations);
        configs.extend(scalared.iter().copied());
        configs.extend(oriented.iter().copied());
        let data = &*source;
        if rows.is_empty() {
            return Err(CalibrationError::Data(format!(
                "{}: no rows to calibrate from",
                data.file.display()
            )));
        }
        let kinds = DataKinds {
            deflections: rows.iter().any(|r| r.kind == RowKind::Deflection),
            absolute: rows.iter().any(|r| r.kind == RowKind::Absolute),
            time: data.has_time,
            own_weight: rows.iter().any(|r| r.kind == RowKind::Absolute)
                && job.robot.chain.joints().iter().any(|j| j.link.is_some()),
            temperature: rows.iter().any(|r| r.dtemp_k().is_some()),
        };
        Ok(Self {
            rows,
            orientation_groups: oriented.len(),
            scalar_groups: scalared.len(),
            configs,
            kinds,
            bins,
            compensator_ok,
            gravity,
            com,
            file: data.file.display().to_string(),
            temperature_ref_c: setup.model.temperature_column.clone().zip(temp_mean),
            chains: Vec::new(),
            markers: Vec::new(),
            tool_rotation: nalgebra::Rotation3::identity(),
            gravity_unit: Vector3::zeros(),
            at: None,
        })
    }
}

/// Observations a chunk of absolute rows is made from
/// ([`Rows::from_measurements`]): ~6 MB of them, ~7 MB of rows.
const CHUNK: usize = 1 << 15;

/// Taken measurements without their observations from `start` on (their
/// memory given back); nothing when borrowed.
fn release_from(data: &mut Cow<'_, Measurements>, start: usize) {
    if let Cow::Owned(m) = data {
        m.observations.truncate(start);
        m.observations.shrink_to_fit();
    }
}

/// Taken measurements without their joint cells as written (their text
/// freed with the last); nothing when borrowed.
fn forget_cells(data: &mut Cow<'_, Measurements>) {
    if let Cow::Owned(m) = data {
        for o in &mut m.observations {
            o.q_written = crate::io::measurements::WrittenCells::default();
        }
    }
}

/// The group (index into the sorted, distinct `configs`) of `config`.
/// Rows come in file order, and files mostly list a configuration's rows
/// together in increasing order: the group of the row before (`hint`) or
/// the next is tried before a binary search (10⁶ searches over 10⁶
/// configurations were a tenth of a second).
fn group_of(configs: &[i64], config: i64, hint: &mut usize) -> usize {
    let g = if configs.get(*hint) == Some(&config) {
        *hint
    } else if configs.get(*hint + 1) == Some(&config) {
        *hint + 1
    } else {
        configs.binary_search(&config).unwrap_or(0)
    };
    *hint = g;
    g
}

/// The centres of [`clusters`] of `values` (in sorted order) when there
/// are at most `max` of them, else `None`: sorted a growing prefix at a
/// time (the smallest values selected, then sorted), stopping once the
/// prefix's closed clusters are more than `max` (a later value never
/// joins a closed cluster). At a million random joint values, as many
/// clusters show in the first few thousand: two selections, where the
/// sort of every value was 0.1 s a joint.
fn clusters_at_most(values: &[f64], max: usize) -> Option<Vec<f64>> {
    let mut v = values.to_vec();
    let n = v.len();
    // `v[..sorted]`: the `sorted` smallest values, in order.
    let (mut sorted, mut next) = (0, PREFIX.min(n));
    loop {
        if next >= n / 4 {
            // (Equal under `total_cmp` is the same bits: unstable is the
            // same order, and faster on a million values.)
            v[sorted..].sort_unstable_by(f64::total_cmp);
            sorted = n;
        } else {
            v[sorted..].select_nth_unstable_by(next - sorted - 1, f64::total_cmp);
            v[sorted..next].sort_unstable_by(f64::total_cmp);
            sorted = next;
        }
        let mut count = 0_usize;
        clusters(&v[..sorted], |_| count += 1);
        if sorted == n {
            if count > max {
                return None;
            }
            let mut centres = Vec::with_capacity(count);
            clusters(&v, |c| centres.push(c));
            return Some(centres);
        }
        if count.saturating_sub(1) > max {
            return None;
        }
        next = next.saturating_mul(2).min(n);
    }
}

/// The first prefix [`clusters_at_most`] sorts.
const PREFIX: usize = 4096;

#[cfg(test)]
mod tests {
    use crate::calibrate::rows::build::{clusters, clusters_at_most};

    #[test]
    fn the_clusters_of_a_prefix_decide_as_those_of_all_values() {
        let mut s = 7_u64;
        let mut next = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        // Random values, binned values with jitter, a few values, one.
        let random: Vec<f64> = (0..100_000).map(|_| 6.0 * next() - 3.0).collect();
        let binned: Vec<f64> = (0..100_000)
            .map(|i| (i % 9) as f64 * 0.3 + 2e-4 * next())
            .collect();
        let wide: Vec<f64> = (0..40_000).map(|i| (i % 40) as f64 * 0.01).collect();
        for values in [random, binned, wide, vec![0.5; 3], vec![1.0], Vec::new()] {
            let mut sorted = values.clone();
            sorted.sort_unstable_by(f64::total_cmp);
            let mut all = Vec::new();
            clusters(&sorted, |c| all.push(c));
            for max in [0, 8, 9, 32, 39, 40, 1000] {
                let want = (all.len() <= max).then(|| all.clone());
                assert_eq!(
                    clusters_at_most(&values, max),
                    want,
                    "{} values, max {max}",
                    values.len()
                );
            }
        }
    }
}
