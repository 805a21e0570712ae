//! `deformcal compare`: the mapping error between two calibrations beside the
//! difference their uncertainties predict. Two independent calibrations of the
//! same rigid-board camera differ by about what the noise explains; `standard`
//! against `dynamic` on bending boards differs by far more.
mod common;
use common::*;
use deformcal::app::calibration_json::CalibrationJson;
use deformcal::app::compare::{compare, REAL_DIFFERENCE_FACTOR};
use deformcal::model::synthetic::Preset;
use deformcal::solver::problem::Loss;
use deformcal::Method;
use std::process::Command;

fn json(preset: Preset, seed: u64, bend: f64, method: Method) -> CalibrationJson {
    let (d, _) = data(preset, 30, seed, bend, 0.0);
    let mut c = run(&d, method, Loss::Cauchy);
    c.detector_noise_px = Some(0.15);
    CalibrationJson::from(&c)
}

#[test]
fn independent_calibrations_differ_by_their_noise_and_a_bias_by_more() {
    // Four pairs of independent rigid-board calibrations: on average their
    // difference is what the two uncertainties predict.
    let ratios: Vec<f64> = (0..4)
        .map(|i| {
            let a = json(Preset::T2, 20 + 2 * i, 0.0, Method::Standard);
            let b = json(Preset::T2, 21 + 2 * i, 0.0, Method::Standard);
            let d = &compare(&a, &b).unwrap()[0];
            eprintln!(
                "rigid pair {i}: {:.4} px rot., {}",
                d.mapping_error_rot_px,
                d.verdict()
            );
            d.ratio().expect("both files carry their uncertainty")
        })
        .collect();
    let mean = ratios.iter().sum::<f64>() / ratios.len() as f64;
    assert!((0.5..=REAL_DIFFERENCE_FACTOR).contains(&mean), "{ratios:?}");
    // On T3's strongly bending boards `standard` is biased: far more than noise
    // from `dynamic` (on the same data, so their own noise mostly cancels).
    let a = json(Preset::T3, 30, 1.0, Method::Standard);
    let b = json(Preset::T3, 30, 1.0, Method::Dynamic);
    let d = &compare(&a, &b).unwrap()[0];
    eprintln!(
        "standard vs dynamic: {:.4} px rot., {}",
        d.mapping_error_rot_px,
        d.verdict()
    );
    assert!(d.ratio().unwrap() > 3.0 * REAL_DIFFERENCE_FACTOR, "{d:?}");
    assert!(
        d.verdict().starts_with("a real difference"),
        "{}",
        d.verdict()
    );
}

#[test]
fn compare_on_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let a = json(Preset::T3, 31, 1.0, Method::Standard);
    let b = json(Preset::T3, 31, 1.0, Method::Dynamic);
    let (pa, pb) = (dir.path().join("a.json"), dir.path().join("b.json"));
    std::fs::write(&pa, serde_json::to_string(&a).unwrap()).unwrap();
    std::fs::write(&pb, serde_json::to_string(&b).unwrap()).unwrap();
    let bin = env!("CARGO_BIN_EXE_deformcal");
    let out = Command::new(bin)
        .arg("compare")
        .args([&pa, &pb])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let d = &compare(&a, &b).unwrap()[0];
    assert!(
        text.contains(&format!("{:.3} px", d.mapping_error_px)),
        "{text}"
    );
    assert!(text.contains("a real difference"), "{text}");
    // A calibration against itself: no difference at all.
    let out = Command::new(bin)
        .arg("compare")
        .args([&pa, &pa])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("     0.000 px     0.000 px"), "{text}");
    // A file that is not a calibration names itself.
    std::fs::write(dir.path().join("x.json"), "{\"x\": 1}").unwrap();
    let out = Command::new(bin)
        .arg("compare")
        .args([&pa, &dir.path().join("x.json")])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("x.json:1: not a deformcal calibration.json: missing field `method`"),
        "{err}"
    );
}
