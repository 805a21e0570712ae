//! mrgingham's / mrcal's `corners.vnl` corner table (docs/conventions.md §5 Interchange): reading
//! it into a dataset, with camera patterns for several cameras, and writing one.
use crate::error::{Error, Result};
use crate::model::camera::CameraSpec;
use crate::model::dataset::{Dataset, DetectedCorner};
use crate::model::target::Target;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write;
use std::path::Path;

/// Longest `camera_patterns` glob accepted.
const MAX_PATTERN_CHARS: usize = 1000;

/// A `camera_patterns` glob (`*` any run of characters, `?` one character) as an
/// anchored regular expression with one group per wildcard. The `regex` crate
/// matches in time linear in the name, whatever the pattern (a backtracking
/// matcher takes exponential time on `*a*a*a*…z`); globset matches linearly too but
/// cannot report what the wildcards matched, which is the time step.
fn glob_regex(pattern: &str) -> Option<regex::Regex> {
    if pattern.chars().count() > MAX_PATTERN_CHARS {
        return None;
    }
    let mut re = String::from("^(?s:");
    for c in pattern.chars() {
        match c {
            '*' => re.push_str("(.*)"),
            '?' => re.push_str("(.)"),
            c => re.push_str(&regex::escape(c.encode_utf8(&mut [0; 4]))),
        }
    }
    re.push_str(")$");
    regex::RegexBuilder::new(&re)
        .size_limit(1 << 24)
        .build()
        .ok()
}

/// Matches `name` against a glob with `*` and `?`; returns what the wildcards matched.
pub fn glob_captures(pattern: &str, name: &str) -> Option<String> {
    let re = glob_regex(pattern)?;
    captures(&re, name)
}

/// What the wildcard groups of a compiled glob matched in `name`.
fn captures(re: &regex::Regex, name: &str) -> Option<String> {
    let caps = re.captures(name)?;
    Some(caps.iter().skip(1).flatten().map(|m| m.as_str()).collect())
}

/// The cameras whose patterns match an image file (against the base name unless
/// the pattern has a `/`), each with what its wildcards matched, the time-step
/// key; without patterns, camera 0 and the whole name. More than one is an
/// ambiguity the caller refuses: the image would be a view of whichever came first.
fn cameras_of(
    file: &str,
    cameras: &[CameraSpec],
    patterns: &[Option<(regex::Regex, bool)>],
) -> Vec<(usize, String)> {
    if patterns.is_empty() {
        return vec![(0, file.to_string())];
    }
    let base = file.rsplit('/').next().unwrap_or(file);
    cameras
        .iter()
        .enumerate()
        .filter_map(|(k, _)| {
            let (re, whole_path) = patterns[k].as_ref()?;
            let subject = if *whole_path { file } else { base };
            captures(re, subject).map(|key| (k, key))
        })
        .collect()
}

/// Each camera's compiled pattern (with whether it matches the whole path), in
/// camera order; empty without patterns.
fn compile_patterns(
    path: &Path,
    cameras: &[CameraSpec],
    patterns: &BTreeMap<String, String>,
) -> Result<Vec<Option<(regex::Regex, bool)>>> {
    if patterns.is_empty() {
        return Ok(Vec::new());
    }
    cameras
        .iter()
        .map(|c| match patterns.get(&c.name) {
            None => Ok(None),
            Some(p) => glob_regex(p)
                .map(|re| Some((re, p.contains('/'))))
                .ok_or_else(|| {
                    Error::Invalid(format!(
                        "{}: data.camera_patterns of `{}` is not a usable pattern (at most {MAX_PATTERN_CHARS} characters)",
                        path.display(),
                        crate::app::text::short(&c.name)
                    ))
                }),
        })
        .collect()
}

/// Largest decimation level accepted; mrgingham uses a handful, and far beyond
/// this a corner's weight 0.5^level underflows the solver's cost to nothing.
pub const MAX_LEVEL: f64 = 10.0;
/// The range of an explicit `weight` column, for the same reason.
pub const WEIGHT_RANGE: (f64, f64) = (1e-3, 1e3);

/// One parsed corner row.
struct Corner {
    line: u64,
    xy: Option<[f64; 2]>,
    weight: f64,
    /// Marked not found by a negative weight (mrcal's convention), though it has
    /// coordinates: said in the error when no corner is left.
    negative_weight: bool,
}

/// A data error at `line` of the table at `path`.
fn data_err(path: &Path, line: u64, message: String) -> Error {
    Error::Data {
        path: path.into(),
        line,
        message,
    }
}

/// The table's text: refuses binary and non-UTF-8 input, drops a byte-order mark.
fn table_text<'a>(bytes: &'a [u8], path: &Path) -> Result<&'a str> {
    if bytes.contains(&0) {
        return Err(data_err(
            path,
            1,
            "this is a binary file, not a corners.vnl table".into(),
        ));
    }
    let text = std::str::from_utf8(bytes)
        .map_err(|_| data_err(path, 1, "not a UTF-8 text file".into()))?;
    // Editors on Windows start UTF-8 files with a byte-order mark.
    Ok(text.strip_prefix('\u{feff}').unwrap_or(text))
}

/// Refuses several cameras unless every one has a pattern to tell its images apart.
fn check_patterns_cover(
    path: &Path,
    cameras: &[CameraSpec],
    patterns: &BTreeMap<String, String>,
) -> Result<()> {
    if cameras.len() > 1 {
        for c in cameras {
            if !patterns.contains_key(&c.name) {
                return Err(Error::Invalid(format!(
                    "{}: with several cameras, data.camera_patterns needs a pattern for `{}`",
                    path.display(),
                    c.name
                )));
            }
        }
    }
    Ok(())
}

/// Column positions of the table's fields.
struct Columns {
    file: usize,
    x: usize,
    y: usize,
    level: Option<usize>,
    weight: Option<usize>,
}

impl Default for Columns {
    /// Without a vnlog legend: filename x y [level].
    fn default() -> Self {
        Columns {
            file: 0,
            x: 1,
            y: 2,
            level: Some(3),
            weight: None,
        }
    }
}

/// The columns a vnlog legend (`trimmed`, `#` and all) names.
fn parse_legend(path: &Path, line: u64, trimmed: &str, legend: &str) -> Result<Columns> {
    let names: Vec<&str> = legend.split_whitespace().collect();
    let find = |n: &str| names.iter().position(|&c| c == n);
    match (find("filename"), find("x"), find("y")) {
        (Some(file), Some(x), Some(y)) => Ok(Columns {
            file,
            x,
            y,
            level: find("level"),
            weight: find("weight"),
        }),
        _ => Err(data_err(
            path,
            line,
            format!("legend `{trimmed}` lacks filename, x and y columns"),
        )),
    }
}

/// A numeric field, `None` for `-`.
fn number(path: &Path, line: u64, s: &str, what: &str) -> Result<Option<f64>> {
    if s == "-" {
        return Ok(None);
    }
    let v: f64 = s.parse().map_err(|_| {
        data_err(
            path,
            line,
            format!("{what} `{}` is not a number", crate::app::text::short(s)),
        )
    })?;
    if !v.is_finite() {
        return Err(data_err(path, line, format!("{what} is not finite ({v})")));
    }
    Ok(Some(v))
}

/// One data row: its image file name and its corner.
fn parse_row(path: &Path, line: u64, trimmed: &str, cols: &Columns) -> Result<(String, Corner)> {
    let err = |message: String| data_err(path, line, message);
    let fields: Vec<&str> = trimmed.split_whitespace().collect();
    let needed = cols.file.max(cols.x).max(cols.y) + 1;
    if fields.len() < needed {
        return Err(err(format!(
            "expected at least {needed} columns (filename x y), found {}",
            fields.len()
        )));
    }
    let x = number(path, line, fields[cols.x], "x")?;
    let y = number(path, line, fields[cols.y], "y")?;
    let mut weight = 1.0;
    let mut present = x.is_some() && y.is_some();
    let mut negative_weight = false;
    if let Some(c) = cols.level.filter(|&c| c < fields.len()) {
        match number(path, line, fields[c], "level")? {
            // mrgingham: noise doubles with each decimation level.
            Some(l) if (0.0..=MAX_LEVEL).contains(&l) => weight = 0.5f64.powf(l),
            Some(l) => return Err(err(format!("level {l} is outside 0..{MAX_LEVEL}"))),
            None => present = false,
        }
    }
    if let Some(c) = cols.weight.filter(|&c| c < fields.len()) {
        let (lo, hi) = WEIGHT_RANGE;
        match number(path, line, fields[c], "weight")? {
            Some(w) if (lo..=hi).contains(&w) => weight = w,
            Some(w) if w > 0.0 => return Err(err(format!("weight {w} is outside {lo}..{hi}"))),
            // mrcal reads a negative weight as "corner not found"; 0 is neither a
            // weight the solver can use nor that mark, so it is a mistake.
            Some(w) if w < 0.0 => {
                negative_weight = present;
                present = false;
            }
            Some(_) => {
                return Err(err(format!(
                    "weight 0 is not a usable weight (use {lo}..{hi}, or `-` or a negative weight for a corner not found)"
                )))
            }
            None => present = false,
        }
    }
    let corner = Corner {
        line,
        xy: if present {
            Some([x.unwrap_or(0.0), y.unwrap_or(0.0)])
        } else {
            None
        },
        weight,
        negative_weight,
    };
    Ok((fields[cols.file].to_string(), corner))
}

/// The table's rows grouped per image, in file order; an image's rows must be contiguous.
fn group_rows(text: &str, path: &Path) -> Result<Vec<(String, Vec<Corner>)>> {
    let mut cols = Columns::default();
    let mut images: Vec<(String, Vec<Corner>)> = Vec::new();
    let mut seen_data = false;
    for (i, raw) in text.lines().enumerate() {
        let line = i as u64 + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with("##") {
            continue;
        }
        if let Some(legend) = trimmed.strip_prefix('#') {
            // A legend after the data is a comment.
            if !seen_data {
                cols = parse_legend(path, line, trimmed, legend)?;
            }
            continue;
        }
        seen_data = true;
        let (file, corner) = parse_row(path, line, trimmed, &cols)?;
        match images.last_mut() {
            Some((name, corners)) if *name == file => corners.push(corner),
            _ => {
                if images.iter().any(|(n, _)| *n == file) {
                    return Err(data_err(
                        path,
                        line,
                        format!("the rows of `{file}` are not contiguous"),
                    ));
                }
                images.push((file, vec![corner]));
            }
        }
    }
    Ok(images)
}

/// An image's camera, frame number and file name.
pub type ImageName = (usize, i64, String);

/// An image's camera, time-step key, corners and file name.
type Keyed = (usize, String, Vec<Corner>, String);

/// Keys each image with a board by camera and time step; also counts those without.
fn key_images(
    images: Vec<(String, Vec<Corner>)>,
    path: &Path,
    target: &Target,
    cameras: &[CameraSpec],
    patterns: &BTreeMap<String, String>,
) -> Result<(Vec<Keyed>, usize)> {
    let n = target.num_corners();
    let compiled = compile_patterns(path, cameras, patterns)?;
    let mut without_board = 0;
    let mut keyed: Vec<Keyed> = Vec::new();
    let mut keys_seen = BTreeSet::new();
    for (file, corners) in images {
        let first_line = corners[0].line;
        let err = |message: String| data_err(path, first_line, message);
        if corners.len() == 1 && corners[0].xy.is_none() {
            without_board += 1;
            continue;
        }
        if corners.len() != n {
            return Err(err(format!(
                "`{file}` has {} corner rows; a {} × {} board has {n}",
                corners.len(),
                target.rows,
                target.cols
            )));
        }
        let (camera, key) = match cameras_of(&file, cameras, &compiled).as_slice() {
            [] => {
                return Err(err(format!(
                    "`{file}` matches no pattern of data.camera_patterns"
                )))
            }
            [one] => one.clone(),
            [a, b, ..] => {
                return Err(err(format!(
                    "`{file}` matches the data.camera_patterns of both `{}` and `{}`; an image belongs to one camera",
                    cameras[a.0].name, cameras[b.0].name
                )))
            }
        };
        if !keys_seen.insert((camera, key.clone())) {
            return Err(err(format!(
                "`{file}` is a second image of camera {} at time step `{key}`",
                cameras[camera].name
            )));
        }
        keyed.push((camera, key, corners, file));
    }
    Ok((keyed, without_board))
}

/// The dataset of the keyed images, frames numbered in sorted order of their keys,
/// and each image's camera, frame number and file name.
fn assemble(
    keyed: &[Keyed],
    path: &Path,
    target: Target,
    cameras: Vec<CameraSpec>,
) -> Result<(Dataset, Vec<ImageName>)> {
    let keys: BTreeSet<&String> = keyed.iter().map(|(_, k, _, _)| k).collect();
    let frame_of: BTreeMap<&String, i64> = keys
        .into_iter()
        .enumerate()
        .map(|(i, k)| (k, i as i64))
        .collect();
    let mut rows = Vec::new();
    let mut files = Vec::new();
    for (camera, key, corners, file) in keyed {
        files.push((*camera, frame_of[key], file.clone()));
        for (i, c) in corners.iter().enumerate() {
            if let Some(uv) = c.xy {
                rows.push(DetectedCorner {
                    camera: *camera,
                    frame_id: frame_of[key],
                    corner: i,
                    uv,
                    weight: c.weight,
                });
            }
        }
    }
    if rows.is_empty() {
        let negative: Vec<u64> = keyed
            .iter()
            .flat_map(|(_, _, corners, _)| corners)
            .filter(|c| c.negative_weight)
            .map(|c| c.line)
            .collect();
        if let Some(&first) = negative.first() {
            return Err(data_err(
                path,
                first,
                format!(
                    "no corner is left: all {} corners with coordinates have a negative weight, which mrcal's corners.vnl uses to mark a corner not found",
                    negative.len()
                ),
            ));
        }
        return Err(data_err(path, 1, "no corner was found in any image".into()));
    }
    Ok((Dataset::from_detected(target, cameras, rows), files))
}

/// A parsed corners table: the dataset, how many images had no board, and each
/// image with a board as (camera, frame number, file name).
pub struct Table {
    pub dataset: Dataset,
    pub without_board: usize,
    pub files: Vec<ImageName>,
}

/// Reads a `corners.vnl` (docs/conventions.md §5): one row per corner, `filename x y [level|weight]`,
/// `-` for a corner not found, a single `filename - - -` row for an image without a
/// board, corners in row-major order. Frames are numbered in sorted order of their
/// time-step keys; returns the dataset and how many images had no board.
pub fn read_corners_vnl(
    path: &Path,
    target: Target,
    cameras: Vec<CameraSpec>,
    patterns: &BTreeMap<String, String>,
) -> Result<(Dataset, usize)> {
    let t = read_table(path, target, cameras, patterns)?;
    Ok((t.dataset, t.without_board))
}

/// [`read_corners_vnl`] with the image file names.
pub fn read_table(
    path: &Path,
    target: Target,
    cameras: Vec<CameraSpec>,
    patterns: &BTreeMap<String, String>,
) -> Result<Table> {
    let bytes = crate::app::fsio::read_limited(path, crate::app::fsio::MAX_DATA_BYTES)?;
    parse_table(&bytes, path, target, cameras, patterns)
}

/// Parses `corners.vnl` bytes; `path` names the source in messages.
pub fn parse_corners_vnl(
    bytes: &[u8],
    path: &Path,
    target: Target,
    cameras: Vec<CameraSpec>,
    patterns: &BTreeMap<String, String>,
) -> Result<(Dataset, usize)> {
    let t = parse_table(bytes, path, target, cameras, patterns)?;
    Ok((t.dataset, t.without_board))
}

/// [`parse_corners_vnl`] with the image file names.
pub fn parse_table(
    bytes: &[u8],
    path: &Path,
    target: Target,
    cameras: Vec<CameraSpec>,
    patterns: &BTreeMap<String, String>,
) -> Result<Table> {
    let text = table_text(bytes, path)?;
    check_patterns_cover(path, &cameras, patterns)?;
    let images = group_rows(text, path)?;
    let (keyed, without_board) = key_images(images, path, &target, &cameras, patterns)?;
    let (dataset, files) = assemble(&keyed, path, target, cameras)?;
    Ok(Table {
        dataset,
        without_board,
        files,
    })
}

/// Writes a dataset as a `corners.vnl` with one image per (camera, frame) named
/// `<camera>-<frame>.png`, missing corners as `- - -` rows.
pub fn write_corners_vnl(dataset: &Dataset) -> String {
    let mut s = String::from("# filename x y level\n");
    let n = dataset.target.num_corners();
    let mut views: BTreeMap<(usize, usize), Vec<Option<[f64; 2]>>> = BTreeMap::new();
    for o in &dataset.observations {
        views
            .entry((o.camera, o.frame))
            .or_insert_with(|| vec![None; n])[o.corner] = Some(o.uv);
    }
    for ((camera, frame), corners) in views {
        let name = format!(
            "{}-{:06}.png",
            dataset.cameras[camera].name, dataset.frame_ids[frame]
        );
        for c in corners {
            match c {
                Some([u, v]) => {
                    let _ = writeln!(s, "{name} {u} {v} 0");
                }
                None => {
                    let _ = writeln!(s, "{name} - - -");
                }
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn globs_capture_the_time_step() {
        assert_eq!(
            glob_captures("left*.png", "left0042.png").as_deref(),
            Some("0042")
        );
        assert_eq!(
            glob_captures("cam?/*", "cam1/frame7").as_deref(),
            Some("1frame7")
        );
        assert_eq!(glob_captures("right*", "left1.png"), None);
        assert_eq!(glob_captures("*", "").as_deref(), Some(""));
    }
}
