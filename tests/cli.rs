//! The command line on good and bad input: clear errors, non-zero exit, no stray files.
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn deformcal(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .args(args)
        .output()
        .expect("run deformcal")
}

struct Case {
    dir: tempfile::TempDir,
}

const CAMERA: &str = "[target]\nrows = 13\ncols = 13\nspacing = 0.07\n\n[[cameras]]\nname = \"cam0\"\nwidth = 1936\nheight = 1216\n";

impl Case {
    fn new() -> Self {
        Case {
            dir: tempfile::tempdir().unwrap(),
        }
    }
    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
    fn write(&self, name: &str, text: &str) -> PathBuf {
        let p = self.path(name);
        std::fs::write(&p, text).unwrap();
        p
    }
    /// A config reading `obs.csv` and writing to `out/`.
    fn config(&self, extra: &str) -> PathBuf {
        self.write(
            "c.toml",
            &format!(
                "{CAMERA}\n[data]\nobservations = \"obs.csv\"\n\n[output]\ndir = \"out\"\n{extra}"
            ),
        )
    }
    /// Runs a calibration that must fail; returns its single error message.
    fn fails(&self, config: &Path) -> String {
        let out = deformcal(&["--config", config.to_str().unwrap()]);
        let stderr = String::from_utf8_lossy(&out.stderr).to_string();
        assert!(
            !out.status.success(),
            "expected failure, got success: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "panic: {stderr}");
        assert!(stderr.starts_with("error: "), "{stderr}");
        assert_eq!(
            stderr.trim_end().lines().count(),
            1,
            "one message expected: {stderr}"
        );
        assert!(!self.path("out").exists(), "an output was left behind");
        stderr
    }
}

fn good_csv(case: &Case) -> PathBuf {
    let out = deformcal(&[
        "generate",
        "--preset",
        "t2",
        "--images",
        "12",
        "--seed",
        "4",
        "--out",
        case.dir.path().to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let p = case.path("observations.csv");
    std::fs::rename(&p, case.path("obs.csv")).unwrap();
    case.path("obs.csv")
}

#[test]
fn generated_data_calibrates_from_csv() {
    let case = Case::new();
    good_csv(&case);
    let config = case.config("[calibration]\nmethod = \"dynamic\"\n");
    let out = deformcal(&["--config", config.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("method dynamic") && stdout.contains("RMSE"),
        "{stdout}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(case.path("out/calibration.json")).unwrap())
            .unwrap();
    assert_eq!(json["method"], "dynamic");
    assert_eq!(json["converged"], true);
    assert_eq!(json["frames"].as_array().unwrap().len(), 12);
    assert!(json["frames"][0]["deformation"]["a"].is_number());
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(case.path("truth.json")).unwrap()).unwrap();
    let fx = json["cameras"][0]["intrinsics"]["fx"].as_f64().unwrap();
    let true_fx = truth["intrinsics"][0]["fx"].as_f64().unwrap();
    assert!((fx / true_fx - 1.0).abs() < 0.005, "{fx} vs {true_fx}");
    // The override flag wins over the config's method.
    let out = deformcal(&[
        "--config",
        config.to_str().unwrap(),
        "--method",
        "static",
        "--output",
        case.path("o2").to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(case.path("o2/calibration.json")).unwrap())
            .unwrap();
    assert_eq!(json["method"], "static");
    assert_eq!(json["static_correction"].as_array().unwrap().len(), 169);
}

#[test]
fn malformed_toml_names_file_and_line() {
    let case = Case::new();
    let c = case.write("c.toml", "[data]\nsynthetic = \"t2\n");
    let e = case.fails(&c);
    assert!(e.contains("c.toml") && e.contains("line 2"), "{e}");
}

#[test]
fn unknown_and_missing_keys_are_named() {
    let case = Case::new();
    let e = case.fails(&case.config("[calibration]\nmethod = \"full\"\nloss_scale = 2.0\n"));
    assert!(e.contains("loss_scale") && e.contains("c.toml"), "{e}");
    let e = case.fails(&case.write(
        "c.toml",
        "[target]\nrows = 13\ncols = 13\n[data]\nobservations = \"x.csv\"\n",
    ));
    assert!(e.contains("spacing"), "{e}");
    let e = case.fails(&case.config("[calibration]\nmethod = \"bendy\"\n"));
    assert!(e.contains("bendy"), "{e}");
    let e = case.fails(&case.config("[calibration]\nloss_scale_px = -1.0\n"));
    assert!(e.contains("calibration.loss_scale_px"), "{e}");
    let e = case.fails(&case.write(
        "c.toml",
        &format!(
            "{}\n[data]\nobservations = \"obs.csv\"\n",
            CAMERA.replace("spacing = 0.07", "spacing = 0.0")
        ),
    ));
    assert!(e.contains("target.spacing"), "{e}");
}

#[test]
fn missing_data_file_is_named() {
    let case = Case::new();
    let e = case.fails(&case.config(""));
    assert!(e.contains("obs.csv"), "{e}");
}

#[test]
fn bad_csv_rows_name_file_and_line() {
    let header = "camera,frame,corner,u,v\n";
    let row = "cam0,0,5,100.5,200.25\n";
    for (body, line, what) in [
        (
            "cam,frame,corner,u,v\ncam0,0,0,1,2\n".to_string(),
            ":1:",
            "bad header",
        ),
        (
            format!("{header}{row}cam0,0,6,abc,3\n"),
            ":3:",
            "not a number",
        ),
        (
            format!("{header}{row}cam0,0,6,NaN,3\n"),
            ":3:",
            "not finite",
        ),
        (
            format!("{header}{row}cam0,0,169,1,3\n"),
            ":3:",
            "outside the 13 × 13 board",
        ),
        (
            format!("{header}{row}cam9,0,6,1,3\n"),
            ":3:",
            "unknown camera `cam9`",
        ),
        (
            format!("{header}{row}{row}"),
            ":3:",
            "duplicate observation",
        ),
        (
            format!("{header}{row}cam0,0,6\n"),
            ":3:",
            "expected 5 fields",
        ),
        (
            format!("{header}cam0,x,6,1,2\n"),
            ":2:",
            "frame `x` is not an integer",
        ),
        (String::new(), ":1:", "empty"),
        ("\0\x01binary".to_string(), ":1:", "binary"),
        (header.to_string(), ":1:", "no observations"),
    ] {
        let case = Case::new();
        case.write("obs.csv", &body);
        let e = case.fails(&case.config(""));
        assert!(
            e.contains(&format!("obs.csv{line}")) && e.contains(what),
            "{what}: {e}"
        );
    }
}

#[test]
fn too_few_images_are_refused_with_the_reason() {
    let case = Case::new();
    good_csv(&case);
    let text = std::fs::read_to_string(case.path("obs.csv")).unwrap();
    let kept: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("camera") || l.starts_with("cam0,0,") || l.starts_with("cam0,1,"))
        .collect();
    case.write("obs.csv", &(kept.join("\n") + "\n"));
    let e = case.fails(&case.config(""));
    assert!(
        e.contains("2 usable image(s)") && e.contains("at least 3"),
        "{e}"
    );
}

#[test]
fn bad_flags_are_refused() {
    let case = Case::new();
    let c = case.write(
        "c.toml",
        "[data]\nsynthetic = \"t2\"\nimages = 5\n[output]\ndir = \"out\"\n",
    );
    let out = deformcal(&["--config", c.to_str().unwrap(), "--method", "wobbly"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("wobbly"));
    assert!(!case.path("out").exists());
    let out = deformcal(&[]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--config"));
}

#[test]
fn warnings_go_to_stderr_and_results_to_stdout() {
    let case = Case::new();
    good_csv(&case);
    let text = std::fs::read_to_string(case.path("obs.csv")).unwrap();
    // One corner moved far outside the image: dropped with a warning.
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let fields: Vec<&str> = lines[5].split(',').collect();
    lines[5] = format!(
        "{},{},{},7160,{}",
        fields[0], fields[1], fields[2], fields[4]
    );
    case.write("obs.csv", &(lines.join("\n") + "\n"));
    let out = deformcal(&["--config", case.config("").to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("RMSE"), "{stdout}");
    assert!(!stdout.contains("warning"), "{stdout}");
    assert!(
        stderr
            .lines()
            .any(|l| l.starts_with("warning: 1 observation(s) outside the image dropped")),
        "{stderr}"
    );
}

#[test]
fn too_few_usable_images_say_why_the_others_were_dropped() {
    let case = Case::new();
    // Three frames whose corners all lie at one pixel: no homography, no view.
    let mut text = String::from("camera,frame,corner,u,v\n");
    for frame in 0..3 {
        for corner in 0..169 {
            text += &format!("cam0,{frame},{corner},500,{}\n", 400 + frame);
        }
    }
    case.write("obs.csv", &text);
    let e = case.fails(&case.config(""));
    assert!(
        e.contains("0 usable image(s)")
            && e.contains("frame 0 skipped: its corners are collinear or degenerate")
            && e.contains("frame 2 skipped"),
        "{e}"
    );
}

/// A synthetic t2 config of `images` images calibrated with `method`, writing to `out/`.
fn t2_config(case: &Case, images: usize, method: &str) -> PathBuf {
    case.write(
        "t2.toml",
        &format!(
            "[data]\nsynthetic = \"t2\"\nimages = {images}\nseed = 3\n[calibration]\nmethod = \"{method}\"\n[output]\ndir = \"out\"\n"
        ),
    )
}

/// The entries of `dir` a run stages or sets aside (`.out.new-*`, `*old*`).
fn litter(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .filter(|n| n.contains(".new-") || n.contains("old-"))
        .collect()
}

/// `cmd` run as a program of this test, or `None` when it is missing or not
/// permitted (not root, no `chattr`): the test then says it skipped.
fn try_run(cmd: &str, args: &[&str]) -> Option<()> {
    let out = Command::new(cmd).args(args).output().ok()?;
    out.status.success().then_some(())
}

/// The one `error:` line of a failed run.
fn one_error(out: &Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "expected failure: {stderr}");
    assert!(!stderr.contains("panicked"), "panic: {stderr}");
    let errors: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("error: "))
        .collect();
    assert_eq!(errors.len(), 1, "one error line expected: {stderr}");
    errors[0].to_string()
}

#[test]
fn an_output_that_cannot_be_swapped_in_fails_before_the_data_are_read() {
    let case = Case::new();
    // The data are missing: the output's problem must be found first.
    let config = case.config("");
    let out = case.path("out");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    if try_run("chattr", &["+i", out.to_str().unwrap()]).is_none() {
        eprintln!("skipped: cannot make a directory immutable (chattr +i needs root)");
        return;
    }
    let run = deformcal(&["--config", config.to_str().unwrap()]);
    let _ = try_run("chattr", &["-i", out.to_str().unwrap()]);
    let e = one_error(&run);
    assert!(e.contains("out") && e.contains("cannot"), "{e}");
    assert!(!e.contains("obs.csv"), "the data were read first: {e}");
    assert!(
        litter(case.dir.path()).is_empty(),
        "{:?}",
        litter(case.dir.path())
    );
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );

    // A mount point cannot be renamed either.
    if try_run(
        "mount",
        &["--bind", out.to_str().unwrap(), out.to_str().unwrap()],
    )
    .is_none()
    {
        eprintln!("skipped: cannot bind-mount (needs root)");
        return;
    }
    let run = deformcal(&["--config", config.to_str().unwrap()]);
    let _ = try_run("umount", &[out.to_str().unwrap()]);
    let e = one_error(&run);
    assert!(e.contains("out") && !e.contains("obs.csv"), "{e}");
    assert!(
        litter(case.dir.path()).is_empty(),
        "{:?}",
        litter(case.dir.path())
    );
}

#[cfg(unix)]
#[test]
fn a_symlinked_output_stays_a_link_and_its_aliases_share_the_lock() {
    use deformcal::app::fsio::OutputSet;
    let case = Case::new();
    let config = t2_config(&case, 12, "standard");
    let real = case.path("real");
    std::fs::create_dir(&real).unwrap();
    std::fs::write(real.join("calibration.json"), "old").unwrap();
    let link = case.path("out");
    std::os::unix::fs::symlink("real", &link).unwrap();
    let run = deformcal(&["--config", config.to_str().unwrap()]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        link.symlink_metadata().unwrap().file_type().is_symlink(),
        "the link was replaced"
    );
    let json = std::fs::read_to_string(real.join("calibration.json")).unwrap();
    assert!(
        json.contains("\"method\": \"standard\""),
        "the link's target kept its old result"
    );
    // A run through one alias locks out a run through the other.
    let held = OutputSet::begin(&real, deformcal::app::output::calibration_files()).unwrap();
    let run = deformcal(&["--config", config.to_str().unwrap()]);
    let e = one_error(&run);
    assert!(
        e.contains("another deformcal run is writing this output directory"),
        "{e}"
    );
    drop(held);
    // A dangling link is followed to where it points.
    std::fs::remove_file(&link).unwrap();
    std::os::unix::fs::symlink("elsewhere/new", &link).unwrap();
    let run = deformcal(&["--config", config.to_str().unwrap()]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(link.symlink_metadata().unwrap().file_type().is_symlink());
    assert!(case.path("elsewhere/new/calibration.json").is_file());
    assert!(litter(case.dir.path()).is_empty() && litter(&case.path("elsewhere")).is_empty());
}

#[cfg(unix)]
#[test]
fn the_output_dir_keeps_its_mode_and_owner() {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    let case = Case::new();
    let config = t2_config(&case, 12, "standard");
    let out = case.path("out");
    std::fs::create_dir(&out).unwrap();
    std::fs::set_permissions(&out, std::fs::Permissions::from_mode(0o700)).unwrap();
    let run = deformcal(&["--config", config.to_str().unwrap()]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let mode = |p: &Path| std::fs::metadata(p).unwrap().mode() & 0o7777;
    assert_eq!(
        mode(&out),
        0o700,
        "a private output became {:o}",
        mode(&out)
    );
    // A group-shared dir of another owner, where permitted (root).
    std::fs::set_permissions(&out, std::fs::Permissions::from_mode(0o2770)).unwrap();
    if std::os::unix::fs::chown(&out, Some(65534), Some(65534)).is_ok() {
        let run = deformcal(&["--config", config.to_str().unwrap()]);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        let meta = std::fs::metadata(&out).unwrap();
        assert_eq!(meta.mode() & 0o7777, 0o2770, "{:o}", meta.mode() & 0o7777);
        assert_eq!((meta.uid(), meta.gid()), (65534, 65534));
    } else {
        eprintln!("skipped the owner check: chown needs root");
    }
    // A new output dir gets what any new dir gets here (the umask's default).
    let fresh = case.path("fresh");
    let probe = case.path("probe");
    std::fs::create_dir(&probe).unwrap();
    let run = deformcal(&[
        "--config",
        config.to_str().unwrap(),
        "--output",
        fresh.to_str().unwrap(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert_eq!(mode(&fresh), mode(&probe));
}

#[cfg(unix)]
#[test]
fn a_signal_removes_the_staging_dir_and_says_so() {
    let case = Case::new();
    // Long enough to be caught in the solve.
    let config = t2_config(&case, 600, "full");
    for (signal, name) in [
        (libc::SIGINT, "SIGINT"),
        (libc::SIGTERM, "SIGTERM"),
        (libc::SIGHUP, "SIGHUP"),
    ] {
        let child = Command::new(env!("CARGO_BIN_EXE_deformcal"))
            .args(["--config", config.to_str().unwrap()])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let start = std::time::Instant::now();
        while litter(case.dir.path()).is_empty() {
            assert!(
                start.elapsed().as_secs() < 60,
                "{name}: no staging dir appeared"
            );
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        std::thread::sleep(std::time::Duration::from_millis(300));
        // SAFETY: signalling our own child, whose pid is live until waited for.
        assert_eq!(unsafe { libc::kill(child.id() as i32, signal) }, 0);
        let out = child.wait_with_output().unwrap();
        assert!(!out.status.success(), "{name}: exit 0");
        assert!(
            out.status.code().is_some(),
            "{name}: killed by the signal, no cleanup"
        );
        let e = one_error(&out);
        assert!(e.contains(name), "{name}: {e}");
        assert!(
            litter(case.dir.path()).is_empty(),
            "{name}: {:?}",
            litter(case.dir.path())
        );
        assert!(
            !case.path("out").exists(),
            "{name}: an output was swapped in"
        );
    }
}

#[cfg(unix)]
#[test]
fn a_file_size_limit_gives_one_error_line_and_no_staging_dir() {
    use std::os::unix::process::CommandExt;
    let case = Case::new();
    let config = t2_config(&case, 12, "standard");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_deformcal"));
    cmd.args(["--config", config.to_str().unwrap()]);
    // SAFETY: setrlimit is async-signal-safe, as pre_exec requires.
    unsafe {
        cmd.pre_exec(|| {
            let limit = libc::rlimit {
                rlim_cur: 4096,
                rlim_max: 4096,
            };
            libc::setrlimit(libc::RLIMIT_FSIZE, &limit);
            Ok(())
        });
    }
    let out = cmd.output().unwrap();
    assert_ne!(out.status.code(), None, "killed by SIGXFSZ");
    let e = one_error(&out);
    assert!(
        e.contains("too large") || e.contains("File too large"),
        "{e}"
    );
    assert!(
        litter(case.dir.path()).is_empty(),
        "{:?}",
        litter(case.dir.path())
    );
    assert!(!case.path("out").exists());
}

#[test]
fn a_later_run_removes_the_staging_dir_of_a_dead_one() {
    let case = Case::new();
    let config = t2_config(&case, 12, "standard");
    // What a run killed with SIGKILL leaves: its staging dir, full.
    let stale = case.path(".out.new-4194304-abcdef");
    std::fs::create_dir_all(stale.join("sub")).unwrap();
    std::fs::write(stale.join("calibration.json"), "half").unwrap();
    std::fs::write(stale.join("sub/x"), "x").unwrap();
    let run = deformcal(&["--config", config.to_str().unwrap()]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(!stale.exists(), "the stale staging dir is still there");
    assert!(case.path("out/calibration.json").is_file());
}
