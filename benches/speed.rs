//! The solver's speed against its previous path (issue 17), and its cost growth.
//!
//! `cargo bench --bench speed` times whole calibrations (initialisation, the
//! `standard` warm start, the method, outlier rejection; no covariance) of
//! 25-image `t2` subsets for every lens model and method, one thread (CPU time
//! of the calibrating thread, since the machine may be shared), on the
//! default path (one residual block per view where the board model allows,
//! the loss-free warm-up from far starts) and on the previous one
//! (`per_corner_blocks`: one block per corner, Ceres' Cauchy loss throughout),
//! and checks that they reach the same intrinsics: the mapping error to the
//! optimum converged with tolerances of 1e-15 must stay within 0.01 px on every
//! subset for the new path (the run fails otherwise); the old path's own
//! distance to it and the distance between the two paths are printed beside it.
//! Where the new path rejected other observations than that optimum (greedy
//! rejection of misfit residuals near k·σ depends on the path), it is checked
//! against the converged optimum of the observations it kept instead, and how
//! far the two rules' optima lie apart is printed.
//! (The old path stops early on its slow Cauchy tail: on one subset it kept an
//! outlier the converged optimum rejects, 0.17 px away from it.)
//! `-- radial3` limits it to one lens model.
//!
//! `-- growth N...` instead times one `standard` and one `full` calibration of N
//! images each (time per image, for the README's cost-growth table); run one
//! size per process under `/usr/bin/time -v` for its peak memory. Method names
//! among the arguments (`-- growth 10000 standard`) time only those. A result
//! that rejected observations is checked against the previous pipeline's
//! answer, the kept observations fitted afresh (within 0.01 px, the run fails
//! otherwise); `SPEED_DIAG=1` lists each result's stages, `SPEED_VERBOSE=1`
//! prints Ceres' iterations and its timing report. `SPEED_SAVE=file` appends
//! each result's intrinsics to `file`, and `SPEED_PREVIOUS=file` prints each
//! result's mapping error to the same size and method there (a run of another
//! build), failing beyond 0.01 px: a change of the solver path must not move
//! the answer.
//!
//! `-- refit N... [method...] [model...]` (default `standard` and `static`,
//! `radial3`, `opencv5`, `opencv8`, `kb4`) compares, where a calibration
//! rejected observations, its result with the kept observations fitted afresh
//! (the rule before a few rejected were solved on): each one's mapping error
//! to the optimum of the kept observations converged with tolerances of 1e-15
//! (from both answers, the lower cost kept; how far apart those two ends are),
//! and the time of each refit.
use deformcal::model::metrics::mapping_error;
use deformcal::model::synthetic::{Generator, Preset};
use deformcal::solver::problem::SolverSettings;
use deformcal::{calibrate, Calibration, LensModel, Method, Request};
use std::time::Instant;

/// Timed runs per subset, path and method (the best is kept: the machine is shared).
const REPEATS: usize = 3;
/// 25-image subsets (seeds) per lens model.
const SUBSETS: u64 = 3;
/// The largest mapping error between the two paths' intrinsics.
const SAME_ANSWER_PX: f64 = 0.01;

/// This thread's CPU time in milliseconds: the machine is shared, and the
/// calibrations run on one thread, so CPU time is what the solver costs.
pub fn thread_cpu_ms() -> f64 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec, which `t` is.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    t.tv_sec as f64 * 1e3 + t.tv_nsec as f64 * 1e-6
}

/// Least CPU time of `REPEATS` calibrations, the last result and its solver time.
fn time(dataset: &deformcal::Dataset, request: &Request) -> (f64, f64, Calibration) {
    let mut best = f64::INFINITY;
    let mut c = calibrate(dataset, request).expect("calibration");
    for _ in 0..REPEATS {
        let start = thread_cpu_ms();
        c = calibrate(dataset, request).expect("calibration");
        best = best.min(thread_cpu_ms() - start);
    }
    let solver_ms = c.stages.iter().map(|s| s.seconds).sum::<f64>() * 1e3;
    (best, solver_ms, c)
}

fn request(method: Method, per_corner_blocks: bool) -> Request {
    Request {
        method,
        settings: SolverSettings {
            per_corner_blocks,
            // Ceres' per-iteration lines and its timing report on stderr.
            verbose: std::env::var("SPEED_VERBOSE").is_ok(),
            ..SolverSettings::default()
        },
        gauge: None,
    }
}

/// The optimum converged far beyond the default tolerances (old path).
fn tight_optimum(dataset: &deformcal::Dataset, method: Method) -> Calibration {
    let mut r = request(method, true);
    r.settings.function_tolerance = 1e-15;
    r.settings.parameter_tolerance = 1e-15;
    r.settings.gradient_tolerance = 1e-15;
    r.settings.max_iterations = 1000;
    calibrate(dataset, &r).expect("tight calibration")
}

/// The optimum of `kept` (a result's observations after its rejection)
/// converged as [`tight_optimum`], rejecting nothing more.
fn tight_on_kept(kept: &deformcal::Dataset, method: Method) -> Calibration {
    let mut r = request(method, true);
    r.settings.function_tolerance = 1e-15;
    r.settings.parameter_tolerance = 1e-15;
    r.settings.gradient_tolerance = 1e-15;
    r.settings.max_iterations = 1000;
    r.settings.outlier_k = 0.0;
    calibrate(kept, &r).expect("tight calibration of the kept observations")
}

/// The observations a calibration rejected, as (camera, frame, corner).
fn rejected_set(c: &Calibration) -> Vec<(String, i64, usize)> {
    let mut v: Vec<_> = c
        .rejected
        .iter()
        .map(|s| (s.camera.clone(), s.frame, s.corner))
        .collect();
    v.sort();
    v
}

/// One lens model: every method, both paths, on `SUBSETS` subsets.
fn compare_paths(model: LensModel) -> bool {
    println!("{model}: t2 preset, 25 images, {SUBSETS} subsets, best of {REPEATS}, 1 thread");
    println!(
        "  {:9} {:>10} {:>10} {:>7} {:>10} {:>10} {:>7} {:>8} {:>8} {:>8} {:>8}",
        "method",
        "old ms",
        "old Ceres",
        "iters",
        "new ms",
        "new Ceres",
        "iters",
        "speed-up",
        "old-new",
        "old-opt",
        "new-opt"
    );
    println!("  (ms: least CPU time of a whole calibration incl. covariance; Ceres: its solver stages (wall);");
    println!(
        "   mapping errors in px, worst subset; opt: the optimum converged with tolerances 1e-15,"
    );
    println!("   which the new path must reach within {SAME_ANSWER_PX} px)");
    let mut ok = true;
    for method in Method::ALL {
        let (mut old, mut new) = ([0.0; 3], [0.0; 3]);
        let (mut worst, mut worst_old, mut worst_new): (f64, f64, f64) = (0.0, 0.0, 0.0);
        let (mut worst_rule, mut other_rejections) = (0.0_f64, 0_usize);
        for seed in 0..SUBSETS {
            let (dataset, _) = Generator::new(Preset::T2, Some(25), 7 + seed)
                .with_models(&[model])
                .generate();
            let (a_ms, a_solver, a) = time(&dataset, &request(method, true));
            let (b_ms, b_solver, b) = time(&dataset, &request(method, false));
            let cam = &dataset.cameras[0];
            let e = mapping_error(
                &a.state.intrinsics[0],
                &b.state.intrinsics[0],
                cam.width,
                cam.height,
            );
            let tight = tight_optimum(&dataset, method);
            let to = |c: &Calibration, optimum: &Calibration| {
                mapping_error(
                    &c.state.intrinsics[0],
                    &optimum.state.intrinsics[0],
                    cam.width,
                    cam.height,
                )
            };
            // mrcal's rejection is greedy: each round drops what lies beyond k·σ
            // after a one-step re-solve, so where a rigid model leaves misfit
            // residuals near k·σ (a bent board), which of them go depends on the
            // path, and each moves the intrinsics by about 0.01 px. The solver
            // is then checked against the converged optimum of the observations
            // it kept, and the two rules' distance is printed beside it.
            let (new_optimum, rule) = if rejected_set(&b) == rejected_set(&tight) {
                (tight.clone(), 0.0)
            } else {
                let kept = tight_on_kept(&b.dataset, method);
                let rule = to(&kept, &tight);
                (kept, rule)
            };
            if std::env::var("SPEED_DIAG").is_ok() {
                println!(
                    "    seed {seed}: rejected old {} new {} converged {}; to the converged optimum: old {:.4} new {:.4} px{}",
                    a.rejected.len(),
                    b.rejected.len(),
                    tight.rejected.len(),
                    to(&a, &tight),
                    to(&b, &new_optimum),
                    if rule > 0.0 {
                        format!(" (of its kept observations, {rule:.4} px from the converged one's)")
                    } else {
                        String::new()
                    }
                );
            }
            worst_old = worst_old.max(to(&a, &tight));
            worst_new = worst_new.max(to(&b, &new_optimum));
            worst_rule = worst_rule.max(rule);
            other_rejections += usize::from(rule > 0.0);
            worst = worst.max(e);
            for (acc, v) in old.iter_mut().zip([a_ms, a_solver, a.iterations() as f64]) {
                *acc += v / SUBSETS as f64;
            }
            for (acc, v) in new.iter_mut().zip([b_ms, b_solver, b.iterations() as f64]) {
                *acc += v / SUBSETS as f64;
            }
        }
        ok &= worst_new <= SAME_ANSWER_PX;
        println!(
            "  {:9} {:10.1} {:10.1} {:7.1} {:10.1} {:10.1} {:7.1} {:7.2}× {:8.4} {:8.4} {:8.4}{}",
            method.name(),
            old[0],
            old[1],
            old[2],
            new[0],
            new[1],
            new[2],
            old[0] / new[0],
            worst,
            worst_old,
            worst_new,
            if worst_new <= SAME_ANSWER_PX {
                ""
            } else {
                "  NOT THE OPTIMUM"
            }
        );
        if other_rejections > 0 {
            println!(
                "            {other_rejections} of {SUBSETS} subsets rejected other observations than the converged \
                 optimum; the two optima {worst_rule:.4} px apart at worst"
            );
        }
    }
    ok
}

/// One calibration per size and method, time per image; false if a result
/// with rejected observations is not the fit of the kept ones afresh.
fn growth(sizes: &[usize], methods: &[Method]) -> bool {
    let mut ok = true;
    println!("cost growth: t2 preset, radial3, 1 thread, whole calibration without covariance");
    for &n in sizes {
        let (dataset, _) = Generator::new(Preset::T2, Some(n), 7).generate();
        for &method in methods {
            let start = Instant::now();
            let cpu = thread_cpu_ms();
            let c =
                deformcal::solver::calibrate::fit(&dataset, &request(method, false)).expect("fit");
            let ms = thread_cpu_ms() - cpu;
            let wall = start.elapsed().as_secs_f64() * 1e3;
            println!(
                "  {n:6} images {:8} {:10.1} ms CPU ({wall:.0} ms wall)  {:7.3} ms/image  {} iterations  {}",
                method.name(),
                ms,
                ms / n as f64,
                c.iterations(),
                c.stages.last().map_or("", |s| s.linear_solver.as_str())
            );
            if std::env::var("SPEED_DIAG").is_ok() {
                for s in &c.stages {
                    println!(
                        "    stage {:8} {:3} iterations {:9.1} ms {}",
                        s.method.name(),
                        s.iterations,
                        s.seconds * 1e3,
                        s.linear_solver
                    );
                }
            }
            let cam = &dataset.cameras[0];
            ok &= against_saved(n, method, &c.state.intrinsics[0], cam.width, cam.height);
            if !c.rejected.is_empty() {
                // Only what the check needs is kept (peak memory).
                let (kept_data, intrinsics, rejected) =
                    (c.dataset, c.state.intrinsics[0], c.rejected.len());
                // The previous pipeline's answer: the kept observations fitted
                // afresh (what `without_footprint` did for any rejection).
                let mut kept = request(method, false);
                kept.settings.outlier_k = 0.0;
                let fresh = deformcal::solver::calibrate::fit(&kept_data, &kept).expect("fit");
                let e = mapping_error(
                    &fresh.state.intrinsics[0],
                    &intrinsics,
                    cam.width,
                    cam.height,
                );
                println!(
                    "    {} rejected; {e:.5} px from the kept observations fitted afresh{}",
                    rejected,
                    if e <= SAME_ANSWER_PX {
                        ""
                    } else {
                        "  NOT THE SAME ANSWER"
                    }
                );
                ok &= e <= SAME_ANSWER_PX;
            }
        }
    }
    ok
}

/// Appends this result to `SPEED_SAVE`, and compares it with the same size and
/// method in `SPEED_PREVIOUS` (see the module's comment); false if too far.
fn against_saved(n: usize, method: Method, k: &deformcal::Intrinsics, w: u32, h: u32) -> bool {
    let key = format!("{n} {}", method.name());
    if let Ok(path) = std::env::var("SPEED_SAVE") {
        use std::io::Write;
        let values: Vec<String> = k.params().iter().map(|v| format!("{v:e}")).collect();
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .expect("SPEED_SAVE file");
        writeln!(f, "{key} {}", values.join(" ")).expect("SPEED_SAVE write");
    }
    let Ok(path) = std::env::var("SPEED_PREVIOUS") else {
        return true;
    };
    let text = std::fs::read_to_string(&path).expect("SPEED_PREVIOUS file");
    let Some(line) = text
        .lines()
        .rev()
        .find(|l| l.starts_with(&format!("{key} ")))
    else {
        println!("    no previous result for {key}");
        return true;
    };
    let values: Vec<f64> = line
        .split_whitespace()
        .skip(2)
        .map(|v| v.parse().expect("a saved value"))
        .collect();
    let previous =
        deformcal::Intrinsics::from_params(k.model(), &values).expect("saved intrinsics");
    let e = mapping_error(&previous, k, w, h);
    println!(
        "    {e:.5} px from the previous build's result{}",
        if e <= SAME_ANSWER_PX {
            ""
        } else {
            "  NOT THE SAME ANSWER"
        }
    );
    e <= SAME_ANSWER_PX
}

/// `start`'s state solved on `on`'s problem and settings with tolerances of
/// 1e-15 (no rejection): its intrinsics and final cost.
fn tight_from(on: &Calibration, start: &Calibration) -> (deformcal::Intrinsics, f64) {
    let mut s = on.settings.clone();
    s.outlier_k = 0.0;
    s.function_tolerance = 1e-15;
    s.parameter_tolerance = 1e-15;
    s.gradient_tolerance = 1e-15;
    s.max_iterations = 1000;
    let mut state = start.state.clone();
    let r = on.problem().solve(&mut state, &s).expect("tight solve");
    (state.intrinsics[0], r.final_cost)
}

/// The converged optimum of `on`'s objective: the lower of the tight solves
/// from `a`'s and `b`'s results, and how far apart the two ended (px).
fn optimum(on: &Calibration, a: &Calibration, b: &Calibration) -> (deformcal::Intrinsics, f64) {
    let (ta, ca) = tight_from(on, a);
    let (tb, cb) = tight_from(on, b);
    let cam = &on.dataset.cameras[0];
    let apart = mapping_error(&ta, &tb, cam.width, cam.height);
    (if ca <= cb { ta } else { tb }, apart)
}

/// The refit after outlier rejection: for each method, lens model and size,
/// the library's result, the kept observations fitted afresh, and their
/// distances to the optimum converged with tolerances of 1e-15.
fn refit_study(sizes: &[usize], methods: &[Method], models: &[LensModel]) {
    println!("refit after rejection: t2, seed 7, 1 thread; px to the converged optimum");
    for &method in methods {
        for &model in models {
            for &n in sizes {
                let (d, _) = Generator::new(Preset::T2, Some(n), 7)
                    .with_models(&[model])
                    .generate();
                let req = request(method, false);
                let cpu = thread_cpu_ms();
                let c = deformcal::solver::calibrate::fit(&d, &req).expect("fit");
                let ms = thread_cpu_ms() - cpu;
                if c.rejected.is_empty() {
                    println!("  {method:8} {model:8} {n:6}: nothing rejected ({ms:.0} ms)");
                    continue;
                }
                let last = c.stages.last().expect("a stage");
                let cont_ms = last.seconds * 1e3;
                let mut kept = req.clone();
                kept.settings.outlier_k = 0.0;
                let cpu = thread_cpu_ms();
                let fresh = deformcal::solver::calibrate::fit(&c.dataset, &kept).expect("fit");
                let fresh_ms = thread_cpu_ms() - cpu;
                assert_eq!(fresh.dataset, c.dataset);
                let (opt, apart) = optimum(&fresh, &c, &fresh);
                let cam = &d.cameras[0];
                let m = |a: &deformcal::Intrinsics, b: &deformcal::Intrinsics| {
                    mapping_error(a, b, cam.width, cam.height)
                };
                let own = if c.settings.board.noise_px != fresh.settings.board.noise_px {
                    let (o, a) = optimum(&c, &c, &fresh);
                    format!(
                        "; own objective: new {:.4} (ends {a:.4} apart), optima {:.4} apart",
                        m(&c.state.intrinsics[0], &o),
                        m(&o, &opt)
                    )
                } else {
                    String::new()
                };
                println!(
                    "  {method:8} {model:8} {n:6}: {:4} rej; to opt: new {:.4} afresh {:.4} (ends {apart:.4} apart); new refit {cont_ms:.0} ms ({} it) afresh {fresh_ms:.0} ms; whole {ms:.0} ms{own}",
                    c.rejected.len(),
                    m(&c.state.intrinsics[0], &opt),
                    m(&fresh.state.intrinsics[0], &opt),
                    last.iterations,
                );
            }
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    if args.first().map(String::as_str) == Some("refit") {
        let sizes: Vec<usize> = args[1..].iter().filter_map(|s| s.parse().ok()).collect();
        let mut methods: Vec<Method> = args[1..].iter().filter_map(|s| Method::parse(s)).collect();
        if methods.is_empty() {
            methods = vec![Method::Standard, Method::Static];
        }
        let mut models: Vec<LensModel> = args[1..]
            .iter()
            .filter_map(|s| LensModel::ALL.into_iter().find(|m| m.name() == s))
            .collect();
        if models.is_empty() {
            models = vec![
                LensModel::Radial3,
                LensModel::OpenCv5,
                LensModel::OpenCv8,
                LensModel::Kb4,
            ];
        }
        refit_study(&sizes, &methods, &models);
        return;
    }
    if args.first().map(String::as_str) == Some("growth") {
        let sizes: Vec<usize> = args[1..].iter().filter_map(|s| s.parse().ok()).collect();
        let mut methods: Vec<Method> = args[1..].iter().filter_map(|s| Method::parse(s)).collect();
        if methods.is_empty() {
            methods = vec![Method::Standard, Method::Full];
        }
        let sizes: &[usize] = if sizes.is_empty() {
            &[25, 100, 400, 1600]
        } else {
            &sizes
        };
        if !growth(sizes, &methods) {
            eprintln!("a result is more than {SAME_ANSWER_PX} px from the previous answer");
            std::process::exit(1);
        }
        return;
    }
    let mut ok = true;
    for model in LensModel::ALL {
        if args.first().is_some_and(|m| m != model.name()) {
            continue;
        }
        ok &= compare_paths(model);
    }
    if !ok {
        eprintln!("the new path missed the converged optimum by more than {SAME_ANSWER_PX} px");
        std::process::exit(1);
    }
}
