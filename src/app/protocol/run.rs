//! Running the tasks: the reference calibration and what rows are measured
//! against, each subset × method calibrated (sharing its subset's warm start)
//! and turned into a row, in parallel and beside the reference.
use super::record::{CameraRow, Header, ReferenceInfo, Row, Task};
use super::refit::{test_rmse, TestError};
use super::shard::Shard;
use crate::app::sfm::{Experiment, SfmConfig};
use crate::error::{Error, Result};
use crate::model::board::Method;
use crate::model::dataset::Dataset;
use crate::model::lens::Intrinsics;
use crate::model::metrics::{grid_rays, mapping_error_of, mapping_error_rot_of};
use crate::model::selection::AutoSettings;
use crate::model::synthetic::Truth;
use crate::model::uncertainty::CameraUncertainty;
use crate::solver::calibrate::{calibrate, Calibration, Request, SharedWarmStart};
use crate::solver::problem::SolverSettings;
use crate::solver::select::calibrate_auto_sharing;
use rayon::prelude::*;
use std::borrow::Cow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::OnceLock;

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
    pub(super) measures: Measures,
    /// The reference set, until its calibration is installed.
    pub(super) reference_data: Option<Dataset>,
    /// `[sfm]`, whose scene may need the reference calibration.
    pub(super) sfm_config: Option<SfmConfig>,
}

/// A mapping-error grid's pixels and rays ([`grid_rays`]).
type Rays = Vec<(nalgebra::Vector2<f64>, nalgebra::Vector3<f64>)>;

/// `[sfm]` without synthetic data's truth or a reference set.
pub(super) fn no_sfm_camera() -> Error {
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
    /// with the settings of every task, and its covariance: the rows use its
    /// parameters and its board, never its uncertainty, but its board's σ comes
    /// out of the covariance pass, and beside the σ the intrinsics' Σ_θ costs
    /// little (the Jacobian, H and its factor are the σ's too).
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
    pub(super) fn measures(&self) -> Result<Measures> {
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
    pub(super) fn install(&mut self, mut m: Measures) {
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
            self.calibrate_task(t, &SubsetShare::default()),
        )
    }

    /// The calibration of task `t`, and the part of its row that does not need
    /// the reference calibration; `share` is its subset's (see [`Setup::subset_groups`]).
    fn calibrate_task(&self, t: usize, share: &SubsetShare) -> Calibrated {
        let (subset, method, auto) = match self.header.task(t) {
            Task::Fixed(s, m) => (s, m, false),
            Task::Auto(s) => (s, Method::Standard, true),
        };
        let data = share.data(subset, || self.dataset.subset(&self.subsets[subset]));
        let warm = &share.warm;
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
        row.bias_ratio = c.assessment.trust.map(|t| t.bias_ratio);
        let uncertainty = c.assessment.uncertainty.clone().ok();
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
                let share = SubsetShare::default();
                let against = self.against();
                group
                    .iter()
                    .map(|&t| {
                        let row = self.row(&against, self.calibrate_task(t, &share));
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
pub struct Plan(pub(super) Setup);

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
                        let share = SubsetShare::default();
                        let part = |t| {
                            if failed.load(Ordering::Relaxed) {
                                return Part::Skipped;
                            }
                            let c = setup.calibrate_task(t, &share);
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
pub(super) struct Measures {
    reference: Option<Calibration>,
    /// The header's part of it, taken into the header on install.
    reference_info: Option<ReferenceInfo>,
    /// `[sfm]`: the scene every calibration reconstructs.
    pub(super) sfm: Option<Experiment>,
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

/// What the tasks of one subset share, one after another on one thread: its
/// data, built once, and its warm start.
#[derive(Default)]
struct SubsetShare {
    data: OnceLock<(usize, Dataset)>,
    warm: SharedWarmStart,
}

impl SubsetShare {
    /// Subset `subset`'s data, built by `build` the first time.
    fn data(&self, subset: usize, build: impl Fn() -> Dataset) -> Cow<'_, Dataset> {
        match self.data.get_or_init(|| (subset, build())) {
            (s, data) if *s == subset => Cow::Borrowed(data),
            // A share is one subset's; another subset's data is built apart.
            _ => Cow::Owned(build()),
        }
    }
}

/// A task's calibration and the part of its row that needs no reference.
struct Calibrated {
    row: Row,
    solved: Option<(Calibration, Option<Vec<CameraUncertainty>>)>,
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}
