//! Frames that the first solve left in a wrong pose basin, found by their
//! residuals and posed again from the solved intrinsics.
//!
//! An initial board pose can be far off: a fisheye view near 90° off axis is posed
//! from the few rays that an equidistant guess of the lens unprojects well. Under
//! the robust loss such a frame's corners lie far beyond the scale, so they pull on
//! nothing and the solve leaves the frame where it started, while the other frames
//! fix the intrinsics (and, through the loss's tails, bias them). The solved
//! intrinsics unproject the frame's pixels far better than the initial guess did,
//! so a pose from those rays lands in the right basin. Nothing here changes a
//! calibration whose frames all fit alike. The boundary: this module picks and
//! re-poses frames of a solved `standard` state; the caller re-solves.
use crate::error::Result;
use crate::model::pose::Pose;
use crate::model::state::State;
use crate::model::{fisheye_init, zhang};
use crate::solver::problem::{Problem, SolverSettings};
use crate::solver::robust;

/// A frame is a suspect when its RMS residual exceeds this many times the median
/// frame's. Bends that `standard` cannot follow leave frames 2–5 times the median;
/// a frame in a wrong basin is off by tens to hundreds of pixels.
const STRAY_FACTOR: f64 = 8.0;
/// ... and exceeds this many pixels, so that a fit at the noise level flags nothing.
const STRAY_MIN_PX: f64 = 2.0;
/// A new pose is taken only when it brings the frame's RMS below this share of
/// the old one: a clear win, not noise in the comparison.
const ACCEPT_SHARE: f64 = 0.5;

/// Per frame, the RMS of the residuals (pixels, u and v per observation in
/// `problem.dataset`'s order); NaN for a frame without observations.
fn frame_rms(problem: &Problem, residuals: &[f64]) -> Vec<f64> {
    let n = problem.dataset.num_frames();
    let mut sum = vec![0.0; n];
    let mut count = vec![0usize; n];
    for (o, r) in problem.dataset.observations.iter().zip(residuals.chunks(2)) {
        let r2 = r[0] * r[0] + r[1] * r[1];
        sum[o.frame] += if r2.is_finite() { r2 } else { f64::INFINITY };
        count[o.frame] += 1;
    }
    sum.iter()
        .zip(&count)
        .map(|(s, &c)| {
            if c == 0 {
                f64::NAN
            } else {
                (s / c as f64).sqrt()
            }
        })
        .collect()
}

/// The frames whose RMS stands far above the median frame's.
fn stray_frames(rms: &[f64]) -> Vec<usize> {
    let mut finite: Vec<f64> = rms.iter().copied().filter(|r| r.is_finite()).collect();
    if finite.is_empty() {
        return Vec::new();
    }
    let bound = (STRAY_FACTOR * robust::median(&mut finite)).max(STRAY_MIN_PX);
    (0..rms.len()).filter(|&j| rms[j] > bound).collect()
}

/// Camera-0-from-board of frame `j` from the rays of the camera that sees most of
/// its corners, under `state`'s intrinsics and rig.
fn pose_from_solved_rays(problem: &Problem, state: &State, j: usize) -> Option<Pose> {
    let cameras = problem.dataset.cameras.len();
    let mut seen = vec![0usize; cameras];
    for o in problem.dataset.observations.iter().filter(|o| o.frame == j) {
        seen[o.camera] += 1;
    }
    let k = (0..cameras).max_by_key(|&k| seen[k])?;
    let (board, pixels) = fisheye_init::views_of(problem.dataset, k, &[j]).pop()?;
    let camera_k_from_board = zhang::pose_from_pixels(&state.intrinsics[k], &board, &pixels)?;
    Some(
        state.camera_poses[k]
            .inverse()
            .compose(&camera_k_from_board),
    )
}

/// Gives every stray frame of the solved `state` (residuals `residuals`) a pose
/// from the solved intrinsics where that pose fits the frame's corners clearly
/// better; returns how many frames were re-posed (the caller re-solves if any).
pub fn repose_stray_frames(
    problem: &Problem,
    state: &mut State,
    residuals: &[f64],
    settings: &SolverSettings,
) -> Result<usize> {
    let before = frame_rms(problem, residuals);
    let stray = stray_frames(&before);
    if stray.is_empty() {
        return Ok(0);
    }
    let mut candidate = state.clone();
    let mut any = false;
    for &j in &stray {
        if let Some(pose) = pose_from_solved_rays(problem, state, j) {
            candidate.frame_poses[j] = pose;
            any = true;
        }
    }
    if !any {
        return Ok(0);
    }
    // One evaluation scores every candidate: in `standard` a frame's residuals
    // depend on its own pose and on nothing another frame's pose changes.
    let after = frame_rms(
        problem,
        &problem.evaluate(&candidate, settings, false)?.residuals,
    );
    let mut moved = 0;
    for &j in &stray {
        if after[j] < ACCEPT_SHARE * before[j] {
            state.frame_poses[j] = candidate.frame_poses[j];
            moved += 1;
        }
    }
    Ok(moved)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::lens::LensModel;
    use crate::model::synthetic::{Generator, Preset};
    use nalgebra::{Rotation3, Vector3};

    /// A `ds` view beside the camera and a central one, their poses turned into
    /// wrong basins at the true intrinsics: both come back to the truth, no other
    /// frame moves, and a state with no stray frame is left alone.
    #[test]
    fn stray_frames_come_back_to_their_true_poses() {
        let mut g = Generator::new(Preset::T2, Some(20), 3).with_models(&[LensModel::DoubleSphere]);
        g.bend_scale = 0.0;
        g.print_scale = 0.0;
        let (dataset, truth) = g.generate();
        let problem = Problem::standard(&dataset);
        let settings = SolverSettings::default();
        let exact = State::rigid(
            truth.intrinsics.clone(),
            truth.camera_poses.clone(),
            truth.frame_poses.clone(),
            &dataset.target,
        );
        let residuals = |s: &State| problem.evaluate(s, &settings, false).unwrap().residuals;
        let mut state = exact.clone();
        let clean = residuals(&exact);
        assert_eq!(
            repose_stray_frames(&problem, &mut state, &clean, &settings).unwrap(),
            0
        );
        assert_eq!(state, exact);

        // The frame whose board centre lies furthest off axis, and frame 0.
        let off_axis = |j: usize| {
            let c = truth.frame_poses[j].transform(&Vector3::zeros());
            c.xy().norm().atan2(c.z).to_degrees()
        };
        let beside = (0..dataset.num_frames())
            .max_by(|&a, &b| off_axis(a).total_cmp(&off_axis(b)))
            .unwrap();
        assert!(off_axis(beside) > 70.0, "{}°", off_axis(beside));
        let mut wrong = exact.clone();
        for j in [0, beside] {
            let turn = Pose::from_parts(
                &Rotation3::new(Vector3::new(0.0, 0.9, 0.4)),
                &Vector3::zeros(),
            );
            wrong.frame_poses[j] = wrong.frame_poses[j].compose(&turn);
        }
        let before = residuals(&wrong);
        let moved = repose_stray_frames(&problem, &mut wrong, &before, &settings).unwrap();
        assert_eq!(moved, 2);
        for (j, (p, t)) in wrong.frame_poses.iter().zip(&truth.frame_poses).enumerate() {
            let dt = (p.translation_vector() - t.translation_vector()).norm();
            let dr = (p.rotation_matrix().matrix() - t.rotation_matrix().matrix()).norm();
            // The DLT pose from noisy rays, not refined: millimetres, milliradians.
            assert!(dt < 5e-3 && dr < 5e-3, "frame {j}: {dt} m, {dr}");
        }
    }

    #[test]
    fn only_frames_far_above_the_median_are_strays() {
        let rms = [
            0.3,
            0.25,
            0.4,
            2.1,
            0.35,
            186.0,
            f64::NAN,
            f64::INFINITY,
            0.3,
        ];
        // Median 0.35 → bound max(2.8, 2.0) = 2.8: 2.1 px is a poorly fitted frame,
        // not a stray; a frame with no observations is no stray either.
        assert_eq!(stray_frames(&rms), vec![5, 7]);
        let bent = [3.0, 4.0, 5.0, 15.0, 60.0];
        assert_eq!(stray_frames(&bent), vec![4]);
        assert!(stray_frames(&[]).is_empty());
    }
}
