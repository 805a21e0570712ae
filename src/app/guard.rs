//! The guard rails of a finished calibration: whether its result may be used, and
//! if not, why and what would likely fix it. A calibration fails when its last
//! solve did not converge, when outlier rejection removed more than
//! [`MAX_REJECTED_SHARE`] of the data, or when its RMSE is far above what the data
//! support: above [`MAX_RMSE_PX`], or above [`NOISE_FACTOR`] times the noise floor
//! √2·σ̂ (and above [`NOISE_RULE_FLOOR_PX`]); `[calibration] max_rmse_px` replaces
//! both RMSE rules by one bound. The hints come from cheap re-calibrations (`standard`
//! on at most [`TRIAL_FRAMES`] frames) under the likely mistakes: rows and cols
//! swapped, a lens model that cannot follow the lens; and from the worst frames.
//! Writing the failed result and the exit code are the callers' business.
use crate::app::lint::{frame_label, FrameFiles};
use crate::model::camera::CameraSpec;
use crate::model::dataset::Dataset;
use crate::model::lens::LensModel;
use crate::model::target::Target;
use crate::solver::calibrate::{calibrate, Calibration, Request};
use crate::Method;
use serde::{Deserialize, Serialize};

/// An RMSE above this, in pixels, is no calibration: good ones give 0.1–0.5 px on
/// real photos and at most about 1 px with a bending board under `standard`.
pub const MAX_RMSE_PX: f64 = 5.0;
/// An RMSE this many times the noise floor √2·σ̂ is more than any model error of
/// the repo's bending presets (at most about 5× for `standard` on T3).
pub const NOISE_FACTOR: f64 = 10.0;
/// Below this RMSE, in pixels, the noise rule does not apply: with very clean
/// corners a small model error is many times the noise and still harmless.
pub const NOISE_RULE_FLOOR_PX: f64 = 1.0;
/// Frames a trial re-calibration uses at most, evenly spread: enough to tell a
/// right board or lens model from a wrong one, and quick.
pub const TRIAL_FRAMES: usize = 40;
/// A result for which outlier rejection removed more than this share of the
/// observations describes only the rest: good data lose well under 1 %.
pub const MAX_REJECTED_SHARE: f64 = 0.25;

/// Why a calibration failed its guard rails, and what may fix it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Failure {
    pub reasons: Vec<String>,
    pub hints: Vec<String>,
}

/// The rules a result is held to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rules {
    /// `[calibration] max_rmse_px`: one RMSE bound instead of the default two rules.
    pub max_rmse_px: Option<f64>,
}

/// The reasons a calibration cannot be used; empty when it passes.
pub fn reasons(c: &Calibration, rules: Rules) -> Vec<String> {
    let mut out = Vec::new();
    if !c.converged {
        let last = c.stages.last();
        out.push(format!(
            "the {} solve did not converge after {} iterations ({})",
            c.method,
            last.map_or(0, |s| s.iterations),
            last.map_or("", |s| s.message.trim_end_matches('.'))
        ));
    }
    let rejected = c.rejected.len();
    let total = rejected + c.dataset.observations.len();
    if rejected as f64 > MAX_REJECTED_SHARE * total as f64 {
        out.push(format!(
            "outlier rejection removed {rejected} of its {total} observations ({:.0}%): \
             the model describes only the rest",
            100.0 * rejected as f64 / total as f64
        ));
    }
    let rmse = c.rmse_px;
    let bound = rules.max_rmse_px.unwrap_or(MAX_RMSE_PX);
    if rmse.is_nan() || rmse > bound {
        out.push(match rules.max_rmse_px {
            Some(_) => format!("its RMSE {rmse:.3} px is above calibration.max_rmse_px = {bound} px"),
            None => format!(
                "its RMSE {rmse:.3} px is above {bound} px, far more than a calibration gives (0.1–1 px)"
            ),
        });
    } else if rules.max_rmse_px.is_none() && rmse > NOISE_RULE_FLOOR_PX {
        if let Some(t) = c.assessment.trust {
            let floor = std::f64::consts::SQRT_2 * t.noise_px;
            if rmse > NOISE_FACTOR * floor {
                out.push(format!(
                    "its RMSE {rmse:.3} px is {:.0} times the {floor:.3} px that the corners' noise \
                     (σ̂ = {:.3} px) explains: the model cannot describe the data (one that can \
                     gives about 1 time)",
                    rmse / floor,
                    t.noise_px
                ));
            }
        }
    }
    out
}

/// Judges a calibration of `input` made with `request`: `None` when it may be
/// used, else the reasons and hints. `files` names the frames in the hints.
pub fn judge(
    input: &Dataset,
    request: &Request,
    c: &Calibration,
    rules: Rules,
    files: &FrameFiles,
) -> Option<Failure> {
    let reasons = reasons(c, rules);
    if reasons.is_empty() {
        return None;
    }
    let mut hints = Vec::new();
    if let Some(h) = iterations_hint(c, request) {
        hints.push(h);
    }
    // A rule on the data broke (not only convergence): look for the likely mistake.
    if reasons.len() > usize::from(!c.converged) {
        hints.extend(likely_mistakes(input, request, c.rmse_px, rules));
        hints.extend(worst_frames_hint(c, files));
    }
    Some(Failure { reasons, hints })
}

/// Hints for a calibration of `input` that failed before it had a result
/// (degenerate views, no initialisation): the same trials as for a failed result.
pub fn error_hints(input: &Dataset, request: &Request, rules: Rules) -> Vec<String> {
    likely_mistakes(input, request, f64::NAN, rules)
}

/// Hints that name a likely mistake (rows and cols swapped, the wrong lens model),
/// each only when the user's own settings fail the rules on the trial's frames
/// while the other reading passes them: a richer lens model that merely fits a
/// little better is no sign of a mistake.
fn likely_mistakes(input: &Dataset, request: &Request, failed: f64, rules: Rules) -> Vec<String> {
    if trial(input, request, rules).is_some() {
        return Vec::new();
    }
    let mut hints = Vec::new();
    hints.extend(swapped_hint(input, request, failed, rules));
    hints.extend(lens_hint(input, request, failed, rules));
    hints
}

/// When the solve ran out of iterations: say so and how to give it more.
fn iterations_hint(c: &Calibration, request: &Request) -> Option<String> {
    let last = c.stages.last()?;
    let max = request.settings.max_iterations;
    (!c.converged && i64::from(last.iterations) >= i64::from(max)).then(|| {
        format!(
            "the solve stopped at calibration.max_iterations = {max}; if the RMSE is fine, raise it \
             (or loosen function_tolerance / parameter_tolerance)"
        )
    })
}

/// `standard` on at most [`TRIAL_FRAMES`] evenly spread frames of `d`: the RMSE
/// when the trial passes the rules, else `None`.
fn trial(d: &Dataset, request: &Request, rules: Rules) -> Option<f64> {
    let n = d.num_frames();
    let frames: Vec<usize> = if n > TRIAL_FRAMES {
        (0..TRIAL_FRAMES).map(|i| i * n / TRIAL_FRAMES).collect()
    } else {
        (0..n).collect()
    };
    let r = Request {
        method: Method::Standard,
        settings: request.settings.clone(),
        gauge: None,
    };
    let c = calibrate(&d.subset(&frames), &r).ok()?;
    reasons(&c, rules).is_empty().then_some(c.rmse_px)
}

/// Whether a trial that passed the rules beats the failed result: a lower RMSE
/// (the failed one may have lost its worst observations to outlier rejection), or
/// any when there was no result (NaN).
fn better(trial: f64, failed: f64) -> bool {
    failed.is_nan() || trial < failed
}

/// "rows and cols may be swapped", when the same corner numbers read on the
/// swapped board (corner i = row·rows + col) fit.
fn swapped_hint(input: &Dataset, request: &Request, failed: f64, rules: Rules) -> Option<String> {
    let t = input.target;
    if t.rows == t.cols {
        return None;
    }
    let swapped = Dataset {
        target: Target {
            rows: t.cols,
            cols: t.rows,
            spacing: t.spacing,
        },
        ..input.clone()
    };
    let rmse = trial(&swapped, request, rules)?;
    better(rmse, failed).then(|| {
        format!(
            "rows and cols may be swapped: read as a {} × {} board (target.rows = {}, target.cols = {}) \
             the same corners give RMSE {rmse:.3} px with `standard`",
            t.cols, t.rows, t.cols, t.rows
        )
    })
}

/// "the lens may need model X", when another lens model fits (a fisheye taken for
/// a pinhole lens, or a wide lens beyond radial3).
fn lens_hint(input: &Dataset, request: &Request, failed: f64, rules: Rules) -> Option<String> {
    for model in LensModel::WIDEST {
        if input.cameras.iter().all(|cam| cam.model == model) {
            continue;
        }
        let cameras: Vec<CameraSpec> = input
            .cameras
            .iter()
            .map(|cam| CameraSpec::new(cam.name.clone(), cam.width, cam.height, model))
            .collect();
        let other = Dataset {
            cameras,
            ..input.clone()
        };
        if let Some(rmse) = trial(&other, request, rules).filter(|&r| better(r, failed)) {
            return Some(format!(
                "the lens model may not fit the lens: with model = \"{model}\" the same corners give \
                 RMSE {rmse:.3} px with `standard`"
            ));
        }
    }
    None
}

/// The frames with the worst RMSE, and whether a few of them hold most of it.
fn worst_frames_hint(c: &Calibration, files: &FrameFiles) -> Option<String> {
    let d = &c.dataset;
    let mut sq = vec![0.0; d.num_frames()];
    let mut n = vec![0usize; d.num_frames()];
    for (o, r) in d.observations.iter().zip(c.residuals.chunks(2)) {
        sq[o.frame] += r[0] * r[0] + r[1] * r[1];
        n[o.frame] += 1;
    }
    let mut frames: Vec<(usize, f64)> = (0..d.num_frames())
        .filter(|&j| n[j] > 0)
        .map(|j| (j, (sq[j] / n[j] as f64).sqrt()))
        .collect();
    if frames.is_empty() {
        return None;
    }
    frames.sort_by(|a, b| b.1.total_cmp(&a.1));
    let worst: Vec<String> = frames
        .iter()
        .take(3)
        .map(|&(j, e)| format!("{} {e:.2} px", frame_label(d, files, j)))
        .collect();
    let median = frames[frames.len() / 2].1;
    let total: f64 = sq.iter().sum();
    let top: f64 = frames.iter().take(3).map(|&(j, _)| sq[j]).sum();
    let share = if total > 0.0 { top / total } else { 0.0 };
    let advice = if share > 0.5 && frames.len() > 6 {
        format!(
            "; they hold {:.0}% of the squared residual: check their corners, or leave those images out",
            100.0 * share
        )
    } else {
        String::new()
    };
    Some(format!(
        "frames with the worst RMSE: {} (median frame {median:.2} px){advice}",
        worst.join(", ")
    ))
}
