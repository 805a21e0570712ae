//! The noise σ̂ that a photo calibration reports against the true corner error of
//! rendered photos: the corners' true positions are known, so their detection
//! error is measured directly and σ̂ (from the calibration's residuals, with the
//! corner refinement's per-corner σ as relative weights) must match it.
use crate::common;
use crate::detect_common;

use common::run;
use deformcal::app::detect::detect_image;
use deformcal::app::detect::render::render_board;
use deformcal::model::dataset::DetectedCorner;
use deformcal::solver::problem::Loss;
use deformcal::Method;
use deformcal::{CameraSpec, Dataset, LensModel, Target};
use detect_common::*;

/// Varied tilted views (rotation, distance, shift, bend in m).
const VIEWS: [([f64; 3], f64, [f64; 2], f64); 12] = [
    ([0.45, -0.1, 0.05], 0.55, [0.0, 0.0], 0.0),
    ([-0.4, 0.2, 0.1], 0.55, [0.02, 0.01], 0.003),
    ([0.1, 0.5, -0.1], 0.6, [-0.03, 0.0], 0.0),
    ([0.2, -0.45, 0.2], 0.5, [0.03, -0.02], 0.002),
    ([-0.3, -0.35, 1.6], 0.6, [0.0, 0.03], 0.002),
    ([0.35, 0.35, -0.2], 0.45, [-0.05, -0.04], 0.0),
    ([-0.5, 0.0, 0.0], 0.6, [0.05, 0.05], 0.001),
    ([0.0, 0.45, 3.0], 0.5, [0.06, -0.05], 0.0),
    ([0.25, 0.25, 0.3], 0.5, [-0.08, 0.0], 0.003),
    ([0.3, -0.3, -0.1], 0.5, [-0.06, 0.05], 0.003),
    ([-0.2, 0.4, 0.8], 0.55, [0.04, 0.02], 0.0),
    ([0.4, 0.2, -0.6], 0.5, [-0.02, -0.03], 0.002),
];

/// Renders the views at `noise` grey levels and `blur` px, detects them, and returns
/// the weighted dataset with the weighted RMS per coordinate of the true detection
/// error (the σ that a weight-1 corner has).
fn photos(noise: f64, blur: f64) -> (Dataset, f64) {
    let (rows, cols) = (6, 9);
    let mut corners = Vec::new();
    let (mut sq, mut n) = (0.0, 0.0);
    for (k, (rvec, dist, shift, bend)) in VIEWS.into_iter().enumerate() {
        let mut sc = scene(rows, cols, rvec, dist, shift);
        sc.bend = bend;
        sc.noise = noise;
        sc.blur = blur;
        sc.seed = 100 + k as u64;
        sc.supersample = 4;
        let (img, truth) = render_board(&sc);
        let det = detect_image(&image::DynamicImage::ImageLuma8(img), rows, cols)
            .unwrap_or_else(|e| panic!("view {k}: {e:?}"));
        for c in &det.corners {
            let t = truth[c.index].expect("a detected corner is in view");
            let w = c.weight;
            sq += w * w * ((c.uv[0] - t[0]).powi(2) + (c.uv[1] - t[1]).powi(2));
            n += 2.0;
            corners.push(DetectedCorner {
                camera: 0,
                frame_id: k as i64,
                corner: c.index,
                uv: c.uv,
                weight: w,
            });
        }
    }
    let target = Target {
        rows,
        cols,
        spacing: 0.03,
    };
    let camera = CameraSpec::new("cam0", W, H, LensModel::Radial3);
    let d = Dataset::from_detected(target, vec![camera], corners);
    (d, (sq / n).sqrt())
}

#[test]
fn photo_noise_estimate_matches_the_true_corner_error() {
    for (noise, blur) in [(1.0, 0.9), (4.0, 0.9), (12.0, 0.9), (4.0, 1.5), (12.0, 1.5)] {
        let (d, true_sigma) = photos(noise, blur);
        let c = run(&d, Method::Dynamic, Loss::Cauchy);
        let est = c.trust(None).expect("a noise estimate").noise_px;
        eprintln!(
            "noise {noise} blur {blur}: true corner σ {true_sigma:.4} px, σ̂ {est:.4} px ({:.2}×)",
            est / true_sigma
        );
        // The 1.4 that the uncertainty must hold to (issue 14).
        assert!(
            (1.0 / 1.4..=1.4).contains(&(est / true_sigma)),
            "noise {noise} blur {blur}: σ̂ {est} against the true {true_sigma}"
        );
    }
}
