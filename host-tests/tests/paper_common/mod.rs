//! Shared helpers of the `paper_*` tests: the committed KR-270 data set and
//! an independent dense batch reference (nalgebra `DMatrix`, SVD, explicit
//! `W` and `Σ` matrices) for OLS, WLS and the sandwich covariances.
#![allow(dead_code)]

use std::path::PathBuf;

use nalgebra::{DMatrix, DVector, Vector3};
use robcal::elastostatic::{compliance_columns, joint_torques};
use robcal::io::Job;
use robcal::irls::IrlsSettings;
use robcal::paper::{self, Experiment, N};

/// The job and the experiment of `data/kr270/`.
pub fn experiment() -> (Job, Experiment) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/kr270");
    let job = Job::load(dir.join("setup.toml")).unwrap();
    let data = job.read_measurements(dir.join("measurements.csv")).unwrap();
    let exp = Experiment::new(&job, &data).unwrap();
    (job, exp)
}

/// The iteration settings of the main job: σ0 = 10 µm, λ = 1, tolerance
/// 1e-6 σ.
pub fn settings() -> IrlsSettings<f64> {
    IrlsSettings {
        tolerance: 1e-6,
        max_iterations: 100,
        ..IrlsSettings::new(paper::weight(10e-6, 1.0).unwrap())
    }
}

/// The stacked system of the linear model (eq. 3): `B` (3m × 9, µrad/(N·m)
/// columns), `Δp` (3m, metres) and the (group, axis) of every row. `B` is
/// built here from the compliance columns directly, not with
/// `Layout::block`.
pub struct Batch {
    pub b: DMatrix<f64>,
    pub y: DVector<f64>,
    /// Row → group index 0..15 (configuration − 1).
    pub group: Vec<usize>,
    /// Row → axis 0..3.
    pub axis: Vec<usize>,
}

pub fn batch(exp: &Experiment, dp: &[Vector3<f64>]) -> Batch {
    let m = 3 * exp.obs.len();
    let mut b = DMatrix::zeros(m, N);
    let mut y = DVector::zeros(m);
    let mut group = Vec::with_capacity(m);
    let mut axis = Vec::with_capacity(m);
    for (i, (o, d)) in exp.obs.iter().zip(dp).enumerate() {
        let frames = exp.chain.frames(&o.q).unwrap();
        let dof = frames.dof();
        let mut tau = vec![0.0; dof];
        joint_torques(&frames, &o.load.wrench(&frames), &mut tau).unwrap();
        let p = frames.point_m(&o.marker.xyz_m);
        let mut cols = vec![Vector3::zeros(); dof];
        compliance_columns(&frames, &p, &tau, &mut cols).unwrap();
        for a in 0..3 {
            let r = 3 * i + a;
            b[(r, o.q2_group)] = cols[1][a] * 1e-6;
            for j in 2..6 {
                b[(r, 3 + j)] = cols[j][a] * 1e-6;
            }
            y[r] = d[a];
            group.push(o.config as usize - 1);
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
    /// σ per (group, axis) of the residuals, with the `m/(m − p)` correction.
    pub sigma: Vec<[f64; 3]>,
    /// Sandwich (eq. 8 / 11) with that σ.
    pub cov: DMatrix<f64>,
    /// Eq. 7: `RSS/(m − p) · (BᵀB)⁻¹` (meaningful for unit weights).
    pub cov_iid: DMatrix<f64>,
}

/// Weighted least squares by SVD of `W B`; covariances with explicit
/// `W` and `Σ` diagonal matrices.
pub fn batch_fit(s: &Batch, w: &[f64]) -> BatchFit {
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
    let r = &s.y - &s.b * &x;
    let mut rss = vec![[0.0; 3]; 15];
    let mut n = vec![[0usize; 3]; 15];
    for i in 0..m {
        rss[s.group[i]][s.axis[i]] += r[i] * r[i];
        n[s.group[i]][s.axis[i]] += 1;
    }
    let corr = m as f64 / (m - N) as f64;
    let sigma: Vec<[f64; 3]> = rss
        .iter()
        .zip(&n)
        .map(|(r, n)| [0, 1, 2].map(|a| (r[a] / n[a] as f64 * corr).sqrt()))
        .collect();
    let sig = DMatrix::from_diagonal(&DVector::from_iterator(
        m,
        (0..m).map(|i| sigma[s.group[i]][s.axis[i]]),
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
