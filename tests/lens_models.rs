//! Every registered lens model end to end: unprojection over the whole image, the
//! chained Jacobian against autodiff, the four methods on rigid and bending
//! boards against the synthetic truth, a rig of two different models, fixed
//! parameters, and the protocol.
use crate::common;
use common::*;
use deformcal::model::metrics::mapping_error_rot;
use deformcal::model::synthetic::{true_intrinsics_of, Generator, Preset, Truth};
use deformcal::solver::problem::{Loss, SolverSettings};
use deformcal::{calibrate, Calibration, Dataset, LensModel, Method, Request};
use nalgebra::Vector2;

const WIDTH: u32 = 1936;
const HEIGHT: u32 = 1216;

/// A synthetic dataset seen through `models` (one per camera of the preset).
fn through(
    preset: Preset,
    models: &[LensModel],
    images: usize,
    seed: u64,
    bend: f64,
) -> (Dataset, Truth) {
    let mut g = Generator::new(preset, Some(images), seed).with_models(models);
    g.bend_scale = bend;
    g.print_scale = 0.0;
    g.generate()
}

#[test]
fn unprojection_round_trips_over_the_whole_image() {
    for model in LensModel::ALL {
        let k = true_intrinsics_of(model);
        let (mut valid, mut total, mut worst) = (0usize, 0usize, 0.0f64);
        for v in (0..HEIGHT).step_by(4) {
            for u in (0..WIDTH).step_by(4) {
                total += 1;
                let px = Vector2::new(u as f64, v as f64);
                if let Some(ray) = k.unproject(&px) {
                    valid += 1;
                    let back = k.project(&ray).expect("a valid ray projects");
                    worst = worst.max((back - px).norm());
                }
            }
        }
        eprintln!("{model}: {valid}/{total} pixels valid, worst round trip {worst:.2e} px");
        assert!(worst <= 1e-9, "{model}: round trip {worst} px");
        // Every simulated lens sees its whole image, but for the corners beyond
        // the double sphere's image circle.
        let share = valid as f64 / total as f64;
        assert!(
            share
                >= if model == LensModel::DoubleSphere {
                    0.99
                } else {
                    1.0
                },
            "{model}: {share}"
        );
    }
    // Beyond the fold of a strong barrel distortion there is no valid ray.
    let folded =
        deformcal::Intrinsics::pinhole(1000.0, 1000.0, 960.0, 608.0).with_param("k1", -0.6);
    assert!(folded.unproject(&Vector2::new(1900.0, 1200.0)).is_none());
    assert!(folded.unproject(&Vector2::new(1000.0, 650.0)).is_some());
}

#[test]
fn chained_jacobian_equals_autodiff_for_every_lens_model() {
    // Two-camera rigs so that each model appears behind a rig block too.
    let pairs = [
        [LensModel::OpenCv5, LensModel::Kb4],
        [LensModel::DoubleSphere, LensModel::OpenCv8],
        [LensModel::Kb4, LensModel::Radial3],
        // opencv8 keeps one block per corner (solver.cc, PreviousPath): ds also
        // beside another model, so that its per-view blocks are checked too.
        [LensModel::DoubleSphere, LensModel::OpenCv5],
    ];
    for models in pairs {
        let (d, _) = through(Preset::Stereo, &models, 12, 5, 1.0);
        for m in Method::ALL {
            let c = run(&d, m, Loss::Cauchy);
            assert_chained_equals_autodiff(&c.problem(), &c.state, &format!("{models:?} {m}"));
        }
    }
}

fn calibrate_with(d: &Dataset, method: Method) -> Calibration {
    calibrate(
        d,
        &Request {
            method,
            settings: SolverSettings::default(),
            gauge: None,
        },
    )
    .unwrap_or_else(|e| panic!("{method}: {e}"))
}

fn rot_error(c: &Calibration, t: &Truth) -> f64 {
    mapping_error_rot(&t.intrinsics[0], &c.state.intrinsics[0], WIDTH, HEIGHT)
}

/// Mean rotation-compensated mapping error to the truth of `method` over several
/// datasets: one dataset's error is mostly its noise draw.
fn mean_error(model: LensModel, bend: f64, method: Method) -> f64 {
    let seeds = 1..=SEEDS;
    let total: f64 = seeds
        .map(|seed| {
            let (d, t) = through(Preset::T2, &[model], 30, seed, bend);
            rot_error(&calibrate_with(&d, method), &t)
        })
        .sum();
    total / SEEDS as f64
}
const SEEDS: u64 = 4;

/// The largest ratio to the rigid floor allowed of (rigid boards, bent boards),
/// with the paper's model (no board prior). The issue's targets (1.3, 1.5) hold
/// for `radial3` and `opencv5` on these four sets only; they are not met in
/// general with the paper's model. Over 32 sets (`bending_board_experiment`)
/// `dynamic` and `full` cost 1.1–1.8× on rigid boards, and the covariance
/// predicts 1.24–1.40× (`dynamic`) and 1.49–1.64× (`full`): the paraboloid's
/// three parameters per image correlate with the intrinsics. A fixed bend prior
/// does not help (σ = 0.5 mm, a quarter of T2's real bends, lowers the rigid
/// `dynamic` ratio by 3 % at most); `bend_prior_mm = "auto"` and
/// `static_prior_mm` do, and meet the targets for every model
/// ([`recommended_settings_meet_the_lens_targets_over_32_sets`]).
fn allowed(model: LensModel) -> (f64, f64) {
    if matches!(
        model,
        LensModel::Radial3 | LensModel::OpenCv5 | LensModel::Pinhole
    ) {
        (1.3, 1.5)
    } else {
        (2.5, 2.0)
    }
}

#[test]
fn bending_boards_through_every_lens_model() {
    for model in LensModel::ALL {
        let (rigid_ratio, bent_ratio) = allowed(model);
        // The same poses and noise, once rigid and once bent as the T2 target.
        let floor = mean_error(model, 0.0, Method::Standard);
        let mut line = format!("{model}: rigid floor {floor:.3} px;");
        for m in &Method::ALL[1..] {
            let on_rigid = mean_error(model, 0.0, *m);
            line += &format!(" rigid {m} {on_rigid:.3} ({:.2}×)", on_rigid / floor);
            assert!(
                on_rigid <= rigid_ratio * floor,
                "{model} {m} on a rigid board: {on_rigid} vs standard {floor}"
            );
        }
        let standard = mean_error(model, 1.0, Method::Standard);
        let dynamic = mean_error(model, 1.0, Method::Dynamic);
        let full = mean_error(model, 1.0, Method::Full);
        eprintln!(
            "{line}; bent: standard {standard:.3} ({:.1}×) dynamic {dynamic:.3} ({:.2}×) full {full:.3} ({:.2}×)",
            standard / floor,
            dynamic / floor,
            full / floor
        );
        assert!(
            dynamic <= bent_ratio * floor,
            "{model} dynamic {dynamic} vs {floor}"
        );
        assert!(full <= bent_ratio * floor, "{model} full {full} vs {floor}");
        assert!(
            standard > 5.0 * floor,
            "{model} standard {standard} vs {floor}"
        );
    }
}

#[test]
fn a_fisheye_and_a_pinhole_camera_in_one_rig() {
    let (d, t) = through(
        Preset::Stereo,
        &[LensModel::Kb4, LensModel::OpenCv5],
        40,
        8,
        1.0,
    );
    let c = run(&d, Method::Dynamic, Loss::Cauchy);
    for k in 0..2 {
        assert_eq!(c.state.intrinsics[k].model(), t.intrinsics[k].model());
        let e = truth_error_rot(&c, &t, k);
        eprintln!("camera {k} ({}): {e:.3} px", t.intrinsics[k].model());
        assert!(e < 1.0, "camera {k}: {e} px");
    }
    let baseline = c.state.camera_poses[1]
        .inverse()
        .translation_vector()
        .norm();
    let true_baseline = t.camera_poses[1].inverse().translation_vector().norm();
    assert!(
        (baseline - true_baseline).abs() < 2e-3,
        "{baseline} vs {true_baseline}"
    );
}

#[test]
fn fixed_parameters_hold_and_opencv5_without_tangential_terms_is_radial3() {
    let (d, _) = through(Preset::T2, &[LensModel::Radial3], 25, 4, 0.0);
    let radial3 = run(&d, Method::Standard, Loss::Cauchy);
    let mut d5 = d.clone();
    d5.cameras[0].model = LensModel::OpenCv5;
    d5.cameras[0].fix = vec!["p1".into(), "p2".into()];
    let opencv5 = run(&d5, Method::Standard, Loss::Cauchy);
    let (a, b) = (radial3.state.intrinsics[0], opencv5.state.intrinsics[0]);
    assert_eq!(b.get("p1"), Some(0.0));
    assert_eq!(b.get("p2"), Some(0.0));
    for name in ["fx", "fy", "cx", "cy", "k1", "k2", "k3"] {
        let (x, y) = (a.get(name).unwrap(), b.get(name).unwrap());
        assert!(
            (x - y).abs() <= 1e-6 * x.abs().max(1.0),
            "{name}: {x} vs {y}"
        );
    }
    // Without the hold the tangential terms move.
    d5.cameras[0].fix.clear();
    let free = run(&d5, Method::Standard, Loss::Cauchy);
    assert_ne!(free.state.intrinsics[0].get("p1"), Some(0.0));
}

#[test]
fn protocol_runs_with_a_fisheye_model() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("kb4.toml");
    std::fs::write(
        &config,
        r#"
[[cameras]]
name = "fish"
width = 1936
height = 1216
model = "kb4"

[data]
synthetic = "t2"
images = 60

[reference]
synthetic = "reference"
images = 40

[protocol]
subsets = 3
images_per_subset = 15
methods = ["standard", "dynamic"]

[output]
dir = "out"
"#,
    )
    .unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .args(["protocol", "--config", config.to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let csv = std::fs::read_to_string(dir.path().join("out/protocol.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    // The intrinsics columns are kb4's.
    assert!(header.ends_with("fx,fy,cx,cy,k1,k2,k3,k4"), "{header}");
    assert_eq!(
        csv.lines().filter(|l| l.contains(",ok,")).count(),
        6,
        "{csv}"
    );
}

#[test]
fn export_refuses_intrinsics_of_another_model() {
    let (d, _) = through(Preset::T2, &[LensModel::OpenCv5], 8, 2, 0.0);
    let c = run(&d, Method::Standard, Loss::Cauchy);
    let dir = tempfile::tempdir().unwrap();
    deformcal::app::output::write_calibration(dir.path(), &c).unwrap();
    let text = std::fs::read_to_string(dir.path().join("calibration.json")).unwrap();
    let export = |json: &serde_json::Value| {
        let path = dir.path().join("edited.json");
        std::fs::write(&path, json.to_string()).unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_deformcal"))
            .args([
                "export",
                "--calibration",
                path.to_str().unwrap(),
                "--output",
            ])
            .arg(dir.path().join("models"))
            .output()
            .unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).to_string()
    };
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["cameras"][0]["model"] = "kb4".into();
    let stderr = export(&json);
    assert!(
        stderr.contains("cameras[0] `cam0`: model `kb4` needs the intrinsics fx, fy, cx, cy, k1, k2, k3, k4, but they are those of `opencv5`"),
        "{stderr}"
    );
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["cameras"][0]["intrinsics"]
        .as_object_mut()
        .unwrap()
        .remove("p1");
    let stderr = export(&json);
    assert!(stderr.contains("match no lens model"), "{stderr}");
}

/// Mean (or median) rotation-compensated mapping errors to the truth over seeds
/// 1..=`seeds` of 30-image T2-like sets, as ratios to the rigid floor.
struct Sweep {
    seeds: u64,
    settings: SolverSettings,
    fix: Vec<String>,
    median: bool,
    expected: bool,
    verbose: bool,
}

/// What one model gives in a [`Sweep`].
struct Ratios {
    /// `standard` on the rigid boards, px.
    floor: f64,
    /// `static`, `dynamic`, `full` on the rigid boards.
    rigid: [f64; 3],
    /// `standard`, `dynamic`, `full` on the bending boards.
    bent: [f64; 3],
    /// Sets whose calibration failed (left out of the means).
    failed: usize,
}

impl Sweep {
    fn error(&self, model: LensModel, bend: f64, method: Method, failed: &mut usize) -> f64 {
        use rayon::prelude::*;
        let e: Vec<f64> = (1..=self.seeds)
            .into_par_iter()
            .map(|seed| {
                let (mut d, t) = through(Preset::T2, &[model], 30, seed, bend);
                d.cameras[0].fix = self.fix.clone();
                let request = Request {
                    method,
                    settings: self.settings.clone(),
                    gauge: None,
                };
                match calibrate(&d, &request) {
                    Ok(c) if self.expected => c
                        .uncertainty()
                        .map_or(f64::NAN, |u| u[0].expected_mapping_error_rot_px),
                    Ok(c) => rot_error(&c, &t),
                    Err(_) => f64::NAN,
                }
            })
            .collect();
        if self.verbose {
            let v: Vec<String> = e.iter().map(|x| format!("{x:.3}")).collect();
            println!("  {model} {method} bend {bend}: {}", v.join(" "));
        }
        let mut ok: Vec<f64> = e.into_iter().filter(|x| x.is_finite()).collect();
        *failed += self.seeds as usize - ok.len();
        if self.median {
            // The means have heavy tails (single sets far off): the median too.
            ok.sort_by(f64::total_cmp);
            return (ok[(ok.len() - 1) / 2] + ok[ok.len() / 2]) / 2.0;
        }
        ok.iter().sum::<f64>() / ok.len() as f64
    }

    fn ratios(&self, model: LensModel) -> Ratios {
        let mut failed = 0;
        let floor = self.error(model, 0.0, Method::Standard, &mut failed);
        let mut ratio = |bend: f64, m: Method| self.error(model, bend, m, &mut failed) / floor;
        let rigid = [Method::Static, Method::Dynamic, Method::Full].map(|m| ratio(0.0, m));
        let bent = [Method::Standard, Method::Dynamic, Method::Full].map(|m| ratio(1.0, m));
        Ratios {
            floor,
            rigid,
            bent,
            failed,
        }
    }
}

const RATIO_HEADER: &str =
    "| model | rigid floor | static | dynamic | full | bent standard | dynamic | full |";

impl Ratios {
    fn row(&self, model: LensModel) -> String {
        let cells: Vec<String> = self
            .rigid
            .iter()
            .chain(&self.bent)
            .map(|r| format!("{r:.2}"))
            .collect();
        format!("| {model} | {:.4} | {} |", self.floor, cells.join(" | "))
    }
}

/// The experiment behind [`allowed`]: the ratios of the bending-board test over
/// more seeds, with board priors and fixed lens terms to compare
/// (`cargo test --release --test integration -- --ignored --nocapture`;
/// env `LENS_SEEDS`, `LENS_MODELS`, `LENS_STATIC_MM`, `LENS_BEND_MM`,
/// `LENS_BEND_AUTO` (`bend_prior_mm = "auto"`), `LENS_STATIC_AUTO`
/// (`static_prior_mm = "auto"`), `LENS_PRIOR` (σ, or `none`), `LENS_FIX`,
/// `LENS_MEDIAN` for medians, `LENS_EXPECTED` for the covariance's prediction).
#[test]
#[ignore]
fn bending_board_experiment() {
    let var = |k: &str| std::env::var(k).ok();
    let mm = |k: &str| var(k).and_then(|v| v.parse::<f64>().ok()).map(|v| v * 1e-3);
    let models: Vec<LensModel> = match var("LENS_MODELS") {
        Some(s) => s.split(',').filter_map(LensModel::parse).collect(),
        None => LensModel::ALL.to_vec(),
    };
    let mut settings = SolverSettings::default();
    settings.board.static_sigma_m = mm("LENS_STATIC_MM");
    settings.board.bend_sigma_m = mm("LENS_BEND_MM");
    settings.board.bend_sigma_auto = var("LENS_BEND_AUTO").is_some();
    settings.board.static_sigma_auto = var("LENS_STATIC_AUTO").is_some();
    if let Some(p) = var("LENS_PRIOR") {
        settings.lens_prior_sigma = p.parse().ok();
    }
    let sweep = Sweep {
        seeds: var("LENS_SEEDS").and_then(|v| v.parse().ok()).unwrap_or(16),
        settings,
        fix: var("LENS_FIX")
            .map(|s| s.split(',').map(String::from).collect())
            .unwrap_or_default(),
        median: var("LENS_MEDIAN").is_some(),
        expected: var("LENS_EXPECTED").is_some(),
        verbose: var("LENS_VERBOSE").is_some(),
    };
    println!("{RATIO_HEADER}");
    for model in models {
        let r = sweep.ratios(model);
        if r.failed > 0 {
            println!("  {model}: {} calibrations failed", r.failed);
        }
        println!("{}", r.row(model));
    }
}

/// Issue 12's targets, over 32 sets per model, with the recommended settings
/// (README, "Lens models"): `bend_prior_mm = "auto"`, `static_prior_mm` at the
/// board's print error (0.05 mm), the default lens prior. On rigid boards no
/// method is worse than `standard` by more than 1.3×; on bending boards `dynamic`
/// and `full` reach the rigid floor within 1.5× and `standard` does not.
#[test]
fn recommended_settings_meet_the_lens_targets_over_32_sets() {
    let mut settings = SolverSettings::default();
    settings.board.static_sigma_m = Some(0.05e-3);
    settings.board.bend_sigma_auto = true;
    let sweep = Sweep {
        seeds: 32,
        settings,
        fix: Vec::new(),
        median: false,
        expected: false,
        verbose: false,
    };
    eprintln!("{RATIO_HEADER}");
    for model in LensModel::ALL {
        let r = sweep.ratios(model);
        eprintln!("{}", r.row(model));
        assert_eq!(r.failed, 0, "{model}");
        assert!(
            r.rigid.iter().all(|&x| x <= 1.3),
            "{model}: rigid {:?}",
            r.rigid
        );
        assert!(
            r.bent[0] > 1.5,
            "{model}: standard on bending boards {}",
            r.bent[0]
        );
        assert!(
            r.bent[1..].iter().all(|&x| x <= 1.5),
            "{model}: bent {:?}",
            r.bent
        );
    }
}

/// Seeds on which one view had no pose under some candidate focal lengths, which
/// used to veto the candidates and fail the whole `ds` initialisation.
#[test]
fn ds_initialisation_survives_a_view_that_a_candidate_cannot_pose() {
    for (seed, bend) in [(14u64, 0.0), (7, 1.0)] {
        let (d, t) = through(Preset::T2, &[LensModel::DoubleSphere], 30, seed, bend);
        let method = if bend > 0.0 {
            Method::Dynamic
        } else {
            Method::Standard
        };
        let c = calibrate_with(&d, method);
        let e = rot_error(&c, &t);
        eprintln!(
            "seed {seed}: {} of 30 frames, mapping error to the truth {e:.3} px",
            c.dataset.num_frames()
        );
        assert!(e < 0.3, "seed {seed}: {e} px");
    }
}

/// `ds`'s cost has a second minimum along the valley where f and ξ trade off.
/// From the initialisation's start alone, seed 23 (rigid) ended there with every
/// method, 0.72 px from the truth, at an RMSE hardly above the truth's. The
/// registry's second start, kept when it ends lower, must find the true one.
#[test]
fn ds_second_start_finds_the_minimum_the_first_misses() {
    let (d, t) = through(Preset::T2, &[LensModel::DoubleSphere], 30, 23, 0.0);
    let c = calibrate_with(&d, Method::Standard);
    let e = rot_error(&c, &t);
    assert!(e < 0.1, "{e} px from the truth");
    let warm_starts = c
        .stages
        .iter()
        .take_while(|s| s.method == Method::Standard)
        .count();
    assert!(warm_starts >= 2, "the second start was not solved");
    // The start keeps the focal length that the central corners fix, f/(1 + ξ).
    let k = c.initial_intrinsics[0];
    let second = (LensModel::DoubleSphere.info().second_start.unwrap())(&k);
    let central = |k: &deformcal::model::lens::Intrinsics| k.params()[0] / (1.0 + k.params()[4]);
    assert!((central(&second) / central(&k) - 1.0).abs() < 1e-12);
    assert_eq!(&second.params()[4..], &[-0.2, 0.57]);
    for m in [
        LensModel::Radial3,
        LensModel::OpenCv5,
        LensModel::OpenCv8,
        LensModel::Kb4,
    ] {
        assert!(m.info().second_start.is_none(), "{m}");
    }
    // A fixed ξ keeps its initial value: the second start, which moves it, is skipped.
    let mut fixed = d.clone();
    fixed.cameras[0].fix = vec!["xi".into()];
    let c = calibrate_with(&fixed, Method::Standard);
    assert_eq!(
        c.state.intrinsics[0].params()[4],
        c.initial_intrinsics[0].params()[4]
    );
}

/// A `ds` lens with ξ = 0, α = 0.6 (not the preset's). On seed 10 the initial
/// poses of three views near 90° off axis used to lie in wrong basins (RMS
/// 186–453 px): under the Cauchy loss they pulled on nothing, and the first solve
/// hit its iteration cap 4.5 px from the truth from both starts. The fisheye
/// initialisation now poses such views from all their rays; on seed 1, where
/// the first solve still stops at 50× the optimum's cost, the frames are posed
/// again from the solved intrinsics and the solve repeated (`solver::repose`).
/// A clean set of the preset's lens sees no re-pose, only the two starts.
#[test]
fn frames_in_a_wrong_pose_basin_are_posed_again() {
    let swapped = |seed: u64| {
        let mut g =
            Generator::new(Preset::T2, Some(30), seed).with_models(&[LensModel::DoubleSphere]);
        g.intrinsics[0] = deformcal::model::lens::Intrinsics::from_params(
            LensModel::DoubleSphere,
            &[520.0, 519.4, 971.6, 606.4, 0.0, 0.6],
        )
        .unwrap();
        g.bend_scale = 0.0;
        g.print_scale = 0.0;
        g.generate()
    };
    let first_solves = |c: &Calibration| {
        c.stages
            .iter()
            .take_while(|s| s.method == Method::Standard)
            .count()
    };
    let (d, t) = swapped(10);
    let c = calibrate_with(&d, Method::Standard);
    let e = rot_error(&c, &t);
    assert!(c.converged, "{:?}", c.stages);
    assert!(e < 0.1, "seed 10: {e} px from the truth");
    assert!(
        c.rejected.len() < 10,
        "{} corners rejected",
        c.rejected.len()
    );

    let (d, t) = swapped(1);
    let c = calibrate_with(&d, Method::Dynamic);
    let e = rot_error(&c, &t);
    assert!(c.converged && e < 0.1, "seed 1: {e} px, {:?}", c.stages);
    assert!(
        first_solves(&c) > 2,
        "no frame was posed again: {:?}",
        c.stages
    );

    let (d, t) = through(Preset::T2, &[LensModel::DoubleSphere], 30, 5, 0.0);
    let c = calibrate_with(&d, Method::Standard);
    assert!(rot_error(&c, &t) < 0.1);
    assert_eq!(c.stages.len(), 2, "{:?}", c.stages);
}

/// On this set `standard` leaves a few corners hundreds of pixels off at a pole
/// of the rational model; the noise that weights the priors must not follow
/// them (it did: σ̂ = 278 px, and a 2 mm bend prior held 7 mm bends flat).
#[test]
fn a_bend_prior_on_the_rational_model_keeps_the_bends() {
    let (d, t) = through(Preset::T2, &[LensModel::OpenCv8], 30, 1, 1.0);
    let free = calibrate_with(&d, Method::Dynamic);
    let mut settings = SolverSettings::default();
    settings.board.bend_sigma_m = Some(2e-3);
    let held = calibrate(
        &d,
        &Request {
            method: Method::Dynamic,
            settings,
            gauge: None,
        },
    )
    .unwrap();
    let noise = held.settings.board.noise_px.unwrap();
    eprintln!(
        "prior noise {noise:.3} px; largest bend {:.2} → {:.2} mm; mapping error {:.3} → {:.3} px",
        free.max_out_of_plane() * 1e3,
        held.max_out_of_plane() * 1e3,
        rot_error(&free, &t),
        rot_error(&held, &t)
    );
    assert!(noise < 0.3, "{noise}");
    assert!(held.max_out_of_plane() > 0.8 * free.max_out_of_plane());
    assert!(rot_error(&held, &t) < 2.0 * rot_error(&free, &t) + 0.05);
}

/// The rational model's lens prior (`lens_prior`, on by default) against none:
/// over several sets it fits the corners as well (it is weak) and lands closer
/// to the true lens over the whole image; on seed 27 of the bent sets, `full`
/// without it wandered along the k1–k4 valley to 8.7 px at the image corners.
#[test]
fn the_lens_prior_holds_the_rational_model_where_the_corners_do_not() {
    let with = |prior: Option<f64>, static_mm: Option<f64>| SolverSettings {
        lens_prior_sigma: prior,
        board: deformcal::model::board::BoardPriors {
            static_sigma_m: static_mm.map(|v| v * 1e-3),
            ..Default::default()
        },
        ..SolverSettings::default()
    };
    let solve = |d: &Dataset, method: Method, settings: SolverSettings| {
        calibrate(
            d,
            &Request {
                method,
                settings,
                gauge: None,
            },
        )
        .unwrap()
    };
    let default = SolverSettings::default().lens_prior_sigma;
    let (mut free_sum, mut held_sum) = (0.0, 0.0);
    for seed in 1..=8 {
        let (d, t) = through(Preset::T2, &[LensModel::OpenCv8], 30, seed, 0.0);
        let free = solve(&d, Method::Standard, with(None, None));
        let held = solve(&d, Method::Standard, with(default, None));
        let (ef, eh) = (rot_error(&free, &t), rot_error(&held, &t));
        eprintln!(
            "seed {seed}: rmse {:.4} → {:.4} px, mapping error {ef:.3} → {eh:.3} px",
            free.rmse_px, held.rmse_px
        );
        assert!(held.rmse_px < 1.01 * free.rmse_px, "seed {seed}");
        (free_sum, held_sum) = (free_sum + ef, held_sum + eh);
    }
    assert!(held_sum < free_sum, "{held_sum} vs {free_sum}");
    let (d, t) = through(Preset::T2, &[LensModel::OpenCv8], 30, 27, 1.0);
    let free = rot_error(&solve(&d, Method::Full, with(None, Some(0.05))), &t);
    let held = rot_error(&solve(&d, Method::Full, with(default, Some(0.05))), &t);
    eprintln!("seed 27, bent, full: {free:.2} → {held:.3} px");
    assert!(held < 0.5 && held < free / 4.0, "{free} → {held}");
}

#[test]
fn lens_prior_in_the_config_is_a_sigma_or_none() {
    use deformcal::app::config::Config;
    let parse = |extra: &str| {
        Config::parse(
            &format!("[data]\nsynthetic = \"t2\"\n[calibration]\n{extra}"),
            std::path::Path::new("c.toml"),
        )
    };
    let sigma =
        |extra: &str| SolverSettings::from(&parse(extra).unwrap().calibration).lens_prior_sigma;
    assert_eq!(sigma(""), SolverSettings::default().lens_prior_sigma);
    assert_eq!(sigma("lens_prior = 0.5\n"), Some(0.5));
    assert_eq!(sigma("lens_prior = \"none\"\n"), None);
    for bad in [
        "lens_prior = -1\n",
        "lens_prior = \"off\"\n",
        "lens_prior = 0\n",
    ] {
        let e = parse(bad).unwrap_err().to_string();
        assert!(
            e.contains("lens_prior must be a positive number or \"none\"") && e.contains("line 4"),
            "{bad}: {e}"
        );
    }
}
