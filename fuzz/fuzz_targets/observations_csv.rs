#![no_main]
//! The observations CSV parser never panics, and what it accepts is consistent.
use deformcal::model::camera::CameraSpec;
use deformcal::{LensModel, Target};
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let target = Target { rows: 4, cols: 5, spacing: 0.05 };
    let cameras: Vec<CameraSpec> = ["cam0", "cam1"]
        .iter()
        .map(|n| CameraSpec::new(*n, 640, 480, LensModel::Radial3))
        .collect();
    if let Ok(d) = deformcal::app::observations_csv::parse(data, Path::new("/fuzz/obs.csv"), target, cameras) {
        assert!(!d.observations.is_empty());
        for o in &d.observations {
            assert!(o.camera < 2 && o.frame < d.frame_ids.len() && o.corner < 20);
            assert!(o.uv[0].is_finite() && o.uv[1].is_finite());
        }
    }
});
