//! Initialisation: the views that have a homography, Zhang's closed form (or
//! the fisheye focal search) per camera, the rig and one board pose per frame,
//! with a warning or an error for every view or camera the data cannot start.
use crate::error::{Error, Result};
use crate::model::dataset::Dataset;
use crate::model::lens::Intrinsics;
use crate::model::pose::Pose;
use crate::model::{fisheye_init, zhang};
use crate::solver::problem::State;
use nalgebra::{Matrix3, Vector2};
use std::collections::HashMap;

/// Fewest corners an image needs to enter the calibration (a homography needs four).
pub const MIN_CORNERS_PER_IMAGE: usize = 4;
/// Fewest images a calibration accepts.
pub const MIN_IMAGES: usize = 3;

/// A view: what one camera saw in one frame.
type View = (usize, usize);
/// Board points and pixels of one view.
type Correspondences = (Vec<Vector2<f64>>, Vec<Vector2<f64>>);

/// Board-to-pixel homography of every view, `None` for a degenerate one.
fn homographies(dataset: &Dataset) -> HashMap<View, Option<Matrix3<f64>>> {
    let mut points: HashMap<View, Correspondences> = HashMap::new();
    for o in &dataset.observations {
        let p = dataset.target.nominal(o.corner);
        let e = points.entry((o.camera, o.frame)).or_default();
        e.0.push(Vector2::new(p.x, p.y));
        e.1.push(Vector2::new(o.uv[0], o.uv[1]));
    }
    points
        .into_iter()
        .map(|(view, (b, i))| {
            let h = (b.len() >= MIN_CORNERS_PER_IMAGE)
                .then(|| zhang::homography(&b, &i))
                .flatten();
            (view, h)
        })
        .collect()
}

/// Keeps the views that have a homography (enough corners, not collinear), with a
/// warning for each one dropped, and the frames that keep at least one view.
fn usable_views(
    dataset: &Dataset,
    warnings: &mut Vec<String>,
) -> (Dataset, HashMap<View, Matrix3<f64>>) {
    let hs = homographies(dataset);
    let mut counts: HashMap<View, usize> = HashMap::new();
    for o in &dataset.observations {
        *counts.entry((o.camera, o.frame)).or_default() += 1;
    }
    let mut dropped: Vec<View> = hs
        .iter()
        .filter(|(_, h)| h.is_none())
        .map(|(v, _)| *v)
        .collect();
    dropped.sort_unstable_by_key(|&(c, f)| (f, c));
    for v in &dropped {
        let n = counts[v];
        warnings.push(if n < MIN_CORNERS_PER_IMAGE {
            format!(
                "{} skipped: {n} corner(s), at least {MIN_CORNERS_PER_IMAGE} needed",
                dataset.view_name(v.0, v.1)
            )
        } else {
            format!(
                "{} skipped: its corners are collinear or degenerate",
                dataset.view_name(v.0, v.1)
            )
        });
    }
    let mut kept = dataset.clone();
    kept.observations
        .retain(|o| hs[&(o.camera, o.frame)].is_some());
    let frames: Vec<usize> = (0..dataset.num_frames())
        .filter(|&j| (0..dataset.cameras.len()).any(|k| matches!(hs.get(&(k, j)), Some(Some(_)))))
        .collect();
    let remap: HashMap<usize, usize> = frames
        .iter()
        .enumerate()
        .map(|(new, &old)| (old, new))
        .collect();
    let hs = hs
        .into_iter()
        .filter_map(|((k, j), h)| Some(((k, *remap.get(&j)?), h?)))
        .collect();
    (kept.subset(&frames), hs)
}

/// Views whose board normals scatter less than this (RMS angle to their mean)
/// cannot determine a focal length (Zhang's degenerate case); detector noise alone
/// scatters the normals of parallel boards by about a degree.
const MIN_ORIENTATION_SPREAD_DEG: f64 = 3.0;

/// Refuses a camera whose views all show the board at the same orientation (for
/// instance all parallel to the image plane): the focal length is then unobservable.
fn check_orientations<'a>(camera: &str, poses: impl Iterator<Item = &'a Pose>) -> Result<()> {
    let normals: Vec<nalgebra::Vector3<f64>> = poses
        .map(|p| p.rotation_matrix() * nalgebra::Vector3::z())
        .collect();
    let mean = normals.iter().sum::<nalgebra::Vector3<f64>>().normalize();
    let spread = (normals
        .iter()
        .map(|n| n.angle(&mean).to_degrees().powi(2))
        .sum::<f64>()
        / normals.len() as f64)
        .sqrt();
    if spread < MIN_ORIENTATION_SPREAD_DEG {
        let tilt = mean.angle(&nalgebra::Vector3::z()).to_degrees();
        return Err(Error::Degenerate(format!(
            "all {} views of {camera} show the board at nearly the same orientation (RMS spread {spread:.2}°, {tilt:.1}° from fronto-parallel): \
             the focal length cannot be determined; tilt the board in different directions",
            normals.len()
        )));
    }
    Ok(())
}

/// Fraction of a 10 × 10 grid over the image that observations touch, below which
/// the distortion is mostly extrapolated.
const MIN_COVERAGE: f64 = 0.25;

/// Warns about cameras whose observations cover little of the image.
pub(super) fn coverage_warnings(dataset: &Dataset, warnings: &mut Vec<String>) {
    for (k, cam) in dataset.cameras.iter().enumerate() {
        let mut cells = [[false; 10]; 10];
        for o in dataset.observations.iter().filter(|o| o.camera == k) {
            let i = ((o.uv[0] / cam.width as f64) * 10.0).clamp(0.0, 9.0) as usize;
            let j = ((o.uv[1] / cam.height as f64) * 10.0).clamp(0.0, 9.0) as usize;
            cells[j][i] = true;
        }
        let covered = cells.iter().flatten().filter(|&&c| c).count() as f64 / 100.0;
        if covered < MIN_COVERAGE {
            warnings.push(format!(
                "the observations of {} cover only {:.0}% of the image: the lens distortion away from them is extrapolated; show the board in all parts of the image",
                cam.name,
                covered * 100.0
            ));
        }
    }
}

/// A camera's views with a homography, refused when fewer than a calibration needs.
fn own_views(
    dataset: &Dataset,
    hs: &HashMap<View, Matrix3<f64>>,
    k: usize,
) -> Result<Vec<(usize, Matrix3<f64>)>> {
    let own: Vec<(usize, Matrix3<f64>)> = (0..dataset.num_frames())
        .filter_map(|j| hs.get(&(k, j)).map(|h| (j, *h)))
        .collect();
    if own.len() < MIN_IMAGES {
        let what = format!(
            "{} usable image(s); a calibration needs at least {MIN_IMAGES}",
            own.len()
        );
        return Err(Error::Degenerate(if dataset.cameras.len() == 1 {
            what
        } else {
            format!("camera {}: {what}", dataset.cameras[k].name)
        }));
    }
    Ok(own)
}

/// What was dropped before too few images were left, for the error that says so:
/// the warnings so far are the drops (outside the image, inconsistent or
/// degenerate views), and the error is all the user sees of a failed run. The
/// first few, cut short, and a count of the rest.
fn dropped_reasons(warnings: &[String]) -> String {
    // Kept short so the whole error stays one readable line.
    const SHOWN: usize = 4;
    const CHARS: usize = 80;
    if warnings.is_empty() {
        return String::new();
    }
    let mut list: Vec<String> = warnings
        .iter()
        .take(SHOWN)
        .map(|w| {
            if w.chars().count() > CHARS {
                format!("{}…", w.chars().take(CHARS).collect::<String>())
            } else {
                w.clone()
            }
        })
        .collect();
    if warnings.len() > SHOWN {
        list.push(format!("{} more", warnings.len() - SHOWN));
    }
    format!(" (dropped: {})", list.join("; "))
}

/// A camera's initial intrinsics, board pose per frame, and whether Zhang fell back.
type CameraInit = (Intrinsics, Vec<Option<Pose>>, bool);

/// Initialises a fisheye camera by a focal-length search: Zhang assumes a pinhole.
fn init_fisheye(dataset: &Dataset, k: usize, own: &[(usize, Matrix3<f64>)]) -> Result<CameraInit> {
    let cam = &dataset.cameras[k];
    let frames: Vec<usize> = own.iter().map(|(j, _)| *j).collect();
    let template = Intrinsics::pinhole_of(cam.model, 1.0, 1.0, 0.0, 0.0);
    let points = fisheye_init::views_of(dataset, k, &frames);
    let (kk, poses) = fisheye_init::initialise(&template, cam.width, cam.height, &points)
        .ok_or_else(|| {
            Error::Init(format!(
                "{}: no focal length of the `{}` model explains the board views",
                cam.name, cam.model
            ))
        })?;
    let mut views = vec![None; dataset.num_frames()];
    for (j, pose) in frames.into_iter().zip(poses) {
        views[j] = pose;
    }
    check_orientations(&cam.name, views.iter().flatten())?;
    Ok((kk, views, false))
}

/// Corners spanning less than 1/this of both image sides tell of a declared
/// image size that is not the photos'.
const SMALL_SPAN_FRACTION: f64 = 20.0;

/// Why Zhang's closed form found no focal length for a camera's homographies.
fn no_focal_length(
    dataset: &Dataset,
    k: usize,
    list: &[Matrix3<f64>],
    e: impl std::fmt::Display,
) -> Error {
    let cam = &dataset.cameras[k];
    // A declared image far larger than the photos (a 100000-px width for
    // 2000-px photos) puts the nominal principal point far off the corners, and
    // no focal length fits: that is the mistake to name, not the perspective.
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for o in dataset.observations.iter().filter(|o| o.camera == k) {
        for a in 0..2 {
            lo[a] = lo[a].min(o.uv[a]);
            hi[a] = hi[a].max(o.uv[a]);
        }
    }
    let (span_u, span_v) = (hi[0] - lo[0], hi[1] - lo[1]);
    if span_u < cam.width as f64 / SMALL_SPAN_FRACTION
        && span_v < cam.height as f64 / SMALL_SPAN_FRACTION
    {
        return Error::Degenerate(format!(
            "no focal length fits the views of {}: its corners span only {span_u:.0} × {span_v:.0} px \
             of its declared {} × {} image; check the camera's width and height (the photos' size in pixels)",
            cam.name, cam.width, cam.height
        ));
    }
    // Explain the usual cause: seen through a nominal lens, every view has
    // the same orientation.
    let size = cam.width.max(cam.height) as f64;
    let nominal = Intrinsics::pinhole(size, size, cam.width as f64 / 2.0, cam.height as f64 / 2.0);
    let poses: Vec<Pose> = list
        .iter()
        .filter_map(|h| zhang::pose_from_homography(h, &nominal))
        .collect();
    if let Err(parallel) = check_orientations(&cam.name, poses.iter()) {
        return parallel;
    }
    // The views are not all parallel: say what else leaves no focal length.
    Error::Degenerate(format!(
        "no focal length fits the {} views of {}, though they are tilted: the board shows too little perspective \
         (too small or too far away) or its corner numbering is inconsistent ({e})",
        list.len(),
        cam.name
    ))
}

/// Initialises a pinhole-like camera by Zhang's closed form on its homographies.
fn init_zhang(
    dataset: &Dataset,
    k: usize,
    own: &[(usize, Matrix3<f64>)],
    warnings: &mut Vec<String>,
) -> Result<CameraInit> {
    let cam = &dataset.cameras[k];
    let list: Vec<Matrix3<f64>> = own.iter().map(|(_, h)| *h).collect();
    let (kk, fallback) = zhang::initial_intrinsics(&list, cam.width, cam.height)
        .map_err(|e| no_focal_length(dataset, k, &list, e))?;
    if fallback {
        warnings.push(format!(
            "{}: Zhang's closed form was ill-conditioned; started from a centred principal point",
            cam.name
        ));
    }
    let mut views = vec![None; dataset.num_frames()];
    for &(j, h) in own {
        views[j] = Some(zhang::pose_from_homography(&h, &kk).ok_or_else(|| {
            Error::Init(format!(
                "{}: no board pose fits its homography",
                dataset.view_name(k, j)
            ))
        })?);
    }
    check_orientations(&cam.name, views.iter().flatten())?;
    // Zhang's pinhole, as the camera's model with no distortion.
    let pinhole = Intrinsics::pinhole_of(cam.model, kk.fx(), kk.fy(), kk.cx(), kk.cy());
    Ok((pinhole, views, fallback))
}

/// Π_j per frame, from the camera that sees most of the board, through the rig.
fn frame_poses(dataset: &Dataset, views: &[Vec<Option<Pose>>], rig: &[Pose]) -> Vec<Pose> {
    let cameras = dataset.cameras.len();
    let mut counts = vec![vec![0usize; dataset.num_frames()]; cameras];
    for o in &dataset.observations {
        counts[o.camera][o.frame] += 1;
    }
    (0..dataset.num_frames())
        .map(|j| {
            let k = (0..cameras)
                .filter(|&k| views[k][j].is_some())
                .max_by_key(|&k| (counts[k][j], std::cmp::Reverse(k)))
                .expect("every kept frame has a view");
            rig[k].inverse().compose(&views[k][j].expect("chosen"))
        })
        .collect()
}

/// Zhang's initialisation: intrinsics per camera, π_k from the views cameras share,
/// and one board pose per frame.
pub(super) fn initialise(
    dataset: &Dataset,
    warnings: &mut Vec<String>,
) -> Result<(Dataset, State, bool)> {
    let (dataset, hs) = usable_views(dataset, warnings);
    if dataset.num_frames() < MIN_IMAGES {
        return Err(Error::Degenerate(format!(
            "{} usable image(s); a calibration needs at least {MIN_IMAGES}{}",
            dataset.num_frames(),
            dropped_reasons(warnings)
        )));
    }
    let cameras = dataset.cameras.len();
    let mut intrinsics = Vec::with_capacity(cameras);
    let mut any_fallback = false;
    let mut views: Vec<Vec<Option<Pose>>> = Vec::with_capacity(cameras);
    for (k, cam) in dataset.cameras.iter().enumerate() {
        let own = own_views(&dataset, &hs, k).map_err(|e| match e {
            Error::Degenerate(m) => Error::Degenerate(m + &dropped_reasons(warnings)),
            e => e,
        })?;
        let (kk, poses, fallback) = if cam.model.info().pinhole_like {
            init_zhang(&dataset, k, &own, warnings)?
        } else {
            init_fisheye(&dataset, k, &own)?
        };
        any_fallback |= fallback;
        intrinsics.push(kk);
        views.push(poses);
    }
    let (dataset, views) = without_unposed_frames(dataset, views, warnings);
    if dataset.num_frames() < MIN_IMAGES {
        return Err(Error::Degenerate(format!(
            "{} image(s) with an initial board pose; a calibration needs at least {MIN_IMAGES}",
            dataset.num_frames()
        )));
    }
    let names: Vec<String> = dataset.cameras.iter().map(|c| c.name.clone()).collect();
    let rig = crate::model::rig::initial_rig(&views, &names)?;
    let poses = frame_poses(&dataset, &views, &rig);
    let state = State::rigid(intrinsics, rig, poses, &dataset.target);
    Ok((dataset, state, any_fallback))
}

/// The dataset without the frames that no camera has an initial pose of (a
/// fisheye view that no candidate focal length explains), each named in a warning.
fn without_unposed_frames(
    dataset: Dataset,
    views: Vec<Vec<Option<Pose>>>,
    warnings: &mut Vec<String>,
) -> (Dataset, Vec<Vec<Option<Pose>>>) {
    let posed = |j: usize| views.iter().any(|v| v[j].is_some());
    let kept: Vec<usize> = (0..dataset.num_frames()).filter(|&j| posed(j)).collect();
    if kept.len() == dataset.num_frames() {
        return (dataset, views);
    }
    for j in (0..dataset.num_frames()).filter(|&j| !posed(j)) {
        warnings.push(format!(
            "frame {} skipped: no initial board pose under the fisheye initialisation",
            dataset.frame_ids[j]
        ));
    }
    let views = views
        .iter()
        .map(|v| kept.iter().map(|&j| v[j]).collect())
        .collect();
    (dataset.subset(&kept), views)
}
