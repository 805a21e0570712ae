//! Which files a `[data] photos` pattern names, and their camera and frame.
//!
//! Only the folders the pattern can reach are listed: its leading literal folders
//! are the start, and the walk goes only as deep as the pattern has components
//! (unlimited with `**`). Every file name is matched with `globset`, which runs in
//! linear time, so a hostile pattern cannot stall the run. No image is opened here.
//!
//! A `**` walk does not enter linked folders, so a link loop cannot list a photo
//! many times; and one file (by its canonical path) is refused when two names reach
//! it, for one camera (a link) or for two (overlapping patterns): it would be two
//! views that are the same picture, or a rig with no baseline.
use crate::app::config::PhotoPatterns;
use crate::error::{Error, Result};
use crate::model::camera::CameraSpec;
use globset::GlobBuilder;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// One image file with its place in the dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageFile {
    /// The file, `base` joined with `name`.
    pub path: PathBuf,
    /// The path as matched: relative to the config's folder, `/`-separated.
    pub name: String,
    /// Index into [[cameras]].
    pub camera: usize,
    /// The frame (time step) number.
    pub frame: i64,
}

/// Characters that make a pattern component more than a literal name.
const META: [char; 6] = ['*', '?', '[', ']', '{', '}'];

/// Folders deeper than this below the pattern's start are not walked for `**`.
const MAX_DEPTH: usize = 32;

/// Lists every camera's files and numbers the frames (docs/conventions.md §5 Photos): with one
/// pattern, frames follow the sorted file names; with one per camera, what the
/// pattern's wildcards matched is the time step, numbered in sorted order.
pub fn list_photos(
    base: &Path,
    patterns: &PhotoPatterns,
    cameras: &[CameraSpec],
) -> Result<Vec<ImageFile>> {
    let files = listed(base, patterns, cameras)?;
    refuse_same_file(&files, patterns, cameras)?;
    Ok(files)
}

/// [`list_photos`] before the check for one file listed twice.
fn listed(base: &Path, patterns: &PhotoPatterns, cameras: &[CameraSpec]) -> Result<Vec<ImageFile>> {
    match patterns {
        PhotoPatterns::One(pattern) => {
            let names = matching(base, pattern)?;
            Ok(names
                .into_iter()
                .enumerate()
                .map(|(i, name)| ImageFile {
                    path: base.join(&name),
                    name,
                    camera: 0,
                    frame: i as i64,
                })
                .collect())
        }
        PhotoPatterns::PerCamera(map) => {
            let mut keyed = Vec::new();
            for (k, camera) in cameras.iter().enumerate() {
                let pattern = map.get(&camera.name).ok_or_else(|| {
                    Error::Invalid(format!("data.photos has no pattern for `{}`", camera.name))
                })?;
                for name in matching(base, pattern)? {
                    keyed.push((k, time_step(pattern, &name), name));
                }
            }
            let keys: BTreeSet<&String> = keyed.iter().map(|(_, key, _)| key).collect();
            let frame_of: BTreeMap<&String, i64> =
                keys.into_iter().zip(0..).collect::<BTreeMap<_, _>>();
            let mut files: Vec<ImageFile> = keyed
                .iter()
                .map(|(k, key, name)| ImageFile {
                    path: base.join(name),
                    name: name.clone(),
                    camera: *k,
                    frame: frame_of[key],
                })
                .collect();
            files.sort_by_key(|f| (f.camera, f.frame));
            Ok(files)
        }
    }
}

/// Refuses a file that two listed names reach (compared by canonical path), naming
/// both names and, when they differ, both cameras.
fn refuse_same_file(
    files: &[ImageFile],
    patterns: &PhotoPatterns,
    cameras: &[CameraSpec],
) -> Result<()> {
    let mut seen: BTreeMap<PathBuf, &ImageFile> = BTreeMap::new();
    for f in files {
        // A file that cannot be resolved is reported as unreadable by detection.
        let Ok(real) = std::fs::canonicalize(&f.path) else {
            continue;
        };
        let Some(first) = seen.insert(real, f) else {
            continue;
        };
        let pattern = |k: usize| match patterns {
            PhotoPatterns::One(p) => p.clone(),
            PhotoPatterns::PerCamera(m) => m.get(&cameras[k].name).cloned().unwrap_or_default(),
        };
        let message = if first.camera != f.camera {
            format!(
                "`{}` is matched by the patterns of both camera `{}` and camera `{}`; a photo belongs to one camera",
                f.name, cameras[first.camera].name, cameras[f.camera].name
            )
        } else if first.name == f.name {
            format!("`{}` is listed twice", f.name)
        } else {
            format!(
                "`{}` and `{}` are the same file (a link); each photo may be listed once",
                first.name, f.name
            )
        };
        return Err(Error::Photos {
            pattern: pattern(f.camera),
            message,
        });
    }
    Ok(())
}

/// The part of `name` the wildcards of `pattern` matched: `name` without the
/// pattern's literal head and tail (`left-0042.png` of `left-*.png` is `0042`).
pub fn time_step(pattern: &str, name: &str) -> String {
    let head = pattern.find(META).unwrap_or(pattern.len());
    let tail = pattern
        .rfind(META)
        .map(|i| pattern.len() - i - 1)
        .unwrap_or(0);
    if head + tail > name.len() || !name.is_char_boundary(head) {
        return name.to_string();
    }
    let end = name.len() - tail;
    if !name.is_char_boundary(end) {
        return name.to_string();
    }
    name[head..end].to_string()
}

/// The sorted names of the files `pattern` matches, relative to `base`; an error
/// naming the pattern when it is invalid or matches nothing.
pub fn matching(base: &Path, pattern: &str) -> Result<Vec<String>> {
    let fail = |message: String| Error::Photos {
        pattern: pattern.to_string(),
        message,
    };
    let glob = GlobBuilder::new(pattern)
        .literal_separator(true)
        .build()
        .map_err(|e| fail(format!("not a valid pattern: {}", e.kind())))?
        .compile_matcher();
    let parts: Vec<&str> = pattern.split('/').collect();
    let literal = parts
        .iter()
        .take(parts.len() - 1)
        .take_while(|p| !p.contains(META))
        .count();
    let prefix = parts[..literal].join("/");
    let start = if prefix.is_empty() && pattern.starts_with('/') {
        PathBuf::from("/")
    } else if base.as_os_str().is_empty() && prefix.is_empty() {
        // A config in the working folder has an empty folder name.
        PathBuf::from(".")
    } else {
        base.join(&prefix)
    };
    let rest = &parts[literal..];
    let recursive = rest.iter().any(|p| p.contains("**"));
    let depth = if recursive { MAX_DEPTH } else { rest.len() };
    if !start.is_dir() {
        return Err(fail(format!(
            "matches no file: the folder {} does not exist",
            start.display()
        )));
    }
    let mut names = Vec::new();
    walk(&start, &prefix, depth, recursive, &mut |name| {
        if glob.is_match(name) {
            names.push(name.to_string());
        }
    })
    .map_err(|e| fail(format!("cannot list {}: {e}", start.display())))?;
    if names.is_empty() {
        return Err(fail(format!(
            "matches no file (looked in {})",
            start.display()
        )));
    }
    names.sort();
    Ok(names)
}

/// Calls `found` with the `/`-joined name of every file up to `depth` levels below
/// `dir` (1: `dir`'s own files). Unreadable subfolders are skipped; only an
/// unreadable `dir` itself is an error. A `recursive` walk does not enter linked
/// folders: a link to a folder above would list the same photos again, level
/// after level.
fn walk(
    dir: &Path,
    prefix: &str,
    depth: usize,
    recursive: bool,
    found: &mut dyn FnMut(&str),
) -> std::io::Result<()> {
    if depth == 0 {
        return Ok(());
    }
    for entry in std::fs::read_dir(dir)? {
        let Ok(entry) = entry else { continue };
        let file_name = entry.file_name();
        let Some(file_name) = file_name.to_str() else {
            continue;
        };
        let name = if prefix.is_empty() {
            file_name.to_string()
        } else if prefix.ends_with('/') {
            format!("{prefix}{file_name}")
        } else {
            format!("{prefix}/{file_name}")
        };
        // `metadata` follows symlinks, so linked photos (and, outside `**`, linked
        // folders) count.
        let Ok(meta) = std::fs::metadata(entry.path()) else {
            continue;
        };
        let linked = entry.file_type().is_ok_and(|t| t.is_symlink());
        if meta.is_dir() {
            if recursive && linked {
                continue;
            }
            let _ = walk(&entry.path(), &name, depth - 1, recursive, found);
        } else if meta.is_file() {
            found(&name);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_step_is_what_the_wildcards_matched() {
        assert_eq!(time_step("left-*.png", "left-0042.png"), "0042");
        assert_eq!(time_step("cam0/*/img*.png", "cam0/a/img7.png"), "a/img7");
        assert_eq!(time_step("photos/l??.jpg", "photos/l01.jpg"), "01");
    }

    #[test]
    fn only_matching_files_in_sorted_order() {
        let dir = tempfile::tempdir().unwrap();
        let sub = dir.path().join("photos");
        std::fs::create_dir_all(sub.join("deeper")).unwrap();
        for f in [
            "left-2.png",
            "left-1.png",
            "right-1.png",
            "deeper/left-3.png",
        ] {
            std::fs::write(sub.join(f), b"x").unwrap();
        }
        let names = matching(dir.path(), "photos/left-*.png").unwrap();
        assert_eq!(names, ["photos/left-1.png", "photos/left-2.png"]);
        let deep = matching(dir.path(), "photos/**/left-*.png").unwrap();
        assert_eq!(
            deep,
            [
                "photos/deeper/left-3.png",
                "photos/left-1.png",
                "photos/left-2.png"
            ]
        );
        let e = matching(dir.path(), "photos/none-*.png").unwrap_err();
        assert!(e.to_string().contains("none-*.png"), "{e}");
        let e = matching(dir.path(), "nowhere/*.png").unwrap_err();
        assert!(e.to_string().contains("does not exist"), "{e}");
    }
}
