//! Errors of the core. Every fallible call returns one of these and leaves
//! the state it was called on exactly as it was.

use core::fmt;

/// What went wrong. Variants carry `&'static str` context and indices, never
/// owned data, so the type is `Copy` and works without an allocator.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Error {
    /// An input value is NaN or ±∞. `what` names the input.
    NonFinite {
        /// Which input (e.g. `"row"`, `"dp"`, `"weight"`, `"sigma"`).
        what: &'static str,
    },
    /// A value that must be strictly positive is not (σ ≤ 0, σ0 ≤ 0, λ < 0, …).
    NotPositive {
        /// Which input.
        what: &'static str,
    },
    /// A fixed-capacity container is full (groups, history, joints).
    CapacityExceeded {
        /// Which container.
        what: &'static str,
        /// Its capacity.
        capacity: usize,
    },
    /// Fewer equations than active parameters.
    TooFewEquations {
        /// Equations (weighted rows) accumulated.
        equations: usize,
        /// Parameters to estimate.
        parameters: usize,
    },
    /// The information matrix is singular or too ill-conditioned on the
    /// active parameters: `column` is the first parameter (index in the
    /// layout) that is a linear combination of the ones before it.
    NotIdentifiable {
        /// Index of the parameter that cannot be identified.
        column: usize,
        /// Reciprocal condition estimate seen (ratio of the smallest to the
        /// largest pivot of the column-scaled information matrix).
        rcond: f64,
    },
    /// An index is outside the valid range (group, axis, parameter, joint).
    OutOfRange {
        /// Which index.
        what: &'static str,
        /// The index given.
        index: usize,
        /// The exclusive upper bound.
        len: usize,
    },
    /// Two objects that must agree in shape or settings do not.
    Mismatch {
        /// What disagrees.
        what: &'static str,
    },
    /// An iteration did not settle within its maximum number of iterations.
    NotConverged {
        /// Iterations run.
        iterations: usize,
    },
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Error::NonFinite { what } => write!(f, "non-finite value in {what}"),
            Error::NotPositive { what } => write!(f, "{what} must be positive"),
            Error::CapacityExceeded { what, capacity } => {
                write!(f, "{what} is full (capacity {capacity})")
            }
            Error::TooFewEquations {
                equations,
                parameters,
            } => write!(
                f,
                "too few equations: {equations} for {parameters} parameters"
            ),
            Error::NotIdentifiable { column, rcond } => write!(
                f,
                "parameter {column} is not identifiable (reciprocal condition {rcond:.3e})"
            ),
            Error::OutOfRange { what, index, len } => {
                write!(f, "{what} index {index} out of range 0..{len}")
            }
            Error::Mismatch { what } => write!(f, "mismatch: {what}"),
            Error::NotConverged { iterations } => {
                write!(f, "did not converge in {iterations} iterations")
            }
        }
    }
}

impl core::error::Error for Error {}
