//! Board-independent checks of a calibrated stereo pair on held-out frames: the
//! epipolar distance and the two-view triangulation error (docs/real-photos.md).
//!
//! Both use only the cameras (intrinsics and the rig's relative pose), never the
//! board model a method fitted, so a method cannot lower them by bending the board:
//! a corner seen by both cameras must lie on its partner's epipolar line whatever
//! shape the board had, and the two rays must meet at a point of the board.
//!
//! - Epipolar distance: each pixel is unprojected with its camera's lens, so
//!   distortion is removed, and the distance of each corner to the epipolar line of
//!   its partner is measured in the pinhole image of its camera (normalised
//!   coordinates × fx), both ways. A corner whose ray is 90° or more off axis has no
//!   pinhole image and is left out (`skipped`).
//! - Triangulation error: each corner is triangulated from its two rays (midpoint
//!   of the closest points), and each held-out frame's triangulated board is
//!   compared with the nominal flat board after the best rigid transform (Kabsch).
//!   Rigid, not a similarity: a wrong baseline or focal length shows as a board of
//!   the wrong size, which a scale in the alignment would hide. The held-out board's
//!   own bend adds the same amount for every calibration of the same frames.
use crate::error::{Error, Result};
use crate::model::dataset::Dataset;
use crate::model::lens::Intrinsics;
use crate::model::pose::Pose;
use nalgebra::{Matrix3, Vector2, Vector3};
use std::collections::BTreeMap;

/// Fewest corners seen by both cameras for a frame to enter the triangulation
/// error: fewer leave the six parameters of the rigid alignment nearly free.
pub const MIN_TRIANGULATED_CORNERS: usize = 6;

/// The two metrics on one held-out dataset.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct StereoErrors {
    /// Mean epipolar distance, pixels of the pinhole image (fx scale), over both
    /// directions of every corner pair.
    pub epipolar_mean_px: f64,
    /// RMS of the same distances.
    pub epipolar_rms_px: f64,
    /// RMS distance, millimetres, of the triangulated corners from the nominal board
    /// after each frame's best rigid alignment.
    pub triangulation_rms_mm: f64,
    /// Corners seen by both cameras and measured.
    pub pairs: usize,
    /// Frames in the triangulation error.
    pub frames: usize,
    /// Corner pairs left out: a ray without a pinhole image, or rays that do not
    /// meet in front of both cameras.
    pub skipped: usize,
}

/// [`stereo_errors`] of a calibrated rig of exactly two cameras: `intrinsics[k]`
/// and `camera_poses[k]` (camera-k-from-camera-0) as in `State`.
pub fn stereo_errors(
    intrinsics: &[Intrinsics],
    camera_poses: &[Pose],
    held_out: &Dataset,
) -> Result<StereoErrors> {
    if held_out.cameras.len() != 2 || intrinsics.len() != 2 || camera_poses.len() != 2 {
        return Err(Error::Invalid(format!(
            "the stereo check needs a rig of two cameras (the data have {}, the calibration {})",
            held_out.cameras.len(),
            intrinsics.len()
        )));
    }
    let right_from_left = camera_poses[1].compose(&camera_poses[0].inverse());
    let rot = *right_from_left.rotation_matrix().matrix();
    let t = right_from_left.translation_vector();
    if t.norm() == 0.0 {
        return Err(Error::Degenerate(
            "the two cameras share one centre: no epipolar geometry".into(),
        ));
    }
    // x_right = R x_left + t, so x_rightᵀ [t]× R x_left = 0.
    let essential = t.cross_matrix() * rot;

    let mut seen: [BTreeMap<(usize, usize), Vector2<f64>>; 2] = Default::default();
    for o in &held_out.observations {
        seen[o.camera].insert((o.frame, o.corner), Vector2::from(o.uv));
    }
    let mut distances = Vec::new();
    let mut skipped = 0;
    let mut boards: BTreeMap<usize, Vec<(usize, Vector3<f64>)>> = BTreeMap::new();
    for (&(frame, corner), uv0) in &seen[0] {
        let Some(uv1) = seen[1].get(&(frame, corner)) else {
            continue;
        };
        let (Some(r0), Some(r1)) = (intrinsics[0].unproject(uv0), intrinsics[1].unproject(uv1))
        else {
            skipped += 1;
            continue;
        };
        let (Some(d1), Some(d0)) = (
            line_distance(&r1, &(essential * r0), intrinsics[1].fx()),
            line_distance(&r0, &(essential.transpose() * r1), intrinsics[0].fx()),
        ) else {
            skipped += 1;
            continue;
        };
        let Some(x) = triangulate(&r0, &r1, &rot, &t) else {
            skipped += 1;
            continue;
        };
        distances.extend([d0, d1]);
        boards.entry(frame).or_default().push((corner, x));
    }
    if distances.is_empty() {
        return Err(Error::Degenerate(
            "no corner is seen by both cameras in the held-out frames".into(),
        ));
    }
    let n = distances.len() as f64;
    let (sq_mm, corners, frames) = triangulation_misfit(&boards, &held_out.target);
    Ok(StereoErrors {
        epipolar_mean_px: distances.iter().sum::<f64>() / n,
        epipolar_rms_px: (distances.iter().map(|d| d * d).sum::<f64>() / n).sqrt(),
        triangulation_rms_mm: if corners == 0 {
            f64::NAN
        } else {
            (sq_mm / corners as f64).sqrt()
        },
        pairs: distances.len() / 2,
        frames,
        skipped,
    })
}

/// The triangulated boards' squared misfit after each frame's best rigid
/// alignment (mm², summed over corners), the corners and the frames that count:
/// a frame with fewer than [`MIN_TRIANGULATED_CORNERS`] is left out.
fn triangulation_misfit(
    boards: &BTreeMap<usize, Vec<(usize, Vector3<f64>)>>,
    target: &crate::model::target::Target,
) -> (f64, usize, usize) {
    let mut sq_mm = 0.0;
    let mut corners = 0usize;
    let mut frames = 0;
    for points in boards.values() {
        if points.len() < MIN_TRIANGULATED_CORNERS {
            continue;
        }
        let nominal: Vec<Vector3<f64>> = points.iter().map(|(i, _)| target.nominal(*i)).collect();
        let triangulated: Vec<Vector3<f64>> = points.iter().map(|(_, x)| *x).collect();
        sq_mm += rigid_residual_sq(&nominal, &triangulated) * 1e6;
        corners += points.len();
        frames += 1;
    }
    (sq_mm, corners, frames)
}

/// Distance, pixels at focal length `f`, of ray `r`'s pinhole image from the line
/// `line` (homogeneous, in normalised coordinates); `None` for a ray at 90° or more.
fn line_distance(r: &Vector3<f64>, line: &Vector3<f64>, f: f64) -> Option<f64> {
    let scale = line.x.hypot(line.y);
    // Rays a few degrees short of 90° would dominate the mean with huge pixel values.
    (r.z > 1e-6 * r.norm() && scale > 0.0).then(|| f * (line.dot(&(r / r.z))).abs() / scale)
}

/// The midpoint of the closest points of the left ray `r0` (from the origin) and
/// the right ray `r1` (in the right camera's frame), in the left camera's frame;
/// `None` for parallel rays or a point behind either camera.
fn triangulate(
    r0: &Vector3<f64>,
    r1: &Vector3<f64>,
    rot: &Matrix3<f64>,
    t: &Vector3<f64>,
) -> Option<Vector3<f64>> {
    let c1 = -(rot.transpose() * t);
    let d1 = rot.transpose() * r1;
    // Minimise |s r0 − (c1 + u d1)|² over the depths s and u.
    let (a, b, c) = (r0.dot(r0), r0.dot(&d1), d1.dot(&d1));
    let det = a * c - b * b;
    if det <= 1e-14 * a * c {
        return None;
    }
    let (e, g) = (r0.dot(&c1), d1.dot(&c1));
    let s = (c * e - b * g) / det;
    let u = (b * e - a * g) / det;
    (s > 0.0 && u > 0.0).then(|| (s * r0 + c1 + u * d1) / 2.0)
}

/// Sum of squared distances between `points` and `reference` after the rigid
/// transform of `reference` that fits `points` best (Kabsch).
fn rigid_residual_sq(reference: &[Vector3<f64>], points: &[Vector3<f64>]) -> f64 {
    let n = points.len() as f64;
    let mean = |v: &[Vector3<f64>]| v.iter().fold(Vector3::zeros(), |a, p| a + p) / n;
    let (mr, mp) = (mean(reference), mean(points));
    let mut cov = Matrix3::zeros();
    for (r, p) in reference.iter().zip(points) {
        cov += (p - mp) * (r - mr).transpose();
    }
    let svd = cov.svd(true, true);
    let (u, vt) = (svd.u.expect("requested"), svd.v_t.expect("requested"));
    let mut s = Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let rot = u * s * vt;
    reference
        .iter()
        .zip(points)
        .map(|(r, p)| (rot * (r - mr) + mp - p).norm_squared())
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::synthetic::{Generator, Preset, Truth};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// Stereo frames of a rigid, perfectly printed board, without detector noise.
    fn exact(g: Generator) -> (Dataset, Truth) {
        let mut g = g;
        g.bend_scale = 0.0;
        g.print_scale = 0.0;
        g.noise_px = 0.0;
        g.generate()
    }

    fn stereo(images: usize, seed: u64) -> Generator {
        Generator::new(Preset::Stereo, Some(images), seed)
    }

    fn errors(truth: &Truth, data: &Dataset) -> StereoErrors {
        stereo_errors(&truth.intrinsics, &truth.camera_poses, data).unwrap()
    }

    #[test]
    fn zero_with_the_true_rig_and_exact_corners() {
        let (data, truth) = exact(stereo(30, 3));
        let e = errors(&truth, &data);
        assert!(e.pairs > 500 && e.frames >= 10, "{e:?}");
        assert_eq!(e.skipped, 0);
        assert!(e.epipolar_rms_px < 1e-6, "{e:?}");
        assert!(e.triangulation_rms_mm < 1e-6, "{e:?}");
    }

    #[test]
    fn a_turned_or_stretched_rig_is_seen() {
        let (data, truth) = exact(stereo(30, 4));
        // 0.05° about the baseline's normal tilts every epipolar line's offset by
        // about f·8.7e-4 ≈ 2.5 px in these 2900 px cameras.
        let mut turned = truth.camera_poses.clone();
        let tilt = Pose {
            rotation: [0.05f64.to_radians(), 0.0, 0.0],
            translation: [0.0; 3],
        };
        turned[1] = tilt.compose(&turned[1]);
        let e = stereo_errors(&truth.intrinsics, &turned, &data).unwrap();
        assert!(
            e.epipolar_mean_px > 1.0 && e.epipolar_mean_px < 5.0,
            "{e:?}"
        );
        // A baseline 1 % long triangulates boards 1 % too large: the corners of this
        // 0.84 m board lie 0.37 m (RMS) from its centre, so about 3.7 mm off after the
        // rigid alignment, while the epipolar lines do not move.
        let mut long = truth.camera_poses.clone();
        long[1].translation = long[1].translation.map(|x| x * 1.01);
        let e = stereo_errors(&truth.intrinsics, &long, &data).unwrap();
        assert!(e.epipolar_rms_px < 1e-6, "{e:?}");
        assert!(e.triangulation_rms_mm > 2.0, "{e:?}");
    }

    #[test]
    fn noise_across_the_epipolar_lines_gives_root_two_sigma() {
        // A rectified rig: same pinhole camera, pure baseline along x, so epipolar
        // lines are image rows and the distance of a pair is |v0 − v1|; noise of σ on
        // v in both images gives RMS √2·σ, noise on u none.
        let mut g = stereo(60, 5);
        let k = Intrinsics::pinhole(2900.0, 2900.0, 968.0, 608.0);
        g.intrinsics = vec![k, k];
        g.rig[1] = Pose {
            rotation: [0.0; 3],
            translation: [-0.3, 0.0, 0.0],
        };
        let (data, truth) = exact(g);
        let sigma = 0.3;
        let noisy = |axis: usize, seed: u64| {
            let mut d = data.clone();
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let normal = Normal::new(0.0, sigma).unwrap();
            for o in &mut d.observations {
                o.uv[axis] += normal.sample(&mut rng);
            }
            errors(&truth, &d)
        };
        let across = noisy(1, 1);
        let expected = 2f64.sqrt() * sigma;
        // Relative standard error of an RMS over n pairs: 1/√(2n) ≈ 2 % here.
        assert!(across.pairs > 1000, "{across:?}");
        assert!(
            (across.epipolar_rms_px / expected - 1.0).abs() < 0.06,
            "{across:?} vs {expected}"
        );
        // The mean of |N(0, 2σ²)| is √2σ·√(2/π).
        let mean = expected * (2.0 / std::f64::consts::PI).sqrt();
        assert!(
            (across.epipolar_mean_px / mean - 1.0).abs() < 0.06,
            "{across:?} vs {mean}"
        );
        let along = noisy(0, 2);
        assert!(along.epipolar_rms_px < 1e-6, "{along:?}");
        // Noise along the rows still moves the triangulated depth.
        assert!(along.triangulation_rms_mm > 0.01, "{along:?}");
    }

    #[test]
    fn refuses_a_single_camera_and_data_without_pairs() {
        let (data, truth) = exact(stereo(6, 6));
        let e = stereo_errors(&truth.intrinsics[..1], &truth.camera_poses[..1], &data);
        assert!(e.unwrap_err().to_string().contains("two cameras"));
        let mut left_only = data.clone();
        left_only.observations.retain(|o| o.camera == 0);
        let e = stereo_errors(&truth.intrinsics, &truth.camera_poses, &left_only);
        assert!(e.unwrap_err().to_string().contains("both cameras"));
    }
}
