//! Kalibr's `camchain.yaml`: `cam0`, `cam1`, … with `camera_model`, `intrinsics`,
//! `distortion_model`, `distortion_coeffs`, `resolution`, and from `cam1` on
//! `T_cn_cnm1`, the 4×4 transform from the previous camera in the chain to this
//! one. Which Kalibr model holds which lens model is the lens registry's
//! (`LensInfo::kalibr`): `pinhole-radtan` (k1 k2 p1 p2: radial3 and opencv5 only
//! when k3 is exactly 0), `pinhole-equi` (kb4) and `ds-none` (double sphere,
//! intrinsics [xi alpha fu fv pu pv]). Kalibr counts every top-level key as a
//! camera, so each camera's deformcal name goes into a comment.
use super::common::fmt;
use crate::app::calibration_json::{CalibrationJson, CameraJson};
use crate::model::pose::Pose;
use std::fmt::Write;

/// The file name.
pub const KALIBR_FILE: &str = "camchain.yaml";

/// A camera as Kalibr holds it.
struct KalibrCamera {
    /// `camera_model`: `pinhole` or `ds`.
    model: &'static str,
    intrinsics: Vec<f64>,
    /// `distortion_model`: `radtan`, `equidistant` or `none`.
    distortion: &'static str,
    coefficients: Vec<f64>,
}

/// Kalibr's camera model, intrinsics, distortion model and coefficients of a
/// camera (the registry's Kalibr form), or why Kalibr cannot hold it exactly.
fn kalibr_model(c: &CameraJson) -> Result<KalibrCamera, String> {
    let i = &c.intrinsics;
    let form = i
        .model()
        .info()
        .kalibr
        .ok_or_else(|| super::common::unrepresentable(KALIBR_FILE, c))?;
    for &name in form.requires_zero {
        let v = i.get(name).unwrap_or(0.0);
        if v != 0.0 {
            return Err(format!(
                "{KALIBR_FILE}: camera `{}` is left out: Kalibr's {} has no {name} and `{}` has {name} = {}",
                super::common::printable(&c.name), form.name, c.model, fmt(v)
            ));
        }
    }
    Ok(KalibrCamera {
        model: form.camera_model,
        intrinsics: super::common::values(i, form.intrinsics),
        distortion: form.distortion_model,
        coefficients: super::common::values(i, form.coefficients),
    })
}

fn list(values: &[f64]) -> String {
    let v: Vec<String> = values.iter().map(|&x| fmt(x)).collect();
    format!("[{}]", v.join(", "))
}

/// T_cn_cnm1 = π_n ∘ π_{n-1}⁻¹ (π_k: camera k from camera 0), as four YAML rows.
fn t_cn_cnm1(this: &CameraJson, previous: &CameraJson) -> String {
    let pose = |c: &CameraJson| Pose {
        rotation: c.rotation,
        translation: c.translation,
    };
    let t = pose(this).compose(&pose(previous).inverse());
    let r = t.rotation_matrix();
    let mut s = String::from("  T_cn_cnm1:\n");
    for i in 0..3 {
        let row = [r[(i, 0)], r[(i, 1)], r[(i, 2)], t.translation[i]];
        let _ = writeln!(s, "  - {}", list(&row));
    }
    s + "  - [0.0, 0.0, 0.0, 1.0]\n"
}

/// The camchain of a calibration: the cameras Kalibr can hold, in order, each
/// chained to the previous one written; `None` when none can be written. A
/// camera left out adds a warning (and the chain links over it).
pub fn camchain_yaml(c: &CalibrationJson, warnings: &mut Vec<String>) -> Option<String> {
    let mut s = String::from("# Kalibr camera chain, written by deformcal\n");
    let mut previous: Option<&CameraJson> = None;
    let mut n = 0;
    for cam in &c.cameras {
        let k = match kalibr_model(cam) {
            Ok(m) => m,
            Err(w) => {
                warnings.push(w);
                continue;
            }
        };
        let _ = writeln!(
            s,
            "# cam{n}: deformcal camera `{}` ({})",
            super::common::printable(&cam.name),
            cam.model
        );
        let _ = writeln!(s, "cam{n}:");
        if let Some(prev) = previous {
            s += &t_cn_cnm1(cam, prev);
        }
        let _ = writeln!(s, "  camera_model: {}", k.model);
        let _ = writeln!(s, "  intrinsics: {}", list(&k.intrinsics));
        let _ = writeln!(s, "  distortion_model: {}", k.distortion);
        let _ = writeln!(s, "  distortion_coeffs: {}", list(&k.coefficients));
        let _ = writeln!(s, "  resolution: [{}, {}]", cam.width, cam.height);
        let _ = writeln!(
            s,
            "  rostopic: /{}/image_raw",
            super::common::key_of(&cam.name)
        );
        previous = Some(cam);
        n += 1;
    }
    (n > 0).then_some(s)
}
