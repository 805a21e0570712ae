//! `method = "auto"` against synthetic truth: it picks a deformation model where
//! the board bends, keeps `standard` (or something no worse) where it does not,
//! and never returns a model whose cross-validated error is worse than
//! `standard`'s by more than its noise.
use crate::common;
use common::*;
use deformcal::model::metrics::mapping_error;
use deformcal::model::selection::{AutoSettings, Selection};
use deformcal::model::synthetic::{Preset, Truth};
use deformcal::solver::calibrate::MIN_IMAGES;
use deformcal::solver::problem::SolverSettings;
use deformcal::solver::select::calibrate_auto;
use deformcal::{Calibration, Dataset, Method, Request};
use rayon::prelude::*;

/// `auto` as a config without `[calibration]` keys runs it (board priors estimated).
fn auto(d: &Dataset) -> Calibration {
    let request = Request {
        method: Method::Standard,
        settings: SolverSettings::recommended(),
        gauge: None,
    };
    let settings = AutoSettings {
        detector_noise_px: Some(0.15),
        ..AutoSettings::default()
    };
    calibrate_auto(d, &request, &settings, &|| {}).expect("auto calibrates")
}

fn candidate(sel: &Selection, m: Method) -> &deformcal::model::selection::Candidate {
    sel.candidates.iter().find(|c| c.method == m).unwrap()
}

/// The chosen method is never worse than `standard` by more than its noise.
fn no_worse_than_standard(name: &str, sel: &Selection) {
    let chosen = candidate(sel, sel.chosen);
    let standard = candidate(sel, Method::Standard);
    let (c, s) = (chosen.cv_rmse_px.unwrap(), standard.cv_rmse_px.unwrap());
    let noise = standard
        .cv_noise_px
        .unwrap()
        .max(chosen.cv_noise_px.unwrap());
    assert!(
        c <= s + noise,
        "{name}: chosen {c} vs standard {s} ± {noise}"
    );
}

fn truth_error(c: &Calibration, truth: &Truth) -> f64 {
    let cam = &c.dataset.cameras[0];
    mapping_error(
        &truth.intrinsics[0],
        &c.state.intrinsics[0],
        cam.width,
        cam.height,
    )
}

#[test]
fn auto_models_the_bend_of_the_bending_presets() {
    for (preset, seed) in [(Preset::T1, 3), (Preset::T2, 4), (Preset::T3, 5)] {
        let name = preset.name();
        let (d, truth) = data(preset, 40, seed, 1.0, 1.0);
        let c = auto(&d);
        let sel = c.selection.clone().expect("auto records its choice");
        eprintln!("{name}: {} — {}", sel.chosen, sel.reason);
        for k in &sel.candidates {
            eprintln!(
                "  {:8} cv {:.4} ± {:.4} px, train {:.4}, bias {:.2}",
                k.method,
                k.cv_rmse_px.unwrap(),
                k.cv_noise_px.unwrap(),
                k.rmse_px.unwrap(),
                k.bias_ratio.unwrap()
            );
        }
        assert!(
            matches!(sel.chosen, Method::Dynamic | Method::Full),
            "{name}: chose {}",
            sel.chosen
        );
        assert_eq!(c.method, sel.chosen, "{name}: the result is the chosen fit");
        no_worse_than_standard(name, &sel);
        // What auto delivers is closer to the true lens than `standard` is.
        let standard = run(
            &d,
            Method::Standard,
            deformcal::solver::problem::Loss::Cauchy,
        );
        let (e_auto, e_std) = (truth_error(&c, &truth), truth_error(&standard, &truth));
        eprintln!("  mapping error to truth: auto {e_auto:.3} px, standard {e_std:.3} px");
        assert!(e_auto < e_std, "{name}: {e_auto} vs {e_std}");
        // The shift it reports is the one between the two fits.
        let shift = mapping_error(
            &standard.state.intrinsics[0],
            &c.state.intrinsics[0],
            1936,
            1216,
        );
        assert!((sel.projection_shift_px - shift).abs() < 1e-6 * shift.max(1.0));
    }
}

#[test]
fn auto_keeps_standard_on_rigid_and_stiff_boards() {
    // A rigid, perfectly printed board, and the stiff T4 as generated.
    let cases = [
        ("rigid", data(Preset::T2, 40, 6, 0.0, 0.0).0),
        ("t4", data(Preset::T4, 40, 7, 1.0, 1.0).0),
    ];
    for (name, d) in cases {
        let c = auto(&d);
        let sel = c.selection.clone().unwrap();
        eprintln!("{name}: {} — {}", sel.chosen, sel.reason);
        no_worse_than_standard(name, &sel);
        if name == "rigid" {
            assert_eq!(sel.chosen, Method::Standard, "{name}: {}", sel.reason);
            let summary = deformcal::app::report::summary(&c);
            assert!(
                summary.contains("verdict: no bending detected above noise: `standard`"),
                "{summary}"
            );
        }
    }
}

#[test]
fn auto_is_written_to_calibration_json_and_read_back() {
    let (d, _) = data(Preset::T1, 20, 8, 1.0, 1.0);
    let c = auto(&d);
    let json = deformcal::app::calibration_json::CalibrationJson::from(&c);
    assert_eq!(json.method, c.method.name());
    let sel = json.auto.clone().unwrap();
    assert_eq!(sel.chosen, c.method);
    assert_eq!(sel.candidates.len(), 3);
    let text = serde_json::to_string(&json).unwrap();
    let back: deformcal::app::calibration_json::CalibrationJson =
        serde_json::from_str(&text).unwrap();
    assert_eq!(back.auto, json.auto);
    assert!(text.contains("\"cv_rmse_px\""), "{text}");
}

#[test]
fn auto_calibrates_small_captures() {
    // Eight photos: too few for five folds of two, so each is left out in turn.
    let request = Request {
        method: Method::Standard,
        settings: SolverSettings::recommended(),
        gauge: None,
    };
    let (d, truth) = data(Preset::T2, 8, 9, 1.0, 1.0);
    let c = calibrate_auto(&d, &request, &AutoSettings::default(), &|| {}).expect("8 photos");
    let sel = c.selection.clone().unwrap();
    assert_eq!(sel.folds, 8, "leave-one-out: {}", sel.reason);
    assert_eq!(sel.candidates.len(), 3);
    assert!(sel.candidates.iter().all(|k| k.cv_rmse_px.is_some()));
    assert!(truth_error(&c, &truth) < 3.0, "{}", truth_error(&c, &truth));
    // Two folds of five photos would train on two: left out one by one instead.
    let (d, _) = data(Preset::T2, 5, 10, 1.0, 1.0);
    let two = AutoSettings {
        folds: 2,
        ..AutoSettings::default()
    };
    let c = calibrate_auto(&d, &request, &two, &|| {}).expect("5 photos, 2 folds");
    let sel = c.selection.clone().unwrap();
    assert_eq!(sel.folds, 5, "{}", sel.reason);
    assert!(sel.candidates.iter().all(|k| k.cv_rmse_px.is_some()));
    // Three photos calibrate `standard` but leave nothing to cross-validate with.
    let (d, truth) = data(Preset::T2, 3, 9, 1.0, 1.0);
    let c = calibrate_auto(&d, &request, &AutoSettings::default(), &|| {}).expect("3 photos");
    assert_eq!(c.method, Method::Standard);
    let sel = c.selection.clone().unwrap();
    assert!(sel.reason.contains("too few"), "{}", sel.reason);
    let standard = run_with(&d, Method::Standard, SolverSettings::recommended());
    assert_eq!(c.state.intrinsics, standard.state.intrinsics);
    assert!(truth_error(&c, &truth).is_finite());
}

/// Every capture that `standard` calibrates (3 photos and up) gets an answer from
/// `auto`: below the default folds' ten photos each photo is left out in turn, and
/// with too few to leave one out it keeps `standard`.
#[test]
fn auto_answers_every_capture_from_three_to_nine_photos() {
    let request = Request {
        method: Method::Standard,
        settings: SolverSettings::recommended(),
        gauge: None,
    };
    for n in 3..=9 {
        let (d, truth) = data(Preset::T2, n, 20 + n as u64, 1.0, 1.0);
        let standard = run_with(&d, Method::Standard, SolverSettings::recommended());
        let c = calibrate_auto(&d, &request, &AutoSettings::default(), &|| {})
            .unwrap_or_else(|e| panic!("{n} photos: {e}"));
        let sel = c.selection.clone().unwrap();
        if n > MIN_IMAGES {
            assert_eq!(sel.folds, n, "{n} photos, leave-one-out: {}", sel.reason);
            assert!(sel.candidates.iter().all(|k| k.cv_rmse_px.is_some()));
        } else {
            assert_eq!(c.method, Method::Standard, "{n} photos");
            assert_eq!(c.state.intrinsics, standard.state.intrinsics);
        }
        // Near the true lens (3 px: the bound of the eight photos above).
        let (e, es) = (truth_error(&c, &truth), truth_error(&standard, &truth));
        eprintln!(
            "{n} photos: auto chose {} ({e:.3} px), standard {es:.3} px",
            c.method
        );
        assert!(e.is_finite() && e < 3.0, "{n} photos: {e} px");
    }
}

/// A slice of the evaluation grid (`cargo bench --bench auto_grid` runs all of
/// it), on seeds used neither to fit the rule's threshold (1-3) nor by the grid
/// (100, 200): `auto` with the default settings stays within the targets: at
/// most 10 % worse than `standard` on a rigid board, never `standard` where
/// `standard` is twice as far from the true lens as the best candidate, median
/// regret at most 1.05; and regret at most 1.3 on the 25-photo cases. Small
/// captures of 8 and 12 photos (left out one at a time) of every kind of board
/// are held to all but the last: on the grid no rule, not even one that knows
/// the kind of board, keeps every case's regret under 1.3 (docs/benchmarks.md).
#[test]
fn auto_meets_its_targets_on_a_slice_of_the_grid() {
    use common::auto_grid::{self, Board, Case};
    use deformcal::model::lens::LensModel;
    let mut cases = Vec::new();
    for (board, print_mm) in [
        (Board::Rigid, 0.0),
        (Board::Paraboloid(3.0), 0.0),
        (Board::Plate(2.0), 0.2),
    ] {
        for (model, seed) in [(LensModel::OpenCv5, 11), (LensModel::Kb4, 12)] {
            cases.push(Case {
                board,
                print_mm,
                frames: 25,
                noise_px: 0.2,
                model,
                seed,
            });
        }
    }
    for (board, print_mm) in [
        (Board::Rigid, 0.0),
        (Board::Paraboloid(2.0), 0.0),
        (Board::Twist(2.0), 0.0),
        (Board::Plate(2.0), 0.2),
    ] {
        for (frames, model, noise_px, seed) in [
            (8, LensModel::Radial3, 0.1, 7),
            (12, LensModel::OpenCv5, 0.3, 8),
        ] {
            cases.push(Case {
                board,
                print_mm,
                frames,
                noise_px,
                model,
                seed,
            });
        }
    }
    let outcomes: Vec<_> = cases.into_par_iter().map(auto_grid::run).collect();
    eprint!("{}", auto_grid::table(&outcomes));
    for o in &outcomes {
        eprintln!(
            "{} {} frames {:?}: chose {} ({:.3} px; standard {:.3}, dynamic {:.3}, full {:.3}) — {}",
            o.case.board.label(),
            o.case.frames,
            o.case.model,
            o.chosen,
            o.error_of(o.chosen),
            o.error_of(Method::Standard),
            o.error_of(Method::Dynamic),
            o.error_of(Method::Full),
            o.reason
        );
    }
    let small = |o: &auto_grid::Outcome| o.case.frames < 25;
    let (small_captures, at_25): (Vec<_>, Vec<_>) = outcomes.iter().cloned().partition(small);
    let failures = auto_grid::failures(&at_25);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    let failures: Vec<String> = auto_grid::failures(&small_captures)
        .into_iter()
        .filter(|f| !f.starts_with("regret"))
        .collect();
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    let mut regret: Vec<f64> = outcomes.iter().map(|o| o.regret()).collect();
    regret.sort_by(f64::total_cmp);
    assert!(regret[regret.len() / 2] <= 1.05, "{regret:?}");
}

/// The report says why `auto` chose, and that rejection was off when it was.
#[test]
fn the_report_gives_autos_reason_and_says_when_rejection_is_off() {
    use deformcal::app::html_report::calibration::calibration_page;
    let (d, _) = data(Preset::T2, 12, 14, 1.0, 1.0);
    let request = Request {
        method: Method::Standard,
        settings: SolverSettings {
            outlier_k: 0.0,
            ..SolverSettings::recommended()
        },
        gauge: None,
    };
    let c = calibrate_auto(&d, &request, &AutoSettings::default(), &|| {}).unwrap();
    let reason = c.selection.clone().unwrap().reason;
    let page = calibration_page(&c, &Default::default(), &[]).unwrap();
    let first_words: String = reason.chars().take(20).collect();
    assert!(
        page.contains("chosen by <code>auto</code>: "),
        "no auto verdict"
    );
    assert!(page.contains(&first_words), "{first_words}");
    assert!(page.contains("Outlier rejection is off"));
    assert!(!page.contains("beyond 0σ"));
}
