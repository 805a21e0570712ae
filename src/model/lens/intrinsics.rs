//! Intrinsics θ of a camera under any registered lens model, with projection and
//! unprojection through the model's registry entry.
use super::model::{LensModel, MAX_PARAMS};
use super::pinhole_like;
use super::projection::Projection;
use nalgebra::{Matrix3, Vector2, Vector3};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

/// Intrinsics θ of a camera under one lens model.
#[derive(Clone, Copy, PartialEq)]
pub struct Intrinsics {
    model: LensModel,
    values: [f64; MAX_PARAMS],
}

impl fmt::Debug for Intrinsics {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut s = f.debug_struct(self.model.name());
        for (name, v) in self.model.param_names().iter().zip(self.params()) {
            s.field(name, v);
        }
        s.finish()
    }
}

impl Intrinsics {
    /// A model's intrinsics with the given focal lengths and principal point and
    /// no distortion: the registry's `undistorted` values (zero coefficients, or
    /// for `ds` a stereographic lens, which has the focal length `fx` at the
    /// image centre).
    pub fn pinhole_of(model: LensModel, fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        let mut values = [0.0; MAX_PARAMS];
        values[..4].copy_from_slice(&[fx, fy, cx, cy]);
        let rest = model.info().undistorted;
        values[4..4 + rest.len()].copy_from_slice(rest);
        Intrinsics { model, values }
    }

    /// `radial3` intrinsics without distortion.
    pub fn pinhole(fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Intrinsics::pinhole_of(LensModel::Radial3, fx, fy, cx, cy)
    }

    /// Intrinsics from a model and its parameters in solver order; `None` for a
    /// wrong count.
    pub fn from_params(model: LensModel, params: &[f64]) -> Option<Self> {
        if params.len() != model.num_params() {
            return None;
        }
        let mut values = [0.0; MAX_PARAMS];
        values[..params.len()].copy_from_slice(params);
        Some(Intrinsics { model, values })
    }

    /// `radial3` intrinsics from (fx, fy, cx, cy, k1, k2, k3).
    pub fn radial3(p: [f64; 7]) -> Self {
        Intrinsics::from_params(LensModel::Radial3, &p).expect("seven parameters")
    }

    /// The lens model.
    pub fn model(&self) -> LensModel {
        self.model
    }

    /// The parameters in solver order.
    pub fn params(&self) -> &[f64] {
        &self.values[..self.model.num_params()]
    }

    /// The parameters in solver order, mutable.
    pub fn params_mut(&mut self) -> &mut [f64] {
        let n = self.model.num_params();
        &mut self.values[..n]
    }

    /// A parameter by name.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.model.param_index(name).map(|i| self.values[i])
    }

    /// Sets a parameter by name; false if the model has no such parameter.
    pub fn set(&mut self, name: &str, value: f64) -> bool {
        match self.model.param_index(name) {
            Some(i) => {
                self.values[i] = value;
                true
            }
            None => false,
        }
    }

    /// The same intrinsics with a parameter set by name.
    ///
    /// # Panics
    /// If the model has no parameter of that name (a programming error).
    pub fn with_param(mut self, name: &str, value: f64) -> Self {
        assert!(
            self.set(name, value),
            "{} has no parameter `{name}`",
            self.model
        );
        self
    }

    /// (name, value) pairs in solver order.
    pub fn named(&self) -> impl Iterator<Item = (&'static str, f64)> + '_ {
        self.model
            .param_names()
            .iter()
            .copied()
            .zip(self.params().iter().copied())
    }

    /// Focal length along u, pixels.
    pub fn fx(&self) -> f64 {
        self.values[0]
    }
    /// Focal length along v, pixels.
    pub fn fy(&self) -> f64 {
        self.values[1]
    }
    /// Principal point u, pixels.
    pub fn cx(&self) -> f64 {
        self.values[2]
    }
    /// Principal point v, pixels.
    pub fn cy(&self) -> f64 {
        self.values[3]
    }

    /// The 3×3 camera matrix K.
    pub fn camera_matrix(&self) -> Matrix3<f64> {
        Matrix3::new(
            self.fx(),
            0.0,
            self.cx(),
            0.0,
            self.fy(),
            self.cy(),
            0.0,
            0.0,
            1.0,
        )
    }

    /// Projects a camera-frame point to a pixel; `None` where the model has no
    /// image of it (behind a pinhole camera, outside a fisheye's valid domain).
    pub fn project(&self, xc: &Vector3<f64>) -> Option<Vector2<f64>> {
        let p = self.params();
        let m = self.normalised(xc)?;
        Some(Vector2::new(p[0] * m.x + p[2], p[1] * m.y + p[3]))
    }

    /// The normalised image coordinates m of a camera-frame point, whose pixel
    /// is (fx mx + cx, fy my + cy): [`Intrinsics::project`] before its last step.
    /// m does not depend on fx, fy, cx, cy (`Projection`'s contract).
    pub fn normalised(&self, xc: &Vector3<f64>) -> Option<Vector2<f64>> {
        let p = self.params();
        match self.model.info().projection {
            Projection::PinholeLike { distort, .. } => {
                if xc.z <= 0.0 {
                    return None;
                }
                Some(distort(p, xc.x / xc.z, xc.y / xc.z))
            }
            Projection::Central { project, .. } => project(p, xc),
        }
    }

    /// Unprojects a pixel to a unit ray in the camera frame; `None` where the
    /// model maps no valid ray to it (beyond the fold of a distortion polynomial,
    /// outside a fisheye's image circle).
    pub fn unproject(&self, uv: &Vector2<f64>) -> Option<Vector3<f64>> {
        let p = self.params();
        let m = Vector2::new((uv.x - p[2]) / p[0], (uv.y - p[3]) / p[1]);
        let ray = match self.model.info().projection {
            Projection::PinholeLike { derivatives, .. } => {
                let n = pinhole_like::undistort(derivatives, p, &m)?;
                Vector3::new(n.x, n.y, 1.0)
            }
            Projection::Central { unproject, .. } => unproject(p, &m)?,
        };
        let ray = ray.normalize();
        // A ray the forward model rejects, or that does not map back to the pixel
        // (the fold beyond a polynomial's turning point), is no valid ray.
        let back = self.project(&ray)?;
        ((back - uv).norm() <= 1e-6 * (1.0 + p[0].abs())).then_some(ray)
    }
}

impl Serialize for Intrinsics {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = s.serialize_map(Some(self.model.num_params()))?;
        for (name, v) in self.named() {
            map.serialize_entry(name, &v)?;
        }
        map.end()
    }
}

impl<'de> Deserialize<'de> for Intrinsics {
    /// The model is the one whose parameter names are exactly the keys given.
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let map = std::collections::BTreeMap::<String, f64>::deserialize(d)?;
        let model = LensModel::ALL
            .into_iter()
            .find(|m| {
                m.num_params() == map.len() && m.param_names().iter().all(|p| map.contains_key(*p))
            })
            .ok_or_else(|| {
                let keys: Vec<&str> = map.keys().map(String::as_str).collect();
                serde::de::Error::custom(format!(
                    "intrinsics {{{}}} match no lens model ({})",
                    keys.join(", "),
                    LensModel::names()
                ))
            })?;
        let params: Vec<f64> = model.param_names().iter().map(|p| map[*p]).collect();
        Ok(Intrinsics::from_params(model, &params).expect("count checked"))
    }
}
