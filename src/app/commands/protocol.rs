//! `deformcal protocol`, `merge` and `batch`: the evaluation protocol of one config
//! (or a shard of it), the merge of shard files, and several configs' protocols
//! with one combined report. Progress on stderr, the summary table on stdout.
use crate::app::config::Config;
use crate::app::fsio::{self, OutputSet};
use crate::app::html_report::REPORT_FILE;
use crate::app::protocol::{self as plan, Shard};
use crate::app::protocol_report;
use anyhow::{Context, Result};
use std::path::PathBuf;

/// `deformcal protocol`.
#[derive(clap::Args, Debug)]
pub struct ProtocolArgs {
    /// The TOML config (its [protocol] table, defaults otherwise).
    #[arg(long, short)]
    pub config: PathBuf,
    /// Run only the i-th of N slices of the subset × method grid (e.g. 0/4), or
    /// `auto`: from a Slurm job array or a Kubernetes Indexed Job's environment.
    #[arg(long)]
    pub shard: Option<String>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Override [protocol] subsets (e.g. a quick run).
    #[arg(long)]
    pub subsets: Option<usize>,
    /// Override [output] dir.
    #[arg(long)]
    pub output: Option<PathBuf>,
}

/// `deformcal merge`.
#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// Folder to write the merged outputs into.
    #[arg(long)]
    pub output: PathBuf,
    /// Shard files written by `protocol --shard`.
    #[arg(required = true)]
    pub shards: Vec<PathBuf>,
}

/// `deformcal batch`.
#[derive(clap::Args, Debug)]
pub struct BatchArgs {
    /// Protocol configs, one per dataset.
    #[arg(required = true)]
    pub configs: Vec<PathBuf>,
    /// Folder for the combined report; each dataset goes to a subfolder named after its config.
    #[arg(long)]
    pub output: PathBuf,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Override every config's [protocol] subsets.
    #[arg(long)]
    pub subsets: Option<usize>,
}

/// Runs (a shard of) one config's protocol with a progress bar; returns header and rows.
fn protocol_rows(
    config: &Config,
    subsets: Option<usize>,
    shard: Option<Shard>,
    threads: Option<usize>,
) -> Result<(plan::Header, Vec<plan::Row>)> {
    let mut p = config.protocol.clone().unwrap_or_default();
    if let Some(n) = subsets {
        anyhow::ensure!(
            (1..=plan::MAX_SUBSETS).contains(&n),
            "--subsets must be 1 to {}",
            plan::MAX_SUBSETS
        );
        p.subsets = n;
    }
    let threads = threads.unwrap_or_else(|| {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    });
    anyhow::ensure!((1..=256).contains(&threads), "--threads must be 1 to 256");
    eprintln!(
        "{}: reference calibration and subsets…",
        config.path.display()
    );
    let planned = plan::plan(config, &p).with_context(|| format!("{}", config.path.display()))?;
    for w in planned.warnings() {
        eprintln!("warning: {}: {w}", config.path.display());
    }
    let calibrations = planned.calibrations(shard);
    let bar = super::progress_bar(
        calibrations as u64,
        "{prefix} [{bar:40}] {pos}/{len} calibrations, {elapsed} elapsed, ETA {eta}",
    );
    bar.set_prefix(planned.header().dataset.clone());
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    let run = pool
        .install(|| planned.run_beside_reference(shard, &|| bar.inc(1)))
        .with_context(|| format!("{}", config.path.display()));
    bar.finish_and_clear();
    let (setup, rows) = run?;
    Ok((setup.header, rows))
}

fn print_summary(summary: &protocol_report::Summary) {
    use protocol_report::camera_key;
    let h = &summary.header;
    println!("{}", h.dataset);
    for (k, cam) in h.cameras.iter().enumerate() {
        if h.cameras.len() > 1 {
            println!(" camera {}", cam.name);
        }
        println!(
            "  {:9} {:>16} {:>16} {:>16} {:>7}",
            "method", "train RMSE", "test RMSE", "map. error (px)", "failed"
        );
        let names = h.methods.iter().map(|m| m.name());
        for name in names.chain(h.auto.as_ref().map(|_| "auto")) {
            let s = &summary.methods[name];
            let f = |key: &str| {
                s.metrics
                    .get(key)
                    .map(|x| format!("{:.3} ± {:.3}", x.mean, x.std))
                    .unwrap_or_else(|| "–".into())
            };
            let mapping = if h.truth.is_some() {
                "truth_mapping_error_px"
            } else {
                "mapping_error_px"
            };
            println!(
                "  {:9} {:>16} {:>16} {:>16} {:>7}",
                name,
                f("rmse_px"),
                f(&camera_key(h, k, "test_rmse_px")),
                f(&camera_key(h, k, mapping)),
                s.failed
            );
        }
    }
    if !summary.auto_choices.is_empty() {
        let choices: Vec<String> = summary
            .auto_choices
            .iter()
            .map(|(m, n)| format!("{m} {n}×"))
            .collect();
        println!("  auto chose: {}", choices.join(", "));
    }
    // The [sfm] experiment's figure (the paper's Table 1), where the run had one.
    let loops: Vec<String> = h
        .methods
        .iter()
        .filter_map(|m| {
            let x = summary.methods[m.name()].metrics.get("loop_closure_px")?;
            Some(format!("{m} {:.2} ± {:.2}", x.mean, x.std))
        })
        .collect();
    if !loops.is_empty() {
        println!("  SfM loop-closure error (px): {}", loops.join(", "));
    }
}

/// `deformcal protocol`.
pub fn run(args: ProtocolArgs) -> Result<()> {
    let start = std::time::Instant::now();
    let mut config = Config::load(&args.config)?;
    if let Some(o) = args.output {
        config.output_dir = o;
    }
    let shard =
        match args.shard.as_deref() {
            Some("auto") => {
                let (s, from) = Shard::from_env(|v| std::env::var(v).ok())?;
                eprintln!("shard {}/{} (from {from})", s.index, s.count);
                Some(s)
            }
            Some(s) => Some(Shard::parse(s).with_context(|| {
                format!("--shard: `{s}` is not i/N with 0 <= i < N, nor `auto`")
            })?),
            None => None,
        };
    // Shards of one run write side by side into one directory, each its own file;
    // the unsharded outputs are one set, staged and swapped in under the lock.
    let set = match shard {
        Some(_) => {
            std::fs::create_dir_all(&config.output_dir)
                .map_err(|e| crate::Error::write(&config.output_dir, e))?;
            None
        }
        None => Some(OutputSet::begin(
            &config.output_dir,
            fsio::protocol_files(),
        )?),
    };
    let (header, rows) = protocol_rows(&config, args.subsets, shard, args.threads)?;
    match set {
        None => {
            let s = shard.expect("a shard when there is no output set");
            let file = plan::ShardFile {
                header,
                shard: [s.index, s.count],
                rows,
            };
            let path = config
                .output_dir
                .join(format!("shard-{}-of-{}.json", s.index, s.count));
            fsio::write_atomic(&path, serde_json::to_string(&file)?.as_bytes())?;
            println!(
                "wrote {} ({} calibrations) in {:.1} s",
                path.display(),
                file.rows.len(),
                start.elapsed().as_secs_f64()
            );
        }
        Some(set) => {
            let summary = protocol_report::write_outputs(set.path(), &header, &rows)?;
            set.commit()?;
            print_summary(&summary);
            all_failed(&header, &rows)?;
            println!(
                "wrote {} in {:.1} s",
                config.output_dir.join("report.md").display(),
                start.elapsed().as_secs_f64()
            );
        }
    }
    Ok(())
}

/// `deformcal merge`.
pub fn run_merge(args: MergeArgs) -> Result<()> {
    let set = OutputSet::begin(&args.output, fsio::protocol_files())?;
    let mut files = Vec::new();
    for p in &args.shards {
        files.push((p.display().to_string(), plan::read_shard(p)?));
    }
    let (header, rows) = plan::merge_named(files)?;
    let summary = protocol_report::write_outputs(set.path(), &header, &rows)?;
    set.commit()?;
    print_summary(&summary);
    all_failed(&header, &rows)?;
    println!("wrote {}", args.output.join("report.md").display());
    Ok(())
}

/// `deformcal batch`.
pub fn run_batch(args: BatchArgs) -> Result<()> {
    let start = std::time::Instant::now();
    let mut report = String::from("# deformcal evaluation protocol: combined report\n\n");
    let mut names = std::collections::BTreeSet::new();
    // Every config is checked before the first dataset runs.
    let mut configs = Vec::new();
    for path in &args.configs {
        let config = Config::load(path)?;
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        anyhow::ensure!(
            names.insert(name.clone()),
            "{}: two configs share the name `{name}`",
            path.display()
        );
        configs.push((config, name));
    }
    let owned = names.clone();
    let set = OutputSet::begin(
        &args.output,
        Box::new(move |n| n == "report.md" || n == REPORT_FILE || owned.contains(n)),
    )?;
    let mut failed = Vec::new();
    let mut html = Vec::new();
    for (config, name) in &configs {
        let (header, rows) = protocol_rows(config, args.subsets, None, args.threads)?;
        let dir = set.path().join(name);
        let summary = protocol_report::write_outputs(&dir, &header, &rows)?;
        print_summary(&summary);
        if let Err(e) = all_failed(&header, &rows) {
            failed.push(format!("{name}: {e}"));
        }
        report.push_str(&protocol_report::report_markdown(
            &summary,
            &rows,
            &format!("{name}/"),
        ));
        html.push(protocol_report::dataset_report(&summary, &rows)?);
    }
    fsio::write_atomic(&set.path().join("report.md"), report.as_bytes())?;
    let page = crate::app::html_report::protocol::protocol_page(
        "deformcal evaluation protocol: combined report",
        &html,
    );
    fsio::write_atomic(&set.path().join(REPORT_FILE), page.as_bytes())?;
    set.commit()?;
    anyhow::ensure!(failed.is_empty(), "{}", failed.join("; "));
    println!(
        "wrote {} in {:.1} s",
        args.output.join("report.md").display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// A protocol run in which every calibration failed is a failure, not a result.
fn all_failed(header: &plan::Header, rows: &[plan::Row]) -> Result<()> {
    if !rows.is_empty() && rows.iter().all(|r| !r.ok()) {
        let first = rows[0].error.as_deref().unwrap_or("");
        anyhow::bail!(
            "every one of the {} calibrations of {} failed (the first: {first}); the outputs say why",
            rows.len(),
            header.dataset
        );
    }
    Ok(())
}
