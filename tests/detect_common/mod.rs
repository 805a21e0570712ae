//! Shared helpers for the integration tests: a standard camera and scene,
//! and checks of a detection against rendered truth.
#![allow(dead_code)]

use deformcal::app::detect::render::{render_board, rodrigues, Camera, Pose, Scene};
use deformcal::app::detect::{detect_image, Detection};

pub const W: u32 = 800;
pub const H: u32 = 600;

pub fn camera() -> Camera {
    Camera {
        fx: 700.0,
        fy: 700.0,
        cx: 399.5,
        cy: 299.5,
        k1: -0.12,
        k2: 0.03,
    }
}

/// A rows×cols board of 30 mm squares, rotated by `rvec` about its centre,
/// centred `dist` m in front of the camera and shifted by `shift` (m).
pub fn scene(rows: usize, cols: usize, rvec: [f64; 3], dist: f64, shift: [f64; 2]) -> Scene {
    let s = 0.03;
    let (w, h) = ((cols - 1) as f64 * s, (rows - 1) as f64 * s);
    let r = rodrigues(rvec);
    let c: Vec<f64> = (0..3)
        .map(|i| r[i][0] * w / 2.0 + r[i][1] * h / 2.0)
        .collect();
    Scene {
        camera: camera().into(),
        image_circle_deg: 0.0,
        vignetting: 0.0,
        pose: Pose {
            rvec,
            t: [shift[0] - c[0], shift[1] - c[1], dist - c[2]],
        },
        bend: 0.0,
        rows,
        cols,
        spacing: s,
        width: W,
        height: H,
        blur: 0.9,
        noise: 2.0,
        seed: 7,
        supersample: 8,
    }
}

/// A board-index map (row, col) → (row, col).
pub type IndexMap = Box<dyn Fn(usize, usize) -> (usize, usize)>;

/// Index maps under which the coloured board looks identical (identity first).
pub fn symmetries(rows: usize, cols: usize) -> Vec<IndexMap> {
    let mut v: Vec<IndexMap> = vec![Box::new(|r, c| (r, c))];
    if (rows + cols).is_multiple_of(2) {
        v.push(Box::new(move |r, c| (rows - 1 - r, cols - 1 - c)));
    }
    if rows == cols && rows.is_multiple_of(2) {
        v.push(Box::new(move |r, c| (c, rows - 1 - r)));
        v.push(Box::new(move |r, c| (rows - 1 - c, r)));
    }
    v
}

/// RMS error of the detection against truth under the first index map that
/// puts every corner within 1 px of its truth; None if no map does (wrong
/// indexing).
pub fn rms_if_indexed(
    det: &Detection,
    truth: &[Option<[f64; 2]>],
    rows: usize,
    cols: usize,
) -> Option<f64> {
    symmetries(rows, cols).iter().find_map(|f| {
        let mut se = 0.0;
        for c in &det.corners {
            let (r, k) = f(c.index / cols, c.index % cols);
            let t = truth[r * cols + k]?;
            let e = (t[0] - c.uv[0]).hypot(t[1] - c.uv[1]);
            if e > 1.0 {
                return None;
            }
            se += e * e;
        }
        Some((se / det.corners.len() as f64).sqrt())
    })
}

/// Render and detect; returns the detection result and the truth.
pub fn run(
    scene: &Scene,
) -> (
    Result<Detection, deformcal::app::detect::Rejection>,
    Vec<Option<[f64; 2]>>,
) {
    let (img, truth) = render_board(scene);
    (
        detect_image(
            &image::DynamicImage::ImageLuma8(img),
            scene.rows,
            scene.cols,
        ),
        truth,
    )
}
