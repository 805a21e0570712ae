//! `detect`: the command line's chessboard detector on an image file or a numpy
//! image, returning the corners' pixels and ids (`row * cols + col`).
use crate::{py_error, run_detached};
use deformcal::app::detect::{self, Detection, Rejection};
use numpy::{PyArray1, PyArray2, PyReadonlyArrayDyn, ToPyArray};
use pyo3::prelude::*;
use std::path::PathBuf;

/// Corners (N, 2) as float64, ids (N,) as int64, the image size and whether the whole board was seen.
type Found<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<i64>>,
    (u32, u32),
    bool,
);

/// A detection as numpy arrays.
fn found(py: Python<'_>, d: Detection) -> Found<'_> {
    let mut uv = numpy::ndarray::Array2::zeros((d.corners.len(), 2));
    let mut ids = numpy::ndarray::Array1::zeros(d.corners.len());
    for (i, c) in d.corners.iter().enumerate() {
        uv[(i, 0)] = c.uv[0];
        uv[(i, 1)] = c.uv[1];
        ids[i] = c.index as i64;
    }
    (
        uv.to_pyarray(py),
        ids.to_pyarray(py),
        (d.width, d.height),
        d.complete,
    )
}

/// A rejection as the exception of its class: an unreadable or oversized file is
/// the file's fault, a board not found is a detection's.
fn rejected(what: &str, r: Rejection) -> PyErr {
    let class = match r {
        Rejection::Unreadable(_) => "FileError",
        Rejection::InvalidPattern { .. } | Rejection::TooLarge { .. } => "InputError",
        Rejection::Internal(_) => "Error",
        _ => "DetectionError",
    };
    py_error(class, format!("{what}: {r}"))
}

/// Detects a rows × cols board (inner corners) in the image file at `path`.
#[pyfunction]
pub fn detect_file(py: Python<'_>, path: PathBuf, rows: usize, cols: usize) -> PyResult<Found<'_>> {
    let d = run_detached(py, || {
        detect::detect_file(&path, rows, cols).map_err(|r| rejected(&path.display().to_string(), r))
    })?;
    Ok(found(py, d))
}

/// Detects a rows × cols board in an 8-bit image: (H, W) grey or (H, W, 3) RGB.
#[pyfunction]
pub fn detect_array<'py>(
    py: Python<'py>,
    image: PyReadonlyArrayDyn<'py, u8>,
    rows: usize,
    cols: usize,
) -> PyResult<Found<'py>> {
    let shape = image.as_array().shape().to_vec();
    let bytes: Vec<u8> = image.as_array().iter().copied().collect();
    let (h, w) = (shape[0] as u32, shape[1] as u32);
    let img = match shape.len() {
        2 => image::GrayImage::from_raw(w, h, bytes).map(image::DynamicImage::ImageLuma8),
        _ => image::RgbImage::from_raw(w, h, bytes).map(image::DynamicImage::ImageRgb8),
    }
    .ok_or_else(|| {
        py_error(
            "InputError",
            format!("image of shape {shape:?} does not hold its pixels"),
        )
    })?;
    let d = run_detached(py, move || {
        detect::detect_image(&img, rows, cols).map_err(|r| rejected("image", r))
    })?;
    Ok(found(py, d))
}
