//! Times the evaluation protocol on the `t2` preset: 4 methods × 50 subsets × 25
//! images with the 650-image reference, on all cores. `SUBSETS=n cargo bench --bench
//! protocol` runs a shorter variant; `PER_CORNER=1` solves the subsets and the
//! test-error refits on the solver's previous path (one residual block per corner,
//! no warm-up; one Ceres problem per refit). It then times the CLI's path, which
//! calibrates the reference beside the subsets, and checks that its rows are the same.
use deformcal::app::config::{Config, ProtocolConfig};
use deformcal::app::protocol::{plan, prepare, test_rmse};
use deformcal::app::protocol_report::protocol_csv;
use deformcal::solver::problem::SolverSettings;
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
        "reference calibration + data: {prepared:.2} s ({prepared_cpu:.2} s CPU); one test-error refit on {} images: {:.1} ms CPU (RMSE {:.12}), previous path {:.1} ms CPU (RMSE {:.12})",
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

    // The CLI's path: the reference calibrated beside the subsets. With
    // PER_CORNER=1 it would calibrate the reference on the previous path too.
    if setup.settings.per_corner_blocks {
        return;
    }
    let before = process_cpu_seconds();
    let t = Instant::now();
    let planned = plan(&config, &protocol).expect("plan");
    let (planned, beside) = planned
        .run_beside_reference(None, &|| {})
        .expect("protocol");
    let csv = |h, r| protocol_csv(h, r).expect("protocol.csv");
    assert!(
        csv(&planned.header, &beside) == csv(&setup.header, &rows),
        "the rows depend on when the reference is calibrated"
    );
    println!(
        "the CLI's path (data, then the reference beside the {} calibrations): {:.2} s wall, {:.2} s CPU",
        beside.len(),
        t.elapsed().as_secs_f64(),
        process_cpu_seconds() - before
    );
}
