//! COLMAP's `cameras.txt`: `CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]` per camera, in
//! the COLMAP model the lens registry names (`LensInfo::colmap`), e.g. `OPENCV`
//! (fx fy cx cy k1 k2 p1 p2), `FULL_OPENCV` (… k3 k4 k5 k6) or `OPENCV_FISHEYE`
//! (fx fy cx cy k1 k2 k3 k4). COLMAP puts the centre of the
//! top-left pixel at (0.5, 0.5) where OpenCV (and deformcal) put it at (0, 0), so
//! cx and cy are written 0.5 larger. Camera k (from 0) is COLMAP camera k + 1.
use super::common::{fmt, unrepresentable};
use crate::app::calibration_json::CalibrationJson;
use crate::app::calibration_json::CameraJson;
use std::fmt::Write;

/// The file name.
pub const COLMAP_FILE: &str = "cameras.txt";

/// COLMAP's model and parameters of a camera: the first of the registry's
/// COLMAP forms of its lens model that holds it exactly; `None` where none does.
fn colmap_model(c: &CameraJson) -> Option<(&'static str, Vec<f64>)> {
    let i = &c.intrinsics;
    let form = i.model().info().colmap.iter().find(|f| {
        f.requires_zero
            .iter()
            .all(|n| i.get(n).unwrap_or(0.0) == 0.0)
    })?;
    let mut params = vec![i.fx(), i.fy(), i.cx() + 0.5, i.cy() + 0.5];
    params.extend(super::common::values(i, form.params));
    Some((form.model, params))
}

/// The `cameras.txt` of a calibration; `None` when no camera can be written. A
/// camera left out adds a warning (its id stays unused, so ids keep matching
/// deformcal's camera order).
pub fn cameras_txt(c: &CalibrationJson, warnings: &mut Vec<String>) -> Option<String> {
    let mut lines = Vec::new();
    for (k, cam) in c.cameras.iter().enumerate() {
        let Some((model, params)) = colmap_model(cam) else {
            warnings.push(unrepresentable(COLMAP_FILE, cam));
            continue;
        };
        let p: Vec<String> = params.iter().map(|&v| fmt(v)).collect();
        lines.push(format!(
            "# camera {}: deformcal camera `{}` ({})",
            k + 1,
            super::common::printable(&cam.name),
            cam.model
        ));
        lines.push(format!(
            "{} {model} {} {} {}",
            k + 1,
            cam.width,
            cam.height,
            p.join(" ")
        ));
    }
    if lines.is_empty() {
        return None;
    }
    let mut s = String::from("# Camera list with one line of data per camera:\n");
    s += "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n";
    let _ = writeln!(s, "# Number of cameras: {}", lines.len() / 2);
    for l in lines {
        let _ = writeln!(s, "{l}");
    }
    Some(s)
}
