//! Issue 16's guard rails and bad-input cases, each with its exact message: a
//! calibration that did not converge, lost most of its data to outlier rejection or
//! has an RMSE far above what the data support exits 3 and writes only `FAILED-`
//! files (replacing a previous good result); hints name a swapped board and a
//! lens model that fits; the config names unknown and missing keys; `[protocol]`
//! in the plain command runs the protocol; warnings for several cameras in one, a
//! reference set that is the training data, and frames turned by 180°; per-camera
//! RMSE in opencv.yaml. Numbers in the expected messages come from the library on
//! the same data, or from the truth of the synthetic data.
use deformcal::app::guard::{self, Rules};
use deformcal::app::lint;
use deformcal::model::synthetic::{Generator, Preset};
use deformcal::solver::problem::SolverSettings;
use deformcal::{calibrate, Calibration, Dataset, LensModel, Method, Request, Target};
use std::path::Path;
use std::process::{Command, Output};

fn deformcal(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .args(args)
        .output()
        .unwrap()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).to_string()
}

/// The last line of stderr of a run that exited with `code`.
fn last_line(out: &Output, code: i32) -> String {
    let e = stderr(out);
    assert_eq!(out.status.code(), Some(code), "{e}");
    assert!(!e.contains("panicked"), "{e}");
    e.trim_end().lines().last().unwrap_or("").to_string()
}

fn ok(out: &Output) -> String {
    assert!(out.status.success(), "{}", stderr(out));
    String::from_utf8_lossy(&out.stdout).to_string()
}

fn request(method: Method) -> Request {
    Request {
        method,
        settings: SolverSettings::default(),
        gauge: None,
    }
}

/// What a config with only `method` asks for: the board priors estimated.
fn recommended(method: Method) -> Request {
    Request {
        settings: SolverSettings::recommended(),
        ..request(method)
    }
}

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .collect();
    v.sort();
    v
}

/// Writes `d` as `obs.csv` in `dir` and reads it back as the binary will (the
/// file's order of observations, which the sums of the solver follow).
fn write_csv(dir: &Path, d: &Dataset) -> Dataset {
    let path = dir.join("obs.csv");
    deformcal::app::observations_csv::write(d, &path).unwrap();
    deformcal::app::observations_csv::read(&path, d.target, d.cameras.clone()).unwrap()
}

/// Writes a config for an observations CSV of one camera.
fn csv_config(dir: &Path, name: &str, board: (usize, usize, f64), model: &str, extra: &str) {
    let (rows, cols, spacing) = board;
    std::fs::write(
        dir.join(name),
        format!(
            "[target]\nrows = {rows}\ncols = {cols}\nspacing = {spacing}\n[[cameras]]\nname = \"cam0\"\nwidth = 1936\nheight = 1216\nmodel = \"{model}\"\n[data]\nobservations = \"obs.csv\"\n{extra}[output]\ndir = \"out\"\n"
        ),
    )
    .unwrap();
}

#[test]
fn a_solve_that_does_not_converge_exits_3_and_replaces_the_previous_result() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.toml");
    let bad = dir.path().join("bad.toml");
    let data = "[data]\nsynthetic = \"t2\"\nimages = 20\nseed = 4\n";
    std::fs::write(&good, format!("{data}[output]\ndir = \"out\"\n")).unwrap();
    std::fs::write(
        &bad,
        format!("{data}[calibration]\nmax_iterations = 1\n[output]\ndir = \"out\"\n"),
    )
    .unwrap();
    let out = dir.path().join("out");
    ok(&deformcal(&["--config", good.to_str().unwrap()]));
    assert!(out.join("calibration.json").exists() && out.join("opencv.yaml").exists());
    std::fs::write(out.join("notes.txt"), "mine").unwrap();

    let run = deformcal(&["--config", bad.to_str().unwrap()]);
    let last = last_line(&run, 3);
    assert!(String::from_utf8_lossy(&run.stdout).contains("NOT CONVERGED after"));
    let reason = "the full solve did not converge after 1 iterations (Maximum number of iterations reached. Number of iterations: 1)";
    assert_eq!(
        last,
        format!(
            "error: the calibration FAILED: {reason}; wrote {}/FAILED-calibration.json and FAILED-outliers.csv (no model files)",
            out.display()
        )
    );
    assert!(stderr(&run).lines().any(|l| l
        == "hint: the solve stopped at calibration.max_iterations = 1; if the RMSE is fine, raise it (or loosen function_tolerance / parameter_tolerance)"));
    // Nothing of the previous good result is left to be taken for this run's.
    assert_eq!(
        files_in(&out),
        [
            "FAILED-calibration.json",
            "FAILED-outliers.csv",
            "notes.txt"
        ]
    );
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("FAILED-calibration.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(json["converged"], false);
    assert_eq!(json["failure"]["reasons"][0], reason);

    let export = deformcal(&[
        "export",
        "--calibration",
        out.join("FAILED-calibration.json").to_str().unwrap(),
        "--output",
        dir.path().join("models").to_str().unwrap(),
    ]);
    assert_eq!(
        last_line(&export, 1),
        format!(
            "error: {}: this calibration FAILED its guard rails ({reason}); it cannot be used",
            out.join("FAILED-calibration.json").display()
        )
    );
    assert!(!dir.path().join("models").exists());

    ok(&deformcal(&["--config", good.to_str().unwrap()]));
    assert!(!out.join("FAILED-calibration.json").exists());
    assert!(out.join("calibration.json").exists() && out.join("notes.txt").exists());
}

#[test]
fn a_fisheye_taken_for_a_pinhole_fails_with_the_lens_hint() {
    let dir = tempfile::tempdir().unwrap();
    let (d, _) = Generator::new(Preset::T2, Some(15), 3)
        .with_models(&[LensModel::Kb4])
        .generate();
    let d = write_csv(dir.path(), &d);
    csv_config(dir.path(), "c.toml", (13, 13, 0.07), "radial3", "");
    let c = dir.path().join("c.toml");
    let run = deformcal(&["--config", c.to_str().unwrap(), "--method", "standard"]);
    let last = last_line(&run, 3);

    // The same calibration and the kb4 trial, in the library.
    let as_radial3 = Dataset {
        cameras: vec![deformcal::CameraSpec::new(
            "cam0",
            1936,
            1216,
            LensModel::Radial3,
        )],
        ..d.clone()
    };
    let failed = calibrate(&as_radial3, &request(Method::Standard)).unwrap();
    let reasons = guard::reasons(&failed, Rules { max_rmse_px: None });
    // A pinhole cannot follow the fisheye: the solve wanders and does not
    // converge, and no outlier rejection runs on a solve that stopped short.
    assert!(
        reasons[0].starts_with("the standard solve did not converge after "),
        "{reasons:?}"
    );
    assert!(failed.rejected.is_empty());
    assert!(
        last.starts_with(&format!(
            "error: the calibration FAILED: {}",
            reasons.join("; ")
        )),
        "{last}"
    );
    let kb4 = calibrate(&d, &request(Method::Standard)).unwrap();
    let hint = format!(
        "hint: the lens model may not fit the lens: with model = \"kb4\" the same corners give RMSE {:.3} px with `standard`",
        kb4.rmse_px
    );
    assert!(stderr(&run).lines().any(|l| l == hint), "{}", stderr(&run));
    assert!(stderr(&run).contains("\nhint: frames with the worst RMSE: frame "));
    // The lens model that does fit gets no hint to change it, although a richer
    // model (opencv8) fits the same corners a little better.
    let rules = Rules { max_rmse_px: None };
    assert_eq!(
        guard::error_hints(&d, &request(Method::Standard), rules),
        Vec::<String>::new()
    );
    assert!(!guard::error_hints(&as_radial3, &request(Method::Standard), rules).is_empty());
}

#[test]
fn swapped_rows_and_cols_are_named_with_the_board_that_fits() {
    let dir = tempfile::tempdir().unwrap();
    let (d, _) = Generator::new(Preset::T4, Some(20), 3).generate();
    let d = write_csv(dir.path(), &d);
    csv_config(dir.path(), "c.toml", (11, 7, 0.03), "radial3", "");
    let c = dir.path().join("c.toml");
    let run = deformcal(&["--config", c.to_str().unwrap()]);
    assert_eq!(
        last_line(&run, 1),
        "error: degenerate data: no view's corners fit a planar 11 × 7 board with corner i = row·7 + col (misfit 22% of the view's size or more): check target.rows and target.cols (swapped?) and the corner numbering"
    );
    // The hint's RMSE is `standard` on the board as it is (T4: 7 × 11).
    let right = calibrate(&d, &request(Method::Standard)).unwrap();
    assert_eq!(
        d.target,
        Target {
            rows: 7,
            cols: 11,
            spacing: 0.03
        }
    );
    assert!(stderr(&run).starts_with(&format!(
        "hint: rows and cols may be swapped: read as a 7 × 11 board (target.rows = 7, target.cols = 11) the same corners give RMSE {:.3} px with `standard`\n",
        right.rmse_px
    )), "{}", stderr(&run));
    assert!(!dir.path().join("out").exists());
}

#[test]
fn an_rmse_far_above_the_data_fails_by_each_rule() {
    // Absolute: 4 px of detector noise on a rigid board, a model that fits.
    let mut g = Generator::new(Preset::T2, Some(20), 8);
    (g.noise_px, g.bend_scale, g.print_scale) = (4.0, 0.0, 0.0);
    let c = calibrate(&g.generate().0, &request(Method::Standard)).unwrap();
    assert!(c.rmse_px > 5.0, "{}", c.rmse_px);
    assert_eq!(
        guard::reasons(&c, Rules { max_rmse_px: None }),
        [format!(
            "its RMSE {:.3} px is above 5 px, far more than a calibration gives (0.1–1 px)",
            c.rmse_px
        )]
    );
    assert!(guard::reasons(
        &c,
        Rules {
            max_rmse_px: Some(10.0)
        }
    )
    .is_empty());

    // Relative: clean corners (0.02 px) on a strongly bending board under
    // `standard`, outlier rejection off (it would take the bend for outliers).
    let mut g = Generator::new(Preset::T1, Some(20), 8);
    (g.noise_px, g.bend_scale) = (0.02, 6.0);
    let (d, _) = g.generate();
    let no_rejection = |method| Request {
        settings: SolverSettings {
            outlier_k: 0.0,
            ..SolverSettings::default()
        },
        ..request(method)
    };
    let c = calibrate(&d, &no_rejection(Method::Standard)).unwrap();
    let t = c.trust(None).unwrap();
    let floor = std::f64::consts::SQRT_2 * t.noise_px;
    assert!(c.rmse_px > 10.0 * floor && c.rmse_px < 5.0, "{}", c.rmse_px);
    assert_eq!(
        guard::reasons(&c, Rules { max_rmse_px: None }),
        [format!(
            "its RMSE {:.3} px is {:.0} times the {floor:.3} px that the corners' noise (σ̂ = {:.3} px) explains: the model cannot describe the data (one that can gives about 1 time)",
            c.rmse_px,
            c.rmse_px / floor,
            t.noise_px
        )]
    );
    // `dynamic` follows the bend: the same data pass.
    let c = calibrate(&d, &no_rejection(Method::Dynamic)).unwrap();
    assert!(guard::reasons(&c, Rules { max_rmse_px: None }).is_empty());
}

#[test]
fn max_rmse_px_in_the_config_is_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    let c = dir.path().join("c.toml");
    std::fs::write(&c, "[data]\nsynthetic = \"t2\"\nimages = 12\n[calibration]\nmethod = \"full\"\nmax_rmse_px = 0.1\n[output]\ndir = \"out\"\n").unwrap();
    let run = deformcal(&["--config", c.to_str().unwrap()]);
    let (d, _) = Generator::new(Preset::T2, Some(12), 1).generate();
    let lib = calibrate(&d, &recommended(Method::Full)).unwrap();
    assert!(last_line(&run, 3).starts_with(&format!(
        "error: the calibration FAILED: its RMSE {:.3} px is above calibration.max_rmse_px = 0.1 px; wrote ",
        lib.rmse_px
    )));
    std::fs::write(
        &c,
        "[data]\nsynthetic = \"t2\"\n[calibration]\nmax_rmse_px = -1\n",
    )
    .unwrap();
    assert_eq!(
        last_line(&deformcal(&["--config", c.to_str().unwrap()]), 1),
        format!(
            "error: {}: line 4: calibration.max_rmse_px must be a positive number of pixels (got -1)",
            c.display()
        )
    );
}

#[test]
fn presets_and_the_repos_configs_pass_the_guard_without_warnings() {
    for preset in ["t1", "t2", "t3", "t4", "reference", "stereo"] {
        let p = Preset::parse(preset).unwrap();
        let (d, _) = Generator::new(p, Some(25), 2).generate();
        for method in [Method::Standard, Method::Full] {
            let c = calibrate(&d, &request(method)).unwrap();
            let none = guard::judge(
                &d,
                &request(method),
                &c,
                Rules { max_rmse_px: None },
                &Default::default(),
            );
            assert_eq!(none, None, "{preset} {method}");
            assert_eq!(
                lint::flipped_frames(&c, &Default::default()),
                None,
                "{preset} {method}"
            );
        }
    }
    let configs = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    for name in [
        "t1_full",
        "t2_standard",
        "t2_static",
        "t2_dynamic",
        "t2_full",
        "t3_full",
        "t4_full",
        "reference_static",
    ] {
        let config = deformcal::Config::load(&configs.join(format!("{name}.toml"))).unwrap();
        let loaded = deformcal::app::source::load(&config).unwrap();
        let deformcal::model::selection::MethodChoice::Fixed(method) = config.calibration.method
        else {
            panic!("{name}: the configs name a method");
        };
        let r = Request {
            method,
            settings: SolverSettings::from(&config.calibration),
            gauge: config.calibration.gauge_corners.clone(),
        };
        let c = calibrate(&loaded.dataset, &r).unwrap();
        let rules = Rules {
            max_rmse_px: config.calibration.max_rmse_px,
        };
        assert_eq!(
            guard::judge(&loaded.dataset, &r, &c, rules, &loaded.files),
            None,
            "{name}"
        );
        assert!(loaded.warnings.is_empty(), "{name}: {:?}", loaded.warnings);
        assert_eq!(lint::flipped_frames(&c, &loaded.files), None, "{name}");
    }
}

/// Runs a config through the binary and returns its one `error:` line (exit 1,
/// nothing written).
fn config_error(dir: &Path, text: &str) -> String {
    let c = dir.join("c.toml");
    std::fs::write(&c, text).unwrap();
    let run = deformcal(&["--config", c.to_str().unwrap()]);
    let e = stderr(&run);
    assert_eq!(e.lines().count(), 1, "{e}");
    assert!(!dir.join("out").exists());
    last_line(&run, 1)
        .strip_prefix(&format!("error: {}: ", c.display()))
        .unwrap_or_else(|| panic!("{e}"))
        .to_string()
}

#[test]
fn unknown_and_missing_keys_are_named_with_section_line_and_suggestion() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cam = "[[cameras]]\nname = \"cam0\"\nwidth = 640\nheight = 480\n";
    let data = "[data]\nobservations = \"obs.csv\"\n";
    let board = "[target]\nrows = 6\ncols = 9\nspacing = 0.025\n";
    assert_eq!(
        config_error(d, &format!("{board}spaceing = 0.07\n{cam}{data}")),
        "line 5: unknown key `spaceing` in [target]; did you mean `spacing`?"
    );
    assert_eq!(
        config_error(
            d,
            &format!("[target]\nrows = 6\ncols = 9\nspaceing = 0.025\n{cam}{data}")
        ),
        "line 4: unknown key `spaceing` in [target]; did you mean `spacing`?"
    );
    assert_eq!(
        config_error(d, &format!("{board}{cam}{cam}widht = 3\n{data}")),
        "line 13: unknown key `widht` in [[cameras]] #2 (line 9); did you mean `width`?"
    );
    assert_eq!(
        config_error(
            d,
            &format!("{board}{cam}{data}[calibraton]\nmethod = \"full\"\n")
        ),
        "line 11: unknown section `[calibraton]`; did you mean `[calibration]`?"
    );
    assert_eq!(
        config_error(
            d,
            &format!("{board}{cam}{data}[output]\ndirectory = \"x\"\n")
        ),
        "line 12: unknown key `directory` in [output] (known: dir)"
    );
    assert_eq!(
        config_error(
            d,
            &format!("{board}[[cameras]]\nwidth = 640\nheight = 480\n{data}")
        ),
        "line 5: [[cameras]] #1 lacks the required key `name`"
    );
    assert_eq!(
        config_error(d, &format!("{board}{cam}")),
        "the config needs a `[data]` section"
    );
    assert_eq!(
        config_error(d, &format!("{cam}{data}")),
        "the config needs a `[target]` section (rows, cols, spacing)"
    );
    assert_eq!(
        config_error(d, &format!("{board}{cam}{data}[calibration]\nloss = \"cauchi\"\n")),
        "line 12: in [calibration]: unknown variant `cauchi`, expected `none` or `cauchy`; did you mean `cauchy`?"
    );
}

#[test]
fn protocol_in_the_plain_command_runs_the_protocol() {
    let dir = tempfile::tempdir().unwrap();
    let c = dir.path().join("c.toml");
    std::fs::write(&c, "[data]\nsynthetic = \"t2\"\nimages = 12\n[protocol]\nsubsets = 1\nimages_per_subset = 5\nmethods = [\"standard\"]\n[output]\ndir = \"out\"\n").unwrap();
    let path = c.to_str().unwrap();
    let run = deformcal(&["--config", path, "--threads", "1"]);
    ok(&run);
    assert!(stderr(&run).starts_with(&format!(
        "{path}: the config has a [protocol] section: running the evaluation protocol (`deformcal calibrate --config …` calibrates once instead)\n"
    )));
    let out = dir.path().join("out");
    assert!(out.join("protocol.csv").exists() && out.join("summary.json").exists());
    assert!(!out.join("calibration.json").exists());
    assert_eq!(
        last_line(&deformcal(&["--config", path, "--method", "full"]), 1),
        format!("error: {path}: --method applies to one calibration, but the config has a [protocol] section, which runs its `methods`; to calibrate once use `deformcal calibrate --config {path}`")
    );
    ok(&deformcal(&["calibrate", "--config", path]));
    assert!(out.join("calibration.json").exists() && out.join("protocol.csv").exists());
}

#[test]
fn two_cameras_in_one_are_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let (d, _) = Generator::new(Preset::Stereo, Some(12), 2).generate();
    // corners.vnl names each view `<camera>-<frame>.png`: call them left and right.
    let vnl = deformcal::app::corners_vnl::write_corners_vnl(&d)
        .replace("cam0-", "left")
        .replace("cam1-", "right");
    std::fs::write(dir.path().join("corners.vnl"), &vnl).unwrap();
    let c = dir.path().join("c.toml");
    std::fs::write(&c, "[target]\nrows = 13\ncols = 13\nspacing = 0.07\n[[cameras]]\nname = \"cam0\"\nwidth = 1936\nheight = 1216\n[data]\ncorners_vnl = \"corners.vnl\"\n[output]\ndir = \"out\"\n").unwrap();
    let run = deformcal(&["--config", c.to_str().unwrap()]);
    ok(&run);
    let views = |k: usize| {
        d.observations
            .iter()
            .filter(|o| o.camera == k)
            .map(|o| o.frame)
            .collect::<std::collections::BTreeSet<_>>()
    };
    let (left, right) = (views(0), views(1));
    let shared = left.intersection(&right).count();
    let warning = format!(
        "the images of camera `cam0` look like 2 cameras: `left*.png` ({} files) and `right*.png` ({} files) share {shared} frame numbers; one model fitted to several cameras is wrong. If they are, list one [[cameras]] per camera and set `camera_patterns = {{ cam0 = \"left*.png\", cam1 = \"right*.png\" }}`",
        left.len(),
        right.len()
    );
    assert!(
        stderr(&run).contains(&format!("warning: {warning}\n")),
        "{}",
        stderr(&run)
    );
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("out/calibration.json")).unwrap(),
    )
    .unwrap();
    assert!(json["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .any(|w| w == &warning));
}

#[test]
fn a_reference_set_that_is_the_training_data_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let c = dir.path().join("c.toml");
    std::fs::write(&c, "[data]\nsynthetic = \"t2\"\nimages = 12\n[reference]\nsynthetic = \"t2\"\nimages = 12\n[protocol]\nsubsets = 1\nimages_per_subset = 5\nmethods = [\"standard\"]\n[output]\ndir = \"out\"\n").unwrap();
    let run = deformcal(&[
        "protocol",
        "--config",
        c.to_str().unwrap(),
        "--threads",
        "1",
    ]);
    ok(&run);
    let n = Generator::new(Preset::T2, Some(12), 1)
        .generate()
        .0
        .observations
        .len();
    assert!(stderr(&run).contains(&format!(
        "warning: {}: [reference] is the training data (all {n} of its observations are training observations): test_rmse_px and the mapping errors then measure the fit to the images calibrated on, not to independent ones; give a separate static reference set\n",
        c.display()
    )), "{}", stderr(&run));
    // Another seed is another set: no warning.
    std::fs::write(&c, "[data]\nsynthetic = \"t2\"\nimages = 12\n[reference]\nsynthetic = \"t2\"\nimages = 12\nseed = 2\n[protocol]\nsubsets = 1\nimages_per_subset = 5\nmethods = [\"standard\"]\n[output]\ndir = \"out\"\n").unwrap();
    let run = deformcal(&[
        "protocol",
        "--config",
        c.to_str().unwrap(),
        "--threads",
        "1",
    ]);
    ok(&run);
    assert!(!stderr(&run).contains("[reference] is"), "{}", stderr(&run));
}

/// Numbers the corners of `frames` from the other end (corner i → N − 1 − i), as
/// a detector does that takes the board for turned by 180°.
fn flip(d: &mut Dataset, frames: &[i64]) {
    let n = d.target.num_corners();
    for o in &mut d.observations {
        if frames.contains(&d.frame_ids[o.frame]) {
            o.corner = n - 1 - o.corner;
        }
    }
}

#[test]
fn frames_numbered_from_the_other_end_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let (mut d, _) = Generator::new(Preset::T2, Some(20), 6).generate();
    flip(&mut d, &[3, 17]);
    let mut d = write_csv(dir.path(), &d);
    csv_config(dir.path(), "c.toml", (13, 13, 0.07), "radial3", "");
    let run = deformcal(&["--config", dir.path().join("c.toml").to_str().unwrap()]);
    ok(&run);
    let warning = "frame 3, frame 17 show the board turned by about 180° in its plane against the other 18 frames: either it was held upside down there, or the corners were numbered from the other end of the board; that matters for `static` and `full` (their corrections belong to corners) and with several cameras: check the corner order in those images";
    assert!(
        stderr(&run).contains(&format!("warning: {warning}\n")),
        "{}",
        stderr(&run)
    );
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("out/calibration.json")).unwrap(),
    )
    .unwrap();
    assert!(json["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .any(|w| w == warning));
    // Turned back, nothing is named.
    flip(&mut d, &[3, 17]);
    let c: Calibration = calibrate(&d, &request(Method::Full)).unwrap();
    assert_eq!(lint::flipped_frames(&c, &Default::default()), None);
}

#[test]
fn opencv_yaml_gives_each_camera_its_own_rmse() {
    let dir = tempfile::tempdir().unwrap();
    let c = dir.path().join("c.toml");
    std::fs::write(
        &c,
        "[data]\nsynthetic = \"stereo\"\nimages = 15\n[calibration]\nmethod = \"full\"\n[output]\ndir = \"out\"\n",
    )
    .unwrap();
    ok(&deformcal(&["--config", c.to_str().unwrap()]));
    let yaml = std::fs::read_to_string(dir.path().join("out/opencv.yaml")).unwrap();
    // The same calibration in the library; each camera's RMSE over its own residuals.
    let (d, _) = Generator::new(Preset::Stereo, Some(15), 1).generate();
    let lib = calibrate(&d, &recommended(Method::Full)).unwrap();
    for (k, name) in ["cam0", "cam1"].iter().enumerate() {
        let (mut sq, mut n) = (0.0, 0);
        for (o, r) in lib.dataset.observations.iter().zip(lib.residuals.chunks(2)) {
            if o.camera == k {
                sq += r[0] * r[0] + r[1] * r[1];
                n += 1;
            }
        }
        let own = (sq / n as f64).sqrt();
        let line = yaml
            .lines()
            .find(|l| l.starts_with(&format!("{name}_avg_reprojection_error:")))
            .unwrap();
        let written: f64 = line.split(':').nth(1).unwrap().trim().parse().unwrap();
        assert!((written - own).abs() < 1e-9, "{name}: {written} vs {own}");
        assert!(
            (written - lib.rmse_px).abs() > 1e-6,
            "{name}: the overall RMSE"
        );
    }
}

/// A board spacing no board has (1e11 m) was calibrated with exit 0 and an RMSE
/// five times the noise's (1.05 px for 0.21): the translations dwarfed every
/// other parameter. Refused before any work with the key, its line and the
/// range; the same corners with the board's own spacing calibrate.
#[test]
fn an_absurd_board_spacing_is_refused_before_the_solve() {
    let dir = tempfile::tempdir().unwrap();
    let (d, _) = Generator::new(Preset::T2, Some(12), 5).generate();
    write_csv(dir.path(), &d);
    for (spacing, shown) in [(1e11, "1e11"), (70.0, "70"), (1e-7, "1e-7")] {
        csv_config(dir.path(), "bad.toml", (13, 13, spacing), "radial3", "");
        let run = deformcal(&["--config", dir.path().join("bad.toml").to_str().unwrap()]);
        let last = last_line(&run, 1);
        assert!(
            last.contains(
                "bad.toml: line 4: target.spacing must be a length in metres from 0.0001 to 10"
            ) && last.contains(&format!("(got {shown})")),
            "{last}"
        );
        assert!(!dir.path().join("out").exists());
    }
    csv_config(
        dir.path(),
        "good.toml",
        (13, 13, d.target.spacing),
        "radial3",
        "",
    );
    ok(&deformcal(&[
        "--config",
        dir.path().join("good.toml").to_str().unwrap(),
    ]));
}
