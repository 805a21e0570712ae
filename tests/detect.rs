//! Detection against rendered ground truth: accuracy ≤ 0.1 px RMS, correct
//! indexing, partial views, ambiguity and failure reasons.
mod detect_common;

use detect_common::*;
use deformcal::app::detect::render::render_board;
use deformcal::app::detect::{Detector, Rejection, detect_image};
use image::DynamicImage;

/// Fully visible boards in varied poses must be found complete, indexed
/// exactly (9×6: no symmetry at all) and accurate.
#[test]
fn full_9x6_boards_any_orientation() {
    let poses = [
        [0.0, 0.0, 0.05],
        [0.4, -0.3, 0.2],
        [-0.35, 0.25, 3.1],
        [0.2, 0.45, 1.5],
        [0.3, 0.1, -1.7],
    ];
    for (k, rvec) in poses.into_iter().enumerate() {
        let mut sc = scene(6, 9, rvec, 0.55, [0.01, -0.01]);
        sc.seed = k as u64;
        let (det, truth) = run(&sc);
        let det = det.unwrap_or_else(|e| panic!("pose {k}: {e}"));
        assert!(det.complete, "pose {k}: {} corners", det.corners.len());
        let rms = rms_if_indexed(&det, &truth, 6, 9).expect("exact indexing");
        // No symmetry for 9×6: the identity map must be the one that matched.
        let c0 = det.corners[0];
        let t0 = truth[0].unwrap();
        assert!(
            (c0.uv[0] - t0[0]).hypot(c0.uv[1] - t0[1]) < 1.0,
            "pose {k}: corner 0 misplaced"
        );
        assert!(rms <= 0.1, "pose {k}: rms {rms}");
    }
}

#[test]
fn bent_board_with_distortion() {
    let mut sc = scene(6, 9, [0.3, -0.2, 0.1], 0.5, [0.0, 0.0]);
    sc.bend = 0.004;
    sc.camera.k1 = -0.2;
    let (det, truth) = run(&sc);
    let det = det.expect("bent board found");
    assert!(det.complete);
    let rms = rms_if_indexed(&det, &truth, 6, 9).expect("indexing");
    assert!(rms <= 0.1, "rms {rms}");
}

/// Square boards: indexing is only defined up to the colour symmetry, and the
/// tie-break must put board +x towards image +u.
#[test]
fn square_boards() {
    for (n, rvec) in [(7, [0.2, 0.3, 2.0]), (8, [-0.3, 0.2, 3.0]), (8, [0.1, -0.2, 0.4])] {
        let (det, truth) = run(&scene(n, n, rvec, 0.55, [0.0, 0.0]));
        let det = det.unwrap_or_else(|e| panic!("{n}x{n}: {e}"));
        assert!(det.complete);
        let rms = rms_if_indexed(&det, &truth, n, n).expect("indexing up to symmetry");
        assert!(rms <= 0.1, "{n}x{n}: rms {rms}");
        let (a, b) = (det.corners[0].uv, det.corners[n - 1].uv);
        assert!(b[0] - a[0] > 0.0, "{n}x{n}: +x must point right (tie-break rule)");
    }
}

/// Board partly outside the image: the visible board edges pin the placement.
#[test]
fn partly_out_of_view_is_indexed() {
    for (shift, label) in [([-0.17, 0.0], "left cut"), ([0.0, 0.16], "bottom cut")] {
        let sc = scene(6, 9, [0.15, -0.1, 0.05], 0.45, shift);
        let (det, truth) = run(&sc);
        let visible = truth.iter().flatten().count();
        assert!(visible < 54, "{label}: scene should be partial");
        let det = det.unwrap_or_else(|e| panic!("{label}: {e}"));
        assert!(!det.complete);
        assert!(
            det.corners.len() + 6 >= visible,
            "{label}: {} of {visible}",
            det.corners.len()
        );
        let rms = rms_if_indexed(&det, &truth, 6, 9).expect("indexing");
        assert!(rms <= 0.1, "{label}: rms {rms}");
    }
}

/// Occluded middle corners: the extent still spans the board.
#[test]
fn occluded_board_is_indexed() {
    let sc = scene(6, 9, [0.2, 0.2, 0.1], 0.55, [0.0, 0.0]);
    let (mut img, truth) = render_board(&sc);
    let c = truth[2 * 9 + 4].unwrap();
    for y in 0..img.height() {
        for x in 0..img.width() {
            if (x as f64 - c[0]).hypot(y as f64 - c[1]) < 40.0 {
                img.put_pixel(x, y, image::Luma([90]));
            }
        }
    }
    let det = detect_image(&DynamicImage::ImageLuma8(img), 6, 9).expect("occluded board");
    assert!(!det.complete && det.corners.len() >= 44);
    let rms = rms_if_indexed(&det, &truth, 6, 9).expect("indexing");
    assert!(rms <= 0.1, "rms {rms}");
}

/// Only the middle of the board visible, no edge in view: every placement
/// fits, so the view must be rejected as ambiguous.
#[test]
fn central_crop_is_ambiguous() {
    let sc = scene(6, 9, [0.05, 0.05, 0.02], 0.16, [0.0, 0.0]);
    let (det, _) = run(&sc);
    assert_eq!(det, Err(Rejection::PartialAmbiguous));
}

#[test]
fn heavy_blur_is_reported() {
    let mut sc = scene(6, 9, [0.1, 0.1, 0.1], 0.55, [0.0, 0.0]);
    sc.blur = 9.0;
    let (det, _) = run(&sc);
    assert_eq!(det, Err(Rejection::Blurred));
}

#[test]
fn no_board_in_noise() {
    let img = image::GrayImage::from_fn(320, 240, |x, y| {
        image::Luma([((x * 7919 + y * 104729) % 251) as u8])
    });
    let det = detect_image(&DynamicImage::ImageLuma8(img), 6, 9);
    assert!(
        matches!(det, Err(Rejection::NoBoard) | Err(Rejection::Blurred)),
        "{det:?}"
    );
}

/// 16-bit grey and 8-bit colour inputs give the same corners as 8-bit grey.
#[test]
fn bit_depths_and_colour_agree() {
    let sc = scene(6, 9, [0.3, -0.2, 0.3], 0.55, [0.0, 0.0]);
    let (img, truth) = render_board(&sc);
    let g16 = image::ImageBuffer::from_fn(img.width(), img.height(), |x, y| {
        image::Luma([img.get_pixel(x, y)[0] as u16 * 257])
    });
    let rgb = DynamicImage::ImageLuma8(img.clone()).to_rgb8();
    for input in [DynamicImage::ImageLuma16(g16), DynamicImage::ImageRgb8(rgb)] {
        let det = detect_image(&input, 6, 9).expect("detected");
        assert!(det.complete);
        assert!(rms_if_indexed(&det, &truth, 6, 9).expect("indexing") <= 0.1);
    }
}

#[test]
fn weights_are_in_range() {
    let (det, _) = run(&scene(6, 9, [0.2, 0.1, 0.0], 0.55, [0.0, 0.0]));
    for c in det.expect("found").corners {
        assert!(c.weight > 0.0 && c.weight <= 1.0 && c.sigma.is_finite(), "{c:?}");
    }
}

#[test]
fn detector_is_shareable_across_threads() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<Detector>();
}
