//! mrcal's `optimization_inputs` in our `.cameramodel` files, checked with the real
//! mrcal: it loads the problem, finds our residuals (RMS equal to our RMSE) and our
//! robust optimum as its own weighted least-squares optimum, and its uncertainty
//! and diff tools run on our models. Where mrcal cannot represent the problem the
//! file says why and carries none. Skips, saying so, without mrcal.
use crate::common;
use common::{python_has, run_tool};
use deformcal::app::exports::NOT_IN_CALIBRATION_JSON;
use deformcal::app::output::write_calibration;
use deformcal::model::synthetic::{Generator, Preset};
use deformcal::solver::problem::SolverSettings;
use deformcal::{calibrate, Calibration, LensModel, Method, Request};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Gross detection errors planted in the data: outlier rejection removes them, and
/// mrcal must see them as outliers (negative weight).
const PLANTED_OUTLIERS: usize = 4;

/// Calibrates a synthetic rigid-board set through `models` with the default robust
/// settings (Cauchy loss, outlier rejection) run to tight tolerances, with a few
/// gross outliers planted, and writes it into a fresh directory; without the
/// lens prior, so that the problem is mrcal's own.
fn calibrated(
    preset: Preset,
    models: &[LensModel],
    method: Method,
    seed: u64,
) -> (tempfile::TempDir, Calibration) {
    calibrated_with(preset, models, method, seed, None)
}

/// [`calibrated`] with the lens prior's σ given.
fn calibrated_with(
    preset: Preset,
    models: &[LensModel],
    method: Method,
    seed: u64,
    lens_prior_sigma: Option<f64>,
) -> (tempfile::TempDir, Calibration) {
    let mut g = Generator::new(preset, Some(12), seed).with_models(models);
    g.bend_scale = 0.0;
    let (mut dataset, _) = g.generate();
    let n = dataset.observations.len();
    for i in 0..PLANTED_OUTLIERS {
        dataset.observations[(i * 977 + 13) % n].uv[0] += 25.0;
    }
    let settings = SolverSettings {
        function_tolerance: 1e-15,
        parameter_tolerance: 1e-15,
        gradient_tolerance: 1e-15,
        max_iterations: 500,
        lens_prior_sigma,
        ..SolverSettings::default()
    };
    let request = Request {
        method,
        settings,
        gauge: None,
    };
    let c = calibrate(&dataset, &request).expect("calibrates");
    let dir = tempfile::tempdir().unwrap();
    write_calibration(dir.path(), &c).unwrap();
    (dir, c)
}

fn model_paths(dir: &Path, c: &Calibration) -> Vec<String> {
    c.dataset
        .cameras
        .iter()
        .map(|cam| {
            dir.join(format!("{}.cameramodel", cam.name))
                .display()
                .to_string()
        })
        .collect()
}

#[test]
fn mrcal_finds_our_residuals_and_our_optimum_in_the_models() {
    if !python_has(&["mrcal"]) {
        return;
    }
    for models in [
        &[LensModel::OpenCv5, LensModel::OpenCv5][..],
        &[LensModel::OpenCv8][..],
        &[LensModel::Radial3][..],
    ] {
        let preset = if models.len() == 2 {
            Preset::Stereo
        } else {
            Preset::T2
        };
        let (dir, c) = calibrated(preset, models, Method::Standard, 3);
        assert!(
            c.rejected.len() >= PLANTED_OUTLIERS,
            "{models:?}: {}",
            c.rejected.len()
        );
        let out = run_tool("mrcal_inputs.py", &model_paths(dir.path(), &c), "");
        for (k, m) in out["models"].as_array().unwrap().iter().enumerate() {
            let label = format!("{:?} camera {k}", models[k]);
            assert_eq!(m["carried"], true, "{label}");
            assert_eq!(m["icam_intrinsics"], k, "{label}");
            let mrcal_name = if models[k] == LensModel::Radial3 {
                "LENSMODEL_OPENCV5"
            } else {
                models[k].info().mrcal.unwrap()
            };
            assert_eq!(m["lensmodel"], mrcal_name, "{label}");
            assert_eq!(m["intrinsics_equal"], true, "{label}");
            assert_eq!(m["extrinsics_equal"], true, "{label}");
            assert_eq!(m["used"], c.dataset.observations.len(), "{label}");
            assert_eq!(m["rejected"], c.rejected.len(), "{label}");
            let rms = m["rms_px"].as_f64().unwrap();
            let rel = (rms / c.rmse_px - 1.0).abs();
            assert!(rel < 1e-6, "{label}: mrcal {rms} px, ours {} px", c.rmse_px);
            let (cost, again) = (
                m["cost"].as_f64().unwrap(),
                m["cost_reoptimised"].as_f64().unwrap(),
            );
            let moved = m["intrinsics_moved"].as_f64().unwrap();
            let uncertainty = m["uncertainty_px"].as_f64().unwrap();
            eprintln!(
                "{label}: RMS mrcal/ours − 1 = {rel:.1e}; mrcal re-optimising lowers the cost by {:.1e} (relative) and moves the intrinsics by {moved:.1e}; uncertainty at the centre {uncertainty:.3} px",
                (cost - again) / cost
            );
            assert!(uncertainty.is_finite() && uncertainty > 0.0, "{label}");
            // Every parameter free in both problems: our robust optimum is mrcal's
            // weighted least-squares optimum. (radial3's p1, p2 are free in mrcal's only.)
            if models[k] != LensModel::Radial3 {
                assert!((cost - again) / cost < 1e-9, "{label}: {cost} → {again}");
                assert!(
                    moved < 1e-4,
                    "{label}: mrcal moved the intrinsics by {moved}"
                );
            }
        }
    }
}

/// Whether an executable is on PATH; prints why a test skips if not.
fn tool_present(tool: &str) -> bool {
    let ok = Command::new(tool)
        .arg("--help")
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        eprintln!("SKIPPED: `{tool}` is not installed (apt-get install mrcal)");
    }
    ok
}

/// Runs a mrcal tool writing a PNG, and checks it exits 0 with a PNG written.
fn run_plot(tool: &str, args: &[&str], png: &PathBuf) {
    let out = Command::new(tool)
        .args(args)
        .arg("--hardcopy")
        .arg(png)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{tool} {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let bytes = std::fs::read(png).unwrap();
    assert!(bytes.starts_with(b"\x89PNG"), "{tool} wrote no PNG");
    eprintln!("{tool}: exit 0, {} ({} bytes)", png.display(), bytes.len());
}

#[test]
fn mrcals_uncertainty_and_diff_tools_run_on_our_models() {
    let tools = [
        "mrcal-show-projection-uncertainty",
        "mrcal-show-projection-diff",
    ];
    if !tools.iter().all(|t| tool_present(t)) {
        return;
    }
    // The default lens model, radial3, on two independent data sets.
    let (a, ca) = calibrated(Preset::T2, &[LensModel::Radial3], Method::Standard, 5);
    let (b, cb) = calibrated(Preset::T2, &[LensModel::Radial3], Method::Standard, 6);
    let (ma, mb) = (
        &model_paths(a.path(), &ca)[0],
        &model_paths(b.path(), &cb)[0],
    );
    let plots = std::env::temp_dir().join(format!("deformcal-mrcal-{}", std::process::id()));
    std::fs::create_dir_all(&plots).unwrap();
    run_plot(tools[0], &[ma], &plots.join("uncertainty.png"));
    // Without --no-uncertainties the diff fits the cameras' relative rotation
    // weighted by both models' uncertainties, from their optimization_inputs.
    run_plot(tools[1], &[ma, mb], &plots.join("diff.png"));
    std::fs::remove_dir_all(&plots).unwrap();
}

/// The comment a model carries instead of optimization_inputs.
fn absent_comment(dir: &Path, camera: &str) -> Option<String> {
    let text = std::fs::read_to_string(dir.join(format!("{camera}.cameramodel"))).unwrap();
    assert_eq!(
        text.contains("'optimization_inputs'"),
        !text.contains("# no optimization_inputs: "),
        "{text}"
    );
    text.lines()
        .find_map(|l| l.trim().strip_prefix("# no optimization_inputs: "))
        .map(str::to_string)
}

#[test]
fn a_problem_mrcal_cannot_represent_is_left_out_with_the_reason() {
    let (dir, _) = calibrated(Preset::T2, &[LensModel::OpenCv5], Method::Dynamic, 3);
    assert_eq!(
        absent_comment(dir.path(), "cam0").as_deref(),
        Some("mrcal's board is rigid up to its own two-parameter calobject_warp, and method `dynamic` bends the board in every image")
    );
    let (dir, _) = calibrated(Preset::T2, &[LensModel::OpenCv5], Method::Static, 3);
    assert_eq!(
        absent_comment(dir.path(), "cam0").as_deref(),
        Some("mrcal's board is rigid up to its own two-parameter calobject_warp, and method `static` moves every corner by its own offset")
    );
    // The default lens prior on opencv8's denominator: no term of mrcal's.
    let (dir, _) = calibrated_with(
        Preset::T2,
        &[LensModel::OpenCv8],
        Method::Standard,
        3,
        SolverSettings::default().lens_prior_sigma,
    );
    assert_eq!(
        absent_comment(dir.path(), "cam0").as_deref(),
        Some("our problem holds k4, k5, k6 of `opencv8` with a lens prior (lens_prior = 0.1), which mrcal's problem has no term for; lens_prior = \"none\" gives mrcal's problem")
    );
    // A rig of two lens models: mrcal solves with one.
    let (dir, _) = calibrated(
        Preset::Stereo,
        &[LensModel::OpenCv5, LensModel::OpenCv8],
        Method::Standard,
        3,
    );
    let mixed = "mrcal solves every camera with one lens model, and camera `cam0` is `opencv5` while camera `cam1` is `opencv8`";
    assert_eq!(absent_comment(dir.path(), "cam0").as_deref(), Some(mixed));
    assert_eq!(absent_comment(dir.path(), "cam1").as_deref(), Some(mixed));
    // kb4 has no mrcal model: no file for it, and its partner says why.
    let (dir, _) = calibrated(
        Preset::Stereo,
        &[LensModel::OpenCv5, LensModel::Kb4],
        Method::Standard,
        3,
    );
    assert!(!dir.path().join("cam1.cameramodel").exists());
    assert_eq!(
        absent_comment(dir.path(), "cam0").as_deref(),
        Some("mrcal has no `kb4` lens model (camera `cam1`)")
    );
    if python_has(&["mrcal"]) {
        let out = run_tool(
            "mrcal_inputs.py",
            &[dir.path().join("cam0.cameramodel").display().to_string()],
            "",
        );
        assert_eq!(out["models"][0]["carried"], false);
    }
}

#[test]
fn radial3_models_say_that_mrcal_frees_p1_and_p2() {
    let (dir, _) = calibrated(Preset::T2, &[LensModel::Radial3], Method::Standard, 3);
    let text = std::fs::read_to_string(dir.path().join("cam0.cameramodel")).unwrap();
    assert!(
        text.contains("    # note: mrcal holds all four core or all distortion parameters or none, so these, held in deformcal's problem (radial3 has p1 = p2 = 0), are free in this one: `cam0` p1, p2\n"),
        "{text}"
    );
    let (dir, _) = calibrated(Preset::T2, &[LensModel::OpenCv5], Method::Standard, 3);
    let text = std::fs::read_to_string(dir.path().join("cam0.cameramodel")).unwrap();
    assert!(!text.contains("# note:"), "{text}");
}

#[test]
fn export_from_calibration_json_writes_models_without_optimization_inputs() {
    let (dir, _) = calibrated(Preset::T2, &[LensModel::OpenCv5], Method::Standard, 3);
    let out = dir.path().join("exported");
    let run = Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .args(["export", "--calibration"])
        .arg(dir.path().join("calibration.json"))
        .arg("--output")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains(&format!(
            "the mrcal models carry no optimization_inputs: {NOT_IN_CALIBRATION_JSON}"
        )),
        "{stdout}"
    );
    assert_eq!(
        absent_comment(&out, "cam0").as_deref(),
        Some(NOT_IN_CALIBRATION_JSON)
    );
}
