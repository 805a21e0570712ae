//! OpenCV FileStorage YAML (`opencv.yaml`, docs/conventions.md §5): what `cv::FileStorage` and
//! `calibrateCamera`'s users read.
use super::common::{fmt, key_of, unrepresentable};
use crate::app::calibration_json::{CalibrationJson, CameraJson};
use crate::model::lens::{Intrinsics, OpenCvForm};
use crate::model::pose::Pose;
use std::fmt::Write;

fn matrix(name: &str, rows: usize, cols: usize, data: &[f64]) -> String {
    let values: Vec<String> = data.iter().map(|&v| fmt(v)).collect();
    format!(
        "{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: [ {} ]\n",
        values.join(", ")
    )
}

/// OpenCV's form of a lens model (the registry's), where OpenCV has it, and its
/// coefficient vector: `calibrateCamera`'s k1 k2 p1 p2 k3 [k4 k5 k6], or
/// `cv::fisheye`'s k1..k4.
pub(super) fn opencv_distortion(i: &Intrinsics) -> Option<(OpenCvForm, Vec<f64>)> {
    let form = i.model().info().opencv?;
    Some((form, super::common::values(i, form.coefficients)))
}

fn camera_block(prefix: &str, c: &CameraJson, rmse: f64) -> Option<String> {
    let i = &c.intrinsics;
    let (form, coefficients) = opencv_distortion(i)?;
    let model = form.distortion_model;
    let mut s = String::new();
    let _ = writeln!(s, "{prefix}image_width: {}", c.width);
    let _ = writeln!(s, "{prefix}image_height: {}", c.height);
    let _ = writeln!(s, "{prefix}distortion_model: \"{model}\"");
    s += &matrix(
        &format!("{prefix}camera_matrix"),
        3,
        3,
        &[i.fx(), 0.0, i.cx(), 0.0, i.fy(), i.cy(), 0.0, 0.0, 1.0],
    );
    s += &matrix(
        &format!("{prefix}distortion_coefficients"),
        coefficients.len(),
        1,
        &coefficients,
    );
    let _ = writeln!(s, "{prefix}avg_reprojection_error: {}", fmt(rmse));
    Some(s)
}

/// OpenCV FileStorage YAML (docs/conventions.md §5): unprefixed keys for one camera; for several,
/// keys prefixed `<camera>_`, plus `<camera>_R` and `<camera>_T` (camera from camera 0).
/// `None` when no camera's model can be written; a camera left out adds a warning.
pub fn opencv_yaml(c: &CalibrationJson, warnings: &mut Vec<String>) -> Option<String> {
    let mut s = String::from("%YAML:1.0\n---\n");
    if c.cameras.len() == 1 {
        let Some(block) = camera_block("", &c.cameras[0], c.rmse_px) else {
            warnings.push(unrepresentable("opencv.yaml", &c.cameras[0]));
            return None;
        };
        s += &block;
        return Some(s);
    }
    let _ = writeln!(s, "camera_count: {}", c.cameras.len());
    let mut written = 0;
    for cam in &c.cameras {
        let prefix = format!("{}_", key_of(&cam.name));
        // Each camera's own RMSE, as OpenCV's per-camera calibration reports it; a
        // file written before per-camera RMSEs existed has only the overall one.
        let rmse = cam.rmse_px.unwrap_or(c.rmse_px);
        let Some(block) = camera_block(&prefix, cam, rmse) else {
            warnings.push(unrepresentable("opencv.yaml", cam));
            continue;
        };
        written += 1;
        s += &block;
        let pose = Pose {
            rotation: cam.rotation,
            translation: cam.translation,
        };
        let r = pose.rotation_matrix();
        let m = r.matrix();
        let rows: Vec<f64> = (0..3)
            .flat_map(|i| (0..3).map(move |j| m[(i, j)]))
            .collect();
        s += &matrix(&format!("{prefix}R"), 3, 3, &rows);
        s += &matrix(&format!("{prefix}T"), 3, 1, &cam.translation);
    }
    (written > 0).then_some(s)
}
