//! Times the evaluation protocol on the `t2` preset: 4 methods × 50 subsets × 25
//! images with the 650-image reference, on all cores. `SUBSETS=n cargo bench --bench
//! protocol` runs a shorter variant.
use deformcal::app::config::{Config, ProtocolConfig};
use deformcal::app::protocol::{prepare, test_rmse};
use std::path::Path;
use std::time::Instant;

fn main() {
    let subsets = std::env::var("SUBSETS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(50);
    let config = Config::parse(
        "[data]\nsynthetic = \"t2\"\n[reference]\nsynthetic = \"reference\"\n",
        Path::new("bench.toml"),
    )
    .expect("bench config");
    let protocol = ProtocolConfig {
        subsets,
        ..ProtocolConfig::default()
    };
    let start = Instant::now();
    let setup = prepare(&config, &protocol).expect("setup");
    let prepared = start.elapsed().as_secs_f64();
    let reference = setup.reference.as_ref().expect("reference");
    let t = Instant::now();
    let truth = setup.header.truth.as_ref().expect("truth");
    let e = test_rmse(reference, 0, &truth[0], &setup.settings).expect("refit");
    println!(
        "reference calibration + data: {prepared:.2} s; one test-error refit on {} images: {:.0} ms (RMSE {e:.4})",
        reference.dataset.num_frames(),
        t.elapsed().as_secs_f64() * 1e3
    );
    let t = Instant::now();
    let rows = setup.run(None, &|| {});
    let failed = rows.iter().filter(|r| !r.ok()).count();
    println!(
        "protocol: {} calibrations ({failed} failed) in {:.2} s on {} threads; total {:.2} s",
        rows.len(),
        t.elapsed().as_secs_f64(),
        rayon::current_num_threads(),
        start.elapsed().as_secs_f64()
    );
}
