//! Deformation models: the four calibration methods and the per-image paraboloid (SPEC §2).
use crate::model::target::Target;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::fmt;

/// A calibration method: which board deformation is modelled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, PartialOrd, Ord)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Rigid, planar board.
    Standard,
    /// One 3D correction per corner for the whole dataset.
    Static,
    /// A paraboloid out-of-plane bend per image.
    Dynamic,
    /// Static in-plane correction plus the per-image paraboloid.
    Full,
}

impl Method {
    /// All methods in the paper's order.
    pub const ALL: [Method; 4] = [
        Method::Standard,
        Method::Static,
        Method::Dynamic,
        Method::Full,
    ];

    /// The registry entry: the board model behind the method.
    pub fn info(self) -> BoardModelInfo {
        let (name, frame_params, corner_params, gauge_corners, gauge_dof) = match self {
            Method::Standard => ("standard", 0, 0, 0, 0),
            // 7 DOF: two corners fully, the z of a third (SPEC §2).
            Method::Static => ("static", 0, 3, 3, 7),
            Method::Dynamic => ("dynamic", PARABOLOID_PARAMS, 0, 0, 0),
            // 4 DOF: (Δx, Δy) of two corners.
            Method::Full => ("full", PARABOLOID_PARAMS, 2, 2, 4),
        };
        BoardModelInfo {
            name,
            frame_params,
            corner_params,
            gauge_corners,
            gauge_dof,
        }
    }

    /// The name used in configs and outputs.
    pub fn name(self) -> &'static str {
        self.info().name
    }

    /// Parses a method name.
    pub fn parse(s: &str) -> Option<Method> {
        Method::ALL.into_iter().find(|m| m.name() == s)
    }

    /// Whether the method estimates a per-corner correction.
    pub fn has_correction(self) -> bool {
        self.info().corner_params > 0
    }

    /// Whether the method estimates a per-image paraboloid.
    pub fn has_paraboloid(self) -> bool {
        self.info().frame_params > 0
    }

    /// How many corners carry the gauge of the correction.
    pub fn gauge_corners(self) -> usize {
        self.info().gauge_corners
    }

    /// Components of the per-corner correction that are estimated.
    pub fn correction_dims(self) -> usize {
        self.info().corner_params
    }
}

/// Parameters of the per-frame paraboloid (a, b, c).
pub const PARABOLOID_PARAMS: usize = 3;

/// What the board-model registry knows of a method's board model; the C++ model
/// of the same name in `cpp/board.h` has the same sizes (checked by a test).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoardModelInfo {
    /// The method's name, also the C++ model's `kName`.
    pub name: &'static str,
    /// Parameters per frame beside its pose.
    pub frame_params: usize,
    /// Estimated values of each corner's correction (a prefix of Δx, Δy, Δz).
    pub corner_params: usize,
    /// Corners whose correction is held to fix the gauge.
    pub gauge_corners: usize,
    /// Correction values those corners hold.
    pub gauge_dof: usize,
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Out-of-plane bend Δz = a x² + b y² + c x y of one image.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Paraboloid {
    pub a: f64,
    pub b: f64,
    pub c: f64,
}

impl Paraboloid {
    /// Δz at board coordinates (x, y).
    pub fn dz(&self, x: f64, y: f64) -> f64 {
        self.a * x * x + self.b * y * y + self.c * x * y
    }

    /// `max_out_of_plane_m`: the largest |Δz| over the board's corners (SPEC §3).
    pub fn max_out_of_plane(&self, target: &Target) -> f64 {
        target
            .nominal_points()
            .iter()
            .map(|p| self.dz(p.x, p.y).abs())
            .fold(0.0, f64::max)
    }

    /// The three solver parameters.
    pub fn to_array(&self) -> [f64; 3] {
        [self.a, self.b, self.c]
    }
}

/// Board point of a corner under a method's deformation: nominal + correction + bend.
pub fn board_point(
    method: Method,
    nominal: &Vector3<f64>,
    correction: &[f64; 3],
    bend: &Paraboloid,
) -> Vector3<f64> {
    let mut p = *nominal;
    match method {
        Method::Standard => {}
        Method::Static => p += Vector3::from(*correction),
        Method::Dynamic => p.z += bend.dz(nominal.x, nominal.y),
        Method::Full => {
            p.x += correction[0];
            p.y += correction[1];
            p.z += bend.dz(nominal.x, nominal.y);
        }
    }
    p
}
