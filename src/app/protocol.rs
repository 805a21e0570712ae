//! The evaluation protocol (docs/conventions.md §3–4, the paper's section 4): reference calibration,
//! reproducible subsets, every subset × method calibrated and measured, in parallel,
//! sharded if asked.
use crate::app::board_json::BoardJson;
use crate::app::config::{Config, ProtocolConfig};
use crate::app::sfm::{Experiment, SfmConfig};
use crate::error::{Error, Result};
use crate::model::board::{HigherBend, Method, Paraboloid};
use crate::model::camera::CameraSpec;
use crate::model::dataset::Dataset;
use crate::model::lens::Intrinsics;
use crate::model::metrics::{grid_rays, mapping_error_of, mapping_error_rot_of};
use crate::model::selection::{AutoSettings, Selection};
use crate::model::state::State;
use crate::model::synthetic::Truth;
use crate::model::target::Target;
use crate::model::uncertainty::CameraUncertainty;
use crate::solver::calibrate::{calibrate, Calibration, Request, SharedWarmStart};
use crate::solver::problem::{rmse, Hold, PreparedRefit, Problem, SolverSettings};
use crate::solver::select::calibrate_auto_sharing;
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;

pub use crate::app::config::MAX_SUBSETS;

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

/// What a merge needs to know about the run that produced a set of rows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// The dataset's name (preset name or CSV file).
    pub dataset: String,
    pub subsets: usize,
    pub images_per_subset: usize,
    pub seed: u64,
    pub methods: Vec<Method>,
    pub target: Target,
    pub cameras: Vec<CameraSpec>,
    pub dataset_images: usize,
    pub reference: Option<ReferenceInfo>,
    /// True intrinsics per camera (synthetic data).
    pub truth: Option<Vec<Intrinsics>>,
    /// How `auto` chose per subset, when the run records its choice.
    #[serde(default)]
    pub auto: Option<AutoRun>,
    /// The fingerprint of the data the run saw ([`data_fingerprint`]): shards
    /// computed on other data (another seed, an edited CSV) are not one run.
    pub data: String,
}

/// A fingerprint of the observations a run calibrates from and of its reference
/// set: taken from the loaded data rather than the files, so every source is
/// covered alike (a synthetic preset's seed and image count, CSV or corners.vnl
/// bytes, the detections in photos) and the fingerprint changes exactly when
/// what the calibrations see changes. 64-bit FNV-1a: shards of one run are
/// compared, not guarded against forgery.
pub fn data_fingerprint(dataset: &Dataset, reference: Option<&Dataset>) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for &b in bytes {
            h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    };
    for d in std::iter::once(dataset).chain(reference) {
        eat(&(d.frame_ids.len() as u64).to_le_bytes());
        for id in &d.frame_ids {
            eat(&id.to_le_bytes());
        }
        eat(&(d.observations.len() as u64).to_le_bytes());
        for o in &d.observations {
            for n in [o.camera, o.frame, o.corner] {
                eat(&(n as u64).to_le_bytes());
            }
            for x in [o.uv[0], o.uv[1], o.weight] {
                eat(&x.to_bits().to_le_bytes());
            }
        }
    }
    format!(
        "{} observations, fnv1a64 {h:016x}",
        dataset.observations.len()
    )
}

/// `auto`'s settings in a protocol run: every subset gets one more task, which
/// cross-validates these candidates and records the method it keeps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AutoRun {
    pub candidates: Vec<Method>,
    pub folds: usize,
    pub seed: u64,
}

/// What task `t` of the grid runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Task {
    /// Calibrate subset `.0` with a fixed method.
    Fixed(usize, Method),
    /// Let `auto` choose a method for subset `.0`.
    Auto(usize),
}

impl Header {
    /// Tasks per subset: the fixed methods, then `auto` if it is recorded.
    fn per_subset(&self) -> usize {
        self.methods.len() + usize::from(self.auto.is_some())
    }

    /// Number of subset × method tasks.
    pub fn tasks(&self) -> usize {
        self.subsets.saturating_mul(self.per_subset())
    }

    /// What task `t` runs (fixed methods first within a subset, `auto` last).
    pub fn task(&self, t: usize) -> Task {
        let per = self.per_subset();
        let (subset, slot) = (t / per, t % per);
        match self.methods.get(slot) {
            Some(&m) => Task::Fixed(subset, m),
            None => Task::Auto(subset),
        }
    }

    /// The task a row answers, if it lies inside this run's grid.
    fn slot_of(&self, row: &Row) -> Option<usize> {
        let slot = if row.auto {
            self.auto.as_ref().map(|_| self.methods.len())?
        } else {
            self.methods.iter().position(|&x| x == row.method)?
        };
        let t = row
            .subset
            .checked_mul(self.per_subset())?
            .checked_add(slot)?;
        (t < self.tasks()).then_some(t)
    }

    /// Refuses a header whose sizes are out of bounds (a hand-edited or corrupt
    /// shard file) before anything is allocated from them.
    pub fn check(&self) -> Result<()> {
        if self.subsets == 0 || self.subsets > MAX_SUBSETS {
            return Err(Error::TooLarge(format!(
                "the run claims {} subsets; 1 to {MAX_SUBSETS} are possible",
                self.subsets
            )));
        }
        if (self.methods.is_empty() && self.auto.is_none())
            || self.methods.len() > Method::ALL.len()
        {
            return Err(Error::Invalid(format!(
                "the run claims {} methods; 1 to {} are possible",
                self.methods.len(),
                Method::ALL.len()
            )));
        }
        for (i, m) in self.methods.iter().enumerate() {
            if self.methods[..i].contains(m) {
                return Err(Error::Invalid(format!("method {m} is listed twice")));
            }
        }
        Ok(())
    }
}

/// The reference calibration as the report shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReferenceInfo {
    /// Per camera.
    pub intrinsics: Vec<Intrinsics>,
    pub rmse_px: f64,
    pub images: usize,
    pub observations: usize,
    pub converged: bool,
    /// The reference's static correction in `board.json`'s format, written as
    /// [`REFERENCE_BOARD_JSON`] and read back by `[target] geometry`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub board: Option<BoardJson>,
}

/// The protocol's file of the reference static correction (`board.json`'s format).
pub const REFERENCE_BOARD_JSON: &str = "reference_board.json";

/// One subset × method result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    pub subset: usize,
    pub method: Method,
    /// `None` when the calibration succeeded, else the reason it failed.
    pub error: Option<String>,
    pub images: usize,
    pub observations: usize,
    pub converged: bool,
    pub iterations: i32,
    pub rmse_px: Option<f64>,
    /// Per camera (empty when the calibration failed).
    pub cameras: Vec<CameraRow>,
    /// User frame ids of the subset's images, in order.
    pub frames: Vec<i64>,
    /// The per-image paraboloid (methods that have one).
    pub deformations: Vec<Paraboloid>,
    /// `max_out_of_plane_m` per image (methods that have a paraboloid).
    pub max_out_of_plane_m: Vec<f64>,
    /// The degree-3 and -4 bend terms per image (bend orders 3 and 4 only).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub higher_bends: Vec<HigherBend>,
    /// The share of the residual the noise does not explain (docs/conventions.md §3a).
    #[serde(default)]
    pub bias_ratio: Option<f64>,
    /// This row is `auto`'s: `method` is the method it chose (see `selection`).
    #[serde(default)]
    pub auto: bool,
    /// `auto`'s evidence and reason (its rows only, when the choice succeeded).
    #[serde(default)]
    pub selection: Option<Selection>,
    /// The structure-from-motion loop-closure error of camera 0's intrinsics,
    /// pixels (`[sfm]`; the paper's Table 1).
    #[serde(default)]
    pub loop_closure_px: Option<f64>,
    /// Why the reconstruction with this calibration broke off, if it did.
    #[serde(default)]
    pub sfm_error: Option<String>,
}

/// One camera's results in a [`Row`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraRow {
    pub intrinsics: Intrinsics,
    /// π_k: camera-k-from-camera-0.
    pub pose: crate::model::pose::Pose,
    pub test_rmse_px: Option<f64>,
    pub mapping_error_px: Option<f64>,
    pub mapping_error_rot_px: Option<f64>,
    pub truth_mapping_error_px: Option<f64>,
    pub truth_mapping_error_rot_px: Option<f64>,
    /// The mapping error to the truth the noise alone is expected to leave (docs/conventions.md §3a).
    #[serde(default)]
    pub expected_mapping_error_px: Option<f64>,
    /// The same with the virtual rotation profiled out.
    #[serde(default)]
    pub expected_mapping_error_rot_px: Option<f64>,
}

impl Row {
    /// Whether the calibration succeeded.
    pub fn ok(&self) -> bool {
        self.error.is_none()
    }

    /// `auto` for `auto`'s rows, else the method's name: the outputs' method column.
    pub fn label(&self) -> &'static str {
        if self.auto {
            "auto"
        } else {
            self.method.name()
        }
    }

    /// Whether this row is a calibration with the fixed method `m` (not `auto`'s).
    pub fn is_fixed(&self, m: Method) -> bool {
        !self.auto && self.method == m
    }
}

/// `--shard i/N`: the i-th of N disjoint slices of the task grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// Parses `i/N` with 0 ≤ i < N.
    pub fn parse(s: &str) -> Option<Shard> {
        let (i, n) = s.split_once('/')?;
        let (index, count) = (i.trim().parse().ok()?, n.trim().parse().ok()?);
        (count > 0 && index < count).then_some(Shard { index, count })
    }

    /// `--shard auto`: the shard of a Slurm job array task (`SLURM_ARRAY_TASK_ID`,
    /// `_MIN`, `_MAX`, `_COUNT`, `_STEP`) or of a Kubernetes Indexed Job
    /// (`JOB_COMPLETION_INDEX`, with the Job's completions in `DEFORMCAL_SHARD_COUNT`).
    /// `var` reads an environment variable; returns the shard and where it came from.
    pub fn from_env(var: impl Fn(&str) -> Option<String>) -> Result<(Shard, &'static str)> {
        let number = |name: &str| -> Result<Option<usize>> {
            match var(name) {
                None => Ok(None),
                Some(v) => v.trim().parse().map(Some).map_err(|_| {
                    Error::Invalid(format!("--shard auto: {name} is `{v}`, not a number"))
                }),
            }
        };
        if let Some(id) = number("SLURM_ARRAY_TASK_ID")? {
            // Without _MAX the range is taken from _MIN and _COUNT; the task must lie in it.
            let min = number("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let count = number("SLURM_ARRAY_TASK_COUNT")?.ok_or_else(|| {
                Error::Invalid(
                    "--shard auto: SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not"
                        .into(),
                )
            })?;
            let max = number("SLURM_ARRAY_TASK_MAX")?.unwrap_or(min + count.max(1) - 1);
            let step = number("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1);
            if step != 1 || max + 1 != min + count || id < min {
                return Err(Error::Invalid(format!(
                    "--shard auto: the Slurm array must be one contiguous range such as --array=0-{} \
                     (got tasks {min} to {max}, step {step}, {count} tasks)",
                    count.max(1) - 1
                )));
            }
            if id > max {
                return Err(Error::Invalid(format!(
                    "--shard auto: SLURM_ARRAY_TASK_ID {id} is outside the array's tasks {min} to {max}"
                )));
            }
            return Ok((
                Shard {
                    index: id - min,
                    count,
                },
                "SLURM_ARRAY_TASK_ID",
            ));
        }
        if let Some(index) = number("JOB_COMPLETION_INDEX")? {
            let count = number("DEFORMCAL_SHARD_COUNT")?.ok_or_else(|| {
                Error::Invalid(
                    "--shard auto: JOB_COMPLETION_INDEX is set (a Kubernetes Indexed Job) but DEFORMCAL_SHARD_COUNT is not; \
                     set it to the Job's completions"
                        .into(),
                )
            })?;
            if index >= count {
                return Err(Error::Invalid(format!(
                    "--shard auto: JOB_COMPLETION_INDEX {index} is not below DEFORMCAL_SHARD_COUNT {count}"
                )));
            }
            return Ok((Shard { index, count }, "JOB_COMPLETION_INDEX"));
        }
        Err(Error::Invalid(
            "--shard auto: neither SLURM_ARRAY_TASK_ID (a Slurm job array) nor JOB_COMPLETION_INDEX \
             (a Kubernetes Indexed Job) is set; give --shard i/N instead"
                .into(),
        ))
    }

    /// Whether task `t` belongs to this shard (round robin, so shards stay balanced).
    pub fn owns(&self, t: usize) -> bool {
        t % self.count == self.index
    }
}

/// A shard's output file: the header and its rows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardFile {
    pub header: Header,
    pub shard: [usize; 2],
    pub rows: Vec<Row>,
}

/// Everything prepared before the tasks run, the reference calibration included
/// ([`prepare`]; [`plan`] leaves it to [`Plan::run_beside_reference`]).
pub struct Setup {
    pub header: Header,
    pub dataset: Dataset,
    pub truth: Option<Truth>,
    pub subsets: Vec<Vec<usize>>,
    pub settings: SolverSettings,
    /// Warnings about the configuration (a reference set that is the training data).
    pub warnings: Vec<String>,
    /// `[calibration] detector_noise_px`: σ̂ of the bias ratio and the uncertainty
    /// (estimated per subset when `None`).
    pub detector_noise_px: Option<f64>,
    /// The reference calibration and what the rows are measured against with
    /// it; empty until installed.
    measures: Measures,
    /// The reference set, until its calibration is installed.
    reference_data: Option<Dataset>,
    /// `[sfm]`, whose scene may need the reference calibration.
    sfm_config: Option<SfmConfig>,
}

/// A mapping-error grid's pixels and rays ([`grid_rays`]).
type Rays = Vec<(nalgebra::Vector2<f64>, nalgebra::Vector3<f64>)>;

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

/// `[sfm]` without synthetic data's truth or a reference set.
fn no_sfm_camera() -> Error {
    Error::Invalid(
        "[sfm] needs a camera to see the scene with: synthetic data (its true camera) or a \
         [reference] set (its calibration)"
            .into(),
    )
}

/// The scene of `[sfm]`, seen by camera 0's true intrinsics: the truth of
/// synthetic data, else the reference calibration (as the paper's reference
/// stands in for the truth in its mapping error).
pub fn sfm_experiment(
    s: &SfmConfig,
    header: &Header,
    truth: Option<&Truth>,
    reference: Option<&Calibration>,
) -> Result<Experiment> {
    let camera = truth
        .map(|t| t.intrinsics[0])
        .or_else(|| reference.map(|r| r.state.intrinsics[0]))
        .ok_or_else(no_sfm_camera)?;
    let cam = &header.cameras[0];
    Experiment::new(s, &camera, cam.width, cam.height)
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
    }
}

/// The row's per-image bends (methods that have a paraboloid): the paraboloid,
/// the largest deflection and, for bend orders 3 and 4, the higher terms.
fn record_bends(row: &mut Row, c: &Calibration) {
    if row.method.has_paraboloid() {
        row.deformations = c.state.deformations.clone();
        row.max_out_of_plane_m = c.frame_bends();
        if c.state.higher_bends.iter().flatten().any(|&h| h != 0.0) {
            row.higher_bends = c.state.higher_bends.clone();
        }
    }
}

/// `test_rmse_px` of camera `k`: its views of the reference set refitted with only
/// the board poses free, the given intrinsics and the reference static correction
/// held.  The refit is plain least squares: the reference set is clean, and the
/// RMSE is a least-squares figure.  With `settings.per_corner_blocks` it runs on
/// the previous path (one Ceres problem over all frames), which converges to the
/// same optimum within its solver tolerances.  The protocol prepares the refit
/// once per camera instead ([`TestError`]).
pub fn test_rmse(
    reference: &Calibration,
    k: usize,
    intrinsics: &Intrinsics,
    settings: &SolverSettings,
) -> Result<f64> {
    if !settings.per_corner_blocks {
        return TestError::new(reference, k, settings)?.rmse_px(intrinsics);
    }
    let settings = &refit_settings(settings);
    let dataset = reference_views(reference, k)?;
    let mut state = refit_start(reference, k, intrinsics);
    let problem = refit_problem(reference, &dataset);
    let report = problem.solve(&mut state, settings)?;
    if report.usable && !report.residuals.is_empty() {
        return Ok(rmse(&report.residuals));
    }
    Ok(rmse(&problem.evaluate(&state, settings, false)?.residuals))
}

/// The test error of one reference camera, its refit prepared once and run for
/// every calibration measured against it: only the board poses are free and
/// there is no loss, so every frame is its own 6-parameter problem, refitted on
/// its own from the reference's pose (the joint Ceres solve of
/// [`test_rmse`]'s previous path is what it is tested against).
pub struct TestError {
    refit: PreparedRefit,
}

impl TestError {
    /// Prepares camera `k`'s refit on the reference set.
    pub fn new(reference: &Calibration, k: usize, settings: &SolverSettings) -> Result<Self> {
        let dataset = reference_views(reference, k)?;
        let state = refit_start(reference, k, &reference.state.intrinsics[k]);
        let refit = refit_problem(reference, &dataset)
            .prepare_pose_refit(&state, &refit_settings(settings))?;
        Ok(TestError { refit })
    }

    /// `test_rmse_px` under `intrinsics`.
    pub fn rmse_px(&self, intrinsics: &Intrinsics) -> Result<f64> {
        self.refit.rmse_px(std::slice::from_ref(intrinsics))
    }
}

/// The refit's settings: plain least squares.
fn refit_settings(settings: &SolverSettings) -> SolverSettings {
    SolverSettings {
        loss: crate::solver::problem::Loss::None,
        ..settings.clone()
    }
}

/// Camera `k`'s views of the reference set, as a one-camera dataset.
fn reference_views(reference: &Calibration, k: usize) -> Result<Dataset> {
    let r = &reference.dataset;
    let dataset = Dataset {
        cameras: vec![r.cameras[k].clone()],
        observations: r
            .observations
            .iter()
            .filter(|o| o.camera == k)
            .map(|o| crate::model::dataset::Observation { camera: 0, ..*o })
            .collect(),
        ..r.clone()
    };
    if dataset.observations.is_empty() {
        return Err(Error::Degenerate(format!(
            "camera {} has no reference observations",
            r.cameras[k].name
        )));
    }
    Ok(dataset)
}

/// The refit's start: the reference's board poses seen from camera `k`.
fn refit_start(reference: &Calibration, k: usize, intrinsics: &Intrinsics) -> State {
    let pi = reference.state.camera_poses[k];
    State {
        intrinsics: vec![*intrinsics],
        camera_poses: vec![crate::model::pose::Pose::identity()],
        frame_poses: reference
            .state
            .frame_poses
            .iter()
            .map(|p| pi.compose(p))
            .collect(),
        ..reference.state.clone()
    }
}

/// Everything but the board poses held, the reference's static correction among it.
fn refit_problem<'a>(reference: &Calibration, dataset: &'a Dataset) -> Problem<'a> {
    Problem {
        dataset,
        method: Method::Static,
        gauge: reference.gauge.clone(),
        frozen: reference.frozen.clone(),
        hold: Hold {
            intrinsics: true,
            camera_poses: true,
            corrections: true,
            deformations: true,
        },
    }
}

impl Setup {
    /// The reference set's `static` calibration, once installed (none without a
    /// reference set).
    pub fn reference(&self) -> Option<&Calibration> {
        self.measures.reference.as_ref()
    }

    /// The `[sfm]` scene every calibration reconstructs, once installed.
    pub fn sfm(&self) -> Option<&Experiment> {
        self.measures.sfm.as_ref()
    }

    /// The reference set's `static` calibration (none without a reference set),
    /// with the settings of every task.
    fn reference_calibration(&self) -> Result<Option<Calibration>> {
        let Some(ref_data) = &self.reference_data else {
            return Ok(None);
        };
        let request = Request {
            method: Method::Static,
            settings: self.settings.clone(),
            gauge: None,
        };
        calibrate(ref_data, &request)
            .map(Some)
            .map_err(|e| match e {
                Error::Degenerate(m) | Error::Init(m) | Error::Solver(m) => {
                    Error::Degenerate(format!("the reference calibration failed: {m}"))
                }
                other => other,
            })
    }

    /// The reference calibration and what the rows are measured against with it.
    fn measures(&self) -> Result<Measures> {
        let reference = self.reference_calibration()?;
        let reference_info = reference.as_ref().map(|c| ReferenceInfo {
            intrinsics: c.state.intrinsics.clone(),
            rmse_px: c.rmse_px,
            images: c.dataset.num_frames(),
            observations: c.dataset.observations.len(),
            converged: c.converged,
            board: crate::app::board_json::of(c),
        });
        let sfm = match &self.sfm_config {
            None => None,
            Some(s) => Some(sfm_experiment(
                s,
                &self.header,
                self.truth.as_ref(),
                reference.as_ref(),
            )?),
        };
        let grids = self
            .header
            .cameras
            .iter()
            .enumerate()
            .map(|(k, cam)| {
                let rays = |i: &Intrinsics| grid_rays(i, cam.width, cam.height);
                [
                    reference.as_ref().map(|r| rays(&r.state.intrinsics[k])),
                    self.truth.as_ref().map(|t| rays(&t.intrinsics[k])),
                ]
            })
            .collect();
        let test_errors = match &reference {
            None => Vec::new(),
            Some(r) => (0..self.header.cameras.len())
                .map(|k| TestError::new(r, k, &self.settings).map_err(|e| e.to_string()))
                .collect(),
        };
        Ok(Measures {
            reference,
            reference_info,
            sfm,
            grids,
            test_errors,
        })
    }

    /// Takes the reference calibration into the header and the setup.
    fn install(&mut self, mut m: Measures) {
        self.header.reference = m.reference_info.take();
        self.measures = m;
        self.reference_data = None;
    }

    /// What the rows are measured against, once installed.
    fn against(&self) -> Against<'_> {
        self.measures.against()
    }

    /// Camera `k`'s results in `c`; a failed test error is recorded in the row's `error`.
    fn camera_row(
        &self,
        against: &Against,
        c: &Calibration,
        k: usize,
        uncertainty: Option<&CameraUncertainty>,
        error: &mut Option<String>,
    ) -> CameraRow {
        let cam = &self.header.cameras[k];
        let theta = c.state.intrinsics[k];
        let errors = |rays: &Option<Rays>| {
            rays.as_ref().map_or((None, None), |r| {
                (
                    finite(mapping_error_of(r, &theta)),
                    finite(mapping_error_rot_of(r, &theta)),
                )
            })
        };
        let [reference, truth] = &against.grids[k];
        let (mapping, mapping_rot) = errors(reference);
        let (truth, truth_rot) = errors(truth);
        let measured = match (against.reference, against.test_errors.get(k)) {
            (None, _) => None,
            // The previous path (the bench's `PER_CORNER=1`) refits from scratch.
            (Some(r), _) if self.settings.per_corner_blocks => {
                Some(test_rmse(r, k, &theta, &self.settings).map_err(|e| e.to_string()))
            }
            (Some(_), Some(t)) => Some(
                t.as_ref()
                    .map_err(String::clone)
                    .and_then(|t| t.rmse_px(&theta).map_err(|e| e.to_string())),
            ),
            (Some(_), None) => Some(Err("no test-error refit was prepared".to_string())),
        };
        let test = match measured {
            None => None,
            Some(Ok(e)) => finite(e),
            Some(Err(e)) => {
                *error = Some(format!("test error of {}: {e}", cam.name));
                None
            }
        };
        CameraRow {
            intrinsics: theta,
            pose: c.state.camera_poses[k],
            test_rmse_px: test,
            mapping_error_px: mapping,
            mapping_error_rot_px: mapping_rot,
            truth_mapping_error_px: truth,
            truth_mapping_error_rot_px: truth_rot,
            expected_mapping_error_px: uncertainty
                .and_then(|u| finite(u.expected_mapping_error_px)),
            expected_mapping_error_rot_px: uncertainty
                .and_then(|u| finite(u.expected_mapping_error_rot_px)),
        }
    }

    /// Runs one subset × method task; failures become a row with the reason.
    pub fn task(&self, t: usize) -> Row {
        self.row(
            &self.against(),
            self.calibrate_task(t, &SharedWarmStart::default()),
        )
    }

    /// The calibration of task `t`, and the part of its row that does not need
    /// the reference calibration; `warm` is its subset's (see [`Setup::subset_groups`]).
    fn calibrate_task(&self, t: usize, warm: &SharedWarmStart) -> Calibrated {
        let (subset, method, auto) = match self.header.task(t) {
            Task::Fixed(s, m) => (s, m, false),
            Task::Auto(s) => (s, Method::Standard, true),
        };
        let data = self.dataset.subset(&self.subsets[subset]);
        let mut row = Row {
            subset,
            method,
            error: None,
            images: data.num_frames(),
            observations: data.observations.len(),
            converged: false,
            iterations: 0,
            rmse_px: None,
            cameras: Vec::new(),
            frames: data.frame_ids.clone(),
            deformations: Vec::new(),
            max_out_of_plane_m: Vec::new(),
            higher_bends: Vec::new(),
            bias_ratio: None,
            auto,
            selection: None,
            loop_closure_px: None,
            sfm_error: None,
        };
        let request = Request {
            method,
            settings: self.settings.clone(),
            gauge: None,
        };
        let solved = match &self.header.auto {
            Some(a) if auto => {
                let settings = AutoSettings {
                    candidates: a.candidates.clone(),
                    folds: a.folds,
                    seed: a.seed,
                    detector_noise_px: self.detector_noise_px,
                };
                calibrate_auto_sharing(&data, &request, &settings, warm, &|| {})
            }
            _ => warm.calibrate(&data, &request),
        };
        let mut c = match solved {
            Ok(c) => c,
            Err(e) => {
                row.error = Some(e.to_string());
                return Calibrated { row, solved: None };
            }
        };
        if let Some(s) = c.selection.take() {
            row.method = s.chosen;
            row.selection = Some(s);
        }
        row.images = c.dataset.num_frames();
        row.observations = c.dataset.observations.len();
        row.frames = c.dataset.frame_ids.clone();
        row.converged = c.converged;
        row.iterations = c.iterations();
        row.rmse_px = Some(c.rmse_px);
        c.detector_noise_px = self.detector_noise_px;
        row.bias_ratio = c.trust(c.detector_noise_px).map(|t| t.bias_ratio);
        let uncertainty = c.uncertainty().ok();
        record_bends(&mut row, &c);
        Calibrated {
            row,
            solved: Some((c, uncertainty)),
        }
    }

    /// The row of a calibrated task: its results against the reference, the
    /// truth and the `[sfm]` scene.
    fn row(&self, against: &Against, calibrated: Calibrated) -> Row {
        let Calibrated { mut row, solved } = calibrated;
        let Some((c, uncertainty)) = solved else {
            return row;
        };
        for k in 0..self.header.cameras.len() {
            let u = uncertainty.as_ref().and_then(|u| u.get(k));
            let camera = self.camera_row(against, &c, k, u, &mut row.error);
            row.cameras.push(camera);
        }
        if let Some(e) = against.sfm {
            match e.run(&c.state.intrinsics[0]) {
                Ok(r) => row.loop_closure_px = finite(r.loop_closure_px),
                Err(err) => row.sfm_error = Some(err.to_string()),
            }
        }
        row
    }

    /// Runs the tasks of `shard` (all without one) on the current rayon pool,
    /// calling `tick` after each; rows come back in task order.
    pub fn run(&self, shard: Option<Shard>, tick: &(dyn Fn() + Sync)) -> Vec<Row> {
        self.subset_groups(shard)
            .par_iter()
            .flat_map_iter(|group| {
                let warm = SharedWarmStart::default();
                let against = self.against();
                group
                    .iter()
                    .map(|&t| {
                        let row = self.row(&against, self.calibrate_task(t, &warm));
                        tick();
                        row
                    })
                    .collect::<Vec<_>>()
            })
            .collect()
    }

    /// The tasks of `shard` in task order, grouped by subset: a group runs on one
    /// thread, its methods one after another, sharing the subset's warm start
    /// (the `standard` solve every deformation method starts from), which is
    /// dropped with the group.
    fn subset_groups(&self, shard: Option<Shard>) -> Vec<Vec<usize>> {
        let mut groups: Vec<Vec<usize>> = Vec::new();
        let mut last = None;
        for t in self.tasks(shard) {
            let subset = match self.header.task(t) {
                Task::Fixed(s, _) | Task::Auto(s) => s,
            };
            match groups.last_mut() {
                Some(g) if last == Some(subset) => g.push(t),
                _ => groups.push(vec![t]),
            }
            last = Some(subset);
        }
        groups
    }

    /// The tasks of `shard`, all without one.
    fn tasks(&self, shard: Option<Shard>) -> Vec<usize> {
        (0..self.header.tasks())
            .filter(|&t| shard.is_none_or(|s| s.owns(t)))
            .collect()
    }
}

/// A [`Setup`] whose reference calibration is still to run ([`plan`]).
pub struct Plan(Setup);

impl Plan {
    /// The header, without the reference calibration's part.
    pub fn header(&self) -> &Header {
        &self.0.header
    }

    /// Warnings about the configuration.
    pub fn warnings(&self) -> &[String] {
        &self.0.warnings
    }

    /// The calibrations [`Plan::run_beside_reference`] runs for `shard`: its
    /// tasks, and the reference's where there is one.
    pub fn calibrations(&self, shard: Option<Shard>) -> usize {
        self.0.tasks(shard).len() + usize::from(self.0.reference_data.is_some())
    }

    /// [`Setup::run`], with the reference calibrated on one thread of the pool
    /// while the others calibrate the subsets; `tick` after each calibration. A
    /// subset calibrated after the reference is measured against it at once, one
    /// calibrated before once both are done. The rows are those [`prepare`] and
    /// [`Setup::run`] give: each row is the same function of its calibration and
    /// the reference's, and every solve is single-threaded. A reference that
    /// fails stops the subsets not yet started.
    pub fn run_beside_reference(
        self,
        shard: Option<Shard>,
        tick: &(dyn Fn() + Sync),
    ) -> Result<(Setup, Vec<Row>)> {
        let Plan(mut setup) = self;
        let groups = setup.subset_groups(shard);
        let measures = OnceLock::new();
        let failed = AtomicBool::new(false);
        let (measured, parts) = rayon::join(
            || {
                let m = setup.measures();
                failed.store(m.is_err(), Ordering::Relaxed);
                if setup.reference_data.is_some() {
                    tick();
                }
                m.map(|m| measures.set(m).ok())
            },
            || {
                groups
                    .par_iter()
                    .flat_map_iter(|group| {
                        let warm = SharedWarmStart::default();
                        let part = |t| {
                            if failed.load(Ordering::Relaxed) {
                                return Part::Skipped;
                            }
                            let c = setup.calibrate_task(t, &warm);
                            tick();
                            match measures.get() {
                                Some(m) => Part::Row(setup.row(&m.against(), c)),
                                None => Part::Pending(c),
                            }
                        };
                        group.iter().map(|&t| part(t)).collect::<Vec<_>>()
                    })
                    .collect::<Vec<_>>()
            },
        );
        measured?;
        let measures = measures
            .into_inner()
            .ok_or_else(|| Error::Invalid("the reference calibration was not kept".into()))?;
        let rows = parts
            .into_par_iter()
            .filter_map(|p| match p {
                Part::Row(row) => Some(row),
                Part::Pending(c) => Some(setup.row(&measures.against(), c)),
                Part::Skipped => None,
            })
            .collect();
        setup.install(measures);
        Ok((setup, rows))
    }
}

/// The reference calibration and what the rows are measured against with it.
#[derive(Default)]
struct Measures {
    reference: Option<Calibration>,
    /// The header's part of it, taken into the header on install.
    reference_info: Option<ReferenceInfo>,
    /// `[sfm]`: the scene every calibration reconstructs.
    sfm: Option<Experiment>,
    /// Per camera, the mapping-error grid's rays under the reference and the
    /// truth: the same for every subset, so unprojected once.
    grids: Vec<[Option<Rays>; 2]>,
    /// Per camera, its test-error refit prepared once (empty without a
    /// reference); a camera it cannot be prepared for has the reason.
    test_errors: Vec<std::result::Result<TestError, String>>,
}

impl Measures {
    fn against(&self) -> Against<'_> {
        Against {
            reference: self.reference.as_ref(),
            sfm: self.sfm.as_ref(),
            grids: &self.grids,
            test_errors: &self.test_errors,
        }
    }
}

/// What a row is measured against: the reference calibration, the `[sfm]`
/// scene, and per camera the mapping-error grids under the reference and the truth.
struct Against<'a> {
    reference: Option<&'a Calibration>,
    sfm: Option<&'a Experiment>,
    grids: &'a [[Option<Rays>; 2]],
    test_errors: &'a [std::result::Result<TestError, String>],
}

/// A task in [`Plan::run_beside_reference`]: its row, or its calibration
/// waiting for the reference's.
#[allow(clippy::large_enum_variant)] // one per task, moved once
enum Part {
    Row(Row),
    Pending(Calibrated),
    /// Not run: the reference calibration failed.
    Skipped,
}

/// A task's calibration and the part of its row that needs no reference.
struct Calibrated {
    row: Row,
    solved: Option<(Calibration, Option<Vec<CameraUncertainty>>)>,
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

impl ShardFile {
    /// Refuses a shard file whose header is out of bounds or whose shard is no
    /// slice of a run (index not below count).
    pub fn check(&self) -> Result<()> {
        let [index, count] = self.shard;
        if index >= count {
            return Err(Error::Invalid(format!(
                "shard {index}/{count} is impossible: the index must be below the count"
            )));
        }
        self.header.check()
    }
}

/// Reads and checks a shard file, naming it in any error (see [`parse_shard`]).
pub fn read_shard(path: &std::path::Path) -> Result<ShardFile> {
    let bytes = crate::app::fsio::read_limited(path, crate::app::fsio::MAX_DATA_BYTES)?;
    parse_shard(&bytes, path)
}

/// Parses and checks ([`ShardFile::check`]) the bytes of shard file `path`.
pub fn parse_shard(bytes: &[u8], path: &std::path::Path) -> Result<ShardFile> {
    let file: ShardFile = serde_json::from_slice(bytes).map_err(|e| Error::Data {
        path: path.to_path_buf(),
        line: e.line() as u64,
        message: format!("not a deformcal shard file: {e}"),
    })?;
    file.check().map_err(|e| Error::Config {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    Ok(file)
}

/// [`merge_named`] with each shard named by its `i/N`.
pub fn merge(files: Vec<ShardFile>) -> Result<(Header, Vec<Row>)> {
    merge_named(
        files
            .into_iter()
            .map(|f| (format!("shard {}/{}", f.shard[0], f.shard[1]), f))
            .collect(),
    )
}

/// Checks that shard files (with the names to give them in messages) come from
/// one run (same header, data fingerprint included) and together cover every
/// task once; returns the header and the rows in task order.
pub fn merge_named(files: Vec<(String, ShardFile)>) -> Result<(Header, Vec<Row>)> {
    let (first_name, first) = files
        .first()
        .ok_or_else(|| Error::Invalid("no shard files to merge".into()))?;
    let (first_name, header) = (first_name.clone(), first.header.clone());
    let mut count = None;
    let mut slots: Vec<Option<Row>> = Vec::new();
    for (name, f) in files {
        f.check()
            .map_err(|e| Error::Invalid(format!("{name}: {e}")))?;
        if f.header != header {
            let what = if f.header.data != header.data {
                format!("other data ({} vs {})", f.header.data, header.data)
            } else {
                "another run (config or seed differ)".to_string()
            };
            return Err(Error::Invalid(format!(
                "{name} and {first_name} are shards of {what}: merge the shards of one run"
            )));
        }
        match count {
            None => count = Some((f.shard[1], name.clone())),
            Some((n, ref other)) if n != f.shard[1] => {
                return Err(Error::Invalid(format!(
                    "{name} is a shard of {} but {other} one of {n}: merge the shards of one run",
                    f.shard[1]
                )));
            }
            Some(_) => {}
        }
        if slots.is_empty() {
            slots = vec![None; header.tasks()];
        }
        for row in f.rows {
            let Some(t) = header.slot_of(&row) else {
                return Err(Error::Invalid(format!(
                    "{name}: a row (subset {}, method {}{}) lies outside the run",
                    row.subset,
                    row.method,
                    if row.auto { ", auto" } else { "" }
                )));
            };
            if slots[t].is_some() {
                return Err(Error::Invalid(format!(
                    "subset {} × {} appears twice (again in {name})",
                    row.subset, row.method
                )));
            }
            slots[t] = Some(row);
        }
    }
    let missing = slots.iter().filter(|s| s.is_none()).count();
    if missing > 0 {
        return Err(Error::Invalid(format!(
            "{missing} of {} subset × method results are missing: merge every shard of the run",
            slots.len()
        )));
    }
    Ok((
        header,
        slots.into_iter().map(|s| s.expect("checked")).collect(),
    ))
}
