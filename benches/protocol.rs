//! Times the evaluation protocol on the `t2` preset: 4 methods × 50 subsets × 25
//! images with the 650-image reference, on all cores. `SUBSETS=n cargo bench --bench
//! protocol` runs a shorter variant; `PER_CORNER=1` solves the subsets on the
//! solver's previous path (one residual block per corner, no warm-up).
use deformcal::app::config::{Config, ProtocolConfig};
use deformcal::app::protocol::{prepare, test_rmse};
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
    let mut setup = prepare(&config, &protocol).expect("setup");
    // PER_CORNER=1: the subsets on the solver's previous path (issue 17's reference).
    setup.settings.per_corner_blocks = std::env::var("PER_CORNER").is_ok();
    let prepared = start.elapsed().as_secs_f64();
    let prepared_cpu = process_cpu_seconds();
    let reference = setup.reference.as_ref().expect("reference");
    let t = Instant::now();
    let truth = setup.header.truth.as_ref().expect("truth");
    let e = test_rmse(reference, 0, &truth[0], &setup.settings).expect("refit");
    println!(
        "reference calibration + data: {prepared:.2} s ({prepared_cpu:.2} s CPU); one test-error refit on {} images: {:.0} ms (RMSE {e:.4})",
        reference.dataset.num_frames(),
        t.elapsed().as_secs_f64() * 1e3
    );
    let t = Instant::now();
    let rows = setup.run(None, &|| {});
    let failed = rows.iter().filter(|r| !r.ok()).count();
    println!(
        "protocol: {} calibrations ({failed} failed) in {:.2} s on {} threads; total {:.2} s wall, {:.2} s CPU",
        rows.len(),
        t.elapsed().as_secs_f64(),
        rayon::current_num_threads(),
        start.elapsed().as_secs_f64(),
        process_cpu_seconds()
    );
}
