//! Camera model: the radial3 lens (SPEC §1) and rigid poses, in f64.
use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// Intrinsics θ = (fx, fy, cx, cy, k1, k2, k3) of the radial3 model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub k1: f64,
    pub k2: f64,
    pub k3: f64,
}

impl Intrinsics {
    /// Pinhole intrinsics without distortion.
    pub fn pinhole(fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Intrinsics {
            fx,
            fy,
            cx,
            cy,
            k1: 0.0,
            k2: 0.0,
            k3: 0.0,
        }
    }

    /// The parameter vector in the order the solver uses.
    pub fn to_array(&self) -> [f64; 7] {
        [
            self.fx, self.fy, self.cx, self.cy, self.k1, self.k2, self.k3,
        ]
    }

    /// Inverse of [`Intrinsics::to_array`].
    pub fn from_slice(p: &[f64]) -> Self {
        Intrinsics {
            fx: p[0],
            fy: p[1],
            cx: p[2],
            cy: p[3],
            k1: p[4],
            k2: p[5],
            k3: p[6],
        }
    }

    /// The 3×3 camera matrix K.
    pub fn camera_matrix(&self) -> Matrix3<f64> {
        Matrix3::new(self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }

    /// Radial factor d(r²).
    fn distortion(&self, r2: f64) -> f64 {
        1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
    }

    /// Projects a camera-frame point; `None` behind the camera.
    pub fn project(&self, xc: &Vector3<f64>) -> Option<Vector2<f64>> {
        if xc.z <= 0.0 {
            return None;
        }
        let (x, y) = (xc.x / xc.z, xc.y / xc.z);
        let d = self.distortion(x * x + y * y);
        Some(Vector2::new(
            self.fx * x * d + self.cx,
            self.fy * y * d + self.cy,
        ))
    }

    /// Unprojects a pixel to normalised coordinates (x/z, y/z) by Newton iteration on r.
    /// `None` where the radial map is not invertible.
    pub fn unproject(&self, uv: &Vector2<f64>) -> Option<Vector2<f64>> {
        let xd = (uv.x - self.cx) / self.fx;
        let yd = (uv.y - self.cy) / self.fy;
        let rd = (xd * xd + yd * yd).sqrt();
        if rd < 1e-15 {
            return Some(Vector2::new(xd, yd));
        }
        // Solve g(r) = r d(r²) - rd = 0 for the undistorted radius r.
        let mut r = rd;
        for _ in 0..50 {
            let r2 = r * r;
            let g = r * self.distortion(r2) - rd;
            let dg = 1.0 + r2 * (3.0 * self.k1 + r2 * (5.0 * self.k2 + 7.0 * r2 * self.k3));
            if dg.abs() < 1e-12 {
                return None;
            }
            let step = g / dg;
            r -= step;
            if step.abs() < 1e-15 * (1.0 + r.abs()) {
                break;
            }
        }
        let residual = r * self.distortion(r * r) - rd;
        if !r.is_finite() || r <= 0.0 || residual.abs() > 1e-9 {
            return None;
        }
        let s = r / rd;
        Some(Vector2::new(xd * s, yd * s))
    }
}

/// A rigid transform x' = R(rotation)·x + translation, rotation as angle-axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub rotation: [f64; 3],
    pub translation: [f64; 3],
}

impl Default for Pose {
    fn default() -> Self {
        Pose::identity()
    }
}

impl Pose {
    /// The identity transform.
    pub fn identity() -> Self {
        Pose {
            rotation: [0.0; 3],
            translation: [0.0; 3],
        }
    }

    /// Builds a pose from a rotation matrix and a translation.
    pub fn from_parts(r: &Rotation3<f64>, t: &Vector3<f64>) -> Self {
        let aa = r.scaled_axis();
        Pose {
            rotation: [aa.x, aa.y, aa.z],
            translation: [t.x, t.y, t.z],
        }
    }

    /// The rotation as a matrix.
    pub fn rotation_matrix(&self) -> Rotation3<f64> {
        Rotation3::from_scaled_axis(Vector3::from(self.rotation))
    }

    /// The translation vector.
    pub fn translation_vector(&self) -> Vector3<f64> {
        Vector3::from(self.translation)
    }

    /// Applies the transform to a point.
    pub fn transform(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.rotation_matrix() * x + self.translation_vector()
    }

    /// self ∘ other: first `other`, then `self`.
    pub fn compose(&self, other: &Pose) -> Pose {
        let r = self.rotation_matrix() * other.rotation_matrix();
        let t = self.rotation_matrix() * other.translation_vector() + self.translation_vector();
        Pose::from_parts(&r, &t)
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Pose {
        let rt = self.rotation_matrix().inverse();
        Pose::from_parts(&rt, &-(rt * self.translation_vector()))
    }

    /// The six solver parameters.
    pub fn to_array(&self) -> [f64; 6] {
        let (r, t) = (self.rotation, self.translation);
        [r[0], r[1], r[2], t[0], t[1], t[2]]
    }

    /// Inverse of [`Pose::to_array`].
    pub fn from_slice(p: &[f64]) -> Self {
        Pose {
            rotation: [p[0], p[1], p[2]],
            translation: [p[3], p[4], p[5]],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn unproject_inverts_project() {
        let k = Intrinsics {
            k1: -0.2,
            k2: 0.1,
            k3: -0.02,
            ..Intrinsics::pinhole(1000.0, 1010.0, 640.0, 360.0)
        };
        for &(x, y) in &[(0.0, 0.0), (0.3, -0.2), (-0.5, 0.4), (0.01, 0.6)] {
            let uv = k.project(&Vector3::new(x, y, 1.0)).unwrap();
            let back = k.unproject(&uv).unwrap();
            assert_relative_eq!(back.x, x, epsilon = 1e-12);
            assert_relative_eq!(back.y, y, epsilon = 1e-12);
        }
    }

    #[test]
    fn compose_with_inverse_is_identity() {
        let p = Pose {
            rotation: [0.1, -0.4, 0.25],
            translation: [0.3, -1.0, 4.0],
        };
        let q = p.compose(&p.inverse());
        for v in q.to_array() {
            assert!(v.abs() < 1e-12);
        }
        let x = Vector3::new(0.2, 0.5, -0.1);
        assert_relative_eq!(p.inverse().transform(&p.transform(&x)), x, epsilon = 1e-12);
    }
}

/// A camera of the rig as the config describes it.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    pub name: String,
    pub width: u32,
    pub height: u32,
    #[serde(default = "default_model")]
    pub model: String,
}

fn default_model() -> String {
    "radial3".into()
}
