//! Times one 25-image calibration of each method on the `t2` preset, one thread.
//! Run with `cargo bench`; prints median and best wall time per method.
use deformcal::model::synthetic::{generate, Preset};
use deformcal::solver::problem::SolverSettings;
use deformcal::{calibrate, Method, Request};
use std::time::Instant;

const REPEATS: usize = 15;

fn main() {
    let (dataset, _) = generate(Preset::T2, Some(25), 7);
    println!(
        "t2 preset: {} images, {} observations, 1 thread, {REPEATS} runs each (Zhang init + warm start + method)",
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
            "{:9} median {:7.1} ms   best {:7.1} ms   {iterations} iterations",
            method.name(),
            times[REPEATS / 2],
            times[0]
        );
    }
}
