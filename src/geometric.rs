//! Geometric identification columns (eq. 2, `Δpᵍ = J⁽ᵖ⁾ ΔΠ`).
//!
//! A *column* is the derivative of one marker's position `p` [m, base or
//! measurement frame] with respect to one parameter, in SI units (m/m or
//! m/rad); [`crate::layout`] rescales columns to the reported units.
//!
//! The parameters, with the error transforms that define them (first order,
//! `Rot(δr) ≈ I + [δr]×`):
//!
//! - **joint offset** `δqⱼ`: added to joint `j`'s value. Column
//!   `zⱼ × (p − oⱼ)` (revolute, m/rad) or `zⱼ` (prismatic, m/m).
//! - **joint-frame error** `(δx, δy, δz, δrx, δry, δrz)` of joint `j`: a small
//!   transform `E = Trans(δt) · Rot(δr)` *right*-multiplying the joint's
//!   origin, `origin_j → origin_j · E`, i.e. expressed in joint `j`'s own
//!   frame at zero joint value `Z_j = T_{j-1} · origin_j` (axes `Rᶻ eₖ`,
//!   origin `aⱼ`), before the joint's motion. Columns: translation `Rᶻ eₖ`,
//!   rotation `(Rᶻ eₖ) × (p − aⱼ)`. The URDF `xyz` of joint `j` is the same
//!   translation expressed in the parent frame: `∂p/∂xyz = Rᶻ R_originᵀ`
//!   times the translation columns.
//! - **base frame** `(δx, δy, δz, δrx, δry, δrz)`: the robot base placed in
//!   the measurement frame by `E = Trans(δt) · Rot(δr)`, `p_meas = E · p`;
//!   rotation about the measurement frame's axes through its origin. Columns
//!   `eₖ` and `eₖ × p`.
//! - **marker position** `(δx, δy, δz)` in the tip frame. Columns
//!   `R_tip eₖ`.

use nalgebra::{RealField, Vector3};

use crate::kinematics::Frames;
use crate::Error;

/// Joint-offset column of joint `j` at a point `p_m` [m, base frame]:
/// `zⱼ × (p − oⱼ)` [m/rad] (revolute) or `zⱼ` [m/m] (prismatic).
///
/// # Errors
/// [`Error::OutOfRange`] when `j ≥ dof`.
pub fn joint_offset_column<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
    j: usize,
    p_m: &Vector3<T>,
) -> Result<Vector3<T>, Error> {
    Ok(frames.joint(j)?.twist_column(p_m))
}

/// Joint-offset columns of every joint, written to `out[..dof]`.
///
/// # Errors
/// [`Error::Mismatch`] when `out` is shorter than the number of joints.
pub fn joint_offset_columns<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
    p_m: &Vector3<T>,
    out: &mut [Vector3<T>],
) -> Result<(), Error> {
    if out.len() < frames.dof() {
        return Err(Error::Mismatch {
            what: "column slice shorter than the chain's dof",
        });
    }
    for (o, jf) in out.iter_mut().zip(frames.joints()) {
        *o = jf.twist_column(p_m);
    }
    Ok(())
}

/// The six joint-frame error columns of joint `j` (see the
/// [module docs](self)): `[δx, δy, δz]` in m/m, then `[δrx, δry, δrz]` in
/// m/rad, all along the axes of `Z_j`.
///
/// # Errors
/// [`Error::OutOfRange`] when `j ≥ dof`.
pub fn joint_frame_columns<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
    j: usize,
    p_m: &Vector3<T>,
) -> Result<[Vector3<T>; 6], Error> {
    let z = frames.joint(j)?.zero;
    let r = z.rotation.to_rotation_matrix();
    let arm = p_m - z.translation.vector;
    let e = |k: usize| r.matrix().column(k).into_owned();
    Ok([
        e(0),
        e(1),
        e(2),
        e(0).cross(&arm),
        e(1).cross(&arm),
        e(2).cross(&arm),
    ])
}

/// The six base-frame columns at a point `p_m` [m, robot base frame]:
/// `[eₓ, e_y, e_z]` (m/m), then `[eₓ × p, e_y × p, e_z × p]` (m/rad).
pub fn base_columns<T: RealField + Copy>(p_m: &Vector3<T>) -> [Vector3<T>; 6] {
    let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
    [x, y, z, x.cross(p_m), y.cross(p_m), z.cross(p_m)]
}

/// The three marker-position columns (m/m): the tip frame's axes in the base
/// frame, `R_tip eₖ`.
pub fn marker_columns<T: RealField + Copy, const J: usize>(
    frames: &Frames<T, J>,
) -> [Vector3<T>; 3] {
    let r = frames.tip().rotation.to_rotation_matrix();
    let e = |k: usize| r.matrix().column(k).into_owned();
    [e(0), e(1), e(2)]
}
