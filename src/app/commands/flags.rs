//! `deformcal calibrate`'s flags and the config they make: a config file (optional),
//! named flags for the common keys, then `--set section.key=value` for any key, in
//! that order, merged into one TOML document (`config::overrides`) that is checked
//! exactly as a file is. This file is the one place that says which flag sets which
//! key (docs/config.md lists the same table for users).
use crate::app::config::overrides::{value_of, Document, KeyPath, OverrideError};
use crate::app::config::Config;
use crate::model::synthetic::Preset;
use anyhow::{Context, Result};
use std::path::PathBuf;
use toml::Value;

/// The flags of one calibration.
#[derive(clap::Args, Debug, Default, Clone)]
pub struct CalibrateArgs {
    /// A TOML config (docs/config.md); every flag below overrides its key.
    #[arg(
        long,
        short,
        value_name = "FILE",
        help_heading = "Data (a config, or one of the sources)"
    )]
    pub config: Option<PathBuf>,
    /// Photos of the board, a glob in quotes: 'photos/left*.jpg'. Sets data.photos.
    #[arg(
        long,
        value_name = "GLOB",
        help_heading = "Data (a config, or one of the sources)",
        group = "source"
    )]
    pub photos: Option<String>,
    /// A video of the board (decoded with ffmpeg; frames sampled every data.stride,
    /// the sharp and different ones kept, up to data.max_frames). Sets data.video.
    #[arg(
        long,
        value_name = "FILE",
        help_heading = "Data (a config, or one of the sources)",
        group = "source"
    )]
    pub video: Option<String>,
    /// Detected corners as CSV (camera,frame,corner,u,v). Sets data.observations.
    #[arg(
        long,
        value_name = "CSV",
        help_heading = "Data (a config, or one of the sources)",
        group = "source"
    )]
    pub observations: Option<String>,
    /// mrgingham's or mrcal's corners.vnl. Sets data.corners_vnl.
    #[arg(
        long = "corners-vnl",
        value_name = "VNL",
        help_heading = "Data (a config, or one of the sources)",
        group = "source"
    )]
    pub corners_vnl: Option<String>,
    /// A built-in synthetic dataset (t1, t2, t3, t4, reference, stereo, warped, flex).
    /// Sets data.synthetic.
    #[arg(
        long,
        value_name = "PRESET",
        help_heading = "Data (a config, or one of the sources)",
        group = "source"
    )]
    pub synthetic: Option<String>,
    /// Inner corners per row x per column, as OpenCV's patternSize: 9x6 is a board
    /// of 9 × 6 inner corners. Sets target.cols and target.rows.
    #[arg(long, value_name = "COLSxROWS", help_heading = "Board")]
    pub board: Option<String>,
    /// Distance between neighbouring corners, metres (0.025 for 25 mm squares).
    /// Sets target.spacing.
    #[arg(
        long,
        value_name = "METRES",
        help_heading = "Board",
        allow_negative_numbers = true
    )]
    pub square: Option<String>,
    /// Lens model of every camera: pinhole, radial3, opencv5, opencv8, kb4 or ds. Sets
    /// cameras.model.
    #[arg(long, value_name = "MODEL", help_heading = "Cameras")]
    pub model: Option<String>,
    /// Image size of every camera, pixels, e.g. 640x480 (with photos, each camera's
    /// read from its first photo when not given). Sets cameras.width and cameras.height.
    #[arg(long = "image-size", value_name = "WxH", help_heading = "Cameras")]
    pub image_size: Option<String>,
    /// Lens parameters held at their initial values, e.g. k3 or p1,p2,k3 (OpenCV's
    /// CALIB_FIX_*). Sets cameras.fix.
    #[arg(long, value_name = "PARAMS", help_heading = "Cameras")]
    pub fix: Option<String>,
    /// standard, static, dynamic, full (the paper's), dynamic3/4, full3/4, or auto
    /// (chosen by cross-validation; the default). Sets calibration.method.
    #[arg(long, value_name = "METHOD", help_heading = "Method and solver")]
    pub method: Option<String>,
    /// cauchy (the default) or none (plain least squares). Sets calibration.loss.
    #[arg(long, value_name = "LOSS", help_heading = "Method and solver")]
    pub loss: Option<String>,
    /// Drop observations beyond k·σ and solve again; 0 turns it off. Sets
    /// calibration.outlier_k.
    #[arg(
        long = "outlier-k",
        value_name = "K",
        help_heading = "Method and solver",
        allow_negative_numbers = true
    )]
    pub outlier_k: Option<String>,
    /// Ceres threads for one solve. Sets calibration.threads.
    #[arg(long, value_name = "N", help_heading = "Method and solver")]
    pub threads: Option<usize>,
    /// Folder for the results (default: out/ beside the config, or ./out). Sets
    /// output.dir.
    #[arg(long, short = 'o', value_name = "DIR", help_heading = "Output")]
    pub output: Option<String>,
    /// Any config key, checked as in a file: --set calibration.outlier_k=3,
    /// --set cameras[1].model=kb4, --set 'data.photos={left="l*.jpg", right="r*.jpg"}'.
    /// Repeatable; applied after the flags above, the last one winning.
    #[arg(
        long = "set",
        value_name = "SECTION.KEY=VALUE",
        help_heading = "Any key"
    )]
    pub set: Vec<String>,
}

/// The source flags and the key each sets in `[data]`.
const SOURCES: [(&str, &str); 5] = [
    ("--photos", "photos"),
    ("--video", "video"),
    ("--observations", "observations"),
    ("--corners-vnl", "corners_vnl"),
    ("--synthetic", "synthetic"),
];

impl CalibrateArgs {
    /// Whether any flag changes the config (beyond `--config`).
    pub fn changes_config(&self) -> bool {
        let named = [
            &self.board,
            &self.square,
            &self.model,
            &self.image_size,
            &self.fix,
            &self.method,
            &self.loss,
            &self.outlier_k,
            &self.output,
        ];
        self.source().is_some()
            || named.iter().any(|f| f.is_some())
            || self.threads.is_some()
            || !self.set.is_empty()
    }

    /// The data source flag: its spelling, its `[data]` key and its value.
    fn source(&self) -> Option<(&'static str, &'static str, &str)> {
        let given = [
            &self.photos,
            &self.video,
            &self.observations,
            &self.corners_vnl,
            &self.synthetic,
        ];
        SOURCES
            .iter()
            .zip(given)
            .find_map(|((flag, key), v)| Some((*flag, *key, v.as_deref()?)))
    }
}

/// The config the flags describe, and the document it was checked from (for the
/// config written beside the result).
pub fn config(args: &CalibrateArgs) -> Result<(Document, Config)> {
    let mut doc = match &args.config {
        Some(path) => Document::load(path)?,
        None => Document::new(),
    };
    let sets_data = args.set.iter().any(|s| s.trim_start().starts_with("data."));
    anyhow::ensure!(
        doc.file().is_some() || args.source().is_some() || sets_data,
        "no data given: use --config FILE (see configs/ for examples), or give the data as \
         --photos, --video, --observations, --corners-vnl or --synthetic (see `deformcal calibrate --help`)"
    );
    let file_has_cameras = !doc.cameras().is_empty();
    apply_source(&mut doc, args)?;
    apply_board(&mut doc, args)?;
    // Before the camera flags when the file holds the photo map, so that they
    // apply to each camera, and again after `--set`, which may give the map.
    cameras_from_photo_map(&mut doc, file_has_cameras);
    apply_cameras(&mut doc, args)?;
    apply_settings(&mut doc, args)?;
    for assignment in &args.set {
        doc.set_assignment(assignment, "--set")?;
    }
    cameras_from_photo_map(&mut doc, file_has_cameras);
    // Where a size came from is said once the config is accepted, so that a
    // refused config gives its one error line alone.
    let mut sizes_read = image_size_from_photos(&mut doc)?;
    sizes_read.extend(image_size_from_video(&mut doc)?);
    let mut config = match doc.config() {
        Err(e) if doc.file().is_none() => return Err(with_hint(e)),
        other => other?,
    };
    for line in sizes_read {
        eprintln!("{line}");
    }
    // The output folder is no key to check: it is taken as written (relative to
    // the working folder), and the written config names it absolutely.
    if let Some(dir) = &args.output {
        config.output_dir = PathBuf::from(dir);
    }
    Ok((doc, config))
}

/// A config file completed as `deformcal calibrate --config FILE` completes it
/// (cameras from a photo map, image sizes from the photos), for the commands that
/// read the same file (`detect`).
pub fn file_config(path: &std::path::Path) -> Result<Config> {
    let args = CalibrateArgs {
        config: Some(path.to_path_buf()),
        ..CalibrateArgs::default()
    };
    Ok(config(&args)?.1)
}

/// A config error of a run without a file says which flag would avoid it.
fn with_hint(e: OverrideError) -> anyhow::Error {
    const HINTS: [(&str, &str); 3] = [
        ("`[target]`", "--board COLSxROWS --square METRES"),
        ("[[cameras]]", "--image-size WxH"),
        (
            "[data] needs",
            "--photos, --video, --observations, --corners-vnl or --synthetic",
        ),
    ];
    let text = e.to_string();
    match HINTS.iter().find(|(what, _)| text.contains(what)) {
        Some((_, flags)) if !matches!(e, OverrideError::Flag { .. }) => {
            anyhow::anyhow!("{text}: give {flags}")
        }
        _ => e.into(),
    }
}

fn set(doc: &mut Document, section: &str, key: &str, value: Value, flag: &str) -> Result<()> {
    let path = KeyPath::Section {
        section: section.into(),
        key: key.into(),
    };
    Ok(doc.set(&path, value, flag)?)
}

fn set_cameras(doc: &mut Document, key: &str, value: Value, flag: &str) -> Result<()> {
    let path = KeyPath::Camera {
        index: None,
        key: key.into(),
    };
    Ok(doc.set(&path, value, flag)?)
}

/// A data source flag replaces the config's whole `[data]`.
fn apply_source(doc: &mut Document, args: &CalibrateArgs) -> Result<()> {
    let Some((flag, key, value)) = args.source() else {
        return Ok(());
    };
    let spelled = format!("{flag} {value}");
    doc.replace_section("data", &spelled);
    let value = if key == "synthetic" {
        Value::String(value.into())
    } else {
        doc.path_value(value)
    };
    set(doc, "data", key, value, &spelled)
}

/// `--board COLSxROWS` and `--square`.
fn apply_board(doc: &mut Document, args: &CalibrateArgs) -> Result<()> {
    if let Some(board) = &args.board {
        let flag = format!("--board {board}");
        let (cols, rows) = pair(board).with_context(|| {
            format!(
                "{flag}: expected COLSxROWS, the inner corners per row and per column (e.g. 9x6)"
            )
        })?;
        set(doc, "target", "cols", Value::Integer(cols), &flag)?;
        set(doc, "target", "rows", Value::Integer(rows), &flag)?;
    }
    if let Some(square) = &args.square {
        set(
            doc,
            "target",
            "spacing",
            number_value(square),
            &format!("--square {square}"),
        )?;
    }
    Ok(())
}

/// `--model`, `--image-size` and `--fix`, for every camera. With synthetic data
/// and no `[[cameras]]`, the preset's cameras are written out first, so that
/// their model can be changed.
fn apply_cameras(doc: &mut Document, args: &CalibrateArgs) -> Result<()> {
    if args.model.is_none() && args.fix.is_none() && args.image_size.is_none() {
        return Ok(());
    }
    if doc.cameras().is_empty() {
        preset_cameras(doc)?;
    }
    if let Some(model) = &args.model {
        set_cameras(
            doc,
            "model",
            Value::String(model.clone()),
            &format!("--model {model}"),
        )?;
    }
    if let Some(size) = &args.image_size {
        let flag = format!("--image-size {size}");
        let (w, h) =
            pair(size).with_context(|| format!("{flag}: expected WxH in pixels (e.g. 640x480)"))?;
        set_cameras(doc, "width", Value::Integer(w), &flag)?;
        set_cameras(doc, "height", Value::Integer(h), &flag)?;
    }
    if let Some(fix) = &args.fix {
        let names = fix
            .split(',')
            .map(|p| Value::String(p.trim().to_string()))
            .filter(|v| v.as_str() != Some(""))
            .collect();
        set_cameras(doc, "fix", Value::Array(names), &format!("--fix {fix}"))?;
    }
    Ok(())
}

/// A synthetic preset's cameras as `[[cameras]]` tables.
fn preset_cameras(doc: &mut Document) -> Result<()> {
    let Some(preset) = doc
        .get("data", "synthetic")
        .and_then(Value::as_str)
        .and_then(Preset::parse)
    else {
        return Ok(());
    };
    let n = doc
        .get("data", "cameras")
        .and_then(Value::as_integer)
        .and_then(|n| usize::try_from(n).ok())
        .filter(|n| (1..=16).contains(n))
        .unwrap_or(preset.default_cameras());
    let flag = format!("--synthetic {}", preset.name());
    for (i, camera) in preset.cameras(n).into_iter().enumerate() {
        let at = |key: &str| KeyPath::Camera {
            index: Some(i),
            key: key.into(),
        };
        doc.set(&at("name"), Value::String(camera.name), &flag)?;
        doc.set(&at("width"), Value::Integer(camera.width.into()), &flag)?;
        doc.set(&at("height"), Value::Integer(camera.height.into()), &flag)?;
    }
    Ok(())
}

/// `--method`, `--loss`, `--outlier-k` and `--threads`.
fn apply_settings(doc: &mut Document, args: &CalibrateArgs) -> Result<()> {
    let named = [
        ("--method", "method", &args.method),
        ("--loss", "loss", &args.loss),
    ];
    for (flag, key, value) in named {
        if let Some(v) = value {
            set(
                doc,
                "calibration",
                key,
                Value::String(v.clone()),
                &format!("{flag} {v}"),
            )?;
        }
    }
    if let Some(k) = &args.outlier_k {
        set(
            doc,
            "calibration",
            "outlier_k",
            number_value(k),
            &format!("--outlier-k {k}"),
        )?;
    }
    if let Some(t) = args.threads {
        let value = Value::Integer(i64::try_from(t).unwrap_or(i64::MAX));
        set(
            doc,
            "calibration",
            "threads",
            value,
            &format!("--threads {t}"),
        )?;
    }
    Ok(())
}

/// A number flag's value; anything else stays a string, for the key's own check
/// to refuse by name.
fn number_value(text: &str) -> Value {
    match value_of(text) {
        Value::Integer(i) => Value::Float(i as f64),
        other => other,
    }
}

/// `AxB` (also `A×B`) as two positive integers.
fn pair(text: &str) -> Option<(i64, i64)> {
    let (a, b) = text.split_once(['x', 'X', '×'])?;
    let parse = |s: &str| s.trim().parse::<i64>().ok().filter(|n| *n > 0);
    Some((parse(a)?, parse(b)?))
}

/// With one photo pattern per camera (`data.photos = { left = "l*.jpg", right =
/// "r*.jpg" }`) and no `[[cameras]]` in the file, the cameras are the map's names,
/// in its (sorted) order, the first being the rig's reference: each with what the
/// flags gave every camera. Cameras the flags named one by one are left to the
/// config's check, which says what is missing.
fn cameras_from_photo_map(doc: &mut Document, file_has_cameras: bool) {
    let Some(map) = doc.get("data", "photos").and_then(Value::as_table) else {
        return;
    };
    if file_has_cameras {
        return;
    }
    let names: Vec<String> = map.keys().cloned().collect();
    let cameras = doc.cameras();
    let made_by_flags = cameras.is_empty()
        || (cameras.len() == 1 && cameras[0].get("name").and_then(Value::as_str) == Some("cam0"));
    if made_by_flags {
        doc.cameras_named(&names, "data.photos");
    }
}

/// Whether the document has at most one camera and it lacks an image size: the
/// one camera a single photo pattern or a video gives its size to.
fn one_camera_to_size(doc: &Document) -> bool {
    match doc.cameras().as_slice() {
        [] => true,
        [camera] => !(camera.contains_key("width") && camera.contains_key("height")),
        _ => false,
    }
}

/// Cameras without an image size take it from their first photo that has one
/// (a header read, not a decode): with one photo pattern, every camera (there is
/// one) from it; with one pattern per camera, each from its own. Returns a line
/// per size read, saying where from.
fn image_size_from_photos(doc: &mut Document) -> Result<Vec<String>> {
    let patterns: Vec<(Option<String>, String)> = match doc.get("data", "photos") {
        Some(Value::String(p)) => vec![(None, p.clone())],
        Some(Value::Table(map)) => map
            .iter()
            .filter_map(|(name, p)| Some((Some(name.clone()), p.as_str()?.to_string())))
            .collect(),
        _ => return Ok(Vec::new()),
    };
    // (camera index and name, or every camera, and its pattern) for each camera to size.
    type Wanted = (Option<(usize, String)>, String);
    let wanted: Vec<Wanted> = match patterns.as_slice() {
        [(None, pattern)] if one_camera_to_size(doc) => vec![(None, pattern.clone())],
        [(None, _)] => Vec::new(),
        _ => doc
            .cameras()
            .iter()
            .enumerate()
            .filter(|(_, c)| !(c.contains_key("width") && c.contains_key("height")))
            .filter_map(|(i, c)| {
                let name = c.get("name")?.as_str()?;
                let (_, p) = patterns.iter().find(|(n, _)| n.as_deref() == Some(name))?;
                Some((Some((i, name.to_string())), p.clone()))
            })
            .collect(),
    };
    let base = doc.base();
    let mut read = Vec::new();
    for (camera, pattern) in wanted {
        let names = crate::app::photos::list::matching(&base, &pattern)?;
        let Some((name, (w, h))) = names.iter().find_map(|n| {
            let size = image::image_dimensions(base.join(n)).ok()?;
            Some((n, size))
        }) else {
            anyhow::bail!(
                "data.photos {pattern}: none of the {} files is an image",
                names.len()
            );
        };
        let flag = format!("data.photos {pattern}: the image size of {name}");
        read.push(match &camera {
            Some((_, c)) => format!("image size {w}×{h} px for camera {c}, from {name}"),
            None => format!("image size {w}×{h} px, from {name}"),
        });
        for (key, value) in [("width", w), ("height", h)] {
            let path = KeyPath::Camera {
                index: camera.as_ref().map(|(i, _)| *i),
                key: key.into(),
            };
            doc.set(&path, Value::Integer(value.into()), &flag)?;
        }
    }
    Ok(read)
}

/// With a video and one camera without an image size, the size is the video's;
/// the line saying so, if it was read.
fn image_size_from_video(doc: &mut Document) -> Result<Option<String>> {
    let Some(video) = doc.get("data", "video").and_then(Value::as_str) else {
        return Ok(None);
    };
    if !one_camera_to_size(doc) {
        return Ok(None);
    }
    let video = video.to_string();
    let probe = crate::app::video::ffmpeg::probe(&doc.base().join(&video))?;
    let flag = format!("data.video {video}: its frame size");
    set_cameras(doc, "width", Value::Integer(probe.width.into()), &flag)?;
    set_cameras(doc, "height", Value::Integer(probe.height.into()), &flag)?;
    Ok(Some(format!(
        "image size {}×{} px, from {video}",
        probe.width, probe.height
    )))
}
