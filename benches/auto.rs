//! Times `method = "auto"` (standard, dynamic and full, 5-fold cross-validation)
//! against one `full` calibration on 100 images of the `t2` preset. Run with
//! `cargo bench --bench auto`; `RAYON_NUM_THREADS=1` times it on one core.
use deformcal::model::selection::AutoSettings;
use deformcal::model::synthetic::{Generator, Preset};
use deformcal::solver::problem::SolverSettings;
use deformcal::solver::select::calibrate_auto;
use deformcal::{calibrate, Method, Request};
use std::time::Instant;

const REPEATS: usize = 3;

/// Median wall time of `f` in seconds, after one warm-up run.
fn median(mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..REPEATS)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[REPEATS / 2]
}

fn main() {
    let (dataset, _) = Generator::new(Preset::T2, Some(100), 1).generate();
    let request = Request {
        method: Method::Full,
        settings: SolverSettings::default(),
        gauge: None,
    };
    let full = median(|| {
        calibrate(&dataset, &request).expect("full");
    });
    let auto = AutoSettings::default();
    let mut chosen = Method::Standard;
    let t_auto = median(|| {
        let c = calibrate_auto(&dataset, &request, &auto, &|| {}).expect("auto");
        chosen = c.method;
    });
    println!(
        "t2, {} images, {} observations, {} rayon thread(s), median of {REPEATS}:",
        dataset.num_frames(),
        dataset.observations.len(),
        rayon::current_num_threads()
    );
    println!("  one `full` calibration   {:8.3} s", full);
    println!(
        "  auto ({}-fold, {} candidates) {:8.3} s = {:.1}× full; chose `{chosen}`",
        auto.folds,
        auto.candidates.len(),
        t_auto,
        t_auto / full
    );
}
