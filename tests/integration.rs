//! Every integration test, in one binary: one link against Ceres instead of one per
//! area. Each area is a module (a file beside this one); `every_test_file_is_a_module`
//! fails when a test file is not listed here (it would silently not run).
mod common;
mod detect_common;

mod advise;
mod auto;
mod bad_inputs;
mod board;
mod capi;
mod charuco;
mod cli;
mod compare;
mod covariance_dense;
mod cpp_example;
mod degenerate;
mod detect;
mod detect_bad_files;
mod docs_links;
mod engine;
mod exports;
mod fisheye_photos;
mod flags;
mod guard_rails;
mod interchange;
mod layers;
mod lens_models;
mod mrcal_uncertainty;
mod opencv;
mod opencv_photos;
mod photo_noise;
mod photos;
mod pose_refit;
mod printable;
mod protocol;
mod protocol_shards;
mod python;
mod real_stereo;
mod rejection;
mod report_html;
mod rig;
mod robustness;
mod sfm;
mod slurm;
mod trust;
mod uncertainty;
mod video;

/// A test file missing above would compile nowhere and run never (`autotests = false`).
#[test]
fn every_test_file_is_a_module() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests");
    let listed = include_str!("integration.rs");
    for entry in std::fs::read_dir(&dir).expect("tests/ is readable") {
        let path = entry.expect("a directory entry").path();
        let (Some(stem), Some("rs")) = (
            path.file_stem().and_then(|s| s.to_str()),
            path.extension().and_then(|s| s.to_str()),
        ) else {
            continue;
        };
        if stem != "integration" {
            assert!(
                listed.contains(&format!("\nmod {stem};\n")),
                "tests/{stem}.rs is not a module of tests/integration.rs, so it never runs"
            );
        }
    }
}
