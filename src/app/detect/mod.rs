//! Chessboard corner detection: one decoded image in, indexed sub-pixel corners
//! out. No file listing, caching or reporting here (that is `app::photos`); the
//! only I/O is decoding one image file in [`load`].
//!
//! Finds a rows×cols (INNER corners) chessboard in a photo and returns its
//! corners, refined to sub-pixel precision and identified by grid index
//! `index = row·cols + col` (board x along increasing col, y along increasing
//! row). Pixel convention is OpenCV's: integer coordinates are pixel centres.
//!
//! # Pipeline
//! 1. [`load`]: decode PNG/JPEG/TIFF (8 or 16 bit, grey or colour) with a size
//!    bound, into an 8-bit grey image (for the detector) and an f32 grey image
//!    at full precision (for refinement).
//! 2. The `calib-targets` crate (ChESS X-junction corners + topological grid
//!    labelling) finds and labels the grid; it is robust to partial views,
//!    blur and distortion but only ~0.2 px accurate.
//! 3. [`refine`]: cornerSubPix-style gradient-orthogonality refinement on the
//!    full-precision image (window 0.3× the cell, shrunk to 0.4× a corner's own
//!    spacing where its squares are compressed), which also yields each
//!    corner's uncertainty. A
//!    corner whose refined window is not point-symmetric (occluder, clutter
//!    or board edge in the window) is retried with half the window and
//!    dropped if still asymmetric: a missing corner is harmless, a wrong one
//!    is not.
//! 4. `grow`: extend the labelled grid outward along its rows and columns
//!    (quadratic extrapolation, then refinement in a window shaped by the
//!    local grid vectors), to the compressed squares near a fisheye's rim
//!    that the grid finder gives up on.
//! 5. [`orient`]: place the labelled patch on the board (handedness, square
//!    colour, visible board edges); partial views that fit in several places
//!    are rejected, those that fit the board turned by 180° kept (the
//!    labelling is then by the orientation rule below). A stray corner
//!    labelled just outside the board is trimmed.
//!
//! Failure reasons: `Blurred` when nothing (or too little) was found and the
//! image's sharpest edges are wider than ~10 px (range/max-gradient);
//! `NoBoard` otherwise, or when the grid found cannot be this rows×cols board.
//!
//! # Orientation rule
//! Corner 0 is the inner corner whose diagonally-outer square (board cell
//! x<0, y<0) is DARK, and board x × y has the image's u × v sense (a board
//! seen from its printed side is never labelled mirrored). When the square
//! colours cannot tell the symmetric placements apart (rows+cols even, or
//! square boards for 180°), the placement whose +x axis points most to the
//! right in the image wins, for complete and partial views alike
//! ([`Detection::labelled_by_symmetry`]). For 9×6 (10×7 squares) this matches
//! OpenCV.
//!
//! # Weight
//! [`Corner::sigma`] is the 1-σ positional uncertainty (px, worst axis) of the
//! refinement: residual variance of the gradient-orthogonality fit times the
//! inverse of its normal matrix. [`Corner::weight`] = 1 / (1 + (σ / 0.05 px)²),
//! in (0, 1]: ≈1 for sharp clean corners, falling for noisy/blurred ones. For
//! least squares use 1/σ² directly.
//!
//! # API
//! - [`detect_file`], [`detect_image`]: one-call detection with defaults.
//! - [`Detector`]: the same with settings; `&self` methods, `Send + Sync`, so
//!   one detector can be shared across rayon workers.
//! - [`render`]: the synthetic-board renderer (public so the integration
//!   tests and the benchmark can draw photos with known truth).

pub mod charuco;
mod grow;
pub mod load;
pub mod orient;
pub mod refine;
pub mod render;

mod pipeline;

use std::path::Path;

/// Identifies the detector's algorithm in the detection cache: change it with any
/// change that alters results, so detections of an older version are not reused.
pub const ALGORITHM: &str = "calib-targets 0.16.1 + deformcal refine 2 + grow 2 + orient 2";

/// σ (px) at which [`Corner::weight`] is 0.5, and the reference σ of an
/// observation weight σ_ref/σ (a clean, sharp corner's σ is about this).
pub const SIGMA_REF: f64 = 0.05;

/// One detected corner.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Corner {
    /// row·cols + col.
    pub index: usize,
    /// Pixel position (u, v), OpenCV pixel-centre convention.
    pub uv: [f64; 2],
    /// Quality in (0, 1], see the crate doc.
    pub weight: f64,
    /// Estimated 1-σ position uncertainty in pixels.
    pub sigma: f64,
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
    pub charuco: Option<charuco::CharucoSpec>,
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
