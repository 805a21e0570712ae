//! Several cameras: the relative poses π_k (camera-k-from-camera-0) at initialisation,
//! from the board poses each camera sees, robustly averaged and chained over the
//! cameras' overlap graph.
use crate::error::{Error, Result};
use crate::model::pose::Pose;
use nalgebra::{Matrix4, Quaternion, UnitQuaternion, Vector3};

/// Robust average of rigid transforms: the medoid (least total rotation angle to the
/// others), then the mean of the transforms close to it in rotation and translation.
pub fn robust_average(poses: &[Pose]) -> Option<Pose> {
    if poses.is_empty() {
        return None;
    }
    let rotations: Vec<UnitQuaternion<f64>> = poses
        .iter()
        .map(|p| UnitQuaternion::from_rotation_matrix(&p.rotation_matrix()))
        .collect();
    let translations: Vec<Vector3<f64>> = poses.iter().map(|p| p.translation_vector()).collect();
    let medoid = (0..poses.len()).min_by(|&a, &b| {
        let cost = |i: usize| -> f64 {
            (0..poses.len())
                .map(|j| {
                    rotations[i].angle_to(&rotations[j])
                        + (translations[i] - translations[j]).norm()
                })
                .sum()
        };
        cost(a).total_cmp(&cost(b))
    })?;
    let angle: Vec<f64> = rotations
        .iter()
        .map(|q| q.angle_to(&rotations[medoid]))
        .collect();
    let shift: Vec<f64> = translations
        .iter()
        .map(|t| (t - translations[medoid]).norm())
        .collect();
    let median = |v: &[f64]| {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    // Inliers: within three median deviations, never tighter than 0.5° and 5 mm.
    let angle_limit = (3.0 * median(&angle)).max(0.5f64.to_radians());
    let shift_limit = (3.0 * median(&shift)).max(0.005);
    let inliers: Vec<usize> = (0..poses.len())
        .filter(|&i| angle[i] <= angle_limit && shift[i] <= shift_limit)
        .collect();
    // Chordal mean of the rotations: the dominant eigenvector of Σ q qᵀ.
    let mut m = Matrix4::<f64>::zeros();
    let mut t = Vector3::zeros();
    for &i in &inliers {
        let q = rotations[i].as_vector();
        m += q * q.transpose();
        t += translations[i];
    }
    let eig = m.symmetric_eigen();
    let (imax, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))?;
    let v = eig.eigenvectors.column(imax);
    let q = UnitQuaternion::from_quaternion(Quaternion::new(v[3], v[0], v[1], v[2]));
    Some(Pose::from_parts(
        &q.to_rotation_matrix(),
        &(t / inliers.len() as f64),
    ))
}

/// π_k for every camera from per-view board poses `views[k][j]` (camera-k-from-board),
/// chained from camera 0 along the pairs that share the most frames.
pub fn initial_rig(views: &[Vec<Option<Pose>>], names: &[String]) -> Result<Vec<Pose>> {
    let n = views.len();
    let frames = views.first().map(|v| v.len()).unwrap_or(0);
    let shared = |a: usize, b: usize| {
        (0..frames)
            .filter(|&j| views[a][j].is_some() && views[b][j].is_some())
            .count()
    };
    let mut rig: Vec<Option<Pose>> = vec![None; n];
    rig[0] = Some(Pose::identity());
    // Prim's maximum spanning tree on the number of shared frames.
    loop {
        let best = (0..n)
            .filter(|&a| rig[a].is_some())
            .flat_map(|a| (0..n).filter(|&b| rig[b].is_none()).map(move |b| (a, b)))
            .map(|(a, b)| (shared(a, b), a, b))
            .filter(|&(s, _, _)| s > 0)
            .max();
        let Some((_, a, b)) = best else { break };
        // camera-b-from-camera-a, once per shared frame.
        let relative: Vec<Pose> = (0..frames)
            .filter_map(|j| Some(views[b][j]?.compose(&views[a][j]?.inverse())))
            .collect();
        let ab = robust_average(&relative).expect("shared frames exist");
        rig[b] = Some(ab.compose(&rig[a].expect("in the tree")));
    }
    let lonely: Vec<&str> = (0..n)
        .filter(|&k| rig[k].is_none())
        .map(|k| names[k].as_str())
        .collect();
    if !lonely.is_empty() {
        return Err(Error::Degenerate(format!(
            "camera(s) {} never see the board in the same image as {} or a camera linked to it: the rig is disconnected",
            lonely.join(", "),
            names[0]
        )));
    }
    Ok(rig.into_iter().map(|p| p.expect("checked")).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(r: [f64; 3], t: [f64; 3]) -> Pose {
        Pose {
            rotation: r,
            translation: t,
        }
    }

    #[test]
    fn average_ignores_outliers() {
        let mut poses: Vec<Pose> = (0..9)
            .map(|i| {
                let e = (i as f64 - 4.0) * 1e-4;
                pose([0.1 + e, -0.2, 0.05 - e], [0.3 + e, 0.01, -e])
            })
            .collect();
        poses.push(pose([0.9, 0.4, 0.0], [2.0, 1.0, 0.0]));
        let avg = robust_average(&poses).unwrap();
        for (a, b) in avg.to_array().iter().zip([0.1, -0.2, 0.05, 0.3, 0.01, 0.0]) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
    }

    #[test]
    fn disconnected_rig_names_the_camera() {
        let p = Some(Pose::identity());
        let views = vec![vec![p, p], vec![p, None], vec![None, None]];
        let names: Vec<String> = ["left", "right", "far"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let e = initial_rig(&views, &names).unwrap_err().to_string();
        assert!(e.contains("far") && !e.contains("right,"), "{e}");
    }
}
