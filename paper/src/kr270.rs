//! The paper's KR-270 experiment (section 5): its published numbers, and
//! the choices robcal makes where the paper is silent.
//!
//! Everything here is data, shared by the data generator
//! (`examples/generate_kr270.rs`), the main job (`examples/kr270.rs`), the
//! host tests and the firmware (`examples/firmware`).
//!
//! [`layout`] builds the paper's 9-parameter model for any chain with the
//! KR-270's six joints.
//!
//! Units: angles in degrees as printed in the paper; σ in µm; compliance in
//! µrad/(N·m). The paper prints compliance in "rad/N×µm", but its values
//! (0.25–3.5) only make physical sense as µrad/(N·m) = 1e-6 rad/(N·m):
//! with ~2.6 kN on a 2.7 m arm they give deflections of 2–11 mm.

use nalgebra::RealField;
use robcal::model::{angle_urad, Layout, Param};
use robcal::{Chain, Error};

/// Number of configurations (Table 2).
pub const CONFIGS: usize = 15;
/// Repetitions per configuration (section 5).
pub const REPS: usize = 6;
/// Markers on the calibration tool (section 5).
pub const MARKERS: usize = 3;
/// Parameters identified: k21…k25, k3, k4, k5, k6.
pub const PARAMS: usize = 9;

/// Table 2: joint angles q1…q6 \[deg\] of the 15 measurement configurations.
/// The paper prints q2 once per group of three; it is repeated here.
pub const CONFIGURATIONS_DEG: [[f64; 6]; CONFIGS] = [
    [79.20, -0.01, -5.57, 51.00, -97.52, -91.67],
    [63.00, -0.01, -12.22, -56.49, 41.42, 150.55],
    [63.00, -0.01, -47.98, -70.04, -61.55, 177.16],
    [95.00, -25.24, 33.00, 129.69, -98.10, 90.57],
    [95.00, -25.24, -107.01, 109.95, -61.19, 174.21],
    [105.00, -25.24, 14.30, 55.21, 41.26, -152.97],
    [56.60, -56.9, 44.54, -55.11, 41.90, 152.06],
    [56.60, -56.9, 64.73, -129.65, -98.260, -90.55],
    [144.80, -56.9, 104.49, -69.41, 61.67, -6.33],
    [-41.00, -99.85, -91.68, 55.12, 41.53, -152.48],
    [-143.00, -99.85, -32.64, 110.31, -61.47, -6.29],
    [-143.00, -99.85, -72.01, 129.65, -98.09, 90.82],
    [133.00, -140.0, 147.68, 129.64, -97.90, 90.99],
    [-60.00, -140.0, 7.59, -110.09, -61.36, -174.09],
    [-60.00, -140.0, -52.00, -124.89, -41.62, 27.78],
];

/// The five angles of joint 2 \[deg\] that carry their own compliance
/// k21…k25 (the gravity compensator, section 5).
pub const Q2_GROUPS_DEG: [f64; 5] = [-0.01, -25.24, -56.9, -99.85, -140.0];

/// Table 1: σ of the deflection measurement errors per configuration and
/// base-frame axis (x, y, z), "mean" column \[µm\].
pub const SIGMA_UM: [[f64; 3]; CONFIGS] = [
    [150.0, 64.0, 33.0],
    [57.0, 86.0, 118.0],
    [97.0, 70.0, 44.0],
    [28.0, 19.0, 35.0],
    [72.0, 48.0, 17.0],
    [153.0, 46.0, 22.0],
    [112.0, 66.0, 53.0],
    [74.0, 55.0, 59.0],
    [80.0, 63.0, 102.0],
    [69.0, 73.0, 79.0],
    [80.0, 36.0, 26.0],
    [53.0, 39.0, 29.0],
    [26.0, 29.0, 29.0],
    [88.0, 121.0, 42.0],
    [90.0, 52.0, 50.0],
];

/// Parameter names in the order of the layout, as the data contract names
/// them in JSON (`k_a2@<angle>` for the compensated joint).
pub const PARAM_NAMES: [&str; PARAMS] = [
    "k_a2@-0.01",
    "k_a2@-25.24",
    "k_a2@-56.9",
    "k_a2@-99.85",
    "k_a2@-140",
    "k_a3",
    "k_a4",
    "k_a5",
    "k_a6",
];

/// The paper's symbols for the same parameters.
pub const PAPER_SYMBOLS: [&str; PARAMS] =
    ["k21", "k22", "k23", "k24", "k25", "k3", "k4", "k5", "k6"];

/// Table 3, WLS column (identical for λ = 0.5, 1, 2) \[µrad/(N·m)\]: the truth
/// of the reconstructed data set.
pub const WLS_VALUE: [f64; PARAMS] = [
    0.287, 0.277, 0.302, 0.293, 0.246, 0.416, 2.786, 3.483, 2.074,
];
/// Table 3, WLS ± 3σ \[µrad/(N·m)\].
pub const WLS_CI3: [f64; PARAMS] = [
    0.0003, 0.0004, 0.0005, 0.0010, 0.0007, 0.0011, 0.0071, 0.0120, 0.0267,
];
/// Table 3, OLS value \[µrad/(N·m)\].
pub const OLS_VALUE: [f64; PARAMS] = [
    0.297, 0.287, 0.315, 0.302, 0.251, 0.396, 3.017, 3.294, 2.248,
];
/// Table 3, OLS ± 3σ \[µrad/(N·m)\].
pub const OLS_CI3: [f64; PARAMS] = [
    0.010, 0.012, 0.018, 0.032, 0.020, 0.031, 0.248, 0.506, 0.725,
];
/// Table 4, CI of OLS as % of the value.
pub const CI_OLS_PERCENT: [f64; PARAMS] = [3.4, 4.2, 5.9, 10.7, 7.8, 7.8, 8.2, 15.3, 32.2];
/// Table 4, CI of (iterative) WLS as % of the value.
pub const CI_WLS_PERCENT: [f64; PARAMS] = [0.09, 0.13, 0.18, 0.33, 0.27, 0.26, 0.25, 0.34, 1.28];
/// Table 4, σ_OLS / σ_WLS.
pub const SIGMA_RATIO: [f64; PARAMS] = [40.5, 33.2, 33.9, 33.1, 30.1, 28.8, 35.1, 42.0, 27.2];

/// Our choice (the paper does not publish its tool): load centre of mass in
/// `tool0` \[m\]. It must be off the A6 axis, or k6 is unidentifiable.
pub const LOAD_COM_M: [f64; 3] = [0.25, 0.0, 0.30];
/// Our choice: three markers on a 0.30 m circle at z = 0.20 m in `tool0`,
/// at 90°, 210° and 330° \[m\].
pub const MARKERS_M: [[f64; 3]; MARKERS] = [
    [0.0, 0.30, 0.20],
    [-0.259_807_621_135_331_5, -0.15, 0.20],
    [0.259_807_621_135_331_5, -0.15, 0.20],
];
/// Range of the load per configuration \[kg\] (section 5: 250–280 kg).
pub const LOAD_KG_RANGE: (f64, f64) = (250.0, 280.0);
/// The tracker's claimed precision σ0 \[µm\] (section 4).
pub const SIGMA0_UM: f64 = 10.0;
/// The λ values of Table 3.
pub const LAMBDAS: [f64; 3] = [0.5, 1.0, 2.0];

/// Index of the q2 group (0…4) of a joint-2 angle \[deg\], matching
/// [`Q2_GROUPS_DEG`] within 1e-6 deg.
pub fn q2_group(q2_deg: f64) -> Option<usize> {
    Q2_GROUPS_DEG
        .iter()
        .position(|g| libm::fabs(g - q2_deg) < 1e-6)
}

/// The paper's parameter layout, in [`PARAM_NAMES`] order: k21…k25 (the
/// compliance of A2, one per q2 group of Table 2 — the gravity compensator,
/// section 5), then k3…k6. Columns in µrad/(N·m). The setup
/// `data/kr270/setup.toml` declares the same model to `robcal calibrate`.
///
/// # Errors
/// From [`Layout::push`]: the chain has fewer than six joints.
pub fn layout<T: RealField + Copy, const J: usize>(
    chain: &Chain<T, J>,
) -> Result<Layout<PARAMS>, Error> {
    let mut l = Layout::new();
    for q2 in Q2_GROUPS_DEG {
        l.push(
            chain,
            Param::ComplianceAt {
                joint: 1,
                angle_urad: angle_urad(q2.to_radians()),
            },
        )?;
    }
    for joint in 2..6 {
        l.push(chain, Param::Compliance { joint })?;
    }
    Ok(l)
}
