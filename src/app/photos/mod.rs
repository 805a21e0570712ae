//! Photos in (docs/conventions.md §5 Photos): from `[data] photos` to a dataset. Lists the files,
//! detects the board in each in parallel (rayon) with a progress bar, reuses
//! unchanged images' detections from the cache, checks that enough images are
//! usable, and writes `detections.csv`, `observations.csv` and the cache into the
//! output dir. The detector itself is `app::detect`; this module decides nothing
//! about a single image beyond its size matching its camera.
pub mod cache;
pub mod list;

use crate::app::config::{DataSource, PhotoPatterns};
use crate::app::detect::{self, load, Detection, Detector, Rejection};
use crate::app::fsio::write_atomic;
use crate::app::observations_csv;
use crate::error::{Error, Result};
use crate::model::camera::CameraSpec;
use crate::model::dataset::{Dataset, DetectedCorner};
use crate::model::target::Target;
use cache::{Cache, Entry, Lookup, Outcome, Status};
use list::ImageFile;
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Fewest usable images per camera: Zhang's initialisation needs three views.
pub const MIN_IMAGES: usize = 3;

/// The file in the output dir with one row per image.
pub const DETECTIONS_CSV: &str = "detections.csv";

/// One image and what detection made of it.
#[derive(Debug, Clone)]
pub struct ImageResult {
    /// The file and its place in the dataset.
    pub file: ImageFile,
    /// The detection (or why there is none).
    pub outcome: Outcome,
    /// Taken from the cache rather than detected now.
    pub cached: bool,
}

/// Everything a photo run produced.
#[derive(Debug, Clone)]
pub struct PhotoRun {
    /// One per image, by camera and frame.
    pub images: Vec<ImageResult>,
    /// The observations of the usable images, weighted by corner quality.
    pub dataset: Dataset,
    /// Where `detections.csv`, `observations.csv` and the cache were written.
    pub output_dir: PathBuf,
}

impl PhotoRun {
    /// How many usable views were labelled by the board's symmetry.
    pub fn labelled_by_symmetry(&self) -> usize {
        let usable = self.images.iter().filter(|r| r.outcome.status.usable());
        usable.filter(|r| r.outcome.by_symmetry).count()
    }
}

/// Detects the board in the photos of a `DataSource::Photos`, writes the results
/// into `output_dir` and returns them; `progress` draws a bar on stderr.
pub fn detect_photos(
    source: &DataSource,
    target: Target,
    charuco: Option<&detect::charuco::CharucoSpec>,
    cameras: &[CameraSpec],
    output_dir: &Path,
    progress: bool,
) -> Result<PhotoRun> {
    let DataSource::Photos { base, patterns } = source else {
        return Err(Error::Invalid("not a photos data source".into()));
    };
    let files = list::list_photos(base, patterns, cameras)?;
    let detector = Detector {
        charuco: charuco.cloned(),
        ..Detector::default()
    };
    let settings = settings_key(&detector, target);
    let mut cache = Cache::load(output_dir, &settings);
    let detected = detect_all(&files, &detector, target, &cache, progress);
    // The cache keeps what the detector said, before any check against the config,
    // and only the current images, so it does not grow without bound.
    cache.images = detected
        .iter()
        .filter_map(|d| {
            let entry = Entry {
                stamp: d.stamp?,
                outcome: d.result.outcome.clone(),
                sharpness: None,
            };
            Some((d.result.file.name.clone(), entry))
        })
        .collect();
    let images: Vec<ImageResult> = detected
        .into_iter()
        .map(|d| check_camera_size(d.result, cameras))
        .collect();
    check_usable(&images, patterns, target, cameras)?;
    let dataset = dataset_of(&images, target, cameras);
    std::fs::create_dir_all(output_dir).map_err(|e| Error::io(output_dir, e))?;
    write_atomic(
        &output_dir.join(DETECTIONS_CSV),
        detections_csv(&images, cameras).as_bytes(),
    )?;
    observations_csv::write(&dataset, &output_dir.join("observations.csv"))?;
    cache.save(output_dir)?;
    Ok(PhotoRun {
        images,
        dataset,
        output_dir: output_dir.to_path_buf(),
    })
}

/// An image result with the file stamp the cache needs (None: file not readable).
struct Detected {
    result: ImageResult,
    stamp: Option<cache::Stamp>,
}

/// The detector version, its settings and the board: a cache made with other
/// values is not used.
pub(crate) fn settings_key(d: &Detector, target: Target) -> String {
    format!(
        "{}; rows {} cols {}; max_pixels {} min_corners {}{}",
        detect::ALGORITHM,
        target.rows,
        target.cols,
        d.max_pixels,
        d.min_corners,
        d.charuco
            .as_ref()
            .map(|c| format!("; charuco {c:?}"))
            .unwrap_or_default()
    )
}

/// Every file through the cache or the detector, in parallel, in input order.
fn detect_all(
    files: &[ImageFile],
    detector: &Detector,
    target: Target,
    cache: &Cache,
    progress: bool,
) -> Vec<Detected> {
    let bar = if progress {
        indicatif::ProgressBar::new(files.len() as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "detecting [{bar:40}] {pos}/{len} images, {elapsed} elapsed, ETA {eta}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    let out = files
        .par_iter()
        .map(|f| {
            let r = detect_one(f, detector, target, cache);
            bar.inc(1);
            r
        })
        .collect();
    bar.finish_and_clear();
    out
}

/// One file: from the cache when unchanged, else read, hash and detect. A panic
/// anywhere in decoding or detection becomes a rejection of this image alone.
fn detect_one(file: &ImageFile, detector: &Detector, target: Target, cache: &Cache) -> Detected {
    let result = |outcome, cached| ImageResult {
        file: file.clone(),
        outcome,
        cached,
    };
    let meta = match std::fs::metadata(&file.path) {
        Ok(m) => m,
        Err(e) => {
            let r = Rejection::Unreadable(e.to_string());
            return Detected {
                result: result(outcome_of(Err(r), 0, 0), false),
                stamp: None,
            };
        }
    };
    let stamp = cache::stamp_of(&meta);
    let mut bytes: Option<std::result::Result<Vec<u8>, Rejection>> = None;
    let lookup = cache.lookup(&file.name, stamp, || {
        let read = load::read_file(&file.path);
        let h = read.as_ref().map_or(0, |b| cache::fnv1a(b));
        bytes = Some(read);
        h
    });
    let hash = match lookup {
        Lookup::Hit(entry) => {
            return Detected {
                result: result(entry.outcome, true),
                stamp: Some(entry.stamp),
            }
        }
        Lookup::Miss(hash) => hash,
    };
    let bytes = bytes.unwrap_or_else(|| load::read_file(&file.path));
    let hash = hash.unwrap_or_else(|| bytes.as_ref().map_or(0, |b| cache::fnv1a(b)));
    let run = || -> (std::result::Result<Detection, Rejection>, u32, u32) {
        let img = match bytes
            .as_deref()
            .map_err(Clone::clone)
            .and_then(|b| load::load_bytes(b, detector.max_pixels))
        {
            Ok(img) => img,
            Err(r) => return (Err(r), 0, 0),
        };
        let (w, h) = (img.width(), img.height());
        (detector.detect_image(&img, target.rows, target.cols), w, h)
    };
    let (det, w, h) =
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(run)).unwrap_or_else(|_| {
            (
                Err(Rejection::Internal("panic while decoding".into())),
                0,
                0,
            )
        });
    Detected {
        result: result(outcome_of(det, w, h), false),
        stamp: Some(cache::Stamp { hash, ..stamp }),
    }
}

/// The cacheable outcome of one detection.
pub(crate) fn outcome_of(
    det: std::result::Result<Detection, Rejection>,
    width: u32,
    height: u32,
) -> Outcome {
    match det {
        Ok(d) => Outcome {
            width,
            height,
            status: if d.complete {
                Status::Complete
            } else {
                Status::Partial
            },
            reason: d.note().to_string(),
            corners: d.corners,
            by_symmetry: d.labelled_by_symmetry,
        },
        Err(r) => Outcome {
            width,
            height,
            status: match r {
                Rejection::Unreadable(_) | Rejection::TooLarge { .. } => Status::Unreadable,
                _ => Status::Rejected,
            },
            reason: r.to_string(),
            corners: Vec::new(),
            by_symmetry: false,
        },
    }
}

/// An image of another size than its camera's is rejected: its corners would be
/// in another pixel frame (a resized or a different camera's image).
fn check_camera_size(mut r: ImageResult, cameras: &[CameraSpec]) -> ImageResult {
    let o = &mut r.outcome;
    let cam = &cameras[r.file.camera];
    if o.status.usable() && (o.width, o.height) != (cam.width, cam.height) {
        o.reason = format!(
            "image is {}x{} but camera `{}` is {}x{}",
            o.width, o.height, cam.name, cam.width, cam.height
        );
        o.status = Status::Rejected;
        o.corners.clear();
    }
    r
}

/// Every camera needs [`MIN_IMAGES`] usable images; otherwise one error naming
/// its pattern, with a count of why the others were rejected.
fn check_usable(
    images: &[ImageResult],
    patterns: &PhotoPatterns,
    target: Target,
    cameras: &[CameraSpec],
) -> Result<()> {
    for (k, cam) in cameras.iter().enumerate() {
        let mine: Vec<&ImageResult> = images.iter().filter(|r| r.file.camera == k).collect();
        let usable = mine.iter().filter(|r| r.outcome.status.usable()).count();
        if usable >= MIN_IMAGES {
            continue;
        }
        let mut why: BTreeMap<String, usize> = BTreeMap::new();
        for r in mine.iter().filter(|r| !r.outcome.status.usable()) {
            *why.entry(short_reason(&r.outcome.reason)).or_default() += 1;
        }
        let why: Vec<String> = why.iter().map(|(r, n)| format!("{n} × {r}")).collect();
        let pattern = match patterns {
            PhotoPatterns::One(p) => p.clone(),
            PhotoPatterns::PerCamera(m) => m.get(&cam.name).cloned().unwrap_or_default(),
        };
        return Err(Error::Photos {
            pattern,
            message: format!(
                "a {} × {} board was found in {usable} of {} images of camera `{}`; a calibration needs {MIN_IMAGES} (rejected: {})",
                target.rows,
                target.cols,
                mine.len(),
                cam.name,
                why.join(", ")
            ),
        });
    }
    Ok(())
}

/// A rejection reason without the file-specific detail after the first colon, so
/// reasons can be counted.
fn short_reason(reason: &str) -> String {
    reason
        .split(':')
        .next()
        .unwrap_or(reason)
        .trim()
        .to_string()
}

/// The observations of the usable images, each corner with the weight the
/// detector gave it ([`detect::observation_weight`]), not recomputed here.
fn dataset_of(images: &[ImageResult], target: Target, cameras: &[CameraSpec]) -> Dataset {
    let usable = images.iter().filter(|r| r.outcome.status.usable());
    let corners = usable.flat_map(|r| {
        r.outcome.corners.iter().map(|c| DetectedCorner {
            camera: r.file.camera,
            frame_id: r.file.frame,
            corner: c.index,
            uv: c.uv,
            weight: c.weight,
        })
    });
    Dataset::from_detected(target, cameras.to_vec(), corners)
}

/// `detections.csv` (docs/conventions.md §5): file, camera, frame, corners, status, reason.
pub fn detections_csv(images: &[ImageResult], cameras: &[CameraSpec]) -> String {
    let mut w = csv::Writer::from_writer(Vec::new());
    let _ = w.write_record(["file", "camera", "frame", "corners", "status", "reason"]);
    for r in images {
        let _ = w.write_record([
            r.file.name.as_str(),
            cameras[r.file.camera].name.as_str(),
            &r.file.frame.to_string(),
            &r.outcome.corners.len().to_string(),
            r.outcome.status.name(),
            r.outcome.reason.as_str(),
        ]);
    }
    String::from_utf8(w.into_inner().expect("writing to memory")).expect("UTF-8 fields")
}

/// What a user should read after detection: one warning per file that is not a
/// readable image (those are mistakes in the folder, not bad photos) and a summary.
pub fn summary(run: &PhotoRun) -> Vec<String> {
    let mut lines: Vec<String> = run
        .images
        .iter()
        .filter(|r| r.outcome.status == Status::Unreadable)
        .map(|r| format!("warning: skipped {}: {}", r.file.name, r.outcome.reason))
        .collect();
    let count = |s: Status| run.images.iter().filter(|r| r.outcome.status == s).count();
    let cached = run.images.iter().filter(|r| r.cached).count();
    lines.push(format!(
        "board found in {} of {} images ({} complete, {} partial; {} rejected, {} unreadable; {} reused from the cache); see {}",
        count(Status::Complete) + count(Status::Partial),
        run.images.len(),
        count(Status::Complete),
        count(Status::Partial),
        count(Status::Rejected),
        count(Status::Unreadable),
        cached,
        run.output_dir.join(DETECTIONS_CSV).display()
    ));
    lines
}
