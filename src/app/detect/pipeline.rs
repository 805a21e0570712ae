//! The detection pipeline: detector → refinement → indexing → result.
//!
//! Kept apart from mod.rs so the public types there stay readable; each step
//! is a small function so failures map cleanly onto a `Rejection`.

use crate::app::detect::grow;
use crate::app::detect::load;
use crate::app::detect::orient::{self, Labelled, OrientError};
use crate::app::detect::refine::{self, FloatImage};
use crate::app::detect::types::{Corner, Detection, Detector, Rejection};
use calib_targets::chessboard::ChessboardParams;
use calib_targets::detect as ct;
use std::collections::HashMap;
use std::panic::{catch_unwind, AssertUnwindSafe};

/// Largest point-symmetry misfit accepted (clean corners are < 0.01; an
/// occluder covering a quarter of the window gives ~0.5).
const MAX_ASYMMETRY: f64 = 0.05;

pub(crate) fn detect(
    det: &Detector,
    img: &image::DynamicImage,
    rows: usize,
    cols: usize,
) -> Result<Detection, Rejection> {
    if rows < 2 || cols < 2 {
        return Err(Rejection::InvalidPattern { rows, cols });
    }
    let (width, height) = (img.width(), img.height());
    load::check_size(width, height, det.max_pixels)?;
    if width < 8 || height < 8 {
        return Err(Rejection::NoBoard);
    }
    let (fimg, gray) = load::grey_images(img);
    // Coarse to fine first: ChESS finds seeds on a downscaled pyramid level and
    // computes its response at full resolution only around them, several times
    // less work than the full-image response. It misses corners now and then
    // (small squares, a fisheye's rim), so a view it does not find complete is
    // looked at again at full resolution, and that result stands, as if the
    // coarse pass had not been made.
    let coarse = locate(det, &fimg, &gray, rows, cols, Scale::Pyramid);
    if matches!(&coarse, Ok(d) if d.complete) {
        return coarse;
    }
    locate(det, &fimg, &gray, rows, cols, Scale::Full)
}

/// Where ChESS computes its response: around seeds from a downscaled pyramid
/// level, or over the whole image.
#[derive(Clone, Copy)]
enum Scale {
    Pyramid,
    Full,
}

/// Find, refine, grow and index the board with ChESS at `scale`.
fn locate(
    det: &Detector,
    fimg: &FloatImage,
    gray: &image::GrayImage,
    rows: usize,
    cols: usize,
    scale: Scale,
) -> Result<Detection, Rejection> {
    let (width, height) = (fimg.width as u32, fimg.height as u32);
    // Why nothing was found matters only for the last pass.
    let miss = || match scale {
        Scale::Pyramid => Rejection::NoBoard,
        Scale::Full => classify_miss(fimg),
    };
    let (raw, cell) = match find_grid(gray, scale)? {
        Some(found) => found,
        None => return Err(miss()),
    };
    let refined = grow::grow(fimg, refine_all(fimg, raw, cell), rows, cols);
    let needed = det.min_corners.min(rows * cols);
    if refined.len() < needed {
        // A handful of corners on a featureless-looking image is blur, not
        // a small board.
        return Err(match miss() {
            Rejection::Blurred => Rejection::Blurred,
            _ => Rejection::TooFewCorners {
                found: refined.len(),
                needed,
            },
        });
    }
    let indexed = orient::assign_indices(&refined, fimg, rows, cols).map_err(|e| match e {
        OrientError::NoFit => Rejection::NoBoard,
        OrientError::Ambiguous => Rejection::PartialAmbiguous,
    })?;
    let mut corners: Vec<Corner> = indexed
        .corners
        .into_iter()
        .map(|(index, c)| Corner::new(index, c.uv, c.sigma))
        .collect();
    corners.sort_by_key(|c| c.index);
    corners.dedup_by_key(|c| c.index);
    let complete = corners.len() == rows * cols;
    Ok(Detection {
        corners,
        width,
        height,
        complete,
        labelled_by_symmetry: indexed.by_symmetry,
    })
}

/// Refine every found corner, with a window shrunk to 0.4× its own spacing to
/// its neighbours where that is smaller than the board-wide one (which would
/// swallow the compressed squares near a fisheye's rim), dropping those that
/// fail the checks.
fn refine_all(fimg: &FloatImage, raw: Vec<Labelled>, cell: f64) -> Vec<Labelled> {
    let at: HashMap<(i32, i32), [f64; 2]> = raw.iter().map(|c| ((c.u, c.v), c.uv)).collect();
    raw.into_iter()
        .filter_map(|c| {
            // The board-wide window (0.3× the cell) unless this corner's own
            // spacing asks for a smaller one: a larger window than that loses
            // accuracy on ordinary boards (tests/photo_noise.rs).
            let board_wide = ((0.3 * cell).round() as usize).clamp(3, 12);
            let spacing = grow::local_spacing((c.u, c.v), &at).unwrap_or(cell);
            let half = board_wide.min(grow::half_window(spacing));
            let r = refine_checked(fimg, c.uv, half)?;
            Some(Labelled {
                uv: r.uv,
                sigma: r.sigma,
                ..c
            })
        })
        .collect()
}

/// Refine, and keep only point-symmetric results: an occluder, clutter or a
/// board edge inside the window drags cornerSubPix off the junction. A
/// smaller window is tried before giving up, which rescues corners next to a
/// thin outer row of squares.
pub(crate) fn refine_checked(
    img: &FloatImage,
    start: [f64; 2],
    half: usize,
) -> Option<refine::Refined> {
    let first = refine::refine_corner(img, start, half);
    if let Some(r) = first.filter(|r| r.asymmetry <= MAX_ASYMMETRY) {
        return Some(r);
    }
    refine::refine_corner(img, start, (half / 2).max(2)).filter(|r| r.asymmetry <= MAX_ASYMMETRY)
}

/// Run calib-targets; returns the labelled corners and the cell size in px.
/// A panic inside the dependency is turned into `Rejection::Internal`.
fn find_grid(
    gray: &image::GrayImage,
    scale: Scale,
) -> Result<Option<(Vec<Labelled>, f64)>, Rejection> {
    let run = || {
        let mut cfg = ct::default_chess_config();
        if let Scale::Pyramid = scale {
            cfg.multiscale = chess_corners::MultiscaleConfig::pyramid_default();
        }
        let found = ct::detect_chessboard(gray, &cfg, &ChessboardParams::default()).ok()?;
        let labelled: Vec<Labelled> = found
            .corners
            .iter()
            .map(|c| Labelled {
                u: c.grid.u,
                v: c.grid.v,
                uv: [c.position.x as f64, c.position.y as f64],
                sigma: f64::NAN,
            })
            .collect();
        let cell = found.cell_size.map_or(20.0, |s| s as f64);
        Some((labelled, cell))
    };
    catch_unwind(AssertUnwindSafe(run)).map_err(|p| {
        let msg = p
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        Rejection::Internal(format!("calib-targets panicked: {msg}"))
    })
}

/// Tell "blurred" from "no board" when nothing was found: with contrast
/// present but no sharp edge anywhere, the likeliest cause is defocus/motion.
/// For a Gaussian-blurred step, range / max gradient = σ·√(2π); we call the
/// image blurred when that exceeds ~10 px (σ ≳ 4 px), which is where the ChESS
/// detector stops responding.
pub(crate) fn classify_miss(f: &FloatImage) -> Rejection {
    let (w, h) = (f.width, f.height);
    let mut grads = Vec::with_capacity(w * h / 4);
    for y in (1..h - 1).step_by(2) {
        for x in (1..w - 1).step_by(2) {
            let gx = 0.5 * (f.data[y * w + x + 1] - f.data[y * w + x - 1]);
            let gy = 0.5 * (f.data[(y + 1) * w + x] - f.data[(y - 1) * w + x]);
            grads.push(gx.hypot(gy));
        }
    }
    let mut vals = f.data.clone();
    vals.sort_by(f32::total_cmp);
    grads.sort_by(f32::total_cmp);
    let q = |v: &[f32], p: f64| v[((v.len() - 1) as f64 * p) as usize] as f64;
    let range = q(&vals, 0.99) - q(&vals, 0.01);
    let gmax = q(&grads, 0.999);
    if range > 20.0 && range / gmax.max(1e-6) > 10.0 {
        Rejection::Blurred
    } else {
        Rejection::NoBoard
    }
}
