//! The Python package: builds its native module with cargo (into this workspace's
//! target directory, so it links the library these tests were built with) and runs
//! its pytest suite, `python/tests`, against the module and the command line of
//! this build. `pip install .` itself, in a fresh virtual environment, runs where
//! `DEFORMCAL_TEST_PIP=1` (CI sets it).
use std::path::{Path, PathBuf};
use std::process::Command;

/// The interpreter with numpy, OpenCV and pytest (Debian's; the `python3` of a
/// pyenv on PATH may lack them).
const PYTHON: &str = "/usr/bin/python3";

fn run(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap_or_else(|e| panic!("{cmd:?}: {e}"));
    let text = format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{cmd:?} failed:\n{text}");
    text
}

/// Why the suite cannot run here, if it cannot: no interpreter, or no pytest.
fn missing_python() -> Option<String> {
    match Command::new(PYTHON)
        .args(["-c", "import pytest, numpy"])
        .output()
    {
        Err(e) => Some(format!("{PYTHON}: {e}")),
        Ok(o) if !o.status.success() => Some(format!(
            "{PYTHON} lacks pytest or numpy (apt-get install python3-pytest python3-numpy): {}",
            String::from_utf8_lossy(&o.stderr).trim()
        )),
        Ok(_) => None,
    }
}

/// Builds the native module and lays out the package in a temporary folder
/// (the sources are not written to); returns the folder to put on `PYTHONPATH`.
fn build_package(root: &Path, into: &Path) -> PathBuf {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    run(Command::new(cargo).current_dir(root).args([
        "build",
        "--release",
        "--quiet",
        // The same packages and targets as the `cargo test` that runs this test
        // (default-members), so features unify alike and nothing is rebuilt.
        "--workspace",
        "--lib",
        "--tests",
    ]));
    let package = into.join("deformcal");
    std::fs::create_dir_all(&package).unwrap();
    for entry in std::fs::read_dir(root.join("python/deformcal")).unwrap() {
        let path = entry.unwrap().path();
        if path.is_file() {
            std::fs::copy(&path, package.join(path.file_name().unwrap())).unwrap();
        }
    }
    std::fs::copy(
        root.join("target/release/lib_deformcal.so"),
        package.join("_deformcal.abi3.so"),
    )
    .unwrap();
    into.to_path_buf()
}

#[test]
fn pytest_suite() {
    if let Some(reason) = missing_python() {
        eprintln!("skipped: {reason}");
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let path = build_package(root, dir.path());
    let out = run(Command::new(PYTHON)
        .current_dir(root)
        .args([
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "python/tests",
        ])
        .env("PYTHONPATH", &path)
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .env("DEFORMCAL_BIN", env!("CARGO_BIN_EXE_deformcal")));
    eprintln!("{out}");
    assert!(out.contains(" passed"), "pytest ran no test:\n{out}");
}

/// `pip install .` from the clone, as the README says, into a fresh virtual
/// environment (with the system's numpy and OpenCV), then the package used from
/// outside the source tree. Costs maturin's download and a rebuild of the module.
#[test]
fn pip_install_from_the_clone() {
    if std::env::var("DEFORMCAL_TEST_PIP").as_deref() != Ok("1") {
        eprintln!("skipped: set DEFORMCAL_TEST_PIP=1 to test `pip install .` (CI does)");
        return;
    }
    if let Some(reason) = missing_python() {
        eprintln!("skipped: {reason}");
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let venv = dir.path().join("venv");
    run(Command::new(PYTHON)
        .args(["-m", "venv", "--system-site-packages"])
        .arg(&venv));
    let python = venv.join("bin/python");
    let start = std::time::Instant::now();
    run(Command::new(&python)
        .current_dir(root)
        .args(["-m", "pip", "install", "--quiet", "."])
        .env("CARGO_TARGET_DIR", root.join("target")));
    eprintln!("pip install . took {:.0} s", start.elapsed().as_secs_f64());
    let check = "import deformcal, numpy as np, os; \
                 assert not deformcal.__file__.startswith(os.environ['ROOT']), deformcal.__file__; \
                 c = deformcal.Camera.load(os.environ['JSON']); \
                 print(deformcal.__version__, c.project(np.array([0.1, 0.0, 1.0])))";
    let json = dir.path().join("calibration.json");
    std::fs::write(
        &json,
        r#"{"method":"standard","rmse_px":0.1,"observations":0,"converged":true,"iterations":0,
           "seconds":0,"cameras":[{"name":"cam0","model":"radial3","width":640,"height":480,
           "intrinsics":{"fx":500,"fy":500,"cx":320,"cy":240,"k1":0,"k2":0,"k3":0},
           "rotation":[0,0,0],"translation":[0,0,0]}],"frames":[],"gauge_corners":[],
           "frozen_corners":[],"initial_intrinsics":[],"stages":[],"warnings":[]}"#,
    )
    .unwrap();
    let out = run(Command::new(&python)
        .current_dir(dir.path())
        .args(["-c", check])
        .env("ROOT", root)
        .env("JSON", &json));
    // f·x/z + cx = 500·0.1 + 320.
    assert!(out.contains("[370. 240.]"), "{out}");
}
