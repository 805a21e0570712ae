//! `opencv5`: OpenCV's default five coefficients, ROS `plumb_bob`
//! (`cpp/lens/opencv5.h` is its C++ side).
use super::info::LensInfo;
use super::opencv_family::{self as cv, radial, radial_slope, with_tangential};
use super::projection::{DistortionDerivatives, Projection};
use nalgebra::Vector2;

/// OpenCV's distortion with k1 k2 k3 (at 4, 5, 8) and p1 p2 (at 6, 7).
fn distort(p: &[f64], x: f64, y: f64) -> Vector2<f64> {
    let r2 = x * x + y * y;
    with_tangential(p, x, y, r2, radial(r2, p[4], p[5], p[8]))
}

/// [`distort`] with its derivatives.
fn derivatives(p: &[f64], x: f64, y: f64) -> DistortionDerivatives {
    let r2 = x * x + y * y;
    let d = radial(r2, p[4], p[5], p[8]);
    let slope = radial_slope(r2, p[4], p[5], p[8]);
    let r4 = r2 * r2;
    let value = with_tangential(p, x, y, r2, d);
    let radial = [(0, r2), (1, r4), (4, r4 * r2)];
    cv::derivatives(p, (x, y, r2), (value, d, slope), &radial, true)
}

pub(super) const INFO: LensInfo = LensInfo {
    name: "opencv5",
    params: &["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"],
    help: "OpenCV's default five coefficients (ROS plumb_bob)",
    pinhole_like: true,
    projection: Projection::PinholeLike {
        distort,
        derivatives,
    },
    undistorted: &[0.0; 5],
    // The 17 mm lens of radial3, with tangential terms.
    synthetic: &[
        2901.0, 2899.5, 975.3, 601.8, -0.11, 0.14, 1.2e-3, -8e-4, -0.05,
    ],
    prior_params: &[],
    second_start: None,
    opencv: Some(cv::PLUMB_BOB),
    ros: Some("plumb_bob"),
    kalibr: Some(cv::PINHOLE_RADTAN),
    colmap: &[cv::COLMAP_OPENCV, cv::COLMAP_FULL_OPENCV],
    mrcal: Some("LENSMODEL_OPENCV5"),
    mrcal_via: None,
};

#[cfg(test)]
mod tests {
    #[test]
    fn unproject_inverts_project() {
        super::super::tests::round_trips(
            super::INFO.name,
            &[1000.0, 1010.0, 640.0, 360.0, -0.2, 0.1, 1e-3, -2e-3, -0.02],
        );
    }
}
