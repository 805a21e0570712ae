//! Where a dataset comes from: an observations CSV, mrgingham's corners.vnl, photos, a video
//! or a built-in synthetic preset; and writing a generated preset to disk.
use crate::app::config::{Config, DataSource};
use crate::app::fsio::write_atomic;
use crate::app::lint::{self, FrameFiles, NameSource};
use crate::app::{corners_vnl, observations_csv};
use crate::error::Result;
use crate::model::camera::CameraSpec;
use crate::model::dataset::Dataset;
use crate::model::synthetic::{self, Truth};
use crate::model::target::Target;
use std::path::Path;

/// A config's data with what loading it learnt beyond the observations.
#[derive(Debug, Clone)]
pub struct Loaded {
    pub dataset: Dataset,
    /// The truth of synthetic data.
    pub truth: Option<synthetic::Truth>,
    /// The image file of each view, where the data came from files.
    pub files: FrameFiles,
    /// Warnings about the input (file names that look like several cameras).
    pub warnings: Vec<String>,
    /// Views whose corner ids the detector chose by the board's symmetry: their
    /// labelling is not tied to the printed board, so a per-corner correction
    /// cannot use it.
    pub labelled_by_symmetry: usize,
}

/// Loads a config's `[data]` with its file names and input warnings; photos are
/// detected (or taken from the detection cache) with a progress bar, their results
/// written into the output dir and summarised on stderr.
pub fn load(config: &Config) -> Result<Loaded> {
    let names: Vec<String> = config.cameras.iter().map(|c| c.name.clone()).collect();
    let mut labelled_by_symmetry = 0;
    let (dataset, truth, listed, kind) = match &config.data {
        DataSource::Photos { .. } => {
            let run = crate::app::photos::detect_photos(
                &config.data,
                config.target,
                config.charuco.as_ref(),
                &config.cameras,
                &config.output_dir,
                true,
            )?;
            for line in crate::app::photos::summary(&run) {
                eprintln!("{line}");
            }
            let listed: Vec<(usize, i64, String)> = run
                .images
                .iter()
                .map(|r| (r.file.camera, r.file.frame, r.file.name.clone()))
                .collect();
            labelled_by_symmetry = run.labelled_by_symmetry();
            (run.dataset, None, listed, Some(NameSource::Photos))
        }
        DataSource::Video(source) => {
            let run = crate::app::video::detect_video(
                source,
                config.target,
                config.charuco.as_ref(),
                &config.cameras[0],
                &config.output_dir,
                true,
            )?;
            for line in crate::app::video::summary(&run) {
                eprintln!("{line}");
            }
            let listed: Vec<(usize, i64, String)> = run
                .frames
                .iter()
                .filter(|f| f.verdict == crate::app::video::choose::Verdict::Kept)
                .map(|f| (0, f.index as i64, run.frame_name(f)))
                .collect();
            (run.dataset, None, listed, None)
        }
        DataSource::CornersVnl { path, patterns } => {
            let t = corners_vnl::read_table(path, config.target, config.cameras.clone(), patterns)?;
            (t.dataset, None, t.files, Some(NameSource::CornersVnl))
        }
        other => {
            let (d, t) = load_source(other, config.target, &config.cameras)?;
            (d, t, Vec::new(), None)
        }
    };
    let warnings = match kind {
        Some(kind) => {
            let by_camera: Vec<(usize, String)> =
                listed.iter().map(|(k, _, n)| (*k, n.clone())).collect();
            lint::several_cameras(&names, &by_camera, kind)
        }
        None => Vec::new(),
    };
    let files = listed.into_iter().map(|(k, f, n)| ((k, f), n)).collect();
    Ok(Loaded {
        dataset,
        truth,
        files,
        warnings,
        labelled_by_symmetry,
    })
}

/// Loads a config's `[data]` (see [`load`]), printing the input warnings on stderr.
pub fn load_data(config: &Config) -> Result<(Dataset, Option<synthetic::Truth>)> {
    let loaded = load(config)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    Ok((loaded.dataset, loaded.truth))
}

/// Loads the dataset a data source names, for the given board and cameras.
/// Photos need an output dir: use [`load_data`].
pub fn load_source(
    source: &DataSource,
    target: Target,
    cameras: &[CameraSpec],
) -> Result<(Dataset, Option<synthetic::Truth>)> {
    match source {
        DataSource::Observations(path) => Ok((
            observations_csv::read(path, target, cameras.to_vec())?,
            None,
        )),
        DataSource::CornersVnl { path, patterns } => {
            let (d, _) = corners_vnl::read_corners_vnl(path, target, cameras.to_vec(), patterns)?;
            Ok((d, None))
        }
        DataSource::Photos { .. } | DataSource::Video(_) => Err(crate::error::Error::Invalid(
            "photos and videos are detected through source::load_data, which knows the output dir"
                .into(),
        )),
        DataSource::Synthetic {
            preset,
            images,
            seed,
            cameras: n,
        } => {
            let models: Vec<_> = (0..*n)
                .map(|k| cameras.get(k).map(|c| c.model).unwrap_or_default())
                .collect();
            let (mut d, t) = synthetic::Generator::new(*preset, *images, *seed)
                .with_cameras(*n)
                .with_models(&models)
                .generate();
            // The config names the simulated cameras and may hold parameters.
            for (spec, given) in d.cameras.iter_mut().zip(cameras) {
                spec.name = given.name.clone();
                spec.fix = given.fix.clone();
            }
            Ok((d, Some(t)))
        }
    }
}

/// Writes `observations.csv` and `truth.json` into `dir`.
pub fn write_preset(dir: &Path, dataset: &Dataset, truth: &Truth) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| crate::error::Error::io(dir, e))?;
    observations_csv::write(dataset, &dir.join("observations.csv"))?;
    let json = serde_json::to_string_pretty(truth).expect("truth serialises");
    write_atomic(&dir.join("truth.json"), json.as_bytes())
}
