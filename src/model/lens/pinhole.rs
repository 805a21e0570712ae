//! `pinhole`: a pinhole camera without distortion, for lenses whose distortion
//! is below the noise (`cpp/lens/pinhole.h` is its C++ side).
use super::info::{ColmapForm, KalibrForm, LensInfo, OpenCvForm};
use super::projection::{DistortionDerivatives, Projection, MAX_DISTORTION};
use nalgebra::{Matrix2, Vector2};

/// No distortion: (x', y') itself.
fn distort(_: &[f64], x: f64, y: f64) -> Vector2<f64> {
    Vector2::new(x, y)
}

/// [`distort`] with its derivatives: the identity.
fn derivatives(_: &[f64], x: f64, y: f64) -> DistortionDerivatives {
    DistortionDerivatives {
        value: Vector2::new(x, y),
        d_input: Matrix2::identity(),
        d_params: [[0.0; MAX_DISTORTION]; 2],
    }
}

pub(super) const INFO: LensInfo = LensInfo {
    name: "pinhole",
    params: &["fx", "fy", "cx", "cy"],
    help: "a pinhole camera without distortion",
    pinhole_like: true,
    projection: Projection::PinholeLike {
        distort,
        derivatives,
    },
    undistorted: &[],
    // The simulated 17 mm lens of radial3, without its distortion.
    synthetic: &[2901.0, 2899.5, 975.3, 601.8],
    prior_params: &[],
    second_start: None,
    // OpenCV's and ROS's plumb_bob with every coefficient 0.
    opencv: Some(OpenCvForm {
        distortion_model: "plumb_bob",
        coefficients: &["k1", "k2", "p1", "p2", "k3"],
        fisheye: false,
    }),
    ros: Some("plumb_bob"),
    // Kalibr's pinhole-radtan with every coefficient 0.
    kalibr: Some(KalibrForm {
        name: "pinhole-radtan",
        camera_model: "pinhole",
        intrinsics: &["fx", "fy", "cx", "cy"],
        distortion_model: "radtan",
        coefficients: &["k1", "k2", "p1", "p2"],
        requires_zero: &[],
    }),
    colmap: &[ColmapForm {
        model: "PINHOLE",
        params: &[],
        requires_zero: &[],
    }],
    mrcal: Some("LENSMODEL_PINHOLE"),
    mrcal_via: None,
};

#[cfg(test)]
mod tests {
    #[test]
    fn unproject_inverts_project() {
        super::super::tests::round_trips(super::INFO.name, &[1000.0, 1010.0, 640.0, 360.0]);
    }
}
