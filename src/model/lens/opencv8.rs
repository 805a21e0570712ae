//! `opencv8`: OpenCV's rational model, ROS `rational_polynomial`, mrcal
//! `LENSMODEL_OPENCV8` (`cpp/lens/opencv8.h` is its C++ side).
use super::info::LensInfo;
use super::opencv_family::{self as cv, radial, with_tangential};
use super::projection::Projection;
use nalgebra::Vector2;

/// OpenCV's distortion with the radial factor (1 + k1 r² + k2 r⁴ + k3 r⁶) /
/// (1 + k4 r² + k5 r⁴ + k6 r⁶).
fn distort(p: &[f64], x: f64, y: f64) -> Vector2<f64> {
    let r2 = x * x + y * y;
    let d = radial(r2, p[4], p[5], p[8]) / radial(r2, p[9], p[10], p[11]);
    with_tangential(p, x, y, r2, d)
}

pub(super) const INFO: LensInfo = LensInfo {
    name: "opencv8",
    params: &[
        "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6",
    ],
    help: "OpenCV's rational model (ROS rational_polynomial)",
    pinhole_like: true,
    projection: Projection::PinholeLike(distort),
    undistorted: &[0.0; 8],
    // A 112° (diagonal) wide-angle lens: a narrow lens cannot determine the
    // rational terms.
    synthetic: &[
        1100.0, 1099.4, 975.3, 601.8, 0.1, 0.01, 1.2e-3, -8e-4, 5e-4, 0.3, 0.03, 1e-3,
    ],
    prior_params: &["k4", "k5", "k6"],
    second_start: None,
    opencv: Some(cv::RATIONAL_POLYNOMIAL),
    ros: Some("rational_polynomial"),
    kalibr: None,
    colmap: &[cv::COLMAP_FULL_OPENCV],
    mrcal: Some("LENSMODEL_OPENCV8"),
    mrcal_via: None,
};

#[cfg(test)]
mod tests {
    #[test]
    fn unproject_inverts_project() {
        super::super::tests::round_trips(
            super::INFO.name,
            &[
                1000.0, 1010.0, 640.0, 360.0, 0.3, -0.1, 1e-3, -2e-3, 0.01, 0.5, -0.05, 0.02,
            ],
        );
    }
}
