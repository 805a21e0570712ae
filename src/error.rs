//! The library's error type: every failure names the file, line or key it concerns.
use std::path::PathBuf;

/// Everything that can go wrong between reading a config and writing a result.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A config file that cannot be read, parsed or accepted.
    #[error("{path}: {message}")]
    Config { path: PathBuf, message: String },
    /// A data file (CSV, corners) with a problem on a given line.
    #[error("{path}:{line}: {message}")]
    Data {
        path: PathBuf,
        line: u64,
        message: String,
    },
    /// A file that cannot be read or written.
    #[error("{path}: {cause}")]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    /// Data that cannot support the requested calibration.
    #[error("degenerate data: {0}")]
    Degenerate(String),
    /// Initialisation could not produce a starting point.
    #[error("initialisation failed: {0}")]
    Init(String),
    /// Ceres rejected the problem or could not solve it.
    #[error("solver: {0}")]
    Solver(String),
    /// Photos that cannot give a calibration: a pattern matching nothing, too
    /// few usable images. Names the pattern.
    #[error("photos `{pattern}`: {message}")]
    Photos { pattern: String, message: String },
    /// A video that cannot be decoded (no `ffmpeg`, not a video, no board in
    /// enough frames). Names the file.
    #[error("video {path}: {message}")]
    Video { path: PathBuf, message: String },
    /// The C++ core refused the problem it was given (sizes, values, layout): a
    /// bug in the caller, or input that should have been refused earlier.
    #[error("invalid problem: {0}")]
    Problem(String),
    /// An argument outside its valid range.
    #[error("invalid argument: {0}")]
    Invalid(String),
    /// A result that cannot be written (disk full, no permission, name too long).
    #[error("{path}: cannot write: {cause}")]
    Write {
        path: PathBuf,
        cause: std::io::Error,
    },
    /// Another run holds the output directory's advisory lock.
    #[error("{0}: another deformcal run is writing this output directory; wait for it or choose another output")]
    Locked(PathBuf),
    /// A size beyond a documented limit, refused before anything is allocated.
    #[error("{0}")]
    TooLarge(String),
}

/// Library result type.
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            cause: source,
        }
    }

    /// A write failure on `path`.
    pub fn write(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Write {
            path: path.into(),
            cause: source,
        }
    }
}
