//! mrcal's `optimization_inputs`: a calibration restated as the arguments of
//! `mrcal.optimize()` at deformcal's solution, so that mrcal's uncertainty and diff
//! tools work on our models. Only where mrcal's problem is ours: a rigid board
//! (`standard`) and cameras of one lens model mrcal has. This module maps the
//! conventions; `npz` formats the bytes.
use super::npz::{b85encode, npz, Npy};
use crate::model::dataset::Dataset;
use crate::model::lens::LensModel;
use crate::model::pose::Pose;
use crate::solver::calibrate::Calibration;
use std::collections::BTreeMap;

/// What the `.cameramodel` files of one calibration say about its problem.
#[derive(Debug, Clone, PartialEq)]
pub enum OptimizationInputs {
    /// The problem, serialised as mrcal does (`np.savez_compressed`, base85), and
    /// a note where mrcal's problem frees parameters deformcal held.
    Carried { blob: String, note: Option<String> },
    /// Why the models carry none (one line, for a comment in the file).
    Absent(String),
}

/// Why `deformcal export` writes models without optimization inputs.
pub const NOT_IN_CALIBRATION_JSON: &str =
    "calibration.json holds no observations; the calibration run itself writes models with them";

/// One board observation in mrcal's layout: `(x, y, weight)` per corner in
/// row-major order (mrcal's `[row][col]`), weight < 0 for a corner not used.
type BoardView = Vec<[f64; 3]>;

/// mrcal's marker of a corner it must ignore (missing or an outlier).
const UNUSED: [f64; 3] = [-1.0, -1.0, -1.0];

/// The calibration's problem as mrcal's `optimization_inputs`, or why mrcal cannot
/// represent it.
pub fn optimization_inputs(c: &Calibration) -> OptimizationInputs {
    match serialise(c) {
        Ok(inputs) => inputs,
        Err(why) => OptimizationInputs::Absent(why),
    }
}

fn serialise(c: &Calibration) -> Result<OptimizationInputs, String> {
    if c.method.has_correction() || c.method.has_paraboloid() {
        return Err(format!(
            "mrcal's board is rigid up to its own two-parameter calobject_warp, and method `{}` {}",
            c.method,
            board_change(c.method)
        ));
    }
    let model = common_model(&c.dataset)?;
    if c.settings.lens_prior_on(&[model]) {
        let prior = model.info().prior_params.join(", ");
        return Err(format!(
            "our problem holds {prior} of `{model}` with a lens prior (lens_prior = {}), which mrcal's problem has no term for; lens_prior = \"none\" gives mrcal's problem",
            c.settings.lens_prior_sigma.unwrap_or_default()
        ));
    }
    let views = board_views(c)?;
    let (core, distortions, note) = optimised(&c.dataset, model);
    let mut entries = problem_arrays(c, model, &views)?;
    let none = || Npy::str("");
    entries.extend([
        ("points", none()),
        ("observations_point", none()),
        ("indices_point_camintrinsics_camextrinsics", none()),
        (
            "lensmodel",
            Npy::str(model.info().mrcal.unwrap_or_default()),
        ),
        ("calobject_warp", none()),
        ("do_optimize_intrinsics_core", Npy::bool(core)),
        ("do_optimize_intrinsics_distortions", Npy::bool(distortions)),
        ("do_optimize_extrinsics", Npy::bool(true)),
        ("do_optimize_frames", Npy::bool(true)),
        ("do_optimize_calobject_warp", Npy::bool(false)),
        (
            "calibration_object_spacing",
            Npy::scalar(c.dataset.target.spacing),
        ),
        // Our outliers are already marked; our problem has no regulariser.
        ("do_apply_outlier_rejection", Npy::bool(false)),
        ("do_apply_regularization", Npy::bool(false)),
        ("verbose", Npy::bool(false)),
    ]);
    let archive = npz(&entries).map_err(|e| e.to_string())?;
    Ok(OptimizationInputs::Carried {
        blob: b85encode(&archive),
        note,
    })
}

/// The state and the data in mrcal's arrays: intrinsics in `model`'s order, rig
/// and board poses, board observations with their (frame, camera, camera - 1)
/// indices, and image sizes. Frames without a view are left out.
fn problem_arrays(
    c: &Calibration,
    model: LensModel,
    views: &BTreeMap<(usize, usize), BoardView>,
) -> Result<Vec<(&'static str, Npy)>, String> {
    let d = &c.dataset;
    let frames: Vec<usize> = views
        .keys()
        .map(|&(j, _)| j)
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let dense = |j: usize| frames.binary_search(&j).expect("a view's frame is kept") as i32;
    let names = model.param_names();
    let intrinsics: Vec<f64> = c
        .state
        .intrinsics
        .iter()
        .flat_map(|i| names.iter().map(|n| i.get(n).unwrap_or(0.0)))
        .collect();
    let extrinsics: Vec<f64> = c.state.camera_poses[1..]
        .iter()
        .flat_map(Pose::to_array)
        .collect();
    let frames_rt: Vec<f64> = frames
        .iter()
        .flat_map(|&j| board_to_mrcal(&c.state.frame_poses[j], d).to_array())
        .collect();
    let indices: Vec<i32> = views
        .keys()
        .flat_map(|&(j, k)| [dense(j), k as i32, k as i32 - 1])
        .collect();
    let observations: Vec<f64> = views.values().flatten().flatten().copied().collect();
    let imagersizes = d
        .cameras
        .iter()
        .map(|cam| Ok([i32::try_from(cam.width)?, i32::try_from(cam.height)?]))
        .collect::<Result<Vec<[i32; 2]>, std::num::TryFromIntError>>()
        .map_err(|_| "an image size exceeds mrcal's 32-bit integers".to_string())?
        .concat();
    let (nc, nf, nv) = (d.cameras.len(), frames.len(), views.len());
    let (h, w) = (d.target.rows, d.target.cols);
    Ok(vec![
        ("intrinsics", Npy::f64(&[nc, names.len()], &intrinsics)),
        ("extrinsics_rt_fromref", Npy::f64(&[nc - 1, 6], &extrinsics)),
        ("frames_rt_toref", Npy::f64(&[nf, 6], &frames_rt)),
        (
            "observations_board",
            Npy::f64(&[nv, h, w, 3], &observations),
        ),
        (
            "indices_frame_camintrinsics_camextrinsics",
            Npy::i32(&[nv, 3], &indices),
        ),
        ("imagersizes", Npy::i32(&[nc, 2], &imagersizes)),
    ])
}

/// How a deformation method changes the board, for the message.
fn board_change(method: crate::model::board::Method) -> &'static str {
    match (method.has_correction(), method.has_paraboloid()) {
        (true, true) => "moves every corner and bends the board in every image",
        (true, false) => "moves every corner by its own offset",
        _ => "bends the board in every image",
    }
}

/// The one lens model, in mrcal's parameterisation, that every camera has.
fn common_model(d: &Dataset) -> Result<LensModel, String> {
    let mut model = None;
    for cam in &d.cameras {
        let m = cam.model.mrcal_equivalent().ok_or_else(|| {
            format!(
                "mrcal has no `{}` lens model (camera `{}`)",
                cam.model, cam.name
            )
        })?;
        match model {
            Some(first) if first != m => {
                return Err(format!(
                    "mrcal solves every camera with one lens model, and camera `{}` is `{}` while camera `{}` is `{}`",
                    d.cameras[0].name, d.cameras[0].model, cam.name, cam.model
                ))
            }
            _ => model = Some(m),
        }
    }
    model.ok_or_else(|| "there are no cameras".to_string())
}

/// Camera-0-from-board in mrcal's board frame, whose origin is corner 0 (ours is
/// the board's centre; the axes agree): x_ours = x_mrcal + nominal(0).
fn board_to_mrcal(pose: &Pose, d: &Dataset) -> Pose {
    let t = pose.transform(&d.target.nominal(0));
    Pose {
        rotation: pose.rotation,
        translation: [t.x, t.y, t.z],
    }
}

/// Every (frame, camera) view with at least one used corner, sorted as mrcal
/// requires. Each used corner's weight is its detector weight times the square root
/// of the loss's weight at our solution (so our robust optimum is mrcal's weighted
/// least-squares optimum); outlier rejection's corners get a negative weight.
fn board_views(c: &Calibration) -> Result<BTreeMap<(usize, usize), BoardView>, String> {
    let d = &c.dataset;
    let n = d.target.num_corners();
    let mut views: BTreeMap<(usize, usize), BoardView> = BTreeMap::new();
    let mut put = |frame: usize, camera: usize, corner: usize, corner_value: [f64; 3]| {
        let view = views
            .entry((frame, camera))
            .or_insert_with(|| vec![UNUSED; n]);
        if view[corner] != UNUSED {
            return Err(format!(
                "{} has corner {corner} twice, and mrcal takes one observation per corner",
                d.view_name(camera, frame)
            ));
        }
        view[corner] = corner_value;
        Ok(())
    };
    for (o, r) in d.observations.iter().zip(c.residuals.chunks(2)) {
        let e = r[0].hypot(r[1]);
        let weight = o.weight * c.settings.loss_weight(e * o.weight).sqrt();
        put(o.frame, o.camera, o.corner, [o.uv[0], o.uv[1], weight])?;
    }
    for s in &c.rejected {
        let camera = d.cameras.iter().position(|cam| cam.name == s.camera);
        let frame = d.frame_ids.binary_search(&s.frame).ok();
        if let (Some(camera), Some(frame)) = (camera, frame) {
            put(frame, camera, s.corner, [s.u, s.v, -1.0])?;
        }
    }
    views.retain(|_, v| v.iter().any(|p| p[2] > 0.0));
    Ok(views)
}

/// mrcal's `do_optimize_intrinsics_core` and `_distortions`, which hold a group for
/// every camera or for none, and a note naming the parameters deformcal held that
/// mrcal's problem therefore frees (radial3's p1 and p2 among them).
fn optimised(d: &Dataset, model: LensModel) -> (bool, bool, Option<String>) {
    const CORE: usize = 4;
    // held[k][i]: camera k holds mrcal parameter i (a parameter its model lacks is held at 0).
    let held: Vec<Vec<bool>> = d
        .cameras
        .iter()
        .map(|cam| {
            let h = cam.held();
            model
                .param_names()
                .iter()
                .map(|n| cam.model.param_index(n).is_none_or(|i| h[i]))
                .collect()
        })
        .collect();
    let free =
        |group: std::ops::Range<usize>| held.iter().any(|h| h[group.clone()].iter().any(|x| !x));
    let n = model.num_params();
    let (core, distortions) = (free(0..CORE), free(CORE..n));
    let freed: Vec<String> = d
        .cameras
        .iter()
        .zip(&held)
        .filter_map(|(cam, h)| {
            let names: Vec<&str> = (0..n)
                .filter(|&i| h[i] && if i < CORE { core } else { distortions })
                .map(|i| model.param_names()[i])
                .collect();
            (!names.is_empty()).then(|| format!("`{}` {}", cam.name, names.join(", ")))
        })
        .collect();
    let note = (!freed.is_empty()).then(|| {
        format!(
            "mrcal holds all four core or all distortion parameters or none, so these, held in deformcal's problem (radial3 has p1 = p2 = 0), are free in this one: {}",
            freed.join("; ")
        )
    });
    (core, distortions, note)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::camera::CameraSpec;
    use crate::model::lens::LensModel;
    use crate::model::target::Target;

    fn dataset(cameras: Vec<CameraSpec>) -> Dataset {
        Dataset {
            target: Target {
                rows: 4,
                cols: 6,
                spacing: 0.05,
            },
            cameras,
            frame_ids: vec![0],
            observations: Vec::new(),
        }
    }

    #[test]
    fn mrcals_board_frame_lands_on_ours() {
        let d = dataset(vec![CameraSpec::new("c", 640, 480, LensModel::OpenCv5)]);
        let pose = Pose {
            rotation: [0.3, -0.2, 0.1],
            translation: [0.1, 0.05, 2.0],
        };
        let mrcal = board_to_mrcal(&pose, &d);
        assert_eq!(mrcal.rotation, pose.rotation);
        for i in 0..d.target.num_corners() {
            // mrcal.ref_calibration_object: corner [row][col] at (col·s, row·s, 0).
            let (row, col) = (i / d.target.cols, i % d.target.cols);
            let s = d.target.spacing;
            let m = nalgebra::Vector3::new(col as f64 * s, row as f64 * s, 0.0);
            let ours = pose.transform(&d.target.nominal(i));
            assert!((mrcal.transform(&m) - ours).norm() < 1e-15, "corner {i}");
        }
    }

    #[test]
    fn held_groups_map_to_mrcals_flags_and_the_rest_is_named() {
        let mut a = CameraSpec::new("a", 640, 480, LensModel::Radial3);
        let d = dataset(vec![a.clone()]);
        let (core, dist, note) = optimised(&d, LensModel::OpenCv5);
        assert!(core && dist);
        assert!(note.unwrap().ends_with(": `a` p1, p2"));
        // All of radial3's distortion held: p1 = p2 = 0 held too, exactly mrcal's flag.
        a.fix = vec!["k1".into(), "k2".into(), "k3".into()];
        let (core, dist, note) = optimised(&dataset(vec![a.clone()]), LensModel::OpenCv5);
        assert!(core && !dist);
        assert_eq!(note, None);
        // One camera holds k3, the other nothing: mrcal frees k3 too.
        let mut b = CameraSpec::new("b", 640, 480, LensModel::OpenCv5);
        b.fix = vec!["k3".into(), "fx".into()];
        let c = CameraSpec::new("c", 640, 480, LensModel::OpenCv5);
        let (core, dist, note) = optimised(&dataset(vec![b, c]), LensModel::OpenCv5);
        assert!(core && dist);
        assert!(note.unwrap().ends_with(": `b` fx, k3"));
        assert!(matches!(
            common_model(&dataset(vec![a, CameraSpec::new("d", 1, 1, LensModel::OpenCv8)])),
            Err(m) if m.contains("one lens model")
        ));
    }
}
