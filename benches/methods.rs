//! Times one 25-image calibration of each lens model and method on the `t2`
//! preset, one thread, and the covariance of the intrinsics against the method's
//! own solve. Run with `cargo bench --bench methods`; prints median and best wall
//! time and the median CPU time per model and method. `-- radial3` times one model only, `-- models` every
//! model without the covariance, `-- covariance` only the covariance. Each row also gives the solver stages (iterations each;
//! the stages after the method's are outlier-rejection re-solves) and the
//! rejected count. `METHODS_SAVE=FILE` writes every model's and method's
//! intrinsics as JSON; `METHODS_BASELINE=FILE` prints the mapping error of each
//! to the saved ones (a speed-up must not change the answer). `-- rejection` prints
//! every model's and method's mean mapping error to the truth and the corners
//! outlier rejection removed, over 25-image sets of `t1` and `t2` (seeds 1–6),
//! which hold no bad detection: each rejection is a false alarm.
use deformcal::model::metrics::{mapping_error, mapping_error_rot};
use deformcal::model::synthetic::{Generator, Preset};
use deformcal::solver::problem::SolverSettings;
use deformcal::solver::uncertainty::unit_covariance;
use deformcal::{calibrate, Calibration, LensModel, Method, Request};
use std::collections::BTreeMap;
use std::time::Instant;

const REPEATS: usize = 15;

/// The CPU time of this process in ms: on a shared machine wall time counts the
/// other jobs' share too, CPU time of a one-thread solve does not.
fn cpu_ms() -> f64 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec through a valid pointer.
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
    t.tv_sec as f64 * 1e3 + t.tv_nsec as f64 * 1e-6
}

/// Median and best of a list of times.
fn median_best(mut times: Vec<f64>) -> (f64, f64) {
    times.sort_by(f64::total_cmp);
    (times[times.len() / 2], times[0])
}

/// The covariance (Jacobian at the optimum, Schur complement, Σ_θ) against the
/// method's own Ceres solve (its first stage after the `standard` warm start;
/// for `standard` the warm start itself), medians, on 25 and 100 images of `t2`.
fn covariance_vs_solve() {
    for images in [25, 100] {
        let (dataset, _) = Generator::new(Preset::T2, Some(images), 7).generate();
        println!(
            "covariance: t2 preset, {images} images, {} observations, 1 thread, {REPEATS} runs each",
            dataset.observations.len()
        );
        for method in Method::ALL {
            let request = Request {
                method,
                settings: SolverSettings::default(),
                gauge: None,
            };
            let mut solves = Vec::with_capacity(REPEATS);
            let mut c = calibrate(&dataset, &request).expect("calibration");
            for _ in 0..REPEATS {
                c = calibrate(&dataset, &request).expect("calibration");
                let stage = c.stages.iter().find(|s| s.method == method);
                solves.push(stage.map_or(f64::NAN, |s| s.seconds * 1e3));
            }
            let (solve_ms, _) = median_best(solves);
            unit_covariance(&c).expect("covariance");
            let times = (0..REPEATS)
                .map(|_| {
                    let start = Instant::now();
                    unit_covariance(&c).expect("covariance");
                    start.elapsed().as_secs_f64() * 1e3
                })
                .collect();
            let (median, best) = median_best(times);
            println!(
                "  {:9} covariance median {median:6.1} ms   best {best:6.1} ms   the method's solve median {solve_ms:6.1} ms ({:.2}×)",
                method.name(),
                median / solve_ms
            );
        }
    }
}

/// Intrinsics per "model method", as `METHODS_SAVE` writes them.
type Saved = BTreeMap<String, deformcal::model::lens::Intrinsics>;

/// The solver stages of a calibration: iterations per stage, and how many
/// observations outlier rejection removed.
fn stages(c: &Calibration) -> String {
    let its: Vec<String> = c
        .stages
        .iter()
        .map(|s| format!("{}/{:.1}", s.iterations, s.seconds * 1e3))
        .collect();
    format!(
        "stages (iterations/ms) [{}], fit {:.1} ms, {} rejected",
        its.join(" "),
        c.seconds * 1e3,
        c.rejected.len()
    )
}

/// The mapping error to the baseline's intrinsics, when there is one.
fn against(baseline: &Option<Saved>, key: &str, c: &Calibration) -> String {
    let Some(b) = baseline.as_ref().and_then(|b| b.get(key)) else {
        return String::new();
    };
    let cam = &c.dataset.cameras[0];
    let e = mapping_error(b, &c.state.intrinsics[0], cam.width, cam.height);
    format!("   {e:.2e} px to the baseline")
}

/// Mean rotation-compensated mapping error to the truth and the corners rejected,
/// per model and method, over sets without bad detections.
fn rejection_against_truth() {
    println!("rejection: t1 and t2 presets, 25 images, seeds 1-6, default settings");
    for model in LensModel::ALL {
        for method in Method::ALL {
            let (mut error, mut rejected, mut sets) = (0.0, 0, 0);
            for preset in [Preset::T1, Preset::T2] {
                for seed in 1..=6 {
                    let (dataset, truth) = Generator::new(preset, Some(25), seed)
                        .with_models(&[model])
                        .generate();
                    let request = Request {
                        method,
                        settings: SolverSettings::default(),
                        gauge: None,
                    };
                    let c = calibrate(&dataset, &request).expect("calibration");
                    let cam = &dataset.cameras[0];
                    error += mapping_error_rot(
                        &truth.intrinsics[0],
                        &c.state.intrinsics[0],
                        cam.width,
                        cam.height,
                    );
                    rejected += c.rejected.len();
                    sets += 1;
                }
            }
            println!(
                "  {:8} {:9} mapping error to the truth {:.4} px (mean of {sets}), {rejected} rejected",
                model.name(),
                method.name(),
                error / sets as f64
            );
        }
    }
}

fn main() {
    if std::env::args().skip(1).any(|a| a == "rejection") {
        rejection_against_truth();
        return;
    }
    let baseline: Option<Saved> = std::env::var("METHODS_BASELINE").ok().map(|f| {
        serde_json::from_str(&std::fs::read_to_string(f).expect("baseline file"))
            .expect("baseline JSON")
    });
    let mut saved = Saved::new();
    let only: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    if only.is_none() || only.as_deref() == Some("covariance") {
        covariance_vs_solve();
    }
    if only.as_deref() == Some("covariance") {
        return;
    }
    for model in LensModel::ALL {
        if only
            .as_deref()
            .is_some_and(|m| m != model.name() && m != "models")
        {
            continue;
        }
        let (dataset, _) = Generator::new(Preset::T2, Some(25), 7)
            .with_models(&[model])
            .generate();
        println!(
            "{model}: t2 preset, {} images, {} observations, 1 thread, {REPEATS} runs each (init + warm start + method)",
            dataset.num_frames(),
            dataset.observations.len()
        );
        for method in Method::ALL {
            let request = Request {
                method,
                settings: SolverSettings::default(),
                gauge: None,
            };
            let mut times = Vec::with_capacity(REPEATS);
            let mut cpu = Vec::with_capacity(REPEATS);
            let mut c = calibrate(&dataset, &request).expect("warm-up calibration");
            for _ in 0..REPEATS {
                let start = Instant::now();
                let cpu_start = cpu_ms();
                c = calibrate(&dataset, &request).expect("calibration");
                cpu.push(cpu_ms() - cpu_start);
                times.push(start.elapsed().as_secs_f64() * 1e3);
            }
            times.sort_by(f64::total_cmp);
            let (cpu_median, _) = median_best(cpu);
            let key = format!("{model} {}", method.name());
            println!(
                "  {:9} median {:7.1} ms   best {:7.1} ms   CPU median {cpu_median:7.1} ms   {} iterations, {}{}",
                method.name(),
                times[REPEATS / 2],
                times[0],
                c.iterations(),
                stages(&c),
                against(&baseline, &key, &c)
            );
            saved.insert(key, c.state.intrinsics[0]);
        }
    }
    if let Ok(f) = std::env::var("METHODS_SAVE") {
        std::fs::write(&f, serde_json::to_string_pretty(&saved).expect("JSON")).expect("save");
    }
}
