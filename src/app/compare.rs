//! `deformcal compare a.json b.json`: how far two calibrations of the same
//! cameras disagree (the mapping error of docs/conventions.md §3, plain and with
//! the virtual rotation profiled out), beside the difference their own
//! uncertainties predict (§3a), so a user can tell a real difference from noise.
use crate::app::calibration_json::{CalibrationJson, CameraJson};
use crate::error::{Error, Result};
use crate::model::lens::Intrinsics;
use crate::model::metrics::{mapping_error_of, mapping_error_rot_of, MAPPING_GRID_STEP_PX};
use nalgebra::{Vector2, Vector3};
use std::fmt::Write;

/// Most grid points a camera's comparison evaluates: docs/conventions.md §3's 20 px grid up to
/// images of about 4 megapixels, a coarser grid of about this many points beyond,
/// so the time does not grow with the image (a 4-gigapixel image would need ten
/// million points and minutes).
pub const MAX_GRID_POINTS: u64 = 10_000;

/// The grid step for a `width` × `height` image: 20 px, or the step that keeps
/// the grid within [`MAX_GRID_POINTS`].
pub fn grid_step_px(width: u32, height: u32) -> u32 {
    let mut step = MAPPING_GRID_STEP_PX;
    let points = |s: u32| u64::from(width.div_ceil(s)) * u64::from(height.div_ceil(s));
    while points(step) > MAX_GRID_POINTS {
        step = step.saturating_mul(2).max(step + 1);
    }
    step
}

/// The grid's pixels with their rays under `a` (pixels without a ray left out),
/// every [`grid_step_px`] pixels from the top-left pixel.
fn grid_rays(a: &Intrinsics, width: u32, height: u32) -> Vec<(Vector2<f64>, Vector3<f64>)> {
    let step = grid_step_px(width, height) as usize;
    let mut out = Vec::new();
    for v in (0..height).step_by(step) {
        for u in (0..width).step_by(step) {
            let px = Vector2::new(f64::from(u), f64::from(v));
            if let Some(ray) = a.unproject(&px) {
                out.push((px, ray));
            }
        }
    }
    out
}

/// A difference above this many times the predicted one is more than noise.
pub const REAL_DIFFERENCE_FACTOR: f64 = 2.0;

/// One camera's difference between the two calibrations.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraDiff {
    pub name: String,
    /// Unproject with `a`, project with `b`: RMSE over the image grid, px.
    pub mapping_error_px: f64,
    pub mapping_error_rot_px: f64,
    /// The grid's step, pixels ([`grid_step_px`]).
    pub grid_step_px: u32,
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
/// Both must be usable calibrations ([`CalibrationJson::check`]).
pub fn compare(a: &CalibrationJson, b: &CalibrationJson) -> Result<Vec<CameraDiff>> {
    for (which, c) in [("first", a), ("second", b)] {
        c.check()
            .map_err(|e| Error::Invalid(format!("the {which} calibration: {e}")))?;
    }
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
        let rays = grid_rays(&ca.intrinsics, ca.width, ca.height);
        out.push(CameraDiff {
            name: ca.name.clone(),
            mapping_error_px: mapping_error_of(&rays, &cb.intrinsics),
            mapping_error_rot_px: mapping_error_rot_of(&rays, &cb.intrinsics),
            grid_step_px: grid_step_px(ca.width, ca.height),
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
        // Only a grid coarser than docs/conventions.md §3's is worth a word.
        let grid = if d.grid_step_px == MAPPING_GRID_STEP_PX {
            String::new()
        } else {
            format!(" ({} px grid)", d.grid_step_px)
        };
        let _ = writeln!(
            s,
            "  {:12} {:>9.3} px {:>9.3} px {:>16} {:>16}{grid}",
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
        "  (px, RMSE over a {MAPPING_GRID_STEP_PX} px grid, coarser where an image would need more than \
         {MAX_GRID_POINTS} points; expected: each file's expected_mapping_error_px / _rot_px; two \
         independent calibrations differ by about √(a² + b²))"
    );
    s
}
