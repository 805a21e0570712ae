//! Times the evaluation protocol on the `t2` preset: 4 methods × 50 subsets × 25
//! images with the 650-image reference, on all cores. `SUBSETS=n cargo bench --bench
//! protocol` runs a shorter variant; `PER_CORNER=1` solves the subsets and the
//! test-error refits on the solver's previous path (one residual block per corner,
//! no warm-up; one Ceres problem per refit). It then times the CLI's path, which
//! calibrates the reference beside the subsets, and checks that its rows are the same.
//! `PHASES=n` then prints, over the first n subsets, the CPU of each part of a
//! task (each method's fit, its covariance and uncertainty figures, the test-error
//! refit, the mapping errors) and of the reference's parts: where the time goes.
use deformcal::app::config::{Config, ProtocolConfig};
use deformcal::app::protocol::{plan, prepare, test_rmse, Setup, TestError};
use deformcal::app::protocol_report::protocol_csv;
use deformcal::model::metrics::{grid_rays, mapping_error_of, mapping_error_rot_of};
use deformcal::solver::calibrate::{Request, SharedWarmStart};
use deformcal::solver::problem::SolverSettings;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

/// User plus system CPU time of this process: on a shared machine the wall time
/// also counts other processes' turns.
fn process_cpu_seconds() -> f64 {
    // SAFETY: getrusage fills the zeroed struct it is given.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    let s = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    s(u.ru_utime) + s(u.ru_stime)
}

/// CPU time of the calling thread.
fn thread_cpu_seconds() -> f64 {
    // SAFETY: clock_gettime fills the zeroed struct it is given.
    let mut t: libc::timespec = unsafe { std::mem::zeroed() };
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

fn main() {
    let subsets = std::env::var("SUBSETS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(50);
    // The paper's protocol, as configs/protocol_*.toml set it: no board priors
    // (the default, "auto", estimates them and costs about half a `full` solve).
    let config = Config::parse(
        "[data]\nsynthetic = \"t2\"\n[reference]\nsynthetic = \"reference\"\n\
         [calibration]\npriors = \"none\"\n",
        Path::new("bench.toml"),
    )
    .expect("bench config");
    let protocol = ProtocolConfig {
        subsets,
        ..ProtocolConfig::default()
    };
    let start = Instant::now();
    let mut setup = prepare(&config, &protocol).expect("setup");
    // PER_CORNER=1: the subsets on the solver's previous path (issue 17's reference).
    setup.settings.per_corner_blocks = std::env::var("PER_CORNER").is_ok();
    let prepared = start.elapsed().as_secs_f64();
    let prepared_cpu = process_cpu_seconds();
    let reference = setup.reference().expect("reference");
    let truth = setup.header.truth.as_ref().expect("truth");
    // The test-error refit at the true intrinsics (a subset's lie about as far from
    // the reference's), on the default and on the previous path: CPU ms, least of 5.
    let refit = |per_corner: bool| {
        let settings = SolverSettings {
            per_corner_blocks: per_corner,
            ..setup.settings.clone()
        };
        let mut best = (f64::INFINITY, f64::NAN);
        for _ in 0..5 {
            let c = thread_cpu_seconds();
            let e = test_rmse(reference, 0, &truth[0], &settings).expect("refit");
            best.0 = best.0.min(thread_cpu_seconds() - c);
            best.1 = e;
        }
        best
    };
    let (new, old) = (refit(false), refit(true));
    println!(
        "reference calibration + data: {prepared:.2} s ({prepared_cpu:.2} s CPU); one test-error refit on {} images, prepared and run once: {:.1} ms CPU (RMSE {:.12}), previous path {:.1} ms CPU (RMSE {:.12})",
        reference.dataset.num_frames(),
        new.0 * 1e3,
        new.1,
        old.0 * 1e3,
        old.1
    );
    let before_run = process_cpu_seconds();
    let t = Instant::now();
    let rows = setup.run(None, &|| {});
    let failed = rows.iter().filter(|r| !r.ok()).count();
    println!(
        "protocol: {} calibrations ({failed} failed) in {:.2} s ({:.2} s CPU) on {} threads; total {:.2} s wall, {:.2} s CPU without the refit timing above",
        rows.len(),
        t.elapsed().as_secs_f64(),
        process_cpu_seconds() - before_run,
        rayon::current_num_threads(),
        prepared + t.elapsed().as_secs_f64(),
        prepared_cpu + process_cpu_seconds() - before_run
    );

    if let Some(n) = std::env::var("PHASES").ok().and_then(|s| s.parse().ok()) {
        phases(&setup, n);
    }

    // The CLI's path: the reference calibrated beside the subsets. With
    // PER_CORNER=1 it would calibrate the reference on the previous path too.
    if setup.settings.per_corner_blocks {
        return;
    }
    // Each pool thread's CPU over the run: on a shared machine the wall time
    // cannot show whether both threads worked to the end, their CPU can (a
    // thread idle while the other works has that much less).
    let threads_before = rayon::broadcast(|_| thread_cpu_seconds());
    let before = process_cpu_seconds();
    let t = Instant::now();
    let planned = plan(&config, &protocol).expect("plan");
    let planning = t.elapsed().as_secs_f64();
    let (planned, beside) = planned
        .run_beside_reference(None, &|| {})
        .expect("protocol");
    let csv = |h, r| protocol_csv(h, r).expect("protocol.csv");
    assert!(
        csv(&planned.header, &beside) == csv(&setup.header, &rows),
        "the rows depend on when the reference is calibrated"
    );
    println!(
        "the CLI's path (data, then the reference beside the {} calibrations): {:.2} s wall, {:.2} s CPU; its data {planning:.2} s wall",
        beside.len(),
        t.elapsed().as_secs_f64(),
        process_cpu_seconds() - before
    );
    let per_thread: Vec<String> = rayon::broadcast(|_| thread_cpu_seconds())
        .iter()
        .zip(&threads_before)
        .map(|(a, b)| format!("{:.2}", a - b))
        .collect();
    println!(
        "  CPU of each pool thread over it (s): {}",
        per_thread.join(", ")
    );
}

/// `PHASES=n`: the thread CPU of each part of the protocol's work over the
/// first `n` subsets, done one after another as a task does them, and of the
/// reference calibration's parts (its stages' solve time, its covariance pass with the board's σ).
fn phases(setup: &Setup, n: usize) {
    let reference = setup.reference().expect("reference");
    let solves: f64 = reference.stages.iter().map(|s| s.seconds).sum();
    // Its covariance pass again (the calibration already holds it): Σ_θ and
    // the board's σ, the Jacobian evaluated once for both.
    let c = thread_cpu_seconds();
    let pass = deformcal::solver::uncertainty::unit_covariance(reference);
    let pass_cpu = thread_cpu_seconds() - c;
    assert!(
        pass.as_ref().ok() == reference.covariance.as_ref().ok(),
        "the covariance pass depends on when it runs"
    );
    let c = thread_cpu_seconds();
    let board = deformcal::app::board_json::of(reference);
    println!(
        "reference: {} stages, {} observations rejected; its solves {solves:.2} s wall, its covariance pass (Σ_θ and the board's σ) {pass_cpu:.2} s CPU, board.json from it {:.4} s CPU (σ {})",
        reference.stages.len(),
        reference.rejected.len(),
        thread_cpu_seconds() - c,
        if board.is_some_and(|b| b.correction_std.is_some()) { "present" } else { "none" }
    );
    let test = TestError::new(reference, 0, &setup.settings).expect("refit");
    let cam = &setup.header.cameras[0];
    let truth = &setup.header.truth.as_ref().expect("truth")[0];
    let grids = [
        grid_rays(&reference.state.intrinsics[0], cam.width, cam.height),
        grid_rays(truth, cam.width, cam.height),
    ];
    let mut cpu: BTreeMap<String, f64> = BTreeMap::new();
    let mut timed = |what: String, f: &mut dyn FnMut()| {
        let c = thread_cpu_seconds();
        f();
        *cpu.entry(what).or_default() += thread_cpu_seconds() - c;
    };
    let mut thetas = Vec::new();
    for subset in setup.subsets.iter().take(n) {
        let data = setup.dataset.subset(subset);
        let warm = SharedWarmStart::default();
        for method in &setup.header.methods {
            let request = Request {
                method: *method,
                settings: setup.settings.clone(),
                gauge: None,
            };
            let mut fitted = None;
            // The first deformation method's fit computes the shared warm start.
            timed(format!("fit: {method}"), &mut || {
                fitted = Some(warm.fit(&data, &request).expect("fit"))
            });
            let mut c = fitted.expect("fit");
            timed("covariance".into(), &mut || {
                c.covariance = deformcal::solver::uncertainty::unit_covariance(&c);
            });
            timed("uncertainty figures from it".into(), &mut || {
                c.assessment.uncertainty = c.uncertainty_at(c.assessment.trust.as_ref());
            });
            let theta = c.state.intrinsics[0];
            thetas.push(theta);
            timed("test-error refit".into(), &mut || {
                test.rmse_px(&theta).expect("refit");
            });
            timed("mapping errors (reference, truth)".into(), &mut || {
                for g in &grids {
                    std::hint::black_box((
                        mapping_error_of(g, &theta),
                        mapping_error_rot_of(g, &theta),
                    ));
                }
            });
        }
    }
    // The refits alone, again, the least of three rounds: steadier than the
    // sum above on a shared machine.
    let best = (0..3)
        .map(|_| {
            let c = thread_cpu_seconds();
            for theta in &thetas {
                std::hint::black_box(test.rmse_px(theta).expect("refit"));
            }
            thread_cpu_seconds() - c
        })
        .fold(f64::INFINITY, f64::min);
    println!(
        "  the {} test-error refits again, least of 3 rounds: {:.1} ms CPU per subset, {:.1} us per reference frame",
        thetas.len(),
        best / n.min(setup.subsets.len()) as f64 * 1e3,
        best / thetas.len() as f64 / reference.dataset.num_frames() as f64 * 1e6
    );
    compare_refits(&thetas, &test);
    let total: f64 = cpu.values().sum();
    for (what, s) in &cpu {
        println!(
            "  {what}: {:.1} ms CPU per subset ({:.0} %)",
            s / n as f64 * 1e3,
            100.0 * s / total
        );
    }
    println!(
        "  in all {:.1} ms CPU per subset: {:.2} s for {} subsets",
        total / n as f64 * 1e3,
        total / n as f64 * setup.subsets.len() as f64,
        setup.subsets.len()
    );
}

/// `REFIT_SAVE=file` writes the test errors of the phases' calibrations (one
/// per line, full precision); `REFIT_PREVIOUS=file` compares them with a saved
/// run's: a change of the refit must leave every value at the same optimum.
fn compare_refits(thetas: &[deformcal::model::lens::Intrinsics], test: &TestError) {
    let values: Vec<f64> = thetas
        .iter()
        .map(|t| test.rmse_px(t).expect("refit"))
        .collect();
    if let Ok(path) = std::env::var("REFIT_SAVE") {
        let text: String = values.iter().map(|v| format!("{v:e}\n")).collect();
        std::fs::write(&path, text).expect("REFIT_SAVE");
    }
    if let Ok(path) = std::env::var("REFIT_PREVIOUS") {
        let text = std::fs::read_to_string(&path).expect("REFIT_PREVIOUS");
        let previous: Vec<f64> = text.lines().map(|l| l.parse().expect("a value")).collect();
        assert_eq!(
            previous.len(),
            values.len(),
            "REFIT_PREVIOUS has another count"
        );
        let worst = values
            .iter()
            .zip(&previous)
            .map(|(a, b)| ((a - b) / b).abs())
            .fold(0.0, f64::max);
        println!(
            "  test errors against {path}: largest relative difference {worst:.1e} over {}",
            values.len()
        );
    }
}
