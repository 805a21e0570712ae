//! Times one 25-image calibration of each lens model and method on the `t2`
//! preset, one thread, and the covariance of the intrinsics against the method's
//! own solve. Run with `cargo bench --bench methods`; prints median and best wall
//! time per model and method. `-- radial3` times one model only, `-- covariance`
//! only the covariance.
use deformcal::model::synthetic::{Generator, Preset};
use deformcal::solver::problem::SolverSettings;
use deformcal::solver::uncertainty::unit_covariance;
use deformcal::{calibrate, LensModel, Method, Request};
use std::time::Instant;

const REPEATS: usize = 15;

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

fn main() {
    let only: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    covariance_vs_solve();
    if only.as_deref() == Some("covariance") {
        return;
    }
    for model in LensModel::ALL {
        if only.as_deref().is_some_and(|m| m != model.name()) {
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
            let mut iterations = 0;
            calibrate(&dataset, &request).expect("warm-up calibration");
            for _ in 0..REPEATS {
                let start = Instant::now();
                let c = calibrate(&dataset, &request).expect("calibration");
                times.push(start.elapsed().as_secs_f64() * 1e3);
                iterations = c.iterations();
            }
            times.sort_by(f64::total_cmp);
            println!(
                "  {:9} median {:7.1} ms   best {:7.1} ms   {iterations} iterations",
                method.name(),
                times[REPEATS / 2],
                times[0]
            );
        }
    }
}
