//! The detector's vocabulary: a detected corner, a found board, why an image
//! gave none, and the detector's settings. Plain data shared by every stage of
//! the detector (and by its callers); no detection logic here.

use crate::app::detect::charuco_spec::CharucoSpec;

/// Identifies the detector's algorithm in the detection cache: change it with any
/// change that alters results, so detections of an older version are not reused.
pub const ALGORITHM: &str =
    "calib-targets 0.16.1 + deformcal refine 2 + grow 2 + orient 2 + coarse to fine 1";

/// The reference σ (px) of a corner's observation weight σ_ref/σ: a clean,
/// sharp corner's σ is about this.
pub const SIGMA_REF: f64 = 0.05;

/// One detected corner: the observation that goes, unchanged, into the
/// detection cache and the calibration's dataset.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Corner {
    /// row·cols + col.
    pub index: usize,
    /// Pixel position (u, v), OpenCV pixel-centre convention.
    pub uv: [f64; 2],
    /// The weight of its residual, σ_ref/σ in (0, 1] ([`observation_weight`]).
    pub weight: f64,
    /// Estimated 1-σ position uncertainty in pixels.
    pub sigma: f64,
}

impl Corner {
    /// A corner refined to `uv` with uncertainty `sigma`; its weight follows
    /// from `sigma`, here and nowhere else.
    pub fn new(index: usize, uv: [f64; 2], sigma: f64) -> Corner {
        Corner {
            index,
            uv,
            weight: observation_weight(sigma),
            sigma,
        }
    }
}

/// The observation weight of a corner with refinement σ (px): σ_ref/σ, capped
/// at 1, so a residual is in units of the corner's own noise (as 0.5^level is
/// for mrgingham's decimated corners); 1 when σ is not a number.
pub fn observation_weight(sigma: f64) -> f64 {
    if sigma.is_finite() && sigma > SIGMA_REF {
        SIGMA_REF / sigma
    } else {
        1.0
    }
}

/// A found board.
#[derive(Clone, Debug, PartialEq)]
pub struct Detection {
    /// Sorted by index; each index at most once.
    pub corners: Vec<Corner>,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// All rows·cols corners were found.
    pub complete: bool,
    /// The board looks alike turned by 180° (rows + cols even) and the view
    /// was labelled by the orientation rule (see the crate doc), not by
    /// anything printed on the board: the labelling is consistent between
    /// views that show the board the same way up.
    pub labelled_by_symmetry: bool,
}

impl Detection {
    /// A note for `detections.csv`'s reason column, or "" when there is
    /// nothing to say.
    pub fn note(&self) -> &'static str {
        if self.labelled_by_symmetry {
            "labelled by its orientation in the image: the board looks alike turned by 180 degrees"
        } else {
            ""
        }
    }
}

/// Why an image gave no detection. A per-image outcome, not a failure of the
/// run: the caller lists it and goes on with the other images.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Rejection {
    /// No chessboard grid found (or the grid found does not fit rows×cols).
    #[error("no chessboard found")]
    NoBoard,
    /// A partial view that fits the board in more than one place/orientation.
    #[error("partial board with ambiguous orientation")]
    PartialAmbiguous,
    /// No board found and the image has no sharp edges anywhere.
    #[error("image too blurred to find a board")]
    Blurred,
    /// A board was found but with fewer usable corners than required.
    #[error("only {found} corners found, {needed} needed")]
    TooFewCorners { found: usize, needed: usize },
    /// The file could not be read or decoded.
    #[error("unreadable image: {0}")]
    Unreadable(String),
    /// The image exceeds the pixel budget.
    #[error("image {width}x{height} exceeds the limit of {max_pixels} pixels")]
    TooLarge {
        width: u32,
        height: u32,
        max_pixels: u64,
    },
    /// rows or cols < 2.
    #[error("invalid pattern {rows}x{cols}: need at least 2x2 inner corners")]
    InvalidPattern { rows: usize, cols: usize },
    /// The third-party detector panicked; caught so callers never see a panic.
    #[error("internal detector failure: {0}")]
    Internal(String),
}

/// Detector settings. Cheap to clone; all methods take `&self`.
#[derive(Clone, Debug)]
pub struct Detector {
    /// Refuse images with more pixels than this (default 100 MP).
    pub max_pixels: u64,
    /// Fewest corners a detection may have (default 6, and never more than
    /// rows·cols).
    pub min_corners: usize,
    /// A ChArUco board to find instead of a chessboard (`charuco`); rows and
    /// cols given to the detect methods are then the board's inner corners.
    pub charuco: Option<CharucoSpec>,
}

impl Default for Detector {
    fn default() -> Self {
        Detector {
            max_pixels: 100_000_000,
            min_corners: 6,
            charuco: None,
        }
    }
}
