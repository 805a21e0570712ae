//! How a lens model maps camera-frame points to normalised image coordinates
//! and back, with the map's derivatives: the one piece of a registry entry that
//! is code.
use nalgebra::{Matrix2, Matrix2x3, Vector2, Vector3};

/// Most parameters a model has after fx, fy, cx, cy (`MAX_PARAMS` − 4).
pub const MAX_DISTORTION: usize = 8;

/// A map's value with its derivatives: `d_input` by its input (the undistorted
/// point, or the camera-frame point) and `d_params` by the parameters after fx,
/// fy, cx, cy (the first `num_params − 4` columns of each row hold them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Derivatives<D> {
    pub value: Vector2<f64>,
    pub d_input: D,
    pub d_params: [[f64; MAX_DISTORTION]; 2],
}

/// A distortion's value and derivatives by the undistorted point (x', y').
pub type DistortionDerivatives = Derivatives<Matrix2<f64>>;
/// A central model's m and its derivatives by the camera-frame point.
pub type PointDerivatives = Derivatives<Matrix2x3<f64>>;

/// How a model maps camera-frame points to normalised image coordinates m,
/// whose pixel is (fx mx + cx, fy my + cy), and back.
#[derive(Debug, Clone, Copy)]
pub enum Projection {
    /// A pinhole image (x/z, y/z), in front of the camera only, then a
    /// distortion of it: parameters in solver order and the undistorted point
    /// in, the distorted point out; `derivatives` gives the same point (the same
    /// arithmetic) with its closed-form derivatives. Unprojection inverts it by
    /// Newton's method.
    PinholeLike {
        distort: fn(&[f64], f64, f64) -> Vector2<f64>,
        derivatives: fn(&[f64], f64, f64) -> DistortionDerivatives,
    },
    /// A model with its own maps: `None` where the model has no image of a
    /// point, or no valid ray (not normalised) for an m; `derivatives` is
    /// `project` with its closed-form derivatives.
    Central {
        project: fn(&[f64], &Vector3<f64>) -> Option<Vector2<f64>>,
        unproject: fn(&[f64], &Vector2<f64>) -> Option<Vector3<f64>>,
        derivatives: fn(&[f64], &Vector3<f64>) -> Option<PointDerivatives>,
    },
}
