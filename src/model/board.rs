//! Deformation models: the four calibration methods and the per-image paraboloid (docs/conventions.md §2).
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
    /// A cubic per-image bend (`dynamic` with `bend_order = 3`).
    Dynamic3,
    /// A quartic per-image bend (`dynamic` with `bend_order = 4`).
    Dynamic4,
    /// `full` with a cubic bend (`bend_order = 3`).
    Full3,
    /// `full` with a quartic bend (`bend_order = 4`).
    Full4,
}

impl Method {
    /// All methods in the paper's order.
    pub const ALL: [Method; 4] = [
        Method::Standard,
        Method::Static,
        Method::Dynamic,
        Method::Full,
    ];

    /// Every registered board model: the paper's four, then the richer bends.
    pub const REGISTRY: [Method; 8] = [
        Method::Standard,
        Method::Static,
        Method::Dynamic,
        Method::Full,
        Method::Dynamic3,
        Method::Dynamic4,
        Method::Full3,
        Method::Full4,
    ];

    /// The registry entry: the board model behind the method.
    pub fn info(self) -> BoardModelInfo {
        let (name, frame_params, corner_params, gauge_corners, gauge_dof, tolerance_scale) =
            match self {
                Method::Standard => ("standard", 0, 0, 0, 0, 1.0),
                // 7 DOF: two corners fully, the z of a third (docs/conventions.md §2). Its solves
                // converge linearly (each step about 0.45 of the one before, on
                // 25-image t2 sets), so a relative cost change of 1e-8 comes while
                // the intrinsics still move: one opencv5 set stopped 0.027 px from
                // the optimum converged to 1e-15, and 0.005 px at 1e-10, two
                // iterations later; the parameter tolerance stops the others first.
                Method::Static => ("static", 0, 3, 3, 7, 0.01),
                Method::Dynamic => ("dynamic", PARABOLOID_PARAMS, 0, 0, 0, 1.0),
                // 4 DOF: (Δx, Δy) of two corners.
                Method::Full => ("full", PARABOLOID_PARAMS, 2, 2, 4, 1.0),
                Method::Dynamic3 => ("dynamic3", bend_terms(3), 0, 0, 0, 1.0),
                Method::Dynamic4 => ("dynamic4", bend_terms(4), 0, 0, 0, 1.0),
                Method::Full3 => ("full3", bend_terms(3), 2, 2, 4, 1.0),
                Method::Full4 => ("full4", bend_terms(4), 2, 2, 4, 1.0),
            };
        BoardModelInfo {
            name,
            frame_params,
            corner_params,
            gauge_corners,
            gauge_dof,
            function_tolerance_scale: tolerance_scale,
        }
    }

    /// The name used in configs and outputs.
    pub fn name(self) -> &'static str {
        self.info().name
    }

    /// Parses a method name.
    pub fn parse(s: &str) -> Option<Method> {
        Method::REGISTRY.into_iter().find(|m| m.name() == s)
    }

    /// The order of the per-image polynomial bend (0: none, 2: the paraboloid).
    pub fn bend_order(self) -> usize {
        match self {
            Method::Standard | Method::Static => 0,
            Method::Dynamic | Method::Full => 2,
            Method::Dynamic3 | Method::Full3 => 3,
            Method::Dynamic4 | Method::Full4 => 4,
        }
    }

    /// The same deformation with a bend of `order` (2, 3 or 4); methods without a
    /// bend stay themselves, `None` for an order not registered.
    pub fn with_bend_order(self, order: usize) -> Option<Method> {
        if self.bend_order() == 0 {
            return Some(self);
        }
        let full = self.has_correction();
        Some(match (order, full) {
            (2, false) => Method::Dynamic,
            (3, false) => Method::Dynamic3,
            (4, false) => Method::Dynamic4,
            (2, true) => Method::Full,
            (3, true) => Method::Full3,
            (4, true) => Method::Full4,
            _ => return None,
        })
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

/// Coefficients of a polynomial bend of `order`: monomials xᵐyⁿ, 2 ≤ m + n ≤ order.
pub const fn bend_terms(order: usize) -> usize {
    (order + 1) * (order + 2) / 2 - 3
}

/// Coefficients beyond the paraboloid's of the richest registered bend (order 4).
pub const HIGHER_BEND_PARAMS: usize = bend_terms(4) - PARABOLOID_PARAMS;

/// The degree-3 and degree-4 coefficients of a bend, in `cpp/board.h`'s order
/// (x³, x²y, xy², y³, x⁴, x³y, x²y², xy³, y⁴); zero beyond a method's order.
pub type HigherBend = [f64; HIGHER_BEND_PARAMS];

/// Δz of the degree-3 and -4 terms at board coordinates (x, y).
pub fn higher_dz(h: &HigherBend, x: f64, y: f64) -> f64 {
    let mut z = 0.0;
    let mut k = 0;
    for degree in 3..=4 {
        for m in (0..=degree).rev() {
            z += h[k] * x.powi(m) * y.powi(degree - m);
            k += 1;
        }
    }
    z
}

/// The largest |Δz| over the board's corners of a bend with higher terms.
pub fn max_bend(target: &Target, p: &Paraboloid, h: &HigherBend) -> f64 {
    target
        .nominal_points()
        .iter()
        .map(|q| (p.dz(q.x, q.y) + higher_dz(h, q.x, q.y)).abs())
        .fold(0.0, f64::max)
}

/// What the board-model registry knows of a method's board model; the C++ model
/// of the same name in `cpp/board.h` has the same sizes (checked by a test).
#[derive(Debug, Clone, Copy, PartialEq)]
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
    /// Factor on the function tolerance of this model's solves, for a model
    /// whose solves still move the intrinsics after the cost has settled.
    pub function_tolerance_scale: f64,
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

    /// `max_out_of_plane_m`: the largest |Δz| over the board's corners (docs/conventions.md §3).
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

/// Board point of a corner under a method's deformation: nominal + correction + bend
/// (the higher terms count up to the method's bend order).
pub fn board_point(
    method: Method,
    nominal: &Vector3<f64>,
    correction: &[f64; 3],
    bend: &Paraboloid,
    higher: &HigherBend,
) -> Vector3<f64> {
    let mut p = *nominal;
    let info = method.info();
    for (k, c) in correction.iter().enumerate().take(info.corner_params) {
        p[k] += c;
    }
    if method.bend_order() >= 2 {
        let mut h = [0.0; HIGHER_BEND_PARAMS];
        let n = info.frame_params - PARABOLOID_PARAMS;
        h[..n].copy_from_slice(&higher[..n]);
        p.z += bend.dz(nominal.x, nominal.y) + higher_dz(&h, nominal.x, nominal.y);
    }
    p
}

/// A measured board (`board.json`): its static correction, per corner, and that
/// correction's standard deviation; later calibrations use nominal + correction
/// as the board and the deviation as the prior's spread.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BoardGeometry {
    /// The board the correction belongs to.
    pub target: Target,
    /// Δx, Δy, Δz per corner, metres.
    pub correction: Vec<[f64; 3]>,
    /// 1σ of each value of `correction`, metres (0 where the gauge holds it).
    pub correction_std: Vec<[f64; 3]>,
}

/// Priors on the board model (beyond the paper, docs/conventions.md §2: extra residuals on top of
/// the gauge); every one is off by default, which is the paper's behaviour.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BoardPriors {
    /// 1σ of every static correction value, metres (`static_prior_mm`).
    pub static_sigma_m: Option<f64>,
    /// `static_prior_mm = "auto"`: the static prior's σ is estimated from the
    /// data (empirical Bayes) after a solve without it.
    pub static_sigma_auto: bool,
    /// 1σ of each bend term's Δz at the board's corner, metres (`bend_prior_mm`).
    pub bend_sigma_m: Option<f64>,
    /// `bend_prior_mm = "auto"`: the bend prior's σ is estimated from the data
    /// (empirical Bayes) after a solve without it.
    pub bend_sigma_auto: bool,
    /// 1σ of each bend term's change from one frame to the next, as Δz at the
    /// board's corner, metres (`bend_smoothness`).
    pub smoothness_sigma_m: Option<f64>,
    /// `bend_smoothness = "auto"`: the smoothness prior's σ is estimated from
    /// the frames' own bends (empirical Bayes).
    pub smoothness_auto: bool,
    /// A measured board used as the nominal one (`[target] geometry`).
    pub geometry: Option<std::sync::Arc<BoardGeometry>>,
    /// The pixel noise σ the priors are weighted by; the pipeline estimates it
    /// when `None`.
    pub noise_px: Option<f64>,
    /// Frames bent more than this, metres, are flagged (`max_bend_mm`; no prior).
    pub max_bend_m: Option<f64>,
}

/// Smallest prior σ taken from a measured board's covariance, metres: a value
/// measured to better than this is not trusted beyond it.
pub const MIN_GEOMETRY_STD_M: f64 = 1e-6;

impl BoardPriors {
    /// The project's default: the static and bend priors' σ estimated from the
    /// data (`priors = "auto"`); [`BoardPriors::default`] is the paper's, none.
    pub fn estimated() -> Self {
        BoardPriors {
            static_sigma_auto: true,
            bend_sigma_auto: true,
            ..BoardPriors::default()
        }
    }

    /// Whether any prior is on (and so the noise that weights them is needed).
    pub fn any(&self) -> bool {
        self.static_sigma_m.is_some()
            || self.static_sigma_auto
            || self.bend_sigma_m.is_some()
            || self.bend_sigma_auto
            || self.smoothness_sigma_m.is_some()
            || self.smoothness_auto
            || self.geometry.is_some()
    }

    /// The nominal board points: the grid, plus the measured correction if any.
    pub fn board_points(&self, target: &Target) -> Vec<Vector3<f64>> {
        let mut points = target.nominal_points();
        if let Some(g) = &self.geometry {
            for (p, c) in points.iter_mut().zip(&g.correction) {
                *p += Vector3::from(*c);
            }
        }
        points
    }

    /// Weights σ_noise/σ of the static-correction prior, 3 per corner (empty: off):
    /// `static_sigma_m` if given, else the measured board's σ.
    pub fn correction_weights(&self, corners: usize) -> Vec<f64> {
        let noise = self.noise_px.unwrap_or(0.0);
        if let Some(s) = self.static_sigma_m {
            return vec![noise / s; 3 * corners];
        }
        match &self.geometry {
            Some(g) if g.correction_std.len() == corners => g
                .correction_std
                .iter()
                .flatten()
                .map(|s| noise / s.max(MIN_GEOMETRY_STD_M))
                .collect(),
            _ => Vec::new(),
        }
    }

    /// Weights of a per-frame bend prior of σ metres on each term's Δz at the
    /// board's corner (|x| and |y| largest), for a bend of `terms` coefficients.
    pub fn bend_weights(&self, target: &Target, terms: usize, sigma_m: Option<f64>) -> Vec<f64> {
        let (Some(s), Some(noise)) = (sigma_m, self.noise_px) else {
            return Vec::new();
        };
        bend_reach(target, terms)
            .iter()
            .map(|r| noise * r / s)
            .collect()
    }
}

/// Each of the first `terms` bend terms' monomial at the board's corner (|x| and
/// |y| largest), metres^degree: a coefficient times it is that term's Δz there.
pub fn bend_reach(target: &Target, terms: usize) -> Vec<f64> {
    let x = (target.cols as f64 - 1.0) / 2.0 * target.spacing;
    let y = (target.rows as f64 - 1.0) / 2.0 * target.spacing;
    // The paraboloid's x², y², xy, then degree by degree with falling powers of x.
    let mut reach = vec![x * x, y * y, x * y];
    for degree in 3..=4 {
        for m in (0..=degree).rev() {
            reach.push(x.powi(m) * y.powi(degree - m));
        }
    }
    reach.truncate(terms);
    reach
}
