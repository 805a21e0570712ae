//! The evaluation protocol: reproducibility, sharding, and the paper's findings on
//! the synthetic presets (quick variants of configs/protocol_*.toml).
use deformcal::app::config::{Config, ProtocolConfig};
use deformcal::app::protocol::{
    draw_subsets, merge, plan, prepare, test_rmse, Setup, Shard, ShardFile, TestError,
};
use deformcal::app::protocol_report::{protocol_csv, summarise, Summary};
use deformcal::model::lens::Intrinsics;
use deformcal::model::synthetic::{Generator, Preset};
use deformcal::solver::problem::{rmse, Hold, Loss, Problem, SolverSettings, State};
use deformcal::{LensModel, Method};
use std::path::Path;
use std::process::Command;

fn config_of(
    preset: &str,
    reference_images: usize,
    subsets: usize,
    methods: &[Method],
) -> (Config, ProtocolConfig) {
    let text = format!(
        "[data]\nsynthetic = \"{preset}\"\n[reference]\nsynthetic = \"reference\"\nimages = {reference_images}\n"
    );
    let config = Config::parse(&text, Path::new("test.toml")).unwrap();
    let protocol = ProtocolConfig {
        subsets,
        images_per_subset: 25,
        seed: 7,
        methods: methods.to_vec(),
        auto: false,
    };
    (config, protocol)
}

fn setup(preset: &str, reference_images: usize, subsets: usize, methods: &[Method]) -> Setup {
    let (config, protocol) = config_of(preset, reference_images, subsets, methods);
    prepare(&config, &protocol).unwrap()
}

fn run_on(
    setup: &Setup,
    threads: usize,
    shard: Option<Shard>,
) -> Vec<deformcal::app::protocol::Row> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| setup.run(shard, &|| {}))
}

fn mean(s: &Summary, m: Method, key: &str) -> f64 {
    s.methods[m.name()].metrics[key].mean
}

#[test]
fn subsets_are_reproducible_distinct_and_in_range() {
    let a = draw_subsets(500, 25, 50, 7).unwrap();
    assert_eq!(a, draw_subsets(500, 25, 50, 7).unwrap());
    assert_ne!(a, draw_subsets(500, 25, 50, 8).unwrap());
    for s in &a {
        assert_eq!(s.len(), 25);
        assert!(s.windows(2).all(|w| w[0] < w[1]), "sorted and distinct");
        assert!(*s.last().unwrap() < 500);
    }
    assert_ne!(a[0], a[1]);
    assert!(draw_subsets(20, 25, 1, 7).is_err());
}

#[test]
fn same_seed_same_results_across_threads_and_shards() {
    // `dynamic` and `full` share each subset's warm start in a run; a task run
    // on its own computes its own, and so does a shard that holds one of them.
    let methods = [Method::Standard, Method::Dynamic, Method::Full];
    let s = setup("t2", 80, 3, &methods);
    let one = run_on(&s, 1, None);
    let two = run_on(&s, 2, None);
    assert_eq!(
        protocol_csv(&s.header, &one).unwrap(),
        protocol_csv(&s.header, &two).unwrap()
    );
    let alone: Vec<_> = (0..s.header.tasks()).map(|t| s.task(t)).collect();
    assert_eq!(
        protocol_csv(&s.header, &alone).unwrap(),
        protocol_csv(&s.header, &one).unwrap()
    );
    // The CLI's path: the reference calibrated beside the subsets, not before them.
    let (config, protocol) = config_of("t2", 80, 3, &methods);
    let planned = plan(&config, &protocol).unwrap();
    assert!(planned.header().reference.is_none());
    assert_eq!(planned.calibrations(None), one.len() + 1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let (beside, rows) = pool
        .install(|| planned.run_beside_reference(None, &|| {}))
        .unwrap();
    assert_eq!(beside.header, s.header);
    assert_eq!(
        protocol_csv(&s.header, &rows).unwrap(),
        protocol_csv(&s.header, &one).unwrap()
    );
    let shards: Vec<ShardFile> = (0..2)
        .map(|i| {
            let shard = Shard { index: i, count: 2 };
            ShardFile {
                header: s.header.clone(),
                shard: [i, 2],
                rows: run_on(&s, 2, Some(shard)),
            }
        })
        .collect();
    assert!(shards.iter().all(|f| !f.rows.is_empty()));
    let (header, merged) = merge(shards.clone()).unwrap();
    assert_eq!(header, s.header);
    assert_eq!(
        protocol_csv(&s.header, &merged).unwrap(),
        protocol_csv(&s.header, &one).unwrap()
    );
    // Incomplete or overlapping shard sets are refused.
    assert!(merge(vec![shards[0].clone()]).is_err());
    assert!(merge(vec![
        shards[0].clone(),
        shards[0].clone(),
        shards[1].clone()
    ])
    .is_err());
}

/// A reference that cannot be calibrated (2 images) fails the run beside the
/// subsets with its reason and no rows, as it fails `prepare`, and stops the
/// subsets not yet started.
#[test]
fn a_failing_reference_fails_the_run_beside_the_subsets() {
    let (config, protocol) = config_of("t2", 2, 4, &[Method::Standard]);
    // On one thread the reference runs first, so no subset is calibrated after
    // it failed: one tick, the reference's.
    let ticks = std::sync::atomic::AtomicUsize::new(0);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let planned = plan(&config, &protocol).unwrap();
    let err = pool
        .install(|| {
            planned.run_beside_reference(None, &|| {
                ticks.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            })
        })
        .err()
        .expect("a failed reference is an error")
        .to_string();
    assert!(err.contains("the reference calibration failed"), "{err}");
    assert_eq!(
        ticks.into_inner(),
        1,
        "subsets were calibrated after the reference failed"
    );
    let before = prepare(&config, &protocol).err().unwrap().to_string();
    assert_eq!(err, before);
}

/// `"auto"` among the protocol's methods: one more row per subset, with the method
/// `auto` chose, whose calibration is that method's on the same subset.
#[test]
fn protocol_records_the_auto_choice_per_subset() {
    let dir = tempfile::tempdir().unwrap();
    let text = "[data]\nsynthetic = \"t2\"\n[reference]\nsynthetic = \"reference\"\nimages = 80\n\
                [protocol]\nsubsets = 3\nmethods = [\"standard\", \"dynamic\", \"full\", \"auto\"]\n";
    let config = Config::parse(text, &dir.path().join("c.toml")).unwrap();
    let protocol = config.protocol.clone().unwrap();
    assert!(protocol.auto);
    assert_eq!(protocol.methods.len(), 3);
    let s = prepare(&config, &protocol).unwrap();
    assert_eq!(s.header.tasks(), 3 * 4);
    let rows = run_on(&s, 2, None);
    let autos: Vec<_> = rows.iter().filter(|r| r.auto).collect();
    assert_eq!(autos.len(), 3);
    // `auto` shares its subset's warm start with the fixed methods and still
    // gives what it gives on its own, with a warm start of its own.
    for (t, row) in rows.iter().enumerate().filter(|(_, r)| r.auto) {
        assert_eq!(*row, s.task(t), "task {t}");
    }
    for a in &autos {
        assert!(a.ok(), "{:?}", a.error);
        let sel = a.selection.as_ref().expect("auto's evidence");
        assert_eq!(sel.chosen, a.method);
        // The bending T2 board: auto keeps a method that models the bend (issue 14).
        assert!(
            matches!(a.method, Method::Dynamic | Method::Full),
            "{}",
            a.method
        );
        let fixed = rows
            .iter()
            .find(|r| r.subset == a.subset && r.is_fixed(a.method))
            .unwrap();
        assert_eq!(fixed.cameras[0].intrinsics, a.cameras[0].intrinsics);
        assert_eq!(
            fixed.cameras[0].truth_mapping_error_px,
            a.cameras[0].truth_mapping_error_px
        );
    }
    let sum = summarise(&s.header, &rows);
    assert_eq!(sum.auto_choices.values().sum::<usize>(), 3);
    assert_eq!(sum.methods["auto"].calibrations, 3);
    // Fixed-method statistics do not take in auto's rows.
    assert_eq!(sum.methods["dynamic"].calibrations, 3);
    let csv = String::from_utf8(protocol_csv(&s.header, &rows).unwrap()).unwrap();
    let auto_lines: Vec<&str> = csv
        .lines()
        .filter(|l| l.split(',').nth(1) == Some("auto"))
        .collect();
    assert_eq!(auto_lines.len(), 3);
    assert!(auto_lines
        .iter()
        .all(|l| l.contains(",dynamic,") || l.contains(",full,")));
    // Shards that split auto's tasks merge back into the same rows.
    let shards: Vec<ShardFile> = (0..2)
        .map(|i| ShardFile {
            header: s.header.clone(),
            shard: [i, 2],
            rows: run_on(&s, 1, Some(Shard { index: i, count: 2 })),
        })
        .collect();
    let (_, merged) = merge(shards).unwrap();
    assert_eq!(merged, rows);
    // `auto` twice is refused with the key named.
    let twice = text.replace("\"full\", \"auto\"", "\"auto\", \"auto\"");
    let err = Config::parse(&twice, &dir.path().join("c.toml"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("auto") && err.contains("twice"), "{err}");
}

#[test]
fn deformation_methods_win_on_carried_targets() {
    let methods = Method::ALL;
    for preset in ["t1", "t2"] {
        let s = setup(preset, 150, 6, &methods);
        let rows = run_on(&s, 2, None);
        assert!(
            rows.iter().all(|r| r.ok()),
            "{preset}: a calibration failed"
        );
        let sum = summarise(&s.header, &rows);
        for m in [Method::Dynamic, Method::Full] {
            for key in [
                "test_rmse_px",
                "truth_mapping_error_px",
                "truth_mapping_error_rot_px",
            ] {
                let (ours, standard) = (mean(&sum, m, key), mean(&sum, Method::Standard, key));
                assert!(
                    ours < standard,
                    "{preset} {m} {key}: {ours} not below standard {standard}"
                );
            }
            assert!(
                mean(&sum, m, "truth_mapping_error_rot_px")
                    < 0.5 * mean(&sum, Method::Standard, "truth_mapping_error_rot_px")
            );
        }
        // Table S2: the dynamic method sees bends of the preset's size (T1 2.6 mm, T2 1.7 mm).
        let bend = mean(&sum, Method::Dynamic, "max_out_of_plane_m");
        assert!(bend > 1e-3 && bend < 5e-3, "{preset}: mean bend {bend}");
    }
}

#[test]
fn small_stiff_target_methods_are_close() {
    let s = setup(
        "t4",
        150,
        6,
        &[Method::Standard, Method::Dynamic, Method::Full],
    );
    let sum = summarise(&s.header, &run_on(&s, 2, None));
    let tests: Vec<f64> = [Method::Standard, Method::Dynamic, Method::Full]
        .iter()
        .map(|&m| mean(&sum, m, "test_rmse_px"))
        .collect();
    let (lo, hi) = tests
        .iter()
        .fold((f64::MAX, 0.0f64), |(a, b), &v| (a.min(v), b.max(v)));
    assert!(hi / lo < 1.15, "T4 test errors differ too much: {tests:?}");
}

#[test]
fn nothing_overfits_on_a_rigid_board() {
    let s = setup("reference", 150, 6, &Method::ALL);
    let sum = summarise(&s.header, &run_on(&s, 2, None));
    let standard_test = mean(&sum, Method::Standard, "test_rmse_px");
    for m in [Method::Static, Method::Dynamic, Method::Full] {
        // Train error falls with more parameters; test error must not rise beyond noise.
        assert!(mean(&sum, m, "rmse_px") <= mean(&sum, Method::Standard, "rmse_px") + 1e-9);
        let t = mean(&sum, m, "test_rmse_px");
        assert!(
            t < standard_test * 1.02,
            "{m}: test error {t} vs standard {standard_test}"
        );
    }
}

#[test]
fn pose_only_refit_evaluates_like_the_general_problem() {
    let s = setup("t2", 40, 1, &[Method::Standard]);
    let r = s.reference().unwrap();
    let settings = SolverSettings::default();
    let problem = |hold| Problem {
        hold,
        ..r.problem()
    };
    let held = Hold {
        intrinsics: true,
        camera_poses: true,
        corrections: true,
        deformations: true,
    };
    let plain = SolverSettings {
        loss: deformcal::solver::problem::Loss::None,
        ..settings.clone()
    };
    let general = problem(Hold::default())
        .evaluate(&r.state, &settings, false)
        .unwrap();
    for st in [&settings, &plain] {
        let fast = problem(held).evaluate(&r.state, st, false).unwrap();
        assert_eq!(fast.residuals.len(), general.residuals.len());
        for (a, b) in fast.residuals.iter().zip(&general.residuals) {
            assert!((a - b).abs() < 1e-9, "{a} vs {b}");
        }
    }
}

/// Tolerances tight enough that Ceres stops at the optimum to round-off.
pub(crate) fn converged(settings: &SolverSettings) -> SolverSettings {
    SolverSettings {
        function_tolerance: 1e-16,
        gradient_tolerance: 1e-16,
        parameter_tolerance: 1e-16,
        max_iterations: 500,
        ..settings.clone()
    }
}

/// The test error's per-frame refit against the previous path (one Ceres problem
/// over all 40 reference frames, static corrections held): the same optimum, at
/// the reference's own intrinsics and at intrinsics far from both.
#[test]
fn test_error_refit_frame_by_frame_matches_the_joint_ceres_solve() {
    let s = setup("t2", 40, 1, &[Method::Standard]);
    let r = s.reference().unwrap();
    let truth = s.header.truth.as_ref().unwrap()[0];
    let away = truth
        .with_param("fx", truth.fx() + 3.0)
        .with_param("cy", truth.cy() - 2.0)
        .with_param("k1", truth.get("k1").unwrap() + 0.05);
    let previous = SolverSettings {
        per_corner_blocks: true,
        ..s.settings.clone()
    };
    for theta in [r.state.intrinsics[0], truth, away] {
        let fast = test_rmse(r, 0, &theta, &s.settings).unwrap();
        let joint = test_rmse(r, 0, &theta, &converged(&previous)).unwrap();
        let today = test_rmse(r, 0, &theta, &previous).unwrap();
        assert!((fast - joint).abs() <= 1e-9 * joint, "{fast} vs {joint}");
        // The previous path at its default tolerances stops a little short.
        assert!(fast <= today * (1.0 + 1e-12), "{fast} vs {today}");
        assert!((fast - today).abs() <= 1e-7 * today, "{fast} vs {today}");
    }
    // At the truth the refit leaves about the noise (the reference preset's
    // σ = 0.15 px per axis: √2 σ per corner, less the 6 poses' share and what
    // the reference's correction misses); intrinsics 3 px away leave clearly more.
    let noise = Preset::Reference.spec().noise_px * 2f64.sqrt();
    let at_truth = test_rmse(r, 0, &truth, &s.settings).unwrap();
    assert!(
        (at_truth - noise).abs() < 0.1 * noise,
        "{at_truth} vs {noise}"
    );
    let at_away = test_rmse(r, 0, &away, &s.settings).unwrap();
    assert!(at_away > 1.5 * at_truth, "{at_away} vs {at_truth}");

    // One prepared refit, shared by threads as the protocol's rows share it,
    // starts every refit from the reference's poses: each value is the one-shot
    // joint solve's, whatever ran before it and on whichever thread.
    let prepared = TestError::new(r, 0, &s.settings).unwrap();
    let thetas = [away, truth, r.state.intrinsics[0], away, truth];
    let shared: Vec<f64> = std::thread::scope(|scope| {
        let handles: Vec<_> = thetas
            .iter()
            .map(|theta| scope.spawn(|| prepared.rmse_px(theta).unwrap()))
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for (theta, e) in thetas.iter().zip(&shared) {
        let joint = test_rmse(r, 0, theta, &converged(&previous)).unwrap();
        assert!((e - joint).abs() <= 1e-9 * joint, "{e} vs {joint}");
        assert_eq!(*e, prepared.rmse_px(theta).unwrap());
    }
    // Intrinsics of the wrong length are refused, not read past.
    let wide = Intrinsics::pinhole_of(
        LensModel::OpenCv8,
        truth.fx(),
        truth.fy(),
        truth.cx(),
        truth.cy(),
    );
    let err = prepared.rmse_px(&wide);
    assert!(err.is_err());
}

/// The per-frame refit with a rig, held per-image bends and weighted
/// observations: the same poses and residuals as the joint Ceres solve; the
/// held parameters untouched; a problem that is no pose-only refit refused.
/// Every lens model, each in a rig with the next one of the registry (the
/// refit chains each model's closed-form projection Jacobian by hand).
#[test]
fn per_frame_pose_refit_matches_the_joint_solve_with_a_rig_and_weights() {
    let (data, start) = rig_refit_case(None);
    let tight = Agreement {
        pose: 1e-9,
        residual_px: 1e-7,
    };
    refit_matches_joint_solve(&data, &start, "radial3 rig", tight);
    // Through wide lenses both solvers end at the same weighted cost (to 1e-10)
    // with poses a few 1e-9 apart: the cost is that flat along some directions.
    let all = LensModel::ALL;
    for (m, &model) in all.iter().enumerate() {
        let models = [model, all[(m + 1) % all.len()]];
        let (data, start) = rig_refit_case(Some(&models));
        let tol = Agreement {
            pose: 1e-8,
            residual_px: 1e-6,
        };
        refit_matches_joint_solve(&data, &start, &format!("{models:?}"), tol);
    }
    let problem = held_dynamic(&data);
    let plain = SolverSettings {
        loss: Loss::None,
        ..SolverSettings::default()
    };
    // With a loss, or the intrinsics free, frames are not independent.
    let robust = SolverSettings::default();
    assert!(problem.refit_poses(&mut start.clone(), &robust).is_err());
    let free = Problem {
        hold: Hold::default(),
        ..problem.clone()
    };
    assert!(free.refit_poses(&mut start.clone(), &plain).is_err());
}

/// The whole command line: sharded and merged outputs equal one unsharded run's, file by file.
#[test]
fn cli_shards_merge_into_the_unsharded_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("p.toml");
    std::fs::write(
        &config,
        "[data]\nsynthetic = \"t2\"\n[reference]\nsynthetic = \"reference\"\nimages = 60\n[protocol]\nsubsets = 3\nmethods = [\"standard\", \"dynamic\"]\n[output]\ndir = \"whole\"\n",
    )
    .unwrap();
    let bin = env!("CARGO_BIN_EXE_deformcal");
    let run = |args: &[&str]| {
        let out = Command::new(bin).args(args).output().unwrap();
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let c = config.to_str().unwrap();
    run(&["protocol", "--config", c, "--threads", "1"]);
    let shards = dir.path().join("shards");
    for i in 0..2 {
        run(&[
            "protocol",
            "--config",
            c,
            "--threads",
            "2",
            "--shard",
            &format!("{i}/2"),
            "--output",
            shards.to_str().unwrap(),
        ]);
    }
    let merged = dir.path().join("merged");
    run(&[
        "merge",
        "--output",
        merged.to_str().unwrap(),
        shards.join("shard-0-of-2.json").to_str().unwrap(),
        shards.join("shard-1-of-2.json").to_str().unwrap(),
    ]);
    let whole = dir.path().join("whole");
    for f in [
        "protocol.csv",
        "summary.json",
        "report.md",
        "report.html",
        "deformations.csv",
        "rmse.svg",
        "intrinsics.svg",
        "mapping.svg",
        "bend.svg",
        "deformation.svg",
        deformcal::app::protocol::REFERENCE_BOARD_JSON,
    ] {
        let a = std::fs::read(whole.join(f)).unwrap_or_else(|_| panic!("missing {f}"));
        assert_eq!(a, std::fs::read(merged.join(f)).unwrap(), "{f} differs");
    }
    let csv = std::fs::read_to_string(whole.join("protocol.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 3 * 2);
    let report = std::fs::read_to_string(whole.join("report.md")).unwrap();
    assert!(
        report.contains("Train and test error") && report.contains("![mapping error](mapping.svg)")
    );
}

#[test]
fn a_failed_subset_is_recorded_and_the_run_goes_on() {
    // Ten images, six of them with only three corners: subsets of four images
    // sometimes keep fewer than the three usable images a calibration needs.
    let (mut d, _) =
        deformcal::model::synthetic::generate(deformcal::model::synthetic::Preset::T2, Some(10), 4);
    d.observations.retain(|o| o.frame < 4 || o.corner < 3);
    let dir = tempfile::tempdir().unwrap();
    deformcal::app::observations_csv::write(&d, &dir.path().join("obs.csv")).unwrap();
    let config = Config::parse(
        "[target]\nrows = 13\ncols = 13\nspacing = 0.07\n[[cameras]]\nname = \"cam0\"\nwidth = 1936\nheight = 1216\n[data]\nobservations = \"obs.csv\"\n",
        &dir.path().join("c.toml"),
    )
    .unwrap();
    let protocol = ProtocolConfig {
        subsets: 12,
        images_per_subset: 4,
        seed: 1,
        methods: vec![Method::Standard],
        auto: false,
    };
    let s = prepare(&config, &protocol).unwrap();
    let rows = run_on(&s, 2, None);
    assert_eq!(rows.len(), 12);
    let failed: Vec<_> = rows.iter().filter(|r| !r.ok()).collect();
    assert!(
        !failed.is_empty() && failed.len() < rows.len(),
        "{} of {} failed",
        failed.len(),
        rows.len()
    );
    for r in &failed {
        assert!(
            r.error.as_deref().unwrap().contains("usable image"),
            "{:?}",
            r.error
        );
        assert!(r.cameras.is_empty() && r.rmse_px.is_none());
    }
    let sum = summarise(&s.header, &rows);
    assert_eq!(sum.methods["standard"].failed, failed.len());
    let csv = String::from_utf8(protocol_csv(&s.header, &rows).unwrap()).unwrap();
    assert_eq!(csv.matches(",failed,").count(), failed.len());
}

/// The shipped batch configs through `deformcal batch`, quick: one combined report.
#[test]
fn cli_batch_writes_one_combined_report() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .arg("batch")
        .arg(root.join("configs/protocol_t4.toml"))
        .arg(root.join("configs/protocol_reference.toml"))
        .args(["--subsets", "2", "--output"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(
        report.contains("## Dataset `t4`") && report.contains("## Dataset `reference`"),
        "{report}"
    );
    assert!(report.contains("(protocol_t4/rmse.svg)"));
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(
        html.contains("id=\"dataset-t4\"") && html.contains("id=\"dataset-reference\""),
        "the combined report.html lacks a dataset"
    );
    for name in ["protocol_t4", "protocol_reference"] {
        let csv = std::fs::read_to_string(dir.path().join(name).join("protocol.csv")).unwrap();
        assert_eq!(csv.lines().count(), 1 + 2 * 4, "{name}");
        assert!(!csv.contains(",failed,"), "{name}: {csv}");
        assert!(dir.path().join(name).join("mapping.svg").exists());
    }
}

/// A 2-camera rig (of `models`, the preset's lenses without) on 8 bent T2
/// frames, a third of the corners weighted 0.5, started at the truth with every
/// frame pose moved.
pub(crate) fn rig_refit_case(models: Option<&[LensModel]>) -> (deformcal::Dataset, State) {
    let gen = Generator::new(Preset::T2, Some(8), 3).with_cameras(2);
    let gen = match models {
        Some(m) => gen.with_models(m),
        None => gen,
    };
    let (mut data, truth) = gen.generate();
    for (i, o) in data.observations.iter_mut().enumerate() {
        if i % 3 == 0 {
            o.weight = 0.5;
        }
    }
    let mut start = State::rigid(
        truth.intrinsics.clone(),
        truth.camera_poses.clone(),
        truth.frame_poses.clone(),
        &data.target,
    );
    start.deformations = truth.deformations.clone();
    for (j, p) in start.frame_poses.iter_mut().enumerate() {
        p.rotation[j % 3] += 0.01;
        p.translation[(j + 1) % 3] += 0.005;
    }
    (data, start)
}

/// `dynamic` with everything but the board poses held: a pose-only refit.
pub(crate) fn held_dynamic(data: &deformcal::Dataset) -> Problem<'_> {
    Problem {
        dataset: data,
        method: Method::Dynamic,
        gauge: Vec::new(),
        frozen: Vec::new(),
        hold: Hold {
            intrinsics: true,
            camera_poses: true,
            corrections: true,
            deformations: true,
        },
    }
}

/// How close the per-frame refit and the joint solve must end.
struct Agreement {
    /// Largest difference of a pose value (rad, m).
    pose: f64,
    /// Largest difference of a residual (px).
    residual_px: f64,
}

/// The per-frame refit of `start` ends where the joint Ceres solve does.
fn refit_matches_joint_solve(data: &deformcal::Dataset, start: &State, case: &str, tol: Agreement) {
    let problem = held_dynamic(data);
    let plain = SolverSettings {
        loss: Loss::None,
        ..SolverSettings::default()
    };
    let (mut joint, mut fast) = (start.clone(), start.clone());
    let a = problem.solve(&mut joint, &converged(&plain)).unwrap();
    let b = problem.refit_poses(&mut fast, &plain).unwrap();
    assert!(b.converged && b.iterations > 0, "{case}");
    // The weighted cost both minimise; the RMSE of the unweighted residuals
    // varies to first order with poses off by round-off.
    let (ca, cb) = (a.final_cost, b.final_cost);
    assert!((ca - cb).abs() <= 1e-10 * ca, "{case}: cost {ca} vs {cb}");
    let (ea, eb) = (rmse(&a.residuals), rmse(&b.residuals));
    assert!(
        (ea - eb).abs() <= 10.0 * tol.pose * ea,
        "{case}: {ea} vs {eb}"
    );
    // Far below the 0.2 px noise: the poses came back from their offsets.
    assert!(eb < 0.5, "{case}: {eb}");
    for (x, y) in a.residuals.iter().zip(&b.residuals) {
        assert!((x - y).abs() < tol.residual_px, "{case}: {x} vs {y}");
    }
    for (p, q) in joint.frame_poses.iter().zip(&fast.frame_poses) {
        for i in 0..3 {
            assert!((p.rotation[i] - q.rotation[i]).abs() < tol.pose, "{case}");
            assert!(
                (p.translation[i] - q.translation[i]).abs() < tol.pose,
                "{case}"
            );
        }
    }
    assert_eq!(fast.intrinsics, start.intrinsics);
    assert_eq!(fast.camera_poses, start.camera_poses);
    assert_eq!(fast.deformations, start.deformations);
}
