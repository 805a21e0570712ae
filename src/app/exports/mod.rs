//! Exports of a calibration for the tools around it: OpenCV FileStorage YAML, mrcal
//! `.cameramodel` (with the problem as `optimization_inputs` where mrcal has it), ROS `camera_info` YAML (with OpenCV's stereo rectification for a
//! pair), a Kalibr `camchain.yaml` and COLMAP `cameras.txt`.
//!
//! Every writer follows one rule: a camera is written only where the format has
//! its lens model exactly; otherwise it is left out with a one-line warning, never
//! approximated.
mod colmap;
mod common;
mod kalibr;
mod mrcal;
mod mrcal_inputs;
mod npz;
mod opencv;
mod rectify;
mod ros;

pub use colmap::{cameras_txt, COLMAP_FILE};
use common::key_of;
pub use common::{file_stem, model_file_name, printable};
pub use kalibr::{camchain_yaml, KALIBR_FILE};
pub use mrcal::mrcal_cameramodel;
pub use mrcal_inputs::{optimization_inputs, OptimizationInputs, NOT_IN_CALIBRATION_JSON};
pub use opencv::opencv_yaml;
pub use rectify::{stereo_rectify, Rectification};
pub use ros::{camera_infos, ros_file_name, ROS_SUFFIX};

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
