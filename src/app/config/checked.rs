//! The checked config: its data source, rig, reference and settings, with paths
//! resolved against the config's folder. Made only by the checks.
use super::calibration::CalibrationConfig;
use super::protocol::ProtocolConfig;
use super::raw::PhotoPatterns;
use crate::model::camera::CameraSpec;
use crate::model::synthetic::Preset;
use crate::model::target::Target;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Where observations come from.
#[derive(Debug, Clone, PartialEq)]
pub enum DataSource {
    /// Image files in which the board is detected (docs/conventions.md §5 Photos).
    Photos {
        /// The config's folder, which the patterns are relative to.
        base: PathBuf,
        patterns: PhotoPatterns,
    },
    /// A video whose frames are sampled, detected and chosen (docs/video.md).
    Video(VideoSource),
    /// An observations CSV (path resolved against the config's folder).
    Observations(PathBuf),
    /// mrgingham's / mrcal's corners table, with file-name patterns per camera.
    CornersVnl {
        path: PathBuf,
        patterns: BTreeMap<String, String>,
    },
    /// A built-in synthetic preset.
    Synthetic {
        preset: Preset,
        images: Option<usize>,
        seed: u64,
        /// Number of cameras on the simulated rig.
        cameras: usize,
    },
}

/// `[data] stride` when the config gives none: 6 frames a second of a 30 fps video.
pub const DEFAULT_STRIDE: usize = 5;
/// `[data] max_frames` when the config gives none.
pub const DEFAULT_MAX_FRAMES: usize = 40;
/// The least `max_frames`: Zhang's initialisation needs three views.
pub const MIN_MAX_FRAMES: usize = 3;

/// A video and how to sample it (`app::video` reads it) (`[data] video`, `stride`, `max_frames`).
#[derive(Debug, Clone, PartialEq)]
pub struct VideoSource {
    /// The file.
    pub path: PathBuf,
    /// The name the config gives it (relative to the config's folder).
    pub name: String,
    /// Every `stride`-th frame is decoded.
    pub stride: usize,
    /// At most this many frames are calibrated from.
    pub max_frames: usize,
}

/// `[reference]`: the static reference set and its board.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceConfig {
    pub source: DataSource,
    pub target: Target,
}

/// A checked config with paths resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    pub path: PathBuf,
    pub target: Target,
    /// `[target] type = "charuco"`: the ChArUco board the photos show.
    pub charuco: Option<crate::app::detect::charuco::CharucoSpec>,
    pub cameras: Vec<CameraSpec>,
    pub data: DataSource,
    pub reference: Option<ReferenceConfig>,
    pub calibration: CalibrationConfig,
    pub protocol: Option<ProtocolConfig>,
    /// `[sfm]`: the structure-from-motion loop-closure experiment (`app::sfm`).
    pub sfm: Option<crate::app::sfm::SfmConfig>,
    pub output_dir: PathBuf,
}

/// Seed of synthetic data when the config gives none.
pub const DEFAULT_SYNTHETIC_SEED: u64 = 1;
