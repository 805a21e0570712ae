//! The config's value ranges: the limits where the solver is meaningful and the
//! inputs are bounded before anything is allocated from them, and their checks.
use super::calibration::{CalibrationConfig, PriorSigma};
use super::checker::Checker;
use super::protocol::ProtocolConfig;
use crate::app::text::{number, short};
use crate::error::Result;
use crate::model::board::Method;
use crate::model::camera::CameraSpec;
use crate::model::selection::MethodChoice;
use crate::model::target::Target;
use crate::solver::calibrate::MIN_IMAGES;
use std::collections::BTreeMap;

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
    pub(super) fn check_camera_names(&self, cameras: &[CameraSpec]) -> Result<()> {
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
    pub(super) fn check_calibration(&self, c: &CalibrationConfig, target: &Target) -> Result<()> {
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
    pub(super) fn check_auto(&self, c: &CalibrationConfig) -> Result<()> {
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
    pub(super) fn check_gauge(
        &self,
        c: &CalibrationConfig,
        g: &[usize],
        target: &Target,
    ) -> Result<()> {
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
    pub(super) fn check_board_priors(&self, c: &CalibrationConfig) -> Result<()> {
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
    pub(super) fn check_protocol(&self, p: &ProtocolConfig) -> Result<()> {
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

    pub(super) fn check_target(&self, table: &str, t: &Target) -> Result<()> {
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

    /// Each camera's image size is positive and its fixed parameters are its model's.
    pub(super) fn check_camera_params(&self, cameras: &[CameraSpec]) -> Result<()> {
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

    /// `[calibration]` threads and tolerances within what Ceres accepts.
    pub(super) fn check_solver_limits(&self, c: &CalibrationConfig) -> Result<()> {
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
}
