//! The paper's KR-270 experiment as data: a user of robcal, not part of it.
//!
//! Klimchik et al., *Robust algorithm for calibration of robotic manipulator
//! model*, section 5: a KUKA KR 270 R2700 ultra loaded with 250–280 kg,
//! three markers seen by a laser tracker in 15 configurations, 6
//! repetitions each, and the compliances of A2…A6 identified by OLS, WLS and
//! iterative WLS.
//!
//! - [`kr270`]: the paper's published numbers (Tables 1–4) and the choices
//!   robcal's reconstruction makes where the paper is silent (load centre
//!   of mass, marker positions), and the paper's 9-parameter layout for the
//!   firmware;
//! - [`rng`]: the seeded generator of `data/kr270/measurements.csv`.
//!
//! `no_std`: the firmware example (`examples/firmware`) uses it too.
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod kr270;
pub mod rng;
