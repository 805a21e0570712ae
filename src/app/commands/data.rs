//! `deformcal generate`, `import` and `detect`: data in and out without a
//! calibration (a synthetic dataset, a config's data as an observations CSV, the
//! board detected in a config's photos).
use crate::app::config::Config;
use crate::app::fsio::OutputSet;
use crate::model::lens::LensModel;
use crate::model::synthetic::{Generator, Preset, MAX_IMAGES};
use anyhow::{Context, Result};
use std::path::PathBuf;

/// `deformcal generate`.
#[derive(clap::Args, Debug)]
pub struct GenerateArgs {
    /// Preset: t1, t2, t3, t4 or reference.
    #[arg(long)]
    pub preset: String,
    /// Folder to write observations.csv and truth.json into.
    #[arg(long)]
    pub out: PathBuf,
    /// Number of images (default: the preset's).
    #[arg(long)]
    pub images: Option<usize>,
    /// Random seed.
    #[arg(long, default_value_t = crate::app::config::DEFAULT_SYNTHETIC_SEED)]
    pub seed: u64,
    /// Cameras on the simulated rig, 0.3 m apart (default: the preset's).
    #[arg(long)]
    pub cameras: Option<usize>,
    /// Lens model of the simulated cameras (default: the registry's default model).
    #[arg(long, default_value_t = LensModel::default().name().to_string())]
    pub model: String,
}

/// `deformcal import`.
#[derive(clap::Args, Debug)]
pub struct ImportArgs {
    /// The TOML config whose [data] to read.
    #[arg(long, short)]
    pub config: PathBuf,
    /// The observations CSV to write.
    #[arg(long)]
    pub out: PathBuf,
}

/// `deformcal detect`.
#[derive(clap::Args, Debug)]
pub struct DetectArgs {
    /// The TOML config whose `[data] photos` or `video` to detect.
    #[arg(long, short)]
    pub config: PathBuf,
    /// Also write the observations CSV here (it is always written to the output dir).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Override [output] dir (detections.csv, observations.csv, the detection cache).
    #[arg(long)]
    pub output: Option<PathBuf>,
}

/// `deformcal generate`.
pub fn run_generate(args: GenerateArgs) -> Result<()> {
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
    let model = crate::LensModel::parse(&args.model).with_context(|| {
        format!(
            "--model: unknown lens model `{}` (expected one of {})",
            args.model,
            crate::LensModel::names()
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
    crate::app::source::write_preset(set.path(), &dataset, &truth)?;
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

/// `deformcal import`.
pub fn run_import(args: ImportArgs) -> Result<()> {
    let config = Config::load(&args.config)?;
    let (dataset, _) = crate::app::source::load_data(&config)?;
    crate::app::observations_csv::write(&dataset, &args.out)?;
    println!(
        "wrote {} observations of {} frames to {}",
        dataset.observations.len(),
        dataset.num_frames(),
        args.out.display()
    );
    Ok(())
}

/// `deformcal detect`.
pub fn run_detect(args: DetectArgs) -> Result<()> {
    let mut config = super::flags::file_config(&args.config)?;
    if let Some(o) = args.output {
        config.output_dir = o;
    }
    anyhow::ensure!(
        matches!(
            config.data,
            crate::app::config::DataSource::Photos { .. }
                | crate::app::config::DataSource::Video(_)
        ),
        "{}: [data] has no `photos` or `video` to detect the board in",
        args.config.display()
    );
    let (dataset, _) = crate::app::source::load_data(&config)?;
    if let Some(out) = &args.out {
        crate::app::observations_csv::write(&dataset, out)?;
        println!(
            "wrote {} observations of {} frames to {}",
            dataset.observations.len(),
            dataset.num_frames(),
            out.display()
        );
    }
    Ok(())
}
