//! What a parameter is called, and the model's value the rows are
//! evaluated at: the contract's names ([`names`]), the current geometry of
//! Gauss–Newton ([`geometry`]), the joint law with its deflection model
//! ([`linearisation`]), and the columns of the links' masses, which act
//! through that law ([`masses`]).

pub mod geometry;
pub mod linearisation;
pub mod masses;
pub mod names;
