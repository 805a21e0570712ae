//! What every export writer shares: numbers, keys and camera names as the formats
//! write them, parameter values by name, and the warning for a camera left out.
use crate::app::calibration_json::CameraJson;
use crate::model::lens::Intrinsics;

/// A number as Rust writes it: shortest round-trip form, always with a `.` or an
/// exponent (`500.0`, not `500`), so YAML readers that check for floats (Kalibr
/// does) accept it and no digit is lost.
pub(super) fn fmt(v: f64) -> String {
    format!("{v:?}")
}

/// A key from a camera name: letters, digits and underscores, starting with a
/// letter (OpenCV FileStorage keys, ROS camera names).
pub(super) fn key_of(name: &str) -> String {
    let mut k: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if !k.starts_with(|c: char| c.is_ascii_alphabetic()) {
        k.insert_str(0, "cam_");
    }
    k
}

/// A camera name as it may stand in a comment or a message line: control
/// characters and Unicode line separators become escapes, so a name read from a
/// hand-edited calibration.json cannot end the comment and write a value of its own
/// (config names are restricted to a safe set; see docs/conventions.md).
pub fn printable(name: &str) -> String {
    let mut s = String::with_capacity(name.len());
    for c in name.chars() {
        if c.is_control() || c == '\u{2028}' || c == '\u{2029}' {
            s.extend(c.escape_default());
        } else {
            s.push(c);
        }
    }
    s
}

/// The values of parameters by name, in the order given; a name the model lacks
/// is 0 (the registry's export forms name such parameters, e.g. radial3's p1, p2).
pub(super) fn values(i: &Intrinsics, names: &[&str]) -> Vec<f64> {
    names.iter().map(|n| i.get(n).unwrap_or(0.0)).collect()
}

/// Why a camera is left out of an export format.
pub(super) fn unrepresentable(format: &str, c: &CameraJson) -> String {
    format!(
        "{format}: camera `{}` is left out: the format has no `{}` lens model",
        printable(&c.name),
        c.model
    )
}

/// A camera name made safe for a file name: path separators and control
/// characters (NUL, newlines) become `_`.
pub fn file_stem(camera: &str) -> String {
    camera
        .chars()
        .map(|c| {
            if c == '/' || c == '\\' || c.is_control() {
                '_'
            } else {
                c
            }
        })
        .collect()
}

/// A file name for a camera's model: its name with path separators replaced.
pub fn model_file_name(camera: &str) -> String {
    format!("{}.cameramodel", file_stem(camera))
}
