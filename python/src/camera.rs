//! A camera's projection and unprojection over arrays of points (the library's
//! lens registry, point by point), reading `calibration.json`, and writing a
//! calibration in each format the command line writes (the library's exporters).
use crate::{lib_error, py_error, run_detached};
use deformcal::app::calibration_json::CalibrationJson;
use deformcal::app::exports::{self, OptimizationInputs, NOT_IN_CALIBRATION_JSON};
use deformcal::app::fsio::write_atomic;
use deformcal::{Intrinsics, LensModel};
use nalgebra::{Vector2, Vector3};
use numpy::{PyArray2, PyReadonlyArray1, PyReadonlyArray2, ToPyArray};
use pyo3::prelude::*;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// The intrinsics of lens model `model` with `params` in the registry's order.
fn intrinsics(model: &str, params: &[f64]) -> PyResult<Intrinsics> {
    let lens = LensModel::parse(model).ok_or_else(|| {
        py_error(
            "InputError",
            format!(
                "unknown lens model `{model}` (expected one of {})",
                LensModel::names()
            ),
        )
    })?;
    Intrinsics::from_params(lens, params).ok_or_else(|| {
        py_error(
            "InputError",
            format!(
                "lens model {model} has {} parameters ({}), got {}",
                lens.num_params(),
                lens.param_names().join(", "),
                params.len()
            ),
        )
    })
}

/// Every lens model's parameter names, in the registry's (and calibration.json's) order.
#[pyfunction]
pub fn lens_models() -> BTreeMap<&'static str, Vec<&'static str>> {
    LensModel::ALL
        .iter()
        .map(|m| (m.name(), m.param_names().to_vec()))
        .collect()
}

/// Pixels (M, 2) of camera-frame points (M, 3); NaN where the model has no image.
#[pyfunction]
pub fn project<'py>(
    py: Python<'py>,
    model: &str,
    params: PyReadonlyArray1<'py, f64>,
    points: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let k = intrinsics(model, &params.as_array().to_vec())?;
    let points = points.as_array().to_owned();
    let out = run_detached(py, move || {
        let mut out = numpy::ndarray::Array2::from_elem((points.nrows(), 2), f64::NAN);
        for (i, p) in points.outer_iter().enumerate() {
            if let Some(uv) = k.project(&Vector3::new(p[0], p[1], p[2])) {
                out[(i, 0)] = uv.x;
                out[(i, 1)] = uv.y;
            }
        }
        Ok(out)
    })?;
    Ok(out.to_pyarray(py))
}

/// Unit rays (M, 3) of pixels (M, 2); NaN where no ray maps to the pixel.
#[pyfunction]
pub fn unproject<'py>(
    py: Python<'py>,
    model: &str,
    params: PyReadonlyArray1<'py, f64>,
    pixels: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let k = intrinsics(model, &params.as_array().to_vec())?;
    let pixels = pixels.as_array().to_owned();
    let out = run_detached(py, move || {
        let mut out = numpy::ndarray::Array2::from_elem((pixels.nrows(), 3), f64::NAN);
        for (i, p) in pixels.outer_iter().enumerate() {
            if let Some(ray) = k.unproject(&Vector2::new(p[0], p[1])) {
                let ray = ray.normalize();
                for j in 0..3 {
                    out[(i, j)] = ray[j];
                }
            }
        }
        Ok(out)
    })?;
    Ok(out.to_pyarray(py))
}

/// A calibration.json's text: read from `path` with the command line's checks,
/// or, given `text`, parsed and checked as if read from `path`.
#[pyfunction]
#[pyo3(signature = (path, text=None))]
pub fn check_calibration_json(path: PathBuf, text: Option<String>) -> PyResult<String> {
    let json = match text {
        None => CalibrationJson::load(&path).map_err(|e| match e {
            deformcal::Error::Io { .. } => lib_error(e),
            other => py_error("InputError", other.to_string()),
        })?,
        Some(text) => parse_checked(&text, &path)?,
    };
    serde_json::to_string(&json).map_err(|e| py_error("Error", e.to_string()))
}

/// `text` as a checked calibration.json; messages name `path`.
fn parse_checked(text: &str, path: &std::path::Path) -> PyResult<CalibrationJson> {
    let json: CalibrationJson = serde_json::from_str(text).map_err(|e| {
        py_error(
            "InputError",
            format!("{}: not a deformcal calibration.json: {e}", path.display()),
        )
    })?;
    json.check()
        .map_err(|m| py_error("InputError", format!("{}: {m}", path.display())))?;
    Ok(json)
}

/// The export formats and what each writes.
pub const FORMATS: [&str; 6] = ["json", "opencv", "mrcal", "ros", "kalibr", "colmap"];

/// The file text of `json` in format `fmt`, or why the format cannot hold it.
fn export_text(json: &CalibrationJson, fmt: &str) -> PyResult<String> {
    let mut warnings = Vec::new();
    let text = match fmt {
        "json" => {
            Some(serde_json::to_string_pretty(json).map_err(|e| py_error("Error", e.to_string()))?)
        }
        "opencv" => exports::opencv_yaml(json, &mut warnings),
        "mrcal" => {
            let inputs = OptimizationInputs::Absent(NOT_IN_CALIBRATION_JSON.into());
            let model = json
                .cameras
                .first()
                .and_then(|c| exports::mrcal_cameramodel(c, 0, &inputs));
            if model.is_none() {
                warnings.push(format!(
                    "mrcal has no `{}` lens model",
                    json.cameras.first().map(|c| c.model.name()).unwrap_or("?")
                ));
            }
            model
        }
        "ros" => exports::camera_infos(json, &mut warnings)
            .into_iter()
            .next()
            .map(|(_, text)| text),
        "kalibr" => exports::camchain_yaml(json, &mut warnings),
        "colmap" => exports::cameras_txt(json, &mut warnings),
        other => {
            return Err(py_error(
                "InputError",
                format!(
                    "unknown export format `{other}` (expected one of {})",
                    FORMATS.join(", ")
                ),
            ))
        }
    };
    text.ok_or_else(|| {
        py_error(
            "ExportError",
            format!("cannot write this camera as {fmt}: {}", warnings.join("; ")),
        )
    })
}

/// Writes the calibration.json `text` (checked) in format `fmt` to `path`, atomically.
#[pyfunction]
pub fn export(py: Python<'_>, text: String, fmt: String, path: PathBuf) -> PyResult<()> {
    run_detached(py, move || {
        let json = parse_checked(&text, &path)?;
        let out = export_text(&json, &fmt)?;
        write_atomic(&path, out.as_bytes()).map_err(lib_error)
    })
}
