//! Shared helpers of the `paper_*` tests: the committed KR-270 data set,
//! the product's fits of it (`robcal::calibrate`), the paper's rows with
//! robcal's core (for the analyses the product does not make), and an
//! independent dense batch reference (nalgebra `DMatrix`, SVD, explicit `W`
//! and `Σ` matrices, its own columns) for OLS, WLS and the sandwich
//! covariances.
#![allow(dead_code)]

use std::path::PathBuf;

use nalgebra::{Const, DMatrix, DVector, Vector3};
use robcal::calibrate::{self, DeflectionModel, Method, Report, Settings};
use robcal::io::{Job, Measurements};
use robcal::model::{compliance_columns, Marker};
use robcal::robot::{joint_torques, PointLoad};
use robcal::GroupedStats;
use robcal_paper::kr270;

/// Parameters of the paper's model.
pub const N: usize = kr270::PARAMS;
/// Configurations.
pub const G: usize = kr270::CONFIGS;
/// Grouped statistics of the paper's rows.
pub type Stats = GroupedStats<f64, Const<N>, G>;

/// The job and the measurements of `data/kr270/`.
pub fn experiment() -> (Job, Measurements) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/kr270");
    let job = Job::load(dir.join("setup.toml")).unwrap();
    let data = job.read_measurements(dir.join("measurements.csv")).unwrap();
    (job, data)
}

/// The product's fit of the declared model with the paper's first-order
/// deflection model (eq. 3, the rows the batch reference builds): no
/// diagnosis, no held-out error; `method`, λ of the setup unless given.
pub fn fit(job: &Job, data: &Measurements, method: Method, lambda: Option<f64>) -> Report {
    fit_with(job, data, method, lambda, DeflectionModel::Linear)
}

/// [`fit`] with the exact deflection model (the product's default).
pub fn fit_exact(job: &Job, data: &Measurements, method: Method, lambda: Option<f64>) -> Report {
    fit_with(job, data, method, lambda, DeflectionModel::Exact)
}

fn fit_with(
    job: &Job,
    data: &Measurements,
    method: Method,
    lambda: Option<f64>,
    deflection_model: DeflectionModel,
) -> Report {
    let settings = Settings {
        method,
        lambda,
        diagnose: false,
        heldout: false,
        deflection_model,
        ..Settings::default()
    };
    let r = calibrate::calibrate(job, data, &settings, &mut |_| {}).unwrap();
    let names: Vec<&str> = r.parameters.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, kr270::PARAM_NAMES, "the paper's model, in order");
    r
}

/// Estimate and standard deviations of a report, in parameter order.
pub fn x_sd(r: &Report) -> (Vec<f64>, Vec<f64>) {
    (
        r.parameters.iter().map(|p| p.value).collect(),
        r.parameters.iter().map(|p| p.std).collect(),
    )
}

/// The truth of the data set: Table 3's WLS column.
pub fn truth() -> [f64; N] {
    kr270::WLS_VALUE
}

/// The paper's rows with robcal's core (`kr270::layout`, `Layout::block`),
/// grouped by configuration.
pub fn core_stats(job: &Job, data: &Measurements) -> Stats {
    let chain = &job.robot.chain;
    let layout = kr270::layout(chain).unwrap();
    let load = job.setup.load.unwrap();
    let mut stats = Stats::new();
    for d in &data.deflections {
        let m = job
            .setup
            .markers
            .iter()
            .position(|m| m.id == d.marker)
            .unwrap();
        let marker = Marker {
            index: m as u8,
            xyz_m: Vector3::from(job.setup.markers[m].xyz),
        };
        let pl = PointLoad {
            mass_kg: d.load_kg,
            com_m: Vector3::from(load.com),
            gravity_mps2: Vector3::from(load.gravity),
        };
        let b = layout
            .block::<f64, { robcal::io::MAX_JOINTS }, Const<N>>(chain, &d.q, &marker, Some(&pl))
            .unwrap();
        stats
            .update(d.config as i32, &b, &Vector3::from(d.dp_m))
            .unwrap();
    }
    stats
}

/// The stacked system of the linear model (eq. 3): `B` (3m × 9, µrad/(N·m)
/// columns), `Δp` (3m, metres) and the (group, axis) of every row. `B` is
/// built here from the compliance columns directly: the q2 group of Table 2
/// picks k21…k25, not the layout's angle bins.
pub struct Batch {
    pub b: DMatrix<f64>,
    pub y: DVector<f64>,
    /// Row → group index 0..15 (configuration − 1).
    pub group: Vec<usize>,
    /// Row → axis 0..3.
    pub axis: Vec<usize>,
}

pub fn batch(job: &Job, data: &Measurements) -> Batch {
    let chain = &job.robot.chain;
    let load = job.setup.load.unwrap();
    let m = 3 * data.deflections.len();
    let mut b = DMatrix::zeros(m, N);
    let mut y = DVector::zeros(m);
    let mut group = Vec::with_capacity(m);
    let mut axis = Vec::with_capacity(m);
    for (i, d) in data.deflections.iter().enumerate() {
        let q2 = kr270::q2_group(d.q[1].to_degrees()).unwrap();
        let frames = chain.frames(&d.q).unwrap();
        let dof = frames.dof();
        let pl = PointLoad {
            mass_kg: d.load_kg,
            com_m: Vector3::from(load.com),
            gravity_mps2: Vector3::from(load.gravity),
        };
        let mut tau = vec![0.0; dof];
        joint_torques(&frames, &pl.wrench(&frames), &mut tau).unwrap();
        let marker = job.setup.markers.iter().find(|m| m.id == d.marker).unwrap();
        let p = frames.point_m(&Vector3::from(marker.xyz));
        let mut cols = vec![Vector3::zeros(); dof];
        compliance_columns(&frames, &p, &tau, &mut cols).unwrap();
        for a in 0..3 {
            let r = 3 * i + a;
            b[(r, q2)] = cols[1][a] * 1e-6;
            for (j, c) in cols.iter().enumerate().take(6).skip(2) {
                b[(r, 3 + j)] = c[a] * 1e-6;
            }
            y[r] = d.dp_m[a];
            group.push(d.config as usize - 1);
            axis.push(a);
        }
    }
    Batch { b, y, group, axis }
}

/// A dense batch fit with explicit weights per row.
pub struct BatchFit {
    pub x: DVector<f64>,
    /// `(Bᵀ W² B)⁻¹`.
    pub lambda_inv: DMatrix<f64>,
    /// σ per (group, axis) of the residuals: `RSS / (n − h)` with `h` the
    /// group and axis's part of the trace of the hat matrix.
    pub sigma: Vec<[f64; 3]>,
    /// Those degrees of freedom `n − h`.
    pub dof: Vec<[f64; 3]>,
    /// Sandwich (eq. 8 / 11) with that σ (times `ν / (ν − 4(1 − w))` per
    /// row when the weights were estimated from these data, eq. 14).
    pub cov: DMatrix<f64>,
    /// Eq. 7: `RSS/(m − p) · (BᵀB)⁻¹` (meaningful for unit weights).
    pub cov_iid: DMatrix<f64>,
}

/// Weighted least squares by SVD of `W B`; the hat matrix
/// `H = W B (BᵀW²B)⁻¹ BᵀW` and the covariances with explicit `W` and `Σ`
/// diagonal matrices. `estimated`: the weights are eq. 14 of σ estimated
/// from these data.
pub fn batch_fit(s: &Batch, w: &[f64], estimated: bool) -> BatchFit {
    let m = s.b.nrows();
    let wm = DMatrix::from_diagonal(&DVector::from_column_slice(w));
    let wb = &wm * &s.b;
    let wy = &wm * &s.y;
    let svd = wb.clone().svd(true, true);
    let x = svd.solve(&wy, 1e-14).unwrap();
    let v = svd.v_t.as_ref().unwrap().transpose();
    let sv = &svd.singular_values;
    let dinv = DMatrix::from_diagonal(&sv.map(|s| 1.0 / (s * s)));
    let lambda_inv = &v * dinv * v.transpose();
    let hat = &wb * &lambda_inv * wb.transpose();
    let r = &s.y - &s.b * &x;
    let mut rss = vec![[0.0; 3]; G];
    let mut h = vec![[0.0; 3]; G];
    let mut n = vec![[0usize; 3]; G];
    for i in 0..m {
        rss[s.group[i]][s.axis[i]] += r[i] * r[i];
        h[s.group[i]][s.axis[i]] += hat[(i, i)];
        n[s.group[i]][s.axis[i]] += 1;
    }
    let dof: Vec<[f64; 3]> = (0..G)
        .map(|g| [0, 1, 2].map(|a| n[g][a] as f64 - h[g][a]))
        .collect();
    // No group of the paper's experiment is small enough to be pooled.
    assert!(dof.iter().flatten().all(|&v| v >= 8.0), "{dof:?}");
    let sigma: Vec<[f64; 3]> = (0..G)
        .map(|g| [0, 1, 2].map(|a| (rss[g][a] / dof[g][a]).sqrt()))
        .collect();
    let sig = DMatrix::from_diagonal(&DVector::from_iterator(
        m,
        (0..m).map(|i| {
            let (g, a) = (s.group[i], s.axis[i]);
            let c = if estimated {
                dof[g][a] / (dof[g][a] - 4.0 * (1.0 - w[i]))
            } else {
                1.0
            };
            sigma[g][a] * c.sqrt()
        }),
    ));
    let w2 = &wm * &wm;
    let middle = s.b.transpose() * &w2 * &sig * &sig * &w2 * &s.b;
    let cov = &lambda_inv * middle * &lambda_inv;
    let rss_all = r.dot(&r);
    let cov_iid = &lambda_inv * (rss_all / (m - N) as f64);
    BatchFit {
        x,
        lambda_inv,
        sigma,
        dof,
        cov,
        cov_iid,
    }
}

/// Row weights of eq. 14 from σ per (group, axis).
pub fn weights_eq14(s: &Batch, sigma: &[[f64; 3]], sigma0: f64, lambda: f64) -> Vec<f64> {
    (0..s.b.nrows())
        .map(|i| sigma0 / (sigma0 + lambda * sigma[s.group[i]][s.axis[i]]))
        .collect()
}
