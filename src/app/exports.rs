//! Exports of a calibration for the tools around it: OpenCV FileStorage YAML and
//! mrcal `.cameramodel`.
use crate::app::calibration_json::{CalibrationJson, CameraJson};
use crate::model::lens::{Intrinsics, LensModel};
use crate::model::pose::Pose;
use std::fmt::Write;

fn fmt(v: f64) -> String {
    format!("{v:?}")
}

fn matrix(name: &str, rows: usize, cols: usize, data: &[f64]) -> String {
    let values: Vec<String> = data.iter().map(|&v| fmt(v)).collect();
    format!(
        "{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: [ {} ]\n",
        values.join(", ")
    )
}

/// A FileStorage key from a camera name: letters, digits and underscores, starting with a letter.
fn key_of(name: &str) -> String {
    let mut k: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if !k.starts_with(|c: char| c.is_ascii_alphabetic()) {
        k.insert_str(0, "cam_");
    }
    k
}

/// OpenCV's name and coefficient vector of a lens model, where OpenCV has it:
/// `calibrateCamera`'s k1 k2 p1 p2 k3 [k4 k5 k6], or `cv::fisheye`'s k1..k4.
fn opencv_distortion(i: &Intrinsics) -> Option<(&'static str, Vec<f64>)> {
    let g = |n: &str| i.get(n).unwrap_or(0.0);
    let (name, keys): (&str, &[&str]) = match i.model() {
        LensModel::Radial3 | LensModel::OpenCv5 => ("plumb_bob", &["k1", "k2", "p1", "p2", "k3"]),
        LensModel::OpenCv8 => (
            "rational_polynomial",
            &["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"],
        ),
        LensModel::Kb4 => ("fisheye", &["k1", "k2", "k3", "k4"]),
        LensModel::DoubleSphere => return None,
    };
    Some((name, keys.iter().map(|k| g(k)).collect()))
}

fn camera_block(prefix: &str, c: &CameraJson, rmse: f64) -> Option<String> {
    let i = &c.intrinsics;
    let (model, coefficients) = opencv_distortion(i)?;
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

/// Why a camera is left out of an export format.
fn unrepresentable(format: &str, c: &CameraJson) -> String {
    format!(
        "{format}: camera `{}` is left out: the format has no `{}` lens model",
        c.name, c.model
    )
}

/// OpenCV FileStorage YAML (SPEC §5): unprefixed keys for one camera; for several,
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
        let Some(block) = camera_block(&prefix, cam, c.rmse_px) else {
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

/// mrcal's `.cameramodel` of one camera, where mrcal has its lens model (radial3
/// is LENSMODEL_OPENCV5 with p1 = p2 = 0, exactly); extrinsics are rt_cam_ref with
/// camera 0 as the reference.
pub fn mrcal_cameramodel(c: &CameraJson) -> Option<String> {
    let i = &c.intrinsics;
    let (lensmodel, values) = match i.model() {
        LensModel::Radial3 => {
            let g = |n: &str| i.get(n).unwrap_or(0.0);
            let v = vec![
                i.fx(),
                i.fy(),
                i.cx(),
                i.cy(),
                g("k1"),
                g("k2"),
                0.0,
                0.0,
                g("k3"),
            ];
            ("LENSMODEL_OPENCV5", v)
        }
        m => (m.info().mrcal?, i.params().to_vec()),
    };
    let intrinsics: Vec<String> = values.iter().map(|&v| fmt(v)).collect();
    let extrinsics: Vec<String> = c
        .rotation
        .iter()
        .chain(&c.translation)
        .map(|&v| fmt(v))
        .collect();
    Some(format!(
        "# generated by deformcal\n{{\n    'lensmodel':  '{lensmodel}',\n    'intrinsics': [ {} ],\n    'extrinsics': [ {} ],\n    'imagersize': [ {}, {} ],\n}}\n",
        intrinsics.join(", "),
        extrinsics.join(", "),
        c.width,
        c.height
    ))
}

/// A file name for a camera's model: its name with path separators replaced.
pub fn model_file_name(camera: &str) -> String {
    let safe: String = camera
        .chars()
        .map(|c| {
            if c == '/' || c == '\\' || c == '\0' {
                '_'
            } else {
                c
            }
        })
        .collect();
    format!("{safe}.cameramodel")
}
