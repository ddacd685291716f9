//! The units of the measurement CSV's columns (`[units]` of the setup)
//! and the largest magnitudes a quantity may have in any unit: what the
//! setup, the cells, the URDF and the measurements share.

use serde::{Deserialize, Serialize};

/// Unit of the CSV's revolute joint columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AngleUnit {
    /// Degrees.
    Deg,
    /// Radians (default).
    #[default]
    Rad,
}

/// Unit of the CSV's `x`, `y`, `z` and prismatic joint columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LengthUnit {
    /// Millimetres.
    Mm,
    /// Metres (default).
    #[default]
    M,
}

/// `[units]`: units of the CSV columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Units {
    /// Revolute and continuous joint columns.
    #[serde(default)]
    pub angle: AngleUnit,
    /// `x`, `y`, `z` and prismatic joint columns.
    #[serde(default)]
    pub length: LengthUnit,
}

impl Units {
    /// SI units: rad and m.
    pub const SI: Units = Units {
        angle: AngleUnit::Rad,
        length: LengthUnit::M,
    };
}

/// Largest `load_kg` \[kg\]: 100 t, beyond any robot's payload.
pub const MAX_LOAD_KG: f64 = 1e5;

/// Largest position \[m\] in any unit: 10 km, beyond any instrument.
pub const MAX_POSITION_M: f64 = 1e4;

/// Largest standard deviation of a measured orientation \[rad\]
/// (`srx, sry, srz`): a radian, beyond any instrument that measures one.
pub const MAX_SIGMA_RAD: f64 = 1.0;

/// Largest `|t|` \[s\]: 10¹⁰ s (317 years; Unix time in seconds is
/// 1.8·10⁹). Larger is another unit (ms since 1970 is 1.8·10¹²) or an
/// overflow, and differences of such times lose the seconds.
pub const MAX_TIME_S: f64 = 1e10;

/// Lowest temperature a measurement may be taken at \[°C\]
/// (`[model] temperature_column`): below it, a cell is
/// in another unit.
pub const MIN_TEMPERATURE_C: f64 = -50.0;

/// Highest temperature a measurement may be taken at \[°C\]: above it, the
/// cell is in kelvin or °F.
pub const MAX_TEMPERATURE_C: f64 = 150.0;
