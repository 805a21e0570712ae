//! The C API on issue 19's bad calls: each returns non-zero with its message, none
//! aborts, and a calibration still works; `deformcal_calibrate_ex`'s tolerances,
//! frame results and guard rails (code 4); run natively and, when valgrind is
//! installed (CI installs it), under valgrind with memory errors fatal.
use std::path::Path;
use std::process::Command;

fn check(printed: &str) {
    for (case, message) in [
        (
            "images_1e9",
            "1000000000 images; at most 20000 can be generated",
        ),
        ("stereo", "preset `stereo` is a rig of 2 cameras"),
        (
            "target_20000",
            "a board of 20000 × 20000 corners is too large",
        ),
        ("result_null", "result is NULL"),
        ("duplicate_names", "cameras 0 and 1 are both named `cam0`"),
        (
            "scale_negative",
            "options.loss_scale_px is -1; use 0.001 to 10000 pixels",
        ),
        ("scale_nan", "options.loss_scale_px is NaN"),
        ("scale_huge", "options.loss_scale_px is 1000000000"),
        (
            "tolerance_negative",
            "tolerances.function_tolerance is -1; use a non-negative number, or 0 for the default",
        ),
        (
            "max_rmse_nan",
            "tolerances.max_rmse_px is NaN; use a positive number of pixels, or 0 for the default rules",
        ),
        (
            "frames_small",
            "frame_results holds 2 entries; 8 needed (one per frame number)",
        ),
    ] {
        let line = printed
            .lines()
            .find(|l| l.starts_with(&format!("{case} ")))
            .unwrap_or_else(|| panic!("no {case} in {printed}"));
        assert!(line.contains("rc=1") && line.contains(message), "{line}");
    }
    assert!(printed.contains("calibrate rc=0"), "{printed}");
    assert!(printed.contains("fx "), "{printed}");
    // The count is given even when the room is too small.
    assert!(printed.contains("num_frames 8\n"), "{printed}");
    // A result that fails the guard rails is code 4, filled in for inspection.
    // Two iterations: the warm-up's and the robust solve's, one each (far from
    // the optimum most corners lie beyond the loss's scale).
    assert!(
        printed.contains(
            "not_converged rc=4 msg=the calibration FAILED: the standard solve did not converge after 2 iterations"
        ),
        "{printed}"
    );
    assert!(
        printed.contains("not_converged converged 0 fx_filled 1 frame_used 1"),
        "{printed}"
    );
    assert!(printed.contains("calibrate_ex_no_frames rc=0"), "{printed}");
    assert!(printed.contains("calibrate_ex rc=0"), "{printed}");
    assert!(
        printed.contains("frames_used 8 of 8 frame0 0 rmse 0."),
        "{printed}"
    );
}

#[test]
fn bad_calls_through_the_c_api_fail_cleanly_also_under_valgrind() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let built = Command::new(cargo)
        .current_dir(root)
        .args(["build", "--release", "--lib", "--quiet"])
        .status()
        .unwrap();
    assert!(built.success());
    let lib_dir = root.join("target/release");
    let dir = tempfile::tempdir().unwrap();
    let exe = dir.path().join("robust");
    let cc = Command::new("gcc")
        .args(["-std=c99", "-Wall", "-Wextra", "-Werror"])
        .arg(root.join("tests/capi/robust.c"))
        .arg(format!("-I{}", root.join("include").display()))
        .arg(format!("-L{}", lib_dir.display()))
        .arg("-ldeformcal")
        .arg("-lm")
        .arg(format!("-Wl,-rpath,{}", lib_dir.display()))
        .arg("-o")
        .arg(&exe)
        .status()
        .unwrap();
    assert!(cc.success());
    let out = Command::new(&exe).output().unwrap();
    assert!(out.status.success(), "{out:?}");
    check(&String::from_utf8_lossy(&out.stdout));

    if Command::new("valgrind").arg("--version").output().is_err() {
        eprintln!("skipped the valgrind run: valgrind is not installed");
        return;
    }
    let out = Command::new("valgrind")
        .args(["--error-exitcode=99", "--leak-check=no", "--quiet"])
        .arg(&exe)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "valgrind: {stderr}");
    check(&String::from_utf8_lossy(&out.stdout));
}
