//! What the OpenCV family (`radial3`, `opencv5`, `opencv8`) shares: the radial
//! and tangential terms, and the forms in which OpenCV, Kalibr and COLMAP hold
//! the family (`cpp/lens/opencv_family.h` is the C++ side).
use super::info::{ColmapForm, KalibrForm, OpenCvForm};
use nalgebra::Vector2;

/// 1 + k1 r² + k2 r⁴ + k3 r⁶.
pub(super) fn radial(r2: f64, k1: f64, k2: f64, k3: f64) -> f64 {
    1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
}

/// OpenCV's distorted point: radial factor `d` and tangential terms p1 = p[6],
/// p2 = p[7].
pub(super) fn with_tangential(p: &[f64], x: f64, y: f64, r2: f64, d: f64) -> Vector2<f64> {
    let (p1, p2) = (p[6], p[7]);
    let xy = x * y;
    Vector2::new(
        x * d + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x),
        y * d + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy,
    )
}

/// `calibrateCamera`'s default five coefficients (ROS `plumb_bob`).
pub(super) const PLUMB_BOB: OpenCvForm = OpenCvForm {
    distortion_model: "plumb_bob",
    coefficients: &["k1", "k2", "p1", "p2", "k3"],
    fisheye: false,
};

/// `calibrateCamera`'s rational model (ROS `rational_polynomial`).
pub(super) const RATIONAL_POLYNOMIAL: OpenCvForm = OpenCvForm {
    distortion_model: "rational_polynomial",
    coefficients: &["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"],
    fisheye: false,
};

/// Kalibr's `pinhole-radtan`: k1 k2 p1 p2, no k3.
pub(super) const PINHOLE_RADTAN: KalibrForm = KalibrForm {
    name: "pinhole-radtan",
    camera_model: "pinhole",
    intrinsics: &["fx", "fy", "cx", "cy"],
    distortion_model: "radtan",
    coefficients: &["k1", "k2", "p1", "p2"],
    requires_zero: &["k3"],
};

/// COLMAP's `OPENCV`: k1 k2 p1 p2, no k3 (a nonzero k3 needs `FULL_OPENCV`).
pub(super) const COLMAP_OPENCV: ColmapForm = ColmapForm {
    model: "OPENCV",
    params: &["k1", "k2", "p1", "p2"],
    requires_zero: &["k3"],
};

/// COLMAP's `FULL_OPENCV`: k1 k2 p1 p2 k3 k4 k5 k6.
pub(super) const COLMAP_FULL_OPENCV: ColmapForm = ColmapForm {
    model: "FULL_OPENCV",
    params: &["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"],
    requires_zero: &[],
};
