//! `advise` on synthetic captures with known truth: the information it sums
//! reproduces the solver's covariance, the first advised pose fills the image
//! corner the capture left empty, and adding the advised view (simulated, then
//! calibrated by the real solver) lowers the true mapping error as predicted and
//! more than adding a random candidate view.
use crate::common;

use deformcal::app::advise::{self, Knowledge};
use deformcal::model::metrics::mapping_error;
use deformcal::model::synthetic::true_intrinsics;
use deformcal::model::uncertainty::camera_uncertainty;
use deformcal::{CameraSpec, Dataset, Intrinsics, LensModel, Method, Observation, Pose, Target};
use nalgebra::{Rotation3, Vector2};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const NOISE: f64 = 0.3;
const W: u32 = 1936;
const H: u32 = 1216;

fn target() -> Target {
    Target {
        rows: 6,
        cols: 9,
        spacing: 0.03,
    }
}

/// Twelve views whose boards all lie right of and below the image's centre
/// region: the top-left corner of the image is never covered.
fn capture_poses(k: &Intrinsics) -> Vec<Pose> {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut poses = Vec::new();
    while poses.len() < 12 {
        let px = Vector2::new(
            rng.gen_range(0.55..0.8) * W as f64,
            rng.gen_range(0.55..0.8) * H as f64,
        );
        let ray = k.unproject(&px).unwrap();
        let dist = rng.gen_range(0.9..1.3);
        let r = Rotation3::from_euler_angles(
            rng.gen_range(-0.6..0.6),
            rng.gen_range(-0.6..0.6),
            rng.gen_range(-0.3..0.3),
        );
        let pose = Pose::from_parts(&r, &(ray * (dist / ray.z)));
        if project_all(k, &pose).iter().all(Option::is_some) {
            poses.push(pose);
        }
    }
    poses
}

/// Every corner's projection, None outside the image.
fn project_all(k: &Intrinsics, pose: &Pose) -> Vec<Option<[f64; 2]>> {
    let t = target();
    (0..t.num_corners())
        .map(|i| {
            let uv = k.project(&pose.transform(&t.nominal(i)))?;
            (uv.x >= 0.0 && uv.y >= 0.0 && uv.x <= (W - 1) as f64 && uv.y <= (H - 1) as f64)
                .then_some([uv.x, uv.y])
        })
        .collect()
}

/// The views' in-image corners with Gaussian noise of `NOISE` px.
fn dataset(k: &Intrinsics, poses: &[Pose], seed: u64) -> Dataset {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, NOISE).unwrap();
    let mut observations = Vec::new();
    for (frame, pose) in poses.iter().enumerate() {
        for (corner, uv) in project_all(k, pose).into_iter().enumerate() {
            let Some(uv) = uv else { continue };
            observations.push(Observation {
                camera: 0,
                frame,
                corner,
                uv: [
                    uv[0] + noise.sample(&mut rng),
                    uv[1] + noise.sample(&mut rng),
                ],
                weight: 1.0,
            });
        }
    }
    Dataset {
        target: target(),
        cameras: vec![CameraSpec::new("cam", W, H, LensModel::Radial3)],
        frame_ids: (0..poses.len() as i64).collect(),
        observations,
    }
}

fn calibrated(d: &Dataset) -> deformcal::Calibration {
    common::run_with(d, Method::Standard, common::exact_settings())
}

fn knowledge(c: &deformcal::Calibration) -> Knowledge {
    let k = c.state.intrinsics[0];
    let free = vec![true; k.params().len()];
    let frames: Vec<Option<Pose>> = c.state.frame_poses.iter().map(|p| Some(*p)).collect();
    let information =
        advise::dataset_information(&k, &free, &c.dataset, 0, &Pose::identity(), &frames);
    Knowledge {
        intrinsics: k,
        width: W,
        height: H,
        free,
        target: target(),
        noise_px: NOISE,
        information,
    }
}

/// RMS over noise draws of the true mapping error of calibrating the capture
/// plus `extra` views.
fn simulated_error(k: &Intrinsics, poses: &[Pose], extra: &[Pose], draws: u64) -> f64 {
    let all: Vec<Pose> = poses.iter().chain(extra).copied().collect();
    let sq: f64 = (0..draws)
        .map(|s| {
            let c = calibrated(&dataset(k, &all, 100 + s));
            mapping_error(k, &c.state.intrinsics[0], W, H).powi(2)
        })
        .sum();
    (sq / draws as f64).sqrt()
}

#[test]
fn advised_pose_fills_the_empty_corner_and_helps_as_predicted() {
    let truth = true_intrinsics();
    let poses = capture_poses(&truth);
    let c = calibrated(&dataset(&truth, &poses, 1));
    let kn = knowledge(&c);

    // The summed view information is the solver's covariance (standard method).
    let unit = &c.covariance.as_ref().unwrap().cameras[0].unit;
    let solver = camera_uncertainty(&kn.intrinsics, &kn.free, &(unit * NOISE * NOISE), W, H)
        .unwrap()
        .expected_mapping_error_px;
    let ours = advise::expected_error(&kn, &kn.information).unwrap();
    assert!(
        (ours / solver - 1.0).abs() < 0.05,
        "{ours} vs solver {solver}"
    );

    let advice = advise::advise(&kn, 3).expect("advice");
    assert_eq!(advice.poses.len(), 3);
    let first = &advice.poses[0];
    // The first board reaches into the empty top-left of the image.
    let in_corner = project_all(&truth, &first.camera_from_board)
        .iter()
        .flatten()
        .filter(|uv| uv[0] < 0.35 * W as f64 && uv[1] < 0.35 * H as f64)
        .count();
    assert!(
        in_corner >= 6,
        "{in_corner} corners in the empty corner: {first:?}"
    );
    assert!(first.predicted_error_px < advice.current_error_px);
    for w in advice.poses.windows(2) {
        assert!(w[1].predicted_error_px <= w[0].predicted_error_px);
    }

    // Simulate: the capture alone, with the advised view, with random candidates.
    let draws = 16;
    let before = simulated_error(&truth, &poses, &[], draws);
    let advised = simulated_error(&truth, &poses, &[first.camera_from_board], draws);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let pool: Vec<Pose> = advise::candidates(&kn)
        .into_iter()
        .filter(|p| project_all(&truth, p).iter().flatten().count() >= 27)
        .collect();
    let random: Vec<f64> = (0..3)
        .map(|_| {
            let p = pool[rng.gen_range(0..pool.len())];
            simulated_error(&truth, &poses, &[p], draws)
        })
        .collect();
    let random_mean = random.iter().sum::<f64>() / random.len() as f64;
    eprintln!(
        "mapping error: predicted {:.4} → {:.4} px; simulated {before:.4} → {advised:.4} px \
         (random candidates: {random:.4?}, mean {random_mean:.4})",
        advice.current_error_px, first.predicted_error_px
    );
    assert!(
        advised < before && advised < random_mean,
        "{advised} vs {random_mean}"
    );
    // The drop the simulation measures is the one predicted, within 30 %.
    let (pred_drop, sim_drop) = (
        advice.current_error_px - first.predicted_error_px,
        before - advised,
    );
    assert!(
        (sim_drop / pred_drop - 1.0).abs() < 0.3,
        "drop {sim_drop} simulated, {pred_drop} predicted"
    );
}

/// The report's section takes the calibration's own covariance (no new solve):
/// its advice agrees with advice from the views' information summed anew, and
/// the section shows the picture and the three predicted errors.
#[test]
fn the_report_section_reuses_the_covariance_and_agrees() {
    let truth = true_intrinsics();
    let c = calibrated(&dataset(&truth, &capture_poses(&truth), 1));
    let mut summed = knowledge(&c);
    let from_cov = advise::knowledge_of(&c, 0).expect("a covariance and a noise estimate");
    // Same noise on both sides: the calibration's estimate.
    summed.noise_px = from_cov.noise_px;
    let a = advise::advise(&from_cov, 3).unwrap();
    let b = advise::advise(&summed, 3).unwrap();
    assert!(
        (a.current_error_px / b.current_error_px - 1.0).abs() < 0.05,
        "{} vs {}",
        a.current_error_px,
        b.current_error_px
    );
    let reported = c.assessment.uncertainty.as_ref().unwrap()[0].expected_mapping_error_px;
    assert!(
        (a.current_error_px / reported - 1.0).abs() < 1e-6,
        "{} vs {reported}",
        a.current_error_px
    );
    assert_eq!(a.poses[0].camera_from_board, b.poses[0].camera_from_board);
    for (p, q) in a.poses.iter().zip(&b.poses) {
        assert!(
            (p.predicted_error_px / q.predicted_error_px - 1.0).abs() < 0.05,
            "{p:?} vs {q:?}"
        );
    }
    let html = deformcal::app::html_report::advice::advice_section(&c);
    assert!(html.contains("data:image/svg+xml;base64,"), "the picture");
    for p in &a.poses {
        assert!(
            html.contains(&format!("{:.3}", p.predicted_error_px)),
            "{html}"
        );
    }
}
