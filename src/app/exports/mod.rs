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

/// A camera name as it may stand in a comment or a message line: control
/// characters and Unicode line separators become escapes, so a name read from a
/// hand-edited calibration.json cannot end the comment and write a value of its own
/// (config names are restricted to a safe set; see docs/conventions.md).
pub fn printable(name: &str) -> String {
    let mut s = String::with_capacity(name.len());
    for c in name.chars() {
        if c.is_control() || c == '\u{2028}' || c == '\u{2029}' {
            s.extend(c.escape_default());
        } else {
            s.push(c);
        }
    }
    s
}

/// Two cameras whose names become the same name in an export.
#[derive(Debug, Clone, PartialEq)]
pub struct NameClash {
    /// The index of the earlier camera.
    pub first: usize,
    /// The index of the later camera.
    pub second: usize,
    /// What both would be written as, e.g. "opencv.yaml key prefix `a_b_`".
    pub what: String,
}

/// The first pair of cameras whose names collide in any export: the file names
/// (`<camera>.cameramodel`, `<camera>_camera_info.yaml`, `uncertainty_<camera>.svg`
/// share one stem, compared without case because macOS and Windows file systems
/// ignore it) and the keys (opencv.yaml's `<camera>_` prefixes, ROS `camera_name`,
/// Kalibr's rostopic). Kalibr's `camN` and COLMAP's ids are numbered, so unique.
/// A reader given a collided key returns one camera's values for both.
pub fn name_clash<'a>(names: impl IntoIterator<Item = &'a str>) -> Option<NameClash> {
    let mut files = std::collections::BTreeMap::new();
    let mut keys = std::collections::BTreeMap::new();
    for (k, name) in names.into_iter().enumerate() {
        let stem = file_stem(name);
        if let Some(&first) = files.get(&stem.to_lowercase()) {
            return Some(NameClash {
                first,
                second: k,
                what: format!("the file `{}`", model_file_name(name)),
            });
        }
        files.insert(stem.to_lowercase(), k);
        let key = key_of(name);
        if let Some(&first) = keys.get(&key) {
            return Some(NameClash {
                first,
                second: k,
                what: format!("opencv.yaml key prefix `{key}_` (and ROS camera_name `{key}`)"),
            });
        }
        keys.insert(key, k);
    }
    None
}

/// Why a camera is left out of an export format.
fn unrepresentable(format: &str, c: &CameraJson) -> String {
    format!(
        "{format}: camera `{}` is left out: the format has no `{}` lens model",
        printable(&c.name),
        c.model
    )
}

/// A camera name made safe for a file name: path separators and control
/// characters (NUL, newlines) become `_`.
pub fn file_stem(camera: &str) -> String {
    camera
        .chars()
        .map(|c| {
            if c == '/' || c == '\\' || c.is_control() {
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
