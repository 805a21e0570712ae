//! Rigid transforms: a pose is an angle-axis rotation and a translation, named
//! by the direction it maps (`camera_from_board`).
use nalgebra::{Rotation3, Vector3};
use serde::{Deserialize, Serialize};

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
