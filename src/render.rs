//! What a calibration hands on, written out: the data contract's JSON
//! (`--json`, §5; `model.json`, §7.4), the HTML report and its SVG
//! figures, and the set of files `robcal calibrate --output DIR` writes.
//! The command and the Python package (`python/`) both write through
//! here, so the same report gives the same bytes in both.
//!
//! | module | what |
//! |---|---|
//! | [`json`] | the report and `model.json` as serde types; `model.json` read back into a [`Predictor`](crate::calibrate::outputs::predict::Predictor) |
//! | [`plots`] | the report's figures (plotters, SVG) |
//! | [`html`] | `report.html`: one self-contained page |
//! | [`files`] | `--output DIR`'s files: `robot.urdf`, `model.json`, `report.html`, the figures |
//!
//! Needs the `render` feature (on with `cli`); `std` only. It stands after
//! `calibrate` in the flow and only reads its results.

pub mod files;
pub mod html;
pub mod json;
pub mod plots;
