//! Shared helpers for the integration tests.
#![allow(dead_code)]
pub mod auto_grid;
pub mod sample_photos;
use deformcal::model::metrics::mapping_error;
use deformcal::model::synthetic::{Generator, Preset, Truth};
use deformcal::solver::problem::Loss;
use deformcal::solver::problem::SolverSettings;
use deformcal::{calibrate, Calibration, Dataset, Method, Request};

/// A synthetic preset with scaled bend and print error.
pub fn data(preset: Preset, images: usize, seed: u64, bend: f64, print: f64) -> (Dataset, Truth) {
    let mut g = Generator::new(preset, Some(images), seed);
    g.bend_scale = bend;
    g.print_scale = print;
    g.generate()
}

/// Calibrates with the default settings and the given loss.
pub fn run(dataset: &Dataset, method: Method, loss: Loss) -> Calibration {
    run_k(dataset, method, loss, SolverSettings::default().outlier_k)
}

/// Calibrates with the given loss and outlier rejection threshold (0: off).
pub fn run_k(dataset: &Dataset, method: Method, loss: Loss, outlier_k: f64) -> Calibration {
    let settings = SolverSettings {
        loss,
        outlier_k,
        ..SolverSettings::default()
    };
    run_with(dataset, method, settings)
}

/// Calibrates with the given settings and the default gauge.
pub fn run_with(dataset: &Dataset, method: Method, settings: SolverSettings) -> Calibration {
    calibrate(
        dataset,
        &Request {
            method,
            settings,
            gauge: None,
        },
    )
    .unwrap_or_else(|e| panic!("{method} failed: {e}"))
}

/// Mapping error between two calibrations' intrinsics of camera `k` of `dataset`.
pub fn intrinsics_apart(dataset: &Dataset, a: &Calibration, b: &Calibration, k: usize) -> f64 {
    let cam = &dataset.cameras[k];
    mapping_error(
        &a.state.intrinsics[k],
        &b.state.intrinsics[k],
        cam.width,
        cam.height,
    )
}

/// Mapping error of a calibration against the truth.
pub fn truth_error(c: &Calibration, truth: &Truth) -> f64 {
    let cam = &c.dataset.cameras[0];
    mapping_error(
        &truth.intrinsics[0],
        &c.state.intrinsics[0],
        cam.width,
        cam.height,
    )
}

/// RMS distance between `est` and `truth` after the best similarity transform
/// (Umeyama) of `est` onto `truth`.
pub fn aligned_rms(est: &[nalgebra::Vector3<f64>], truth: &[nalgebra::Vector3<f64>]) -> f64 {
    use nalgebra::{Matrix3, Vector3};
    let n = est.len() as f64;
    let me = est.iter().fold(Vector3::zeros(), |a, p| a + p) / n;
    let mt = truth.iter().fold(Vector3::zeros(), |a, p| a + p) / n;
    let mut cov = Matrix3::zeros();
    let mut var = 0.0;
    for (e, t) in est.iter().zip(truth) {
        cov += (t - mt) * (e - me).transpose();
        var += (e - me).norm_squared();
    }
    cov /= n;
    var /= n;
    let svd = cov.svd(true, true);
    let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
    let mut s = Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let r = u * s * vt;
    let scale = (svd.singular_values.component_mul(&s.diagonal())).sum() / var;
    let t = mt - scale * r * me;
    (est.iter()
        .zip(truth)
        .map(|(e, tr)| (scale * r * e + t - tr).norm_squared())
        .sum::<f64>()
        / n)
        .sqrt()
}

/// Mapping error to the truth with the best virtual rotation removed, camera `k`.
pub fn truth_error_rot(c: &Calibration, truth: &Truth, k: usize) -> f64 {
    let cam = &c.dataset.cameras[k];
    deformcal::model::metrics::mapping_error_rot(
        &truth.intrinsics[k],
        &c.state.intrinsics[k],
        cam.width,
        cam.height,
    )
}

/// Per-image RMS over the board of the error of the estimated bend Δz, in the
/// calibration's frame order.
pub fn bend_errors(c: &Calibration, truth: &Truth) -> Vec<f64> {
    let target = c.dataset.target;
    c.dataset
        .frame_ids
        .iter()
        .zip(&c.state.deformations)
        .map(|(&f, est)| {
            let tr = truth.deformations[f as usize];
            let sq: f64 = target
                .nominal_points()
                .iter()
                .map(|p| (est.dz(p.x, p.y) - tr.dz(p.x, p.y)).powi(2))
                .sum();
            (sq / target.num_corners() as f64).sqrt()
        })
        .collect()
}

/// Debian's interpreter, where python3-opencv and python3-mrcal install cv2 and mrcal.
pub const PYTHON: &str = "/usr/bin/python3";

/// Whether `/usr/bin/python3` can import every module; prints why a test skips if not.
/// (CI installs both, so there the peer tests always run.)
pub fn python_has(modules: &[&str]) -> bool {
    let code = modules
        .iter()
        .map(|m| format!("import {m}"))
        .collect::<Vec<_>>()
        .join("; ");
    let ok = std::process::Command::new(PYTHON)
        .args(["-c", &code])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !ok {
        eprintln!(
            "SKIPPED: {PYTHON} cannot `{code}` (apt-get install python3-opencv python3-mrcal)"
        );
    }
    ok
}

/// Runs `tests/tools/<script>` with `args`, `stdin` piped in, and parses its JSON output;
/// panics with the script's stderr if it fails.
pub fn run_tool(script: &str, args: &[String], stdin: &str) -> serde_json::Value {
    use std::io::Write;
    use std::process::{Command, Stdio};
    let path = format!("{}/tests/tools/{script}", env!("CARGO_MANIFEST_DIR"));
    let mut child = Command::new(PYTHON)
        .arg(&path)
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("run {PYTHON} {path}: {e}"));
    child
        .stdin
        .take()
        .unwrap()
        .write_all(stdin.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{script} {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{script}: {e}: {}", String::from_utf8_lossy(&out.stdout)))
}

/// Settings that run the solver to convergence without a robust loss, for comparisons
/// with other tools' plain least squares.
pub fn exact_settings() -> SolverSettings {
    SolverSettings {
        loss: Loss::None,
        function_tolerance: 1e-15,
        parameter_tolerance: 1e-15,
        gradient_tolerance: 1e-15,
        max_iterations: 500,
        // The peers reject nothing: compare fits of the same observations.
        outlier_k: 0.0,
        // Nor do they hold a lens parameter with a prior.
        lens_prior_sigma: None,
        ..SolverSettings::default()
    }
}

/// The chained Jacobian (and residuals) of `problem` at `state` equal the
/// single-piece autodiff reference's; `label` names the case in failures.
pub fn assert_chained_equals_autodiff(
    problem: &deformcal::solver::problem::Problem,
    state: &deformcal::solver::problem::State,
    label: &str,
) {
    let chained = problem
        .evaluate(state, &SolverSettings::default(), true)
        .unwrap();
    let reference = SolverSettings {
        reference_jacobian: true,
        ..SolverSettings::default()
    };
    let autodiff = problem.evaluate(state, &reference, true).unwrap();
    assert_eq!(
        chained.jacobian_col_idx, autodiff.jacobian_col_idx,
        "{label}: sparsity"
    );
    let scale = autodiff
        .jacobian_values
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()));
    for (a, b) in chained
        .jacobian_values
        .iter()
        .zip(&autodiff.jacobian_values)
    {
        assert!(
            (a - b).abs() <= 1e-9 * scale + 1e-12 * b.abs(),
            "{label}: {a} vs {b}"
        );
    }
    for (a, b) in chained.residuals.iter().zip(&autodiff.residuals) {
        assert!((a - b).abs() < 1e-9, "{label}: residual {a} vs {b}");
    }
}

/// Moves `percent` % of the observations by `lo`–`hi` px in a spread of
/// directions (the same ones every run); returns how many moved.
pub fn displace(d: &mut Dataset, percent: usize, lo: f64, hi: f64) -> usize {
    displace_by(d, |i| {
        ((i * 7919) % 100 < percent).then(|| lo + (hi - lo) * ((i * 31) % 97) as f64 / 96.0)
    })
    .len()
}

/// Moves observation `i` by `by(i)` px when that is `Some`, each in its own
/// direction (golden-angle steps, the same every run); returns the (frame,
/// corner) of those moved.
pub fn displace_by(d: &mut Dataset, by: impl Fn(usize) -> Option<f64>) -> Vec<(usize, usize)> {
    let mut moved = Vec::new();
    for (i, o) in d.observations.iter_mut().enumerate() {
        if let Some(r) = by(i) {
            let a = i as f64 * 2.399;
            o.uv[0] += r * a.cos();
            o.uv[1] += r * a.sin();
            moved.push((o.frame, o.corner));
        }
    }
    moved
}
