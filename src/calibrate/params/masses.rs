//! Link masses as parameters ([`crate::model::Param::LinkMass`]): what a robot's own
//! weight does depends on masses that URDFs often lack or get wrong, and
//! an assumed mass model (setup `assumed_link_mass_kg`) puts an equal lump
//! at every joint. The masses are identified with the compliances they
//! load, by the host's Gauss–Newton: each step is applied to the model
//! ([`crate::calibrate::params::geometry::Geometry::apply`]) and the rows
//! (their own-weight torques and moments) are evaluated again there.
//!
//! **The column.** One kilogram more on joint `l`'s moving body, at its
//! centre of mass `c_l`, adds the force `g` \[N/kg\] there. Each joint `i`
//! that carries the body (and the marker) sees its torque change by
//! `∂τᵢ/∂m_l = zᵢ · ((c_l − oᵢ) × g)` (prismatic: `zᵢ · g`), yields by
//! `∂δᵢ/∂τᵢ` of it (its effective compliance at the row's torque,
//! `kᵢ + 2cᵢ|τᵢ|`), which moves the marker along the column of joint
//! `i`'s value (the exact model's or `zᵢ × (p − oᵢ)`,
//! [`crate::model::Sample::twist`]); and its link, with a bending
//! `k_bᵢ` ([`crate::model::Param::LinkCompliance`]), turns by
//! `k_bᵢ ((c_l − oᵢ) × g)⊥`, which moves the marker by that times
//! `(p − oᵢ)`:
//!
//! `∂p/∂m_l = Σᵢ [∂δᵢ/∂τᵢ · ∂τᵢ/∂m_l · twistᵢ + k_bᵢ ((c_l − oᵢ) × g)⊥ × (p − oᵢ)]`.
//!
//! It is linear in the compliances and zero without them: a mass is seen
//! only through what it bends. Every mass and every compliance together
//! are one scale short (twice the masses and half the compliances bend
//! the robot alike: `Σ_l m_l ∂p/∂m_l` is the compliances' own columns
//! times their values), which the identifiability test finds; a mass
//! left at its nominal value, or a load of known mass, fixes the scale.
//! A deflection (loaded minus unloaded) does not see the robot's own
//! weight: its column is zero.

use nalgebra::Vector3;

use crate::calibrate::params::geometry::J;
use crate::calibrate::params::linearisation::Law;
use crate::error::Error;
use crate::model::Sample;
use crate::robot::{Chain, JointKind, JointLaw, Wrench};

/// The column `∂p/∂m_l` \[m/kg\] of the mass of joint `l`'s moving body at
/// `sample` (an absolute row, its frames on `chain`), under gravity
/// `gravity_mps2` \[m/s², the frames' frame\], with the joint law `law` at
/// the row's torques and the links' bendings `bending(i)` \[rad/(N·m)\]
/// (see the [module docs](self)). Zero for a deflection.
///
/// # Errors
/// [`Error::OutOfRange`] when the chain or the frames have no joint `l`.
pub fn column(
    chain: &Chain<f64, J>,
    sample: &Sample<'_, f64, J>,
    l: usize,
    gravity_mps2: &Vector3<f64>,
    law: &Law,
    bending: impl Fn(usize) -> f64,
) -> Result<Vector3<f64>, Error> {
    if !sample.absolute {
        return Ok(Vector3::zeros());
    }
    let frames = sample.frames;
    let body = chain.joints().get(l).ok_or(Error::OutOfRange {
        what: "joint",
        index: l,
        len: chain.dof(),
    })?;
    let com = body.link.map_or(Vector3::zeros(), |b| b.com_m);
    let c = frames
        .joint(l)?
        .frame
        .transform_point(&nalgebra::Point3::from(com))
        .coords;
    let unit = Wrench::force(*gravity_mps2, c);
    let p = sample.point_m;
    let mut col = Vector3::zeros();
    for i in chain.path(Some(l)) {
        let jf = frames.joint(i)?;
        if !jf.carries {
            continue;
        }
        let tau = sample.tau.get(i).copied().unwrap_or(0.0);
        let dtau = unit.torque_on(jf);
        let yields = law.deflection(i, tau).1;
        if yields != 0.0 && dtau != 0.0 {
            col += sample.twist(i as u8)? * (yields * dtau);
        }
        let kb = bending(i);
        if kb != 0.0 && jf.kind == JointKind::Revolute {
            let o = jf.origin_m();
            let m = (c - o).cross(gravity_mps2);
            let z = jf.axis.into_inner();
            col += (m - z * z.dot(&m)).cross(&(p - o)) * kb;
        }
    }
    Ok(col)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::{equilibrium, EquilibriumSettings, Joint, LinkInertia, Loading};

    /// Three revolute joints (z, y, y), each link 0.4 m along x with a
    /// mass at its middle, compliant joints: the column of each mass is the
    /// central difference of the exact equilibrium's point in that mass.
    #[test]
    fn the_column_is_the_equilibriums_derivative() {
        let mut chain = Chain::<f64, J>::new();
        let axes = [Vector3::z(), Vector3::y(), Vector3::y()];
        let xyz = [
            Vector3::zeros(),
            Vector3::new(0.0, 0.0, 0.3),
            Vector3::new(0.4, 0.0, 0.0),
        ];
        for (k, (a, t)) in axes.iter().zip(&xyz).enumerate() {
            let mut j = Joint::from_urdf(*t, Vector3::zeros(), *a, JointKind::Revolute).unwrap();
            j.link = Some(LinkInertia {
                mass_kg: 3.0 + k as f64,
                com_m: Vector3::new(0.2, 0.01, 0.0),
            });
            chain.push(j).unwrap();
        }
        let tool = Vector3::new(0.45, 0.02, 0.05);
        let q = [0.3, -0.7, 0.9];
        let g = Vector3::new(0.0, 0.0, -9.80665);
        let loading = Loading {
            load: None,
            own_weight_mps2: Some(g),
        };
        let law = Law {
            compliance: vec![2e-4, 5e-4, 8e-4],
            quadratic: vec![0.0, 1e-6, 0.0],
            backlash: vec![0.0; 3],
            fixed: vec![0.0; 3],
        };
        let settings = EquilibriumSettings {
            tolerance: 1e-14,
            max_iterations: 50,
        };
        let point = |chain: &Chain<f64, J>| {
            let eq = equilibrium(chain, &q, &q, &loading, &law, &settings).unwrap();
            (eq.frames.point_m(&tool), eq)
        };
        let (p, eq) = point(&chain);
        let twists: Vec<Vector3<f64>> = (0..3).map(|j| eq.twist_column(j, &p).unwrap()).collect();
        let sample = Sample {
            twists: &twists,
            ..Sample::absolute(&eq.frames, p, 0, &eq.tau[..3])
        };
        for l in 0..3 {
            let col = column(&chain, &sample, l, &g, &law, |_| 0.0).unwrap();
            let h = 1e-3;
            let at = |d: f64| {
                let mut c = chain.clone();
                c.joints_mut()[l].link.as_mut().unwrap().mass_kg += d;
                point(&c).0
            };
            let fd = (at(h) - at(-h)) / (2.0 * h);
            assert!(
                (col - fd).norm() <= 1e-6 * fd.norm() + 1e-12,
                "link {l}: column {col:?}, central difference {fd:?}"
            );
            // (The first link turns about the vertical: its weight loads
            // no joint.)
            assert!(
                l == 0 || fd.norm() > 1e-5,
                "link {l}: the mass moves the point"
            );
        }
    }
}
