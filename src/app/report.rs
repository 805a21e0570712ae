//! The short human summary printed after a calibration.
use crate::model::board::Method;
use crate::model::selection::Selection;
use crate::model::trust::Trust;
use crate::solver::calibrate::Calibration;
use std::fmt::Write;

/// Method, RMSE, intrinsics, deformation, iterations and time, as a few lines of text.
pub fn summary(c: &Calibration) -> String {
    summary_with(c, &c.warnings)
}

/// [`summary`] with `warnings` in place of the calibration's own: the command line
/// passes none, because it prints every warning on stderr (stdout holds results),
/// while the HTML report's summary carries them all.
pub fn summary_with(c: &Calibration, warnings: &[String]) -> String {
    let mut s = String::new();
    let d = &c.dataset;
    let _ = writeln!(
        s,
        "deformcal: method {} on {} image(s), {} observations",
        c.method,
        d.num_frames(),
        d.observations.len()
    );
    let status = if c.converged {
        "converged"
    } else {
        "NOT CONVERGED"
    };
    let _ = writeln!(
        s,
        "  {status} after {} iterations in {:.3} s; RMSE {:.4} px",
        c.iterations(),
        c.seconds,
        c.rmse_px
    );
    let _ = writeln!(s, "  {}", rejection_line(c));
    write_trust(&mut s, c);
    if let Some(sel) = &c.selection {
        write_selection(&mut s, sel, c);
    }
    write_cameras(&mut s, c);
    write_rig(&mut s, c);
    write_board(&mut s, c);
    for w in warnings {
        let _ = writeln!(s, "  warning: {w}");
    }
    s
}

/// What outlier rejection did, in one line.
fn rejection_line(c: &Calibration) -> String {
    let k = c.settings.outlier_k;
    match c.rejected.len() {
        _ if k <= 0.0 => "outlier rejection: off (calibration.outlier_k = 0)".to_string(),
        0 => format!("outliers rejected: none beyond {k}σ"),
        n => format!(
            "outliers rejected: {n} beyond {k}σ (listed in outliers.csv); the result is the \
             calibration of the observations kept alone"
        ),
    }
}

/// The noise, the bias ratio and what it suggests (docs/conventions.md §3a).
fn write_trust(s: &mut String, c: &Calibration) {
    let Some(t) = c.assessment.trust else {
        return;
    };
    let weighted = c.dataset.observations.iter().any(|o| o.weight != 1.0);
    let source = if t.noise_source == "config" {
        "as configured"
    } else if weighted {
        // Photos (the refinement's σ_ref/σ) and corners.vnl (0.5^level).
        "of a weight-1 corner, estimated from neighbouring corners' weighted residuals"
    } else {
        "estimated from neighbouring corners"
    };
    let _ = writeln!(
        s,
        "  noise {:.3} px ({source}); bias ratio {:.2}: {}; G-AIC {:.1} with {} parameters",
        t.noise_px,
        t.bias_ratio,
        trust_verdict(c, &t),
        t.g_aic,
        t.parameters
    );
}

/// Whether the bias ratio above [`BIAS_RATIO_OK`] leaves room for doubt.
pub const BIAS_RATIO_OK: f64 = 0.1;

/// What the bias ratio says of a calibration, and what to do about it.
pub fn trust_verdict(c: &Calibration, t: &Trust) -> String {
    if t.bias_ratio <= BIAS_RATIO_OK {
        "the noise explains the residual".to_string()
    } else if c.method.has_paraboloid() {
        format!(
            "{:.0}% of the residual is more than noise: check the detections (outliers.csv) and the lens model",
            100.0 * t.bias_ratio
        )
    } else {
        format!(
            "{:.0}% of the residual is more than noise: the board may bend; compare with `dynamic` (lower G-AIC is better)",
            100.0 * t.bias_ratio
        )
    }
}

/// `auto`'s table of candidates and its verdict.
fn write_selection(s: &mut String, sel: &Selection, c: &Calibration) {
    if sel.candidates.is_empty() {
        let _ = writeln!(s, "  auto: {}", sel.reason);
        return;
    }
    let _ = writeln!(
        s,
        "  auto: {}-fold cross-validation over frames (seed {})",
        sel.folds, sel.seed
    );
    let _ = writeln!(
        s,
        "    {:9} {:>12} {:>10} {:>12} {:>6} {:>12} {:>7}",
        "method", "CV RMSE px", "± noise", "train RMSE", "bias", "G-AIC", "params"
    );
    let f = |v: Option<f64>, digits: usize| {
        v.map(|x| format!("{x:.digits$}"))
            .unwrap_or_else(|| "–".into())
    };
    for k in &sel.candidates {
        let mark = if k.method == sel.chosen { "*" } else { " " };
        let _ = writeln!(
            s,
            "  {mark} {:9} {:>12} {:>10} {:>12} {:>6} {:>12} {:>7}{}",
            k.method.name(),
            f(k.cv_rmse_px, 4),
            f(k.cv_noise_px, 4),
            f(k.rmse_px, 4),
            f(k.bias_ratio, 2),
            f(k.g_aic, 1),
            k.parameters,
            k.failed
                .as_ref()
                .map(|e| format!("  ({e})"))
                .unwrap_or_default()
        );
    }
    let _ = writeln!(s, "  verdict: {}", verdict(sel, c));
    let _ = writeln!(s, "    ({})", sel.reason);
}

/// One sentence: does the board bend, by how much, what it changes, which method.
pub fn verdict(sel: &Selection, c: &Calibration) -> String {
    if sel.chosen == Method::Standard {
        return "no bending detected above noise: `standard`".into();
    }
    let mut parts = Vec::new();
    if sel.chosen.has_paraboloid() {
        parts.push(format!(
            "the board bends by up to {:.1} mm",
            1e3 * c.max_out_of_plane()
        ));
    }
    if sel.chosen.has_correction() {
        let worst = c
            .state
            .corrections
            .iter()
            .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
            .fold(0.0, f64::max);
        parts.push(format!(
            "its corners sit up to {:.2} mm off the nominal grid",
            1e3 * worst
        ));
    }
    // As `compare` does: the larger of the plain and the rotation-compensated
    // shift relative to the expected mapping error of the same kind.
    let expected = c.assessment.uncertainty.as_ref().ok().map(|u| {
        u.iter().fold((0.0f64, 0.0f64), |m, x| {
            (
                m.0.max(x.expected_mapping_error_px),
                m.1.max(x.expected_mapping_error_rot_px),
            )
        })
    });
    parts.push(match expected {
        Some((e, e_rot)) if e > 0.0 && e_rot > 0.0 => format!(
            "modelling it moves the projection by {:.2} px ({:.3} px with the rotation removed), {:.1}× the calibration's uncertainty",
            sel.projection_shift_px,
            sel.projection_shift_rot_px,
            (sel.projection_shift_px / e).max(sel.projection_shift_rot_px / e_rot)
        ),
        _ => format!(
            "modelling it moves the projection by {:.2} px",
            sel.projection_shift_px
        ),
    });
    format!("{}: use `{}`", parts.join("; "), sel.chosen)
}

/// One line per camera: its size, lens model and intrinsics.
/// One line per camera: its size, lens model and intrinsics with their 1-σ
/// uncertainty, then the expected mapping error (docs/conventions.md §3a).
fn write_cameras(s: &mut String, c: &Calibration) {
    let d = &c.dataset;
    let uncertainty = &c.assessment.uncertainty;
    for (k, cam) in d.cameras.iter().enumerate() {
        let i = c.state.intrinsics[k];
        let u = uncertainty.as_ref().ok().and_then(|u| u.get(k));
        let values: Vec<String> = i
            .named()
            .enumerate()
            // Pixels (fx, fy, cx, cy) to 2 decimals, coefficients to 5.
            .map(|(n, (name, v))| {
                let digits = if n < 4 { 2 } else { 5 };
                let sigma = u.map(|u| u.intrinsics_std.iter().find(|(p, _)| *p == name));
                match sigma {
                    Some(Some((_, e))) => format!("{name} {v:.digits$} ± {e:.digits$}"),
                    Some(None) => format!("{name} {v:.digits$} (held)"),
                    None => format!("{name} {v:.digits$}"),
                }
            })
            .collect();
        let _ = writeln!(
            s,
            "  {} ({}×{}, {}): {}",
            cam.name,
            cam.width,
            cam.height,
            cam.model,
            values.join("  ")
        );
        if let (true, Some(sigma)) = (
            c.settings.lens_prior_on(&[cam.model]),
            c.settings.lens_prior_sigma,
        ) {
            let _ = writeln!(
                s,
                "    lens prior: {} held towards 0 with σ {sigma} where the corners leave them free (lens_prior = \"none\": OpenCV's problem)",
                cam.model.info().prior_params.join(", ")
            );
        }
        if let Some(u) = u {
            let _ = writeln!(
                s,
                "    expected mapping error {:.3} px ({:.3} px with the rotation removed): the noise alone leaves this much; map in {}",
                u.expected_mapping_error_px,
                u.expected_mapping_error_rot_px,
                crate::app::uncertainty_plot::file_name(&cam.name)
            );
        }
    }
    if let Err(e) = uncertainty {
        let _ = writeln!(s, "  uncertainty unavailable: {e}");
    }
}

/// One line per camera after the first: its baseline and rotation from camera 0.
fn write_rig(s: &mut String, c: &Calibration) {
    let d = &c.dataset;
    for (k, cam) in d.cameras.iter().enumerate().skip(1) {
        let pose = c.state.camera_poses[k];
        // The baseline is the distance between the optical centres.
        let centre = pose.inverse().translation_vector();
        let _ = writeln!(
            s,
            "  {} from {}: baseline {:.4} m, rotation {:.3}°",
            cam.name,
            d.cameras[0].name,
            centre.norm(),
            pose.rotation_matrix().angle().to_degrees()
        );
    }
}

/// Board health: the frames bent beyond `max_bend_mm` or with residuals far above
/// the rest (see `solver::health`).
fn write_health(s: &mut String, c: &Calibration) {
    let h = crate::solver::health::board_health(c, c.settings.board.max_bend_m);
    let flagged: Vec<_> = h.flagged().collect();
    if flagged.is_empty() {
        return;
    }
    let _ = writeln!(s, "  board health: {} frame(s) flagged", flagged.len());
    for f in flagged.iter().take(10) {
        let _ = writeln!(s, "    frame {}: {}", f.frame, f.flags.join("; "));
    }
    if flagged.len() > 10 {
        let _ = writeln!(s, "    … and {} more (see report.html)", flagged.len() - 10);
    }
}

/// The board's bend and static correction, for the methods that estimate them.
fn write_board(s: &mut String, c: &Calibration) {
    write_health(s, c);
    if c.method.has_paraboloid() {
        let _ = writeln!(
            s,
            "  max out-of-plane deformation: {:.3} mm",
            c.max_out_of_plane() * 1e3
        );
        let board = &c.settings.board;
        if let (true, Some(sigma)) = (board.bend_sigma_auto, board.bend_sigma_m) {
            let _ = writeln!(
                s,
                "  bend prior σ {:.3} mm per term at the board's corner, from the bends' spread beyond their noise (bend_prior_mm = \"auto\")",
                sigma * 1e3
            );
        }
        if let Some(sigma) = board.smoothness_sigma_m {
            let from = if board.smoothness_auto {
                "from the frames' own bends (bend_smoothness = \"auto\")"
            } else {
                "as configured; the frames' bends follow their order"
            };
            let _ = writeln!(
                s,
                "  temporal smoothness σ {:.3} mm per term and frame, {from}",
                sigma * 1e3
            );
        }
    }
    if c.method.has_correction() {
        let max = c
            .state
            .corrections
            .iter()
            .map(|v| v.iter().map(|x| x * x).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        let _ = writeln!(
            s,
            "  largest static correction: {:.3} mm (gauge corners {:?})",
            max * 1e3,
            c.gauge
        );
        let board = &c.settings.board;
        if let (true, Some(sigma)) = (board.static_sigma_auto, board.static_sigma_m) {
            let _ = writeln!(
                s,
                "  static prior σ {:.4} mm per correction value, from the corrections' spread beyond their noise (static_prior_mm = \"auto\")",
                sigma * 1e3
            );
        }
    }
}
