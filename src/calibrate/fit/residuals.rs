//! What is left in the residuals of a fit: the errors reported, the lack of
//! fit against the repetitions, and the variable the residuals follow.

use nalgebra::{Dyn, OMatrix, Vector3, U3};

use crate::calibrate::effects::Candidate;
use crate::calibrate::fit::FitOut;
use crate::calibrate::params::names::Names;
use crate::calibrate::rows::{revolute, RowKind, Rows};
use crate::estimate::{nested_test, Accumulator, Block};

/// RMS of the norm of 3-D position residuals \[m\], in µm (0 for none).
pub fn rms_um(res: &[Vector3<f64>]) -> f64 {
    let mut s = SquareSum::default();
    s.extend(res);
    s.rms_um()
}

/// `Σ |r|²` of residuals in the order they come, and their number: the
/// [`rms_um`] of residuals that need not all be held at once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SquareSum {
    sum: f64,
    count: usize,
}

impl Default for SquareSum {
    fn default() -> Self {
        // From −0, as `Iterator::sum` of `f64` starts.
        Self {
            sum: -0.0,
            count: 0,
        }
    }
}

impl SquareSum {
    /// Adds the squares of `res`, in order.
    pub fn extend(&mut self, res: &[Vector3<f64>]) {
        for r in res {
            self.sum += r.norm_squared();
        }
        self.count += res.len();
    }

    /// RMS \[µm\] of every residual added (0 for none).
    pub fn rms_um(&self) -> f64 {
        if self.count == 0 {
            return 0.0;
        }
        (self.sum / self.count as f64).sqrt() * 1e6
    }
}

/// Lack of fit from the repetitions (the core's, so that the device's
/// in-stream diagnosis decides by the same numbers).
pub use crate::estimate::screen::LackOfFit;

/// The cell (configuration, marker, kind) of each row, numbered by first
/// appearance, and the number of cells. Each configuration's cells in a
/// short chain (a configuration has few markers and kinds; a map of a
/// million keys was most of a lack-of-fit test at 10⁶ rows).
fn cells(rows: &Rows) -> (Vec<usize>, usize) {
    const NONE: usize = usize::MAX;
    // `head[g]`: the first of group `g`'s cells in `chain`; each entry its
    // marker, kind, cell number and the next entry of its group.
    let groups = rows.rows.iter().map(|r| r.group() + 1).max().unwrap_or(0);
    let mut head = vec![NONE; groups];
    let mut chain: Vec<(u8, bool, usize, usize)> = Vec::new();
    let cell = rows
        .rows
        .iter()
        .map(|r| {
            let deflection = r.kind == RowKind::Deflection;
            let first = &mut head[r.group()];
            let mut at = *first;
            let mut last = NONE;
            while at != NONE {
                let (m, k, c, next) = chain[at];
                if m == r.marker && k == deflection {
                    return c;
                }
                (last, at) = (at, next);
            }
            let n = chain.len();
            chain.push((r.marker, deflection, n, NONE));
            match last {
                NONE => *first = n,
                l => chain[l].3 = n,
            }
            n
        })
        .collect();
    (cell, chain.len())
}

/// The lack-of-fit test of a fit of `params` parameters with `residuals`
/// (`None` without repetitions).
pub fn lack_of_fit(
    rows: &Rows,
    fit: &FitOut,
    params: usize,
    residuals: &[Vector3<f64>],
) -> Option<LackOfFit> {
    // No repetitions: no pure error to test against (one row per
    // configuration says so without the cells).
    if rows.rows.len() == rows.configs.len() {
        return None;
    }
    let (cell, n_cells) = cells(rows);
    if n_cells == rows.rows.len() {
        return None;
    }
    // Per cell, in row order: the sum, then the squares about the mean (the
    // sums of one vector per cell, without one per cell: a million rows
    // may be a million cells).
    let weighted = |row: &crate::calibrate::rows::Row, r: &Vector3<f64>| {
        r.component_mul(&fit.weights[row.group()]) * rows.noise_scale(row)
    };
    let mut sum = vec![Vector3::<f64>::zeros(); n_cells];
    let mut count = vec![0usize; n_cells];
    // Equations per row of each cell: 3, or 1 for a plane contact or a
    // distance (`rows::scalar`; a cell is of one group, all of one kind).
    let mut axes = vec![3usize; n_cells];
    for ((row, r), &c) in rows.rows.iter().zip(residuals).zip(&cell) {
        sum[c] += weighted(row, r);
        count[c] += 1;
        if row.scalar().is_some() {
            axes[c] = 1;
        }
    }
    let mean: Vec<Vector3<f64>> = sum.iter().zip(&count).map(|(s, &n)| s / n as f64).collect();
    let mut pe = vec![0.0_f64; n_cells];
    for ((row, r), &c) in rows.rows.iter().zip(residuals).zip(&cell) {
        pe[c] += (weighted(row, r) - mean[c]).norm_squared();
    }
    let (mut ss_lof, mut ss_pe, mut df_pe) = (0.0, 0.0, 0usize);
    for c in 0..n_cells {
        ss_lof += count[c] as f64 * mean[c].norm_squared();
        ss_pe += pe[c];
        df_pe += axes[c] * (count[c] - 1);
    }
    let df_lof = axes.iter().sum::<usize>().checked_sub(params)?;
    LackOfFit::new(ss_lof, df_lof, ss_pe, df_pe)
}

/// A variable the residuals may follow: its name, its value per row, and
/// whether it is an angle (then it is expanded in harmonics, else in powers).
struct Variable {
    name: String,
    values: Vec<f64>,
    angle: bool,
}

/// Variables the residuals may follow, per row: joint values, joint
/// torques, the load, the time, the marker.
fn variables(rows: &Rows, names: &Names) -> Vec<Variable> {
    let r = &rows.rows;
    let var = |name: String, values: Vec<f64>, angle: bool| Variable {
        name,
        values,
        angle,
    };
    let mut out = Vec::new();
    for (j, name) in names.joints.iter().enumerate() {
        out.push(var(
            format!("q_{name}"),
            r.iter().map(|r| r.q[j]).collect(),
            revolute(names, j),
        ));
    }
    for (j, name) in names.joints.iter().enumerate() {
        out.push(var(
            format!("tau_{name}"),
            r.iter().map(|r| r.tau()[j]).collect(),
            false,
        ));
    }
    if rows.kinds.deflections {
        out.push(var(
            "load_kg".into(),
            r.iter().map(|r| r.load_kg()).collect(),
            false,
        ));
    }
    if rows.kinds.time {
        out.push(var(
            "t".into(),
            r.iter().map(|r| r.dt().unwrap_or(0.0)).collect(),
            false,
        ));
    }
    if let Some((column, _)) = &rows.temperature_ref_c {
        out.push(var(
            column.clone(),
            r.iter().map(|r| r.dtemp_k().unwrap_or(0.0)).collect(),
            false,
        ));
    }
    if names.markers.len() > 1 {
        let id = |r: &crate::calibrate::rows::Row| f64::from(names.marker_id(r.marker));
        out.push(var("marker".into(), r.iter().map(id).collect(), false));
    }
    out
}

/// How strongly the weighted residuals follow `v`: the p-value of the
/// nested F test ([`crate::estimate::nested_test`]) of regressing each
/// residual axis on smooth functions of `v` (harmonics 1–3 for an angle,
/// powers 1–3 otherwise) against a mean, pooled over the three axes.
/// Smaller is stronger. Functions the rank test
/// ([`crate::estimate::rank`]) finds dependent on the others are left out.
///
/// `live` says per residual which axes are equations (a plane contact's or
/// a distance's first alone, [`crate::calibrate::rows::Row::live`]): the
/// others weigh 0, and an axis no residual has is not regressed.
fn follow_p_value(v: &Variable, res: &[Vector3<f64>], live: &[Vector3<f64>]) -> f64 {
    let n = v.values.len();
    let mean = v.values.iter().sum::<f64>() / n.max(1) as f64;
    let sd = (v.values.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n.max(1) as f64).sqrt();
    if n < 8 || sd == 0.0 {
        return 1.0;
    }
    let features = |x: f64| -> [f64; 7] {
        if v.angle {
            let h = |k: f64| [(k * x).sin(), (k * x).cos()];
            let [s1, c1] = h(1.0);
            let [s2, c2] = h(2.0);
            let [s3, c3] = h(3.0);
            [1.0, s1, c1, s2, c2, s3, c3]
        } else {
            let z = (x - mean) / sd;
            [1.0, z, z * z, z * z * z, 0.0, 0.0, 0.0]
        }
    };
    let f = if v.angle { 7 } else { 4 };
    // Which functions are independent of the mean and of the ones before.
    let mut one = Accumulator::<f64, Dyn>::zeros(Dyn(f));
    let mut b1 = Block::new(OMatrix::<f64, U3, Dyn>::zeros(f), Vector3::zeros());
    b1.rows = 1;
    for &x in &v.values {
        b1.b.row_mut(0).copy_from_slice(&features(x)[..f]);
        let _ = one.update(&b1);
    }
    let Ok(rank) = one.identifiable() else {
        return 1.0;
    };
    let kept: Vec<usize> = (1..f).filter(|&k| rank.kept[k]).collect();
    let k = kept.len();
    if k == 0 || n <= k + 1 || !rank.kept[0] {
        return 1.0;
    }
    // Per axis with equations a mean and the kept functions: a
    // block-diagonal design of L (k + 1) columns, the means first.
    let axes: Vec<usize> = (0..3)
        .filter(|&a| live.iter().any(|l| l[a] > 0.0))
        .collect();
    let l = axes.len();
    let p = l * (k + 1);
    let mut acc = Accumulator::<f64, Dyn>::zeros(Dyn(p));
    let mut b = Block::new(OMatrix::<f64, U3, Dyn>::zeros(p), Vector3::zeros());
    for ((&x, r), w) in v.values.iter().zip(res).zip(live) {
        let fx = features(x);
        for (ia, &a) in axes.iter().enumerate() {
            b.b[(a, ia)] = 1.0;
            for (i, &c) in kept.iter().enumerate() {
                b.b[(a, l + l * i + ia)] = fx[c];
            }
        }
        b.dp = *r;
        b.w = *w;
        let _ = acc.update(&b);
    }
    let model: Vec<bool> = (0..p).map(|i| i < l).collect();
    let candidate: Vec<bool> = model.iter().map(|m| !m).collect();
    let test = acc
        .solve_active(&model)
        .and_then(|fit| nested_test(&acc, &model, &fit, &candidate));
    match test {
        Ok(t) if t.rss_before - t.delta_rss <= 0.0 => 0.0,
        Ok(t) => t.p_value,
        Err(_) => 1.0,
    }
}

/// The variable the residuals follow most, and its p-value. Rows that
/// repeat one another (same configuration, marker, kind) are averaged
/// first: they share their regressors, so counting them as independent
/// would let a many-harmonic fit look significant.
pub fn most_followed(
    rows: &Rows,
    names: &Names,
    weights: &[Vector3<f64>],
    residuals: &[Vector3<f64>],
) -> (String, f64) {
    let (cell, cells) = cells(rows);
    let mut count = vec![0.0; cells];
    let mut res = vec![Vector3::<f64>::zeros(); cells];
    let mut live = vec![Vector3::<f64>::zeros(); cells];
    for ((row, r), &c) in rows.rows.iter().zip(residuals).zip(&cell) {
        res[c] += r.component_mul(&weights[row.group()]) * rows.noise_scale(row);
        count[c] += 1.0;
        live[c] = Vector3::from(row.live());
    }
    for (r, n) in res.iter_mut().zip(&count) {
        *r /= *n;
    }
    variables(rows, names)
        .into_iter()
        .map(|v| {
            let mut values = vec![0.0; cells];
            for (&x, &c) in v.values.iter().zip(&cell) {
                values[c] += x / count[c];
            }
            let v = Variable { values, ..v };
            let s = follow_p_value(&v, &res, &live);
            (v.name, s)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or_else(|| ("none".into(), 1.0))
}

/// Values of the variable an effect is traced by, per row, with its name
/// and unit, for plots.
pub fn traced_variable(rows: &Rows, names: &Names, c: &Candidate) -> (String, Vec<f64>) {
    let r = &rows.rows;
    match c.joint {
        Some(j) if c.effect.follows_angle() => {
            let scale = if revolute(names, j) {
                180.0 / std::f64::consts::PI
            } else {
                1000.0
            };
            let unit = if revolute(names, j) { "deg" } else { "mm" };
            (
                format!("q_{} [{unit}]", names.joints[j]),
                r.iter().map(|r| r.q[j] * scale).collect(),
            )
        }
        Some(j) => (
            format!("tau_{} [N*m]", names.joints[j]),
            r.iter().map(|r| r.tau()[j]).collect(),
        ),
        None => match c.effect {
            crate::calibrate::effects::Effect::Drift => (
                "t [s]".into(),
                r.iter().map(|r| r.dt().unwrap_or(0.0)).collect(),
            ),
            crate::calibrate::effects::Effect::ThermalExpansion => {
                let (column, mean) = rows
                    .temperature_ref_c
                    .clone()
                    .unwrap_or_else(|| ("temperature".into(), 0.0));
                (
                    format!("{column} [degC]"),
                    r.iter()
                        .map(|r| mean + r.dtemp_k().unwrap_or(0.0))
                        .collect(),
                )
            }
            crate::calibrate::effects::Effect::LoadCom => {
                ("load_kg".into(), r.iter().map(|r| r.load_kg()).collect())
            }
            _ => ("config".into(), configs_per_row(rows)),
        },
    }
}

/// Values of the variable `name` ([`most_followed`]) per row (the
/// configuration number when there is no such variable).
pub fn variable_values(rows: &Rows, names: &Names, name: &str) -> Vec<f64> {
    variables(rows, names)
        .into_iter()
        .find(|v| v.name == name)
        .map(|v| v.values)
        .unwrap_or_else(|| configs_per_row(rows))
}

/// Each row's configuration id (as in the CSV), as a value.
fn configs_per_row(rows: &Rows) -> Vec<f64> {
    rows.rows
        .iter()
        .map(|r| rows.configs.get(r.group()).map_or(f64::NAN, |&c| c as f64))
        .collect()
}
