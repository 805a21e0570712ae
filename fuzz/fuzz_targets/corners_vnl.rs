#![no_main]
//! The corners.vnl parser never panics, with and without camera patterns.
use deformcal::model::camera::CameraSpec;
use deformcal::app::corners_vnl::parse_corners_vnl;
use deformcal::{LensModel, Target};
use libfuzzer_sys::fuzz_target;
use std::collections::BTreeMap;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Some((&mode, data)) = data.split_first() else { return };
    let target = Target { rows: 2, cols: 2, spacing: 0.05 };
    let camera = |n: &str| CameraSpec::new(n, 640, 480, LensModel::Radial3);
    let (cameras, patterns) = if mode % 2 == 0 {
        (vec![camera("cam0")], BTreeMap::new())
    } else {
        let p = BTreeMap::from([("cam0".to_string(), "l*".to_string()), ("cam1".to_string(), "r*?.png".to_string())]);
        (vec![camera("cam0"), camera("cam1")], p)
    };
    if let Ok((d, _)) = parse_corners_vnl(data, Path::new("/fuzz/corners.vnl"), target, cameras, &patterns) {
        for o in &d.observations {
            assert!(o.corner < 4 && o.weight > 0.0 && o.weight.is_finite());
        }
    }
});
