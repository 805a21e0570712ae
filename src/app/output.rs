//! The result files of one calibration: `calibration.json`, its exports,
//! `outliers.csv` and `report.html`, written into a directory (the staging directory of an
//! [`crate::app::fsio::OutputSet`], which swaps them in as one set).
use crate::app::calibration_json::CalibrationJson;
use crate::app::exports;
use crate::app::fsio::write_atomic;
use crate::app::guard::Failure;
use crate::app::html_report;
use crate::app::lint::FrameFiles;
use crate::error::{Error, Result};
use crate::solver::calibrate::Calibration;
use std::path::{Path, PathBuf};

/// The config that reruns a calibration: its config file and flags as one file
/// (written by `deformcal calibrate` on success).
pub const RERUN_CONFIG: &str = "config.toml";

/// What a calibration that failed its guard rails writes instead of
/// `calibration.json`: a name no pipeline takes for a result.
pub const FAILED_CALIBRATION: &str = "FAILED-calibration.json";
/// What a failed calibration writes instead of `outliers.csv`.
pub const FAILED_OUTLIERS: &str = "FAILED-outliers.csv";

/// The files of one calibration (`calibration.json` and what goes with it, or the
/// `FAILED-` files of a failed one): a new run replaces all of them.
pub fn calibration_files() -> crate::app::fsio::Owns {
    Box::new(|name| {
        matches!(
            name,
            "calibration.json"
                | RERUN_CONFIG
                | crate::app::board_json::BOARD_JSON
                | FAILED_CALIBRATION
                | FAILED_OUTLIERS
                | "opencv.yaml"
                | "outliers.csv"
                | crate::app::fsio::REPORT_HTML
                | crate::app::exports::KALIBR_FILE
                | crate::app::exports::COLMAP_FILE
        ) || name.ends_with(".cameramodel")
            || name.ends_with(crate::app::exports::ROS_SUFFIX)
            || (name.starts_with(crate::app::fsio::UNCERTAINTY_MAP_PREFIX)
                && name.ends_with(".svg"))
    })
}

/// Writes `calibration.json`, its exports (see [`write_models`]; the mrcal models
/// with the problem as `optimization_inputs` where mrcal can represent it),
/// `outliers.csv`, each camera's projection-uncertainty map and `report.html`
/// into `dir` (created if needed); returns the JSON's path.
pub fn write_calibration(dir: &Path, c: &Calibration) -> Result<Written> {
    write_calibration_labelled(dir, c, &FrameFiles::new())
}

/// [`write_calibration`], the report naming each frame's image file from `labels`.
///
/// The parts run side by side (rayon). The report's advice section, the longest
/// part, runs beside all the others, which go in two rounds: first what does not
/// need the uncertainty figures (the mrcal problem, `outliers.csv`, the uncertainty
/// maps, `board.json` with its own covariance), while a caller's summary may be
/// computing those figures on the other core; then `calibration.json` with the
/// exports, and the rest of the report, which embeds the maps' own text. No part
/// reads what another writes, so the files are those of writing them one after
/// the other.
pub fn write_calibration_labelled(
    dir: &Path,
    c: &Calibration,
    labels: &FrameFiles,
) -> Result<Written> {
    // Refused before any file is written, as `write_models` would.
    check_model_files(c.dataset.cameras.iter().map(|cam| cam.name.as_str()))?;
    std::fs::create_dir_all(dir).map_err(|e| Error::write(dir, e))?;
    let (advice, rest) = rayon::join(
        || html_report::advice::advice_section(c),
        || write_all_but_report(dir, c, labels),
    );
    let (written, page) = rest?;
    html_report::write_report(dir, page, advice)?;
    Ok(written)
}

/// [`write_calibration_labelled`]'s two rounds: every file but the report, and
/// the report's page but its advice section.
fn write_all_but_report(
    dir: &Path,
    c: &Calibration,
    labels: &FrameFiles,
) -> Result<(Written, html_report::page::Page)> {
    let inputs_and_outliers = || -> Result<exports::OptimizationInputs> {
        write_atomic(&dir.join("outliers.csv"), &suspects_csv(c)?)?;
        Ok(exports::optimization_inputs(c))
    };
    let maps = || -> Result<Vec<Option<Vec<u8>>>> {
        let mut embedded = Vec::new();
        for map in crate::app::uncertainty_plot::render_maps(dir, c)? {
            embedded.push(match map {
                Some((path, svg)) => {
                    write_atomic(&path, svg.as_bytes())?;
                    Some(svg.into_bytes())
                }
                None => None,
            });
        }
        Ok(embedded)
    };
    let (inputs, (maps, board)) = rayon::join(inputs_and_outliers, || {
        rayon::join(maps, || crate::app::board_json::write(dir, c))
    });
    let (inputs, maps) = (inputs?, maps?);
    board?;
    let (written, page) = rayon::join(
        || write_models(dir, &CalibrationJson::from(c), &inputs),
        || html_report::report_page(c, labels, &maps),
    );
    Ok((written?, page?))
}

/// Writes a calibration that failed its guard rails: only `FAILED-calibration.json`
/// (with the failure's reasons and hints) and `FAILED-outliers.csv`, and no model
/// file, so that nothing a pipeline loads exists for it; returns the JSON's path.
pub fn write_failed(dir: &Path, c: &Calibration, failure: &Failure) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).map_err(|e| Error::write(dir, e))?;
    let mut json = CalibrationJson::from(c);
    json.failure = Some(failure.clone());
    let text = serde_json::to_string_pretty(&json).expect("calibration serialises");
    let path = dir.join(FAILED_CALIBRATION);
    write_atomic(&path, text.as_bytes())?;
    write_atomic(&dir.join(FAILED_OUTLIERS), &suspects_csv(c)?)?;
    Ok(path)
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
/// format cannot hold exactly (left out, never approximated). The mrcal models
/// carry `inputs` (or say in a comment why they do not).
pub fn write_models(
    dir: &Path,
    json: &CalibrationJson,
    inputs: &exports::OptimizationInputs,
) -> Result<Written> {
    if let Some(f) = &json.failure {
        return Err(Error::Invalid(format!(
            "this calibration failed its guard rails ({}); its models are not exported",
            f.reasons.join("; ")
        )));
    }
    check_model_files(json.cameras.iter().map(|c| c.name.as_str()))?;
    std::fs::create_dir_all(dir).map_err(|e| Error::write(dir, e))?;
    let text = serde_json::to_string_pretty(json).expect("calibration serialises");
    let mut warnings = Vec::new();
    if let Some(yaml) = exports::opencv_yaml(json, &mut warnings) {
        write_atomic(&dir.join("opencv.yaml"), yaml.as_bytes())?;
    }
    for (k, cam) in json.cameras.iter().enumerate() {
        match exports::mrcal_cameramodel(cam, k, inputs) {
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

/// Refuses cameras whose names would collide in an export (a file or a key): a
/// calibration.json given to `export` is not checked by the config.
fn check_model_files<'a>(names: impl Iterator<Item = &'a str>) -> Result<()> {
    let names: Vec<&str> = names.collect();
    match exports::name_clash(names.iter().copied()) {
        None => Ok(()),
        Some(c) => Err(Error::Invalid(format!(
            "cameras `{}` and `{}` would both be written as {}; rename one",
            exports::printable(&crate::app::text::short(names[c.first])),
            exports::printable(&crate::app::text::short(names[c.second])),
            c.what
        ))),
    }
}

/// What a calibration wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Written {
    /// The path of `calibration.json`.
    pub calibration: PathBuf,
    /// One line per export that a lens model could not be written to.
    pub warnings: Vec<String>,
}
