//! `deformcal compare a.json b.json`: how far two calibrations of the same
//! cameras disagree (SPEC §3 mapping error, plain and with the virtual rotation
//! profiled out), beside the difference their own uncertainties predict (SPEC
//! §3a), so a user can tell a real difference from noise.
use crate::app::calibration_json::{CalibrationJson, CameraJson};
use crate::error::{Error, Result};
use crate::model::metrics::{mapping_error, mapping_error_rot};
use std::fmt::Write;

/// A difference above this many times the predicted one is more than noise.
pub const REAL_DIFFERENCE_FACTOR: f64 = 2.0;

/// One camera's difference between the two calibrations.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraDiff {
    pub name: String,
    /// Unproject with `a`, project with `b`: RMSE over the image grid, px.
    pub mapping_error_px: f64,
    pub mapping_error_rot_px: f64,
    /// Each calibration's expected mapping error (plain, rot), when it has one.
    pub expected_a: Option<(f64, f64)>,
    pub expected_b: Option<(f64, f64)>,
}

impl CameraDiff {
    /// The difference over the one two independent calibrations with these
    /// uncertainties would show, √(e_a² + e_b²): the larger of the plain and the
    /// rotation-compensated ratio (a bias may hide from either).
    pub fn ratio(&self) -> Option<f64> {
        let (a, b) = (self.expected_a?, self.expected_b?);
        let plain = (a.0 * a.0 + b.0 * b.0).sqrt();
        let rot = (a.1 * a.1 + b.1 * b.1).sqrt();
        (plain > 0.0 && rot > 0.0)
            .then(|| (self.mapping_error_px / plain).max(self.mapping_error_rot_px / rot))
    }

    /// Real difference or noise, in words.
    pub fn verdict(&self) -> String {
        match self.ratio() {
            None => "no uncertainty in one of the files: cannot tell a real difference from noise"
                .into(),
            Some(r) if r > REAL_DIFFERENCE_FACTOR => {
                format!("a real difference: {r:.1}× what the two calibrations' noise explains")
            }
            Some(r) => {
                format!("within the noise: {r:.1}× what the two calibrations' noise explains")
            }
        }
    }
}

/// The expected mapping errors a camera's file records, if any.
fn expected(cam: &CameraJson) -> Option<(f64, f64)> {
    let u = cam.uncertainty.as_ref()?;
    Some((u.expected_mapping_error_px, u.expected_mapping_error_rot_px))
}

/// Every camera of `a` that `b` has too (same name, model may differ, same size).
pub fn compare(a: &CalibrationJson, b: &CalibrationJson) -> Result<Vec<CameraDiff>> {
    let mut out = Vec::new();
    for ca in &a.cameras {
        let Some(cb) = b.cameras.iter().find(|c| c.name == ca.name) else {
            continue;
        };
        if (ca.width, ca.height) != (cb.width, cb.height) {
            return Err(Error::Invalid(format!(
                "camera `{}` is {}×{} in the first calibration and {}×{} in the second",
                ca.name, ca.width, ca.height, cb.width, cb.height
            )));
        }
        out.push(CameraDiff {
            name: ca.name.clone(),
            mapping_error_px: mapping_error(&ca.intrinsics, &cb.intrinsics, ca.width, ca.height),
            mapping_error_rot_px: mapping_error_rot(
                &ca.intrinsics,
                &cb.intrinsics,
                ca.width,
                ca.height,
            ),
            expected_a: expected(ca),
            expected_b: expected(cb),
        });
    }
    if out.is_empty() {
        return Err(Error::Invalid(
            "the two calibrations have no camera name in common".into(),
        ));
    }
    Ok(out)
}

/// The comparison as a table with a verdict per camera.
pub fn format(a_name: &str, b_name: &str, diffs: &[CameraDiff]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "a: {a_name}\nb: {b_name}");
    let _ = writeln!(
        s,
        "  {:12} {:>12} {:>12} {:>16} {:>16}",
        "camera", "map. error", "rot.-comp.", "expected a", "expected b"
    );
    let e = |x: Option<(f64, f64)>| {
        x.map(|(p, r)| format!("{p:.3} / {r:.3}"))
            .unwrap_or_else(|| "–".into())
    };
    for d in diffs {
        let _ = writeln!(
            s,
            "  {:12} {:>9.3} px {:>9.3} px {:>16} {:>16}",
            d.name,
            d.mapping_error_px,
            d.mapping_error_rot_px,
            e(d.expected_a),
            e(d.expected_b)
        );
        let _ = writeln!(s, "    {}", d.verdict());
    }
    let _ = writeln!(
        s,
        "  (px, RMSE over a {} px grid; expected: each file's expected_mapping_error_px / _rot_px; \
         two independent calibrations differ by about √(a² + b²))",
        crate::model::metrics::MAPPING_GRID_STEP_PX
    );
    s
}
