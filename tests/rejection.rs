//! Outlier rejection without a footprint: what a calibration delivers after
//! rejecting observations is the calibration of the observations it kept, for
//! every method and lens model, and with 3 % gross outliers on a bending board
//! every method stays near its clean result.
use crate::common;
use common::*;
use deformcal::model::lens::LensModel;
use deformcal::model::metrics::mapping_error;
use deformcal::model::synthetic::{Generator, Preset, Truth};
use deformcal::solver::problem::SolverSettings;
use deformcal::{Dataset, Method};

fn bending(model: LensModel, frames: usize, seed: u64) -> (Dataset, Truth) {
    Generator::new(Preset::T2, Some(frames), seed)
        .with_models(&[model])
        .generate()
}

#[test]
fn a_calibration_that_rejected_equals_one_of_the_kept_observations() {
    let models = [
        LensModel::Radial3,
        LensModel::OpenCv5,
        LensModel::OpenCv8,
        LensModel::Kb4,
        LensModel::DoubleSphere,
    ];
    for (k, model) in models.into_iter().enumerate() {
        let (mut d, _) = bending(model, 20, 30 + k as u64);
        displace(&mut d, 3, 3.0, 15.0);
        for method in [
            Method::Standard,
            Method::Static,
            Method::Dynamic,
            Method::Full,
        ] {
            let with = run_with(&d, method, SolverSettings::recommended());
            assert!(
                !with.rejected.is_empty(),
                "{model:?} {method}: nothing rejected"
            );
            let kept = run_with(
                &with.dataset,
                method,
                SolverSettings {
                    outlier_k: 0.0,
                    ..SolverSettings::recommended()
                },
            );
            let cam = &d.cameras[0];
            let apart = mapping_error(
                &with.state.intrinsics[0],
                &kept.state.intrinsics[0],
                cam.width,
                cam.height,
            );
            eprintln!(
                "{model:?} {method}: {} rejected; {apart:.2e} px from the kept data's calibration",
                with.rejected.len()
            );
            assert!(apart <= 0.01, "{model:?} {method}: {apart} px");
        }
    }
}

#[test]
fn gross_outliers_on_a_bending_board_leave_every_method_near_its_clean_result() {
    for seed in [41, 42, 43] {
        let (clean, t) = bending(LensModel::OpenCv5, 30, seed);
        let mut dirty = clean.clone();
        let moved = displace(&mut dirty, 3, 3.0, 15.0);
        assert!(moved > 0);
        for method in [
            Method::Standard,
            Method::Static,
            Method::Dynamic,
            Method::Full,
        ] {
            let settings = SolverSettings::recommended();
            let base = truth_error_rot(&run_with(&clean, method, settings.clone()), &t, 0);
            let with = run_with(&dirty, method, settings);
            let e = truth_error_rot(&with, &t, 0);
            eprintln!(
                "seed {seed} {method}: clean {base:.4} px, with {moved} outliers {e:.4} px ({} rejected)",
                with.rejected.len()
            );
            assert!(
                e <= 1.5 * base + 0.05,
                "seed {seed} {method}: {e} vs clean {base}"
            );
        }
    }
}
