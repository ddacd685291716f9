//! The paper's KR-270 experiment (section 5) as a host pipeline (`std`):
//! the 9-parameter model, its rows, the fits of Tables 3 and 4, and the
//! refinement on the exact (non-linear) deflection model.
//!
//! ```text
//!   Job + Measurements ──Experiment::new──► Experiment (one Obs per deflection)
//!        │ linear_stats()        rows at the unloaded pose (eq. 3)
//!        │ exact_stats(x0)       rows at the deflected pose (Gauss–Newton)
//!        ▼
//!   GroupedStats<f64, 9, 15> ──fits()──► Fits { OLS, WLS λ = 0.5, 1, 2, iterative WLS }
//! ```
//!
//! Units: the estimate is in µrad/(N·m) (the layout's unit); `Δp` and σ in
//! metres inside, µm in what is printed.
//!
//! **Exact model.** A hanging load with joint torques `τ` (computed at the
//! unloaded pose `q`) turns the joints by `δqⱼ = kⱼ τⱼ`; the marker moves by
//! `f(k) = p(q + δq) − p(q)`. The linear model (eq. 3) is its first-order
//! term `Σ kⱼ τⱼ zⱼ × (p − oⱼ)` at `q`. Since `δq` is linear in `k`, the exact
//! Jacobian of `f` is the same compliance columns evaluated at the
//! **deflected** frames `q + δq(k)` (with the torques still at `q`).
//! [`Experiment::exact_stats`] linearises there: rows `J(x0)` and
//! pseudo-observations `Δp − f(x0) + J(x0) x0`, so that any fit of these
//! statistics is one Gauss–Newton step from `x0`, and its residuals at the
//! fixed point are the exact model's residuals.
//!
//! ```
//! use robcal::io::Job;
//! use robcal::paper::{self, Experiment};
//!
//! let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/data/kr270/");
//! let job = Job::load(format!("{dir}setup.toml"))?;
//! let data = job.read_measurements(format!("{dir}measurements.csv"))?;
//! let exp = Experiment::new(&job, &data)?;
//! let stats = exp.linear_stats()?;
//! assert_eq!(stats.equations(), 810);
//! let settings = robcal::IrlsSettings::new(paper::weight(10e-6, 1.0)?);
//! let fits = paper::fits(&stats, &settings)?;
//! // k21 [µrad/(N·m)] within 3σ of the truth (Table 3), WLS tighter than OLS.
//! let (k21, s) = (fits.irls.solution.x[0], fits.irls.std()[0]);
//! assert!((k21 - 0.287).abs() < 3.0 * s);
//! assert!(s < fits.ols.std()[0]);
//! // Gauss–Newton on the exact model moves k22 by ~+2σ (the linear bias).
//! let (exact, _) = exp.refine(&fits.ols.solution.x, 1e-6, 20, |s| {
//!     robcal::Reweightable::fit_ols(s, &[true; paper::N])
//! })?;
//! let moved = (exact.solution.x[1] - fits.ols.solution.x[1]) / fits.ols.std()[1];
//! assert!((1.5..2.0).contains(&moved), "{moved}");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::error::Error as StdError;

use nalgebra::{SMatrix, SVector, Vector3};

use crate::chain::Chain;
use crate::elastostatic::{compliance_columns, joint_torques, PointLoad};
use crate::grouped::GroupedStats;
use crate::io::{Job, Measurements, MAX_JOINTS};
use crate::irls::{robust_weights, Fit, IrlsSettings, Iteration, Reweightable};
use crate::kr270;
use crate::layout::{angle_urad, Layout, Marker, Param};
use crate::weights::RobustWeight;
use crate::Error;

/// Number of parameters of the paper's model.
pub const N: usize = kr270::PARAMS;
/// Number of groups (configurations).
pub const G: usize = kr270::CONFIGS;
/// Room for the iteration history (OLS start + iterations).
pub const H: usize = 128;

/// Grouped statistics of the paper's model.
pub type Stats = GroupedStats<f64, N, G>;

/// The paper's layout: k21…k25 (`ComplianceByAngle` on A2, one per q2 group
/// of Table 2), then k3, k4, k5, k6 (`Compliance` on A3…A6).
///
/// # Errors
/// When the chain has fewer than 6 joints.
pub fn layout<const J: usize>(chain: &Chain<f64, J>) -> Result<Layout<N>, Error> {
    let mut l = Layout::new();
    for (bin, q2) in kr270::Q2_GROUPS_DEG.iter().enumerate() {
        l.push(
            chain,
            Param::ComplianceByAngle {
                joint: 1,
                bin: bin as u8,
                angle_urad: angle_urad(q2.to_radians()),
            },
        )?;
    }
    for joint in 2..6 {
        l.push(chain, Param::Compliance { joint })?;
    }
    Ok(l)
}

/// One deflection of the experiment.
#[derive(Debug, Clone)]
pub struct Obs {
    /// Group id: the configuration number of the CSV.
    pub config: i32,
    /// q2 group 0…4 (which of k21…k25 acts).
    pub q2_group: usize,
    /// Unloaded joint values \[rad\].
    pub q: Vec<f64>,
    /// The marker.
    pub marker: Marker<f64>,
    /// The hanging load.
    pub load: PointLoad<f64>,
    /// Measured deflection (loaded − unloaded) \[m\].
    pub dp: Vector3<f64>,
}

/// The experiment: the chain, the layout and every deflection.
#[derive(Debug, Clone)]
pub struct Experiment {
    /// The robot.
    pub chain: Chain<f64, MAX_JOINTS>,
    /// The 9-parameter layout ([`layout`]).
    pub layout: Layout<N>,
    /// The deflections, in file order.
    pub obs: Vec<Obs>,
}

/// The fits of Tables 3 and 4 and Figure 3 on one set of statistics.
#[derive(Debug, Clone)]
pub struct Fits {
    /// OLS (eq. 6); `covariance` is the sandwich (eq. 8).
    pub ols: Fit<f64, N, G>,
    /// OLS covariance under i.i.d. noise (eq. 7), for reference.
    pub ols_cov_iid: SMatrix<f64, N, N>,
    /// One-step WLS (eq. 10, weights eq. 14 from the OLS residuals) for
    /// λ = 0.5, 1, 2 ([`kr270::LAMBDAS`]); covariance eq. 11.
    pub wls: [Fit<f64, N, G>; 3],
    /// Iterative WLS (λ of the settings), covariance eq. 11.
    pub irls: Fit<f64, N, G>,
    /// OLS start and every iteration of the iterative WLS.
    pub history: Vec<Iteration<f64, N>>,
}

impl Experiment {
    /// The experiment of a job: every deflection of `data` becomes one
    /// [`Obs`].
    ///
    /// # Errors
    /// Without a `[load]` in the setup, with a q2 that is none of Table 2's
    /// groups, or a marker id that does not fit the layout's `u8`.
    pub fn new(job: &Job, data: &Measurements) -> Result<Self, Box<dyn StdError>> {
        let chain = job.robot.chain.clone();
        let layout = layout(&chain)?;
        let load = job.setup.load.ok_or("the setup has no [load]")?;
        let mut obs = Vec::with_capacity(data.deflections.len());
        for d in &data.deflections {
            let q2_deg = d.q.get(1).ok_or("fewer than two joints")?.to_degrees();
            let q2_group = kr270::q2_group(q2_deg)
                .ok_or_else(|| format!("q2 = {q2_deg} deg is none of Table 2's groups"))?;
            let m = job
                .setup
                .markers
                .iter()
                .find(|m| m.id == d.marker)
                .ok_or("unknown marker")?;
            obs.push(Obs {
                config: i32::try_from(d.config)?,
                q2_group,
                q: d.q.clone(),
                marker: Marker {
                    id: u8::try_from(m.id)?,
                    xyz_m: Vector3::from(m.xyz),
                },
                load: PointLoad {
                    mass_kg: d.load_kg,
                    com_m: Vector3::from(load.com),
                    gravity_mps2: Vector3::from(load.gravity),
                },
                dp: Vector3::from(d.dp_m),
            });
        }
        Ok(Self { chain, layout, obs })
    }

    /// Rows `B` (eq. 3) of every deflection at its unloaded pose, in
    /// µrad/(N·m) columns.
    ///
    /// # Errors
    /// From the layout.
    pub fn linear_rows(&self) -> Result<Vec<SMatrix<f64, 3, N>>, Error> {
        self.obs
            .iter()
            .map(|o| {
                self.layout
                    .block(&self.chain, &o.q, &o.marker, Some(&o.load))
            })
            .collect()
    }

    /// Grouped statistics of the linear model (eq. 3) with the measured
    /// deflections.
    ///
    /// # Errors
    /// From the layout and [`GroupedStats::update`].
    pub fn linear_stats(&self) -> Result<Stats, Error> {
        let rows = self.linear_rows()?;
        let dp: Vec<_> = self.obs.iter().map(|o| o.dp).collect();
        stats_of(&self.obs, &rows, &dp)
    }

    /// Joint compliances \[rad/(N·m)\] of A1…A6 for a deflection of q2
    /// group `g`, from the estimate `x` \[µrad/(N·m)\]; k1 = 0.
    pub fn joint_compliances(x: &SVector<f64, N>, g: usize) -> [f64; 6] {
        [0.0, x[g], x[5], x[6], x[7], x[8]].map(|k| k * 1e-6)
    }

    /// The exact deflection `p(q + δq) − p(q)` \[m\] of observation `o` for
    /// compliances `x`, and its Jacobian \[m per µrad/(N·m)\] at `x`
    /// (compliance columns at the deflected frames, torques at `q`).
    ///
    /// # Errors
    /// From the kinematics.
    pub fn exact(
        &self,
        o: &Obs,
        x: &SVector<f64, N>,
    ) -> Result<(Vector3<f64>, SMatrix<f64, 3, N>), Error> {
        let frames = self.chain.frames(&o.q)?;
        let dof = frames.dof();
        let mut tau = [0.0; MAX_JOINTS];
        joint_torques(&frames, &o.load.wrench(&frames), &mut tau)?;
        let k = Self::joint_compliances(x, o.q2_group);
        let q1: Vec<f64> =
            o.q.iter()
                .enumerate()
                .map(|(j, qj)| qj + k.get(j).copied().unwrap_or(0.0) * tau[j])
                .collect();
        let deflected = self.chain.frames(&q1)?;
        let p0 = frames.point_m(&o.marker.xyz_m);
        let p1 = deflected.point_m(&o.marker.xyz_m);
        let mut cols = [Vector3::zeros(); MAX_JOINTS];
        compliance_columns(&deflected, &p1, &tau[..dof], &mut cols[..dof])?;
        let mut jac = SMatrix::<f64, 3, N>::zeros();
        jac.set_column(o.q2_group, &(cols[1] * 1e-6));
        for j in 2..6 {
            jac.set_column(3 + j, &(cols[j] * 1e-6));
        }
        Ok((p1 - p0, jac))
    }

    /// Noise-free exact deflections of every observation for `x`.
    ///
    /// # Errors
    /// From the kinematics.
    pub fn exact_deflections(&self, x: &SVector<f64, N>) -> Result<Vec<Vector3<f64>>, Error> {
        self.obs.iter().map(|o| Ok(self.exact(o, x)?.0)).collect()
    }

    /// Statistics of the exact model linearised at `x0` (module docs): a
    /// fit of them is one Gauss–Newton step from `x0`.
    ///
    /// # Errors
    /// From the kinematics and [`GroupedStats::update`].
    pub fn exact_stats(&self, x0: &SVector<f64, N>) -> Result<Stats, Error> {
        let mut rows = Vec::with_capacity(self.obs.len());
        let mut y = Vec::with_capacity(self.obs.len());
        for o in &self.obs {
            let (f, jac) = self.exact(o, x0)?;
            y.push(o.dp - f + jac * x0);
            rows.push(jac);
        }
        stats_of(&self.obs, &rows, &y)
    }

    /// Gauss–Newton on the exact model: relinearise at the last estimate
    /// and refit with `fit` until no parameter moves by more than
    /// `tolerance` of its standard deviation, or by less than 1e-12 of its
    /// value (at most `max_steps`).
    /// Returns the final fit and the number of relinearisations.
    ///
    /// # Errors
    /// From the statistics and `fit`.
    pub fn refine<F>(
        &self,
        start: &SVector<f64, N>,
        tolerance: f64,
        max_steps: usize,
        mut fit: F,
    ) -> Result<(Fit<f64, N, G>, usize), Error>
    where
        F: FnMut(&Stats) -> Result<Fit<f64, N, G>, Error>,
    {
        let mut x = *start;
        let mut steps = 0;
        loop {
            let f = fit(&self.exact_stats(&x)?)?;
            steps += 1;
            let std = f.std();
            // In σ; on (nearly) noise-free data σ → 0, so a relative
            // change of 1e-12 counts as settled too.
            let moved = (0..N)
                .map(|i| {
                    let scale = std[i].max(1e-12 * f.solution.x[i].abs() / tolerance);
                    (f.solution.x[i] - x[i]).abs() / scale.max(f64::MIN_POSITIVE)
                })
                .fold(0.0, f64::max);
            x = f.solution.x;
            if moved < tolerance || steps >= max_steps {
                return Ok((f, steps));
            }
        }
    }
}

/// Grouped statistics from rows and observations (group = configuration).
///
/// # Errors
/// From [`GroupedStats::update`].
pub fn stats_of(
    obs: &[Obs],
    rows: &[SMatrix<f64, 3, N>],
    dp: &[Vector3<f64>],
) -> Result<Stats, Error> {
    let mut s = Stats::new();
    for ((o, b), y) in obs.iter().zip(rows).zip(dp) {
        s.update(o.config, b, y)?;
    }
    Ok(s)
}

/// The paper's weights (eq. 14) with σ0 \[m\] and λ.
///
/// # Errors
/// For σ0 ≤ 0 or λ < 0.
pub fn weight(sigma0_m: f64, lambda: f64) -> Result<RobustWeight<f64>, Error> {
    RobustWeight::new(sigma0_m, lambda)
}

/// One-step WLS from a previous fit: weights eq. 14 from its residual σ.
///
/// # Errors
/// From the weights and the fit.
pub fn wls_from<R: Reweightable<f64, N>>(
    data: &R,
    previous: &Fit<f64, N, G>,
    w: &RobustWeight<f64>,
) -> Result<Fit<f64, N, G>, Error> {
    let weights = robust_weights::<f64, G>(&previous.sigma, w)?;
    data.fit_weighted(&weights, &[true; N])
}

/// All fits of the paper on `data`: OLS, one-step WLS for λ = 0.5, 1, 2
/// (σ0 of `settings`), and the iterative WLS of `settings`.
///
/// # Errors
/// From the fits.
pub fn fits<R: Reweightable<f64, N>>(
    data: &R,
    settings: &IrlsSettings<f64>,
) -> Result<Fits, Error> {
    let active = [true; N];
    let ols: Fit<f64, N, G> = data.fit_ols(&active)?;
    let ols_cov_iid = ols.solution.cov_iid();
    let sigma0 = settings.weight.sigma0;
    let wls = [
        wls_from(data, &ols, &weight(sigma0, kr270::LAMBDAS[0])?)?,
        wls_from(data, &ols, &weight(sigma0, kr270::LAMBDAS[1])?)?,
        wls_from(data, &ols, &weight(sigma0, kr270::LAMBDAS[2])?)?,
    ];
    let mut history: heapless::Vec<Iteration<f64, N>, H> = heapless::Vec::new();
    let irls = data.fit_irls(settings, &active, &mut history)?;
    Ok(Fits {
        ols,
        ols_cov_iid,
        wls,
        irls,
        history: history.to_vec(),
    })
}

/// The true Table 3 WLS values as a vector (the truth of the data set).
pub fn truth() -> SVector<f64, N> {
    SVector::from_column_slice(&kr270::WLS_VALUE)
}
