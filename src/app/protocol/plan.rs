//! Planning a run: the data loaded, the subsets drawn, the header written;
//! the reference calibration is `run`'s.
use super::record::{data_fingerprint, AutoRun, Header};
use super::run::{no_sfm_camera, Measures, Plan, Setup};
use crate::app::config::{Config, ProtocolConfig, MAX_SUBSETS};
use crate::app::sfm::Experiment;
use crate::error::{Error, Result};
use crate::model::selection::AutoSettings;
use crate::solver::problem::SolverSettings;
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Draws `subsets` subsets of `k` distinct frames out of `n`, each sorted.
///
/// A partial Fisher–Yates shuffle driven by ChaCha8's specified stream, so the
/// subsets are the same on every machine, thread count and library version.
pub fn draw_subsets(n: usize, k: usize, subsets: usize, seed: u64) -> Result<Vec<Vec<usize>>> {
    if k < crate::solver::calibrate::MIN_IMAGES {
        return Err(Error::Invalid(format!(
            "images_per_subset is {k}; a calibration needs at least {}",
            crate::solver::calibrate::MIN_IMAGES
        )));
    }
    if subsets > MAX_SUBSETS {
        return Err(Error::TooLarge(format!(
            "{subsets} subsets; at most {MAX_SUBSETS} are possible"
        )));
    }
    if k > n {
        return Err(Error::Degenerate(format!(
            "images_per_subset is {k} but the dataset has only {n} images"
        )));
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(subsets);
    for _ in 0..subsets {
        let mut idx: Vec<usize> = (0..n).collect();
        for i in 0..k {
            let j = i + (rng.next_u64() % (n - i) as u64) as usize;
            idx.swap(i, j);
        }
        let mut s = idx[..k].to_vec();
        s.sort_unstable();
        out.push(s);
    }
    Ok(out)
}

/// Loads the data, runs the reference calibration and draws the subsets.
pub fn prepare(config: &Config, protocol: &ProtocolConfig) -> Result<Setup> {
    let Plan(mut setup) = plan(config, protocol)?;
    let measures = setup.measures()?;
    setup.install(measures);
    Ok(setup)
}

/// [`prepare`] without the reference calibration, which is left to run beside
/// the subsets' ([`Plan::run_beside_reference`]): it is one long single-threaded
/// solve (650 images), and the other cores would wait for it. What needs the
/// reference (its board σ, the `[sfm]` scene, the mapping-error grids) waits
/// with it; the `[sfm]` values are checked here.
pub fn plan(config: &Config, protocol: &ProtocolConfig) -> Result<Plan> {
    let (dataset, truth) = crate::app::source::load_data(config)?;
    // One Ceres thread per solve: parallelism comes from running tasks side by side,
    // and single-threaded solves sum in a fixed order, so results are reproducible.
    let settings = SolverSettings {
        threads: 1,
        ..SolverSettings::from(&config.calibration)
    };
    let mut warnings = Vec::new();
    let reference_data = match &config.reference {
        None => None,
        Some(r) => {
            let (ref_data, _) =
                crate::app::source::load_source(&r.source, r.target, &config.cameras)?;
            warnings.extend(crate::app::lint::reference_is_training(&dataset, &ref_data));
            if ref_data.cameras.len() != dataset.cameras.len() {
                return Err(Error::Invalid(format!(
                    "the reference set has {} camera(s) but the data has {}; set reference.cameras",
                    ref_data.cameras.len(),
                    dataset.cameras.len()
                )));
            }
            Some(ref_data)
        }
    };
    let subsets = draw_subsets(
        dataset.num_frames(),
        protocol.images_per_subset,
        protocol.subsets,
        protocol.seed,
    )?;
    let header = Header {
        data: data_fingerprint(&dataset, reference_data.as_ref()),
        dataset: dataset_name(config),
        subsets: protocol.subsets,
        images_per_subset: protocol.images_per_subset,
        seed: protocol.seed,
        methods: protocol.methods.clone(),
        target: dataset.target,
        cameras: dataset.cameras.clone(),
        dataset_images: dataset.num_frames(),
        reference: None,
        truth: truth.as_ref().map(|t| t.intrinsics.clone()),
        auto: protocol.auto.then(|| {
            let a = AutoSettings::from(&config.calibration);
            AutoRun {
                candidates: a.candidates,
                folds: a.folds,
                seed: a.seed,
            }
        }),
    };
    if let Some(s) = &config.sfm {
        s.check().map_err(Error::Invalid)?;
        if truth.is_none() && reference_data.is_none() {
            return Err(no_sfm_camera());
        }
    }
    Ok(Plan(Setup {
        measures: Measures::default(),
        header,
        dataset,
        truth,
        subsets,
        settings,
        warnings,
        detector_noise_px: config.calibration.detector_noise_px,
        reference_data,
        sfm_config: config.sfm.clone(),
    }))
}

/// The whole `[sfm]` set-up of a config for `deformcal sfm`: its data's truth or
/// its reference calibration, without drawing subsets.
pub fn sfm_for_config(config: &Config) -> Result<Experiment> {
    let protocol = ProtocolConfig {
        subsets: 1,
        images_per_subset: crate::solver::calibrate::MIN_IMAGES,
        ..ProtocolConfig::default()
    };
    let with_sfm = Config {
        sfm: Some(config.sfm.clone().unwrap_or_default()),
        ..config.clone()
    };
    let setup = prepare(&with_sfm, &protocol)?;
    setup
        .measures
        .sfm
        .ok_or_else(|| Error::Invalid("no [sfm] scene".into()))
}

fn dataset_name(config: &Config) -> String {
    match &config.data {
        crate::app::config::DataSource::Synthetic { preset, .. } => preset.name().to_string(),
        crate::app::config::DataSource::Observations(p) => p.display().to_string(),
        crate::app::config::DataSource::CornersVnl { path, .. } => path.display().to_string(),
        crate::app::config::DataSource::Photos { base, .. } => base.display().to_string(),
        crate::app::config::DataSource::Video(v) => v.path.display().to_string(),
    }
}
