//! The detector's entry points: load an image and run the chessboard or the
//! ChArUco pipeline on it. Dispatch only; the stages live in their own files.

use crate::app::detect::types::{Detection, Detector, Rejection};
use crate::app::detect::{charuco, load, pipeline};
use std::path::Path;

impl Detector {
    /// Load and detect. Never panics; every failure is a [`Rejection`].
    pub fn detect_file(
        &self,
        path: &Path,
        rows: usize,
        cols: usize,
    ) -> Result<Detection, Rejection> {
        let img = load::load(path, self.max_pixels)?;
        self.detect_image(&img, rows, cols)
    }

    /// Detect in an already decoded image.
    pub fn detect_image(
        &self,
        img: &image::DynamicImage,
        rows: usize,
        cols: usize,
    ) -> Result<Detection, Rejection> {
        match &self.charuco {
            Some(spec) => charuco::detect(self, spec, img),
            None => pipeline::detect(self, img, rows, cols),
        }
    }
}

/// [`Detector::detect_file`] with default settings.
pub fn detect_file(path: &Path, rows: usize, cols: usize) -> Result<Detection, Rejection> {
    Detector::default().detect_file(path, rows, cols)
}

/// [`Detector::detect_image`] with default settings.
pub fn detect_image(
    img: &image::DynamicImage,
    rows: usize,
    cols: usize,
) -> Result<Detection, Rejection> {
    Detector::default().detect_image(img, rows, cols)
}
