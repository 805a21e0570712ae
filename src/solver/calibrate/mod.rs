//! The calibration pipeline: Zhang initialisation → `standard` → the chosen method.
//!
//! One file per stage, each depending only on those before it: `types` (the
//! request and the result), `init` (the initialisation), `warm` (the first
//! `standard` solve every method shares), `method` (the method's own solve and
//! its priors), `fit` (from the warm start to the result, outlier rejection
//! included); this file puts them together.
mod fit;
mod init;
mod method;
mod types;
mod warm;

use crate::error::Result;
use crate::model::board::Method;
use crate::model::dataset::Dataset;
use crate::solver::problem::{rmse, SolverSettings};
use crate::solver::robust;
use fit::fit_from;
pub use init::{MIN_CORNERS_PER_IMAGE, MIN_IMAGES};
use std::sync::OnceLock;
pub use types::{Assessment, Calibration, Request, Stage, Suspect};
use warm::{warm_start, warm_start_is_loose, warm_start_settings, WarmStart};

/// Runs the whole pipeline on one dataset.
pub fn calibrate(dataset: &Dataset, request: &Request) -> Result<Calibration> {
    with_covariance(fit(dataset, request)?)
}

/// A fit with its unit covariance, and its uncertainty figures from it.
fn with_covariance(mut c: Calibration) -> Result<Calibration> {
    c.covariance = crate::solver::covariance::unit_covariance(&c.problem(), &c.state, &c.settings);
    c.assessment.uncertainty = c.uncertainty_at(c.assessment.trust.as_ref());
    Ok(c)
}

/// A finished fit with its trust figures (computed here, once).
fn assessed(mut c: Calibration) -> Calibration {
    c.assess();
    c
}

/// [`calibrate`] without the covariance, for fits only their parameters matter
/// of (`auto`'s cross-validation folds).
pub fn fit(dataset: &Dataset, request: &Request) -> Result<Calibration> {
    let c = without_footprint(fit_from(warm_start(dataset, request)?, request)?, request)?;
    Ok(assessed(c))
}

/// Outlier rejection that leaves no trace: the solves after a rejection start
/// where the outliers had pulled the parameters, and with a bending board they
/// can stay in a worse minimum (3 % gross outliers on a bending board: `full`
/// ended 0.27 px from the true lens, a fresh fit of exactly the observations it
/// kept 0.07 px). So a fit that rejected anything is done again from scratch,
/// warm start included, on the observations it kept, with rejection off: the
/// result is the calibration of the kept data, whatever the rejected held.
/// `first`'s rejected observations, stages and warnings are kept in the record.
///
/// A share of at most [`KEEP_FIT_REJECTED_SHARE`] rejected is no such pull:
/// the loss bounds each outlier's weight, and a few among thousands do not hold
/// the solve in another minimum, while the fit from scratch doubled the cost of
/// every large calibration (any large set has a few corners beyond 4σ). For
/// `dynamic` and `full` the first fit's last solve, on exactly the kept
/// observations from next to their optimum, is then the result. `standard` and
/// `static` have a flatter optimum on a bending board, where a solve stops
/// early wherever it starts (with 4 of 10 140 rejected, `opencv5` `standard`'s
/// first fit and the fit afresh ended 0.03 px apart, each 0.013–0.017 px from
/// the converged optimum), so theirs is solved on from where it stopped
/// ([`continued`]), which ends as close to that optimum as a fit from scratch
/// at a fraction of its cost.
fn without_footprint(first: Calibration, request: &Request) -> Result<Calibration> {
    if first.rejected.is_empty() || keeps_first_fit(&first, request) {
        return Ok(first);
    }
    if few_rejected(&first) && matches!(request.method, Method::Standard | Method::Static) {
        return Ok(continued(first));
    }
    let kept = Request {
        settings: SolverSettings {
            outlier_k: 0.0,
            ..request.settings.clone()
        },
        ..request.clone()
    };
    let mut fresh = match warm_start(&first.dataset, &kept).and_then(|w| fit_from(w, &kept)) {
        Ok(fresh) => fresh,
        Err(e) => {
            let mut first = first;
            first.warnings.push(format!(
                "the kept observations alone could not be calibrated afresh ({e}); this result \
                 continues from the fit that still held the rejected ones"
            ));
            return Ok(first);
        }
    };
    fresh.settings.outlier_k = request.settings.outlier_k;
    fresh.rejected = first.rejected;
    fresh.seconds += first.seconds;
    let mut stages = first.stages;
    stages.append(&mut fresh.stages);
    fresh.stages = stages;
    // The first fit's warnings about the data (drops, the share rejected) hold;
    // those about its solves and priors are the fresh fit's to give.
    let about_solves = |w: &String| {
        ["static_prior_mm", "bend_prior_mm", "bend_smoothness"]
            .iter()
            .any(|k| w.starts_with(k))
            || w.contains("solve did not converge")
    };
    let mut warnings: Vec<String> = first
        .warnings
        .into_iter()
        .filter(|w| !about_solves(w))
        .collect();
    for w in fresh.warnings {
        if !warnings.contains(&w) {
            warnings.push(w);
        }
    }
    fresh.warnings = warnings;
    Ok(fresh)
}

/// `first`'s method solved on from its result, on the observations it kept,
/// with rejection off and the request's tolerances: the re-solve after the
/// rejection stopped after one step ([`robust::reject_outliers`]), and the
/// solve of the kept observations goes on until its tolerances stop it, as a
/// fit of them from scratch does. Its stage is recorded after the first fit's.
/// A solve that fails leaves the first fit standing, with a warning.
fn continued(mut first: Calibration) -> Calibration {
    let settings = SolverSettings {
        outlier_k: 0.0,
        ..first.settings.clone()
    };
    let mut state = first.state.clone();
    let report = first.problem().solve(&mut state, &settings).and_then(|r| {
        robust::check_stage(first.method, &r, false)?;
        Ok(r)
    });
    let report = match report {
        Ok(r) => r,
        Err(e) => {
            first.warnings.push(format!(
                "the solve on the observations kept after outlier rejection failed ({e}); \
                 this result is the re-solve right after the rejection"
            ));
            return first;
        }
    };
    first.stages.push(Stage::new(first.method, &report));
    if !report.converged {
        first.warnings.push(format!(
            "the {} solve did not converge: {}",
            first.method, report.message
        ));
    }
    first.state = state;
    first.rmse_px = rmse(&report.residuals);
    first.residuals = report.residuals;
    first.converged = report.converged;
    first.seconds += report.seconds;
    first
}

/// The largest share of rejected observations after which a fit that rejected
/// them is not fitted again from scratch (see [`without_footprint`]): `dynamic`
/// and `full` stand, `standard` and `static` are solved on ([`continued`]). Measured with
/// `cargo bench --bench speed -- growth` (`t2`, `radial3`, 100 to 10 000 images,
/// 0.01–0.05 % rejected): `full` within 0.0011 px of the fit from scratch; and
/// by `a_few_rejected_among_thousands_keep_the_fit_that_rejected_them` for five
/// lens models. The 3 % of gross outliers of `tests/rejection.rs` still get
/// the fit from scratch.
pub const KEEP_FIT_REJECTED_SHARE: f64 = 1e-3;

/// Whether `first` (its request's method) stands as it is, without a fit from scratch.
fn keeps_first_fit(first: &Calibration, request: &Request) -> bool {
    matches!(request.method, Method::Dynamic | Method::Full) && few_rejected(first)
}

/// Whether `first` rejected at most [`KEEP_FIT_REJECTED_SHARE`] of its observations.
fn few_rejected(first: &Calibration) -> bool {
    let total = first.dataset.observations.len() + first.rejected.len();
    first.rejected.len() as f64 <= KEEP_FIT_REJECTED_SHARE * total as f64
}

/// One warm start per dataset, computed by the first calibration that can use
/// it and then shared by the others: the deformation methods of one dataset
/// (the protocol's methods of a subset, `auto`'s candidates) start from the same
/// `standard` solve. Each result is, bit for bit, the one [`fit`] gives (only
/// its `seconds` differ), since the shared part is the same computation.
#[derive(Debug, Default)]
pub struct SharedWarmStart(OnceLock<Option<WarmStart>>);

impl SharedWarmStart {
    /// [`fit`] of `dataset`, from the shared warm start where `request` starts
    /// from a loose one. A dataset or settings other than those the warm start
    /// was computed from are fitted on their own.
    pub fn fit(&self, dataset: &Dataset, request: &Request) -> Result<Calibration> {
        if !warm_start_is_loose(request, dataset) {
            // Its first solve is the answer: nothing another method can share.
            return fit(dataset, request);
        }
        // The closure solves on this thread (no rayon inside), so a thread that
        // waits here waits for a solve under way, never for one queued behind it.
        let shared = self.0.get_or_init(|| warm_start(dataset, request).ok());
        match shared {
            Some(w)
                if w.settings == warm_start_settings(request, dataset) && w.input == *dataset =>
            {
                let c = without_footprint(fit_from(w.clone(), request)?, request)?;
                Ok(assessed(c))
            }
            // A failed warm start fails again with its own error.
            _ => fit(dataset, request),
        }
    }

    /// [`calibrate`] of `dataset` through [`SharedWarmStart::fit`].
    pub fn calibrate(&self, dataset: &Dataset, request: &Request) -> Result<Calibration> {
        with_covariance(self.fit(dataset, request)?)
    }
}

#[cfg(test)]
mod tests;
