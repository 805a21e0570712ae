//! The C interface of libdeformcal (`include/deformcal.h`): calibrate from in-memory
//! observations without files, with per-frame results and the same guard rails as
//! the command line. Panics and errors become a non-zero return and a message.
#![allow(unsafe_code)]
use crate::app::config::{
    number, short, LOSS_SCALE_RANGE, MAX_CAMERAS, MAX_CORNERS, MAX_IMAGE_SIDE_PX, MAX_TOLERANCE,
};
use crate::app::guard::{self, Rules};
use crate::model::camera::CameraSpec;
use crate::model::lens::{LensModel, MAX_PARAMS};
use crate::model::selection::{AutoSettings, MethodChoice};
use crate::model::synthetic::{Generator, Preset, MAX_IMAGES};
use crate::solver::problem::Loss;
use crate::solver::problem::SolverSettings;
use crate::solver::select::calibrate_auto;
use crate::{calibrate, Dataset, Method, Request, Target};
use std::ffi::{c_char, CStr};
use std::panic::{catch_unwind, AssertUnwindSafe};

pub use crate::app::capi_types::{
    DcCamera, DcCameraResult, DcFrameResult, DcObservation, DcOptions, DcResult, DcTarget,
    DcTolerances,
};

/// Why a C API call failed; its code is the function's return value.
#[derive(Debug, thiserror::Error)]
enum CError {
    /// An argument the header's contract does not allow.
    #[error("{0}")]
    Argument(String),
    /// The calibration itself failed (degenerate data, solver failure).
    #[error("{0}")]
    Calibration(#[from] crate::Error),
    /// A bug: a panic caught at the boundary.
    #[error("internal error (panic) in deformcal")]
    Panic,
    /// The calibration ran but failed its guard rails; the results are filled in.
    #[error("{0}")]
    Failed(String),
}

impl CError {
    /// The documented return codes of `include/deformcal.h`.
    fn code(&self) -> i32 {
        match self {
            CError::Argument(_) => 1,
            CError::Calibration(_) => 2,
            CError::Panic => 3,
            CError::Failed(_) => 4,
        }
    }
}

impl From<String> for CError {
    fn from(m: String) -> Self {
        CError::Argument(m)
    }
}

impl From<&str> for CError {
    fn from(m: &str) -> Self {
        CError::Argument(m.to_string())
    }
}

fn write_error(error: *mut c_char, len: usize, message: &str) {
    if error.is_null() || len == 0 {
        return;
    }
    let bytes = message.as_bytes();
    let n = bytes.len().min(len - 1);
    // SAFETY: the caller promises `error` holds `len` bytes.
    unsafe {
        std::ptr::copy_nonoverlapping(bytes.as_ptr(), error as *mut u8, n);
        *error.add(n) = 0;
    }
}

/// Runs `f`, turning an error or a panic into its code and a message.
fn guarded(error: *mut c_char, len: usize, f: impl FnOnce() -> Result<(), CError>) -> i32 {
    let e = match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => return 0,
        Ok(Err(e)) => e,
        Err(_) => CError::Panic,
    };
    write_error(error, len, &e.to_string());
    e.code()
}

/// Solver settings from `DcOptions`: 0 means the default, anything out of range is
/// refused (never silently replaced).
fn settings_from(o: &DcOptions) -> Result<SolverSettings, String> {
    let mut settings = SolverSettings::recommended();
    match o.robust {
        -1 => settings.loss = Loss::None,
        0 | 1 => {}
        r => {
            return Err(format!(
                "options.robust is {r}; use 1 (Cauchy), -1 (none) or 0"
            ))
        }
    }
    let (lo, hi) = LOSS_SCALE_RANGE;
    if o.loss_scale_px != 0.0 {
        if !(lo..=hi).contains(&o.loss_scale_px) {
            return Err(format!(
                "options.loss_scale_px is {}; use {lo} to {hi} pixels, or 0 for 1",
                number(o.loss_scale_px)
            ));
        }
        settings.loss_scale_px = o.loss_scale_px;
    }
    match o.threads {
        0 => {}
        t @ 1..=256 => settings.threads = t as usize,
        t => return Err(format!("options.threads is {t}; use 1 to 256, or 0 for 1")),
    }
    match o.max_iterations {
        0 => {}
        n if n > 0 => settings.max_iterations = n as u32,
        n => {
            return Err(format!(
                "options.max_iterations is {n}; use 1 or more, or 0 for 100"
            ))
        }
    }
    Ok(settings)
}

/// Applies `DcTolerances` to the settings: 0 keeps the default, a negative or
/// non-finite value is refused; returns the guard's rules.
fn apply_tolerances(t: &DcTolerances, settings: &mut SolverSettings) -> Result<Rules, String> {
    for (name, v, slot) in [
        (
            "function_tolerance",
            t.function_tolerance,
            &mut settings.function_tolerance,
        ),
        (
            "parameter_tolerance",
            t.parameter_tolerance,
            &mut settings.parameter_tolerance,
        ),
        (
            "gradient_tolerance",
            t.gradient_tolerance,
            &mut settings.gradient_tolerance,
        ),
    ] {
        // At 1 Ceres stops before its first step (see `config::MAX_TOLERANCE`).
        if !(0.0..=MAX_TOLERANCE).contains(&v) {
            return Err(format!(
                "tolerances.{name} is {}; use a number above 0 and at most {MAX_TOLERANCE}, or 0 for the default",
                number(v)
            ));
        }
        if v > 0.0 {
            *slot = v;
        }
    }
    let m = t.max_rmse_px;
    if !(m.is_finite() && m >= 0.0) {
        return Err(format!(
            "tolerances.max_rmse_px is {}; use a positive number of pixels, or 0 for the default rules",
            number(m)
        ));
    }
    Ok(Rules {
        max_rmse_px: (m > 0.0).then_some(m),
    })
}

/// # Safety
/// `s` is null or a NUL-terminated string.
unsafe fn string(s: *const c_char, what: &str) -> Result<String, String> {
    if s.is_null() {
        return Err(format!("{what} is NULL"));
    }
    CStr::from_ptr(s)
        .to_str()
        .map(str::to_string)
        .map_err(|_| format!("{what} is not UTF-8"))
}

/// # Safety
/// `p` is null (only when `n` is 0) or points to `n` values.
unsafe fn slice<'a, T>(p: *const T, n: usize, what: &str) -> Result<&'a [T], String> {
    if n == 0 {
        return Ok(&[]);
    }
    if p.is_null() {
        return Err(format!("{what} is NULL"));
    }
    Ok(std::slice::from_raw_parts(p, n))
}

/// The board of a `DcTarget`, refused when too small or too large.
///
/// # Safety
/// `target` is null or points to a `DcTarget`.
unsafe fn target_from(target: *const DcTarget) -> Result<Target, CError> {
    let t = target.as_ref().ok_or("target is NULL")?;
    if t.rows < 2 || t.cols < 2 {
        return Err("target: rows and cols must be at least 2".into());
    }
    if let Some(problem) = crate::model::target::spacing_problem(t.spacing) {
        return Err(format!("target.spacing {problem}").into());
    }
    if (t.rows as usize)
        .checked_mul(t.cols as usize)
        .is_none_or(|n| n > MAX_CORNERS)
    {
        return Err(format!(
            "target: a board of {} × {} corners is too large (at most {MAX_CORNERS} corners)",
            t.rows, t.cols
        )
        .into());
    }
    Ok(Target {
        rows: t.rows as usize,
        cols: t.cols as usize,
        spacing: t.spacing,
    })
}

/// The cameras of a `DcCamera` array: named (`cam<k>` when unnamed), sized and distinct.
///
/// # Safety
/// `cameras` is null (only when `num_cameras` is 0) or holds `num_cameras` entries
/// whose strings are null or NUL-terminated.
unsafe fn camera_specs(
    cameras: *const DcCamera,
    num_cameras: usize,
) -> Result<Vec<CameraSpec>, CError> {
    if num_cameras > MAX_CAMERAS {
        return Err(format!("{num_cameras} cameras; at most {MAX_CAMERAS} are supported").into());
    }
    let cams = slice(cameras, num_cameras, "cameras")?;
    if cams.is_empty() {
        return Err("at least one camera is needed".into());
    }
    let specs = cams
        .iter()
        .enumerate()
        .map(|(k, c)| {
            Ok(CameraSpec {
                name: if c.name.is_null() {
                    format!("cam{k}")
                } else {
                    string(c.name, "camera name")?
                },
                width: c.width,
                height: c.height,
                model: lens_model(c.model)?,
                fix: Vec::new(),
            })
        })
        .collect::<Result<Vec<_>, CError>>()?;
    if let Some((k, c)) = specs.iter().enumerate().find(|(_, c)| {
        [c.width, c.height]
            .iter()
            .any(|&v| v == 0 || v > MAX_IMAGE_SIDE_PX)
    }) {
        return Err(format!(
            "cameras[{k}]: width and height must be 1 to {MAX_IMAGE_SIDE_PX} pixels (got {} × {})",
            c.width, c.height
        )
        .into());
    }
    for (k, c) in specs.iter().enumerate() {
        if let Some(j) = specs[..k].iter().position(|o| o.name == c.name) {
            return Err(format!(
                "cameras {j} and {k} are both named `{}`; camera names must differ",
                short(&c.name)
            )
            .into());
        }
    }
    Ok(specs)
}

/// The dataset of a `DcObservation` array, every observation in range, finite and unique.
///
/// # Safety
/// `observations` is null (only when `num_observations` is 0) or holds
/// `num_observations` entries.
unsafe fn dataset_from(
    target: Target,
    specs: Vec<CameraSpec>,
    observations: *const DcObservation,
    num_observations: usize,
) -> Result<Dataset, CError> {
    let obs = slice(observations, num_observations, "observations")?;
    let mut seen = std::collections::HashSet::new();
    let mut rows = Vec::with_capacity(obs.len());
    for (i, o) in obs.iter().enumerate() {
        if o.camera as usize >= specs.len() || o.corner as usize >= target.num_corners() {
            return Err(format!(
                "observation {i}: camera {} or corner {} out of range",
                o.camera, o.corner
            )
            .into());
        }
        if !(o.u.is_finite() && o.v.is_finite()) {
            return Err(format!("observation {i}: pixel is not finite").into());
        }
        if !seen.insert((o.camera, o.frame, o.corner)) {
            return Err(format!("observation {i}: duplicate camera, frame and corner").into());
        }
        rows.push((o.camera as usize, o.frame, o.corner as usize, [o.u, o.v]));
    }
    if rows.is_empty() {
        return Err("no observations".into());
    }
    Ok(Dataset::from_keyed(target, specs, rows))
}

/// The method and solver settings of `DcOptions`; null options or method mean the defaults.
///
/// # Safety
/// `options` is null or points to a `DcOptions` whose `method` is null or NUL-terminated.
unsafe fn request_from(options: *const DcOptions) -> Result<(MethodChoice, Request), CError> {
    let o = options.as_ref();
    let choice = match o.map(|o| o.method).filter(|m| !m.is_null()) {
        Some(m) => {
            let name = string(m, "method")?;
            MethodChoice::parse(&name).ok_or(format!(
                "unknown method `{name}`: use standard, static, dynamic, full or auto"
            ))?
        }
        // The config's default: the method the data support.
        None => MethodChoice::Auto,
    };
    let settings = match o {
        Some(o) => settings_from(o)?,
        None => SolverSettings::recommended(),
    };
    let method = match choice {
        MethodChoice::Fixed(m) => m,
        MethodChoice::Auto => Method::Standard,
    };
    Ok((
        choice,
        Request {
            method,
            settings,
            gauge: None,
        },
    ))
}

/// Copies a calibration into the caller's result and per-camera results.
///
/// # Safety
/// `result` is null or valid; `camera_results` holds `num_cameras` entries.
unsafe fn write_results(
    c: &crate::Calibration,
    result: *mut DcResult,
    camera_results: *mut DcCameraResult,
    num_cameras: usize,
) -> Result<(), CError> {
    let out = result.as_mut().ok_or("result is NULL")?;
    *out = DcResult {
        rmse_px: c.rmse_px,
        converged: c.converged as i32,
        iterations: c.iterations(),
        observations: c.dataset.observations.len() as u64,
        frames: c.dataset.num_frames() as u64,
        max_out_of_plane_m: c.max_out_of_plane(),
    };
    for k in 0..num_cameras {
        let i = c.state.intrinsics[k];
        let p = c.state.camera_poses[k];
        let mut params = [0.0; MAX_PARAMS];
        params[..i.params().len()].copy_from_slice(i.params());
        *camera_results.add(k) = DcCameraResult {
            num_params: i.params().len() as u32,
            params,
            rotation: p.rotation,
            translation: p.translation,
        };
    }
    Ok(())
}

/// One entry per frame number of the input, ascending: the calibrated pose, bend
/// and RMSE of each frame kept, `used = 0` for a frame the calibration dropped.
fn frame_results(input: &Dataset, c: &crate::Calibration) -> Vec<DcFrameResult> {
    let d = &c.dataset;
    let mut sq = vec![0.0; d.num_frames()];
    let mut n = vec![0u64; d.num_frames()];
    for (o, r) in d.observations.iter().zip(c.residuals.chunks(2)) {
        sq[o.frame] += r[0] * r[0] + r[1] * r[1];
        n[o.frame] += 1;
    }
    let bends = c.method.has_paraboloid();
    input
        .frame_ids
        .iter()
        .map(|&id| {
            let Ok(j) = d.frame_ids.binary_search(&id) else {
                return DcFrameResult {
                    frame: id,
                    rmse_px: f64::NAN,
                    ..DcFrameResult::default()
                };
            };
            let pose = c.state.frame_poses[j];
            let b = if bends {
                c.state.deformations[j]
            } else {
                crate::Paraboloid::default()
            };
            DcFrameResult {
                frame: id,
                used: 1,
                rotation: pose.rotation,
                translation: pose.translation,
                bend: [b.a, b.b, b.c],
                max_out_of_plane_m: b.max_out_of_plane(&d.target),
                rmse_px: if n[j] > 0 {
                    (sq[j] / n[j] as f64).sqrt()
                } else {
                    f64::NAN
                },
                observations: n[j],
            }
        })
        .collect()
}

/// Where `deformcal_calibrate_ex` puts the per-frame results.
struct FrameOut {
    results: *mut DcFrameResult,
    capacity: usize,
    count: *mut usize,
}

/// The shared body of both calibrate calls: checks, calibrates, writes every
/// result, then holds the result to the guard rails (code 4 when it fails them).
///
/// # Safety
/// As for [`deformcal_calibrate_ex`].
#[allow(clippy::too_many_arguments)] // the C call's own arguments, passed through
unsafe fn calibrate_into(
    target: *const DcTarget,
    cameras: *const DcCamera,
    num_cameras: usize,
    observations: *const DcObservation,
    num_observations: usize,
    options: *const DcOptions,
    tolerances: *const DcTolerances,
    result: *mut DcResult,
    camera_results: *mut DcCameraResult,
    frames: FrameOut,
) -> Result<(), CError> {
    // Outputs are checked before the work, not after a long solve.
    if result.is_null() {
        return Err("result is NULL".into());
    }
    if camera_results.is_null() {
        return Err("camera_results is NULL".into());
    }
    let target = target_from(target)?;
    let specs = camera_specs(cameras, num_cameras)?;
    let dataset = dataset_from(target, specs, observations, num_observations)?;
    let (choice, mut request) = request_from(options)?;
    let rules = match tolerances.as_ref() {
        Some(t) => apply_tolerances(t, &mut request.settings)?,
        None => Rules { max_rmse_px: None },
    };
    let needed = dataset.num_frames();
    if let Some(count) = frames.count.as_mut() {
        *count = needed;
    }
    if !frames.results.is_null() && frames.capacity < needed {
        return Err(format!(
            "frame_results holds {} entries; {needed} needed (one per frame number)",
            frames.capacity
        )
        .into());
    }
    let c = match choice {
        MethodChoice::Fixed(_) => calibrate(&dataset, &request)?,
        MethodChoice::Auto => calibrate_auto(&dataset, &request, &AutoSettings::default(), &|| {})?,
    };
    // Judged as the method that ran (with `auto`, the one chosen).
    request.method = c.method;
    write_results(&c, result, camera_results, num_cameras)?;
    if !frames.results.is_null() {
        for (i, f) in frame_results(&dataset, &c).into_iter().enumerate() {
            *frames.results.add(i) = f;
        }
    }
    match guard::judge(&dataset, &request, &c, rules, &Default::default()) {
        None => Ok(()),
        Some(f) => {
            let mut message = format!("the calibration FAILED: {}", f.reasons.join("; "));
            for h in &f.hints {
                message.push_str(&format!("; hint: {h}"));
            }
            Err(CError::Failed(message))
        }
    }
}

/// Calibrates from in-memory observations; see `include/deformcal.h`.
///
/// # Safety
/// Pointers follow the header's contract: arrays hold the stated counts, strings are
/// NUL-terminated, `camera_results` holds `num_cameras` entries, `error` `error_len` bytes.
#[no_mangle]
pub unsafe extern "C" fn deformcal_calibrate(
    target: *const DcTarget,
    cameras: *const DcCamera,
    num_cameras: usize,
    observations: *const DcObservation,
    num_observations: usize,
    options: *const DcOptions,
    result: *mut DcResult,
    camera_results: *mut DcCameraResult,
    error: *mut c_char,
    error_len: usize,
) -> i32 {
    let frames = FrameOut {
        results: std::ptr::null_mut(),
        capacity: 0,
        count: std::ptr::null_mut(),
    };
    guarded(error, error_len, || {
        calibrate_into(
            target,
            cameras,
            num_cameras,
            observations,
            num_observations,
            options,
            std::ptr::null(),
            result,
            camera_results,
            frames,
        )
    })
}

/// Calibrates with tolerances and per-frame results; see `include/deformcal.h`.
///
/// # Safety
/// As [`deformcal_calibrate`]; `tolerances` is null or valid, `frame_results` is
/// null or holds `frame_capacity` entries, `num_frames` is null or valid.
#[no_mangle]
pub unsafe extern "C" fn deformcal_calibrate_ex(
    target: *const DcTarget,
    cameras: *const DcCamera,
    num_cameras: usize,
    observations: *const DcObservation,
    num_observations: usize,
    options: *const DcOptions,
    tolerances: *const DcTolerances,
    result: *mut DcResult,
    camera_results: *mut DcCameraResult,
    frame_results: *mut DcFrameResult,
    frame_capacity: usize,
    num_frames: *mut usize,
    error: *mut c_char,
    error_len: usize,
) -> i32 {
    let frames = FrameOut {
        results: frame_results,
        capacity: frame_capacity,
        count: num_frames,
    };
    guarded(error, error_len, || {
        calibrate_into(
            target,
            cameras,
            num_cameras,
            observations,
            num_observations,
            options,
            tolerances,
            result,
            camera_results,
            frames,
        )
    })
}

/// Generates a built-in synthetic dataset into caller memory; see `include/deformcal.h`.
///
/// # Safety
/// Out-pointers are valid; `observations` is null or holds `capacity` entries.
#[no_mangle]
pub unsafe extern "C" fn deformcal_synthetic(
    preset: *const c_char,
    images: u32,
    seed: u64,
    target: *mut DcTarget,
    width: *mut u32,
    height: *mut u32,
    observations: *mut DcObservation,
    capacity: usize,
    count: *mut usize,
    error: *mut c_char,
    error_len: usize,
) -> i32 {
    guarded(error, error_len, || {
        let name = string(preset, "preset")?;
        let preset = Preset::parse(&name).ok_or(format!("unknown preset `{}`", short(&name)))?;
        if preset.default_cameras() != 1 {
            return Err(format!(
                "preset `{name}` is a rig of {} cameras; deformcal_synthetic gives one camera's data (use t1..t4 or reference)",
                preset.default_cameras()
            ).into());
        }
        if images as usize > MAX_IMAGES {
            return Err(format!("{images} images; at most {MAX_IMAGES} can be generated").into());
        }
        let images = (images > 0).then_some(images as usize);
        let (d, _) = Generator::new(preset, images, seed)
            .with_cameras(1)
            .generate();
        *count.as_mut().ok_or("count is NULL")? = d.observations.len();
        if let Some(t) = target.as_mut() {
            *t = DcTarget {
                rows: d.target.rows as u32,
                cols: d.target.cols as u32,
                spacing: d.target.spacing,
            };
        }
        if let Some(w) = width.as_mut() {
            *w = d.cameras[0].width;
        }
        if let Some(h) = height.as_mut() {
            *h = d.cameras[0].height;
        }
        if observations.is_null() {
            return Ok(());
        }
        if capacity < d.observations.len() {
            return Err(format!(
                "room for {capacity} observations, {} needed",
                d.observations.len()
            )
            .into());
        }
        for (i, o) in d.observations.iter().enumerate() {
            *observations.add(i) = DcObservation {
                camera: o.camera as u32,
                frame: d.frame_ids[o.frame],
                corner: o.corner as u32,
                u: o.uv[0],
                v: o.uv[1],
            };
        }
        Ok(())
    })
}

/// # Safety
/// `name` is null or a NUL-terminated string.
unsafe fn lens_model(name: *const c_char) -> Result<LensModel, CError> {
    if name.is_null() {
        return Ok(LensModel::default());
    }
    let name = string(name, "camera model")?;
    LensModel::parse(&name).ok_or_else(|| {
        CError::Argument(format!(
            "unknown lens model `{name}`; expected one of {}",
            LensModel::names()
        ))
    })
}

/// Every lens model's parameter names as C strings, made once.
fn param_names_c() -> &'static [(LensModel, Vec<std::ffi::CString>)] {
    static NAMES: std::sync::OnceLock<Vec<(LensModel, Vec<std::ffi::CString>)>> =
        std::sync::OnceLock::new();
    NAMES.get_or_init(|| {
        LensModel::ALL
            .iter()
            .map(|m| {
                let names = m
                    .param_names()
                    .iter()
                    .map(|n| std::ffi::CString::new(*n).expect("no NUL in a name"))
                    .collect();
                (*m, names)
            })
            .collect()
    })
}

/// The parameter names of a lens model, in the order of `DcCameraResult::params`;
/// see `include/deformcal.h`.
///
/// # Safety
/// `model` is null or NUL-terminated; `names` is null or holds `capacity` pointers.
#[no_mangle]
pub unsafe extern "C" fn deformcal_lens_params(
    model: *const c_char,
    names: *mut *const c_char,
    capacity: usize,
    count: *mut usize,
    error: *mut c_char,
    error_len: usize,
) -> i32 {
    guarded(error, error_len, || {
        let model = lens_model(model)?;
        let (_, list) = param_names_c()
            .iter()
            .find(|(m, _)| *m == model)
            .expect("every model is listed");
        *count.as_mut().ok_or("count is NULL")? = list.len();
        if names.is_null() {
            return Ok(());
        }
        if capacity < list.len() {
            return Err(format!("names holds {capacity} entries; {} needed", list.len()).into());
        }
        for (i, n) in list.iter().enumerate() {
            *names.add(i) = n.as_ptr();
        }
        Ok(())
    })
}
