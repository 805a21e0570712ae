//! ChArUco boards in OpenCV's layout (the board itself is `charuco_spec`): their detection
//! (calib-targets finds the grid and decodes the markers, our refinement makes
//! the corners sub-pixel) and the board's printed appearance, which the
//! renderer and the printable target share. No file I/O, no config parsing.
//!
//! Numbering (docs/conventions.md, ChArUco boards): a board of `rows × cols`
//! squares has `(rows−1) × (cols−1)` inner corners; corner id
//! `r·(cols−1) + c` is inner corner (r, c) counted from the top-left, as
//! OpenCV numbers ChArUco corners. The top-left square is black and the
//! markers sit on the white squares, numbered row by row (OpenCV ≥ 4.6).
//! In deformcal's board frame corner id `i` is corner `i` of a chessboard
//! target of `rows−1 × cols−1` inner corners, so every method, lens model and
//! export works on ChArUco data unchanged.

pub use crate::app::detect::charuco_spec::{CharucoSpec, MAX_SQUARES};
use crate::app::detect::load;
use crate::app::detect::pipeline::{classify_miss, refine_checked};
use crate::app::detect::refine::{refine_masked, Axes, FloatImage, Refined};
use crate::app::detect::types::{Corner, Detection, Detector, Rejection};
use calib_targets::charuco::{CharucoBoardSpec, CharucoDetection, CharucoParams};
use calib_targets::detect as ct;
use calib_targets::printable::{Fill, Primitive};
use chess_corners::UpscaleConfig;
use std::panic::{catch_unwind, AssertUnwindSafe};

/// The board's reflectance at a point of deformcal's board frame (metres, origin
/// at corner 0, see the module doc): `dark`/`light` on the board, `None` off
/// it. Built once (rectangles bucketed by square), then cheap per ray.
pub struct Albedo {
    square: f64,
    cols: usize,
    rows: usize,
    /// Per square (row-major): the rectangles inside it in painting order,
    /// as (x0, y0, x1, y1, black) in metres from the board's outer corner.
    buckets: Vec<Vec<Rect>>,
}

/// (x0, y0, x1, y1, black) in metres from the board's outer corner.
type Rect = (f64, f64, f64, f64, bool);

impl Albedo {
    /// The board's appearance, or None for a board [`CharucoSpec::problem`] refuses.
    pub fn new(spec: &CharucoSpec) -> Option<Albedo> {
        let prims = spec.primitives()?;
        let mut buckets = vec![Vec::new(); spec.rows * spec.cols];
        for p in prims {
            let Primitive::Rect {
                x_mm,
                y_mm,
                width_mm,
                height_mm,
                fill,
            } = p
            else {
                continue;
            };
            let rect = (
                x_mm / 1000.0,
                y_mm / 1000.0,
                (x_mm + width_mm) / 1000.0,
                (y_mm + height_mm) / 1000.0,
                fill == Fill::Black,
            );
            let cx = ((rect.0 + rect.2) / 2.0 / spec.square).floor() as usize;
            let cy = ((rect.1 + rect.3) / 2.0 / spec.square).floor() as usize;
            if cx < spec.cols && cy < spec.rows {
                buckets[cy * spec.cols + cx].push(rect);
            }
        }
        Some(Albedo {
            square: spec.square,
            cols: spec.cols,
            rows: spec.rows,
            buckets,
        })
    }

    /// Black (true) or white (false) at board point (bx, by), metres from
    /// corner 0; None off the squares.
    pub fn is_black(&self, bx: f64, by: f64) -> Option<bool> {
        let (x, y) = (bx + self.square, by + self.square);
        let (cx, cy) = ((x / self.square).floor(), (y / self.square).floor());
        if cx < 0.0 || cy < 0.0 || cx >= self.cols as f64 || cy >= self.rows as f64 {
            return None;
        }
        let bucket = &self.buckets[cy as usize * self.cols + cx as usize];
        bucket
            .iter()
            .rev()
            .find(|r| x >= r.0 && x < r.2 && y >= r.1 && y < r.3)
            .map(|r| r.4)
    }

    /// The renderer's grey level at (bx, by): the board's squares and markers,
    /// a white margin of one square around them, the background beyond.
    pub fn grey(&self, bx: f64, by: f64) -> f64 {
        use crate::app::detect::render::{BACKGROUND, DARK, LIGHT};
        match self.is_black(bx, by) {
            Some(true) => DARK,
            Some(false) => LIGHT,
            None => {
                let (x, y) = (bx / self.square + 1.0, by / self.square + 1.0);
                let margin = x >= -1.0
                    && y >= -1.0
                    && x <= self.cols as f64 + 1.0
                    && y <= self.rows as f64 + 1.0;
                if margin {
                    LIGHT
                } else {
                    BACKGROUND
                }
            }
        }
    }
}

/// Detect a ChArUco board: calib-targets' grid and markers, then our sub-pixel
/// refinement in a window that stays clear of the markers.
pub(crate) fn detect(
    det: &Detector,
    spec: &CharucoSpec,
    img: &image::DynamicImage,
) -> Result<Detection, Rejection> {
    let target = spec.target();
    let board = spec.board_spec().ok_or(Rejection::InvalidPattern {
        rows: spec.rows,
        cols: spec.cols,
    })?;
    let (width, height) = (img.width(), img.height());
    load::check_size(width, height, det.max_pixels)?;
    if width < 8 || height < 8 {
        return Err(Rejection::NoBoard);
    }
    let (fimg, gray) = load::grey_images(img);
    let n = target.num_corners();
    let Some(mut found) = find_board(&gray, board, n)? else {
        return Err(classify_miss(&fimg));
    };
    drop_off_grid(&mut found);
    let cell = median_cell_px(&found);
    // The refinement window must not reach the markers: a marker's edges in
    // the window pull the gradient fit off the junction and break the point
    // symmetry the refinement checks. The gap between a corner and the
    // nearest marker is (square − marker)/2 along both axes.
    let gap = 0.5 * (1.0 - spec.marker / spec.square);
    let mut corners: Vec<Corner> = found
        .corners
        .iter()
        .filter(|c| (c.id as usize) < n)
        .map(|c| {
            let start = [c.position.x as f64, c.position.y as f64];
            let r = grid_axes(&found, c.grid.u, c.grid.v, start)
                .and_then(|axes| refine_along_edges(&fimg, start, axes, gap))
                .or_else(|| {
                    let local = local_cell_px(&found, c.grid.u, c.grid.v, start).unwrap_or(cell);
                    let half = ((0.8 * gap * local).floor() as usize).clamp(2, 12);
                    refine_checked(&fimg, start, half)
                });
            // Our refinement refuses blurred, strongly tilted junctions whose
            // window is not point symmetric; calib-targets' own position is
            // still within a tenth of a pixel there, and dropping it cost
            // whole views (too few corners left), so it is kept with its
            // larger σ and a correspondingly lower weight.
            match r {
                Some(r) => Corner::new(c.id as usize, r.uv, r.sigma),
                None => Corner::new(c.id as usize, start, fallback_sigma(c)),
            }
        })
        .collect();
    corners.sort_by_key(|c| c.index);
    corners.dedup_by_key(|c| c.index);
    let needed = det.min_corners.min(n);
    if corners.len() < needed {
        return Err(Rejection::TooFewCorners {
            found: corners.len(),
            needed,
        });
    }
    let complete = corners.len() == n;
    Ok(Detection {
        corners,
        width,
        height,
        complete,
        // Marker ids fix a ChArUco board's orientation.
        labelled_by_symmetry: false,
    })
}

/// calib-targets' ChArUco detector: its default settings first and, when they
/// leave corners of the board unfound, once more with its ChESS corner pass on
/// the image upscaled ×2, keeping the pass that found more corners. Board
/// squares under ~30 px and strongly tilted boards lose grid corners to the
/// ChESS ring at the original scale (on the rendered test boards the retry
/// found 356 corners instead of 318 on DICT_6X6_250, 410 instead of 331 on the
/// calibration views), and a whole pass at ×2 costs four times the pixels, so
/// complete boards skip it. Partial views pay for it (`cargo bench --bench
/// detect`: 4× the time per megapixel of whole views, for 6 % more corners).
/// Skipping it when every unfound corner is predicted outside the image (by
/// the homography of those found) was tried and kept every corner, but it
/// almost never applies: a partial view has unfound corners just inside the
/// border, which the pass at ×2 finds.
fn find_board(
    gray: &image::GrayImage,
    board: CharucoBoardSpec,
    corners: usize,
) -> Result<Option<CharucoDetection>, Rejection> {
    let found = |d: &Option<CharucoDetection>| {
        d.as_ref().map_or(0, |d| {
            d.corners
                .iter()
                .filter(|c| (c.id as usize) < corners)
                .count()
        })
    };
    let params = CharucoParams::for_board(board);
    let first = run_guarded(gray, &params)?;
    if found(&first) >= corners {
        return Ok(first);
    }
    let mut upscaled = params;
    upscaled.chess.upscale = UpscaleConfig::Fixed(2);
    let second = run_guarded(gray, &upscaled)?;
    Ok(if found(&second) > found(&first) {
        second
    } else {
        first
    })
}

/// One run of calib-targets' ChArUco detector, its panics turned into a rejection.
fn run_guarded(
    gray: &image::GrayImage,
    params: &CharucoParams,
) -> Result<Option<CharucoDetection>, Rejection> {
    let run = || ct::detect_charuco(gray, params).ok();
    catch_unwind(AssertUnwindSafe(run)).map_err(|p| {
        let msg = p
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        Rejection::Internal(format!("calib-targets panicked: {msg}"))
    })
}

/// Neighbours on the grid this much nearer or farther than the median grid
/// step are not both real corners: perspective on the test's tilts (±0.5 rad)
/// stays within 0.6 to 1.6 of the median.
const STEP_RANGE: (f64, f64) = (0.4, 2.5);

/// Drop corners that do not sit at a grid step from their grid neighbours.
/// calib-targets occasionally labels saddle points inside a marker as grid
/// corners (seen with its corner pass on the ×2 image: three "corners" 3 px
/// apart, 200 px from their grid neighbours); their ids are wrong, and one
/// wrong id costs a calibration more than a missing corner. A corner goes when
/// more of its grid neighbours are at an implausible distance than at a
/// plausible one, or when none is at a plausible one (a grid corner has
/// grid neighbours), the worst first, until every corner agrees with its
/// neighbours.
fn drop_off_grid(found: &mut CharucoDetection) {
    let step = median_cell_px(found);
    loop {
        let pos =
            |c: &calib_targets::charuco::CharucoCorner| [c.position.x as f64, c.position.y as f64];
        let score: Vec<(usize, usize)> = found
            .corners
            .iter()
            .map(|c| {
                let (mut good, mut bad) = (0, 0);
                for o in &found.corners {
                    if (o.grid.u - c.grid.u).abs() + (o.grid.v - c.grid.v).abs() != 1 {
                        continue;
                    }
                    let (a, b) = (pos(c), pos(o));
                    let d = (a[0] - b[0]).hypot(a[1] - b[1]) / step;
                    if (STEP_RANGE.0..=STEP_RANGE.1).contains(&d) {
                        good += 1;
                    } else {
                        bad += 1;
                    }
                }
                (good, bad)
            })
            .collect();
        let badness = |(good, bad): (usize, usize)| bad as i64 - good as i64 + i64::from(good == 0);
        let worst = score.iter().map(|&s| badness(s)).max().unwrap_or(0);
        if worst <= 0 {
            return;
        }
        let mut k = 0;
        found.corners.retain(|_| {
            k += 1;
            badness(score[k - 1]) != worst
        });
    }
}

/// The σ of a corner kept at calib-targets' position: its covariance when the
/// corner pass measured one, never below our own refinement's typical σ.
fn fallback_sigma(c: &calib_targets::charuco::CharucoCorner) -> f64 {
    c.position_covariance
        .map(|cov| (0.5 * f64::from(cov.xx + cov.yy)).sqrt())
        .filter(|s| s.is_finite())
        .map_or(FALLBACK_SIGMA_PX, |s| s.max(FALLBACK_SIGMA_PX))
}

/// Median distance between grid neighbours, px (the square's size in the image).
fn median_cell_px(found: &CharucoDetection) -> f64 {
    let mut d: Vec<f64> = found
        .corners
        .iter()
        .filter_map(|c| {
            local_cell_px(
                found,
                c.grid.u,
                c.grid.v,
                [c.position.x as f64, c.position.y as f64],
            )
        })
        .collect();
    if d.is_empty() {
        return 20.0;
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

/// Shortest distance from the corner at grid (u, v) to a found grid neighbour.
fn local_cell_px(found: &CharucoDetection, u: i32, v: i32, at: [f64; 2]) -> Option<f64> {
    found
        .corners
        .iter()
        .filter(|o| (o.grid.u - u).abs() + (o.grid.v - v).abs() == 1)
        .map(|o| (o.position.x as f64 - at[0]).hypot(o.position.y as f64 - at[1]))
        .min_by(f64::total_cmp)
}

/// How far along the edges through a junction the window reaches, in cells:
/// short of the next junction (one cell away) by more than a blur's width.
const EDGE_REACH: f64 = 0.45;
/// Pixels kept between the window and a marker's edge, for the blur.
const MARKER_CLEARANCE_PX: f64 = 2.5;
/// σ (px) of calib-targets' own corner position where it reports none: on
/// the rendered test boards (blur 0.5–1.2 px, noise 2 grey levels) the
/// corners our refinement refuses sit 0.12 px RMS from the truth.
const FALLBACK_SIGMA_PX: f64 = 0.12;
/// The symmetry check of the pipeline's refinement.
const MAX_ASYMMETRY: f64 = 0.05;

/// Refine in a cross-shaped window along the grid: the four edges through
/// the junction out to [`EDGE_REACH`] of a cell, each arm as wide as the gap
/// between the corner and the markers allows. The markers sit inside the
/// white squares at least `gap` (cells) from both edge lines, so the arms see
/// the junction's edges over a long stretch, and no marker edge, which a
/// square window of the same reach would take in. None when the gap is too
/// narrow at this scale or the result is not point symmetric.
fn refine_along_edges(img: &FloatImage, start: [f64; 2], axes: Axes, gap: f64) -> Option<Refined> {
    let len = |e: [f64; 2]| e[0].hypot(e[1]);
    let shortest = len(axes[0]).min(len(axes[1]));
    let arm = gap - MARKER_CLEARANCE_PX / shortest;
    if arm * shortest < 1.5 {
        return None;
    }
    let keep = |a: f64, b: f64| a.abs() <= arm || b.abs() <= arm;
    refine_masked(img, start, axes, EDGE_REACH, &keep).filter(|r| r.asymmetry <= MAX_ASYMMETRY)
}

/// The image vectors from the corner at grid (u, v) to its next corners along
/// the grid's two axes: a central difference where both neighbours were found,
/// else the one-sided one.
fn grid_axes(found: &CharucoDetection, u: i32, v: i32, at: [f64; 2]) -> Option<Axes> {
    let pos = |du: i32, dv: i32| {
        found
            .corners
            .iter()
            .find(|o| o.grid.u == u + du && o.grid.v == v + dv)
            .map(|o| [o.position.x as f64, o.position.y as f64])
    };
    let axis = |du: i32, dv: i32| match (pos(du, dv), pos(-du, -dv)) {
        (Some(p), Some(m)) => Some([(p[0] - m[0]) / 2.0, (p[1] - m[1]) / 2.0]),
        (Some(p), None) => Some([p[0] - at[0], p[1] - at[1]]),
        (None, Some(m)) => Some([at[0] - m[0], at[1] - m[1]]),
        (None, None) => None,
    };
    Some([axis(1, 0)?, axis(0, 1)?])
}
