//! What the OpenCV family (`radial3`, `opencv5`, `opencv8`) shares: the radial
//! and tangential terms, and the forms in which OpenCV, Kalibr and COLMAP hold
//! the family (`cpp/lens/opencv_family.h` is the C++ side).
use super::info::{ColmapForm, KalibrForm, OpenCvForm};
use super::projection::{DistortionDerivatives, MAX_DISTORTION};
use nalgebra::{Matrix2, Vector2};

/// 1 + k1 r² + k2 r⁴ + k3 r⁶.
pub(super) fn radial(r2: f64, k1: f64, k2: f64, k3: f64) -> f64 {
    1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
}

/// ∂/∂r² of [`radial`]: k1 + 2 k2 r² + 3 k3 r⁴.
pub(super) fn radial_slope(r2: f64, k1: f64, k2: f64, k3: f64) -> f64 {
    k1 + r2 * (2.0 * k2 + r2 * 3.0 * k3)
}

/// The derivatives of (x', y') d by (x', y') for a radial factor d whose slope
/// by r² is `slope`.
fn radial_by_point(x: f64, y: f64, d: f64, slope: f64) -> Matrix2<f64> {
    let xy = 2.0 * x * y * slope;
    Matrix2::new(d + 2.0 * x * x * slope, xy, xy, d + 2.0 * y * y * slope)
}

/// The derivatives of a distorted point whose radial factor is d (slope by r²
/// `slope`): `value` is the model's own distorted point; `radial` lists, per
/// parameter after fx fy cx cy that d depends on, its index there and ∂d/∂p;
/// `tangential` says whether p1 = p[6], p2 = p[7] add OpenCV's tangential terms.
pub(super) fn derivatives(
    p: &[f64],
    (x, y, r2): (f64, f64, f64),
    (value, d, slope): (Vector2<f64>, f64, f64),
    radial: &[(usize, f64)],
    tangential: bool,
) -> DistortionDerivatives {
    let mut d_params = [[0.0; MAX_DISTORTION]; 2];
    for &(i, dd) in radial {
        d_params[0][i] = x * dd;
        d_params[1][i] = y * dd;
    }
    let mut d_input = radial_by_point(x, y, d, slope);
    if tangential {
        let (p1, p2) = (p[6], p[7]);
        let cross = 2.0 * (p1 * x + p2 * y);
        d_input += Matrix2::new(
            2.0 * p1 * y + 6.0 * p2 * x,
            cross,
            cross,
            6.0 * p1 * y + 2.0 * p2 * x,
        );
        [d_params[0][2], d_params[1][2]] = [2.0 * x * y, r2 + 2.0 * y * y];
        [d_params[0][3], d_params[1][3]] = [r2 + 2.0 * x * x, 2.0 * x * y];
    }
    DistortionDerivatives {
        value,
        d_input,
        d_params,
    }
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
