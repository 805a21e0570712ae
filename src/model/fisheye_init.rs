//! Initialisation for lens models whose image is not a pinhole image (`kb4`,
//! `ds`), where Zhang's homographies of pixels mean nothing.
//!
//! Chosen approach: the principal point at the image centre, no distortion
//! (an equidistant `kb4`, a stereographic `ds`), and a one-dimensional search
//! for the focal length. For each candidate focal length every observed pixel
//! is unprojected to a ray; the rays in front of the camera (up to 80° off
//! axis) give a homography of the board plane to normalised coordinates, and so
//! a board pose per view (planar PnP by Zhang's decomposition with K = I); the
//! candidate whose poses reproject best wins. Unprojecting first means a view of
//! the board near the border of a 180° image is treated like any other, and the
//! search needs no guess of the field of view. The full model (distortion,
//! principal point) is then left to the `standard` solve that follows.
use crate::model::dataset::Dataset;
use crate::model::lens::Intrinsics;
use crate::model::pose::Pose;
use crate::model::zhang;
use nalgebra::{Vector2, Vector3};

/// Rays further off axis than this (cos of 80°) stay out of the pose homography.
const MIN_RAY_Z: f64 = 0.17;
/// Candidate focal lengths, as fractions of the image diagonal, on a geometric grid.
const F_RANGE: (f64, f64) = (0.05, 3.0);
const F_STEPS: usize = 40;
/// Golden-section steps after the grid. Fewer (12, or a grid of 24) or the
/// search on a few dozen corners per view made it 5× faster, but moved the start
/// by 0.1–1 %, and on `ds` that moved which of 32 synthetic sets fall into a
/// local minimum of the solve (0.4–0.7 px off the truth instead of 0.03; one or
/// two sets either way), so the search stays as it was. With `ds`'s second start
/// (`LensInfo::second_start`) in place it was tried again: one set still ended
/// 0.43–0.50 px off, from both starts.
const GOLDEN_STEPS: usize = 20;
/// Views that take part in the search (evenly picked): enough to find the focal
/// length, few enough to keep the search cheaper than the solve.
const SEARCH_VIEWS: usize = 8;

/// One view's correspondences: board points (x, y) and pixels.
pub type ViewPoints = (Vec<Vector2<f64>>, Vec<Vector2<f64>>);

/// The board pose of one view under `k`, from the rays in front of the camera.
fn view_pose(k: &Intrinsics, board: &[Vector2<f64>], pixels: &[Vector2<f64>]) -> Option<Pose> {
    let mut b = Vec::with_capacity(board.len());
    let mut n = Vec::with_capacity(board.len());
    for (x, uv) in board.iter().zip(pixels) {
        let ray = k.unproject(uv)?;
        if ray.z > MIN_RAY_Z {
            b.push(*x);
            n.push(Vector2::new(ray.x / ray.z, ray.y / ray.z));
        }
    }
    if b.len() < 4 {
        return None;
    }
    let h = zhang::homography(&b, &n)?;
    zhang::pose_from_homography(&h, &Intrinsics::pinhole(1.0, 1.0, 0.0, 0.0))
}

/// RMS reprojection error of a view under `k` at `pose`.
fn view_rms(k: &Intrinsics, pose: &Pose, board: &[Vector2<f64>], pixels: &[Vector2<f64>]) -> f64 {
    // `pose.transform`, with the rotation built once per view, not per corner.
    let (r, t) = (pose.rotation_matrix(), pose.translation_vector());
    let mut sum = 0.0;
    for (x, uv) in board.iter().zip(pixels) {
        match k.project(&(r * Vector3::new(x.x, x.y, 0.0) + t)) {
            Some(p) => sum += (p - uv).norm_squared(),
            None => return f64::INFINITY,
        }
    }
    (sum / board.len() as f64).sqrt()
}

/// Each view's pose and the median RMS of the views that have one under `k`;
/// `None` unless at least half of the views (and three) do. A view can fail
/// under a candidate (too few rays in front, a degenerate homography) without
/// saying anything about the others, so it must not veto the candidate.
fn score(k: &Intrinsics, views: &[ViewPoints]) -> Option<(f64, Vec<Option<Pose>>)> {
    let mut poses = Vec::with_capacity(views.len());
    let mut errors = Vec::with_capacity(views.len());
    for (board, pixels) in views {
        let mut pose = view_pose(k, board, pixels);
        if let Some(p) = &pose {
            let e = view_rms(k, p, board, pixels);
            if e.is_finite() {
                errors.push(e);
            } else {
                pose = None;
            }
        }
        poses.push(pose);
    }
    if errors.len() < 3 || 2 * errors.len() < views.len() {
        return None;
    }
    errors.sort_by(f64::total_cmp);
    Some((errors[errors.len() / 2], poses))
}

/// Initial intrinsics of `template`'s model for one camera and the board pose of
/// each of its views (`None` for a view that no candidate focal length gives a
/// pose), or `None` if no focal length explains the views.
pub fn initialise(
    template: &Intrinsics,
    width: u32,
    height: u32,
    views: &[ViewPoints],
) -> Option<(Intrinsics, Vec<Option<Pose>>)> {
    let (cx, cy) = ((width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0);
    let diagonal = (width as f64).hypot(height as f64);
    let neutral = |f: f64| Intrinsics::pinhole_of(template.model(), f, f, cx, cy);
    let step = views.len().div_ceil(SEARCH_VIEWS).max(1);
    let sample: Vec<ViewPoints> = views.iter().step_by(step).cloned().collect();
    let ratio = (F_RANGE.1 / F_RANGE.0).powf(1.0 / (F_STEPS - 1) as f64);
    let mut best: Option<(f64, f64)> = None;
    let mut f = F_RANGE.0 * diagonal;
    for _ in 0..F_STEPS {
        if let Some((e, _)) = score(&neutral(f), &sample) {
            if best.is_none_or(|b| e < b.1) {
                best = Some((f, e));
            }
        }
        f *= ratio;
    }
    let (f, _) = best?;
    // Golden-section refinement within one grid step either side; each step
    // keeps one of its two inner points, so it scores one new candidate.
    let (mut lo, mut hi) = (f / ratio, f * ratio);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let error = |f: f64| score(&neutral(f), &sample).map_or(f64::INFINITY, |s| s.0);
    let (mut a, mut b) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut ea, mut eb) = (error(a), error(b));
    for _ in 0..GOLDEN_STEPS {
        if ea < eb {
            hi = b;
            (b, eb) = (a, ea);
            a = hi - g * (hi - lo);
            ea = error(a);
        } else {
            lo = a;
            (a, ea) = (b, eb);
            b = lo + g * (hi - lo);
            eb = error(b);
        }
    }
    let (f, mut poses) = [0.5 * (lo + hi), f]
        .into_iter()
        .find_map(|f| score(&neutral(f), views).map(|(_, poses)| (f, poses)))?;
    // A view without a pose at f takes the one it has at the nearest focal
    // length that gives it one: a start that the solve refines.
    for step in 1..F_STEPS as i32 {
        if poses.iter().all(Option::is_some) {
            break;
        }
        for g in [f * ratio.powi(step), f / ratio.powi(step)] {
            let k = neutral(g);
            for (pose, (board, pixels)) in poses.iter_mut().zip(views) {
                if pose.is_none() {
                    *pose = view_pose(&k, board, pixels)
                        .filter(|p| view_rms(&k, p, board, pixels).is_finite());
                }
            }
        }
    }
    let k = neutral(f);
    repose_outlying_views(&k, views, &mut poses);
    Some((k, poses))
}

/// A view whose pose reprojects this many times worse than the median view's is
/// posed again from all of its rays.
const OUTLYING_VIEW: f64 = 3.0;

/// Poses from all rays for the views without one and for those far worse than
/// the median view, kept where they at least halve the view's RMS. A view near 90°
/// off axis has few rays in front within 80°, and a pose from those few (or from
/// another focal length) can lie in a wrong basin. For the other views the pose
/// from the central rays stays: under the undistorted guess of the lens those rays
/// are the trustworthy ones, and on the presets' `ds` lens replacing every pose
/// that all rays fit better cost 45 % more iterations.
fn repose_outlying_views(k: &Intrinsics, views: &[ViewPoints], poses: &mut [Option<Pose>]) {
    let rms: Vec<f64> = poses
        .iter()
        .zip(views)
        .map(|(p, (board, pixels))| p.map_or(f64::INFINITY, |p| view_rms(k, &p, board, pixels)))
        .collect();
    let mut finite: Vec<f64> = rms.iter().copied().filter(|e| e.is_finite()).collect();
    finite.sort_by(f64::total_cmp);
    let bound = finite
        .get(finite.len() / 2)
        .map_or(0.0, |m| OUTLYING_VIEW * m);
    for ((pose, (board, pixels)), &e) in poses.iter_mut().zip(views).zip(&rms) {
        if e <= bound {
            continue;
        }
        if let Some(all) = zhang::pose_from_pixels(k, board, pixels) {
            if view_rms(k, &all, board, pixels) < 0.5 * e {
                *pose = Some(all);
            }
        }
    }
}

/// The correspondences of camera `camera`'s views in `frames`, in that order.
pub fn views_of(dataset: &Dataset, camera: usize, frames: &[usize]) -> Vec<ViewPoints> {
    let mut index = vec![usize::MAX; dataset.num_frames()];
    for (i, &j) in frames.iter().enumerate() {
        index[j] = i;
    }
    let mut out: Vec<ViewPoints> = vec![(Vec::new(), Vec::new()); frames.len()];
    for o in dataset.observations.iter().filter(|o| o.camera == camera) {
        if let Some(view) = out.get_mut(index[o.frame]) {
            let p = dataset.target.nominal(o.corner);
            view.0.push(Vector2::new(p.x, p.y));
            view.1.push(Vector2::new(o.uv[0], o.uv[1]));
        }
    }
    out
}
