//! The command line's commands, one module per command or group: each has its
//! clap `Args` and a `run` function; `src/main.rs` only parses and dispatches.
//! This is the application's outer edge: errors are `anyhow`, messages name the
//! file, line, key or flag, and progress goes to stderr.
pub mod calibrate;
pub mod data;
pub mod flags;
pub mod models;
pub mod protocol;
pub mod sfm;
pub mod signals;

/// A progress bar on stderr with `template` (indicatif's syntax).
pub(crate) fn progress_bar(len: u64, template: &str) -> indicatif::ProgressBar {
    let style = indicatif::ProgressStyle::with_template(template)
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> ");
    indicatif::ProgressBar::new(len).with_style(style)
}
