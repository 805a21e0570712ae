//! The `deformcal` command line.
use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use deformcal::app::config::Config;
use deformcal::app::fsio::{self, OutputSet};
use deformcal::app::html_report::REPORT_FILE;
use deformcal::app::protocol::{self, Shard};
use deformcal::app::{guard, lint, output, report};
use deformcal::model::selection::{AutoSettings, MethodChoice};
use deformcal::model::synthetic::{Generator, Preset, MAX_IMAGES};
use deformcal::solver::problem::SolverSettings;
use deformcal::solver::select::calibrate_auto;
use deformcal::{calibrate, Method, Request};
use std::path::PathBuf;
use std::process::ExitCode;

/// Camera calibration that models how a carried chessboard bends.
#[derive(Parser, Debug)]
#[command(name = "deformcal", version, args_conflicts_with_subcommands = true)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    calibrate: CalibrateArgs,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Calibrate once, even when the config has a [protocol] section.
    Calibrate(CalibrateArgs),
    /// Write a built-in synthetic dataset as observations.csv plus truth.json.
    Generate(GenerateArgs),
    /// Convert a config's data (corners.vnl, synthetic) to an observations CSV.
    Import(ImportArgs),
    /// Write opencv.yaml and <camera>.cameramodel files from a calibration.json.
    Export(ExportArgs),
    /// Run the evaluation protocol: every subset × method, with metrics and a report.
    Protocol(ProtocolArgs),
    /// Combine the shard files of a sharded protocol run into its outputs.
    Merge(MergeArgs),
    /// Run the protocol of several configs and write one combined report.
    Batch(BatchArgs),
    /// Only detect the board in the config's photos: detections.csv and observations.csv.
    Detect(DetectArgs),
    /// Compare two calibration.json files: mapping error between them beside their uncertainty.
    Compare(CompareArgs),
    /// Structure from motion around a synthetic building with a calibration's
    /// intrinsics held: its loop-closure error, and the scene in COLMAP's text format.
    Sfm(SfmArgs),
}

#[derive(Args, Debug)]
struct SfmArgs {
    /// The TOML config: its [sfm] section (defaults otherwise) and the true camera
    /// (its synthetic data's truth, or its [reference] set's calibration).
    #[arg(long, short)]
    config: PathBuf,
    /// The calibration.json whose first camera's intrinsics to test.
    #[arg(long)]
    calibration: PathBuf,
    /// Folder for sfm.json and the COLMAP files (default: the config's output dir + /sfm).
    #[arg(long)]
    output: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct CompareArgs {
    /// The first calibration.json.
    a: PathBuf,
    /// The second calibration.json.
    b: PathBuf,
}

#[derive(Args, Debug)]
struct DetectArgs {
    /// The TOML config whose `[data] photos` to detect.
    #[arg(long, short)]
    config: PathBuf,
    /// Also write the observations CSV here (it is always written to the output dir).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Override [output] dir (detections.csv, observations.csv, the detection cache).
    #[arg(long)]
    output: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct ImportArgs {
    /// The TOML config whose [data] to read.
    #[arg(long, short)]
    config: PathBuf,
    /// The observations CSV to write.
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args, Debug)]
struct ExportArgs {
    /// A calibration.json written by deformcal.
    #[arg(long)]
    calibration: PathBuf,
    /// Folder for opencv.yaml and the .cameramodel files.
    #[arg(long)]
    output: PathBuf,
}

#[derive(Args, Debug)]
struct ProtocolArgs {
    /// The TOML config (its [protocol] table, defaults otherwise).
    #[arg(long, short)]
    config: PathBuf,
    /// Run only the i-th of N slices of the subset × method grid (e.g. 0/4), or
    /// `auto`: from a Slurm job array or a Kubernetes Indexed Job's environment.
    #[arg(long)]
    shard: Option<String>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Override [protocol] subsets (e.g. a quick run).
    #[arg(long)]
    subsets: Option<usize>,
    /// Override [output] dir.
    #[arg(long)]
    output: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct MergeArgs {
    /// Folder to write the merged outputs into.
    #[arg(long)]
    output: PathBuf,
    /// Shard files written by `protocol --shard`.
    #[arg(required = true)]
    shards: Vec<PathBuf>,
}

#[derive(Args, Debug)]
struct BatchArgs {
    /// Protocol configs, one per dataset.
    #[arg(required = true)]
    configs: Vec<PathBuf>,
    /// Folder for the combined report; each dataset goes to a subfolder named after its config.
    #[arg(long)]
    output: PathBuf,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Override every config's [protocol] subsets.
    #[arg(long)]
    subsets: Option<usize>,
}

#[derive(Args, Debug)]
struct CalibrateArgs {
    /// The TOML config.
    #[arg(long, short)]
    config: Option<PathBuf>,
    /// Override [calibration] method: standard, static, dynamic, full or auto.
    #[arg(long)]
    method: Option<String>,
    /// Override [output] dir.
    #[arg(long)]
    output: Option<PathBuf>,
    /// Override [calibration] threads.
    #[arg(long)]
    threads: Option<usize>,
}

#[derive(Args, Debug)]
struct GenerateArgs {
    /// Preset: t1, t2, t3, t4 or reference.
    #[arg(long)]
    preset: String,
    /// Folder to write observations.csv and truth.json into.
    #[arg(long)]
    out: PathBuf,
    /// Number of images (default: the preset's).
    #[arg(long)]
    images: Option<usize>,
    /// Random seed.
    #[arg(long, default_value_t = deformcal::app::config::DEFAULT_SYNTHETIC_SEED)]
    seed: u64,
    /// Cameras on the simulated rig, 0.3 m apart (default: the preset's).
    #[arg(long)]
    cameras: Option<usize>,
    /// Lens model of the simulated cameras: radial3, opencv5, opencv8, kb4 or ds.
    #[arg(long, default_value = "radial3")]
    model: String,
}

/// A calibration that ran but failed its guard rails (exit code [`EXIT_FAILED`]).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct GuardFailed(String);

/// The exit code of a calibration that failed its guard rails: its files were
/// written under `FAILED-` names. (1 is any other error, 2 a command-line error.)
const EXIT_FAILED: u8 = 3;

/// The config with the command line's overrides applied.
fn calibrate_config(args: &CalibrateArgs) -> Result<Config> {
    let path = args
        .config
        .as_ref()
        .context("no config given: use --config FILE (see configs/ for examples)")?;
    let mut config = Config::load(path)?;
    if let Some(m) = &args.method {
        config.calibration.method = MethodChoice::parse(m).with_context(|| {
            format!("--method: unknown method `{m}` (standard, static, dynamic, full, auto)")
        })?;
    }
    if let Some(o) = &args.output {
        config.output_dir = o.clone();
    }
    if let Some(t) = args.threads {
        anyhow::ensure!((1..=256).contains(&t), "--threads must be 1 to 256");
        config.calibration.threads = t;
    }
    Ok(config)
}

/// The default command: the protocol when the config has `[protocol]` (docs/conventions.md §5),
/// else one calibration.
fn run_default(args: CalibrateArgs) -> Result<()> {
    let Some(path) = args.config.clone() else {
        return run_calibrate(args);
    };
    if Config::load(&path)?.protocol.is_none() {
        return run_calibrate(args);
    }
    anyhow::ensure!(
        args.method.is_none(),
        "{}: --method applies to one calibration, but the config has a [protocol] section, which runs \
         its `methods`; to calibrate once use `deformcal calibrate --config {}`",
        path.display(),
        path.display()
    );
    eprintln!(
        "{}: the config has a [protocol] section: running the evaluation protocol \
         (`deformcal calibrate --config …` calibrates once instead)",
        path.display()
    );
    run_protocol(ProtocolArgs {
        config: path,
        shard: None,
        threads: args.threads,
        subsets: None,
        output: args.output,
    })
}

fn run_calibrate(args: CalibrateArgs) -> Result<()> {
    let config = calibrate_config(&args)?;
    // Lock and stage the output before the work: a busy or unwritable output
    // directory fails now, not after a long solve.
    let set = OutputSet::begin(&config.output_dir, output::calibration_files())?;
    let loaded = deformcal::app::source::load(&config)?;
    let rules = guard::Rules {
        max_rmse_px: config.calibration.max_rmse_px,
    };
    let first = match config.calibration.method {
        MethodChoice::Fixed(m) => m,
        MethodChoice::Auto => {
            // Settings `auto` cannot run with are no fault of the data: no hints.
            deformcal::solver::select::check(&AutoSettings::from(&config.calibration))?;
            Method::Standard
        }
    };
    let mut result = run_method(&config, &loaded.dataset).inspect_err(|_| {
        for h in guard::error_hints(&loaded.dataset, &request_of(&config, first), rules) {
            eprintln!("hint: {h}");
        }
    })?;
    // Judged as the method that ran (with `auto`, the one chosen).
    let request = request_of(&config, result.method);
    result.detector_noise_px = config.calibration.detector_noise_px;
    // Every warning goes to stderr (the summary on stdout has none), and all to the JSON.
    let mut warnings = result.warnings.clone();
    warnings.extend(loaded.warnings.iter().cloned());
    let lints = lint::flipped_frames(&result, &loaded.files);
    warnings.extend(lints.iter().cloned());
    result.warnings.extend(loaded.warnings.iter().cloned());
    result.warnings.extend(lints);
    // The summary is made while the files are written (on another core).
    let staging = set.path();
    let (summary, written) = rayon::join(
        || report::summary_with(&result, &[]),
        || -> Result<_> {
            let failure = guard::judge(&loaded.dataset, &request, &result, rules, &loaded.files);
            let written = match &failure {
                None => {
                    output::write_calibration_labelled(staging, &result, &loaded.files)?.warnings
                }
                Some(f) => {
                    output::write_failed(staging, &result, f)?;
                    Vec::new()
                }
            };
            Ok((failure, written))
        },
    );
    let (failure, written) = written?;
    set.commit()?;
    print!("{summary}");
    for w in warnings.iter().chain(&written) {
        eprintln!("warning: {w}");
    }
    let Some(failure) = failure else {
        let path = config.output_dir.join("calibration.json");
        println!("  wrote {}", path.display());
        println!(
            "  report: {}",
            config.output_dir.join(REPORT_FILE).display()
        );
        return Ok(());
    };
    for h in &failure.hints {
        eprintln!("hint: {h}");
    }
    Err(GuardFailed(format!(
        "the calibration FAILED: {}; wrote {} and {} (no model files)",
        failure.reasons.join("; "),
        config.output_dir.join(output::FAILED_CALIBRATION).display(),
        output::FAILED_OUTLIERS
    ))
    .into())
}

/// The config's request for one method.
fn request_of(config: &Config, method: Method) -> Request {
    Request {
        method,
        settings: SolverSettings::from(&config.calibration),
        gauge: config.calibration.gauge_corners.clone(),
    }
}

/// One calibration with the config's method, or `auto`'s choice with a progress bar.
fn run_method(config: &Config, dataset: &deformcal::Dataset) -> Result<deformcal::Calibration> {
    let c = &config.calibration;
    let request = |method| request_of(config, method);
    match c.method {
        MethodChoice::Fixed(m) => Ok(calibrate(dataset, &request(m))?),
        MethodChoice::Auto => {
            let auto = AutoSettings::from(c);
            let folds = deformcal::solver::select::fold_count(dataset.num_frames(), &auto);
            let solves = auto.candidates.len() * (folds + 1);
            let bar = indicatif::ProgressBar::new(solves as u64).with_style(
                indicatif::ProgressStyle::with_template(
                    "auto: {msg} [{bar:40}] {pos}/{len} calibrations, {elapsed} elapsed, ETA {eta}",
                )
                .expect("valid template")
                .progress_chars("=> "),
            );
            bar.set_message(format!("{folds}-fold cross-validation"));
            let result = calibrate_auto(dataset, &request(Method::Standard), &auto, &|| bar.inc(1));
            bar.finish_and_clear();
            Ok(result?)
        }
    }
}

fn run_generate(args: GenerateArgs) -> Result<()> {
    let preset = Preset::parse(&args.preset).with_context(|| {
        format!(
            "--preset: unknown preset `{}` (expected one of {})",
            args.preset,
            Preset::NAMES.join(", ")
        )
    })?;
    anyhow::ensure!(
        args.images.is_none_or(|n| (1..=MAX_IMAGES).contains(&n)),
        "--images must be 1 to {MAX_IMAGES}"
    );
    let cameras = args.cameras.unwrap_or(preset.default_cameras());
    anyhow::ensure!((1..=16).contains(&cameras), "--cameras must be 1 to 16");
    let model = deformcal::LensModel::parse(&args.model).with_context(|| {
        format!(
            "--model: unknown lens model `{}` (expected one of {})",
            args.model,
            deformcal::LensModel::names()
        )
    })?;
    let set = OutputSet::begin(
        &args.out,
        Box::new(|n| n == "observations.csv" || n == "truth.json"),
    )?;
    let (dataset, truth) = Generator::new(preset, args.images, args.seed)
        .with_cameras(cameras)
        .with_models(&vec![model; cameras])
        .generate();
    deformcal::app::source::write_preset(set.path(), &dataset, &truth)?;
    set.commit()?;
    println!(
        "wrote {} images, {} observations of preset {} to {}",
        dataset.num_frames(),
        dataset.observations.len(),
        preset.name(),
        args.out.display()
    );
    Ok(())
}

fn run_import(args: ImportArgs) -> Result<()> {
    let config = Config::load(&args.config)?;
    let (dataset, _) = deformcal::app::source::load_data(&config)?;
    deformcal::app::observations_csv::write(&dataset, &args.out)?;
    println!(
        "wrote {} observations of {} frames to {}",
        dataset.observations.len(),
        dataset.num_frames(),
        args.out.display()
    );
    Ok(())
}

fn run_detect(args: DetectArgs) -> Result<()> {
    let mut config = Config::load(&args.config)?;
    if let Some(o) = args.output {
        config.output_dir = o;
    }
    anyhow::ensure!(
        matches!(
            config.data,
            deformcal::app::config::DataSource::Photos { .. }
        ),
        "{}: [data] has no `photos` to detect the board in",
        args.config.display()
    );
    let (dataset, _) = deformcal::app::source::load_data(&config)?;
    if let Some(out) = &args.out {
        deformcal::app::observations_csv::write(&dataset, out)?;
        println!(
            "wrote {} observations of {} frames to {}",
            dataset.observations.len(),
            dataset.num_frames(),
            out.display()
        );
    }
    Ok(())
}

fn run_compare(args: CompareArgs) -> Result<()> {
    use deformcal::app::calibration_json::CalibrationJson;
    use deformcal::app::compare;
    let (a, b) = (
        CalibrationJson::load(&args.a)?,
        CalibrationJson::load(&args.b)?,
    );
    let diffs = compare::compare(&a, &b)
        .with_context(|| format!("{} vs {}", args.a.display(), args.b.display()))?;
    print!(
        "{}",
        compare::format(
            &args.a.display().to_string(),
            &args.b.display().to_string(),
            &diffs
        )
    );
    Ok(())
}

/// The files of `sfm`'s result set.
fn sfm_files() -> fsio::Owns {
    Box::new(|n| {
        matches!(
            n,
            "sfm.json"
                | "images.txt"
                | "points3D.txt"
                | "match_pairs.txt"
                | deformcal::app::exports::COLMAP_FILE
        )
    })
}

fn run_sfm(args: SfmArgs) -> Result<()> {
    use deformcal::app::calibration_json::CalibrationJson;
    use deformcal::app::{exports, sfm};
    let config = Config::load(&args.config)?;
    let json = CalibrationJson::load(&args.calibration)?;
    if config.cameras.is_empty() {
        anyhow::bail!("{}: no camera to test", args.config.display());
    }
    let (cam, spec) = (&json.cameras[0], &config.cameras[0]);
    if (cam.width, cam.height) != (spec.width, spec.height) {
        anyhow::bail!(
            "{}: camera `{}` is {}×{} but the config's first camera is {}×{}",
            args.calibration.display(),
            cam.name,
            cam.width,
            cam.height,
            spec.width,
            spec.height
        );
    }
    let dir = args.output.unwrap_or_else(|| config.output_dir.join("sfm"));
    // Staged and locked before the solves, like every result set.
    let set = OutputSet::begin(&dir, sfm_files())?;
    let exp = protocol::sfm_for_config(&config)?;
    let tested = exp
        .run(&cam.intrinsics)
        .with_context(|| format!("structure from motion with {}", args.calibration.display()))?;
    let truth = exp.run(&exp.true_camera)?;
    let mut summary = exp.summary_json(&tested);
    summary["loop_closure_px_true_camera"] = truth.loop_closure_px.into();
    let mut warnings = Vec::new();
    let (images, points) = sfm::colmap_scene(&exp.scene);
    let mut files = vec![
        ("sfm.json", serde_json::to_string_pretty(&summary)?),
        ("images.txt", images),
        ("points3D.txt", points),
        ("match_pairs.txt", sfm::match_pairs(&exp.scene)),
    ];
    if let Some(c) = exports::cameras_txt(&json, &mut warnings) {
        files.push((exports::COLMAP_FILE, c));
    }
    for (name, text) in &files {
        fsio::write_atomic(&set.path().join(name), text.as_bytes())?;
    }
    set.commit()?;
    for w in warnings {
        eprintln!("warning: {w}");
    }
    println!(
        "loop-closure error: {:.3} px over {} features of the first image ({} frames); \
         with the true camera: {:.3} px\nwritten: sfm.json and COLMAP's cameras.txt, images.txt, \
         points3D.txt, match_pairs.txt in {}",
        tested.loop_closure_px,
        tested.loop_points,
        exp.scene.num_frames(),
        truth.loop_closure_px,
        dir.display()
    );
    Ok(())
}

fn run_export(args: ExportArgs) -> Result<()> {
    let json = deformcal::app::calibration_json::CalibrationJson::load(&args.calibration)?;
    let set = OutputSet::begin(&args.output, output::calibration_files())?;
    let inputs = deformcal::app::exports::OptimizationInputs::Absent(
        deformcal::app::exports::NOT_IN_CALIBRATION_JSON.into(),
    );
    for w in output::write_models(set.path(), &json, &inputs)?.warnings {
        eprintln!("warning: {w}");
    }
    set.commit()?;
    println!(
        "wrote calibration.json, opencv.yaml and {} camera model(s) to {}",
        json.cameras.len(),
        args.output.display()
    );
    println!(
        "  the mrcal models carry no optimization_inputs: {}",
        deformcal::app::exports::NOT_IN_CALIBRATION_JSON
    );
    Ok(())
}

/// Runs (a shard of) one config's protocol with a progress bar; returns header and rows.
fn protocol_rows(
    config: &Config,
    subsets: Option<usize>,
    shard: Option<Shard>,
    threads: Option<usize>,
) -> Result<(protocol::Header, Vec<protocol::Row>)> {
    let mut p = config.protocol.clone().unwrap_or_default();
    if let Some(n) = subsets {
        anyhow::ensure!(
            (1..=protocol::MAX_SUBSETS).contains(&n),
            "--subsets must be 1 to {}",
            protocol::MAX_SUBSETS
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
    let planned =
        protocol::plan(config, &p).with_context(|| format!("{}", config.path.display()))?;
    for w in planned.warnings() {
        eprintln!("warning: {}: {w}", config.path.display());
    }
    let calibrations = planned.calibrations(shard);
    let bar = indicatif::ProgressBar::new(calibrations as u64).with_style(
        indicatif::ProgressStyle::with_template(
            "{prefix} [{bar:40}] {pos}/{len} calibrations, {elapsed} elapsed, ETA {eta}",
        )
        .expect("valid template")
        .progress_chars("=> "),
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

fn print_summary(summary: &deformcal::app::protocol_report::Summary) {
    use deformcal::app::protocol_report::camera_key;
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

fn run_protocol(args: ProtocolArgs) -> Result<()> {
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
                .map_err(|e| deformcal::Error::write(&config.output_dir, e))?;
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
            let file = protocol::ShardFile {
                header,
                shard: [s.index, s.count],
                rows,
            };
            let path = config
                .output_dir
                .join(format!("shard-{}-of-{}.json", s.index, s.count));
            deformcal::app::fsio::write_atomic(&path, serde_json::to_string(&file)?.as_bytes())?;
            println!(
                "wrote {} ({} calibrations) in {:.1} s",
                path.display(),
                file.rows.len(),
                start.elapsed().as_secs_f64()
            );
        }
        Some(set) => {
            let summary =
                deformcal::app::protocol_report::write_outputs(set.path(), &header, &rows)?;
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

fn run_merge(args: MergeArgs) -> Result<()> {
    let set = OutputSet::begin(&args.output, fsio::protocol_files())?;
    let mut files = Vec::new();
    for p in &args.shards {
        files.push((p.display().to_string(), protocol::read_shard(p)?));
    }
    let (header, rows) = protocol::merge_named(files)?;
    let summary = deformcal::app::protocol_report::write_outputs(set.path(), &header, &rows)?;
    set.commit()?;
    print_summary(&summary);
    all_failed(&header, &rows)?;
    println!("wrote {}", args.output.join("report.md").display());
    Ok(())
}

fn run_batch(args: BatchArgs) -> Result<()> {
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
        let summary = deformcal::app::protocol_report::write_outputs(&dir, &header, &rows)?;
        print_summary(&summary);
        if let Err(e) = all_failed(&header, &rows) {
            failed.push(format!("{name}: {e}"));
        }
        report.push_str(&deformcal::app::protocol_report::report_markdown(
            &summary,
            &rows,
            &format!("{name}/"),
        ));
        html.push(deformcal::app::protocol_report::dataset_report(
            &summary, &rows,
        )?);
    }
    deformcal::app::fsio::write_atomic(&set.path().join("report.md"), report.as_bytes())?;
    let page = deformcal::app::html_report::protocol::protocol_page(
        "deformcal evaluation protocol: combined report",
        &html,
    );
    deformcal::app::fsio::write_atomic(&set.path().join(REPORT_FILE), page.as_bytes())?;
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
fn all_failed(header: &protocol::Header, rows: &[protocol::Row]) -> Result<()> {
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

/// Longest error message printed: a message quotes input (a header, a name), and
/// a multi-megabyte line helps nobody.
const MAX_MESSAGE_CHARS: usize = 400;

/// The message cut to [`MAX_MESSAGE_CHARS`] on one line.
fn brief(message: &str) -> String {
    let one_line = message.replace(['\n', '\r'], " ");
    if one_line.chars().count() <= MAX_MESSAGE_CHARS {
        return one_line;
    }
    let cut: String = one_line.chars().take(MAX_MESSAGE_CHARS).collect();
    format!("{cut}… (message cut)")
}

/// The signals that stop a run: Ctrl-C, `kill`, a closed terminal.
const STOP_SIGNALS: [(libc::c_int, &str); 3] = [
    (libc::SIGINT, "SIGINT"),
    (libc::SIGTERM, "SIGTERM"),
    (libc::SIGHUP, "SIGHUP"),
];

/// Stops the run cleanly on [`STOP_SIGNALS`]: they are blocked in every thread
/// (threads inherit the mask, so this runs before any is started) and taken by
/// one thread with `sigwait`, which then runs ordinary code, not a handler: it
/// removes the unfinished output, says so on one `error:` line and exits
/// 128 + the signal, as a shell reports it. SIGXFSZ (a file size limit) is
/// ignored, so the write fails with "File too large" and the run ends through
/// its ordinary error path.
fn handle_signals() {
    // SAFETY: an empty sigset_t filled by sigemptyset/sigaddset, and masks and
    // dispositions changed before any other thread exists.
    let set = unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        for (signal, _) in STOP_SIGNALS {
            libc::sigaddset(&mut set, signal);
        }
        libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut());
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
        set
    };
    let watch = move || loop {
        let mut signal: libc::c_int = 0;
        // SAFETY: `set` is initialised and its signals are blocked in this thread.
        if unsafe { libc::sigwait(&set, &mut signal) } != 0 {
            continue;
        }
        let name = STOP_SIGNALS
            .iter()
            .find(|(s, _)| *s == signal)
            .map_or("a signal", |(_, n)| n);
        let removed = fsio::remove_unfinished();
        let what = if removed.is_empty() {
            String::new()
        } else {
            "; removed the unfinished output".to_string()
        };
        eprintln!("error: stopped by {name}{what}");
        // SAFETY: _exit ends the process without running atexit handlers, which
        // could race the solver threads still running.
        unsafe { libc::_exit(128 + signal) };
    };
    // Without the thread the signals stay blocked; better to let them act.
    if std::thread::Builder::new()
        .name("signals".into())
        .spawn(watch)
        .is_err()
    {
        // SAFETY: as above.
        unsafe { libc::pthread_sigmask(libc::SIG_UNBLOCK, &set, std::ptr::null_mut()) };
    }
}

fn main() -> ExitCode {
    // Like any Unix filter, end quietly when the reader of stdout goes away
    // (`deformcal … | head`); Rust's default turns that into a panic.
    // SAFETY: setting a signal's disposition to the default has no preconditions.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    handle_signals();
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Command::Calibrate(a)) => run_calibrate(a),
        Some(Command::Generate(a)) => run_generate(a),
        Some(Command::Import(a)) => run_import(a),
        Some(Command::Export(a)) => run_export(a),
        Some(Command::Protocol(a)) => run_protocol(a),
        Some(Command::Merge(a)) => run_merge(a),
        Some(Command::Batch(a)) => run_batch(a),
        Some(Command::Detect(a)) => run_detect(a),
        Some(Command::Compare(a)) => run_compare(a),
        Some(Command::Sfm(a)) => run_sfm(a),
        None => run_default(cli.calibrate),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", brief(&format!("{e:#}")));
            if e.downcast_ref::<GuardFailed>().is_some() {
                ExitCode::from(EXIT_FAILED)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}
