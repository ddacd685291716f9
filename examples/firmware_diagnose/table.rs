//! The device's data for the closed loop: the KR-270 flash table of the
//! firmware example (`examples/firmware/kr270_table.rs`, 270 measured
//! deflections) as a [`Data`] stream, and the same table with an injected
//! backlash on a5 (the second case of issue 17: the device must name it).
//!
//! The injection is not the backlash column of the model: the loaded
//! position of every marker is moved to the forward kinematics of the pose
//! with a5 turned by `b · sign(τ5)` (the load's torque on a5 at the
//! configuration), minus the forward kinematics of the commanded pose. The
//! host test (`host-tests/tests/device_diagnosis.rs`) applies the same
//! displacement to the CSV's loaded rows and checks that `robcal
//! calibrate --linear` decides as the device.

use nalgebra::{RealField, Vector3};
use robcal::model::Marker;
use robcal::robot::{joint_torques, PointLoad};
use robcal::{Chain, Error};

use crate::closed_loop::{Data, Meas, J};
use crate::kr270;

/// The injected backlash: joint a5 (index 4), 0.3 mrad.
pub const BACKLASH: (usize, f64) = (4, 3e-4);

fn c<T: RealField + Copy>(x: f64) -> T {
    nalgebra::convert(x)
}

/// The flash table, optionally with the injected backlash.
pub struct Table<T: RealField + Copy> {
    chain: Chain<T, J>,
    com_m: Vector3<T>,
    gravity_mps2: Vector3<T>,
    /// Inject [`BACKLASH`].
    inject: bool,
}

impl<T: RealField + Copy> Table<T> {
    /// The KR-270 table; with `inject`, the backlash on a5 in it.
    ///
    /// # Errors
    /// From the chain.
    #[inline(never)]
    pub fn new(inject: bool) -> Result<Self, Error> {
        let v = |a: [f64; 3]| Vector3::new(c(a[0]), c(a[1]), c(a[2]));
        Ok(Self {
            chain: kr270::chain()?,
            com_m: v(robcal_paper::kr270::LOAD_COM_M),
            gravity_mps2: v([0.0, 0.0, -9.80665]),
            inject,
        })
    }

    /// The injected displacement of every marker at configuration `g`
    /// \[m\]: `p(q + b · sign(τ5) e5) − p(q)`.
    ///
    /// # Errors
    /// From the kinematics.
    #[inline(never)]
    pub fn injected(&self, g: usize) -> Result<[Vector3<T>; 3], Error> {
        let q = self.q(g);
        let (j, b) = BACKLASH;
        let (at, tau) = self.markers_at(&q, Some(g))?;
        let mut qb = q;
        qb[j] += c::<T>(b) * tau[j].signum();
        let (moved, _) = self.markers_at(&qb, None)?;
        Ok(core::array::from_fn(|m| moved[m] - at[m]))
    }

    /// The markers' positions at the joint angles `q`, and with the
    /// configuration `load` the load's joint torques there. Not inlined:
    /// one set of frames on the stack at a time.
    #[inline(never)]
    fn markers_at(
        &self,
        q: &[T; J],
        load: Option<usize>,
    ) -> Result<([Vector3<T>; 3], [T; J]), Error> {
        let frames = self.chain.frames(q);
        let frames = match &frames {
            Ok(f) => f,
            Err(e) => return Err(*e),
        };
        let mut tau = [T::zero(); J];
        if let Some(g) = load {
            joint_torques(frames, &self.load(g).wrench(frames), &mut tau)?;
        }
        let at = core::array::from_fn(|m| {
            let xyz = self
                .marker(m as u8)
                .map_or_else(Vector3::zeros, |m| m.xyz_m);
            frames.point_m(&xyz)
        });
        Ok((at, tau))
    }
}

impl<T: RealField + Copy> Data<T> for Table<T> {
    fn chain(&self) -> &Chain<T, J> {
        &self.chain
    }

    fn groups(&self) -> usize {
        kr270::G
    }

    fn q(&self, g: usize) -> [T; J] {
        kr270::q_rad(g)
    }

    fn load(&self, g: usize) -> PointLoad<T> {
        PointLoad {
            mass_kg: c::<T>(f64::from(kr270::LOAD_DKG[g]) * 0.1),
            com_m: self.com_m,
            gravity_mps2: self.gravity_mps2,
        }
    }

    fn marker(&self, m: u8) -> Option<Marker<T>> {
        let xyz = robcal_paper::kr270::MARKERS_M.get(usize::from(m))?;
        Some(Marker {
            index: m,
            xyz_m: Vector3::new(c(xyz[0]), c(xyz[1]), c(xyz[2])),
        })
    }

    fn time(&self) -> bool {
        false
    }

    fn for_each(&self, f: &mut dyn FnMut(&Meas<T>) -> Result<(), Error>) -> Result<(), Error> {
        let mut cached = usize::MAX;
        let mut shift = [Vector3::zeros(); 3];
        for d in kr270::deflections() {
            let g = usize::from(d.config);
            if self.inject && g != cached {
                shift = self.injected(g)?;
                cached = g;
            }
            let mut dp = kr270::dp_m::<T>(&d);
            if self.inject {
                dp += shift
                    .get(usize::from(d.marker))
                    .copied()
                    .unwrap_or_else(Vector3::zeros);
            }
            f(&Meas {
                group: g,
                marker: d.marker,
                dt_s: T::zero(),
                dp,
            })?;
        }
        Ok(())
    }
}

/// The naive model of `data/kr270/setup-naive.toml`: one constant
/// compliance per joint a2…a6.
pub fn naive_model() -> [robcal::model::Param; 5] {
    core::array::from_fn(|i| robcal::model::Param::Compliance { joint: i as u8 + 1 })
}

/// The device's IRLS settings (σ0 = 10 µm, λ = 1 of the setup, as the
/// firmware's KR-270 fit).
///
/// # Errors
/// From [`robcal::estimate::RobustWeight::new`].
pub fn settings<T: RealField + Copy>() -> Result<robcal::IrlsSettings<T>, Error> {
    kr270::settings()
}
