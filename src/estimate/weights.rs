//! Weighting coefficients (section 4 of the paper).
//!
//! - eq. 12: `w = a / σ`, the minimum-variance weight for a linear model
//!   (with `a` a unit-fixing scale);
//! - eq. 14: `w = σ0 / (σ0 + λσ)`, the robust weight: σ0 is the claimed
//!   precision of the measuring system (10 µm for the paper's laser
//!   tracker), which also keeps the weight finite as σ → 0, and λ tunes how
//!   much the estimated σ counts.
//!
//! σ and σ0 must be in the same unit (the crate uses metres in the rows and
//! micrometres in the settings; convert before calling).

use nalgebra::RealField;

use crate::error::Error;

/// Settings of the robust weight, eq. 14.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RobustWeight<T> {
    /// σ0: claimed precision of the measuring system, in the unit of σ.
    pub sigma0: T,
    /// λ ≥ 0: tuning factor of eq. 14 (λ = 0 gives equal weights, OLS).
    pub lambda: T,
}

impl<T: RealField + Copy> RobustWeight<T> {
    /// Checked settings: `σ0 > 0`, `λ ≥ 0`, both finite.
    ///
    /// # Errors
    /// [`Error::NonFinite`] or [`Error::NotPositive`].
    pub fn new(sigma0: T, lambda: T) -> Result<Self, Error> {
        if !sigma0.is_finite() {
            return Err(Error::NonFinite { what: "sigma0" });
        }
        if !lambda.is_finite() {
            return Err(Error::NonFinite { what: "lambda" });
        }
        if sigma0 <= T::zero() {
            return Err(Error::NotPositive { what: "sigma0" });
        }
        if lambda < T::zero() {
            return Err(Error::NotPositive { what: "lambda" });
        }
        Ok(Self { sigma0, lambda })
    }

    /// `w = σ0 / (σ0 + λσ)` (eq. 14), in (0, 1].
    ///
    /// # Errors
    /// [`Error::NonFinite`] for a non-finite σ, [`Error::NotPositive`] for σ < 0
    /// (σ = 0 is allowed: a group with no scatter gets weight 1).
    ///
    /// ```
    /// # use robcal::estimate::RobustWeight;
    /// let rw = RobustWeight::new(10.0_f64, 1.0).unwrap();
    /// // σ = σ0: half weight.
    /// assert_eq!(rw.weight(10.0).unwrap(), 0.5);
    /// assert_eq!(rw.weight(0.0).unwrap(), 1.0);
    /// ```
    pub fn weight(&self, sigma: T) -> Result<T, Error> {
        self.check_sigma(sigma)?;
        Ok(self.sigma0 / (self.sigma0 + self.lambda * sigma))
    }

    /// The errors of [`RobustWeight::weight`] for `sigma`, without the
    /// weight.
    pub(crate) fn check_sigma(&self, sigma: T) -> Result<(), Error> {
        if !sigma.is_finite() {
            return Err(Error::NonFinite { what: "sigma" });
        }
        if sigma < T::zero() {
            return Err(Error::NotPositive { what: "sigma" });
        }
        Ok(())
    }
}

/// `w = a / σ` (eq. 12).
///
/// # Errors
/// [`Error::NonFinite`] or [`Error::NotPositive`] when `a` or `σ` is not a
/// positive finite number.
///
/// ```
/// assert_eq!(robcal::estimate::inverse_sigma(2.0_f64, 4.0).unwrap(), 0.5);
/// ```
pub fn inverse_sigma<T: RealField + Copy>(a: T, sigma: T) -> Result<T, Error> {
    if !a.is_finite() || !sigma.is_finite() {
        return Err(Error::NonFinite { what: "sigma" });
    }
    if a <= T::zero() || sigma <= T::zero() {
        return Err(Error::NotPositive { what: "sigma" });
    }
    Ok(a / sigma)
}
