//! `deformcal export` and `compare`: a calibration.json's models in every format
//! the calibration writes, and two calibrations' mapping error beside their
//! uncertainty.
use crate::app::fsio::OutputSet;
use crate::app::output;
use anyhow::{Context, Result};
use std::path::PathBuf;

/// `deformcal export`.
#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// A calibration.json written by deformcal.
    #[arg(long)]
    pub calibration: PathBuf,
    /// Folder for opencv.yaml and the .cameramodel files.
    #[arg(long)]
    pub output: PathBuf,
}

/// `deformcal compare`.
#[derive(clap::Args, Debug)]
pub struct CompareArgs {
    /// The first calibration.json.
    pub a: PathBuf,
    /// The second calibration.json.
    pub b: PathBuf,
}

/// `deformcal export`.
pub fn run_export(args: ExportArgs) -> Result<()> {
    let json = crate::app::calibration_json::CalibrationJson::load(&args.calibration)?;
    // The models are rewritten; a config.toml beside them stays (it made them).
    let models = output::calibration_files();
    let owns = Box::new(move |name: &str| name != output::RERUN_CONFIG && models(name));
    let set = OutputSet::begin(&args.output, owns)?;
    let inputs = crate::app::exports::OptimizationInputs::Absent(
        crate::app::exports::NOT_IN_CALIBRATION_JSON.into(),
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
        crate::app::exports::NOT_IN_CALIBRATION_JSON
    );
    Ok(())
}

/// `deformcal compare`.
pub fn run_compare(args: CompareArgs) -> Result<()> {
    use crate::app::calibration_json::CalibrationJson;
    use crate::app::compare;
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
