//! A calibration job: the setup file and the robot it names (data
//! contract §1–2), and the measurement files read against them (§3).

use std::path::{Path, PathBuf};

use crate::io::error::InputError;
use crate::io::measurements::{
    read_measurements, read_measurements_limited, Measurements, Observation,
};
use crate::io::setup::Setup;
use crate::io::urdf::Robot;
use crate::io::writer::write_measurements_with;

/// A calibration job: the setup, and the robot it names.
#[derive(Debug, Clone, PartialEq)]
pub struct Job {
    /// The setup file.
    pub setup_path: PathBuf,
    /// Its content.
    pub setup: Setup,
    /// The robot, read from [`Setup::robot_path`] with the setup's base and tip.
    pub robot: Robot,
    /// The URDF's text, for a job made from text ([`Job::parse`]); `None`:
    /// the file at [`Setup::robot_path`], read again where its text is
    /// needed (the calibrated URDF).
    pub urdf_text: Option<String>,
}

impl Job {
    /// Reads the setup and the robot it names, and checks one against the other.
    ///
    /// # Errors
    /// Any [`Setup::load`], [`Robot::load`] or [`Setup::check_robot`] error.
    pub fn load(setup_path: impl AsRef<Path>) -> Result<Self, InputError> {
        let setup_path = setup_path.as_ref();
        let setup = Setup::load(setup_path)?;
        let robot = Robot::load_tree(
            setup.robot_path(setup_path),
            setup.base_link.as_deref(),
            setup.tip(),
            &setup.marker_links(),
        )?;
        Self::of(setup_path.to_owned(), setup, robot, None)
    }

    /// A job from text, no file read: the setup's TOML and the robot's
    /// URDF; `setup_file` and `urdf_file` name them in errors (they need
    /// not exist). The setup's `robot` path is not read: the URDF is
    /// `urdf_text`, kept in [`Job::urdf_text`].
    ///
    /// # Errors
    /// Any [`Setup::parse`], [`Robot::parse_tree`] or
    /// [`Setup::check_robot`] error.
    pub fn parse(
        setup_text: &str,
        setup_file: impl Into<PathBuf>,
        urdf_text: &str,
        urdf_file: impl Into<PathBuf>,
    ) -> Result<Self, InputError> {
        let setup_path = setup_file.into();
        let setup = Setup::parse(setup_text, &setup_path)?;
        let robot = Robot::parse_tree(
            urdf_text,
            urdf_file,
            setup.base_link.as_deref(),
            setup.tip(),
            &setup.marker_links(),
        )?;
        Self::of(setup_path, setup, robot, Some(urdf_text.to_owned()))
    }

    /// The job of a setup and its robot as read: the setup's assumed link
    /// masses given to the robot, and one checked against the other.
    fn of(
        setup_path: PathBuf,
        setup: Setup,
        mut robot: Robot,
        urdf_text: Option<String>,
    ) -> Result<Self, InputError> {
        if let Some(m) = setup.assumed_link_mass_kg {
            robot.assume_link_mass(m);
        }
        setup.check_robot(&robot, &setup_path)?;
        Ok(Self {
            setup_path,
            setup,
            robot,
            urdf_text,
        })
    }

    /// Each setup marker's end in the robot ([`Robot::ends`]), in setup
    /// order: 0 for the chain's tip, `k` for `Robot::end_links[k]`.
    pub fn marker_ends(&self) -> Vec<usize> {
        self.setup
            .markers
            .iter()
            .map(|m| self.robot.end_index(m.link.as_deref()).unwrap_or(0))
            .collect()
    }

    /// Reads a measurement file of this job ([`read_measurements`]).
    ///
    /// # Errors
    /// See [`read_measurements`].
    pub fn read_measurements(&self, path: impl AsRef<Path>) -> Result<Measurements, InputError> {
        read_measurements(path, &self.robot, &self.setup)
    }

    /// As [`Job::read_measurements`], refusing a file larger than
    /// `max_bytes` ([`read_measurements_limited`]).
    ///
    /// # Errors
    /// See [`read_measurements_limited`].
    pub fn read_measurements_limited(
        &self,
        path: impl AsRef<Path>,
        max_bytes: u64,
    ) -> Result<Measurements, InputError> {
        read_measurements_limited(path, &self.robot, &self.setup, max_bytes)
    }

    /// Writes a measurement file in this job's units, the temperatures in
    /// its `temperature_column` ([`write_measurements_with`]).
    ///
    /// # Errors
    /// See [`write_measurements_with`].
    pub fn write_measurements(
        &self,
        path: impl AsRef<Path>,
        rows: &[Observation],
    ) -> Result<(), InputError> {
        write_measurements_with(
            path,
            &self.robot,
            self.setup.units,
            self.setup.model.temperature_column.as_deref(),
            rows,
        )
    }
}
