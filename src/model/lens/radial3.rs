//! `radial3`: the paper's model, OpenCV's with p1 = p2 = 0
//! (`cpp/lens/radial3.h` is its C++ side).
use super::info::LensInfo;
use super::model::LensModel;
use super::opencv_family::{self as cv, radial, radial_slope};
use super::projection::{DistortionDerivatives, Projection};
use nalgebra::Vector2;

/// (x', y') (1 + k1 r² + k2 r⁴ + k3 r⁶).
fn distort(p: &[f64], x: f64, y: f64) -> Vector2<f64> {
    let r2 = x * x + y * y;
    let d = radial(r2, p[4], p[5], p[6]);
    Vector2::new(x * d, y * d)
}

/// [`distort`] with its derivatives.
fn derivatives(p: &[f64], x: f64, y: f64) -> DistortionDerivatives {
    let r2 = x * x + y * y;
    let d = radial(r2, p[4], p[5], p[6]);
    let slope = radial_slope(r2, p[4], p[5], p[6]);
    let r4 = r2 * r2;
    let value = Vector2::new(x * d, y * d);
    let radial = [(0, r2), (1, r4), (2, r4 * r2)];
    cv::derivatives(p, (x, y, r2), (value, d, slope), &radial, false)
}

pub(super) const INFO: LensInfo = LensInfo {
    name: "radial3",
    params: &["fx", "fy", "cx", "cy", "k1", "k2", "k3"],
    help: "the paper's model, OpenCV's with p1 = p2 = 0",
    pinhole_like: true,
    projection: Projection::PinholeLike {
        distort,
        derivatives,
    },
    undistorted: &[0.0; 3],
    // The simulated 17 mm lens on 5.86 µm pixels.
    synthetic: &[2901.0, 2899.5, 975.3, 601.8, -0.11, 0.14, -0.05],
    prior_params: &[],
    second_start: None,
    opencv: Some(cv::PLUMB_BOB),
    ros: Some("plumb_bob"),
    kalibr: Some(cv::PINHOLE_RADTAN),
    colmap: &[cv::COLMAP_OPENCV, cv::COLMAP_FULL_OPENCV],
    mrcal: None,
    mrcal_via: Some(LensModel::OpenCv5),
};

#[cfg(test)]
mod tests {
    #[test]
    fn unproject_inverts_project() {
        super::super::tests::round_trips(
            super::INFO.name,
            &[1000.0, 1010.0, 640.0, 360.0, -0.2, 0.1, -0.02],
        );
    }
}
