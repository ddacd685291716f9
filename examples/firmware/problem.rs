//! The synthetic calibration problem the firmware solves, and its checks.
//! Shared by the bare-metal build and the host build of the example, so the
//! host runs exactly the arithmetic the device runs.
//!
//! `Δp = B X_true + ε` (eq. 4) with `N = 9` parameters: `B` uniform in
//! `[-1, 1]` (a ~1 m arm: metres per metre or per radian), `X_true` of a few
//! millimetres / milliradians, and `ε` uniform with standard deviation
//! `σ = 10 µm` (the paper's laser tracker). Rows come from the project's
//! seeded generator (`robcal_paper::rng::SplitMix64`), so every run on every
//! target sees the same numbers and the checks below are deterministic;
//! nothing is stored, every block is generated, streamed in and dropped.

use nalgebra::{Const, SMatrix, SVector, Vector3};
use robcal::{Accumulator, Block, Error, Solution};

/// Parameters.
pub const N: usize = 9;
/// The parameters as a nalgebra dimension.
pub type Dn = Const<N>;
/// Measurement blocks (3 rows each) streamed in: 180 equations.
pub const BLOCKS: usize = 60;
/// Seed of the row generator.
pub const SEED: u32 = 0x5EED_2024;
/// `X_true` [m or rad].
pub const X_TRUE: [f64; N] = [
    1.5e-3, -0.8e-3, 0.3e-3, 2.0e-3, -1.2e-3, 0.5e-3, -0.25e-3, 0.9e-3, -1.7e-3,
];
/// √3: uniform on `[-√3σ, √3σ]` has standard deviation σ.
const SQRT_3: f64 = 1.732_050_807_568_877_2;
/// σ of the measurement noise [m] (10 µm).
pub const SIGMA: f64 = 10e-6;

/// Check 1: every f64 estimate within this many of its standard deviations
/// (sandwich covariance, eq. 11, with the known σ) of `X_true`. With 9
/// parameters, 4σ is a bound a correct estimator meets with overwhelming
/// probability; the data are fixed, so the outcome is too.
pub const TOL_SIGMAS: f64 = 4.0;
/// Check 2: the f32 estimate within this fraction of a standard deviation of
/// the f64 one, i.e. f32 rounding moves the estimate by a negligible part of
/// its statistical uncertainty. Measured: at most 3.7e-4 (the same on the
/// host and both Cortex-M targets); the bound leaves a 27× margin.
pub const TOL_F32_SIGMAS: f64 = 0.01;
/// Check 3: `σ̂ = √(RSS / (m − n))` (eq. 7) within this relative distance of
/// the true σ (for 171 degrees of freedom the spread of σ̂/σ is ~5 %).
pub const TOL_SIGMA_HAT: f64 = 0.2;

/// The generator of the synthetic problem.
pub struct Gen(robcal_paper::rng::SplitMix64);

impl Gen {
    pub fn new(seed: u32) -> Self {
        Self(robcal_paper::rng::SplitMix64::new(u64::from(seed)))
    }

    /// Uniform in `(-1, 1)`.
    fn uniform(&mut self) -> f64 {
        2.0 * self.0.uniform() - 1.0
    }

    /// The next measurement: three rows of `B`, `Δp = B X_true + ε`, unit
    /// weights and the known σ per row.
    pub fn block(&mut self) -> Block<f64, Dn> {
        let b = SMatrix::<f64, 3, N>::from_fn(|_, _| self.uniform());
        let noise = Vector3::from_fn(|_, _| self.uniform() * SIGMA * SQRT_3);
        let dp = b * SVector::<f64, N>::from(X_TRUE) + noise;
        Block::new(b, dp).with_sigma(Vector3::repeat(SIGMA))
    }
}

/// The same block in single precision.
pub fn to_f32(b: &Block<f64, Dn>) -> Block<f32, Dn> {
    Block {
        b: b.b.cast(),
        dp: b.dp.cast(),
        w: b.w.cast(),
        sigma: b.sigma.map(|s| s.cast()),
        rows: b.rows,
    }
}

/// Streams the `BLOCKS` measurements into an f32 and an f64 accumulator;
/// `first` sees the first block (for logging).
// Not inlined: its temporaries get their own stack frame, which is gone
// before the next step (the firmware's stack budget).
#[inline(never)]
pub fn stream(
    acc32: &mut Accumulator<f32, Dn>,
    acc64: &mut Accumulator<f64, Dn>,
    mut first: impl FnMut(&Block<f32, Dn>),
) -> Result<(), Error> {
    let mut gen = Gen::new(SEED);
    for k in 0..BLOCKS {
        let b64 = gen.block();
        let b32 = to_f32(&b64);
        if k == 0 {
            first(&b32);
        }
        acc32.update(&b32)?;
        acc64.update(&b64)?;
    }
    Ok(())
}

/// A non-finite block must be refused with `Error::NonFinite` and leave the
/// accumulator exactly as it was. Returns the error seen, or `None` when
/// the update was (wrongly) accepted or changed the state.
// Not inlined: its temporaries get their own stack frame, which is gone
// before the next step (the firmware's stack budget).
#[inline(never)]
pub fn rejects_bad_block(acc: &mut Accumulator<f32, Dn>) -> Option<Error> {
    let before = acc.clone();
    let mut bad = to_f32(&Gen::new(SEED).block());
    bad.dp[1] = f32::NAN;
    match acc.update(&bad) {
        Err(e @ Error::NonFinite { .. }) if *acc == before => Some(e),
        _ => None,
    }
}

/// The outcome of the checks for one parameter.
#[derive(Clone, Copy)]
pub struct ParamCheck {
    /// `x̂` (f64) [m or rad].
    pub x64: f64,
    /// `x̂` (f32).
    pub x32: f32,
    /// `σ(x̂)` from the sandwich covariance (eq. 11).
    pub sd: f64,
    /// `|x̂₆₄ − x_true| / σ`.
    pub err_sigmas: f64,
    /// `|x̂₃₂ − x̂₆₄| / σ`.
    pub f32_sigmas: f64,
}

/// All checks.
pub struct Verdict {
    pub params: [ParamCheck; N],
    /// `σ̂ / σ` (eq. 7).
    pub sigma_hat_ratio: f64,
    pub pass: bool,
}

/// Compares both solutions with `x_true` (normally [`X_TRUE`]); `acc64`
/// holds the sandwich middle term `M` (eq. 11) for the standard deviations.
// Not inlined: its temporaries get their own stack frame, which is gone
// before the next step (the firmware's stack budget).
#[inline(never)]
pub fn check(
    s32: &Solution<f32, Dn>,
    s64: &Solution<f64, Dn>,
    acc64: &Accumulator<f64, Dn>,
    x_true: &[f64; N],
) -> Verdict {
    let sd = robcal::estimate::std_devs(&s64.cov_sandwich(&acc64.middle()));
    let params = core::array::from_fn(|i| {
        let x64 = s64.x[i];
        let x32 = s32.x[i];
        ParamCheck {
            x64,
            x32,
            sd: sd[i],
            err_sigmas: (x64 - x_true[i]).abs() / sd[i],
            f32_sigmas: (f64::from(x32) - x64).abs() / sd[i],
        }
    });
    let sigma_hat_ratio = libm::sqrt(s64.sigma2_hat()) / SIGMA;
    let pass = params
        .iter()
        .all(|p| p.err_sigmas <= TOL_SIGMAS && p.f32_sigmas <= TOL_F32_SIGMAS)
        && (sigma_hat_ratio - 1.0).abs() <= TOL_SIGMA_HAT;
    Verdict {
        params,
        sigma_hat_ratio,
        pass,
    }
}
