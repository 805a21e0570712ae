//! `protocol --shard auto` on a real Slurm job array (Debian's slurm-wlm, a
//! one-node cluster started by `scripts/slurm-single-node.sh`): the shards the
//! array tasks write merge into exactly what one unsharded run writes. Skips,
//! saying why, where Slurm is not installed or cannot be started (not root).
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

fn have(tool: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Whether a Slurm node answers, starting the one-node cluster if we may.
fn slurm_up() -> Result<(), String> {
    if !have("sbatch") {
        return Err("slurm-wlm is not installed".into());
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/slurm-single-node.sh");
    let is_root = Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0");
    if !is_root {
        return Err("not root: cannot start the one-node Slurm cluster".into());
    }
    let out = Command::new(&script)
        .arg("start")
        .output()
        .map_err(|e| e.to_string())?;
    if !out.status.success() {
        // Installed, and we are root: a cluster that does not come up is a failure.
        panic!(
            "{} failed: {}",
            script.display(),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(())
}

fn run(bin: &str, args: &[&str]) {
    let out = Command::new(bin).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_slurm_job_array_shards_and_merges_into_the_unsharded_outputs() {
    if let Err(why) = slurm_up() {
        eprintln!("skipped: {why}");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("p.toml");
    std::fs::write(
        &config,
        "[data]\nsynthetic = \"t2\"\n[reference]\nsynthetic = \"reference\"\nimages = 60\n[protocol]\nsubsets = 3\nmethods = [\"standard\", \"dynamic\"]\n[output]\ndir = \"whole\"\n",
    )
    .unwrap();
    let bin = env!("CARGO_BIN_EXE_deformcal");
    let c = config.to_str().unwrap();
    run(bin, &["protocol", "--config", c, "--threads", "1"]);
    let shards = dir.path().join("shards");
    let job = format!(
        "{bin} protocol --config {c} --threads 1 --shard auto --output {}",
        shards.display()
    );
    let log = dir.path().join("slurm-%a.out");
    let mut sbatch = Command::new("sbatch")
        .args(["--wait", "--array=0-2", "--time=10", "--parsable"])
        .arg(format!("--output={}", log.display()))
        .arg(format!("--wrap={job}"))
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(900);
    let status = loop {
        if let Some(s) = sbatch.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            let _ = sbatch.kill();
            panic!("the Slurm array did not finish in 15 minutes");
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    for i in 0..3 {
        let text =
            std::fs::read_to_string(dir.path().join(format!("slurm-{i}.out"))).unwrap_or_default();
        eprintln!("array task {i}: {}", text.trim());
        assert!(
            text.contains(&format!("shard {i}/3 (from SLURM_ARRAY_TASK_ID)")),
            "{text}"
        );
    }
    assert!(status.success(), "sbatch: {status}");
    let merged = dir.path().join("merged");
    let shard = |i: usize| shards.join(format!("shard-{i}-of-3.json"));
    run(
        bin,
        &[
            "merge",
            "--output",
            merged.to_str().unwrap(),
            shard(0).to_str().unwrap(),
            shard(1).to_str().unwrap(),
            shard(2).to_str().unwrap(),
        ],
    );
    let whole = dir.path().join("whole");
    for f in [
        "protocol.csv",
        "summary.json",
        "report.md",
        "deformations.csv",
    ] {
        let a = std::fs::read(whole.join(f)).unwrap_or_else(|_| panic!("missing {f}"));
        assert_eq!(a, std::fs::read(merged.join(f)).unwrap(), "{f} differs");
    }
}
