//! Lens models (docs/conventions.md §1): the registry of every model deformcal knows,
//! and intrinsics of any of them with projection and unprojection in f64.
//!
//! The registry is the one place a model is described. `model.rs` names the
//! models ([`LensModel`], [`LensModel::ALL`]); one file per model (`radial3.rs`,
//! `kb4.rs`, …) holds its entry, a [`LensInfo`]: config name, parameter names
//! (also the keys of `calibration.json`), help text, projection and unprojection,
//! the start of its initialisation, the simulated camera, and what OpenCV, ROS,
//! Kalibr, COLMAP and mrcal call it and how they hold it; `registry.rs` maps each
//! model to its entry ([`LensModel::info`]). Generic code reads these facts and
//! names no model. The C++ core has the same models, one header each, in
//! `cpp/lens/`; a test checks that both projections agree for every model, and
//! `tests.rs` that every entry is complete.
mod derivatives;
mod ds;
mod info;
mod intrinsics;
mod kb4;
mod model;
mod opencv5;
mod opencv8;
mod opencv_family;
mod pinhole;
mod pinhole_like;
mod projection;
mod radial3;
mod registry;

pub use derivatives::PixelDerivatives;
pub use info::{ColmapForm, KalibrForm, LensInfo, OpenCvForm};
pub use intrinsics::Intrinsics;
pub use model::{LensModel, MAX_PARAMS};
pub use projection::{
    Derivatives, DistortionDerivatives, PointDerivatives, Projection, MAX_DISTORTION,
};

#[cfg(test)]
mod tests;
