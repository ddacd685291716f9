//! The calibrated model: what a calibration hands back, enough to predict
//! the rows of another measurement file of the same job.

use crate::calibrate::params::geometry::Geometry;
use crate::calibrate::params::linearisation::Linearisation;
use crate::calibrate::params::names::Names;
use crate::calibrate::rows::DataKinds;
use crate::calibrate::settings::Policy;
use crate::model::Param;

/// The final model of a calibration: the geometry it converged to, the
/// estimate of every parameter, and how its rows were built.
#[derive(Debug, Clone)]
pub struct CalibratedModel {
    /// Names of joints, markers, bins.
    pub names: Names,
    /// The calibrated geometry (base, chain with offsets and frame errors,
    /// markers).
    pub geometry: Geometry,
    /// The model's parameters.
    pub params: Vec<Param>,
    /// Their estimate (reported units; geometric ones are the last, unapplied
    /// Gauss–Newton step).
    pub x: Vec<f64>,
    /// The estimate's joint law and deflection model (the rows of another
    /// file are evaluated at it).
    pub linearisation: Linearisation,
    /// The kinds of rows the calibration used.
    pub kinds: DataKinds,
    /// The decision constants of the run.
    pub policy: Policy,
    /// The covariance of `x` (sandwich, eq. 8 / 11), reported units.
    pub covariance: nalgebra::DMatrix<f64>,
    /// The heaviest payload of the calibration's rows \[kg\] (0 without a
    /// loaded row): the range its compliances were identified over.
    pub heaviest_payload_kg: f64,
    /// The calibration data's mean temperature \[°C\]: where the identified
    /// lengths hold, with a thermal expansion (`None` without a temperature
    /// column).
    pub temperature_ref_c: Option<f64>,
}
