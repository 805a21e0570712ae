//! How a lens model maps camera-frame points to normalised image coordinates
//! and back: the one piece of a registry entry that is code.
use nalgebra::{Vector2, Vector3};

/// How a model maps camera-frame points to normalised image coordinates m,
/// whose pixel is (fx mx + cx, fy my + cy), and back.
#[derive(Debug, Clone, Copy)]
pub enum Projection {
    /// A pinhole image (x/z, y/z), in front of the camera only, then a
    /// distortion of it: parameters in solver order and the undistorted point
    /// in, the distorted point out. Unprojection inverts it by Newton's method.
    PinholeLike(fn(&[f64], f64, f64) -> Vector2<f64>),
    /// A model with its own maps: `None` where the model has no image of a
    /// point, or no valid ray (not normalised) for an m.
    Central {
        project: fn(&[f64], &Vector3<f64>) -> Option<Vector2<f64>>,
        unproject: fn(&[f64], &Vector2<f64>) -> Option<Vector3<f64>>,
    },
}
