//! The model layer: the mathematics of calibration, pure Rust. No file I/O, no
//! C++; everything here can be tested and reused without the solver.
pub mod board;
pub mod camera;
pub mod dataset;
pub mod epipolar;
pub mod fisheye_init;
pub mod lens;
pub mod metrics;
pub mod pose;
pub mod rig;
pub mod selection;
pub mod sfm_geometry;
pub mod sfm_scene;
pub mod state;
pub mod synthetic;
pub mod target;
pub mod trust;
pub mod uncertainty;
pub mod zhang;
