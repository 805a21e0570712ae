//! The covariance of the intrinsics against synthetic truth: the predicted
//! standard deviations and expected mapping error match the spread that new data
//! of the same kind actually produce; the covariance does not depend on the gauge;
//! the figures survive `calibration.json`.
use crate::common;
use deformcal::app::calibration_json::CalibrationJson;
use deformcal::model::metrics::{mapping_error, mapping_error_rot};
use deformcal::model::synthetic::{Generator, Preset};
use deformcal::solver::problem::SolverSettings;
use deformcal::{calibrate, LensModel, Method, Request};
use rayon::prelude::*;

/// Subsets per case: the RMS of 60 draws is within about 9 % (1σ) of its
/// expectation for a normal intrinsic, so the 1.4× bound is over 3.5σ away.
const SUBSETS: u64 = 60;
/// The presets' detector noise, given to the calibration as known.
const NOISE_PX: f64 = 0.15;

/// One case's observed / predicted ratios.
struct Ratios {
    mapping: f64,
    mapping_rot: f64,
    intrinsics: Vec<(&'static str, f64)>,
}

fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    (sum / n as f64).sqrt()
}

/// Calibrates `SUBSETS` independent 25-image datasets (a rigid board, or one that
/// bends as T2's do; no print error, so the method's model is the truth) with the
/// default pipeline (Cauchy loss, outlier rejection) and compares the RMS of the
/// errors to the truth with the RMS of their predicted standard deviations.
fn study(method: Method, model: LensModel, bend: f64) -> Ratios {
    let results: Vec<_> = (0..SUBSETS)
        .into_par_iter()
        .map(|seed| {
            let mut g = Generator::new(Preset::T2, Some(25), 9000 + seed).with_models(&[model]);
            g.bend_scale = bend;
            g.print_scale = 0.0;
            let (d, truth) = g.generate();
            let request = Request {
                method,
                settings: SolverSettings::default(),
                gauge: None,
            };
            let mut c = calibrate(&d, &request).unwrap();
            c.detector_noise_px = Some(NOISE_PX);
            let u = c.uncertainty().unwrap().remove(0);
            let (t, e) = (truth.intrinsics[0], c.state.intrinsics[0]);
            let (w, h) = (d.cameras[0].width, d.cameras[0].height);
            let errors: Vec<f64> = e
                .params()
                .iter()
                .zip(t.params())
                .map(|(a, b)| a - b)
                .collect();
            let observed = (mapping_error(&t, &e, w, h), mapping_error_rot(&t, &e, w, h));
            (u, errors, observed)
        })
        .collect();
    let ratio = |observed: f64, predicted: f64| observed / predicted;
    let names = model.param_names();
    Ratios {
        mapping: ratio(
            rms(results.iter().map(|r| r.2 .0)),
            rms(results.iter().map(|r| r.0.expected_mapping_error_px)),
        ),
        mapping_rot: ratio(
            rms(results.iter().map(|r| r.2 .1)),
            rms(results.iter().map(|r| r.0.expected_mapping_error_rot_px)),
        ),
        intrinsics: (0..names.len())
            .map(|i| {
                let predicted = rms(results.iter().map(|r| r.0.intrinsics_std[i].1));
                (
                    names[i],
                    ratio(rms(results.iter().map(|r| r.1[i])), predicted),
                )
            })
            .collect(),
    }
}

fn check(label: &str, r: &Ratios) {
    eprintln!(
        "{label}: observed/predicted mapping error {:.3}, rotation removed {:.3}",
        r.mapping, r.mapping_rot
    );
    let within = |x: f64| (1.0 / 1.4..=1.4).contains(&x);
    assert!(
        within(r.mapping),
        "{label}: mapping error ratio {}",
        r.mapping
    );
    assert!(
        within(r.mapping_rot),
        "{label}: rotated ratio {}",
        r.mapping_rot
    );
    for (name, x) in &r.intrinsics {
        eprintln!("{label}:   {name} observed/predicted σ {x:.3}");
        assert!(within(*x), "{label}: {name} ratio {x}");
    }
}

#[test]
fn standard_on_a_rigid_board_predicts_its_spread() {
    for model in [LensModel::Radial3, LensModel::Kb4] {
        let r = study(Method::Standard, model, 0.0);
        check(&format!("standard, rigid, {model}"), &r);
    }
}

#[test]
fn dynamic_on_a_bending_board_predicts_its_spread() {
    for model in [LensModel::Radial3, LensModel::Kb4] {
        let r = study(Method::Dynamic, model, 1.0);
        check(&format!("dynamic, bending, {model}"), &r);
    }
}

/// Calibrates with the given gauge corners and tolerances tight enough that any
/// gauge reaches the same optimum to round-off.
fn with_gauge(d: &deformcal::Dataset, method: Method, gauge: &[usize]) -> deformcal::Calibration {
    let settings = SolverSettings {
        function_tolerance: 1e-15,
        parameter_tolerance: 1e-15,
        gradient_tolerance: 1e-15,
        max_iterations: 500,
        ..SolverSettings::default()
    };
    let request = Request {
        method,
        settings,
        gauge: Some(gauge.to_vec()),
    };
    let c = calibrate(d, &request).unwrap();
    assert_eq!(c.gauge, gauge);
    c
}

#[test]
fn intrinsics_covariance_does_not_depend_on_the_gauge() {
    // A bending board with its print error, so that the corrections are not zero.
    let (d, _) = common::data(Preset::T2, 20, 31, 1.0, 1.0);
    let cols = d.target.cols;
    for (method, a, b) in [
        (
            Method::Static,
            vec![0, cols - 1, 168 - cols + 1],
            vec![14, 24, 150],
        ),
        (Method::Full, vec![0, cols - 1], vec![40, 100]),
    ] {
        let (ca, cb) = (with_gauge(&d, method, &a), with_gauge(&d, method, &b));
        let (sa, sb) = (
            &ca.covariance.as_ref().unwrap().cameras[0].unit,
            &cb.covariance.as_ref().unwrap().cameras[0].unit,
        );
        let mut worst: f64 = 0.0;
        for i in 0..sa.nrows() {
            for j in 0..sa.ncols() {
                let scale = (sa[(i, i)] * sa[(j, j)]).sqrt();
                worst = worst.max((sa[(i, j)] - sb[(i, j)]).abs() / scale);
            }
        }
        eprintln!("{method}: gauges {a:?} and {b:?} differ by {worst:.1e} (relative)");
        assert!(worst < 1e-6, "{method}: {worst}");
        // The corrections themselves do depend on the gauge: the test is not void.
        let moved = ca
            .state
            .corrections
            .iter()
            .zip(&cb.state.corrections)
            .map(|(p, q)| (p[0] - q[0]).abs())
            .fold(0.0, f64::max);
        assert!(moved > 1e-5, "{method}: {moved}");
    }
}

#[test]
fn without_the_gauge_the_covariance_is_refused() {
    let (d, _) = common::data(Preset::T2, 12, 32, 1.0, 1.0);
    for method in [Method::Static, Method::Full] {
        let mut c = common::run(&d, method, deformcal::solver::problem::Loss::Cauchy);
        assert!(c.covariance.is_ok());
        c.settings.fix_gauge = false;
        let e = deformcal::solver::uncertainty::unit_covariance(&c).unwrap_err();
        eprintln!("{method} without a gauge: {e}");
        assert!(
            matches!(
                e,
                deformcal::model::uncertainty::UncertaintyError::RankDeficient(_)
            ),
            "{e:?}"
        );
        c.covariance = Err(e);
        assert!(c.uncertainty().is_err());
    }
}

#[test]
fn board_json_takes_the_corrections_sigma_from_the_covariance_pass() {
    // The calibration's covariance pass gives the board's σ beside Σ_θ where
    // its normal matrix keeps the corrections (100 images) and none where it
    // eliminates them (25 images); board.json reads it, scaled by the noise,
    // and the pass run again on the finished calibration gives the same bits.
    // tests/covariance_dense.rs checks the σ against a dense H⁻¹GH⁻¹.
    use deformcal::app::board_json;
    use deformcal::solver::uncertainty::unit_covariance;
    for (images, kept) in [(25, false), (100, true)] {
        let (d, _) = common::data(Preset::T2, images, 34, 1.0, 1.0);
        let c = common::run(&d, Method::Static, deformcal::solver::problem::Loss::Cauchy);
        let cov = c.covariance.as_ref().unwrap();
        assert_eq!(cov.correction_std.is_some(), kept, "{images} images");
        assert_eq!(&unit_covariance(&c).unwrap(), cov, "{images} images");
        let written = board_json::of(&c).unwrap().correction_std;
        match (&cov.correction_std, written) {
            (None, None) => assert!(!kept),
            (Some(unit), Some(std)) => {
                let noise = c.assessment.trust.unwrap().noise_px;
                let expected: Vec<[f64; 3]> = unit.iter().map(|s| s.map(|v| v * noise)).collect();
                assert_eq!(std, expected);
                assert!(std.iter().flatten().any(|&v| v > 0.0));
            }
            (unit, written) => panic!("{images} images: {unit:?} against {written:?}"),
        }
    }
}

#[test]
fn every_lens_model_has_a_covariance() {
    // The rational model's k4–k6 nearly trade off against k1–k3: weak, not missing.
    for model in LensModel::ALL {
        let (d, _) = Generator::new(Preset::T2, Some(25), 33)
            .with_models(&[model])
            .generate();
        let c = common::run(
            &d,
            Method::Standard,
            deformcal::solver::problem::Loss::Cauchy,
        );
        let u = c.uncertainty().unwrap_or_else(|e| panic!("{model}: {e}"));
        eprintln!("{model}: {:?}", u[0]);
        let u = &u[0];
        assert_eq!(u.intrinsics_std.len(), model.num_params());
        assert!(u
            .intrinsics_std
            .iter()
            .all(|(_, s)| *s > 0.0 && s.is_finite()));
        assert!(u.expected_mapping_error_rot_px <= u.expected_mapping_error_px);
    }
}

#[test]
fn json_and_summary_carry_the_uncertainty() {
    let (mut d, _) = common::data(Preset::T2, 20, 34, 1.0, 0.0);
    d.cameras[0].fix = vec!["k3".into()];
    let mut c = common::run(
        &d,
        Method::Dynamic,
        deformcal::solver::problem::Loss::Cauchy,
    );
    c.detector_noise_px = Some(NOISE_PX);
    // The figures the files report, at that noise.
    c.assess();
    let u = c.uncertainty().unwrap().remove(0);
    // A held parameter has no σ and no share in the covariance.
    assert!(u.intrinsics_std.iter().all(|(n, _)| *n != "k3"));
    let json = CalibrationJson::from(&c);
    let text = serde_json::to_string_pretty(&json).unwrap();
    let back: CalibrationJson = serde_json::from_str(&text).unwrap();
    assert_eq!(back, json);
    let cu = back.cameras[0].uncertainty.as_ref().unwrap();
    assert_eq!(cu.expected_mapping_error_px, u.expected_mapping_error_px);
    assert_eq!(
        cu.expected_mapping_error_rot_px,
        u.expected_mapping_error_rot_px
    );
    let names: Vec<&str> = cu
        .intrinsics_std
        .0
        .iter()
        .map(|(n, _)| n.as_str())
        .collect();
    assert_eq!(names, ["fx", "fy", "cx", "cy", "k1", "k2"]);
    assert_eq!(cu.intrinsics_std.get("fx"), Some(u.intrinsics_std[0].1));
    assert!(back.uncertainty_note.is_none());
    // The keys of docs/conventions.md §5, in the file.
    let raw: serde_json::Value = serde_json::from_str(&text).unwrap();
    let unc = &raw["cameras"][0]["uncertainty"];
    assert!(unc["intrinsics_std"]["fy"].is_f64() && unc["expected_mapping_error_rot_px"].is_f64());
    let summary = deformcal::app::report::summary(&c);
    assert!(
        summary.contains(&format!(
            "fx {:.2} ± {:.2}",
            c.state.intrinsics[0].fx(),
            u.intrinsics_std[0].1
        )),
        "{summary}"
    );
    assert!(summary.contains("k3 0.00000 (held)"), "{summary}");
    assert!(summary.contains("expected mapping error"), "{summary}");
    // Without the covariance the file says why, and still reads back.
    c.covariance = Err(
        deformcal::model::uncertainty::UncertaintyError::RankDeficient("k1 of camera cam0".into()),
    );
    c.assess();
    let json = CalibrationJson::from(&c);
    assert!(json.cameras[0].uncertainty.is_none());
    let note = json.uncertainty_note.clone().unwrap();
    assert!(note.contains("k1 of camera cam0"), "{note}");
    let back: CalibrationJson =
        serde_json::from_str(&serde_json::to_string(&json).unwrap()).unwrap();
    assert_eq!(back, json);
}

#[test]
fn a_calibration_writes_its_uncertainty_map() {
    let (d, _) = common::data(Preset::T2, 15, 35, 1.0, 0.0);
    let c = common::run(
        &d,
        Method::Standard,
        deformcal::solver::problem::Loss::Cauchy,
    );
    let dir = tempfile::tempdir().unwrap();
    deformcal::app::output::write_calibration(dir.path(), &c).unwrap();
    let svg = std::fs::read_to_string(dir.path().join("uncertainty_cam0.svg")).unwrap();
    assert!(svg.contains("predicted 1-σ projection error"));
}

#[test]
fn protocol_rows_carry_the_prediction_and_the_report_compares_it() {
    use deformcal::app::config::{Config, ProtocolConfig};
    use deformcal::app::protocol::prepare;
    use deformcal::app::protocol_report::{protocol_csv, report_markdown, summarise};
    let text = "[data]\nsynthetic = \"t2\"\nimages = 60\n[calibration]\ndetector_noise_px = 0.15\n";
    let config = Config::parse(text, std::path::Path::new("test.toml")).unwrap();
    let protocol = ProtocolConfig {
        subsets: 3,
        images_per_subset: 20,
        seed: 7,
        methods: vec![Method::Standard, Method::Dynamic],
        auto: false,
    };
    let setup = prepare(&config, &protocol).unwrap();
    let rows = setup.run(None, &|| {});
    // The first subset's `dynamic` row holds what a calibration of it reports.
    let row = rows
        .iter()
        .find(|r| r.subset == 0 && r.method == Method::Dynamic)
        .unwrap();
    let data = setup.dataset.subset(&setup.subsets[0]);
    let request = Request {
        method: Method::Dynamic,
        settings: setup.settings.clone(),
        gauge: None,
    };
    let mut c = calibrate(&data, &request).unwrap();
    c.detector_noise_px = Some(0.15);
    let u = c.uncertainty().unwrap().remove(0);
    assert_eq!(
        row.cameras[0].expected_mapping_error_px,
        Some(u.expected_mapping_error_px)
    );
    assert_eq!(
        row.bias_ratio,
        Some(c.trust(Some(0.15)).unwrap().bias_ratio)
    );
    let summary = summarise(&setup.header, &rows);
    for m in ["standard", "dynamic"] {
        let metrics = &summary.methods[m].metrics;
        assert_eq!(metrics["expected_mapping_error_px"].n, 3, "{m}");
        assert_eq!(metrics["bias_ratio"].n, 3, "{m}");
    }
    let csv = String::from_utf8(protocol_csv(&setup.header, &rows).unwrap()).unwrap();
    let head = csv.lines().next().unwrap();
    assert!(
        head.contains(",bias_ratio,") && head.contains(",expected_mapping_error_px,"),
        "{head}"
    );
    let report = report_markdown(&summary, &rows, "");
    assert!(
        report.contains("### Predicted and observed spread"),
        "{report}"
    );
    assert!(report.contains("| dynamic | "), "{report}");
}

#[test]
fn direct_jacobian_equals_ceres_evaluate() {
    // A stereo rig (rig block), bends (frame block), print error (corner block),
    // a held lens parameter (a subset manifold) and non-unit weights.
    let (mut d, _) = Generator::new(Preset::Stereo, Some(8), 36).generate();
    d.cameras[1].fix = vec!["k2".into()];
    for (i, o) in d.observations.iter_mut().enumerate() {
        o.weight = if i % 5 == 0 { 0.5 } else { 1.0 };
    }
    for method in Method::ALL {
        let c = common::run(&d, method, deformcal::solver::problem::Loss::Cauchy);
        let p = c.problem();
        let ceres = p.evaluate(&c.state, &c.settings, true).unwrap();
        let direct = p.jacobian(&c.state, &c.settings).unwrap();
        assert_eq!(direct.jacobian_rows, ceres.jacobian_rows, "{method}");
        assert_eq!(
            direct.jacobian_col_param, ceres.jacobian_col_param,
            "{method}"
        );
        assert_eq!(direct.residuals, ceres.residuals, "{method}");
        for r in 0..ceres.jacobian_rows {
            let row = |e: &deformcal::solver::problem::Evaluation| {
                let (lo, hi) = (
                    e.jacobian_row_ptr[r] as usize,
                    e.jacobian_row_ptr[r + 1] as usize,
                );
                let mut v: Vec<(u32, f64)> = (lo..hi)
                    .map(|i| (e.jacobian_col_idx[i], e.jacobian_values[i]))
                    .filter(|x| x.1 != 0.0)
                    .collect();
                v.sort_by_key(|x| x.0);
                v
            };
            assert_eq!(row(&direct), row(&ceres), "{method} row {r}");
        }
    }
}

#[test]
fn the_priors_estimated_together_are_those_estimated_one_by_one() {
    // `estimate_all` evaluates the Jacobian once for both priors: its σ are each
    // prior's own estimate, to the bit, and they are real estimates.
    use deformcal::solver::auto_prior::{estimate_bend_sigma, estimate_static_sigma, AutoPrior};
    let (data, _) = Generator::new(Preset::T2, Some(25), 7).generate();
    let settings = SolverSettings::default();
    let c = common::run_with(&data, Method::Full, settings.clone());
    let problem = c.problem();
    let noise = 0.15;
    let together = AutoPrior::estimate_all(&AutoPrior::ALL, &problem, &c.state, &settings, noise);
    let alone = vec![
        estimate_static_sigma(&problem, &c.state, &settings, noise),
        estimate_bend_sigma(&problem, &c.state, &settings, noise),
    ];
    assert_eq!(together, alone);
    assert!(together
        .iter()
        .all(|e| e.is_some_and(|e| e.sigma > 0.0 && e.values > 0)));
    assert_eq!(
        AutoPrior::estimate_all(&[], &problem, &c.state, &settings, noise),
        vec![]
    );
}
