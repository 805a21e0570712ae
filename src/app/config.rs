//! The TOML config (docs/conventions.md §5): typed, unknown keys rejected, values checked by key.
pub use crate::app::text::{number, short};
use crate::error::{Error, Result};
use crate::model::board::{BoardGeometry, BoardPriors, Method};
use crate::model::camera::CameraSpec;
use crate::model::selection::{AutoSettings, MethodChoice};
use crate::model::synthetic::{Preset, MAX_IMAGES};
use crate::model::target::Target;
use crate::solver::calibrate::MIN_IMAGES;
use crate::solver::problem::{Loss, SolverSettings};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

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

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawData {
    observations: Option<PathBuf>,
    corners_vnl: Option<PathBuf>,
    #[serde(default)]
    camera_patterns: BTreeMap<String, String>,
    synthetic: Option<String>,
    images: Option<usize>,
    seed: Option<u64>,
    cameras: Option<usize>,
    photos: Option<PhotoPatterns>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawReference {
    observations: Option<PathBuf>,
    synthetic: Option<String>,
    images: Option<usize>,
    seed: Option<u64>,
    cameras: Option<usize>,
    rows: Option<usize>,
    cols: Option<usize>,
    spacing: Option<f64>,
}

/// `[protocol]`: the evaluation protocol (docs/conventions.md §4).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(try_from = "RawProtocol")]
pub struct ProtocolConfig {
    pub subsets: usize,
    pub images_per_subset: usize,
    pub seed: u64,
    /// The fixed methods, each calibrated on every subset.
    pub methods: Vec<Method>,
    /// `"auto"` among the config's methods: every subset also records the method
    /// `auto` picks (with `[calibration]`'s candidates, folds and seed).
    pub auto: bool,
}

impl Default for ProtocolConfig {
    fn default() -> Self {
        ProtocolConfig {
            subsets: 50,
            images_per_subset: 25,
            seed: 7,
            methods: Method::ALL.to_vec(),
            auto: false,
        }
    }
}

/// `[protocol]` as written: `methods` may name `auto` beside the fixed methods.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProtocol {
    subsets: Option<usize>,
    images_per_subset: Option<usize>,
    seed: Option<u64>,
    methods: Option<Vec<MethodChoice>>,
}

impl TryFrom<RawProtocol> for ProtocolConfig {
    type Error = String;

    fn try_from(r: RawProtocol) -> std::result::Result<Self, String> {
        let d = ProtocolConfig::default();
        let (methods, auto) = match r.methods {
            None => (d.methods, false),
            Some(choices) => {
                let autos = choices.iter().filter(|c| **c == MethodChoice::Auto).count();
                if autos > 1 {
                    return Err("protocol.methods lists `auto` twice".into());
                }
                let fixed = choices
                    .iter()
                    .filter_map(|c| match c {
                        MethodChoice::Fixed(m) => Some(*m),
                        MethodChoice::Auto => None,
                    })
                    .collect();
                (fixed, autos == 1)
            }
        };
        Ok(ProtocolConfig {
            subsets: r.subsets.unwrap_or(d.subsets),
            images_per_subset: r.images_per_subset.unwrap_or(d.images_per_subset),
            seed: r.seed.unwrap_or(d.seed),
            methods,
            auto,
        })
    }
}

// `[target]`: the board, and optionally a measured board (`board.json`).
use crate::app::target_config::TargetSection as RawTarget;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOutput {
    dir: PathBuf,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    target: Option<RawTarget>,
    #[serde(default)]
    cameras: Vec<CameraSpec>,
    data: RawData,
    reference: Option<RawReference>,
    #[serde(default)]
    calibration: CalibrationConfig,
    protocol: Option<ProtocolConfig>,
    sfm: Option<crate::app::sfm::SfmConfig>,
    output: Option<RawOutput>,
}

/// `[data] photos`: one glob for one camera, or one glob per camera name.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum PhotoPatterns {
    /// One camera: one frame per matching file, in sorted name order.
    One(String),
    /// Several cameras: what the wildcards matched is the time step.
    PerCamera(BTreeMap<String, String>),
}

/// Where observations come from.
#[derive(Debug, Clone, PartialEq)]
pub enum DataSource {
    /// Image files in which the board is detected (docs/conventions.md §5 Photos).
    Photos {
        /// The config's folder, which the patterns are relative to.
        base: PathBuf,
        patterns: PhotoPatterns,
    },
    /// An observations CSV (path resolved against the config's folder).
    Observations(PathBuf),
    /// mrgingham's / mrcal's corners table, with file-name patterns per camera.
    CornersVnl {
        path: PathBuf,
        patterns: BTreeMap<String, String>,
    },
    /// A built-in synthetic preset.
    Synthetic {
        preset: Preset,
        images: Option<usize>,
        seed: u64,
        /// Number of cameras on the simulated rig.
        cameras: usize,
    },
}

/// `[reference]`: the static reference set and its board.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceConfig {
    pub source: DataSource,
    pub target: Target,
}

/// A checked config with paths resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    pub path: PathBuf,
    pub target: Target,
    /// `[target] type = "charuco"`: the ChArUco board the photos show.
    pub charuco: Option<crate::app::detect::charuco::CharucoSpec>,
    pub cameras: Vec<CameraSpec>,
    pub data: DataSource,
    pub reference: Option<ReferenceConfig>,
    pub calibration: CalibrationConfig,
    pub protocol: Option<ProtocolConfig>,
    /// `[sfm]`: the structure-from-motion loop-closure experiment (`app::sfm`).
    pub sfm: Option<crate::app::sfm::SfmConfig>,
    pub output_dir: PathBuf,
}

/// Applies `bend_order` to the methods with a bend: a fixed order replaces
/// `dynamic` / `full` by the registry's model of that order (in `[protocol]` too);
/// `auto` turns a fixed `dynamic` / `full` into `method = "auto"` over `standard`
/// and that method's orders 2, 3 and 4.
fn apply_bend_order(c: &mut CalibrationConfig, protocol: Option<&mut ProtocolConfig>) {
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

/// Seed of synthetic data when the config gives none.
pub const DEFAULT_SYNTHETIC_SEED: u64 = 1;

impl Config {
    /// Reads and checks a config file.
    pub fn load(path: &Path) -> Result<Config> {
        let text = crate::app::fsio::read_limited(path, crate::app::fsio::MAX_CONFIG_BYTES)?;
        let text = String::from_utf8(text).map_err(|_| Error::Config {
            path: path.into(),
            message: "not a UTF-8 text file".into(),
        })?;
        Config::parse(&text, path)
    }

    /// Parses config text; `path` names the file in messages and anchors relative paths.
    pub fn parse(text: &str, path: &Path) -> Result<Config> {
        let raw: RawConfig = toml::from_str(text).map_err(|e| Error::Config {
            path: path.into(),
            message: crate::app::config_keys::explain(text, e.message(), e.span()),
        })?;
        let base = path.parent().unwrap_or(Path::new("")).to_path_buf();
        Checker { path, base, text }.check(raw)
    }
}

struct Checker<'a> {
    path: &'a Path,
    base: PathBuf,
    text: &'a str,
}

/// The line of `key` in table `table` (the `index`-th of an array of tables), or of
/// the table's header when `key` is empty.
fn key_line(text: &str, table: &str, index: usize, key: &str) -> Option<usize> {
    let mut current: Option<(String, usize)> = None;
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    for (n, line) in text.lines().enumerate() {
        let t = line.trim();
        if let Some((h, _)) = crate::app::config_keys::header(t) {
            let count = seen.entry(h.clone()).or_insert(0);
            current = Some((h.clone(), *count));
            *count += 1;
            if key.is_empty() && h == table && current.as_ref().map(|c| c.1) == Some(index) {
                return Some(n + 1);
            }
            continue;
        }
        if let Some((h, i)) = &current {
            if h == table && *i == index && !key.is_empty() {
                if let Some(rest) = t.strip_prefix(key) {
                    if rest.trim_start().starts_with('=') {
                        return Some(n + 1);
                    }
                }
            }
        }
    }
    None
}

/// Splits a message that starts with `table.key`, `table[i].key` or `[table]`.
fn message_key(message: &str) -> Option<(String, usize, String)> {
    if let Some(rest) = message.strip_prefix('[') {
        let table = rest.split(']').next()?.trim_start_matches('[');
        return Some((table.to_string(), 0, String::new()));
    }
    let head: String = message
        .chars()
        .take_while(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '[' | ']'))
        .collect();
    let (table, key) = head.split_once('.')?;
    let key: String = key
        .chars()
        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
        .collect();
    let (table, index) = match table.split_once('[') {
        Some((t, i)) => (t, i.trim_end_matches(']').parse().ok()?),
        None => (table, 0),
    };
    Some((table.to_string(), index, key))
}

/// Most subsets a protocol run (or a merged shard header) may have: each subset ×
/// method is a calibration and a row in memory.
pub const MAX_SUBSETS: usize = 100_000;
/// Largest board accepted, in corners (a 1000 × 1000 board).
pub const MAX_CORNERS: usize = 1_000_000;
/// Most cameras a config may list.
pub const MAX_CAMERAS: usize = 64;
/// Longest camera name, in bytes (names are ASCII, see [`camera_name_error`]).
pub const MAX_NAME_BYTES: usize = 64;
/// The range of `loss_scale_px`: beyond it the Cauchy cost underflows or the
/// loss does nothing, and the solver stops at its start.
pub const LOSS_SCALE_RANGE: (f64, f64) = (1e-3, 1e4);
/// The range of a non-zero `outlier_k`: below 2 good data is rejected wholesale.
pub const OUTLIER_K_RANGE: (f64, f64) = (2.0, 100.0);
/// Most folds `auto` cross-validates with (each fold is a full calibration per candidate).
pub const MAX_CV_FOLDS: usize = 20;
/// Largest solver tolerance (function, gradient, parameter): a relative change
/// of more than a tenth is no convergence, and at 1 Ceres stops before its first
/// step, which then looks like a flat cost.
pub const MAX_TOLERANCE: f64 = 0.1;
/// Largest image side, pixels (a 100-megapixel sensor is about 12 000 wide).
pub const MAX_IMAGE_SIDE_PX: u32 = 100_000;
/// The range of `detector_noise_px`: a corner detector is neither exact to a
/// ten-thousandth of a pixel nor off by a hundred.
pub const NOISE_RANGE_PX: (f64, f64) = (1e-4, 100.0);
/// The range of the board priors' σ and of `max_bend_mm`, millimetres: from a
/// tenth of a micrometre (the priors' weight noise/σ grows beyond what the solve
/// can balance) to 10 m (no constraint at all).
pub const BOARD_MM_RANGE: (f64, f64) = (1e-4, 1e4);
/// The range of `lens_prior`'s σ (a distortion coefficient's): below it the
/// prior holds the coefficients at zero as `fix` would, with a badly scaled
/// weight; above it the prior does nothing.
pub const LENS_PRIOR_RANGE: (f64, f64) = (1e-6, 1e3);

/// Why `name` is not a camera name, if it is not: ASCII letters, digits, `_`, `-`,
/// `.` and space, starting with a letter or digit (docs/conventions.md, Camera
/// names). Names become file names, YAML keys and comment lines in the exports,
/// where a `/`, a newline or a `#` would change what another tool reads.
pub fn camera_name_error(name: &str) -> Option<String> {
    if let Some(bad) = name
        .chars()
        .find(|&c| !(c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | ' ')))
    {
        return Some(format!(
            "contains {}; a camera name may have letters, digits, `_`, `-`, `.` and spaces",
            bad.escape_default()
        ));
    }
    if !name.starts_with(|c: char| c.is_ascii_alphanumeric()) {
        return Some("must start with a letter or a digit".into());
    }
    None
}

impl Checker<'_> {
    /// Names: present, short, of the safe characters, distinct, and distinct in
    /// every export too (`a b` and `a_b` would both be opencv.yaml's `a_b_`).
    fn check_camera_names(&self, cameras: &[CameraSpec]) -> Result<()> {
        if cameras.len() > MAX_CAMERAS {
            return Err(self.err(format!(
                "[[cameras]] lists {} cameras; at most {MAX_CAMERAS} are supported",
                cameras.len()
            )));
        }
        let mut names: BTreeMap<&str, usize> = BTreeMap::new();
        for (k, c) in cameras.iter().enumerate() {
            if c.name.trim().is_empty() {
                return Err(self.err(format!("cameras[{k}].name must not be empty")));
            }
            if c.name.len() > MAX_NAME_BYTES {
                return Err(self.err(format!(
                    "cameras[{k}].name `{}` is {} bytes long; at most {MAX_NAME_BYTES} are allowed",
                    short(&c.name),
                    c.name.len()
                )));
            }
            if let Some(why) = camera_name_error(&c.name) {
                return Err(self.err(format!(
                    "cameras[{k}].name `{}` {why}",
                    crate::app::exports::printable(&short(&c.name))
                )));
            }
            if names.insert(&c.name, k).is_some() {
                return Err(self.err(format!(
                    "cameras[{k}].name `{}` is used twice",
                    short(&c.name)
                )));
            }
        }
        if let Some(c) = crate::app::exports::name_clash(cameras.iter().map(|c| c.name.as_str())) {
            return Err(self.err(format!(
                "cameras[{}].name `{}` and `{}` would both be written as {}; rename one",
                c.second, cameras[c.second].name, cameras[c.first].name, c.what
            )));
        }
        Ok(())
    }

    /// `[calibration]` values in the ranges where the solver is meaningful.
    fn check_calibration(&self, c: &CalibrationConfig, target: &Target) -> Result<()> {
        let (lo, hi) = LOSS_SCALE_RANGE;
        if !(c.loss_scale_px.is_finite() && c.loss_scale_px >= lo && c.loss_scale_px <= hi) {
            return Err(self.err(format!(
                "calibration.loss_scale_px must be {lo} to {hi} pixels (got {})",
                number(c.loss_scale_px)
            )));
        }
        if c.max_iterations == 0 {
            return Err(self.err("calibration.max_iterations must be at least 1".into()));
        }
        let (klo, khi) = OUTLIER_K_RANGE;
        if !(c.outlier_k == 0.0 || (c.outlier_k >= klo && c.outlier_k <= khi)) {
            return Err(self.err(format!(
                "calibration.outlier_k must be 0 (off) or {klo} to {khi} (got {})",
                number(c.outlier_k)
            )));
        }
        self.check_auto(c)?;
        if let Some(g) = &c.gauge_corners {
            self.check_gauge(c, g, target)?;
        }
        Ok(())
    }

    /// `auto`'s candidates and folds.
    fn check_auto(&self, c: &CalibrationConfig) -> Result<()> {
        if !c.auto_candidates.contains(&Method::Standard) {
            return Err(self.err(
                "calibration.auto_candidates must include `standard` (the baseline auto compares against)".into(),
            ));
        }
        if let Some((_, m)) = c
            .auto_candidates
            .iter()
            .enumerate()
            .find(|(i, m)| c.auto_candidates[..*i].contains(m))
        {
            return Err(self.err(format!("calibration.auto_candidates lists `{m}` twice")));
        }
        if !(2..=MAX_CV_FOLDS).contains(&c.cv_folds) {
            return Err(self.err(format!(
                "calibration.cv_folds must be 2 to {MAX_CV_FOLDS} (got {})",
                c.cv_folds
            )));
        }
        Ok(())
    }

    /// Gauge corners: as many as each method that uses them needs, on the board, distinct.
    fn check_gauge(&self, c: &CalibrationConfig, g: &[usize], target: &Target) -> Result<()> {
        let methods: Vec<Method> = match c.method {
            MethodChoice::Fixed(m) => vec![m],
            MethodChoice::Auto => c
                .auto_candidates
                .iter()
                .copied()
                .filter(|m| m.has_correction())
                .collect(),
        };
        for method in methods {
            let need = method.gauge_corners();
            if g.len() != need {
                return Err(self.err(format!(
                    "calibration.gauge_corners: method `{method}` needs exactly {need} corners (got {})",
                    g.len()
                )));
            }
        }
        if let Some(bad) = g.iter().find(|&&i| i >= target.num_corners()) {
            return Err(self.err(format!(
                "calibration.gauge_corners: corner {bad} is not on the {} × {} board",
                target.rows, target.cols
            )));
        }
        if let Some((i, dup)) = g.iter().enumerate().find(|(i, c)| g[..*i].contains(c)) {
            return Err(self.err(format!(
                "calibration.gauge_corners: corner {dup} is given twice (entries {} and {i})",
                g.iter().position(|x| x == dup).unwrap_or(0)
            )));
        }
        Ok(())
    }

    /// The board priors' σ and `max_bend_mm`: millimetres in [`BOARD_MM_RANGE`];
    /// the lens prior's σ in [`LENS_PRIOR_RANGE`].
    fn check_board_priors(&self, c: &CalibrationConfig) -> Result<()> {
        let (lo, hi) = BOARD_MM_RANGE;
        for (key, v) in [
            (
                "static_prior_mm",
                c.static_prior_mm.and_then(PriorSigma::mm),
            ),
            ("bend_prior_mm", c.bend_prior_mm.and_then(PriorSigma::mm)),
            (
                "bend_smoothness",
                c.bend_smoothness.and_then(PriorSigma::mm),
            ),
            ("max_bend_mm", Some(c.max_bend_mm)),
        ] {
            if let Some(v) = v {
                if !(lo..=hi).contains(&v) {
                    return Err(self.err(format!(
                        "calibration.{key} must be a positive number of millimetres, {lo} to {hi} (got {})",
                        number(v)
                    )));
                }
            }
        }
        let (lo, hi) = LENS_PRIOR_RANGE;
        if let Some(v) = c.lens_prior.0 {
            if !(lo..=hi).contains(&v) {
                return Err(self.err(format!(
                    "calibration.lens_prior must be {lo} to {hi}, or \"none\" (got {})",
                    number(v)
                )));
            }
        }
        Ok(())
    }

    /// `[protocol]`: sizes bounded before anything is allocated from them.
    fn check_protocol(&self, p: &ProtocolConfig) -> Result<()> {
        if !(1..=MAX_SUBSETS).contains(&p.subsets) {
            return Err(self.err(format!(
                "protocol.subsets must be 1 to {MAX_SUBSETS} (got {})",
                p.subsets
            )));
        }
        if p.images_per_subset < MIN_IMAGES {
            return Err(self.err(format!(
                "protocol.images_per_subset must be at least {MIN_IMAGES}, the fewest images a calibration accepts (got {})",
                p.images_per_subset
            )));
        }
        if p.methods.is_empty() && !p.auto {
            return Err(self.err("protocol.methods must name at least one method".into()));
        }
        if let Some((_, m)) = p
            .methods
            .iter()
            .enumerate()
            .find(|(i, m)| p.methods[..*i].contains(m))
        {
            return Err(self.err(format!("protocol.methods lists `{m}` twice")));
        }
        Ok(())
    }

    /// A config error; when the message starts with a key, its line is named too.
    fn err(&self, message: String) -> Error {
        let line = message_key(&message).and_then(|(t, i, k)| key_line(self.text, &t, i, &k));
        Error::Config {
            path: self.path.into(),
            message: match line {
                Some(n) => format!("line {n}: {message}"),
                None => message,
            },
        }
    }

    fn source(
        &self,
        table: &str,
        observations: Option<PathBuf>,
        synthetic: Option<String>,
        images: Option<usize>,
        seed: Option<u64>,
        cameras: Option<usize>,
    ) -> Result<DataSource> {
        match (observations, synthetic) {
            (Some(_), Some(_)) => Err(self.err(format!(
                "[{table}] has both `observations` and `synthetic`; give one"
            ))),
            (None, None) => Err(self.err(format!(
                "[{table}] needs `observations` (a CSV file) or `synthetic` (a preset)"
            ))),
            (Some(p), None) => {
                if images.is_some() || seed.is_some() || cameras.is_some() {
                    return Err(self.err(format!(
                        "{table}.images, {table}.seed and {table}.cameras apply to synthetic data only"
                    )));
                }
                Ok(DataSource::Observations(self.base.join(p)))
            }
            (None, Some(name)) => {
                let preset = Preset::parse(&name).ok_or_else(|| {
                    self.err(format!(
                        "{table}.synthetic: unknown preset `{name}` (expected one of {})",
                        Preset::NAMES.join(", ")
                    ))
                })?;
                if let Some(n) = images.filter(|n| !(1..=MAX_IMAGES).contains(n)) {
                    return Err(self.err(format!(
                        "{table}.images must be 1 to {MAX_IMAGES} (got {n})"
                    )));
                }
                let cameras = cameras.unwrap_or(preset.default_cameras());
                if !(1..=16).contains(&cameras) {
                    return Err(
                        self.err(format!("{table}.cameras must be 1 to 16 (got {cameras})"))
                    );
                }
                Ok(DataSource::Synthetic {
                    preset,
                    images,
                    seed: seed.unwrap_or(DEFAULT_SYNTHETIC_SEED),
                    cameras,
                })
            }
        }
    }

    /// `[data] photos`, which excludes every other source.
    fn photos(&self, data: &RawData) -> Result<DataSource> {
        let others = data.observations.is_some()
            || data.corners_vnl.is_some()
            || data.synthetic.is_some()
            || !data.camera_patterns.is_empty();
        if others || data.images.is_some() || data.seed.is_some() || data.cameras.is_some() {
            return Err(self.err(
                "[data] photos excludes observations, corners_vnl, camera_patterns and synthetic data"
                    .into(),
            ));
        }
        let patterns = data.photos.clone().expect("caller checked");
        let all: Vec<&String> = match &patterns {
            PhotoPatterns::One(p) => vec![p],
            PhotoPatterns::PerCamera(m) => m.values().collect(),
        };
        if all.is_empty() || all.iter().any(|p| p.trim().is_empty()) {
            return Err(self.err("data.photos: a pattern must not be empty".into()));
        }
        Ok(DataSource::Photos {
            base: self.base.clone(),
            patterns,
        })
    }

    /// Photo patterns and [[cameras]] must name the same cameras.
    fn check_photo_cameras(&self, patterns: &PhotoPatterns, cameras: &[CameraSpec]) -> Result<()> {
        match patterns {
            PhotoPatterns::One(_) if cameras.len() > 1 => Err(self.err(format!(
                "data.photos: with {} cameras give one pattern per camera, e.g. photos = {{ {} = \"left-*.png\", ... }}",
                cameras.len(),
                cameras[0].name
            ))),
            PhotoPatterns::One(_) => Ok(()),
            PhotoPatterns::PerCamera(m) => {
                if let Some(unknown) = m.keys().find(|k| !cameras.iter().any(|c| &c.name == *k)) {
                    return Err(self.err(format!(
                        "data.photos names `{unknown}`, which is not a camera of [[cameras]]"
                    )));
                }
                match cameras.iter().find(|c| !m.contains_key(&c.name)) {
                    Some(c) => Err(self.err(format!(
                        "data.photos needs a pattern for camera `{}`",
                        c.name
                    ))),
                    None => Ok(()),
                }
            }
        }
    }

    fn check_target(&self, table: &str, t: &Target) -> Result<()> {
        if t.rows < 2 || t.cols < 2 {
            return Err(self.err(format!(
                "{table}.rows and {table}.cols must be at least 2 (got {} × {})",
                t.rows, t.cols
            )));
        }
        // Checked: a product that wraps around would slip under the cap.
        if t.rows.checked_mul(t.cols).is_none_or(|n| n > MAX_CORNERS) {
            return Err(self.err(format!(
                "{table}: a board of {} × {} corners is too large",
                t.rows, t.cols
            )));
        }
        if let Some(problem) = crate::model::target::spacing_problem(t.spacing) {
            return Err(self.err(format!("{table}.spacing {problem}")));
        }
        Ok(())
    }

    fn check(&self, mut raw: RawConfig) -> Result<Config> {
        if let Some(t) = &raw.target {
            t.check().map_err(|m| self.err(m))?;
        }
        let data = match raw.data.corners_vnl {
            _ if raw.data.photos.is_some() => self.photos(&raw.data)?,
            Some(vnl) => {
                if raw.data.observations.is_some() || raw.data.synthetic.is_some() {
                    return Err(self.err(
                        "[data] takes one of `observations`, `corners_vnl` and `synthetic`".into(),
                    ));
                }
                DataSource::CornersVnl {
                    path: self.base.join(vnl),
                    patterns: raw.data.camera_patterns.clone(),
                }
            }
            None => {
                if !raw.data.camera_patterns.is_empty() {
                    return Err(
                        self.err("data.camera_patterns applies to `corners_vnl` only".into())
                    );
                }
                self.source(
                    "data",
                    raw.data.observations,
                    raw.data.synthetic,
                    raw.data.images,
                    raw.data.seed,
                    raw.data.cameras,
                )?
            }
        };
        let (target, cameras) = match &data {
            DataSource::Synthetic {
                preset, cameras: n, ..
            } => self.synthetic_rig(
                preset,
                *n,
                raw.target.as_ref().map(RawTarget::target).as_ref(),
                &raw.cameras,
            )?,
            DataSource::Observations(_)
            | DataSource::CornersVnl { .. }
            | DataSource::Photos { .. } => {
                let t = raw.target.as_ref().map(RawTarget::target).ok_or_else(|| {
                    self.err("the config needs a `[target]` section (rows, cols, spacing)".into())
                })?;
                if raw.cameras.is_empty() {
                    return Err(
                        self.err("missing [[cameras]]: at least one camera is needed".into())
                    );
                }
                (t, raw.cameras.clone())
            }
        };
        self.check_target("target", &target)?;
        self.check_camera_names(&cameras)?;
        self.check_camera_params(&cameras)?;
        let reference = self.reference(raw.reference.take(), target)?;
        self.check_calibration(&raw.calibration, &target)?;
        self.check_solver_limits(&raw.calibration)?;
        self.check_board_priors(&raw.calibration)?;
        if let Some(path) = raw.target.as_ref().and_then(|t| t.geometry.clone()) {
            let path = self.base.join(path);
            let g = crate::app::board_json::read(&path, &target)?;
            raw.calibration.geometry = Some(std::sync::Arc::new(g));
        }
        apply_bend_order(&mut raw.calibration, raw.protocol.as_mut());
        if let Some(p) = &raw.protocol {
            self.check_protocol(p)?;
        }
        if let Some(s) = &raw.sfm {
            s.check().map_err(|m| self.err(m))?;
        }
        self.check_camera_patterns(&data, &cameras)?;
        if let DataSource::Photos { patterns, .. } = &data {
            self.check_photo_cameras(patterns, &cameras)?;
        }
        let output_dir = match raw.output {
            Some(o) => self.base.join(o.dir),
            None => self.base.join("out"),
        };
        Ok(Config {
            path: self.path.into(),
            target,
            charuco: raw.target.as_ref().and_then(RawTarget::charuco),
            cameras,
            data,
            reference,
            calibration: raw.calibration,
            protocol: raw.protocol,
            sfm: raw.sfm,
            output_dir,
        })
    }

    /// A synthetic source's board and cameras; `[target]`/`[[cameras]]` must agree with them.
    fn synthetic_rig(
        &self,
        preset: &Preset,
        n: usize,
        target: Option<&Target>,
        cameras: &[CameraSpec],
    ) -> Result<(Target, Vec<CameraSpec>)> {
        let spec = preset.spec();
        if let Some(t) = target {
            if *t != spec.target {
                return Err(self.err(format!(
                    "[target] differs from the `{}` preset's board ({} × {}, {} m); remove it or use observations",
                    preset.name(), spec.target.rows, spec.target.cols, spec.target.spacing
                )));
            }
        }
        if cameras.is_empty() {
            return Ok((spec.target, preset.cameras(n)));
        }
        if cameras.len() != n {
            return Err(self.err(format!(
                "[[cameras]] lists {} camera(s) but the synthetic rig has {n}; set data.cameras or remove [[cameras]]",
                cameras.len()
            )));
        }
        for (given, simulated) in cameras.iter().zip(preset.cameras(n)) {
            if (given.width, given.height) != (simulated.width, simulated.height) {
                return Err(self.err(format!(
                    "[[cameras]] `{}` differs from the simulated {}×{} camera; only the name, model and fix may be changed",
                    given.name, simulated.width, simulated.height
                )));
            }
        }
        Ok((spec.target, cameras.to_vec()))
    }

    /// Each camera's image size is positive and its fixed parameters are its model's.
    fn check_camera_params(&self, cameras: &[CameraSpec]) -> Result<()> {
        for (k, c) in cameras.iter().enumerate() {
            for (key, v) in [("width", c.width), ("height", c.height)] {
                if v == 0 || v > MAX_IMAGE_SIDE_PX {
                    return Err(self.err(format!(
                        "cameras[{k}].{key} of `{}` must be positive, at most {MAX_IMAGE_SIDE_PX} pixels (got {v})",
                        c.name
                    )));
                }
            }
            if let Some(name) = c.unknown_fixed() {
                return Err(self.err(format!(
                    "cameras[{k}].fix: `{name}` is not a parameter of `{}` (its parameters: {})",
                    c.model,
                    c.model.param_names().join(", ")
                )));
            }
        }
        Ok(())
    }

    /// `[reference]`: its source, and its board (defaulting to the preset's or the data's).
    fn reference(
        &self,
        raw: Option<RawReference>,
        target: Target,
    ) -> Result<Option<ReferenceConfig>> {
        let Some(r) = raw else {
            return Ok(None);
        };
        let source = self.source(
            "reference",
            r.observations,
            r.synthetic,
            r.images,
            r.seed,
            r.cameras,
        )?;
        let default_target = match &source {
            DataSource::Synthetic { preset, .. } => preset.spec().target,
            _ => target,
        };
        let t = Target {
            rows: r.rows.unwrap_or(default_target.rows),
            cols: r.cols.unwrap_or(default_target.cols),
            spacing: r.spacing.unwrap_or(default_target.spacing),
        };
        self.check_target("reference", &t)?;
        Ok(Some(ReferenceConfig { source, target: t }))
    }

    /// `[calibration]` threads and tolerances within what Ceres accepts.
    fn check_solver_limits(&self, c: &CalibrationConfig) -> Result<()> {
        let (lo, hi) = NOISE_RANGE_PX;
        if let Some(n) = c.detector_noise_px {
            if !(lo..=hi).contains(&n) {
                return Err(self.err(format!(
                    "calibration.detector_noise_px must be a positive number of pixels, {lo} to {hi} (got {})",
                    number(n)
                )));
            }
        }
        if let Some(m) = c.max_rmse_px {
            if !(m.is_finite() && m > 0.0) {
                return Err(self.err(format!(
                    "calibration.max_rmse_px must be a positive number of pixels (got {})",
                    number(m)
                )));
            }
        }
        if c.threads == 0 || c.threads > 256 {
            return Err(self.err(format!(
                "calibration.threads must be 1 to 256 (got {})",
                c.threads
            )));
        }
        for (key, v) in [
            ("function_tolerance", c.function_tolerance),
            ("gradient_tolerance", c.gradient_tolerance),
            ("parameter_tolerance", c.parameter_tolerance),
        ] {
            if !(v > 0.0 && v <= MAX_TOLERANCE) {
                return Err(self.err(format!(
                    "calibration.{key} must be above 0 and at most {MAX_TOLERANCE} (got {}): it is the relative change at which the solve stops",
                    number(v)
                )));
            }
        }
        Ok(())
    }

    /// `data.camera_patterns` names only known cameras, and all of them when there are several.
    fn check_camera_patterns(&self, data: &DataSource, cameras: &[CameraSpec]) -> Result<()> {
        if let DataSource::CornersVnl { patterns, .. } = data {
            if let Some(unknown) = patterns
                .keys()
                .find(|k| !cameras.iter().any(|c| &c.name == *k))
            {
                return Err(self.err(format!(
                    "data.camera_patterns names `{unknown}`, which is not a camera of [[cameras]]"
                )));
            }
            if cameras.len() > 1 {
                if let Some(c) = cameras.iter().find(|c| !patterns.contains_key(&c.name)) {
                    return Err(self.err(format!(
                        "data.camera_patterns needs a pattern for camera `{}`",
                        c.name
                    )));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Config> {
        Config::parse(text, Path::new("/tmp/x/c.toml"))
    }

    #[test]
    fn unknown_key_is_named_with_line() {
        let e = parse("[data]\nsynthetic = \"t2\"\n[calibration]\nmethdo = \"full\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("methdo"), "{e}");
        assert!(e.contains("line 4"), "{e}");
    }

    #[test]
    fn relative_paths_follow_the_config() {
        let c = parse(
            "[target]\nrows=3\ncols=4\nspacing=0.1\n[[cameras]]\nname=\"c\"\nwidth=10\nheight=10\n[data]\nobservations=\"o.csv\"\n[output]\ndir=\"out/a\"\n",
        )
        .unwrap();
        assert_eq!(c.data, DataSource::Observations("/tmp/x/o.csv".into()));
        assert_eq!(c.output_dir, PathBuf::from("/tmp/x/out/a"));
    }

    #[test]
    fn bad_values_name_their_key() {
        let e = parse("[target]\nrows=0\ncols=4\nspacing=0.1\n[[cameras]]\nname=\"c\"\nwidth=10\nheight=10\n[data]\nobservations=\"o.csv\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("target.rows") && e.contains("line 2"), "{e}");
        let e = parse("[target]\nrows=3\ncols=4\nspacing=0.1\n[[cameras]]\nname=\"a\"\nwidth=10\nheight=10\n[[cameras]]\nname=\"b\"\nwidth=0\nheight=10\n[data]\nobservations=\"o.csv\"\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("cameras[1].width") && e.contains("line 11"),
            "{e}"
        );
        let e = parse("[data]\nsynthetic=\"t9\"\n").unwrap_err().to_string();
        assert!(e.contains("data.synthetic") && e.contains("t9"), "{e}");
    }
}
