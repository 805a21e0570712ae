//! `method = "auto"`: calibrates every candidate method on all the data and in
//! k-fold cross-validation over frames, then keeps the method the held-out frames
//! support (the rule is `model::selection::choose`). Each held frame is refitted
//! with the trained camera (intrinsics, rig, static correction) held and the
//! frame's own unknowns free, as the method models them: its pose, and its bend
//! where the method has one. Judging every candidate on an unbent board (the
//! protocol's test error) charges a real bend to the method that models it, and
//! `auto` kept `standard` on bending boards; the bend's extra unknowns are paid
//! for by scoring each frame per residual degree of freedom, so a rigid board's
//! frames score alike under every candidate.
use crate::error::{Error, Result};
use crate::model::board::{bend_terms, BoardPriors};
use crate::model::board::{Method, Paraboloid};
use crate::model::dataset::Dataset;
use crate::model::lens::Intrinsics;
use crate::model::metrics::{mapping_error, mapping_error_rot};
use crate::model::selection::{self, AutoSettings, Candidate, HeldOut, Selection};
use crate::model::state::State;
use crate::solver::calibrate::{Calibration, Request, SharedWarmStart, MIN_IMAGES};
use crate::solver::problem::{Hold, Loss, Problem, SolverSettings};
use rayon::prelude::*;

/// A held-out frame with fewer observations than this is scored under no
/// candidate: its refitted bend would have almost no residual left to judge.
const MIN_SCORED_OBSERVATIONS: usize = 12;

/// The candidates in the order the rule needs: fewest free parameters first.
fn by_complexity(fits: &[(Method, Result<Calibration>)]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..fits.len()).collect();
    order.sort_by_key(|&i| {
        let p = fits[i].1.as_ref().map(|c| c.free_parameters()).ok();
        (p.is_none(), p.unwrap_or(usize::MAX), fits[i].0)
    });
    order
}

/// Checks `auto`'s settings before any solve (any number of images will do).
pub fn check(auto: &AutoSettings) -> Result<()> {
    if !auto.candidates.contains(&Method::Standard) {
        return Err(Error::Invalid(
            "method = \"auto\" needs `standard` among its candidates (the baseline)".into(),
        ));
    }
    if auto.folds < 2 {
        return Err(Error::Invalid(format!(
            "calibration.cv_folds must be at least 2 (got {})",
            auto.folds
        )));
    }
    Ok(())
}

/// The folds `auto` uses on `frames` frames: [`AutoSettings::folds_for`], and
/// leave-one-out where a training set (all frames but one fold) would be too
/// small a calibration of its own.
pub fn fold_count(frames: usize, auto: &AutoSettings) -> usize {
    let k = auto.folds_for(frames);
    if k >= 2 && frames - frames.div_ceil(k) >= MIN_IMAGES {
        k
    } else {
        frames
    }
}

/// Whether `frames` frames are enough to cross-validate: every training set
/// (all frames but one) must be a calibration of its own.
fn can_cross_validate(frames: usize, auto: &AutoSettings) -> bool {
    let folds = fold_count(frames, auto);
    folds >= 2 && frames - frames.div_ceil(folds) >= MIN_IMAGES
}

/// Calibrates with every candidate (all data) and picks one by cross-validation;
/// `tick` is called once per finished solve (candidates × (folds + 1)).
pub fn calibrate_auto(
    dataset: &Dataset,
    request: &Request,
    auto: &AutoSettings,
    tick: &(dyn Fn() + Sync),
) -> Result<Calibration> {
    // The deformation methods start from the same `standard` solve: computed once.
    calibrate_auto_sharing(dataset, request, auto, &SharedWarmStart::default(), tick)
}

/// [`calibrate_auto`] whose candidates on all the data take their warm start
/// from `warm`, which other calibrations of the same data may share (the
/// protocol's methods on one subset).
pub fn calibrate_auto_sharing(
    dataset: &Dataset,
    request: &Request,
    auto: &AutoSettings,
    warm: &SharedWarmStart,
    tick: &(dyn Fn() + Sync),
) -> Result<Calibration> {
    trial(dataset, request, auto, warm, tick).map(|t| t.result)
}

/// Everything `auto` computed: the result, and every candidate's fit to all the
/// data with its held-out record, for a study of the rule (the evaluation grid).
#[derive(Debug)]
pub struct Trial {
    /// What [`calibrate_auto`] returns.
    pub result: Calibration,
    /// Every candidate's fit to all the data, in `auto.candidates`' order; empty
    /// where the data were too few to cross-validate.
    pub fits: Vec<(Method, Result<Calibration>)>,
    /// Each fit's held-out record (as `fits`); `None` where a fold failed.
    pub held: Vec<Option<HeldOut>>,
}

/// [`calibrate_auto_sharing`], keeping every candidate's fit and held-out record.
pub fn trial(
    dataset: &Dataset,
    request: &Request,
    auto: &AutoSettings,
    warm: &SharedWarmStart,
    tick: &(dyn Fn() + Sync),
) -> Result<Trial> {
    check(auto)?;
    let rigid = |why: String| {
        standard_because(dataset, request, auto, warm, &why).map(|result| Trial {
            result,
            fits: Vec::new(),
            held: Vec::new(),
        })
    };
    if !can_cross_validate(dataset.num_frames(), auto) {
        return rigid(too_few(dataset.num_frames()));
    }
    let mut fits = fit_candidates(dataset, request, auto, warm, tick);
    let at = fits
        .iter()
        .position(|(m, _)| *m == Method::Standard)
        .expect("checked: standard is a candidate");
    // `standard` failing is the data's fault, in its own words.
    if fits[at].1.is_err() {
        return Err(fits.swap_remove(at).1.expect_err("checked: an error"));
    }
    let standard = fits[at].1.as_ref().expect("checked: a calibration");
    // Every candidate is cross-validated on the same data: what `standard` kept.
    let cv = &standard.dataset;
    if !can_cross_validate(cv.num_frames(), auto) {
        return rigid(too_few(cv.num_frames()));
    }
    let k = fold_count(cv.num_frames(), auto);
    let folds = selection::folds(cv.num_frames(), k, auto.seed);
    let held = cross_validate(cv, standard, request, auto, &folds, tick);
    let scored = |h: &Option<HeldOut>| h.as_ref().map_or(0, |h| h.points.iter().sum::<usize>());
    if scored(&held[at]) == 0 {
        return rigid(format!(
            "no left-out photo has {MIN_SCORED_OBSERVATIONS} corners or more to judge a bend by, \
             so the board is taken as rigid (`standard`)"
        ));
    }
    let selection = select(&fits, &held, at, k, auto)?;
    let mut result = fits
        .iter()
        .find(|(m, _)| *m == selection.chosen)
        .and_then(|(_, r)| r.as_ref().ok())
        .expect("`select` chooses a candidate with a fit")
        .clone();
    result.selection = Some(selection);
    Ok(Trial { result, fits, held })
}

/// Every candidate calibrated on all the data (in parallel).
fn fit_candidates(
    dataset: &Dataset,
    request: &Request,
    auto: &AutoSettings,
    warm: &SharedWarmStart,
    tick: &(dyn Fn() + Sync),
) -> Vec<(Method, Result<Calibration>)> {
    auto.candidates
        .par_iter()
        .map(|&m| {
            let r = warm.calibrate(
                dataset,
                &Request {
                    method: m,
                    ..request.clone()
                },
            );
            tick();
            (m, r)
        })
        .collect()
}

/// The rule applied to the candidates' fits and held-out records (`standard` is
/// `fits[at]`), with the figures `calibration.json` records.
fn select(
    fits: &[(Method, Result<Calibration>)],
    held: &[Option<HeldOut>],
    at: usize,
    k: usize,
    auto: &AutoSettings,
) -> Result<Selection> {
    let order = by_complexity(fits);
    let mut entries: Vec<(Candidate, Option<HeldOut>)> = order
        .iter()
        .map(|&i| summarise(&fits[i], held[i].clone()))
        .collect();
    let (chosen_at, reason) = selection::choose(&mut entries)
        .ok_or_else(|| Error::Degenerate("no candidate method could be cross-validated".into()))?;
    let candidates: Vec<Candidate> = entries.into_iter().map(|(c, _)| c).collect();
    let (chosen, reason) = match selection::choose_bend_order(&candidates) {
        Some((m, why)) => (m, format!("{why}; cross-validation alone: {reason}")),
        None => (candidates[chosen_at].method, reason),
    };
    let standard = fits[at].1.as_ref().expect("checked: a calibration");
    let result = fits
        .iter()
        .find(|(m, _)| *m == chosen)
        .and_then(|(_, r)| r.as_ref().ok())
        .ok_or_else(|| Error::Degenerate(format!("the chosen method `{chosen}` has no fit")))?;
    let (shift, shift_rot) = projection_shift(&standard.state.intrinsics, result);
    Ok(Selection {
        chosen,
        folds: k,
        seed: auto.seed,
        candidates,
        reason,
        projection_shift_px: shift,
        projection_shift_rot_px: shift_rot,
    })
}

/// Why `frames` photos cannot be cross-validated.
fn too_few(frames: usize) -> String {
    format!(
        "{frames} photos are too few to tell a bending board from a rigid one (leaving one out \
         needs {} photos), so the board is taken as rigid (`standard`)",
        MIN_IMAGES + 1
    )
}

/// `auto` where the data cannot tell the candidates apart: `standard`, saying why.
fn standard_because(
    dataset: &Dataset,
    request: &Request,
    auto: &AutoSettings,
    warm: &SharedWarmStart,
    reason: &str,
) -> Result<Calibration> {
    let mut c = warm.calibrate(
        dataset,
        &Request {
            method: Method::Standard,
            ..request.clone()
        },
    )?;
    c.selection = Some(Selection {
        chosen: Method::Standard,
        folds: 0,
        seed: auto.seed,
        candidates: Vec::new(),
        reason: reason.to_string(),
        projection_shift_px: 0.0,
        projection_shift_rot_px: 0.0,
    });
    Ok(c)
}

/// Largest mapping error between `standard`'s intrinsics and the result's over
/// the cameras, plain and with the virtual rotation profiled out, px.
fn projection_shift(standard: &[Intrinsics], result: &Calibration) -> (f64, f64) {
    let cameras = result.dataset.cameras.iter();
    cameras
        .zip(standard.iter().zip(&result.state.intrinsics))
        .map(|(cam, (a, b))| {
            (
                mapping_error(a, b, cam.width, cam.height),
                mapping_error_rot(a, b, cam.width, cam.height),
            )
        })
        .fold((0.0, 0.0), |m, x| (m.0.max(x.0), m.1.max(x.1)))
}

/// A candidate's figures from its fit to all data, with its held-out error.
fn summarise(
    fit: &(Method, Result<Calibration>),
    held: Option<HeldOut>,
) -> (Candidate, Option<HeldOut>) {
    let (method, result) = fit;
    let mut c = Candidate {
        method: *method,
        cv_rmse_px: None,
        cv_noise_px: None,
        rmse_px: None,
        g_aic: None,
        bias_ratio: None,
        parameters: 0,
        max_bend_m: None,
        failed: None,
    };
    match result {
        Ok(fit) => {
            let trust = fit.trust(fit.detector_noise_px);
            c.rmse_px = Some(fit.rmse_px);
            c.g_aic = trust.map(|t| t.g_aic);
            c.bias_ratio = trust.map(|t| t.bias_ratio);
            c.parameters = fit.free_parameters();
            c.max_bend_m = method.has_paraboloid().then(|| fit.max_out_of_plane());
        }
        Err(e) => c.failed = Some(format!("fit to all data: {e}")),
    }
    if result.is_ok() && held.is_none() {
        c.failed = Some("a cross-validation fold failed".into());
    }
    let held = if result.is_ok() { held } else { None };
    (c, held)
}

/// Every candidate's held-out error over all folds; `None` where a fold failed.
fn cross_validate(
    cv: &Dataset,
    standard: &Calibration,
    request: &Request,
    auto: &AutoSettings,
    folds: &[Vec<usize>],
    tick: &(dyn Fn() + Sync),
) -> Vec<Option<HeldOut>> {
    // Folds are clean data: outliers were rejected on all of it already.
    let settings = SolverSettings {
        outlier_k: 0.0,
        ..request.settings.clone()
    };
    let tasks: Vec<(usize, usize)> = (0..auto.candidates.len())
        .flat_map(|c| (0..folds.len()).map(move |f| (c, f)))
        .collect();
    // One warm start per fold's training data, shared by its candidates.
    let warm: Vec<SharedWarmStart> = folds.iter().map(|_| SharedWarmStart::default()).collect();
    let results: Vec<Option<(Vec<usize>, HeldOut)>> = tasks
        .par_iter()
        .map(|&(c, f)| {
            let r = fold_error(
                cv,
                standard,
                auto.candidates[c],
                &settings,
                request,
                &folds[f],
                &warm[f],
            );
            tick();
            r.ok().map(|h| (folds[f].clone(), h))
        })
        .collect();
    (0..auto.candidates.len())
        .map(|c| {
            let mut total = HeldOut::new(cv.num_frames());
            for (t, r) in tasks.iter().zip(&results) {
                if t.0 != c {
                    continue;
                }
                let (frames, h) = r.as_ref()?;
                for (i, &j) in frames.iter().enumerate() {
                    total.squared[j] = h.squared[i];
                    total.points[j] = h.points[i];
                }
            }
            Some(total)
        })
        .collect()
}

/// Trains `method` on all frames but `held` (from the fold's shared warm
/// start) and measures it on `held` (indexed like `held`).
fn fold_error(
    cv: &Dataset,
    standard: &Calibration,
    method: Method,
    settings: &SolverSettings,
    request: &Request,
    held: &[usize],
    warm: &SharedWarmStart,
) -> Result<HeldOut> {
    let train: Vec<usize> = (0..cv.num_frames()).filter(|j| !held.contains(j)).collect();
    let trained = warm.fit(
        &cv.subset(&train),
        &Request {
            method,
            settings: settings.clone(),
            ..request.clone()
        },
    )?;
    held_out_error(&trained, &cv.subset(held), held, standard, settings)
}

/// The held frames refitted with the trained camera held: each frame's pose
/// free, and its bend where the method has one (no prior on it: the frame's
/// score pays for its unknowns instead). Each frame's sum of squares is scaled
/// by 2n / (2n − p) for its 2n residuals and p unknowns, the expectation's
/// correction, so that every candidate's score estimates the same noise where
/// the extra unknowns only fit noise.
fn held_out_error(
    trained: &Calibration,
    test: &Dataset,
    held: &[usize],
    standard: &Calibration,
    settings: &SolverSettings,
) -> Result<HeldOut> {
    let settings = SolverSettings {
        loss: Loss::None,
        ..settings.clone()
    };
    let frames = held.len();
    let mut state = State {
        intrinsics: trained.state.intrinsics.clone(),
        camera_poses: trained.state.camera_poses.clone(),
        // `standard` saw every frame: its poses start the refit.
        frame_poses: held
            .iter()
            .map(|&j| standard.state.frame_poses[j])
            .collect(),
        deformations: vec![Paraboloid::default(); frames],
        higher_bends: vec![Default::default(); frames],
        corrections: trained.state.corrections.clone(),
    };
    let with_correction = trained.method.has_correction();
    let with_bend = trained.method.has_paraboloid();
    let method = match (with_correction, with_bend) {
        (_, true) => trained.method,
        (true, false) => Method::Static,
        (false, false) => Method::Standard,
    };
    let settings = SolverSettings {
        board: BoardPriors {
            geometry: settings.board.geometry.clone(),
            ..BoardPriors::default()
        },
        ..settings
    };
    let problem = Problem {
        dataset: test,
        method,
        gauge: if with_correction {
            trained.gauge.clone()
        } else {
            Vec::new()
        },
        frozen: trained.frozen.clone(),
        hold: Hold {
            intrinsics: true,
            camera_poses: true,
            corrections: true,
            deformations: !with_bend,
        },
    };
    let report = problem.solve(&mut state, &settings)?;
    let mut out = HeldOut::new(frames);
    for (o, r) in test.observations.iter().zip(report.residuals.chunks(2)) {
        out.squared[o.frame] += r[0] * r[0] + r[1] * r[1];
        out.points[o.frame] += 1;
    }
    let unknowns = 6 + if with_bend {
        bend_terms(trained.method.bend_order())
    } else {
        0
    };
    for (sq, n) in out.squared.iter_mut().zip(out.points.iter_mut()) {
        if *n < MIN_SCORED_OBSERVATIONS {
            (*sq, *n) = (0.0, 0);
        } else {
            *sq *= (2 * *n) as f64 / (2 * *n - unknowns) as f64;
        }
    }
    Ok(out)
}
