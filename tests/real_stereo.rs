//! Modelling the bend on real stereo photos, judged by figures a bent board cannot
//! win (docs/real-photos.md): OpenCV's sample pairs (left01…right14.jpg, 9×6 board)
//! split into halves in seeded splits; every method, and `auto`, calibrates the rig
//! on one half under `radial3` and `opencv5`, and `model::epipolar` measures the
//! epipolar distance and the triangulation error on the other half.
//!
//! What must hold whichever method `auto` chooses: every calibration puts the
//! held-out corners within 1 px of their epipolar lines (known-good photos); `auto`
//! loses to `standard` in epipolar distance on average by no more than the splits'
//! spread, and in triangulation error by less than 5 %; and on the
//! same training corners `standard` is within 5 % of OpenCV's stereoCalibrate
//! refining both lenses with the rig (CALIB_USE_INTRINSIC_GUESS, as `standard`
//! does), and no more than 5 % worse than OpenCV's textbook stereo calibration
//! (calibrateCamera per camera, then stereoCalibrate with CALIB_FIX_INTRINSIC).
//! Measured: the textbook calibration is 5–6 % worse than both joint ones, since
//! each lens is fixed from its own views before the rig is known
//! (docs/real-photos.md). benches/stereo_photos.rs runs more splits.
use crate::common::sample_photos;
#[path = "common/stereo_split.rs"]
mod stereo_split;

use deformcal::Target;
use stereo_split::*;

/// Few splits: CI runs this test; the bench runs the full set.
const SPLITS: usize = 7;

/// OpenCV's sample board: 9 × 6 inner corners (the square size is not published;
/// any value gives the same pixels, and the millimetres scale with it).
const BOARD: Target = Target {
    rows: 6,
    cols: 9,
    spacing: 0.025,
};

#[test]
fn held_out_stereo_figures_on_opencv_sample_photos() {
    let photos = match sample_photos::sample_photos() {
        Ok(p) => p,
        Err(reason) => {
            eprintln!("skipped: cannot fetch opencv-doc's sample photos: {reason}");
            return;
        }
    };
    let work = tempfile::tempdir().unwrap();
    let data = load(&photos, BOARD, work.path()).unwrap();
    assert_eq!(data.cameras.len(), 2);
    assert_eq!(data.num_frames(), 13, "left01…right14 without 10");

    let splits = splits(data.num_frames(), SPLITS);
    let mut outcomes = run(&data, &splits);
    let opencv = have_opencv();
    if opencv {
        outcomes.extend(run_opencv(&data, &splits));
    } else {
        eprintln!("SKIPPED the comparison with OpenCV: {PYTHON} cannot import cv2 (apt-get install python3-opencv)");
    }
    let rows = rows(&outcomes);
    eprintln!("{}", table(&rows, SPLITS));

    for o in outcomes.iter().filter(|o| o.method != "opencv") {
        let e = &o.errors;
        assert!(
            e.epipolar_mean_px.is_finite() && e.epipolar_mean_px < 1.0,
            "split {} {} {}: {e:?}",
            o.split,
            o.model,
            o.method
        );
        assert!(e.triangulation_rms_mm.is_finite(), "{o:?}");
        assert!(e.pairs >= 200, "six held-out pairs of 54 corners: {e:?}");
    }
    let row = |method: &str, model| {
        rows.iter()
            .find(|r| r.method == method && r.model == model)
            .unwrap()
    };
    for model in MODELS {
        let auto = row("auto", model);
        let d = auto.epipolar_vs_standard;
        assert!(
            d.mean <= d.std + 1e-12,
            "{model}: auto − standard, epipolar px: {:.4} ± {:.4} over the splits",
            d.mean,
            d.std
        );
        // The triangulation error is mostly the held-out boards' own shape, the
        // same for every calibration (0.37–0.40 mm measured); methods differ by
        // about 0.01 mm, and `dynamic` is that much worse on 7 splits, beyond their
        // spread: only a gross loss is a failure whichever method `auto` chooses.
        let (a, s) = (
            auto.triangulation.mean,
            row("standard", model).triangulation.mean,
        );
        assert!(
            a < 1.05 * s,
            "{model}: triangulation error auto {a:.3} mm, standard {s:.3} mm"
        );
        if opencv {
            let ours = row("standard", model).epipolar.mean;
            let textbook = row("opencv", model).epipolar.mean;
            let joint = row("opencv-joint", model).epipolar.mean;
            assert!(
                (ours / joint - 1.0).abs() < 0.05,
                "{model}: standard {ours:.4} px, OpenCV's stereoCalibrate refining the lenses {joint:.4} px"
            );
            assert!(
                ours < 1.05 * textbook,
                "{model}: standard {ours:.4} px, OpenCV with CALIB_FIX_INTRINSIC {textbook:.4} px"
            );
        }
    }
}
