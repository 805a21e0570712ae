//! deformcal: camera calibration with chessboards that bend while carried.
//!
//! Implements the four methods of Hagemann, Knorr and Stiller (WACV 2022) —
//! `standard`, `static`, `dynamic`, `full` — over a Ceres core in C++.
pub mod calibrate;
pub mod camera;
pub mod capi;
pub mod config;
pub mod deformation;
pub mod error;
pub mod ffi;
pub mod interchange;
pub mod metrics;
pub mod observations;
pub mod output;
pub mod plots;
pub mod problem;
pub mod protocol;
pub mod protocol_report;
pub mod report;
pub mod rig;
pub mod synthetic;
pub mod target;
pub mod zhang;

pub use calibrate::{calibrate, Calibration, Request};
pub use camera::{Intrinsics, Pose};
pub use config::Config;
pub use deformation::{Method, Paraboloid};
pub use error::{Error, Result};
pub use observations::{Dataset, Observation};
pub use target::Target;

use config::DataSource;

/// Loads the dataset a data source names, for the given board and cameras.
pub fn load_source(
    source: &DataSource,
    target: Target,
    cameras: &[config::CameraSpec],
) -> Result<(Dataset, Option<synthetic::Truth>)> {
    match source {
        DataSource::Observations(path) => {
            Ok((Dataset::read_csv(path, target, cameras.to_vec())?, None))
        }
        DataSource::CornersVnl { path, patterns } => {
            let (d, _) = interchange::read_corners_vnl(path, target, cameras.to_vec(), patterns)?;
            Ok((d, None))
        }
        DataSource::Synthetic {
            preset,
            images,
            seed,
            cameras: n,
        } => {
            let (mut d, t) = synthetic::Generator::new(*preset, *images, *seed)
                .with_cameras(*n)
                .generate();
            // The config may rename the simulated cameras.
            for (spec, given) in d.cameras.iter_mut().zip(cameras) {
                spec.name = given.name.clone();
            }
            Ok((d, Some(t)))
        }
    }
}
