//! deformcal: camera calibration with chessboards that bend while they are carried.
//!
//! Implements the four methods of Hagemann, Knorr and Stiller (WACV 2022),
//! `standard`, `static`, `dynamic` and `full`, over a Ceres core in C++.
//!
//! # Layout
//! Three layers, each depending only on the ones before it (checked by
//! `tests/layers.rs`):
//! - [`model`]: the mathematics, pure Rust with no I/O and no C++: lens models,
//!   poses, board models, datasets, initialisation, metrics, synthetic data.
//! - [`solver`]: the Ceres problem behind the one cxx bridge, the gauge, and the
//!   calibration pipeline (initialise → `standard` → the method).
//! - [`app`]: everything that meets the user: config, file formats, the
//!   evaluation protocol, reports, plots and the C API.
//!
//! # Glossary
//! - **target** (or board): the printed chessboard, `rows × cols` inner corners.
//!   "Board" is used for its geometry (board point, board frame, board model).
//! - **corner**: one inner corner of the target, index `row * cols + col`.
//! - **frame**: one time step; all cameras of a rig see the target in the same
//!   pose during a frame. With one camera, a frame is one image.
//! - **view**: one camera's image of one frame.
//! - **method**: what is estimated of the board's shape (`standard`, `static`,
//!   `dynamic`, `full`); each method is one board model of the solver.
//! - **lens model**: the camera's projection (`radial3`, …), named by `model`.
//! - Transforms are named `to_from_from`: `camera_from_board` maps board points
//!   into the camera frame.
pub mod app;
pub mod error;
pub mod model;
pub mod solver;

pub use app::config::Config;
pub use error::{Error, Result};
pub use model::board::{Method, Paraboloid};
pub use model::camera::CameraSpec;
pub use model::dataset::{Dataset, Observation};
pub use model::lens::{Intrinsics, LensModel};
pub use model::pose::Pose;
pub use model::target::Target;
pub use solver::calibrate::{calibrate, Calibration, Request};
