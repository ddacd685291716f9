//! The identification model (`no_std`): what the parameters are and how a
//! measured point depends on them — the columns of `Bᵢ = [Jᵢ Aᵢ]` (eq. 2,
//! 3, 4) and of the effect library.
//!
//! ```text
//!   robot::Frames + torques + load ──► Sample ──Param::column──► one column ∂p/∂x
//!                                        │
//!   Layout::fill (firmware) / the host's design ┴──► B (3 rows, one column per Param)
//! ```
//!
//! | module | what |
//! |---|---|
//! | [`param`] | [`Param`]: the one vocabulary of parameters; [`Unit`]s and SI factors |
//! | [`sample`] | [`Sample`]: what one measurement carries at the current model |
//! | [`columns`] | `∂p/∂x` of every parameter: geometric (eq. 2), elastostatic (eq. 3), effects |
//! | [`effect`] | [`effect::Effect`]: the effect library's names; its rule [`effect::candidates`] (which effects a model lacks, on which parameters, in which order: the host's loop and the device's both use it); the candidates of a stream of deflections as masks over one layout |
//! | [`bins`] | the angle-bin rule (the compensator's bins): [`bins::clusters`], [`bins::by_first_appearance`], [`bins::compensator_eligible`]; [`bins::joint_bins`] for the device, `calibrate::rows` on the host |
//! | [`layout`] | [`Layout`]: a fixed-capacity list of parameters for the device and the rows it fills |

pub mod bins;
pub mod columns;
pub mod effect;
pub mod layout;
pub mod param;
pub mod sample;

pub use bins::{in_bin, in_some_bin};
pub use columns::{
    base_columns, compliance_columns, deflection_m, gravity_basis, gravity_components,
    joint_frame_columns, joint_offset_column, joint_offset_columns, marker_columns, tool_columns,
    turn,
};
pub use layout::{column_of, Column, Layout, Marker};
pub use param::{angle_urad, Param, Unit, BIN_TOLERANCE_RAD, POSE_COMPONENTS, XYZ};
pub use sample::Sample;
