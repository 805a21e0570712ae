//! The TOML config (docs/conventions.md §5): typed, unknown keys rejected, values
//! checked by key. One file per concern: the `[calibration]` and `[protocol]`
//! sections with their defaults, the shapes as written (`raw`), the checked config
//! (`checked`), the checks of its structure (`checks`) and of its values
//! (`limits`), and the command line's overrides (`overrides`: flags and
//! `--set section.key=value`, checked as a file is).
mod calibration;
mod checked;
mod checker;
mod checks;
mod limits;
pub mod overrides;
mod protocol;
mod raw;

pub use crate::app::text::{number, short};
pub use calibration::{
    BendOrder, CalibrationConfig, LensPrior, PriorSigma, Priors, DEFAULT_MAX_BEND_MM,
};
pub use checked::{
    Config, DataSource, ReferenceConfig, VideoSource, DEFAULT_MAX_FRAMES, DEFAULT_STRIDE,
    DEFAULT_SYNTHETIC_SEED, MIN_MAX_FRAMES,
};
pub use limits::*;
pub use protocol::ProtocolConfig;
pub use raw::PhotoPatterns;

use crate::error::{Error, Result};
use std::path::Path;

impl Config {
    /// Reads and checks a config file.
    pub fn load(path: &Path) -> Result<Config> {
        Config::parse(&Config::read_text(path)?, path)
    }

    /// A config file's text: bounded in size, UTF-8.
    pub fn read_text(path: &Path) -> Result<String> {
        let text = crate::app::fsio::read_limited(path, crate::app::fsio::MAX_CONFIG_BYTES)?;
        String::from_utf8(text).map_err(|_| Error::Config {
            path: path.into(),
            message: "not a UTF-8 text file".into(),
        })
    }

    /// Parses config text; `path` names the file in messages and anchors relative paths.
    pub fn parse(text: &str, path: &Path) -> Result<Config> {
        let raw: raw::RawConfig = toml::from_str(text).map_err(|e| Error::Config {
            path: path.into(),
            message: crate::app::config_keys::explain(text, e.message(), e.span()),
        })?;
        let base = path.parent().unwrap_or(Path::new("")).to_path_buf();
        checker::Checker { path, base, text }.check(raw)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn parse(text: &str) -> Result<Config> {
        Config::parse(text, Path::new("/tmp/x/c.toml"))
    }

    #[test]
    fn unknown_key_is_named_with_line() {
        let e = parse("[data]\nsynthetic = \"t2\"\n[calibration]\nmethdo = \"full\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("methdo"), "{e}");
        assert!(e.contains("line 4"), "{e}");
    }

    #[test]
    fn relative_paths_follow_the_config() {
        let c = parse(
            "[target]\nrows=3\ncols=4\nspacing=0.1\n[[cameras]]\nname=\"c\"\nwidth=10\nheight=10\n[data]\nobservations=\"o.csv\"\n[output]\ndir=\"out/a\"\n",
        )
        .unwrap();
        assert_eq!(c.data, DataSource::Observations("/tmp/x/o.csv".into()));
        assert_eq!(c.output_dir, PathBuf::from("/tmp/x/out/a"));
    }

    #[test]
    fn bad_values_name_their_key() {
        let e = parse("[target]\nrows=0\ncols=4\nspacing=0.1\n[[cameras]]\nname=\"c\"\nwidth=10\nheight=10\n[data]\nobservations=\"o.csv\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("target.rows") && e.contains("line 2"), "{e}");
        let e = parse("[target]\nrows=3\ncols=4\nspacing=0.1\n[[cameras]]\nname=\"a\"\nwidth=10\nheight=10\n[[cameras]]\nname=\"b\"\nwidth=0\nheight=10\n[data]\nobservations=\"o.csv\"\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("cameras[1].width") && e.contains("line 11"),
            "{e}"
        );
        let e = parse("[data]\nsynthetic=\"t9\"\n").unwrap_err().to_string();
        assert!(e.contains("data.synthetic") && e.contains("t9"), "{e}");
    }

    #[test]
    fn video_keys_are_checked() {
        let rig =
            "[target]\nrows=3\ncols=4\nspacing=0.1\n[[cameras]]\nname=\"c\"\nwidth=10\nheight=10\n";
        let c = parse(&format!("{rig}[data]\nvideo = \"v/a.mp4\"\n")).unwrap();
        let DataSource::Video(v) = c.data else {
            panic!("{:?}", c.data)
        };
        assert_eq!(v.path, PathBuf::from("/tmp/x/v/a.mp4"));
        assert_eq!(
            (v.stride, v.max_frames),
            (DEFAULT_STRIDE, DEFAULT_MAX_FRAMES)
        );
        let e = parse(&format!("{rig}[data]\nvideo = \"a.mp4\"\nstride = 0\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("data.stride") && e.contains("line 11"), "{e}");
        let e = parse(&format!("{rig}[data]\nvideo = \"a.mp4\"\nmax_frames = 2\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("data.max_frames"), "{e}");
        let e = parse(&format!(
            "{rig}[data]\nvideo = \"a.mp4\"\nobservations = \"o.csv\"\n"
        ))
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("[data] video is a data source of its own")
                && e.contains("remove data.observations ("),
            "{e}"
        );
        // Photos beside a video (or a video's stride) used to win silently.
        for (extra, key) in [
            ("video = \"a.mp4\"", "data.video"),
            ("stride = 2", "data.stride"),
            ("seed = 3", "data.seed"),
        ] {
            let e = parse(&format!("{rig}[data]\nphotos = \"*.png\"\n{extra}\n"))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("[data] photos is a data source of its own") && e.contains(key),
                "{extra}: {e}"
            );
        }
        let e = parse(&format!(
            "{rig}[data]\nobservations = \"o.csv\"\nstride = 2\n"
        ))
        .unwrap_err()
        .to_string();
        assert!(e.contains("apply to `video` only"), "{e}");
        let two = format!(
            "{rig}[[cameras]]\nname=\"d\"\nwidth=10\nheight=10\n[data]\nvideo = \"a.mp4\"\n"
        );
        let e = parse(&two).unwrap_err().to_string();
        assert!(e.contains("one camera's video"), "{e}");
    }
}
