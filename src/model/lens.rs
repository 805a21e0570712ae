//! Lens models (docs/conventions.md §1): the registry of every model deformcal knows, and
//! intrinsics of any of them with projection and unprojection in f64.
//!
//! The registry ([`LensModel::ALL`] and [`LensModel::info`]) is the one place a
//! model is described: its config name, its parameter names (which are also the
//! keys of `calibration.json`) and what peers call it. The C++ core has the same
//! models as templated projections in `cpp/camera.h`; a test checks that both
//! projections agree for every model.
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

/// The largest parameter count of any lens model.
pub const MAX_PARAMS: usize = 12;

/// A lens model from the registry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub enum LensModel {
    /// The paper's model: OpenCV's with p1 = p2 = 0.
    #[default]
    Radial3,
    /// OpenCV's default five coefficients (ROS `plumb_bob`).
    OpenCv5,
    /// OpenCV's rational model (ROS `rational_polynomial`, mrcal `LENSMODEL_OPENCV8`).
    OpenCv8,
    /// Kannala-Brandt equidistant fisheye (OpenCV `fisheye`, Kalibr `pinhole-equi`).
    Kb4,
    /// Double sphere (Usenko et al. 2018), beyond 180°.
    DoubleSphere,
}

/// What the registry knows of a lens model.
#[derive(Debug, Clone, Copy)]
pub struct LensInfo {
    /// The config's `model` name, also the C++ model's `kName`.
    pub name: &'static str,
    /// Parameter names in solver order; `calibration.json` keys.
    pub params: &'static [&'static str],
    /// A pinhole image with distortion around it (Zhang's initialisation applies).
    pub pinhole_like: bool,
    /// ROS `distortion_model`, where ROS has the model.
    pub ros: Option<&'static str>,
    /// mrcal's lens model, where mrcal has it.
    pub mrcal: Option<&'static str>,
    /// Parameters the lens prior (`[calibration] lens_prior`) pulls towards zero:
    /// those the data leave nearly free, such as the rational model's denominator,
    /// which trades off against its numerator over the range the corners cover.
    pub prior_params: &'static [&'static str],
    /// A second start for the first solve, for a model whose cost has two basins
    /// that the initialisation cannot tell apart; the calibration keeps the start
    /// that ends at the lower cost (`solver::calibrate`).
    pub second_start: Option<fn(&Intrinsics) -> Intrinsics>,
}

/// `ds`'s second start: ξ = −0.2, α = 0.57 instead of the initialisation's ξ = 0,
/// α = 0.5, with f scaled to keep f/(1 + ξ), the focal length that the central
/// corners fix. Along that valley the solve has a second minimum: on 32 synthetic
/// sets at each of four true lenses, either start alone ended 0.4–0.7 px from the
/// truth on 0–1 sets per method and board, never on the same set (README, "Lens
/// models").
fn ds_second_start(k: &Intrinsics) -> Intrinsics {
    const XI: f64 = -0.2;
    const ALPHA: f64 = 0.57;
    let mut out = *k;
    let p = out.params_mut();
    let scale = (1.0 + XI) / (1.0 + p[4]);
    p[0] *= scale;
    p[1] *= scale;
    p[4] = XI;
    p[5] = ALPHA;
    out
}

impl LensModel {
    /// Every registered model.
    pub const ALL: [LensModel; 5] = [
        LensModel::Radial3,
        LensModel::OpenCv5,
        LensModel::OpenCv8,
        LensModel::Kb4,
        LensModel::DoubleSphere,
    ];

    /// The registry entry.
    pub fn info(self) -> LensInfo {
        match self {
            LensModel::Radial3 => LensInfo {
                name: "radial3",
                params: &["fx", "fy", "cx", "cy", "k1", "k2", "k3"],
                pinhole_like: true,
                ros: None,
                mrcal: None,
                prior_params: &[],
                second_start: None,
            },
            LensModel::OpenCv5 => LensInfo {
                name: "opencv5",
                params: &["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"],
                pinhole_like: true,
                ros: Some("plumb_bob"),
                mrcal: Some("LENSMODEL_OPENCV5"),
                prior_params: &[],
                second_start: None,
            },
            LensModel::OpenCv8 => LensInfo {
                name: "opencv8",
                params: &[
                    "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6",
                ],
                pinhole_like: true,
                ros: Some("rational_polynomial"),
                mrcal: Some("LENSMODEL_OPENCV8"),
                prior_params: &["k4", "k5", "k6"],
                second_start: None,
            },
            LensModel::Kb4 => LensInfo {
                name: "kb4",
                params: &["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"],
                pinhole_like: false,
                ros: Some("equidistant"),
                mrcal: None,
                prior_params: &[],
                second_start: None,
            },
            LensModel::DoubleSphere => LensInfo {
                name: "ds",
                params: &["fx", "fy", "cx", "cy", "xi", "alpha"],
                pinhole_like: false,
                ros: None,
                mrcal: None,
                prior_params: &[],
                second_start: Some(ds_second_start),
            },
        }
    }

    /// The config name.
    pub fn name(self) -> &'static str {
        self.info().name
    }

    /// Parameter names in solver order.
    pub fn param_names(self) -> &'static [&'static str] {
        self.info().params
    }

    /// Number of parameters.
    pub fn num_params(self) -> usize {
        self.info().params.len()
    }

    /// The model of a config name.
    pub fn parse(name: &str) -> Option<LensModel> {
        LensModel::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Every model's name, for messages.
    pub fn names() -> String {
        LensModel::ALL.map(LensModel::name).join(", ")
    }

    /// Index of a parameter name.
    pub fn param_index(self, name: &str) -> Option<usize> {
        self.param_names().iter().position(|p| *p == name)
    }
}

impl fmt::Display for LensModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl Serialize for LensModel {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for LensModel {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        LensModel::parse(&name).ok_or_else(|| {
            serde::de::Error::custom(format!(
                "unknown lens model `{name}`; expected one of {}",
                LensModel::names()
            ))
        })
    }
}

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
    /// no distortion: zero coefficients, or for `ds` a stereographic lens (ξ = 0,
    /// α = ½), which has the focal length `fx` at the image centre.
    pub fn pinhole_of(model: LensModel, fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        let mut values = [0.0; MAX_PARAMS];
        values[..4].copy_from_slice(&[fx, fy, cx, cy]);
        if model == LensModel::DoubleSphere {
            values[5] = 0.5;
        }
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
        let p = &self.values;
        let m = match self.model {
            LensModel::Radial3 | LensModel::OpenCv5 | LensModel::OpenCv8 => {
                if xc.z <= 0.0 {
                    return None;
                }
                self.distort(xc.x / xc.z, xc.y / xc.z)
            }
            LensModel::Kb4 => {
                let r2 = xc.x * xc.x + xc.y * xc.y;
                if r2 < 1e-30 * xc.z * xc.z {
                    if xc.z <= 0.0 {
                        return None;
                    }
                    Vector2::new(xc.x / xc.z, xc.y / xc.z)
                } else {
                    let r = r2.sqrt();
                    let theta = r.atan2(xc.z);
                    let s = kb4_theta_d(p, theta) / r;
                    Vector2::new(xc.x * s, xc.y * s)
                }
            }
            LensModel::DoubleSphere => {
                let (xi, alpha) = (p[4], p[5]);
                let d1 = xc.norm();
                let zz = xi * d1 + xc.z;
                let d2 = (xc.x * xc.x + xc.y * xc.y + zz * zz).sqrt();
                // The model's domain (Usenko et al., eq. 43).
                let w1 = if alpha <= 0.5 {
                    alpha / (1.0 - alpha)
                } else {
                    (1.0 - alpha) / alpha
                };
                let w2 = (w1 + xi) / (2.0 * w1 * xi + xi * xi + 1.0).sqrt();
                if xc.z <= -w2 * d1 {
                    return None;
                }
                let m = alpha * d2 + (1.0 - alpha) * zz;
                Vector2::new(xc.x / m, xc.y / m)
            }
        };
        Some(Vector2::new(p[0] * m.x + p[2], p[1] * m.y + p[3]))
    }

    /// The pinhole-like models' distortion of normalised coordinates (x', y').
    fn distort(&self, x: f64, y: f64) -> Vector2<f64> {
        let p = &self.values;
        let r2 = x * x + y * y;
        let radial = |k1: f64, k2: f64, k3: f64| 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        match self.model {
            LensModel::Radial3 => {
                let d = radial(p[4], p[5], p[6]);
                Vector2::new(x * d, y * d)
            }
            LensModel::OpenCv5 | LensModel::OpenCv8 => {
                let d = if self.model == LensModel::OpenCv5 {
                    radial(p[4], p[5], p[8])
                } else {
                    radial(p[4], p[5], p[8]) / radial(p[9], p[10], p[11])
                };
                let (p1, p2) = (p[6], p[7]);
                let xy = x * y;
                Vector2::new(
                    x * d + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x),
                    y * d + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy,
                )
            }
            LensModel::Kb4 | LensModel::DoubleSphere => unreachable!("not pinhole-like"),
        }
    }

    /// Unprojects a pixel to a unit ray in the camera frame; `None` where the
    /// model maps no valid ray to it (beyond the fold of a distortion polynomial,
    /// outside a fisheye's image circle).
    pub fn unproject(&self, uv: &Vector2<f64>) -> Option<Vector3<f64>> {
        let p = &self.values;
        let m = Vector2::new((uv.x - p[2]) / p[0], (uv.y - p[3]) / p[1]);
        let ray = match self.model {
            LensModel::Radial3 | LensModel::OpenCv5 | LensModel::OpenCv8 => {
                let n = self.undistort(&m)?;
                Vector3::new(n.x, n.y, 1.0)
            }
            LensModel::Kb4 => {
                let theta_d = m.norm();
                if theta_d < 1e-15 {
                    Vector3::new(m.x, m.y, 1.0)
                } else {
                    let theta = kb4_theta(p, theta_d)?;
                    let s = theta.sin() / theta_d;
                    Vector3::new(m.x * s, m.y * s, theta.cos())
                }
            }
            LensModel::DoubleSphere => {
                let (xi, alpha) = (p[4], p[5]);
                let r2 = m.norm_squared();
                let root = 1.0 - (2.0 * alpha - 1.0) * r2;
                if root < 0.0 {
                    return None;
                }
                let mz = (1.0 - alpha * alpha * r2) / (alpha * root.sqrt() + 1.0 - alpha);
                let disc = mz * mz + (1.0 - xi * xi) * r2;
                if disc < 0.0 {
                    return None;
                }
                let s = (mz * xi + disc.sqrt()) / (mz * mz + r2);
                Vector3::new(s * m.x, s * m.y, s * mz - xi)
            }
        };
        let ray = ray.normalize();
        // A ray the forward model rejects, or that does not map back to the pixel
        // (the fold beyond a polynomial's turning point), is no valid ray.
        let back = self.project(&ray)?;
        ((back - uv).norm() <= 1e-6 * (1.0 + p[0].abs())).then_some(ray)
    }

    /// Normalised coordinates whose distortion is `m`, by Newton's method with the
    /// distortion's Jacobian; `None` where it does not converge or the map folds.
    fn undistort(&self, m: &Vector2<f64>) -> Option<Vector2<f64>> {
        let mut x = *m;
        for _ in 0..100 {
            let j = self.distortion_jacobian(&x);
            if j.determinant() <= 0.0 {
                return None;
            }
            let step = j.lu().solve(&(self.distort(x.x, x.y) - m))?;
            x -= step;
            if !x.x.is_finite() || !x.y.is_finite() {
                return None;
            }
            if step.norm() < 1e-16 * (1.0 + x.norm()) {
                break;
            }
        }
        ((self.distort(x.x, x.y) - m).norm() < 1e-12
            && self.distortion_jacobian(&x).determinant() > 0.0)
            .then_some(x)
    }

    /// ∂distort/∂(x', y') by central differences: exact enough for Newton's
    /// direction, whose fixed point does not depend on it.
    fn distortion_jacobian(&self, x: &Vector2<f64>) -> Matrix2<f64> {
        let h = 1e-7 * (1.0 + x.norm());
        let dx = (self.distort(x.x + h, x.y) - self.distort(x.x - h, x.y)) / (2.0 * h);
        let dy = (self.distort(x.x, x.y + h) - self.distort(x.x, x.y - h)) / (2.0 * h);
        Matrix2::new(dx.x, dy.x, dx.y, dy.y)
    }
}

/// θd = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸) of `kb4`.
fn kb4_theta_d(p: &[f64; MAX_PARAMS], theta: f64) -> f64 {
    let t2 = theta * theta;
    theta * (1.0 + t2 * (p[4] + t2 * (p[5] + t2 * (p[6] + t2 * p[7]))))
}

/// The angle θ ∈ [0, π) with θd(θ) = `theta_d` on the increasing branch.
fn kb4_theta(p: &[f64; MAX_PARAMS], theta_d: f64) -> Option<f64> {
    let slope = |t: f64| {
        let t2 = t * t;
        1.0 + t2 * (3.0 * p[4] + t2 * (5.0 * p[5] + t2 * (7.0 * p[6] + t2 * 9.0 * p[7])))
    };
    let mut theta = theta_d.min(3.0);
    for _ in 0..100 {
        let g = slope(theta);
        if g <= 0.0 {
            return None;
        }
        let step = (kb4_theta_d(p, theta) - theta_d) / g;
        theta -= step;
        if !(0.0..std::f64::consts::PI).contains(&theta) {
            return None;
        }
        if step.abs() < 1e-16 * (1.0 + theta) {
            break;
        }
    }
    ((kb4_theta_d(p, theta) - theta_d).abs() < 1e-12 && slope(theta) > 0.0).then_some(theta)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera of every model, with distortion typical of its kind.
    pub(crate) fn examples() -> Vec<Intrinsics> {
        LensModel::ALL
            .into_iter()
            .map(|m| {
                let p: Vec<f64> = match m {
                    LensModel::Radial3 => vec![1000.0, 1010.0, 640.0, 360.0, -0.2, 0.1, -0.02],
                    LensModel::OpenCv5 => {
                        vec![1000.0, 1010.0, 640.0, 360.0, -0.2, 0.1, 1e-3, -2e-3, -0.02]
                    }
                    LensModel::OpenCv8 => vec![
                        1000.0, 1010.0, 640.0, 360.0, 0.3, -0.1, 1e-3, -2e-3, 0.01, 0.5, -0.05,
                        0.02,
                    ],
                    LensModel::Kb4 => vec![400.0, 401.0, 640.0, 480.0, 0.02, -0.01, 0.003, -5e-4],
                    LensModel::DoubleSphere => vec![350.0, 351.0, 640.0, 480.0, -0.2, 0.6],
                };
                Intrinsics::from_params(m, &p).unwrap()
            })
            .collect()
    }

    #[test]
    fn unproject_inverts_project_for_every_model() {
        for k in examples() {
            for &(x, y, z) in &[
                (0.0, 0.0, 1.0),
                (0.3, -0.2, 1.0),
                (-0.5, 0.4, 1.0),
                (0.01, 0.6, 1.0),
            ] {
                let ray = Vector3::new(x, y, z).normalize();
                let uv = k.project(&ray).unwrap();
                let back = k.unproject(&uv).unwrap();
                assert!((back - ray).norm() < 1e-12, "{k:?}: {back} vs {ray}");
            }
        }
    }

    #[test]
    fn json_round_trip_keeps_the_model() {
        for k in examples() {
            let text = serde_json::to_string(&k).unwrap();
            let back: Intrinsics = serde_json::from_str(&text).unwrap();
            assert_eq!(back, k);
        }
        let err = serde_json::from_str::<Intrinsics>(r#"{"fx":1,"fy":1,"cx":0,"cy":0,"k9":0}"#)
            .unwrap_err();
        assert!(err.to_string().contains("match no lens model"), "{err}");
    }
}
