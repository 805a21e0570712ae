//! `[calibration]`: the method and the solver settings as the config gives them,
//! their defaults (the solver's own), and what they become for the solver
//! ([`SolverSettings`], [`AutoSettings`]).
use super::protocol::ProtocolConfig;
use crate::app::text::short;
use crate::model::board::{BoardGeometry, BoardPriors, Method};
use crate::model::selection::{AutoSettings, MethodChoice};
use crate::solver::problem::{Loss, SolverSettings};
use serde::Deserialize;

/// `[calibration]`: the method and the solver settings.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrationConfig {
    /// A method, or `auto` (chosen by cross-validation among `auto_candidates`).
    pub method: MethodChoice,
    /// The methods `auto` tries (`standard` must be among them).
    pub auto_candidates: Vec<Method>,
    /// k of `auto`'s k-fold cross-validation over frames.
    pub cv_folds: usize,
    /// Seed of `auto`'s shuffle of the frames into folds.
    pub cv_seed: u64,
    pub loss: Loss,
    pub loss_scale_px: f64,
    /// Ceres threads for one solve.
    pub threads: usize,
    pub max_iterations: u32,
    pub function_tolerance: f64,
    pub gradient_tolerance: f64,
    pub parameter_tolerance: f64,
    /// Corners whose correction fixes the gauge; default: those of docs/conventions.md §2.
    pub gauge_corners: Option<Vec<usize>>,
    /// Print Ceres' per-iteration log and full report (timings) to stderr.
    pub verbose: bool,
    /// Outlier rejection: observations beyond `outlier_k`·σ are dropped and the
    /// solve repeated until none is; 0 disables it.
    pub outlier_k: f64,
    /// The detector's noise per image coordinate, pixels, for the bias ratio and
    /// G-AIC; without it the noise is estimated from the residuals.
    pub detector_noise_px: Option<f64>,
    /// The largest RMSE a result may have, pixels; replaces the default guard
    /// rails on the RMSE (`app::guard`).
    pub max_rmse_px: Option<f64>,
    /// Whether the board priors that are not set explicitly are on: `"auto"` (the
    /// default: `static_prior_mm` and `bend_prior_mm` estimated from the data) or
    /// `"none"` (the paper's prior-free model).
    pub priors: Priors,
    /// 1σ of the board's print / flatness error, mm: a Gaussian prior on every
    /// static correction value, "auto" (estimated from the data) or "none";
    /// unset, `priors` decides. Read it through [`CalibrationConfig::static_prior`].
    #[serde(deserialize_with = "static_prior_mm")]
    pub static_prior_mm: Option<PriorSigma>,
    /// Order of the per-image polynomial bend of `dynamic` / `full` (2: the
    /// paper's paraboloid), or `auto` (chosen by cross-validation).
    pub bend_order: BendOrder,
    /// 1σ of each bend term's out-of-plane reach at the board's corner, mm: a
    /// zero-mean prior on the bend amplitudes, "auto" or "none"; unset, `priors`
    /// decides. Read it through [`CalibrationConfig::bend_prior`].
    #[serde(deserialize_with = "bend_prior_mm")]
    pub bend_prior_mm: Option<PriorSigma>,
    /// 1σ of each bend term's change between consecutive frames, mm at the
    /// board's corner: temporal smoothness for video (off by default), or "auto".
    #[serde(deserialize_with = "bend_smoothness")]
    pub bend_smoothness: Option<PriorSigma>,
    /// Frames bent more than this (mm, largest |Δz| over the corners) are flagged.
    pub max_bend_mm: f64,
    /// 1σ of the zero-mean prior on the lens parameters the data leave nearly
    /// free (`opencv8`'s k4–k6), or "none" (OpenCV's and mrcal's exact problem).
    pub lens_prior: LensPrior,
    /// The measured board of `[target] geometry` (not a key of this section).
    #[serde(skip)]
    pub geometry: Option<std::sync::Arc<BoardGeometry>>,
}

/// `[calibration] bend_order`: 2, 3, 4 or "auto".
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(try_from = "NumberOrName<i64>")]
pub enum BendOrder {
    /// A polynomial bend of this order.
    Fixed(usize),
    /// Orders 2 to 4 cross-validated against each other and `standard`.
    Auto,
}

/// A config value that is a number or a name (`bend_order`, `lens_prior`).
#[derive(Deserialize)]
#[serde(untagged)]
enum NumberOrName<N> {
    Number(N),
    Name(String),
}

impl TryFrom<NumberOrName<i64>> for BendOrder {
    type Error = String;
    fn try_from(r: NumberOrName<i64>) -> std::result::Result<Self, String> {
        match r {
            NumberOrName::Number(n @ 2..=4) => Ok(BendOrder::Fixed(n as usize)),
            NumberOrName::Name(s) if s == "auto" => Ok(BendOrder::Auto),
            NumberOrName::Number(n) => {
                Err(format!("bend_order must be 2, 3, 4 or \"auto\" (got {n})"))
            }
            NumberOrName::Name(s) => Err(format!(
                "bend_order must be 2, 3, 4 or \"auto\" (got \"{}\")",
                short(&s)
            )),
        }
    }
}

/// `[calibration] static_prior_mm`, `bend_prior_mm` and `bend_smoothness`: a prior's σ in
/// millimetres, "auto" (estimated from the data, `solver::auto_prior`) or "none".
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PriorSigma {
    /// This σ, millimetres.
    Mm(f64),
    /// Empirical Bayes.
    Auto,
    /// No prior.
    Off,
}

/// `[calibration] priors`: the board priors a config does not set itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Priors {
    /// The static and bend priors estimated from the data: on rigid and bending
    /// boards alike within a few per cent of the best method's error, where
    /// without them `full` was up to 2–5× worse than `standard` on a rigid board
    /// (docs/benchmarks.md, "Default priors").
    #[default]
    Auto,
    /// The paper's model: no prior on the board.
    None,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum RawPriorSigma {
    Number(f64),
    Name(String),
    Other(toml::Value),
}

impl PriorSigma {
    /// The fixed σ, millimetres (`None` for "auto" and "none").
    pub fn mm(self) -> Option<f64> {
        match self {
            PriorSigma::Mm(v) => Some(v),
            PriorSigma::Auto | PriorSigma::Off => None,
        }
    }

    /// The prior as it acts: `None` when off.
    fn on(self) -> Option<PriorSigma> {
        (self != PriorSigma::Off).then_some(self)
    }

    /// Reads the value of `key`; the error names the key (serde's does not).
    fn read<'de, D: serde::Deserializer<'de>>(
        d: D,
        key: &str,
    ) -> std::result::Result<Option<Self>, D::Error> {
        match RawPriorSigma::deserialize(d)? {
            RawPriorSigma::Number(v) => Ok(Some(PriorSigma::Mm(v))),
            RawPriorSigma::Name(s) if s == "auto" => Ok(Some(PriorSigma::Auto)),
            RawPriorSigma::Name(s) if s == "none" => Ok(Some(PriorSigma::Off)),
            RawPriorSigma::Name(s) => Err(serde::de::Error::custom(format!(
                "{key} must be a number of millimetres, \"auto\" or \"none\" (got \"{}\")",
                short(&s)
            ))),
            RawPriorSigma::Other(v) => Err(serde::de::Error::custom(format!(
                "{key} must be a number of millimetres, \"auto\" or \"none\" (got {})",
                short(&v.to_string())
            ))),
        }
    }
}

fn static_prior_mm<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<Option<PriorSigma>, D::Error> {
    PriorSigma::read(d, "static_prior_mm")
}

fn bend_prior_mm<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<Option<PriorSigma>, D::Error> {
    PriorSigma::read(d, "bend_prior_mm")
}

fn bend_smoothness<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<Option<PriorSigma>, D::Error> {
    PriorSigma::read(d, "bend_smoothness")
}

/// Default of `max_bend_mm`.
pub const DEFAULT_MAX_BEND_MM: f64 = 5.0;

/// `[calibration] lens_prior`: a σ, or "none".
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(try_from = "NumberOrName<f64>")]
pub struct LensPrior(pub Option<f64>);

impl TryFrom<NumberOrName<f64>> for LensPrior {
    type Error = String;
    fn try_from(r: NumberOrName<f64>) -> std::result::Result<Self, String> {
        match r {
            NumberOrName::Number(v) if v.is_finite() && v > 0.0 => Ok(LensPrior(Some(v))),
            NumberOrName::Name(s) if s == "none" => Ok(LensPrior(None)),
            NumberOrName::Number(v) => Err(format!(
                "lens_prior must be a positive number or \"none\" (got {v})"
            )),
            NumberOrName::Name(s) => Err(format!(
                "lens_prior must be a positive number or \"none\" (got \"{}\")",
                short(&s)
            )),
        }
    }
}

impl Default for CalibrationConfig {
    fn default() -> Self {
        // One set of solver defaults: the solver's own.
        let s = SolverSettings::default();
        let auto = AutoSettings::default();
        CalibrationConfig {
            method: MethodChoice::Auto,
            auto_candidates: auto.candidates,
            cv_folds: auto.folds,
            cv_seed: auto.seed,
            loss: s.loss,
            loss_scale_px: s.loss_scale_px,
            threads: s.threads,
            max_iterations: s.max_iterations,
            function_tolerance: s.function_tolerance,
            gradient_tolerance: s.gradient_tolerance,
            parameter_tolerance: s.parameter_tolerance,
            gauge_corners: None,
            verbose: s.verbose,
            outlier_k: s.outlier_k,
            detector_noise_px: None,
            max_rmse_px: None,
            priors: Priors::Auto,
            static_prior_mm: None,
            bend_order: BendOrder::Fixed(2),
            bend_prior_mm: None,
            bend_smoothness: None,
            max_bend_mm: DEFAULT_MAX_BEND_MM,
            lens_prior: LensPrior(s.lens_prior_sigma),
            geometry: None,
        }
    }
}

impl CalibrationConfig {
    /// The static prior as it acts: the key's value, else what `priors` says.
    pub fn static_prior(&self) -> Option<PriorSigma> {
        self.resolved(self.static_prior_mm)
    }

    /// The bend prior as it acts: the key's value, else what `priors` says.
    pub fn bend_prior(&self) -> Option<PriorSigma> {
        self.resolved(self.bend_prior_mm)
    }

    fn resolved(&self, given: Option<PriorSigma>) -> Option<PriorSigma> {
        match (given, self.priors) {
            (Some(p), _) => p.on(),
            (None, Priors::Auto) => Some(PriorSigma::Auto),
            (None, Priors::None) => None,
        }
    }
}

impl From<&CalibrationConfig> for AutoSettings {
    fn from(c: &CalibrationConfig) -> Self {
        AutoSettings {
            candidates: c.auto_candidates.clone(),
            folds: c.cv_folds,
            seed: c.cv_seed,
            detector_noise_px: c.detector_noise_px,
        }
    }
}

impl From<&CalibrationConfig> for SolverSettings {
    fn from(c: &CalibrationConfig) -> Self {
        SolverSettings {
            loss: c.loss,
            loss_scale_px: c.loss_scale_px,
            threads: c.threads,
            max_iterations: c.max_iterations,
            function_tolerance: c.function_tolerance,
            gradient_tolerance: c.gradient_tolerance,
            parameter_tolerance: c.parameter_tolerance,
            fix_gauge: true,
            verbose: c.verbose,
            reference_jacobian: false,
            per_corner_blocks: false,
            compress_view_rows: true,
            warm_up: SolverSettings::default().warm_up,
            outlier_k: c.outlier_k,
            board: BoardPriors {
                static_sigma_m: c.static_prior().and_then(PriorSigma::mm).map(|v| v * 1e-3),
                static_sigma_auto: c.static_prior() == Some(PriorSigma::Auto),
                bend_sigma_m: c.bend_prior().and_then(PriorSigma::mm).map(|v| v * 1e-3),
                bend_sigma_auto: c.bend_prior() == Some(PriorSigma::Auto),
                smoothness_sigma_m: c.bend_smoothness.and_then(PriorSigma::mm).map(|v| v * 1e-3),
                smoothness_auto: c.bend_smoothness == Some(PriorSigma::Auto),
                geometry: c.geometry.clone(),
                noise_px: c.detector_noise_px,
                max_bend_m: Some(c.max_bend_mm * 1e-3),
            },
            lens_prior_sigma: c.lens_prior.0,
        }
    }
}

/// Applies `bend_order` to the methods with a bend: a fixed order replaces
/// `dynamic` / `full` by the registry's model of that order (in `[protocol]` too);
/// `auto` turns a fixed `dynamic` / `full` into `method = "auto"` over `standard`
/// and that method's orders 2, 3 and 4.
pub(super) fn apply_bend_order(c: &mut CalibrationConfig, protocol: Option<&mut ProtocolConfig>) {
    let order = match c.bend_order {
        // The default: every method as named (`dynamic4` stays itself).
        BendOrder::Fixed(2) => return,
        BendOrder::Fixed(n) => n,
        BendOrder::Auto => {
            if let MethodChoice::Fixed(m) = c.method {
                if m.bend_order() > 0 {
                    c.method = MethodChoice::Auto;
                    c.auto_candidates = std::iter::once(Method::Standard)
                        .chain((2..=4).filter_map(|o| m.with_bend_order(o)))
                        .collect();
                }
            }
            return;
        }
    };
    let apply = |m: Method| m.with_bend_order(order).unwrap_or(m);
    if let MethodChoice::Fixed(m) = c.method {
        c.method = MethodChoice::Fixed(apply(m));
    }
    if let Some(p) = protocol {
        for m in &mut p.methods {
            *m = apply(*m);
        }
    }
}
