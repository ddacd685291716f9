//! The calibrated robot handed on: the URDF (`--output DIR`, [`export`]),
//! the `predictor` section of `model.json` ([`model_file`]), the model
//! applied to joint values and payloads and its compensation ([`predict`]),
//! its error on another measurement file ([`validate`]), its recheck on a
//! new recording ([`check`]), and two calibrations side by side
//! ([`compare`]).

pub mod check;
pub mod compare;
pub mod export;
pub mod model_file;
pub mod predict;
pub mod validate;
