//! The paper's KR-270 experiment (section 5) as the firmware runs it: the
//! robot as a constant, the 270 measured deflections from a compact table in
//! flash (`kr270_table.rs`, generated on the host by
//! `examples/firmware_table.rs` from `data/kr270/measurements.csv`), the
//! identification rows computed on the device, and a [`Reweightable`] source
//! that streams the measurements through an [`Accumulator`] one at a time,
//! on every pass of the iterative WLS.
//!
//! Memory is `O(N² + G)` and does not grow with the number of measurements:
//! one accumulator, the σ and weights per configuration and axis, and the
//! three marker blocks of the configuration being streamed. The rows are
//! recomputed from the joint angles on every pass (one forward kinematics
//! and one set of load torques per configuration), which trades
//! `O(measurements)` RAM (270 × 3 × 9 scalars, 29 KB in f32) or `O(G)` RAM
//! (45 cached blocks, 4.9 KB) for a few percent of the time of a pass.
//!
//! Generic over the scalar: the firmware runs it in f32; the host runs the
//! same code in f64 and compares it with [`robcal::GroupedStats`]
//! (`host-tests/tests/firmware_kr270.rs`).
//!
//! Units: the estimate in µrad/(N·m) (the layout's unit), `Δp` and σ in m.

use nalgebra::{
    Const, Isometry3, RealField, SMatrix, SVector, Translation3, UnitQuaternion, Vector3,
};
use robcal::estimate::{group_dof, group_sigma, leverage, Noise, RobustWeight, Solution};
use robcal::model::{Layout, Marker, Sample};
use robcal::robot::{joint_torques, PointLoad};
use robcal::{Accumulator, Block, Chain, Error, Fit, IrlsSettings, Joint, JointKind, Reweightable};

// The generated data: `Q_CDEG`, `LOAD_DKG`, `KEYS`, `DP_NM`, `DP_QUANTUM_M`
// and the host's reference result `HOST_*`.
include!("kr270_table.rs");

/// Parameters: k21…k25, k3, k4, k5, k6 (`robcal_paper::kr270::PARAM_NAMES`).
pub const N: usize = robcal_paper::kr270::PARAMS;
/// The parameters as a nalgebra dimension.
pub type Dn = Const<N>;
/// Groups: the 15 configurations of Table 2.
pub const G: usize = robcal_paper::kr270::CONFIGS;
/// Movable joints.
pub const J: usize = 6;

/// One measured deflection (loaded − unloaded position of one marker, one
/// repetition), decoded from the table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Deflection {
    /// Configuration index 0…14 (the CSV's `config` − 1): the group.
    pub config: u8,
    /// Marker index 0…2 (the CSV's `marker` − 1).
    pub marker: u8,
    /// `Δp` (x, y, z, base frame) in units of [`DP_QUANTUM_M`] (1 nm).
    pub dp: [i32; 3],
}

/// The deflections of the table, in table order.
pub fn deflections() -> impl Iterator<Item = Deflection> {
    KEYS.iter().zip(DP_NM.iter()).map(|(&k, &dp)| Deflection {
        config: k >> 2,
        marker: k & 3,
        dp,
    })
}

/// The KR 270 R2700 ultra of `data/kr270/kr270.urdf`, written out: joint
/// origins \[m\] (all rpy 0), axes, and the `tool0` tip (flange turned by
/// 1.5707963 rad about y, the URDF's number). The host test checks it
/// against the URDF reader's chain.
pub fn chain<T: RealField + Copy>() -> Result<Chain<T, J>, Error> {
    // (origin xyz [m], axis), base to tip.
    const JOINTS: [([f64; 3], [f64; 3]); J] = [
        ([0.0, 0.0, 0.675], [0.0, 0.0, -1.0]),
        ([0.350, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([1.150, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([1.200, 0.0, -0.041], [-1.0, 0.0, 0.0]),
        ([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([0.240, 0.0, 0.0], [-1.0, 0.0, 0.0]),
    ];
    // The URDF's literal, not π/2: the chain must be the URDF's to rounding.
    #[allow(clippy::approx_constant)]
    const TOOL0_PITCH_RAD: f64 = 1.570_796_3;
    let v = |a: [f64; 3]| Vector3::new(c(a[0]), c(a[1]), c(a[2]));
    let mut chain = Chain::new();
    for (xyz, axis) in JOINTS {
        let joint = Joint::from_urdf(v(xyz), Vector3::zeros(), v(axis), JointKind::Revolute)
            .ok_or(Error::NonFinite { what: "joint axis" })?;
        chain.push(joint)?;
    }
    chain.set_tip(Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_euler_angles(T::zero(), c(TOOL0_PITCH_RAD), T::zero()),
    ));
    Ok(chain)
}

/// The paper's layout: k21…k25 (A2's compliance by angle, one per q2 group
/// of Table 2), then k3…k6.
pub fn layout<T: RealField + Copy>(chain: &Chain<T, J>) -> Result<Layout<N>, Error> {
    robcal_paper::kr270::layout(chain)
}

fn c<T: RealField + Copy>(x: f64) -> T {
    nalgebra::convert(x)
}

/// Joint angles of configuration `g` \[rad\].
pub fn q_rad<T: RealField + Copy>(g: usize) -> [T; J] {
    Q_CDEG[g].map(|cdeg| c::<T>(f64::from(cdeg) * 0.01) * T::pi() / c(180.0))
}

/// `Δp` of a deflection \[m\]: the count of nanometres times the quantum
/// in `T`. The table's counts are below 2²⁴ (checked by the generator,
/// `examples/firmware_table.rs`), so they are exact in f32 as in f64 and
/// the product is the only rounding: in f64 the same value as
/// `f64::from(count) * 1e-9`; in f32 no soft-float f64 arithmetic on the
/// device (through f64 it cost ~400 instructions per deflection on the
/// Cortex-M4F).
pub fn dp_m<T: RealField + Copy>(d: &Deflection) -> Vector3<T> {
    let quantum: T = c(DP_QUANTUM_M);
    // `f64::from(v as f32)`: exact for |v| < 2²⁴, and `as f32` back is the
    // identity, which the compiler folds: no f64 arithmetic in f32.
    Vector3::from_fn(|a, _| c::<T>(f64::from(d.dp[a] as f32)) * quantum)
}

/// The experiment as a streaming [`Reweightable`] source over the flash
/// table.
pub struct Kr270<T: RealField + Copy> {
    chain: Chain<T, J>,
    layout: Layout<N>,
    markers: [Marker<T>; 3],
    com_m: Vector3<T>,
    gravity_mps2: Vector3<T>,
}

impl<T: RealField + Copy> Kr270<T> {
    /// The robot, the layout, the tool (markers and load centre of mass,
    /// `robcal::kr270`) and gravity. Not inlined: its temporaries stay out
    /// of the caller's stack frame.
    #[inline(never)]
    pub fn new() -> Result<Self, Error> {
        let chain = chain()?;
        let layout = layout(&chain)?;
        let v = |a: [f64; 3]| Vector3::new(c(a[0]), c(a[1]), c(a[2]));
        let markers = core::array::from_fn(|i| Marker {
            index: i as u8,
            xyz_m: v(robcal_paper::kr270::MARKERS_M[i]),
        });
        Ok(Self {
            chain,
            layout,
            markers,
            com_m: v(robcal_paper::kr270::LOAD_COM_M),
            gravity_mps2: v([0.0, 0.0, -9.80665]),
        })
    }

    /// The layout.
    pub fn layout(&self) -> &Layout<N> {
        &self.layout
    }

    /// Rows `B` (eq. 3) of the three markers at configuration `g` under its
    /// load: one forward kinematics, one set of joint torques.
    pub fn config_blocks(&self, g: usize) -> Result<[SMatrix<T, 3, N>; 3], Error> {
        let q = q_rad::<T>(g);
        let frames = self.chain.frames(&q)?;
        let load = PointLoad {
            mass_kg: c::<T>(f64::from(LOAD_DKG[g]) * 0.1),
            com_m: self.com_m,
            gravity_mps2: self.gravity_mps2,
        };
        let mut tau = [T::zero(); J];
        let wrench = load.wrench(&frames);
        joint_torques(&frames, &wrench, &mut tau)?;
        let mut blocks = [SMatrix::zeros(); 3];
        for (b, m) in blocks.iter_mut().zip(&self.markers) {
            let point = frames.point_m(&m.xyz_m);
            let sample = Sample::deflection(&frames, point, m.index, &tau, Some(wrench));
            self.layout.fill(&sample, b)?;
        }
        Ok(blocks)
    }

    /// Streams every deflection of the table, in table order, to `f` as
    /// (group, `B`, `Δp`). The rows of a configuration are computed once per
    /// run of consecutive deflections of that configuration (the table is
    /// sorted by configuration, so once per pass).
    pub fn stream(
        &self,
        mut f: impl FnMut(usize, &SMatrix<T, 3, N>, &Vector3<T>) -> Result<(), Error>,
    ) -> Result<(), Error> {
        let mut cached = usize::MAX;
        let mut blocks = [SMatrix::zeros(); 3];
        for d in deflections() {
            let g = usize::from(d.config);
            if g != cached {
                blocks = self.config_blocks(g)?;
                cached = g;
            }
            let b = blocks.get(usize::from(d.marker)).ok_or(Error::OutOfRange {
                what: "marker",
                index: usize::from(d.marker),
                len: 3,
            })?;
            f(g, b, &dp_m(&d))?;
        }
        Ok(())
    }
}

impl<T: RealField + Copy> Reweightable<T, Dn> for Kr270<T> {
    fn group_count(&self) -> usize {
        G
    }

    /// One pass over the table: every deflection is one [`Block`] with the
    /// weight (and σ) of its configuration and axis, streamed into a fresh
    /// accumulator.
    fn weighted(
        &self,
        weights: &[Vector3<T>],
        noise: Option<Noise<'_, T>>,
    ) -> Result<Accumulator<T, Dn>, Error> {
        if weights.len() != G || noise.is_some_and(|n| !n.fits(G)) {
            return Err(Error::Mismatch {
                what: "one weight (and sigma) per group",
            });
        }
        let mut acc = Accumulator::new();
        self.stream(|g, b, dp| {
            let mut block = Block::new(*b, *dp).with_weights(weights[g]);
            if let Some(n) = noise {
                block = block.with_sigma(n.sigma(g, &weights[g]));
            }
            acc.update(&block)
        })?;
        Ok(acc)
    }

    /// One pass over the table: the residuals `Δp − B x` directly (no
    /// difference of large sums) and each row's leverage `w² bᵀ Λ⁻¹ b`; σ
    /// per configuration and axis with its own degrees of freedom, as
    /// [`robcal::GroupedStats::residual_sigma_into`].
    fn residual_sigma_into(
        &self,
        fit: &Solution<T, Dn>,
        weights: &[Vector3<T>],
        sigma: &mut [Vector3<T>],
        dof: &mut [Vector3<T>],
    ) -> Result<(), Error> {
        if sigma.len() != G || dof.len() != G || weights.len() != G {
            return Err(Error::Mismatch {
                what: "one sigma and one weight per group",
            });
        }
        let mut rss = [Vector3::<T>::zeros(); G];
        let mut h = [Vector3::<T>::zeros(); G];
        let mut rows = [0usize; G];
        self.stream(|g, b, dp| {
            let r = dp - b * fit.x;
            rss[g] += r.component_mul(&r);
            for a in 0..3 {
                h[g][a] += leverage(&fit.lambda_inv, |k| b[(a, k)], weights[g][a]);
            }
            rows[g] += 1;
            Ok(())
        })?;
        for g in 0..G {
            sigma[g] = Vector3::from_fn(|a, _| group_sigma(rss[g][a], rows[g], h[g][a]));
            dof[g] = Vector3::from_fn(|a, _| group_dof(rows[g], h[g][a]));
        }
        Ok(())
    }
}

/// History kept by the firmware's fit (OLS start + iterations; the fit goes
/// on when it is full).
#[cfg_attr(not(target_os = "none"), allow(dead_code))]
pub const HISTORY: usize = 10;

/// The firmware's settings: eq. 14 with σ0 and λ of `setup.toml`, stop at a
/// change below 1e-3 σ (as the host), at most 100 iterations.
pub fn settings<T: RealField + Copy>() -> Result<IrlsSettings<T>, Error> {
    Ok(IrlsSettings::new(RobustWeight::new(
        c(SIGMA0_M),
        c(LAMBDA),
    )?))
}

/// Check 1: every estimate within this many of the host's standard
/// deviations of the host's f64 estimate (from the CSV). Measured: at most
/// 1.9e-3 σ (k22), the same on the Cortex-M4F, the Cortex-M3 and x86-64 in
/// f32: f32 rounding of the rows (forward kinematics in f32, relative
/// ~1e-7), of the accumulated sums and of the solve, against standard
/// deviations of 2e-3 … 1e-2 of the estimates; the table's quantisation
/// adds 2e-5 σ (`QUANTISATION_SIGMAS`). The bound leaves a margin of 5×.
pub const TOL_X_SIGMAS: f64 = 0.01;
/// Check 2: every standard deviation within this relative distance of the
/// host's (measured: at most 2.2e-5, k3).
pub const TOL_SD_REL: f64 = 1e-3;

/// The outcome of the checks for one parameter.
#[derive(Clone, Copy, Debug)]
pub struct ParamCheck {
    /// `x̂` on this target \[µrad/(N·m)\].
    pub x: f64,
    /// Its standard deviation.
    pub sd: f64,
    /// `|x̂ − x̂_host| / σ_host`.
    pub x_sigmas: f64,
    /// `|σ / σ_host − 1|`.
    pub sd_rel: f64,
}

/// What the checks need of a fit (small: the firmware keeps only this
/// once the fit is done).
#[derive(Clone, Copy, Debug)]
pub struct Estimate<T: RealField + Copy> {
    /// `X̂` \[µrad/(N·m)\].
    pub x: SVector<T, N>,
    /// Its standard deviations (sandwich, eq. 11).
    pub sd: SVector<T, N>,
    /// WLS iterations after the OLS start.
    pub iterations: usize,
    /// Whether the iteration converged.
    pub converged: bool,
}

impl<T: RealField + Copy> From<&Fit<T, Dn>> for Estimate<T> {
    fn from(fit: &Fit<T, Dn>) -> Self {
        Self {
            x: fit.solution.x,
            sd: fit.std(),
            iterations: fit.iterations,
            converged: fit.converged,
        }
    }
}

/// Compares an estimate with the host's (`expected` is normally
/// [`HOST_X`]): converged, and checks 1 and 2 for every parameter.
pub fn check<T: RealField + Copy>(
    est: &Estimate<T>,
    expected: &[f64; N],
) -> ([ParamCheck; N], bool) {
    let params: [ParamCheck; N] = core::array::from_fn(|i| {
        let x: f64 = to_f64(est.x[i]);
        let s: f64 = to_f64(est.sd[i]);
        ParamCheck {
            x,
            sd: s,
            x_sigmas: libm::fabs(x - expected[i]) / HOST_SD[i],
            sd_rel: libm::fabs(s / HOST_SD[i] - 1.0),
        }
    });
    let pass = est.converged
        && params
            .iter()
            .all(|p| p.x_sigmas <= TOL_X_SIGMAS && p.sd_rel <= TOL_SD_REL);
    (params, pass)
}

fn to_f64<T: RealField + Copy>(x: T) -> f64 {
    // `RealField` has no lossless cast to f64; every scalar robcal runs on
    // (f32, f64) converts exactly through `SubsetOf`.
    nalgebra::try_convert::<T, f64>(x).unwrap_or(f64::NAN)
}

/// The same rows in grouped sufficient statistics (host comparison: the
/// streaming source and [`robcal::GroupedStats`] must agree to rounding).
#[cfg(not(target_os = "none"))]
pub fn grouped<T: RealField + Copy>(
    source: &Kr270<T>,
) -> Result<robcal::GroupedStats<T, Dn, G>, Error> {
    let mut stats = robcal::GroupedStats::new();
    source.stream(|g, b, dp| stats.update(g as i32, b, dp))?;
    Ok(stats)
}

/// The configuration whose taught point the device compensates for (the
/// paper's configuration 1).
pub const COMPENSATE_CONFIG: usize = 0;
/// The payload of the compensation \[kg\] (at the tool's centre of mass).
pub const COMPENSATE_LOAD_KG: f64 = 270.0;

/// The device's compensation problem (issue 14): the point marker 1 has
/// at configuration [`COMPENSATE_CONFIG`] without load (taught) is the
/// target; with [`COMPENSATE_LOAD_KG`] on the tool the robot sags; the
/// compensated command puts the marker back on it. The joint law: A2's
/// compliance of the configuration's q2 group (k21…k25), then k3…k6, of a
/// calibrated estimate.
pub struct Compensation<T: RealField + Copy> {
    chain: Chain<T, J>,
    tool: Vector3<T>,
    /// The target \[m, base frame\].
    pub target: Vector3<T>,
    /// The taught command \[rad\].
    pub q: [T; J],
    loading: robcal::robot::Loading<T>,
    law: robcal::robot::Compliances<T, J>,
}

impl<T: RealField + Copy> Compensation<T> {
    /// The problem for the estimate `x` (µrad/(N·m)).
    ///
    /// # Errors
    /// From the chain and the forward kinematics.
    #[inline(never)]
    pub fn new(x: &SVector<T, N>) -> Result<Self, Error> {
        let chain = chain::<T>()?;
        let v = |a: [f64; 3]| Vector3::new(c(a[0]), c(a[1]), c(a[2]));
        let tool = v(robcal_paper::kr270::MARKERS_M[0]);
        let g = COMPENSATE_CONFIG;
        let q = q_rad::<T>(g);
        let target = chain.frames(&q)?.point_m(&tool);
        let group = robcal_paper::kr270::q2_group(robcal_paper::kr270::CONFIGURATIONS_DEG[g][1])
            .ok_or(Error::Mismatch {
                what: "configuration not in a q2 group",
            })?;
        let micro: T = c(1e-6);
        Ok(Self {
            chain,
            tool,
            target,
            q,
            loading: robcal::robot::Loading {
                load: Some(PointLoad {
                    mass_kg: c(COMPENSATE_LOAD_KG),
                    com_m: v(robcal_paper::kr270::LOAD_COM_M),
                    gravity_mps2: v([0.0, 0.0, -9.80665]),
                }),
                own_weight_mps2: None,
            },
            law: robcal::robot::Compliances {
                k: [T::zero(), x[group], x[5], x[6], x[7], x[8]].map(|k| k * micro),
            },
        })
    }

    /// The compensated command, from the taught one.
    ///
    /// # Errors
    /// From [`robcal::robot::compensate`].
    #[inline(never)]
    pub fn solve(
        &self,
        settings: &robcal::robot::CompensateSettings<T>,
    ) -> Result<robcal::robot::Compensation<T, J>, Error> {
        let law = self.law;
        robcal::robot::compensate(
            &self.chain,
            &self.tool,
            &self.target,
            &self.q,
            &self.loading,
            |_| law,
            settings,
        )
    }

    /// How far the loaded robot commanded to `q` misses the target \[m\],
    /// by its own equilibrium solve.
    ///
    /// # Errors
    /// From the equilibrium.
    #[inline(never)]
    pub fn miss_m(
        &self,
        q: &[T],
        settings: &robcal::robot::EquilibriumSettings<T>,
    ) -> Result<T, Error> {
        let eq = robcal::robot::equilibrium(&self.chain, q, q, &self.loading, &self.law, settings)?;
        Ok((eq.frames.point_m(&self.tool) - self.target).norm())
    }
}

/// The compensation settings of the device (f32): stop within 2 µm, the
/// equilibrium to 1e-6 rad (f32 rounds a joint value at ~2e-7 rad).
pub fn compensate_settings<T: RealField + Copy>() -> robcal::robot::CompensateSettings<T> {
    robcal::robot::CompensateSettings {
        tolerance_m: c(2e-6),
        max_iterations: 10,
        max_step: c(0.1),
        equilibrium: robcal::robot::EquilibriumSettings {
            tolerance: c(1e-6),
            max_iterations: 20,
        },
    }
}

/// The device's compensation must end within [`compensate_settings`]'
/// tolerance, confirmed by a separate equilibrium at the command, in at most
/// this many steps.
pub const COMPENSATE_MAX_STEPS: usize = 5;
