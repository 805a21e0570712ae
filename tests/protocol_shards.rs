//! The protocol's shards from the command line and the environment: Slurm's and
//! Kubernetes' indices, shards of other data refused at merge, impossible shards.
use deformcal::app::protocol::Shard;
use std::path::Path;
use std::process::Command;

#[test]
fn shard_auto_reads_slurm_and_kubernetes_environments() {
    let env = |pairs: &'static [(&'static str, &'static str)]| {
        move |k: &str| {
            pairs
                .iter()
                .find(|(n, _)| *n == k)
                .map(|(_, v)| v.to_string())
        }
    };
    // A Slurm array --array=4-7: task 6 is the third of four.
    let slurm = env(&[
        ("SLURM_ARRAY_TASK_ID", "6"),
        ("SLURM_ARRAY_TASK_MIN", "4"),
        ("SLURM_ARRAY_TASK_MAX", "7"),
        ("SLURM_ARRAY_TASK_COUNT", "4"),
    ]);
    assert_eq!(
        Shard::from_env(slurm).unwrap(),
        (Shard { index: 2, count: 4 }, "SLURM_ARRAY_TASK_ID")
    );
    let k8s = env(&[
        ("JOB_COMPLETION_INDEX", "1"),
        ("DEFORMCAL_SHARD_COUNT", "3"),
    ]);
    assert_eq!(
        Shard::from_env(k8s).unwrap(),
        (Shard { index: 1, count: 3 }, "JOB_COMPLETION_INDEX")
    );
    let err = |e: deformcal::Error| e.to_string();
    // Task 5 of a 3-task array (SLURM_ARRAY_TASK_MAX unset) is no shard of it.
    let beyond = env(&[
        ("SLURM_ARRAY_TASK_ID", "5"),
        ("SLURM_ARRAY_TASK_COUNT", "3"),
    ]);
    assert_eq!(
        err(Shard::from_env(beyond).unwrap_err()),
        "invalid argument: --shard auto: SLURM_ARRAY_TASK_ID 5 is outside the array's tasks 0 to 2"
    );
    // --array=0-6:2 leaves gaps: refused, not silently unbalanced.
    let stepped = env(&[
        ("SLURM_ARRAY_TASK_ID", "2"),
        ("SLURM_ARRAY_TASK_MIN", "0"),
        ("SLURM_ARRAY_TASK_MAX", "6"),
        ("SLURM_ARRAY_TASK_COUNT", "4"),
        ("SLURM_ARRAY_TASK_STEP", "2"),
    ]);
    assert_eq!(
        err(Shard::from_env(stepped).unwrap_err()),
        "invalid argument: --shard auto: the Slurm array must be one contiguous range such as --array=0-3 (got tasks 0 to 6, step 2, 4 tasks)"
    );
    assert_eq!(
        err(Shard::from_env(env(&[("JOB_COMPLETION_INDEX", "0")])).unwrap_err()),
        "invalid argument: --shard auto: JOB_COMPLETION_INDEX is set (a Kubernetes Indexed Job) but DEFORMCAL_SHARD_COUNT is not; set it to the Job's completions"
    );
    assert_eq!(
        err(Shard::from_env(env(&[])).unwrap_err()),
        "invalid argument: --shard auto: neither SLURM_ARRAY_TASK_ID (a Slurm job array) nor JOB_COMPLETION_INDEX (a Kubernetes Indexed Job) is set; give --shard i/N instead"
    );
}

/// Runs the binary with `env` added: (success, stderr).
fn cli(args: &[&str], env: &[(&str, &str)]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .args(args)
        .envs(env.iter().copied())
        .env_remove("SLURM_ARRAY_TASK_MAX")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    (out.status.success(), err)
}

/// The last line of a failed run's stderr: its one `error:` line.
fn error_line(err: &str) -> &str {
    let last = err.trim_end().lines().last().unwrap_or("");
    assert!(last.starts_with("error: "), "{err}");
    assert_eq!(err.matches("error: ").count(), 1, "{err}");
    last
}

/// A quick protocol config on synthetic t2 with `seed`.
fn quick_config(dir: &Path, name: &str, seed: u64) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(
        &path,
        format!(
            "[data]\nsynthetic = \"t2\"\nimages = 30\nseed = {seed}\n[protocol]\nsubsets = 2\n\
             images_per_subset = 6\nmethods = [\"standard\"]\n[output]\ndir = \"out\"\n"
        ),
    )
    .unwrap();
    path
}

#[test]
fn merge_refuses_shards_computed_on_other_data() {
    let dir = tempfile::tempdir().unwrap();
    let shards = dir.path().join("shards");
    let s = shards.to_str().unwrap();
    for (i, seed) in [(0, 1), (1, 2)] {
        let config = quick_config(dir.path(), &format!("seed{seed}.toml"), seed);
        let shard = format!("{i}/2");
        let c = config.to_str().unwrap();
        let (ok, err) = cli(
            &["protocol", "--config", c, "--shard", &shard, "--output", s],
            &[],
        );
        assert!(ok, "{err}");
    }
    let (a, b) = (
        shards.join("shard-0-of-2.json"),
        shards.join("shard-1-of-2.json"),
    );
    let merged = dir.path().join("merged");
    let (ok, err) = cli(
        &[
            "merge",
            "--output",
            merged.to_str().unwrap(),
            a.to_str().unwrap(),
            b.to_str().unwrap(),
        ],
        &[],
    );
    assert!(!ok, "shards of two seeds merged");
    let line = error_line(&err);
    assert!(
        line.contains("shard-0-of-2.json")
            && line.contains("shard-1-of-2.json")
            && line.contains("data"),
        "{line}"
    );
    assert!(!merged.exists());
}

#[test]
fn an_impossible_shard_is_refused_from_slurm_and_in_merge() {
    let dir = tempfile::tempdir().unwrap();
    let config = quick_config(dir.path(), "p.toml", 1);
    let c = config.to_str().unwrap();
    let shards = dir.path().join("shards");
    let s = shards.to_str().unwrap();
    // Task 5 of a 3-task array, SLURM_ARRAY_TASK_MAX unset.
    let (ok, err) = cli(
        &["protocol", "--config", c, "--shard", "auto", "--output", s],
        &[
            ("SLURM_ARRAY_TASK_ID", "5"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ],
    );
    assert!(!ok, "task 5 of 3 accepted: {err}");
    assert!(error_line(&err).contains("SLURM_ARRAY_TASK_ID 5"), "{err}");
    assert!(!shards.join("shard-5-of-3.json").exists());
    // A shard file claiming index 5 of 3 is refused by merge, the file named.
    let (ok, err) = cli(
        &["protocol", "--config", c, "--shard", "0/1", "--output", s],
        &[],
    );
    assert!(ok, "{err}");
    let one = shards.join("shard-0-of-1.json");
    let text = std::fs::read_to_string(&one).unwrap();
    assert!(text.contains("\"shard\":[0,1]"));
    let bad = shards.join("shard-5-of-3.json");
    std::fs::write(&bad, text.replace("\"shard\":[0,1]", "\"shard\":[5,3]")).unwrap();
    let merged = dir.path().join("merged");
    let (ok, err) = cli(
        &[
            "merge",
            "--output",
            merged.to_str().unwrap(),
            bad.to_str().unwrap(),
        ],
        &[],
    );
    assert!(!ok, "shard 5/3 merged");
    let line = error_line(&err);
    assert!(
        line.contains("shard-5-of-3.json") && line.contains("5/3"),
        "{line}"
    );
    assert!(!merged.exists());
}
