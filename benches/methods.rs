//! Times one 25-image calibration of each lens model and method on the `t2`
//! preset, one thread. Run with `cargo bench --bench methods`; prints median and
//! best wall time per model and method.
use deformcal::model::synthetic::{Generator, Preset};
use deformcal::solver::problem::SolverSettings;
use deformcal::{calibrate, LensModel, Method, Request};
use std::time::Instant;

const REPEATS: usize = 15;

fn main() {
    // `cargo bench --bench methods -- radial3` times one model only.
    let only: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
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
