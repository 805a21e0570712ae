//! The `deformcal` command line.
use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use deformcal::config::Config;
use deformcal::problem::SolverSettings;
use deformcal::synthetic::{Generator, Preset};
use deformcal::{calibrate, output, report, Method, Request};
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
    /// Calibrate as the config says (the default command).
    Calibrate(CalibrateArgs),
    /// Write a built-in synthetic dataset as observations.csv plus truth.json.
    Generate(GenerateArgs),
}

#[derive(Args, Debug)]
struct CalibrateArgs {
    /// The TOML config.
    #[arg(long, short)]
    config: Option<PathBuf>,
    /// Override [calibration] method: standard, static, dynamic or full.
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
    #[arg(long, default_value_t = deformcal::config::DEFAULT_SYNTHETIC_SEED)]
    seed: u64,
}

fn run_calibrate(args: CalibrateArgs) -> Result<()> {
    let path = args
        .config
        .context("no config given: use --config FILE (see configs/ for examples)")?;
    let mut config = Config::load(&path)?;
    if let Some(m) = &args.method {
        config.calibration.method = Method::parse(m).with_context(|| {
            format!("--method: unknown method `{m}` (standard, static, dynamic, full)")
        })?;
    }
    if let Some(o) = args.output {
        config.output_dir = o;
    }
    if let Some(t) = args.threads {
        anyhow::ensure!((1..=256).contains(&t), "--threads must be 1 to 256");
        config.calibration.threads = t;
    }
    let (dataset, _truth) = deformcal::load_source(&config.data, config.target, &config.cameras)?;
    let request = Request {
        method: config.calibration.method,
        settings: SolverSettings::from(&config.calibration),
        gauge: config.calibration.gauge_corners.clone(),
    };
    let result = calibrate(&dataset, &request)?;
    let written = output::write_calibration(&config.output_dir, &result)?;
    print!("{}", report::summary(&result));
    println!("  wrote {}", written.display());
    Ok(())
}

fn run_generate(args: GenerateArgs) -> Result<()> {
    let preset = Preset::parse(&args.preset).with_context(|| {
        format!(
            "--preset: unknown preset `{}` (expected one of {})",
            args.preset,
            Preset::NAMES.join(", ")
        )
    })?;
    anyhow::ensure!(args.images != Some(0), "--images must be at least 1");
    let (dataset, truth) = Generator::new(preset, args.images, args.seed).generate();
    deformcal::synthetic::write_preset(&args.out, &dataset, &truth)?;
    println!(
        "wrote {} images, {} observations of preset {} to {}",
        dataset.num_frames(),
        dataset.observations.len(),
        preset.name(),
        args.out.display()
    );
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Command::Calibrate(a)) => run_calibrate(a),
        Some(Command::Generate(a)) => run_generate(a),
        None => run_calibrate(cli.calibrate),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
