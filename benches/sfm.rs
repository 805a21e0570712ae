//! Times the structure-from-motion loop-closure experiment (the paper's section 5):
//! one reconstruction of the default 100-frame loop with the true camera, then the
//! protocol table (subsets × 4 methods, each calibration also reconstructed) for one
//! preset, printed as the paper's Table 1. `PRESET=t3 SUBSETS=10 cargo bench --bench
//! sfm` runs another preset or a shorter variant; `THREADS` sets the worker count.
use deformcal::app::config::{Config, ProtocolConfig};
use deformcal::app::protocol::prepare;
use deformcal::app::protocol_report::summarise;
use deformcal::app::sfm::{Experiment, SfmConfig};
use deformcal::model::synthetic::true_intrinsics;
use std::path::Path;
use std::time::Instant;

fn env<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

fn one_run() {
    let cam = true_intrinsics();
    let t = Instant::now();
    let exp = Experiment::new(&SfmConfig::default(), &cam, 1936, 1216).expect("scene");
    let generated = t.elapsed().as_secs_f64();
    let mut times = Vec::new();
    let mut lc = 0.0;
    for _ in 0..5 {
        let t = Instant::now();
        lc = exp.run(&cam).expect("sfm").loop_closure_px;
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    let features: usize = exp.scene.features.iter().map(Vec::len).sum();
    println!(
        "one SfM run, {} frames, {features} features, {} tracks: min {:.3} s, median {:.3} s \
         (scene generation {:.3} s); loop closure with the true camera {lc:.3} px",
        exp.scene.num_frames(),
        exp.scene.num_tracks,
        times[0],
        times[2],
        generated
    );
}

fn main() {
    let threads = env("THREADS", 2usize);
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global()
        .expect("thread pool");
    one_run();
    let preset: String = env("PRESET", "t2".to_string());
    let subsets = env("SUBSETS", 50usize);
    let text = format!(
        "[data]\nsynthetic = \"{preset}\"\n[reference]\nsynthetic = \"reference\"\n[sfm]\n"
    );
    let config = Config::parse(&text, Path::new("bench.toml")).expect("bench config");
    let protocol = ProtocolConfig {
        subsets,
        ..ProtocolConfig::default()
    };
    let start = Instant::now();
    let setup = prepare(&config, &protocol).expect("setup");
    let rows = setup.run(None, &|| {});
    let summary = summarise(&setup.header, &rows);
    println!(
        "{preset}: {} subsets × {} methods with SfM in {:.1} s on {threads} threads",
        subsets,
        setup.header.methods.len(),
        start.elapsed().as_secs_f64()
    );
    println!("target  method    loop closure (px)   mapping error to truth (px)  broke off");
    for m in &setup.header.methods {
        let s = &summary.methods[m.name()];
        let get = |k: &str| {
            s.metrics.get(k).map_or("–".to_string(), |x| {
                format!("{:7.2} ± {:6.2}", x.mean, x.std)
            })
        };
        let broke = rows
            .iter()
            .filter(|r| r.method == *m && r.sfm_error.is_some())
            .count();
        println!(
            "{preset:<7} {:<9} {}       {}          {broke}",
            m.name(),
            get("loop_closure_px"),
            get("truth_mapping_error_px")
        );
    }
}
