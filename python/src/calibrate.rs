//! `calibrate`: observations and options from Python through the command line's
//! own steps (the config's checks, `calibrate` or `auto`, the guard rails, the
//! output set), and the result kept in Rust until Python asks for its JSON or
//! its files.
use crate::{lib_error, py_error, run_detached};
use deformcal::app::config::Config;
use deformcal::app::fsio::OutputSet;
use deformcal::app::guard::{self, Failure};
use deformcal::app::lint::{self, FrameFiles};
use deformcal::app::{calibration_json::CalibrationJson, output};
use deformcal::model::selection::{AutoSettings, MethodChoice};
use deformcal::solver::problem::SolverSettings;
use deformcal::solver::select;
use deformcal::{Calibration, Dataset, Method, Request};
use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use std::path::{Path, PathBuf};

/// What names the options in messages, where the command line names its config file.
const ORIGIN: &str = "options";

/// One view from Python: camera index, frame number, corner ids (N,) and pixels (N, 2).
type View<'py> = (
    usize,
    i64,
    PyReadonlyArray1<'py, i64>,
    PyReadonlyArray2<'py, f64>,
);

/// One camera from Python: name, width, height, lens model, held parameters.
type CameraTuple = (String, u32, u32, String, Vec<String>);

/// A Python option value as TOML; `None` for a type TOML has no value of.
fn toml_value(v: &Bound<'_, PyAny>) -> PyResult<Option<toml::Value>> {
    // bool before int: Python's True is an int.
    Ok(Some(if v.is_instance_of::<PyBool>() {
        toml::Value::Boolean(v.extract()?)
    } else if v.is_instance_of::<PyInt>() {
        toml::Value::Integer(v.extract()?)
    } else if v.is_instance_of::<PyFloat>() {
        toml::Value::Float(v.extract()?)
    } else if v.is_instance_of::<PyString>() {
        toml::Value::String(v.extract()?)
    } else if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let mut items = Vec::new();
        for item in v.try_iter()? {
            match toml_value(&item?)? {
                Some(x) => items.push(x),
                None => return Ok(None),
            }
        }
        toml::Value::Array(items)
    } else if let Ok(d) = v.cast::<PyDict>() {
        let mut table = toml::Table::new();
        for (k, x) in d.iter() {
            match toml_value(&x)? {
                Some(x) => table.insert(k.extract()?, x),
                None => return Ok(None),
            };
        }
        toml::Value::Table(table)
    } else {
        return Ok(None);
    }))
}

/// The config the options make: the board, the cameras and `[calibration]`,
/// checked by the same code that checks a config file.
fn config_of(
    board: (usize, usize, f64),
    cameras: &[CameraTuple],
    options: &Bound<'_, PyDict>,
) -> PyResult<Config> {
    let mut calibration = toml::Table::new();
    for (k, v) in options.iter() {
        let key: String = k.extract()?;
        let value = toml_value(&v)?.ok_or_else(|| {
            py_error(
                "OptionError",
                format!(
                    "{ORIGIN}: `{key}` has a value of type {}, which no option takes",
                    v.get_type()
                        .name()
                        .map(|n| n.to_string())
                        .unwrap_or_default()
                ),
            )
        })?;
        calibration.insert(key, value);
    }
    let mut target = toml::Table::new();
    target.insert("rows".into(), (board.0 as i64).into());
    target.insert("cols".into(), (board.1 as i64).into());
    target.insert("spacing".into(), board.2.into());
    let cameras: Vec<toml::Value> = cameras
        .iter()
        .map(|(name, width, height, model, fix)| {
            let mut c = toml::Table::new();
            c.insert("name".into(), name.clone().into());
            c.insert("width".into(), i64::from(*width).into());
            c.insert("height".into(), i64::from(*height).into());
            c.insert("model".into(), model.clone().into());
            c.insert("fix".into(), fix.clone().into());
            toml::Value::Table(c)
        })
        .collect();
    let mut data = toml::Table::new();
    data.insert("observations".into(), "observations.csv".into());
    let mut root = toml::Table::new();
    root.insert("target".into(), toml::Value::Table(target));
    root.insert("cameras".into(), toml::Value::Array(cameras));
    root.insert("data".into(), toml::Value::Table(data));
    root.insert("calibration".into(), toml::Value::Table(calibration));
    let text = toml::to_string(&root).map_err(|e| py_error("OptionError", e.to_string()))?;
    Config::parse(&text, Path::new(ORIGIN)).map_err(lib_error)
}

/// The config's request for one method (as the command line makes it).
fn request_of(config: &Config, method: Method) -> Request {
    Request {
        method,
        settings: SolverSettings::from(&config.calibration),
        gauge: config.calibration.gauge_corners.clone(),
    }
}

/// One calibration with the config's method, or `auto`'s choice.
fn run_method(config: &Config, dataset: &Dataset) -> deformcal::Result<Calibration> {
    let c = &config.calibration;
    match c.method {
        MethodChoice::Fixed(m) => deformcal::calibrate(dataset, &request_of(config, m)),
        MethodChoice::Auto => {
            let auto = AutoSettings::from(c);
            select::check(&auto)?;
            select::calibrate_auto(
                dataset,
                &request_of(config, Method::Standard),
                &auto,
                &|| {},
            )
        }
    }
}

/// The command line's calibration of `dataset`: the method, the noise, the
/// warnings and the guard rails' verdict.
fn calibrate_like_cli(config: &Config, dataset: &Dataset) -> PyResult<NativeCalibration> {
    let rules = guard::Rules {
        max_rmse_px: config.calibration.max_rmse_px,
    };
    let first = match config.calibration.method {
        MethodChoice::Fixed(m) => m,
        MethodChoice::Auto => Method::Standard,
    };
    let mut result = run_method(config, dataset).map_err(|e| {
        let hints = guard::error_hints(dataset, &request_of(config, first), rules);
        let class = crate::class_of(&e);
        let mut message = e.to_string();
        for h in hints {
            message += &format!("\nhint: {h}");
        }
        py_error(class, message)
    })?;
    let request = request_of(config, result.method);
    result.detector_noise_px = config.calibration.detector_noise_px;
    let files = FrameFiles::new();
    let lints = lint::flipped_frames(&result, &files);
    result.warnings.extend(lints);
    let failure = guard::judge(dataset, &request, &result, rules, &files);
    Ok(NativeCalibration {
        calibration: result,
        failure,
    })
}

/// Calibrates `views` of a `board` (rows, cols, spacing in metres) seen by
/// `cameras`, with `options` as `[calibration]` keys. Raises the package's
/// exceptions; a result that fails the guard rails comes back with its failure.
#[pyfunction]
pub fn calibrate(
    py: Python<'_>,
    views: Vec<View<'_>>,
    board: (usize, usize, f64),
    cameras: Vec<CameraTuple>,
    options: &Bound<'_, PyDict>,
) -> PyResult<NativeCalibration> {
    if let Some(problem) = deformcal::model::target::spacing_problem(board.2) {
        return Err(py_error(
            "InputError",
            format!("object points: the board's spacing, {}, {problem}", board.2),
        ));
    }
    let config = config_of(board, &cameras, options)?;
    let mut rows = Vec::new();
    for (camera, frame, ids, uv) in &views {
        let (ids, uv) = (ids.as_array(), uv.as_array());
        if uv.nrows() != ids.len() || uv.ncols() != 2 {
            return Err(py_error(
                "InputError",
                format!("frame {frame}: {} ids for {} pixels", ids.len(), uv.nrows()),
            ));
        }
        for (k, &id) in ids.iter().enumerate() {
            let corner = usize::try_from(id)
                .ok()
                .filter(|&c| c < config.target.num_corners());
            let corner = corner.ok_or_else(|| {
                py_error(
                    "InputError",
                    format!("frame {frame}: corner id {id} is off the board"),
                )
            })?;
            rows.push((*camera, *frame, corner, [uv[(k, 0)], uv[(k, 1)]]));
        }
    }
    drop(views);
    let dataset = Dataset::from_keyed(config.target, config.cameras.clone(), rows);
    run_detached(py, move || calibrate_like_cli(&config, &dataset))
}

/// A calibration held in Rust: its JSON and files are made by the library.
#[pyclass(module = "deformcal._deformcal", frozen)]
pub struct NativeCalibration {
    calibration: Calibration,
    failure: Option<Failure>,
}

#[pymethods]
impl NativeCalibration {
    /// `calibration.json`'s text (with `failure` when the guard rails failed it).
    fn json(&self, py: Python<'_>) -> PyResult<String> {
        run_detached(py, || {
            let mut json = CalibrationJson::from(&self.calibration);
            json.failure = self.failure.clone();
            serde_json::to_string(&json).map_err(|e| py_error("Error", e.to_string()))
        })
    }

    /// The guard rails' reasons and hints, or `None` when the calibration passed.
    fn failure(&self) -> Option<(Vec<String>, Vec<String>)> {
        self.failure
            .as_ref()
            .map(|f| (f.reasons.clone(), f.hints.clone()))
    }

    /// The `auto` selection's reason, where `auto` chose.
    fn reason(&self) -> Option<String> {
        self.calibration
            .selection
            .as_ref()
            .map(|s| s.reason.clone())
    }

    /// Writes the command line's files into `dir` as one set (the `FAILED-`
    /// files for a calibration that failed its guard rails); returns the
    /// warnings of exports a lens model could not be written to.
    fn save(&self, py: Python<'_>, dir: PathBuf) -> PyResult<Vec<String>> {
        run_detached(py, || {
            let set = OutputSet::begin(&dir, output::calibration_files()).map_err(lib_error)?;
            let warnings = match &self.failure {
                None => {
                    output::write_calibration_labelled(
                        set.path(),
                        &self.calibration,
                        &FrameFiles::new(),
                    )
                    .map_err(lib_error)?
                    .warnings
                }
                Some(f) => {
                    output::write_failed(set.path(), &self.calibration, f).map_err(lib_error)?;
                    Vec::new()
                }
            };
            set.commit().map_err(lib_error)?;
            Ok(warnings)
        })
    }
}
