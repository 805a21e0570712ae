//! Where a dataset comes from: an observations CSV, mrgingham's corners.vnl, photos
//! or a built-in synthetic preset; and writing a generated preset to disk.
use crate::app::config::{Config, DataSource};
use crate::app::fsio::write_atomic;
use crate::app::{corners_vnl, observations_csv};
use crate::error::Result;
use crate::model::camera::CameraSpec;
use crate::model::dataset::Dataset;
use crate::model::synthetic::{self, Truth};
use crate::model::target::Target;
use std::path::Path;

/// The name of each image a frame came from, by (camera index, frame number), where
/// the data source knows it (photos, corners.vnl); reports show it beside the frame number.
pub type FrameLabels = corners_vnl::FileNames;

/// What a config's `[data]` gives: the dataset, the truth of a synthetic preset and
/// the image file names.
#[derive(Debug, Clone)]
pub struct Loaded {
    /// The observations, cameras and board.
    pub dataset: Dataset,
    /// The truth of a synthetic preset.
    pub truth: Option<synthetic::Truth>,
    /// The image file of each (camera, frame), where known.
    pub labels: FrameLabels,
}

/// Loads a config's `[data]`; photos are detected (or taken from the detection
/// cache) with a progress bar, their results written into the output dir and
/// summarised on stderr.
pub fn load_data(config: &Config) -> Result<(Dataset, Option<synthetic::Truth>)> {
    let loaded = load_labelled(config)?;
    Ok((loaded.dataset, loaded.truth))
}

/// [`load_data`], with the file name of every photo or corners.vnl image.
pub fn load_labelled(config: &Config) -> Result<Loaded> {
    if let DataSource::Photos { .. } = &config.data {
        let run = crate::app::photos::detect_photos(
            &config.data,
            config.target,
            &config.cameras,
            &config.output_dir,
            true,
        )?;
        for line in crate::app::photos::summary(&run) {
            eprintln!("{line}");
        }
        let labels = run
            .images
            .iter()
            .map(|r| ((r.file.camera, r.file.frame), r.file.name.clone()))
            .collect();
        return Ok(Loaded {
            dataset: run.dataset,
            truth: None,
            labels,
        });
    }
    if let DataSource::CornersVnl { path, patterns } = &config.data {
        let (dataset, _, labels) = corners_vnl::read_corners_vnl_named(
            path,
            config.target,
            config.cameras.clone(),
            patterns,
        )?;
        return Ok(Loaded {
            dataset,
            truth: None,
            labels,
        });
    }
    let (dataset, truth) = load_source(&config.data, config.target, &config.cameras)?;
    Ok(Loaded {
        dataset,
        truth,
        labels: FrameLabels::new(),
    })
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
        DataSource::Photos { .. } => Err(crate::error::Error::Invalid(
            "photos are detected through source::load_data, which knows the output dir".into(),
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
