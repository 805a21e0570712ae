//! The short human summary printed after a calibration.
use crate::model::trust::Trust;
use crate::solver::calibrate::Calibration;
use std::fmt::Write;

/// Method, RMSE, intrinsics, deformation, iterations and time, as a few lines of text.
pub fn summary(c: &Calibration) -> String {
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
    let _ = writeln!(
        s,
        "  outliers rejected: {} (beyond {}σ; listed in outliers.csv)",
        c.rejected.len(),
        c.settings.outlier_k
    );
    write_trust(&mut s, c);
    write_cameras(&mut s, c);
    write_rig(&mut s, c);
    write_board(&mut s, c);
    for w in &c.warnings {
        let _ = writeln!(s, "  warning: {w}");
    }
    s
}

/// The noise, the bias ratio and what it suggests (SPEC §3a).
fn write_trust(s: &mut String, c: &Calibration) {
    let Some(t) = c.trust(c.detector_noise_px) else {
        return;
    };
    let source = if t.noise_source == "config" {
        "as configured"
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

/// One line per camera: its size, lens model and intrinsics.
fn write_cameras(s: &mut String, c: &Calibration) {
    let d = &c.dataset;
    for (k, cam) in d.cameras.iter().enumerate() {
        let i = c.state.intrinsics[k];
        let values: Vec<String> = i
            .named()
            .enumerate()
            // Pixels (fx, fy, cx, cy) to 2 decimals, coefficients to 5.
            .map(|(n, (name, v))| {
                if n < 4 {
                    format!("{name} {v:.2}")
                } else {
                    format!("{name} {v:.5}")
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

/// The board's bend and static correction, for the methods that estimate them.
fn write_board(s: &mut String, c: &Calibration) {
    if c.method.has_paraboloid() {
        let _ = writeln!(
            s,
            "  max out-of-plane deformation: {:.3} mm",
            c.max_out_of_plane() * 1e3
        );
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
    }
}
