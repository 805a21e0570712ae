//! The bias ratio against synthetic truth: noise explains the residual of a model
//! that fits the board, and not that of one that cannot follow its bend.
use crate::common;
use common::*;
use deformcal::model::synthetic::Preset;
use deformcal::solver::problem::Loss;
use deformcal::Method;

#[test]
fn bias_ratio_tells_a_bending_board_from_noise() {
    // T1's bends (2.6 ± 1.2 mm), no print error, the presets' 0.15 px noise.
    let (bent, _) = data(Preset::T1, 30, 9, 1.0, 0.0);
    let (rigid, _) = data(Preset::T2, 30, 9, 0.0, 0.0);
    for (name, d, bends) in [("bent", &bent, true), ("rigid", &rigid, false)] {
        for m in Method::ALL {
            let c = run(d, m, Loss::Cauchy);
            let estimated = c.trust(None).unwrap();
            let given = c.trust(Some(0.15)).unwrap();
            eprintln!(
                "{name} {m}: σ̂ {:.4} px, bias ratio {:.3} (σ given: {:.3}), p {}, G-AIC {:.1}",
                estimated.noise_px,
                estimated.bias_ratio,
                given.bias_ratio,
                estimated.parameters,
                estimated.g_aic
            );
            // The neighbour estimate finds the true noise whatever the model.
            assert!(
                (estimated.noise_px - 0.15).abs() < 0.015,
                "{name} {m}: {estimated:?}"
            );
            let standard_on_bend = bends && m == Method::Standard;
            for t in [estimated, given] {
                if standard_on_bend {
                    assert!(t.bias_ratio >= 0.5, "{name} {m}: {t:?}");
                } else if m != Method::Static || !bends {
                    // `static` cannot follow a per-image bend either.
                    assert!(t.bias_ratio <= 0.1, "{name} {m}: {t:?}");
                }
            }
        }
    }
}

#[test]
fn free_parameters_count_the_gauge_out() {
    let (d, _) = data(Preset::T2, 10, 2, 1.0, 0.0);
    let corners = d.target.num_corners();
    let frames = d.num_frames();
    let standard = run(&d, Method::Standard, Loss::Cauchy);
    assert_eq!(standard.free_parameters(), 7 + 6 * frames);
    let dynamic = run(&d, Method::Dynamic, Loss::Cauchy);
    assert_eq!(dynamic.free_parameters(), 7 + 9 * frames);
    let full = run(&d, Method::Full, Loss::Cauchy);
    let frozen = full.frozen.len();
    assert_eq!(
        full.free_parameters(),
        7 + 9 * frames + 2 * (corners - frozen) - 4
    );
}

#[test]
fn calibration_json_and_summary_carry_the_trust_figures() {
    let (bent, _) = data(Preset::T1, 20, 3, 1.0, 0.0);
    let mut c = run(&bent, Method::Standard, Loss::Cauchy);
    c.detector_noise_px = Some(0.15);
    // The figures the files report, at that noise.
    c.assess();
    let json = deformcal::app::calibration_json::CalibrationJson::from(&c);
    let t = c.trust(Some(0.15)).unwrap();
    assert_eq!(json.noise_px, Some(0.15));
    assert_eq!(json.noise_source.as_deref(), Some("config"));
    assert_eq!(json.bias_ratio, Some(t.bias_ratio));
    assert_eq!(json.parameters, Some(c.free_parameters()));
    let summary = deformcal::app::report::summary(&c);
    assert!(
        summary.contains("the board may bend; compare with `dynamic`"),
        "{summary}"
    );
}
