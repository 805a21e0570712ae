//! `deformcal calibrate` (and the plain `deformcal --config`): one calibration from
//! a config and the command line's flags, judged by the guard rails, written as one
//! output set with the config that reruns it. The solve itself is the solver's.
use super::flags::{self, CalibrateArgs};
use super::protocol::{self, ProtocolArgs};
use crate::app::config::overrides::Document;
use crate::app::config::Config;
use crate::app::fsio::{self, OutputSet};
use crate::app::html_report::REPORT_FILE;
use crate::app::source::Loaded;
use crate::app::{guard, lint, output, report};
use crate::model::selection::{AutoSettings, MethodChoice};
use crate::solver::problem::SolverSettings;
use crate::solver::select::calibrate_auto;
use crate::{calibrate, Calibration, Dataset, Method, Request};
use anyhow::Result;

/// A calibration that ran but failed its guard rails (exit code [`EXIT_FAILED`]).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct GuardFailed(String);

/// The exit code of a calibration that failed its guard rails: its files were
/// written under `FAILED-` names. (1 is any other error, 2 a command-line error.)
pub const EXIT_FAILED: u8 = 3;

/// The default command: the protocol when the config has `[protocol]` (docs/conventions.md §5),
/// else one calibration.
pub fn run_default(args: CalibrateArgs) -> Result<()> {
    let Some(path) = args.config.clone() else {
        return run(args);
    };
    if !Document::load(&path)?.has_section("protocol") {
        return run(args);
    }
    // A config that the flags would complete is still refused whole, as before.
    Config::load(&path)?;
    anyhow::ensure!(
        args.method.is_none(),
        "{}: --method applies to one calibration, but the config has a [protocol] section, which runs \
         its `methods`; to calibrate once use `deformcal calibrate --config {}`",
        path.display(),
        path.display()
    );
    let threads = args.threads;
    let output = args.output.clone().map(Into::into);
    anyhow::ensure!(
        !CalibrateArgs {
            threads: None,
            output: None,
            config: None,
            ..args
        }
        .changes_config(),
        "{}: the config has a [protocol] section, which runs its own settings; flags that change \
         the config apply to one calibration: use `deformcal calibrate --config {}`",
        path.display(),
        path.display()
    );
    eprintln!(
        "{}: the config has a [protocol] section: running the evaluation protocol \
         (`deformcal calibrate --config …` calibrates once instead)",
        path.display()
    );
    protocol::run(ProtocolArgs {
        config: path,
        shard: None,
        threads,
        subsets: None,
        output,
    })
}

/// One calibration: `deformcal calibrate`.
pub fn run(args: CalibrateArgs) -> Result<()> {
    // The output's threads (rayon's pool) start now, while the data is read and
    // solved, not when the files are written: on a loaded machine a new thread
    // waits 1–2 ms for a core.
    rayon::current_num_threads();
    let (document, config) = flags::config(&args)?;
    // Lock and stage the output before the work: a busy or unwritable output
    // directory fails now, not after a long solve.
    let set = OutputSet::begin(&config.output_dir, output::calibration_files())?;
    let loaded = crate::app::source::load(&config)?;
    let mut result = solve(&config, &loaded)?;
    // Every warning goes to stderr (the summary on stdout has none), and all to the JSON.
    let mut warnings = result.warnings.clone();
    warnings.extend(loaded.warnings.iter().cloned());
    let lints = lint::flipped_frames(&result, &loaded.files);
    warnings.extend(lints.iter().cloned());
    result.warnings.extend(loaded.warnings.iter().cloned());
    result.warnings.extend(lints);
    let rerun = document.rerunnable(&config);
    // Judged as the method that ran (with `auto`, the one chosen).
    let request = request_of(&config, result.method);
    let rules = rules_of(&config);
    // The summary is made while the files are written (on another core).
    let staging = set.path();
    let (summary, written) = rayon::join(
        || report::summary_with(&result, &[]),
        || -> Result<_> {
            let failure = guard::judge(&loaded.dataset, &request, &result, rules, &loaded.files);
            let written = match &failure {
                None => {
                    fsio::write_atomic(&staging.join(output::RERUN_CONFIG), rerun.as_bytes())?;
                    output::write_calibration_labelled(staging, &result, &loaded.files)?.warnings
                }
                Some(f) => {
                    output::write_failed(staging, &result, f)?;
                    Vec::new()
                }
            };
            Ok((failure, written))
        },
    );
    let (failure, written) = written?;
    set.commit()?;
    print!("{summary}");
    for w in warnings.iter().chain(&written) {
        eprintln!("warning: {w}");
    }
    finish(&config, failure)
}

/// The guard rails' verdict on stdout (success) or as the error (failure).
fn finish(config: &Config, failure: Option<guard::Failure>) -> Result<()> {
    let Some(failure) = failure else {
        let path = config.output_dir.join("calibration.json");
        println!("  wrote {}", path.display());
        println!(
            "  report: {}",
            config.output_dir.join(REPORT_FILE).display()
        );
        return Ok(());
    };
    for h in &failure.hints {
        eprintln!("hint: {h}");
    }
    Err(GuardFailed(format!(
        "the calibration FAILED: {}; wrote {} and {} (no model files)",
        failure.reasons.join("; "),
        config.output_dir.join(output::FAILED_CALIBRATION).display(),
        output::FAILED_OUTLIERS
    ))
    .into())
}

fn rules_of(config: &Config) -> guard::Rules {
    guard::Rules {
        max_rmse_px: config.calibration.max_rmse_px,
    }
}

/// The calibration of the loaded data with the config's method; a failed solve
/// prints the guard rails' hints about the data first.
pub fn solve(config: &Config, loaded: &Loaded) -> Result<Calibration> {
    let (config, note) = &without_corrections(config, loaded.labelled_by_symmetry)?;
    let first = match config.calibration.method {
        MethodChoice::Fixed(m) => m,
        MethodChoice::Auto => {
            // Settings `auto` cannot run with are no fault of the data: no hints.
            crate::solver::select::check(&AutoSettings::from(&config.calibration))?;
            Method::Standard
        }
    };
    let result = run_method(config, &loaded.dataset).inspect_err(|_| {
        let request = request_of(config, first);
        for h in guard::error_hints(&loaded.dataset, &request, rules_of(config)) {
            eprintln!("hint: {h}");
        }
    })?;
    let mut result = result;
    result.warnings.extend(note.clone());
    Ok(result)
}

/// Views labelled by the board's symmetry (a board that looks alike turned by
/// 180°) carry corner ids that may be turned from one photo to the next: fine
/// for the intrinsics and the bends, which the pose absorbs it for, but not for
/// a per-corner correction, whose values belong to a corner of the printed
/// board. Such a method is refused, and `auto` tries the others (with a
/// warning saying so).
fn without_corrections(config: &Config, by_symmetry: usize) -> Result<(Config, Option<String>)> {
    let mut config = config.clone();
    if by_symmetry == 0 {
        return Ok((config, None));
    }
    let why = format!(
        "{by_symmetry} views show a board that looks alike turned by 180 degrees ({} x {} inner corners), so their corner ids follow the photo's orientation, not the printed board",
        config.target.rows, config.target.cols
    );
    let c = &mut config.calibration;
    match c.method {
        MethodChoice::Fixed(m) if m.has_correction() => anyhow::bail!(
            "method `{m}` estimates a correction per corner of the board, but {why}; use a method without one (standard, dynamic) or a board with rows + cols odd (e.g. 9 x 6)"
        ),
        MethodChoice::Auto if c.auto_candidates.iter().any(|m| m.has_correction()) => {
            let left: Vec<String> = c
                .auto_candidates
                .iter()
                .filter(|m| m.has_correction())
                .map(|m| m.to_string())
                .collect();
            c.auto_candidates.retain(|m| !m.has_correction());
            let note = format!(
                "auto left out {} (a correction per corner of the board): {why}",
                left.join(", ")
            );
            Ok((config, Some(note)))
        }
        _ => Ok((config, None)),
    }
}

/// The config's request for one method.
pub fn request_of(config: &Config, method: Method) -> Request {
    Request {
        method,
        settings: SolverSettings::from(&config.calibration),
        gauge: config.calibration.gauge_corners.clone(),
    }
}

/// One calibration with the config's method, or `auto`'s choice with a progress bar.
pub fn run_method(config: &Config, dataset: &Dataset) -> Result<Calibration> {
    let c = &config.calibration;
    let request = |method| request_of(config, method);
    match c.method {
        MethodChoice::Fixed(m) => {
            let what = format!(
                "{m}: calibrating {} images ({} corners)",
                dataset.num_frames(),
                dataset.observations.len()
            );
            Ok(super::with_progress_line(&what, || {
                calibrate(dataset, &request(m))
            })?)
        }
        MethodChoice::Auto => {
            let auto = AutoSettings::from(c);
            let folds = crate::solver::select::fold_count(dataset.num_frames(), &auto);
            let solves = auto.candidates.len() * (folds + 1);
            let bar = super::progress_bar(
                solves as u64,
                "auto: {msg} [{bar:40}] {pos}/{len} calibrations, {elapsed} elapsed, ETA {eta}",
            );
            bar.set_message(format!("{folds}-fold cross-validation"));
            let result = calibrate_auto(dataset, &request(Method::Standard), &auto, &|| bar.inc(1));
            bar.finish_and_clear();
            Ok(result?)
        }
    }
}
