//! The calibrated robot handed on: the URDF (`--output DIR`, [`export`]),
//! the `predictor` section of `model.json` ([`model_file`]), the model
//! applied to joint values and payloads and its compensation ([`predict`]),
//! its error on another measurement file ([`validate`]), and its recheck on
//! a new recording ([`check`]).

pub mod check;
pub mod export;
pub mod model_file;
pub mod predict;
pub mod validate;
