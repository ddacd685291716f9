//! The data contract's files (`shared/spec/data-contract.md`): the robot
//! (URDF), the setup (TOML) and the measurements (CSV). Host only (`std`).
//!
//! ```text
//!   setup.toml ──Setup::load──► Setup ─┐
//!   robot.urdf ──Robot::load──► Robot ─┴─► Job ──read_measurements──► Measurements
//!                                                 (Observation, Deflection)
//!   FIGAROH mocap CSV ──figaroh::import_mocap──► measurement CSV (write_atomic)
//!   wide pose CSV (shared/datasets) ──poses::import_poses──► measurement CSV
//!   points CSV ──points::parse_points──► PointRow (robcal predict / compensate)
//!   Robot ──template::setup_template──► a commented setup (robcal init)
//! ```
//!
//! Everything is converted to SI on reading (rad, m, kg, s); the CSV's
//! `[units]` apply only to its joint and position columns.
//!
//! Every file is read through [`input`] (regular files only, a size limit
//! checked before reading) and written through [`atomic`] (all or nothing,
//! never onto an input, a link or a device); the limits are in
//! `docs/inputs.md`.
//!
//! Every rejected input is one [`InputError`] naming the file, and where
//! known the line (1-based; the CSV header is line 1) and the CSV column.
//! Suspicious but usable input (a joint value far outside its URDF limits,
//! numbers that look like the wrong unit) is returned as [`InputWarning`]s
//! next to the data instead.
//!
//! ```
//! use robcal::io::{parse_measurements, Robot, Setup};
//!
//! let urdf = r#"<robot name="r">
//!   <link name="base"/> <link name="arm"/> <link name="flange"/>
//!   <joint name="a1" type="continuous">
//!     <parent link="base"/> <child link="arm"/> <axis xyz="0 0 1"/>
//!   </joint>
//!   <joint name="tool" type="fixed">
//!     <parent link="arm"/> <child link="flange"/> <origin xyz="0.5 0 0"/>
//!   </joint>
//! </robot>"#;
//! let robot = Robot::parse(urdf, "r.urdf", Some("base"), Some("flange"))?;
//! assert_eq!(robot.joint_names, ["a1"]);
//! assert_eq!(robot.chain.tip().translation.vector.x, 0.5);
//!
//! let setup = Setup::parse(
//!     "robot = \"r.urdf\"\n[units]\nangle = \"deg\"\nlength = \"mm\"\n[load]\n",
//!     "s.toml",
//! )?;
//! let csv = "config,rep,marker,load_kg,a1,x,y,z\n\
//!            1,0,1,0,90,500,0,0\n\
//!            1,0,1,20,90,500,-0.25,0\n";
//! let data = parse_measurements(csv.as_bytes(), "d.csv", &robot, &setup)?;
//! assert_eq!(data.observations[0].q.as_slice(), [std::f64::consts::FRAC_PI_2]);
//! assert_eq!(data.observations[0].p_m, [0.5, 0.0, 0.0]);
//! assert_eq!(data.deflections[0].dp_m, [0.0, -0.00025, 0.0]);
//!
//! // Errors name the file, line and column.
//! let bad = "config,rep,marker,load_kg,a1,x,y,z\n1,0,2,0,90,500,0,0\n";
//! let e = parse_measurements(bad.as_bytes(), "d.csv", &robot, &setup).unwrap_err();
//! assert_eq!(e.to_string(), "d.csv:2: column 'marker': marker 2 is not declared in the setup");
//! # Ok::<(), robcal::io::InputError>(())
//! ```

pub mod atomic;
mod cells;
pub mod error;
pub mod figaroh;
pub mod input;
pub mod job;
pub mod measurements;
pub mod points;
pub mod poses;
pub mod setup;
pub mod template;
pub mod units;
pub mod urdf;
pub mod writer;

pub use atomic::{write_all_atomic, write_atomic};
pub use error::{ErrorKind, InputError, InputWarning, Located, WarningKind};
pub use job::Job;
pub use measurements::{
    parse_measurements, read_measurements, read_measurements_limited, Deflection, JointValues,
    Measurements, Observation, WrittenCells, INLINE_JOINTS,
};
pub use setup::{
    AngleUnit, GeometryModel, LengthUnit, Load, Marker, MarkerModel, Model, Noise, Setup, Units,
    Weighting,
};
pub use urdf::{JointLimits, OffChainBranch, Robot, UrdfJointKind, MAX_JOINTS};
pub use writer::{write_measurements, write_measurements_with};
