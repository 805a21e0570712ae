//! Exports of a calibration for the tools around it: OpenCV FileStorage YAML, mrcal
//! `.cameramodel` (with the problem as `optimization_inputs` where mrcal has it), ROS `camera_info` YAML (with OpenCV's stereo rectification for a
//! pair), a Kalibr `camchain.yaml` and COLMAP `cameras.txt`.
//!
//! Every writer follows one rule: a camera is written only where the format has
//! its lens model exactly; otherwise it is left out with a one-line warning, never
//! approximated.
use crate::app::calibration_json::CameraJson;

mod colmap;
mod kalibr;
mod mrcal;
mod mrcal_inputs;
mod npz;
mod opencv;
mod rectify;
mod ros;

pub use colmap::{cameras_txt, COLMAP_FILE};
pub use kalibr::{camchain_yaml, KALIBR_FILE};
pub use mrcal::mrcal_cameramodel;
pub use mrcal_inputs::{optimization_inputs, OptimizationInputs, NOT_IN_CALIBRATION_JSON};
pub use opencv::opencv_yaml;
pub use rectify::{stereo_rectify, Rectification};
pub use ros::{camera_infos, ros_file_name, ROS_SUFFIX};

/// A number as Rust writes it: shortest round-trip form, always with a `.` or an
/// exponent (`500.0`, not `500`), so YAML readers that check for floats (Kalibr
/// does) accept it and no digit is lost.
fn fmt(v: f64) -> String {
    format!("{v:?}")
}

/// A key from a camera name: letters, digits and underscores, starting with a
/// letter (OpenCV FileStorage keys, ROS camera names).
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

/// Why a camera is left out of an export format.
fn unrepresentable(format: &str, c: &CameraJson) -> String {
    format!(
        "{format}: camera `{}` is left out: the format has no `{}` lens model",
        c.name, c.model
    )
}

/// A camera name made safe for a file name: path separators and NUL become `_`.
pub fn file_stem(camera: &str) -> String {
    camera
        .chars()
        .map(|c| {
            if c == '/' || c == '\\' || c == '\0' {
                '_'
            } else {
                c
            }
        })
        .collect()
}

/// A file name for a camera's model: its name with path separators replaced.
pub fn model_file_name(camera: &str) -> String {
    format!("{}.cameramodel", file_stem(camera))
}
