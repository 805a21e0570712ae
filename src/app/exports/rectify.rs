//! OpenCV's `stereoRectify` for a calibrated pair, reimplemented so the ROS
//! `camera_info` of a stereo pair carries the rectification (`R`, `P`) that ROS's
//! own `camera_calibration` would compute from the same intrinsics and pose.
//!
//! The convention is OpenCV 4's with `CALIB_ZERO_DISPARITY` (both principal points
//! equal) and `alpha = -1` (no scaling to keep or crop pixels: the new focal length
//! is the mean of the two cameras' focal lengths across the baseline). OpenCV
//! computes the new principal point from the four image corners undistorted with
//! five fixed-point iterations in single precision; this copy keeps those steps
//! and roundings, because they move the principal point by up to 1e-4 px and the
//! result must agree with `cv2.stereoRectify` to 1e-9 relative.
use crate::model::lens::Intrinsics;
use nalgebra::{Matrix3, Matrix3x4, Rotation3, Vector3};

/// The rectification of a stereo pair: rotations from each camera into its
/// rectified frame, and the rectified cameras' projection matrices.
#[derive(Debug, Clone, PartialEq)]
pub struct Rectification {
    /// Camera 0's rectifying rotation: x_rect = R1 x_0.
    pub r1: Matrix3<f64>,
    /// Camera 1's rectifying rotation: x_rect = R2 x_1.
    pub r2: Matrix3<f64>,
    /// Camera 0's rectified projection [f 0 cx 0; 0 f cy 0; 0 0 1 0].
    pub p1: Matrix3x4<f64>,
    /// Camera 1's rectified projection, with the baseline term f·t in column 3.
    pub p2: Matrix3x4<f64>,
}

/// OpenCV's distortion vector (k1 k2 p1 p2 k3 k4 k5 k6) of a model that
/// `calibrateCamera` has (the registry's OpenCV form, not `cv::fisheye`); `None`
/// for the others, which `stereoRectify` does not take.
fn opencv_coefficients(i: &Intrinsics) -> Option<[f64; 8]> {
    i.model().info().opencv.filter(|f| !f.fisheye)?;
    let v = super::common::values(i, &["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"]);
    v.try_into().ok()
}

/// `cv::undistortPoints` without R and P: five fixed-point iterations, as OpenCV
/// runs them by default, on a pixel; normalised coordinates out.
fn undistort_opencv(i: &Intrinsics, k: &[f64; 8], u: f64, v: f64) -> (f64, f64) {
    let (ifx, ify) = (1.0 / i.fx(), 1.0 / i.fy());
    let (x0, y0) = ((u - i.cx()) * ifx, (v - i.cy()) * ify);
    let (mut x, mut y) = (x0, y0);
    for _ in 0..5 {
        let r2 = x * x + y * y;
        let icdist = (1.0 + ((k[7] * r2 + k[6]) * r2 + k[5]) * r2)
            / (1.0 + ((k[4] * r2 + k[1]) * r2 + k[0]) * r2);
        if icdist < 0.0 {
            // OpenCV gives up on a point beyond the fold and keeps it undistorted.
            return (x0, y0);
        }
        let dx = 2.0 * k[2] * x * y + k[3] * (r2 + 2.0 * x * x);
        let dy = k[2] * (r2 + 2.0 * y * y) + 2.0 * k[3] * x * y;
        x = (x0 - dx) * icdist;
        y = (y0 - dy) * icdist;
    }
    (x, y)
}

/// Where the rectified camera (focal length `f`, principal point 0, rotation `r`)
/// sees the mean of the image's four corner pixels, as OpenCV computes it (points
/// stored in single precision between the steps).
fn corner_mean(
    i: &Intrinsics,
    k: &[f64; 8],
    size: (u32, u32),
    r: &Matrix3<f64>,
    f: f64,
) -> (f64, f64) {
    let (nx, ny) = (size.0 as f64, size.1 as f64);
    let mut sum = (0.0, 0.0);
    for c in 0..4 {
        let u = ((c % 2) as f64 * (nx - 1.0)) as f32 as f64;
        let v = ((c / 2) as f64 * (ny - 1.0)) as f32 as f64;
        let (x, y) = undistort_opencv(i, k, u, v);
        let p = Vector3::new(x as f32 as f64, y as f32 as f64, 1.0);
        let q = r * p;
        let iz = 1.0 / q.z;
        sum.0 += ((q.x * iz) * f) as f32 as f64;
        sum.1 += ((q.y * iz) * f) as f32 as f64;
    }
    (sum.0 / 4.0, sum.1 / 4.0)
}

/// The rotations of OpenCV's rectification: half the relative rotation each way,
/// then a common rotation that puts the baseline on the x (or y) axis. Returns
/// R1, R2, the baseline in the rectified frame and its axis (0: x, 1: y).
fn rectifying_rotations(
    rotation: &[f64; 3],
    t: &Vector3<f64>,
) -> (Matrix3<f64>, Matrix3<f64>, Vector3<f64>, usize) {
    let om = -0.5 * Vector3::from(*rotation);
    let r_r = *Rotation3::from_scaled_axis(om).matrix();
    let tr = r_r * t;
    let idx = if tr.x.abs() > tr.y.abs() { 0 } else { 1 };
    let c = tr[idx];
    let mut uu = Vector3::zeros();
    uu[idx] = if c > 0.0 { 1.0 } else { -1.0 };
    let mut ww = tr.cross(&uu);
    let nw = ww.norm();
    if nw > 0.0 {
        ww *= (c.abs() / tr.norm()).acos() / nw;
    }
    let w_r = *Rotation3::from_scaled_axis(ww).matrix();
    let r1 = w_r * r_r.transpose();
    let r2 = w_r * r_r;
    (r1, r2, r2 * t, idx)
}

/// OpenCV's `stereoRectify(K1, D1, K2, D2, size, R, T, CALIB_ZERO_DISPARITY,
/// alpha = -1)` for camera 1 posed at `rotation` (angle-axis), `translation`
/// relative to camera 0 (x_1 = R x_0 + T), both with image `size`. `None` when a
/// camera is not pinhole-like or the cameras coincide.
pub fn stereo_rectify(
    cam0: &Intrinsics,
    cam1: &Intrinsics,
    size: (u32, u32),
    rotation: &[f64; 3],
    translation: &[f64; 3],
) -> Option<Rectification> {
    let (d0, d1) = (opencv_coefficients(cam0)?, opencv_coefficients(cam1)?);
    let t = Vector3::from(*translation);
    if t.norm() <= 0.0 {
        return None;
    }
    let (r1, r2, t_rect, idx) = rectifying_rotations(rotation, &t);
    // The focal length across the baseline, averaged (OpenCV 4 with the output
    // image size equal to the input size).
    let across = |i: &Intrinsics| if idx == 0 { i.fy() } else { i.fx() };
    let f = (across(cam0) + across(cam1)) * 0.5;
    let (nx, ny) = (size.0 as f64, size.1 as f64);
    let mut cc = [(0.0, 0.0); 2];
    for (k, (cam, d, r)) in [(cam0, &d0, &r1), (cam1, &d1, &r2)].into_iter().enumerate() {
        let (mx, my) = corner_mean(cam, d, size, r, f);
        cc[k] = ((nx - 1.0) / 2.0 - mx, (ny - 1.0) / 2.0 - my);
    }
    // CALIB_ZERO_DISPARITY: one principal point for both; then OpenCV's rescaling
    // to the output size (the same size here, kept for its rounding).
    let c = ((cc[0].0 + cc[1].0) * 0.5, (cc[0].1 + cc[1].1) * 0.5);
    let c = (nx * c.0 / nx, ny * c.1 / ny);
    let mut p1 = Matrix3x4::zeros();
    p1[(0, 0)] = f;
    p1[(1, 1)] = f;
    p1[(0, 2)] = c.0;
    p1[(1, 2)] = c.1;
    p1[(2, 2)] = 1.0;
    let mut p2 = p1;
    p2[(idx, 3)] = t_rect[idx] * f;
    Some(Rectification { r1, r2, p1, p2 })
}
