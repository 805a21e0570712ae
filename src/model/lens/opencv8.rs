//! `opencv8`: OpenCV's rational model, ROS `rational_polynomial`, mrcal
//! `LENSMODEL_OPENCV8` (`cpp/lens/opencv8.h` is its C++ side).
use super::info::LensInfo;
use super::opencv_family::{self as cv, radial, radial_slope, with_tangential};
use super::projection::{DistortionDerivatives, Projection};
use nalgebra::Vector2;

/// OpenCV's distortion with the radial factor (1 + k1 r² + k2 r⁴ + k3 r⁶) /
/// (1 + k4 r² + k5 r⁴ + k6 r⁶).
fn distort(p: &[f64], x: f64, y: f64) -> Vector2<f64> {
    let r2 = x * x + y * y;
    let d = radial(r2, p[4], p[5], p[8]) / radial(r2, p[9], p[10], p[11]);
    with_tangential(p, x, y, r2, d)
}

/// [`distort`] with its derivatives: d = N/D, so ∂d = (∂N − d ∂D)/D.
fn derivatives(p: &[f64], x: f64, y: f64) -> DistortionDerivatives {
    let r2 = x * x + y * y;
    let (num, den) = (radial(r2, p[4], p[5], p[8]), radial(r2, p[9], p[10], p[11]));
    let d = num / den;
    let slope =
        (radial_slope(r2, p[4], p[5], p[8]) - d * radial_slope(r2, p[9], p[10], p[11])) / den;
    let powers = [r2, r2 * r2, r2 * r2 * r2];
    let value = with_tangential(p, x, y, r2, d);
    let (n, m) = (|i: usize| powers[i] / den, |i: usize| -d * powers[i] / den);
    let radial = [
        (0, n(0)),
        (1, n(1)),
        (4, n(2)),
        (5, m(0)),
        (6, m(1)),
        (7, m(2)),
    ];
    cv::derivatives(p, (x, y, r2), (value, d, slope), &radial, true)
}

pub(super) const INFO: LensInfo = LensInfo {
    name: "opencv8",
    params: &[
        "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6",
    ],
    help: "OpenCV's rational model (ROS rational_polynomial)",
    pinhole_like: true,
    projection: Projection::PinholeLike {
        distort,
        derivatives,
    },
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
