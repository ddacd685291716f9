//! The files of `robcal calibrate --output DIR`, made in memory: the
//! calibrated URDF, `model.json`, `report.html` and the figures. The
//! command writes them all or nothing (`io::atomic`); the Python package
//! hands them over as text.

use std::path::{Path, PathBuf};

use crate::calibrate::outputs::export::{calibrated_urdf_with, UrdfOptions};
use crate::calibrate::outputs::model_file::ModelFile;
use crate::calibrate::outputs::predict::Predictor;
use crate::calibrate::report::Report;
use crate::render::html::{self, JobInfo};
use crate::render::json::{ModelJson, ReportJson};
use crate::render::plots::{self, Figure};

/// `--output DIR`'s files of one report, as text.
pub struct OutputFiles {
    /// `robot.urdf`: the calibrated URDF.
    pub urdf: String,
    /// `model.json`: the report, its covariance and the predictor.
    pub model_json: String,
    /// `report.html`.
    pub report_html: String,
    /// The figures, each under its own file name.
    pub figures: Vec<Figure>,
}

impl OutputFiles {
    /// The files of `report`, for the job and inputs of `info`.
    ///
    /// # Errors
    /// The calibrated URDF cannot be made
    /// ([`calibrated_urdf_with`]), or a figure cannot be drawn: one line.
    pub fn of(report: &Report, info: &JobInfo<'_>, options: UrdfOptions) -> Result<Self, String> {
        let urdf = calibrated_urdf_with(report.urdf_model(), info.job, options)
            .map_err(|e| e.to_string())?;
        let robot = Predictor::new(&report.model, info.job);
        let model_json = model_json(report, ModelFile::of(&robot))?;
        let figures = figures(report)?;
        let report_html = html::page(report, info, &figures);
        Ok(Self {
            urdf,
            model_json,
            report_html,
            figures,
        })
    }

    /// Each file's path in `dir` and its bytes.
    pub fn into_files(self, dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
        let mut files = vec![
            (dir.join("robot.urdf"), self.urdf.into_bytes()),
            (dir.join("model.json"), self.model_json.into_bytes()),
            (dir.join("report.html"), self.report_html.into_bytes()),
        ];
        files.extend(
            self.figures
                .into_iter()
                .map(|f| (dir.join(f.file), f.svg.into_bytes())),
        );
        files
    }
}

/// The report's figures ([`plots::figures`] at the intervals' quantile).
///
/// # Errors
/// A figure that cannot be drawn (its name and why).
pub fn figures(report: &Report) -> Result<Vec<Figure>, String> {
    plots::figures(report, html::t975(report).1)
}

/// `--json`'s document: the report (contract §5), pretty-printed, with a
/// final line end.
///
/// # Errors
/// serde_json's, which a report does not give (its maps have string keys).
pub fn report_json(report: &Report) -> Result<String, String> {
    serde_json::to_string_pretty(&ReportJson::of(report))
        .map(|s| s + "\n")
        .map_err(|e| e.to_string())
}

/// `model.json`'s document, pretty-printed, with a final line end.
///
/// # Errors
/// As [`report_json`].
pub fn model_json(report: &Report, predictor: ModelFile) -> Result<String, String> {
    serde_json::to_string_pretty(&ModelJson::of(report, predictor))
        .map(|s| s + "\n")
        .map_err(|e| e.to_string())
}
