//! The config as written: one serde shape per TOML section, unknown keys rejected.
//! Values are only typed here; [`super::checks`] decides what they may be.
use super::calibration::CalibrationConfig;
use super::protocol::ProtocolConfig;
use crate::model::camera::CameraSpec;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::PathBuf;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawData {
    pub(super) observations: Option<PathBuf>,
    pub(super) corners_vnl: Option<PathBuf>,
    #[serde(default)]
    pub(super) camera_patterns: BTreeMap<String, String>,
    pub(super) synthetic: Option<String>,
    pub(super) images: Option<usize>,
    pub(super) seed: Option<u64>,
    pub(super) cameras: Option<usize>,
    pub(super) photos: Option<PhotoPatterns>,
    pub(super) video: Option<PathBuf>,
    pub(super) stride: Option<usize>,
    pub(super) max_frames: Option<usize>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawReference {
    pub(super) observations: Option<PathBuf>,
    pub(super) synthetic: Option<String>,
    pub(super) images: Option<usize>,
    pub(super) seed: Option<u64>,
    pub(super) cameras: Option<usize>,
    pub(super) rows: Option<usize>,
    pub(super) cols: Option<usize>,
    pub(super) spacing: Option<f64>,
}

/// `[target]`: the board, and optionally a measured board (`board.json`).
pub(super) use crate::app::target_config::TargetSection as RawTarget;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawOutput {
    pub(super) dir: PathBuf,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawConfig {
    pub(super) target: Option<RawTarget>,
    #[serde(default)]
    pub(super) cameras: Vec<CameraSpec>,
    pub(super) data: RawData,
    pub(super) reference: Option<RawReference>,
    #[serde(default)]
    pub(super) calibration: CalibrationConfig,
    pub(super) protocol: Option<ProtocolConfig>,
    pub(super) sfm: Option<crate::app::sfm::SfmConfig>,
    pub(super) output: Option<RawOutput>,
}

/// `[data] photos`: one glob for one camera, or one glob per camera name.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum PhotoPatterns {
    /// One camera: one frame per matching file, in sorted name order.
    One(String),
    /// Several cameras: what the wildcards matched is the time step.
    PerCamera(BTreeMap<String, String>),
}
