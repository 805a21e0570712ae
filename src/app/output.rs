//! The result files of one calibration: `calibration.json`, its exports,
//! `outliers.csv` and `report.html`, written into a directory (the staging directory of an
//! [`crate::app::fsio::OutputSet`], which swaps them in as one set).
use crate::app::calibration_json::CalibrationJson;
use crate::app::exports;
use crate::app::fsio::write_atomic;
use crate::app::html_report;
use crate::app::source::FrameLabels;
use crate::error::{Error, Result};
use crate::solver::calibrate::Calibration;
use std::path::{Path, PathBuf};

/// Writes `calibration.json`, its exports (see [`write_models`]), `outliers.csv`
/// and `report.html` into `dir` (created if needed); returns the JSON's path.
pub fn write_calibration(dir: &Path, c: &Calibration) -> Result<Written> {
    write_calibration_labelled(dir, c, &FrameLabels::new())
}

/// [`write_calibration`], the report naming each frame's image file from `labels`.
/// The report is written last: it embeds the files it finds beside it.
pub fn write_calibration_labelled(
    dir: &Path,
    c: &Calibration,
    labels: &FrameLabels,
) -> Result<Written> {
    let written = write_models(dir, &CalibrationJson::from(c))?;
    write_atomic(&dir.join("outliers.csv"), &suspects_csv(c)?)?;
    html_report::write_calibration_report(dir, c, labels)?;
    Ok(written)
}

/// `outliers.csv`: the observations outlier rejection removed (`rejected`), then
/// those the robust loss down-weighted (`downweighted`), worst first, so bad
/// detections can be inspected.
pub fn suspects_csv(c: &Calibration) -> Result<Vec<u8>> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let suspects = c.suspects();
    for s in &suspects {
        w.serialize(s)
            .map_err(|e| Error::write("outliers.csv", std::io::Error::other(e.to_string())))?;
    }
    // serde writes the header with the first row; an empty report still gets one.
    if suspects.is_empty() {
        w.write_record([
            "camera",
            "frame",
            "corner",
            "u",
            "v",
            "residual_px",
            "weight",
            "status",
        ])
        .map_err(|e| Error::write("outliers.csv", std::io::Error::other(e.to_string())))?;
    }
    w.into_inner()
        .map_err(|e| Error::write("outliers.csv", std::io::Error::other(e.to_string())))
}

/// Writes a calibration's JSON and its exports into `dir`: OpenCV, mrcal, ROS
/// (`<camera>_camera_info.yaml`), Kalibr (`camchain.yaml`) and COLMAP
/// (`cameras.txt`); returns the JSON's path and a warning per camera an export
/// format cannot hold exactly (left out, never approximated).
pub fn write_models(dir: &Path, json: &CalibrationJson) -> Result<Written> {
    let mut files = std::collections::BTreeMap::new();
    for cam in &json.cameras {
        let file = exports::model_file_name(&cam.name);
        if let Some(other) = files.insert(file.clone(), &cam.name) {
            return Err(Error::Invalid(format!(
                "cameras `{}` and `{}` would both be written as `{}`; rename one",
                crate::app::config::short(other),
                crate::app::config::short(&cam.name),
                crate::app::config::short(&file)
            )));
        }
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::write(dir, e))?;
    let text = serde_json::to_string_pretty(json).expect("calibration serialises");
    let mut warnings = Vec::new();
    if let Some(yaml) = exports::opencv_yaml(json, &mut warnings) {
        write_atomic(&dir.join("opencv.yaml"), yaml.as_bytes())?;
    }
    for cam in &json.cameras {
        match exports::mrcal_cameramodel(cam) {
            Some(model) => write_atomic(
                &dir.join(exports::model_file_name(&cam.name)),
                model.as_bytes(),
            )?,
            None => warnings.push(format!(
                "{}: not written: mrcal has no `{}` lens model",
                exports::model_file_name(&cam.name),
                cam.model
            )),
        }
    }
    for (file, text) in exports::camera_infos(json, &mut warnings) {
        write_atomic(&dir.join(file), text.as_bytes())?;
    }
    if let Some(yaml) = exports::camchain_yaml(json, &mut warnings) {
        write_atomic(&dir.join(exports::KALIBR_FILE), yaml.as_bytes())?;
    }
    if let Some(txt) = exports::cameras_txt(json, &mut warnings) {
        write_atomic(&dir.join(exports::COLMAP_FILE), txt.as_bytes())?;
    }
    let path = dir.join("calibration.json");
    write_atomic(&path, text.as_bytes())?;
    Ok(Written {
        calibration: path,
        warnings,
    })
}

/// What a calibration wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Written {
    /// The path of `calibration.json`.
    pub calibration: PathBuf,
    /// One line per export that a lens model could not be written to.
    pub warnings: Vec<String>,
}
