//! Compiles the Ceres core in `cpp/` through cxx and links Debian's Ceres 2.1.
use std::path::Path;

const HEADERS: &[&str] = &[
    "/usr/include/ceres/ceres.h",
    "/usr/include/eigen3/Eigen/Core",
    "/usr/include/glog/logging.h",
];

fn main() {
    let missing: Vec<&str> = HEADERS
        .iter()
        .copied()
        .filter(|h| !Path::new(h).exists())
        .collect();
    if !missing.is_empty() {
        eprintln!(
            "deformcal needs Ceres 2.1, Eigen, SuiteSparse and glog from Debian; missing: {}\n\
             install them with: apt-get install -y libceres-dev libeigen3-dev \
             libsuitesparse-dev libgoogle-glog-dev",
            missing.join(", ")
        );
        std::process::exit(1);
    }

    let mut build = cxx_build::bridge("src/solver/bridge.rs");
    build
        .file("cpp/solver.cc")
        .std("c++17")
        .include("/usr/include/eigen3")
        .flag_if_supported("-Wno-unused-parameter")
        .flag_if_supported("-Wno-deprecated-declarations");
    // Autodiff at -O0 is about ten times slower and compiles no faster.
    if std::env::var("OPT_LEVEL").as_deref() == Ok("0") {
        build.opt_level(2);
    }
    build.compile("deformcal_core");

    println!("cargo:rustc-link-lib=ceres");
    println!("cargo:rustc-link-lib=glog");
    // A directory is scanned whole: every header under cpp/ counts.
    for f in ["src/solver/bridge.rs", "cpp"] {
        println!("cargo:rerun-if-changed={f}");
    }
}
