//! The HTML reports: `report.html` beside every `calibration.json` and beside every
//! protocol's `report.md`. Each is one self-contained file (inline SVG figures,
//! inline CSS, no script, font or network resource), so it opens anywhere.
//!
//! - `page`: the HTML building blocks (escaping, page shell, tables, figures).
//! - `fields` and `figures`: the numbers behind the calibration figures, and the
//!   figures themselves (plotters; shared primitives in `app::plots`).
//! - `calibration`: what the calibration page shows, section by section;
//!   `advice`: its section on where to hold the board next (`app::advise`).
//! - `protocol`: the protocol page, from the tables `app::protocol_report` builds.
pub mod advice;
pub mod calibration;
pub mod fields;
pub mod figures;
pub mod page;
pub mod protocol;

use crate::app::fsio::{read_limited, write_atomic};
use crate::app::lint::FrameFiles as FrameLabels;
use crate::error::Result;
use crate::solver::calibrate::Calibration;
use page::Page;
use std::path::Path;

/// The report's file name, in every output directory that has one.
pub use crate::app::fsio::REPORT_HTML as REPORT_FILE;
pub use calibration::uncertainty_file;

/// Largest uncertainty map embedded; a larger file is left out of the report.
const MAX_EMBEDDED_BYTES: u64 = 16 << 20;

/// Camera `camera`'s uncertainty map from `dir`, if one was written there.
pub fn read_uncertainty(dir: &Path, camera: &str) -> Option<Vec<u8>> {
    let path = dir.join(uncertainty_file(camera));
    path.is_file()
        .then(|| read_limited(&path, MAX_EMBEDDED_BYTES).ok())
        .flatten()
}

/// Writes `report.html` of a calibration into `dir` (the staging directory of the
/// result set), embedding each camera's uncertainty map found there.
pub fn write_calibration_report(dir: &Path, c: &Calibration, labels: &FrameLabels) -> Result<()> {
    let maps: Vec<Option<Vec<u8>>> = c
        .dataset
        .cameras
        .iter()
        .map(|cam| read_uncertainty(dir, &cam.name))
        .collect();
    write_calibration_report_with(dir, c, labels, &maps)
}

/// Writes `report.html` of a calibration into `dir`, embedding `maps[k]` as camera
/// k's uncertainty map (the bytes of its file, as [`read_uncertainty`] would read
/// them once written; one over the embedding limit is left out as there).
pub fn write_calibration_report_with(
    dir: &Path,
    c: &Calibration,
    labels: &FrameLabels,
    maps: &[Option<Vec<u8>>],
) -> Result<()> {
    let page = report_page(c, labels, maps)?;
    write_report(dir, page, advice::advice_section(c))
}

/// The page [`write_calibration_report_with`] writes, but for its advice section
/// ([`advice::advice_section`], given to [`write_report`]), which a caller may
/// compute on another thread meanwhile.
pub fn report_page(
    c: &Calibration,
    labels: &FrameLabels,
    maps: &[Option<Vec<u8>>],
) -> Result<Page> {
    let maps: Vec<Option<Vec<u8>>> = maps
        .iter()
        .map(|m| m.clone().filter(|b| b.len() as u64 <= MAX_EMBEDDED_BYTES))
        .collect();
    calibration::page_but_advice(c, labels, &maps)
}

/// Writes `page` ([`report_page`]) with its advice section `advice` as `report.html` in `dir`.
pub fn write_report(dir: &Path, mut page: Page, advice: String) -> Result<()> {
    page.fill(calibration::ADVICE_SECTION, advice);
    write_atomic(&dir.join(REPORT_FILE), page.render().as_bytes())
}
