//! The held-out stereo figures of tests/real_stereo.rs over more splits: every
//! method and `auto` under `radial3` and `opencv5`, and OpenCV's stereoCalibrate
//! where /usr/bin/python3 has cv2 (docs/real-photos.md).
//!
//! `cargo bench --bench stereo_photos` runs OpenCV's sample pairs. Another stereo
//! set with the same layout (left*.jpg and right*.jpg in one folder, the wildcard
//! naming the pair) runs with
//! `DEFORMCAL_STEREO_PHOTOS=folder DEFORMCAL_STEREO_BOARD=rows,cols,spacing_m`;
//! `DEFORMCAL_STEREO_SPLITS` sets the number of splits (default 21).
#[path = "../tests/common/sample_photos.rs"]
mod sample_photos;
#[path = "../tests/common/stereo_split.rs"]
mod stereo_split;

use deformcal::Target;
use std::path::PathBuf;
use std::time::Instant;
use stereo_split::*;

const DEFAULT_SPLITS: usize = 21;

/// The photos, board and number of splits the environment asks for.
fn setup() -> Result<(PathBuf, Target, usize), String> {
    let folder = match std::env::var_os("DEFORMCAL_STEREO_PHOTOS") {
        Some(f) => PathBuf::from(f),
        None => sample_photos::sample_photos()
            .map_err(|e| format!("cannot fetch opencv-doc's sample photos: {e}"))?,
    };
    let board = std::env::var("DEFORMCAL_STEREO_BOARD").unwrap_or_else(|_| "6,9,0.025".into());
    let parts: Vec<&str> = board.split(',').collect();
    let bad = || {
        format!(
            "DEFORMCAL_STEREO_BOARD: expected rows,cols,spacing_m (e.g. 6,9,0.025), got `{board}`"
        )
    };
    let [rows, cols, spacing] = parts.as_slice() else {
        return Err(bad());
    };
    let target = Target {
        rows: rows.trim().parse().map_err(|_| bad())?,
        cols: cols.trim().parse().map_err(|_| bad())?,
        spacing: spacing.trim().parse().map_err(|_| bad())?,
    };
    if target.rows < 2 || target.cols < 2 || !target.spacing.is_finite() || target.spacing <= 0.0 {
        return Err(bad());
    }
    let splits = match std::env::var("DEFORMCAL_STEREO_SPLITS") {
        Ok(s) => s
            .trim()
            .parse::<usize>()
            .ok()
            .filter(|n| *n >= 2)
            .ok_or_else(|| {
                format!("DEFORMCAL_STEREO_SPLITS: expected a count of at least 2, got `{s}`")
            })?,
        Err(_) => DEFAULT_SPLITS,
    };
    Ok((folder, target, splits))
}

fn main() {
    let (folder, target, count) = setup().unwrap_or_else(|e| {
        eprintln!("error: {e}");
        std::process::exit(1);
    });
    let work = tempfile::tempdir().expect("a temporary folder");
    let data = load(&folder, target, work.path()).unwrap_or_else(|e| {
        eprintln!("error: {e}");
        std::process::exit(1);
    });
    let start = Instant::now();
    let splits = splits(data.num_frames(), count);
    let mut outcomes = run(&data, &splits);
    let ours = start.elapsed().as_secs_f64();
    if have_opencv() {
        outcomes.extend(run_opencv(&data, &splits));
    } else {
        eprintln!("no OpenCV row: {PYTHON} cannot import cv2 (apt-get install python3-opencv)");
    }
    println!(
        "{}: {} frame pairs, {count} splits into {} training and {} held-out pairs, {} rayon thread(s), {ours:.1} s\n",
        folder.display(),
        data.num_frames(),
        splits[0].0.len(),
        splits[0].1.len(),
        rayon::current_num_threads()
    );
    println!("{}", table(&rows(&outcomes), count));
}
