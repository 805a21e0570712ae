//! ROS `camera_info` YAML, one `<camera>_camera_info.yaml` per camera, in the
//! layout `camera_calibration_parsers` writes and reads (the files
//! `camera_info_manager` loads): `plumb_bob` (radial3, opencv5),
//! `rational_polynomial` (opencv8) and `equidistant` (kb4); ROS has no double
//! sphere. For exactly two pinhole-like cameras the rectification matrices and
//! projections are those of OpenCV's `stereoRectify` (see [`super::rectify`]);
//! otherwise each camera is monocular: R = I and P = [K | 0].
use super::common::{file_stem, fmt, key_of};
use super::opencv::opencv_distortion;
use super::rectify::stereo_rectify;
use crate::app::calibration_json::{CalibrationJson, CameraJson};
use nalgebra::{Matrix3, Matrix3x4};
use std::fmt::Write;

/// What ends the name of a camera's ROS file.
pub const ROS_SUFFIX: &str = "_camera_info.yaml";

/// The ROS file name of a camera: `<camera>_camera_info.yaml`.
pub fn ros_file_name(camera: &str) -> String {
    format!("{}{ROS_SUFFIX}", file_stem(camera))
}

/// A `{rows, cols, data}` block as `camera_calibration_parsers` writes it.
fn block(name: &str, rows: usize, cols: usize, data: &[f64]) -> String {
    let values: Vec<String> = data.iter().map(|&v| fmt(v)).collect();
    format!(
        "{name}:\n  rows: {rows}\n  cols: {cols}\n  data: [{}]\n",
        values.join(", ")
    )
}

fn row_major<const C: usize>(m: &nalgebra::SMatrix<f64, 3, C>) -> Vec<f64> {
    (0..3)
        .flat_map(|i| (0..C).map(move |j| m[(i, j)]))
        .collect()
}

/// One camera's file, or `None` where ROS has no such lens model.
fn camera_info(c: &CameraJson, r: &Matrix3<f64>, p: &Matrix3x4<f64>) -> Option<String> {
    let i = &c.intrinsics;
    // ROS names the model its own way (`equidistant` for OpenCV's `fisheye`) and
    // takes OpenCV's coefficients.
    let model = i.model().info().ros?;
    let (_, coefficients) = opencv_distortion(i)?;
    let mut s = String::new();
    let _ = writeln!(s, "image_width: {}", c.width);
    let _ = writeln!(s, "image_height: {}", c.height);
    let _ = writeln!(s, "camera_name: {}", key_of(&c.name));
    s += &block("camera_matrix", 3, 3, &row_major(&i.camera_matrix()));
    let _ = writeln!(s, "distortion_model: {model}");
    s += &block(
        "distortion_coefficients",
        1,
        coefficients.len(),
        &coefficients,
    );
    s += &block("rectification_matrix", 3, 3, &row_major(r));
    s += &block("projection_matrix", 3, 4, &row_major(p));
    Some(s)
}

/// Each camera's R and P: OpenCV's stereo rectification for a pinhole-like pair,
/// the monocular R = I, P = [K | 0] otherwise (with a warning for a pair that
/// cannot be rectified this way).
fn rectifications(
    c: &CalibrationJson,
    warnings: &mut Vec<String>,
) -> Vec<(Matrix3<f64>, Matrix3x4<f64>)> {
    let mono = |cam: &CameraJson| {
        let mut p = Matrix3x4::zeros();
        p.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&cam.intrinsics.camera_matrix());
        (Matrix3::identity(), p)
    };
    if let [a, b] = c.cameras.as_slice() {
        let same_size = (a.width, a.height) == (b.width, b.height);
        let rect = same_size
            .then(|| {
                stereo_rectify(
                    &a.intrinsics,
                    &b.intrinsics,
                    (a.width, a.height),
                    &b.rotation,
                    &b.translation,
                )
            })
            .flatten();
        if let Some(r) = rect {
            return vec![(r.r1, r.p1), (r.r2, r.p2)];
        }
        warnings.push(format!(
            "ROS camera_info: no stereo rectification for `{}` ({}) and `{}` ({}): OpenCV's stereoRectify needs two pinhole-like cameras of one image size; each file has R = I, P = [K | 0]",
            super::common::printable(&a.name), a.model, super::common::printable(&b.name), b.model
        ));
    }
    c.cameras.iter().map(mono).collect()
}

/// The ROS files of a calibration: (file name, contents) per camera ROS can
/// describe; a camera left out adds a warning.
pub fn camera_infos(c: &CalibrationJson, warnings: &mut Vec<String>) -> Vec<(String, String)> {
    let rects = rectifications(c, warnings);
    let mut files = Vec::new();
    for (cam, (r, p)) in c.cameras.iter().zip(&rects) {
        let file = ros_file_name(&cam.name);
        match camera_info(cam, r, p) {
            Some(text) => files.push((file, text)),
            None => warnings.push(format!(
                "{}: not written: ROS has no `{}` lens model",
                super::common::printable(&file),
                cam.model
            )),
        }
    }
    files
}
