//! A video in (docs/video.md): from `[data] video` to a dataset. Streams every
//! `stride`-th frame out of `ffmpeg`, measures its sharpness and detects the
//! board in it (a few frames at a time, in parallel, with a progress bar; frames
//! detected before come from the detection cache), then chooses the frames to
//! calibrate from (`choose`) and writes `detections.csv`, `observations.csv` and
//! the cache into the output dir. Frames keep the video's frame numbers, so they
//! stay in time order for `bend_smoothness`. The detector is `app::detect`'s.
pub mod choose;
pub mod ffmpeg;

pub use crate::app::config::VideoSource;
use crate::app::detect::{self, Detector, Rejection};
use crate::app::fsio::write_atomic;
use crate::app::observations_csv;
use crate::app::photos::cache::{self, Cache, Entry, Lookup, Outcome, Stamp};
use crate::app::photos::{self, DETECTIONS_CSV, MIN_IMAGES};
use crate::error::{Error, Result};
use crate::model::camera::CameraSpec;
use crate::model::dataset::{Dataset, DetectedCorner};
use crate::model::target::Target;
use choose::{Candidate, Verdict};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// One sampled frame and what became of it.
#[derive(Debug, Clone)]
pub struct FrameResult {
    /// Frame number in the video (display order, from 0): the dataset's frame id.
    pub index: usize,
    /// Presentation time, seconds.
    pub time: f64,
    /// Laplacian variance of the frame.
    pub sharpness: f64,
    /// The detection (or why there is none).
    pub outcome: Outcome,
    /// Taken from the cache rather than decoded and detected now.
    pub cached: bool,
    /// Chosen, or why not.
    pub verdict: Verdict,
}

/// Everything a video run produced.
#[derive(Debug, Clone)]
pub struct VideoRun {
    /// The video.
    pub source: VideoSource,
    /// Frames in the video.
    pub total_frames: usize,
    /// One per sampled frame, in time order.
    pub frames: Vec<FrameResult>,
    /// The observations of the kept frames.
    pub dataset: Dataset,
    /// Where `detections.csv`, `observations.csv` and the cache were written.
    pub output_dir: PathBuf,
}

impl VideoRun {
    /// The name a kept frame goes by in reports and warnings.
    pub fn frame_name(&self, f: &FrameResult) -> String {
        format!("{} frame {} ({:.3} s)", self.source.name, f.index, f.time)
    }
}

/// Decodes, detects and chooses the frames of `source` for the one `camera`,
/// writes the results into `output_dir` and returns them.
pub fn detect_video(
    source: &VideoSource,
    target: Target,
    charuco: Option<&detect::charuco::CharucoSpec>,
    camera: &CameraSpec,
    output_dir: &Path,
    progress: bool,
) -> Result<VideoRun> {
    let probe = ffmpeg::probe(&source.path)?;
    if (probe.width, probe.height) != (camera.width, camera.height) {
        return Err(Error::Video {
            path: source.path.clone(),
            message: format!(
                "its frames are {}x{}{} but camera `{}` is {}x{}",
                probe.width,
                probe.height,
                match probe.turned {
                    0 => String::new(),
                    t => format!(" (turned by {t}° as its rotation metadata says)"),
                },
                camera.name,
                camera.width,
                camera.height
            ),
        });
    }
    let detector = Detector {
        charuco: charuco.cloned(),
        ..Detector::default()
    };
    // "upright": frames have been turned by the rotation metadata since this key;
    // a cache of frames as stored is not reused.
    let settings = format!("{}; video upright", photos::settings_key(&detector, target));
    let cache = Cache::load(output_dir, &settings);
    let stamp = std::fs::metadata(&source.path)
        .map(|m| cache::stamp_of(&m))
        .map_err(|e| Error::io(&source.path, e))?;
    let sampled: Vec<usize> = (0..probe.times.len()).step_by(source.stride).collect();
    let scan = Scan {
        source,
        detector: &detector,
        target,
        cache: &cache,
        stamp,
        hash: OnceLock::new(),
    };
    let mut frames = scan.all_cached(&sampled, &probe.times);
    if frames.is_none() {
        frames = Some(scan.decode(&probe, sampled.len(), progress)?);
    }
    let mut frames = frames.expect("set above");
    let stamp = scan.full_stamp();
    let verdicts = choose::choose(
        &frames.iter().map(candidate).collect::<Vec<_>>(),
        target.cols,
        probe.width,
        probe.height,
        source.max_frames,
    );
    for (f, v) in frames.iter_mut().zip(verdicts) {
        f.verdict = v;
    }
    let run = VideoRun {
        source: source.clone(),
        total_frames: probe.times.len(),
        dataset: dataset_of(&frames, target, camera),
        frames,
        output_dir: output_dir.to_path_buf(),
    };
    check_usable(&run, target)?;
    write_outputs(&run, stamp, &settings, camera)?;
    Ok(run)
}

/// What one pass over the video needs.
struct Scan<'a> {
    source: &'a VideoSource,
    detector: &'a Detector,
    target: Target,
    cache: &'a Cache,
    stamp: Stamp,
    /// The video's content hash, computed once when the cache needs it.
    hash: OnceLock<u64>,
}

impl Scan<'_> {
    /// The cache's name of frame `index`.
    fn key(&self, index: usize) -> String {
        format!("{}#{index}", self.source.name)
    }

    fn hash(&self) -> u64 {
        *self.hash.get_or_init(|| hash_file(&self.source.path))
    }

    /// The video's stamp with its hash when it was computed.
    fn full_stamp(&self) -> Stamp {
        Stamp {
            hash: self.hash.get().copied().unwrap_or(0),
            ..self.stamp
        }
    }

    /// The cached entry of frame `index` when the video is unchanged.
    fn cached(&self, index: usize) -> Option<Entry> {
        match self
            .cache
            .lookup(&self.key(index), self.stamp, || self.hash())
        {
            Lookup::Hit(e) if e.sharpness.is_some() => Some(e),
            _ => None,
        }
    }

    /// Every sampled frame from the cache, or None when one is missing (the
    /// video is then decoded).
    fn all_cached(&self, sampled: &[usize], times: &[f64]) -> Option<Vec<FrameResult>> {
        sampled
            .iter()
            .map(|&index| {
                let e = self.cached(index)?;
                Some(FrameResult {
                    index,
                    time: times[index],
                    sharpness: e.sharpness.unwrap_or(0.0),
                    outcome: e.outcome,
                    cached: true,
                    verdict: Verdict::NoBoard,
                })
            })
            .collect()
    }

    /// Decodes the sampled frames, a batch at a time, detecting the board in
    /// those the cache does not hold.
    fn decode(
        &self,
        probe: &ffmpeg::Probe,
        count: usize,
        progress: bool,
    ) -> Result<Vec<FrameResult>> {
        let bar = progress_bar(count, progress);
        let mut frames = ffmpeg::Frames::start(&self.source.path, probe, self.source.stride)?;
        let batch = 2 * rayon::current_num_threads().max(1);
        let mut out = Vec::with_capacity(count);
        loop {
            let mut decoded = Vec::with_capacity(batch);
            while decoded.len() < batch {
                match frames.next_frame()? {
                    Some(f) => {
                        let hit = self.cached(f.index);
                        decoded.push((f, hit));
                    }
                    None => break,
                }
            }
            if decoded.is_empty() {
                break;
            }
            let done: Vec<FrameResult> = decoded
                .into_par_iter()
                .map(|(f, hit)| {
                    let r = self.one(f, hit, probe);
                    bar.inc(1);
                    r
                })
                .collect();
            out.extend(done);
        }
        frames.finish()?;
        bar.finish_and_clear();
        Ok(out)
    }

    /// One decoded frame: its sharpness, and its detection from the cache or now.
    fn one(&self, f: ffmpeg::Frame, hit: Option<Entry>, probe: &ffmpeg::Probe) -> FrameResult {
        let time = probe.times.get(f.index).copied().unwrap_or(0.0);
        if let Some(e) = hit {
            return FrameResult {
                index: f.index,
                time,
                sharpness: e.sharpness.unwrap_or(0.0),
                outcome: e.outcome,
                cached: true,
                verdict: Verdict::NoBoard,
            };
        }
        let sharpness = choose::sharpness(&f.image);
        let (w, h) = (f.image.width(), f.image.height());
        let img = image::DynamicImage::ImageLuma8(f.image);
        let target = self.target;
        let det = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            self.detector.detect_image(&img, target.rows, target.cols)
        }))
        .unwrap_or_else(|_| Err(Rejection::Internal("panic while detecting".into())));
        FrameResult {
            index: f.index,
            time,
            sharpness,
            outcome: photos::outcome_of(det, w, h),
            cached: false,
            verdict: Verdict::NoBoard,
        }
    }
}

fn progress_bar(count: usize, progress: bool) -> indicatif::ProgressBar {
    let bar = if progress {
        indicatif::ProgressBar::new(count as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "video: detecting [{bar:40}] {pos}/{len} frames, {elapsed} elapsed, ETA {eta}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar
}

/// FNV-1a of a file read in pieces (a video may not fit in memory); 0 when it
/// cannot be read (then no cache entry matches).
fn hash_file(path: &Path) -> u64 {
    use std::io::Read;
    let Ok(mut f) = std::fs::File::open(path) else {
        return 0;
    };
    let mut buf = vec![0u8; 1 << 20];
    let mut h = cache::FNV_START;
    loop {
        match f.read(&mut buf) {
            Ok(0) => return h,
            Ok(n) => h = cache::fnv1a_extend(h, &buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(_) => return 0,
        }
    }
}

fn candidate(f: &FrameResult) -> Candidate {
    Candidate {
        index: f.index,
        sharpness: f.sharpness,
        usable: f.outcome.status.usable(),
        corners: f
            .outcome
            .corners
            .iter()
            .map(|c| [c.index as f64, c.uv[0], c.uv[1]])
            .collect(),
    }
}

/// The observations of the kept frames, by video frame number, each corner with
/// the weight the detector gave it.
fn dataset_of(frames: &[FrameResult], target: Target, camera: &CameraSpec) -> Dataset {
    let kept = frames.iter().filter(|f| f.verdict == Verdict::Kept);
    let corners = kept.flat_map(|f| {
        f.outcome.corners.iter().map(|c| DetectedCorner {
            camera: 0,
            frame_id: f.index as i64,
            corner: c.index,
            uv: c.uv,
            weight: c.weight,
        })
    });
    Dataset::from_detected(target, vec![camera.clone()], corners)
}

/// A calibration needs [`MIN_IMAGES`] kept frames; otherwise one error with the counts.
fn check_usable(run: &VideoRun, target: Target) -> Result<()> {
    let count = |p: &dyn Fn(&Verdict) -> bool| run.frames.iter().filter(|f| p(&f.verdict)).count();
    let kept = count(&|v| *v == Verdict::Kept);
    if kept >= MIN_IMAGES {
        return Ok(());
    }
    Err(Error::Video {
        path: run.source.path.clone(),
        message: format!(
            "a {} × {} board was found in {} of {} sampled frames ({} blurred); a calibration needs {MIN_IMAGES}",
            target.rows,
            target.cols,
            kept,
            run.frames.len(),
            count(&|v| matches!(v, Verdict::Blurred(_)))
        ),
    })
}

/// `detections.csv`, `observations.csv` and the cache (every sampled frame, so a
/// rerun with another `max_frames` decodes nothing).
fn write_outputs(run: &VideoRun, stamp: Stamp, settings: &str, camera: &CameraSpec) -> Result<()> {
    let dir = &run.output_dir;
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_atomic(
        &dir.join(DETECTIONS_CSV),
        detections_csv(run, camera).as_bytes(),
    )?;
    observations_csv::write(&run.dataset, &dir.join("observations.csv"))?;
    let cache = Cache {
        version: cache::VERSION,
        settings: settings.to_string(),
        images: run
            .frames
            .iter()
            .map(|f| {
                let entry = Entry {
                    stamp,
                    outcome: f.outcome.clone(),
                    sharpness: Some(f.sharpness),
                };
                (format!("{}#{}", run.source.name, f.index), entry)
            })
            .collect(),
    };
    cache.save(dir)
}

/// `detections.csv` of a video (docs/video.md): one row per sampled frame with
/// its time; kept frames are `complete` or `partial`, usable frames not chosen
/// are `skipped` with the reason.
pub fn detections_csv(run: &VideoRun, camera: &CameraSpec) -> String {
    let mut w = csv::Writer::from_writer(Vec::new());
    let _ = w.write_record([
        "file",
        "camera",
        "frame",
        "time_s",
        "sharpness",
        "corners",
        "status",
        "reason",
    ]);
    for f in &run.frames {
        let (status, reason) = match f.verdict {
            Verdict::Kept | Verdict::NoBoard => (f.outcome.status.name(), f.outcome.reason.clone()),
            Verdict::Blurred(r) => (
                "skipped",
                format!(
                    "motion blur: {:.0} % of the sharpness of the frames around it",
                    100.0 * r
                ),
            ),
            Verdict::Similar(k) => ("skipped", format!("too like frame {k}, kept")),
            Verdict::Surplus => (
                "skipped",
                format!("max_frames ({}) kept before it", run.source.max_frames),
            ),
        };
        let _ = w.write_record([
            run.source.name.as_str(),
            camera.name.as_str(),
            &f.index.to_string(),
            &format!("{:.6}", f.time),
            &format!("{:.1}", f.sharpness),
            &f.outcome.corners.len().to_string(),
            status,
            reason.as_str(),
        ]);
    }
    String::from_utf8(w.into_inner().expect("writing to memory")).expect("UTF-8 fields")
}

/// The lines a user reads after the frames were chosen.
pub fn summary(run: &VideoRun) -> Vec<String> {
    let count = |p: &dyn Fn(&FrameResult) -> bool| run.frames.iter().filter(|f| p(f)).count();
    vec![format!(
        "video {}: {} frames, {} sampled (every {}), board found in {}, {} blurred, {} kept (max_frames {}); {} reused from the cache; see {}",
        run.source.name,
        run.total_frames,
        run.frames.len(),
        run.source.stride,
        count(&|f| f.outcome.status.usable()),
        count(&|f| matches!(f.verdict, Verdict::Blurred(_))),
        count(&|f| f.verdict == Verdict::Kept),
        run.source.max_frames,
        count(&|f| f.cached),
        run.output_dir.join(DETECTIONS_CSV).display()
    )]
}
