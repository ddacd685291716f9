//! The calibrated robot handed on: the URDF (`--output DIR`, [`export`]),
//! the `predictor` section of `model.json` ([`model_file`]), the model
//! applied to joint values and payloads and its compensation ([`predict`]),
//! and its error on another measurement file ([`validate`]).

pub mod export;
pub mod model_file;
pub mod predict;
pub mod validate;
