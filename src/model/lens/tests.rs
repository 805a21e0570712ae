//! The registry's own checks: every entry complete and consistent, and each
//! model's projection inverted by its unprojection (called from the models' files).
use super::*;
use nalgebra::{Vector2, Vector3};

/// Asserts that `params` (a camera of the model `name`, with distortion typical
/// of its kind) unprojects its projections back to the rays.
pub(super) fn round_trips(name: &str, params: &[f64]) {
    let model = LensModel::parse(name).expect("a registered model");
    let k = Intrinsics::from_params(model, params).unwrap();
    for &(x, y, z) in &[
        (0.0, 0.0, 1.0),
        (0.3, -0.2, 1.0),
        (-0.5, 0.4, 1.0),
        (0.01, 0.6, 1.0),
    ] {
        let ray = Vector3::new(x, y, z).normalize();
        let uv = k.project(&ray).unwrap();
        let back = k.unproject(&uv).unwrap();
        assert!((back - ray).norm() < 1e-12, "{k:?}: {back} vs {ray}");
    }
}

fn subset(names: &[&str], of: &[&str]) -> bool {
    names.iter().all(|n| of.contains(n))
}

/// Every parameter of `info` beyond fx fy cx cy is named in one of `lists`: a
/// form that leaves one out would drop it from the export.
fn covers(info: &LensInfo, lists: &[&[&str]]) -> bool {
    info.params[4..]
        .iter()
        .all(|p| lists.iter().any(|l| l.contains(p)))
}

fn check_exports(m: LensModel, i: &LensInfo) {
    if let Some(cv) = i.opencv {
        assert!(!cv.distortion_model.is_empty(), "{m}");
        assert!(covers(i, &[cv.coefficients]), "{m}: OpenCV coefficients");
    }
    assert_eq!(
        i.ros.is_some(),
        i.opencv.is_some(),
        "{m}: ROS follows OpenCV"
    );
    if let Some(k) = i.kalibr {
        assert!(!k.name.is_empty() && !k.camera_model.is_empty(), "{m}");
        assert!(subset(k.intrinsics, i.params), "{m}: Kalibr intrinsics");
        assert!(
            covers(i, &[k.intrinsics, k.coefficients, k.requires_zero]),
            "{m}: Kalibr"
        );
        assert!(subset(k.requires_zero, i.params), "{m}");
    }
    for c in i.colmap {
        assert!(covers(i, &[c.params, c.requires_zero]), "{m}: {}", c.model);
        assert!(subset(c.requires_zero, i.params), "{m}: {}", c.model);
    }
    // The last COLMAP form takes every camera of the model.
    if let Some(last) = i.colmap.last() {
        assert!(last.requires_zero.is_empty(), "{m}: {}", last.model);
    }
    assert!(
        !(i.mrcal.is_some() && i.mrcal_via.is_some()),
        "{m}: mrcal has it or holds it through another, not both"
    );
    if let Some(via) = i.mrcal_via {
        assert!(via.info().mrcal.is_some(), "{m}: via {via}");
        assert!(subset(i.params, via.param_names()), "{m}: via {via}");
    }
}

/// A registry entry that lacks a piece, or whose pieces disagree, fails here.
#[test]
fn every_registry_entry_is_complete() {
    let mut names = std::collections::BTreeSet::new();
    for m in LensModel::ALL {
        let i = m.info();
        assert!(names.insert(i.name), "{m}: name used twice");
        assert!(
            !i.name.is_empty() && i.name.chars().all(|c| c.is_ascii_alphanumeric()),
            "{m}: name"
        );
        assert_eq!(i.params[..4], ["fx", "fy", "cx", "cy"], "{m}");
        assert!(i.params.len() <= MAX_PARAMS, "{m}");
        let unique: std::collections::BTreeSet<_> = i.params.iter().collect();
        assert_eq!(unique.len(), i.params.len(), "{m}: a parameter twice");
        assert!(!i.help.is_empty(), "{m}: help");
        assert_eq!(
            i.pinhole_like,
            matches!(i.projection, Projection::PinholeLike { .. }),
            "{m}: pinhole_like"
        );
        assert_eq!(i.undistorted.len(), i.params.len() - 4, "{m}: undistorted");
        assert_eq!(i.synthetic.len(), i.params.len(), "{m}: synthetic");
        assert!(subset(i.prior_params, i.params), "{m}: prior_params");
        check_exports(m, i);
        assert_eq!(LensModel::parse(i.name), Some(m));
    }
}

/// A pinhole-like model without distortion is the pinhole camera, which is
/// what Zhang's initialisation estimates; every model's undistorted lens has
/// focal length f at the image centre.
#[test]
fn undistorted_lenses_are_pinholes_at_the_centre() {
    for m in LensModel::ALL {
        let k = Intrinsics::pinhole_of(m, 800.0, 810.0, 320.0, 240.0);
        for &(x, y) in &[(0.0, 0.0), (1e-5, -2e-5)] {
            let uv = k.project(&Vector3::new(x, y, 1.0)).unwrap();
            let pinhole = Vector2::new(800.0 * x + 320.0, 810.0 * y + 240.0);
            assert!((uv - pinhole).norm() < 1e-6, "{m}: {uv} vs {pinhole}");
        }
        if m.info().pinhole_like {
            let uv = k.project(&Vector3::new(0.4, -0.3, 1.0)).unwrap();
            let pinhole = Vector2::new(800.0 * 0.4 + 320.0, 810.0 * -0.3 + 240.0);
            assert!((uv - pinhole).norm() < 1e-9, "{m}: {uv} vs {pinhole}");
        }
    }
}

#[test]
fn help_names_every_model_and_its_parameters() {
    let lines = LensModel::help_lines();
    assert_eq!(lines.len(), LensModel::ALL.len());
    for (line, m) in lines.iter().zip(LensModel::ALL) {
        assert!(line.starts_with(m.name()), "{line}");
        assert!(line.contains(&m.param_names().join(" ")), "{line}");
        assert!(line.ends_with(m.info().help), "{line}");
    }
}

#[test]
fn json_round_trip_keeps_the_model() {
    for m in LensModel::ALL {
        let k = Intrinsics::from_params(m, m.info().synthetic).unwrap();
        let text = serde_json::to_string(&k).unwrap();
        let back: Intrinsics = serde_json::from_str(&text).unwrap();
        assert_eq!(back, k);
    }
    let err =
        serde_json::from_str::<Intrinsics>(r#"{"fx":1,"fy":1,"cx":0,"cy":0,"k9":0}"#).unwrap_err();
    assert!(err.to_string().contains("match no lens model"), "{err}");
}

/// `radial3` with k1 = −0.3 alone: the distorted radius r (1 − 0.3 r²) rises to
/// its fold at r = 1/√0.9, where it is 2/(3√0.9) ≈ 0.7027. Below the fold the
/// unprojection is the one root there (found here by bisection, independently of
/// Newton's method); beyond it no ray maps to the pixel.
#[test]
fn unprojection_inverts_the_distortion_up_to_its_fold() {
    let k1 = -0.3;
    let (f, cx, cy) = (1000.0, 640.0, 360.0);
    let k = Intrinsics::from_params(LensModel::Radial3, &[f, f, cx, cy, k1, 0.0, 0.0]).unwrap();
    let fold_r = 1.0 / (-3.0 * k1).sqrt();
    let distorted = |r: f64| r * (1.0 + k1 * r * r);
    let fold = distorted(fold_r);
    for rd in [0.0, 0.1, 0.3, 0.5, 0.65, 0.99 * fold, 1.01 * fold, 0.8, 1.0] {
        for angle in [0.0, 0.7, 2.0, 3.5, 5.1_f64] {
            let uv = Vector2::new(cx + f * rd * angle.cos(), cy + f * rd * angle.sin());
            let ray = k.unproject(&uv);
            if rd > fold {
                assert!(ray.is_none(), "r_d {rd} beyond the fold {fold}: {ray:?}");
                continue;
            }
            let ray = ray.unwrap_or_else(|| panic!("r_d {rd} below the fold {fold}: no ray"));
            let (mut lo, mut hi) = (0.0, fold_r);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if distorted(mid) < rd {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let r = (ray.x * ray.x + ray.y * ray.y).sqrt() / ray.z;
            assert!((r - lo).abs() < 1e-12, "r_d {rd}: {r} against {lo}");
            let back = k.project(&ray).unwrap();
            assert!((back - uv).norm() < 1e-9, "r_d {rd}: {back} against {uv}");
        }
    }
}
