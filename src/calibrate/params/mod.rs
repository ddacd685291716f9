//! What a parameter is called, and the model's value the rows are
//! evaluated at: the contract's names ([`names`]), the current geometry of
//! Gauss–Newton ([`geometry`]), and the joint law with its deflection model
//! ([`linearisation`]).

pub mod geometry;
pub mod linearisation;
pub mod names;
