//! The solver layer: the Ceres problem in `cpp/` behind one cxx bridge, the gauge
//! and what is held fixed, and the calibration pipeline. Depends on the model
//! layer only; knows nothing of files or configs.
pub mod auto_prior;
mod bridge;
pub mod calibrate;
pub mod covariance;
pub mod health;
pub mod identifiable;
pub mod problem;
mod repose;
pub mod residuals;
pub mod robust;
pub mod select;
pub mod sfm;
mod trust;
pub mod uncertainty;
