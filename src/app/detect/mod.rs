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
//!    blur and distortion but only ~0.2 px accurate. Its corner response is
//!    computed coarse to fine (seeds on a downscaled level) first; a view not
//!    found complete that way is searched again over the full image.
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
//! inverse of its normal matrix. [`Corner::weight`] = σ_ref/σ capped at 1
//! ([`observation_weight`], σ_ref = [`SIGMA_REF`] = 0.05 px): the weight of
//! the corner's residual in the calibration, set once here and carried
//! unchanged through the detection cache into the dataset.
//!
//! # API
//! - [`detect_file`], [`detect_image`]: one-call detection with defaults.
//! - [`Detector`]: the same with settings; `&self` methods, `Send + Sync`, so
//!   one detector can be shared across rayon workers.
//! - [`render`]: the synthetic-board renderer (public so the integration
//!   tests and the benchmark can draw photos with known truth).

mod api;
pub mod charuco;
mod charuco_spec;
mod grow;
pub mod load;
pub mod orient;
mod pipeline;
pub mod refine;
pub mod render;
mod types;

pub use api::{detect_file, detect_image};
pub use types::{observation_weight, Corner, Detection, Detector, Rejection, ALGORITHM, SIGMA_REF};
