//! Warnings about input that is valid but probably not what the user meant: image
//! file names of one camera that look like several cameras, a `[reference]` set
//! that is the training data, and frames whose corner numbering looks turned by
//! 180° against the others. Each check returns sentences; printing and recording
//! them is the caller's job.
use crate::model::dataset::Dataset;
use crate::solver::calibrate::Calibration;
use std::collections::{BTreeMap, BTreeSet, HashSet};

/// The image file of each (camera index, frame number) where the data came from
/// files (photos, corners.vnl); empty otherwise.
pub type FrameFiles = BTreeMap<(usize, i64), String>;

/// A frame for messages: `frame 7`, with its image files when known
/// (`frame 7 (left07.jpg)`).
pub fn frame_label(dataset: &Dataset, files: &FrameFiles, frame: usize) -> String {
    let id = dataset.frame_ids[frame];
    let names: Vec<&str> = (0..dataset.cameras.len())
        .filter_map(|k| files.get(&(k, id)).map(String::as_str))
        .collect();
    if names.is_empty() {
        format!("frame {id}")
    } else {
        format!("frame {id} ({})", names.join(", "))
    }
}

/// A file name's template, its last run of digits (before the extension) replaced
/// by `*`, and the number that run holds: `photos/left07.jpg` → (`photos/left*.jpg`, 7).
fn template(name: &str) -> Option<(String, u64)> {
    let dir_end = name.rfind('/').map_or(0, |i| i + 1);
    let stem_end = name[dir_end..]
        .rfind('.')
        .map_or(name.len(), |i| dir_end + i);
    let stem = &name[..stem_end];
    let end = stem.rfind(|c: char| c.is_ascii_digit())? + 1;
    let start = stem[..end]
        .rfind(|c: char| !c.is_ascii_digit())
        .map_or(0, |i| i + 1);
    let number = stem[start..end].parse().ok()?;
    Some((format!("{}*{}", &name[..start], &name[end..]), number))
}

/// How the files of one camera group by template, largest group first.
fn groups<'a>(names: impl Iterator<Item = &'a str>) -> Vec<(String, BTreeSet<u64>, usize)> {
    let mut by: BTreeMap<String, (BTreeSet<u64>, usize)> = BTreeMap::new();
    for (t, n) in names.filter_map(template) {
        let e = by.entry(t).or_default();
        e.0.insert(n);
        e.1 += 1;
    }
    let mut list: Vec<_> = by.into_iter().map(|(t, (n, c))| (t, n, c)).collect();
    list.sort_by(|a, b| b.2.cmp(&a.2).then(a.0.cmp(&b.0)));
    list
}

/// Where the file names came from, for the fix the warning suggests.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NameSource {
    /// `[data] photos`: the fix is one pattern per camera.
    Photos,
    /// `[data] corners_vnl`: the fix is `camera_patterns`.
    CornersVnl,
}

/// A warning per camera whose image files fall into groups that look like several
/// cameras: two or more name templates (`left*.jpg`, `right*.jpg`; `cam0/*.png`,
/// `cam1/*.png`) of at least two files each that share most of their frame numbers,
/// as the views of one time step by different cameras do.
pub fn several_cameras(
    camera_names: &[String],
    files: &[(usize, String)],
    source: NameSource,
) -> Vec<String> {
    let mut out = Vec::new();
    for (k, name) in camera_names.iter().enumerate() {
        let list = groups(files.iter().filter(|f| f.0 == k).map(|f| f.1.as_str()));
        let big: Vec<_> = list.iter().filter(|g| g.2 >= 2).collect();
        if big.len() < 2 {
            continue;
        }
        let shared = big[0].1.intersection(&big[1].1).count();
        if shared < 2 || 2 * shared < big[1].1.len() {
            continue;
        }
        let shown: Vec<_> = big.iter().take(3).collect();
        let described: Vec<String> = shown
            .iter()
            .map(|g| format!("`{}` ({} files)", g.0, g.2))
            .collect();
        let mut names: Vec<String> = vec![name.clone()];
        for i in 1..shown.len() {
            let mut n = i;
            while camera_names.contains(&format!("cam{n}")) || names.contains(&format!("cam{n}")) {
                n += 1;
            }
            names.push(format!("cam{n}"));
        }
        let table: Vec<String> = shown
            .iter()
            .zip(&names)
            .map(|(g, n)| format!("{n} = \"{}\"", g.0))
            .collect();
        let key = match source {
            NameSource::Photos => "photos",
            NameSource::CornersVnl => "camera_patterns",
        };
        out.push(format!(
            "the images of camera `{name}` look like {} cameras: {} share {shared} frame numbers; \
             one model fitted to several cameras is wrong. If they are, list one [[cameras]] per camera and set \
             `{key} = {{ {} }}`",
            big.len(),
            described.join(" and "),
            table.join(", ")
        ));
    }
    out
}

/// A warning when every observation of the reference set is also one of the
/// training data: the test error then measures the fit to the training images.
pub fn reference_is_training(training: &Dataset, reference: &Dataset) -> Option<String> {
    let key = |d: &Dataset, o: &crate::model::dataset::Observation| {
        (
            d.cameras[o.camera].name.clone(),
            d.frame_ids[o.frame],
            o.corner,
            o.uv[0].to_bits(),
            o.uv[1].to_bits(),
        )
    };
    let train: HashSet<_> = training
        .observations
        .iter()
        .map(|o| key(training, o))
        .collect();
    let inside = reference
        .observations
        .iter()
        .all(|o| train.contains(&key(reference, o)));
    (inside && !reference.observations.is_empty()).then(|| {
        let what = if reference.observations.len() == training.observations.len() {
            "is the training data"
        } else {
            "is part of the training data"
        };
        format!(
            "[reference] {what} (all {} of its observations are training observations): \
             test_rmse_px and the mapping errors then measure the fit to the images calibrated on, \
             not to independent ones; give a separate static reference set",
            reference.observations.len()
        )
    })
}

/// The board's in-plane rotation in frame j as camera 0 sees it: the angle of the
/// board's x axis (along increasing col) in the image plane, radians.
fn in_plane_angle(c: &Calibration, j: usize) -> f64 {
    let x = c.state.frame_poses[j].rotation_matrix() * nalgebra::Vector3::x();
    x.y.atan2(x.x)
}

/// Frames whose board is turned by 180° in its plane against the rest (all others
/// within 45° of one direction, these within 45° of the opposite one): a detector
/// that numbers the corners from the other end in some images gives exactly this,
/// since every rows × cols grid maps onto itself under that turn.
pub fn flipped_frames(c: &Calibration, files: &FrameFiles) -> Option<String> {
    let n = c.dataset.num_frames();
    let angles: Vec<f64> = (0..n).map(|j| in_plane_angle(c, j)).collect();
    // The doubled angle is blind to the flip: its mean is the common axis.
    let (s, co) = angles.iter().fold((0.0, 0.0), |(s, c), a| {
        (s + (2.0 * a).sin(), c + (2.0 * a).cos())
    });
    let axis = s.atan2(co) / 2.0;
    let off: Vec<f64> = angles
        .iter()
        .map(|a| {
            let d = (a - axis).rem_euclid(std::f64::consts::TAU);
            d.min(std::f64::consts::TAU - d).to_degrees()
        })
        .collect();
    if off.iter().any(|d| (45.0..=135.0).contains(d)) {
        return None;
    }
    let flipped: Vec<usize> = (0..n).filter(|&j| off[j] > 135.0).collect();
    let minority: Vec<usize> = if 2 * flipped.len() <= n {
        flipped
    } else {
        (0..n).filter(|&j| off[j] < 45.0).collect()
    };
    let others = n - minority.len();
    if minority.is_empty() || others < 3 {
        return None;
    }
    let names: Vec<String> = minority
        .iter()
        .take(5)
        .map(|&j| frame_label(&c.dataset, files, j))
        .collect();
    let more = match minority.len() {
        m if m > 5 => format!(" and {} more", m - 5),
        _ => String::new(),
    };
    Some(format!(
        "{}{more} show the board turned by about 180° in its plane against the other {} frames: \
         either it was held upside down there, or the corners were numbered from the other end \
         of the board; that matters for `static` and `full` (their corrections belong to corners) \
         and with several cameras: check the corner order in those images",
        names.join(", "),
        others
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn templates_replace_the_last_number() {
        assert_eq!(
            template("photos/left07.jpg"),
            Some(("photos/left*.jpg".into(), 7))
        );
        assert_eq!(
            template("cam1/000123.png"),
            Some(("cam1/*.png".into(), 123))
        );
        assert_eq!(template("img_l_12"), Some(("img_l_*".into(), 12)));
        assert_eq!(template("notes.txt"), None);
    }

    #[test]
    fn left_and_right_in_one_camera_warn_once() {
        let files: Vec<(usize, String)> = (1..=5)
            .flat_map(|i| [format!("left{i:02}.jpg"), format!("right{i:02}.jpg")])
            .map(|n| (0, n))
            .collect();
        let w = several_cameras(&["cam0".into()], &files, NameSource::Photos);
        assert_eq!(w.len(), 1);
        assert!(
            w[0].contains("photos = { cam0 = \"left*.jpg\", cam1 = \"right*.jpg\" }"),
            "{}",
            w[0]
        );
        let one: Vec<(usize, String)> = (1..=9).map(|i| (0, format!("left{i:02}.jpg"))).collect();
        assert!(several_cameras(&["cam0".into()], &one, NameSource::Photos).is_empty());
    }
}
