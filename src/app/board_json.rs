//! `board.json`: a board measured once (its static correction and that
//! correction's standard deviation), written beside `calibration.json` by every
//! calibration that estimates a correction and read back by `[target] geometry`
//! as the nominal board of later calibrations. Only this module reads or writes
//! the file; what a calibration does with the geometry is `model::board`'s
//! `BoardPriors`.
use crate::app::fsio::{read_limited, write_atomic};
use crate::app::text::number;
use crate::error::{Error, Result};
use crate::model::board::BoardGeometry;
use crate::model::target::Target;
use crate::solver::calibrate::Calibration;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The file's name beside `calibration.json`.
pub const BOARD_JSON: &str = "board.json";
/// The `format` tag that marks the file.
pub const FORMAT: &str = "deformcal-board";
/// Largest `board.json` read (a 1000 × 1000 board is about 100 MB).
const MAX_BYTES: u64 = 256 << 20;

/// The file's contents.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoardJson {
    pub format: String,
    pub version: u32,
    /// The method that measured the board.
    pub method: String,
    pub rows: usize,
    pub cols: usize,
    pub spacing: f64,
    /// Images the measurement used.
    pub images: usize,
    /// The corners whose correction fixed the gauge (their σ is 0).
    pub gauge_corners: Vec<usize>,
    /// Δx, Δy, Δz per corner in metres, relative to the nominal grid.
    pub correction: Vec<[f64; 3]>,
    /// 1σ of each correction value in metres (the diagonal of its covariance,
    /// σ̂²(JᵀJ)⁻¹ with the gauge fixed); absent when the data could not give it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction_std: Option<Vec<[f64; 3]>>,
}

/// The board a calibration measured, if its method estimates a correction:
/// its correction on top of the geometry it started from, and that correction's σ.
pub fn of(c: &Calibration) -> Option<BoardJson> {
    if !c.method.has_correction() {
        return None;
    }
    let t = c.dataset.target;
    let base = c.settings.board.geometry.as_ref();
    let correction = c
        .state
        .corrections
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let g = base.map(|g| g.correction[i]).unwrap_or([0.0; 3]);
            [g[0] + d[0], g[1] + d[1], g[2] + d[2]]
        })
        .collect();
    // The σ at unit noise came out of the calibration's covariance pass, with
    // its intrinsics' Σ_θ (none when that pass eliminated the corrections, as
    // with 25 images): nothing is evaluated again here.
    let noise = c.assessment.trust.map(|t| t.noise_px);
    let unit = c
        .covariance
        .as_ref()
        .ok()
        .and_then(|cov| cov.correction_std.as_ref());
    let correction_std = noise
        .zip(unit)
        .map(|(noise, unit)| unit.iter().map(|s| s.map(|v| v * noise)).collect());
    Some(BoardJson {
        format: FORMAT.into(),
        version: 1,
        method: c.method.name().into(),
        rows: t.rows,
        cols: t.cols,
        spacing: t.spacing,
        images: c.dataset.num_frames(),
        gauge_corners: c.gauge.clone(),
        correction,
        correction_std,
    })
}

/// Writes `board.json` into `dir` when the calibration measured the board.
pub fn write(dir: &Path, c: &Calibration) -> Result<()> {
    match of(c) {
        Some(b) => write_file(&dir.join(BOARD_JSON), &b),
        None => Ok(()),
    }
}

/// Writes a measured board to `path` (the protocol's reference board too).
pub fn write_file(path: &Path, b: &BoardJson) -> Result<()> {
    let text = serde_json::to_string_pretty(b).expect("board serialises");
    write_atomic(path, text.as_bytes())
}

/// Reads a `board.json` for a calibration of board `target`: refused unless it is
/// one, of the same board, with a finite correction per corner.
pub fn read(path: &Path, target: &Target) -> Result<BoardGeometry> {
    let err = |message: String| Error::Config {
        path: path.into(),
        message,
    };
    let bytes = read_limited(path, MAX_BYTES)?;
    let b: BoardJson =
        serde_json::from_slice(&bytes).map_err(|e| err(format!("not a board.json ({e})")))?;
    if b.format != FORMAT || b.version != 1 {
        return Err(err(format!(
            "format `{}` version {} is not `{FORMAT}` version 1",
            b.format, b.version
        )));
    }
    if (b.rows, b.cols) != (target.rows, target.cols)
        || (b.spacing - target.spacing).abs() > 1e-9 * target.spacing.abs().max(1.0)
    {
        return Err(err(format!(
            "measures a {} × {} board of spacing {} m, but [target] is {} × {} of {} m",
            b.rows, b.cols, b.spacing, target.rows, target.cols, target.spacing
        )));
    }
    let n = target.num_corners();
    let std = b.correction_std.clone().unwrap_or_default();
    if b.correction.len() != n || !(std.is_empty() || std.len() == n) {
        return Err(err(format!(
            "has {} corrections and {} deviations; the board has {n} corners",
            b.correction.len(),
            std.len()
        )));
    }
    // A corner moved by half a square or more would be another corner: such a
    // value is a broken file, and one near f64::MAX overflows the residuals
    // ("evaluation failed" with no file named). The same bound holds a σ.
    let limit = target.spacing / 2.0;
    for (key, values, lowest) in [
        ("correction", &b.correction, -limit),
        ("correction_std", &std, 0.0),
    ] {
        if let Some((i, v)) = values
            .iter()
            .enumerate()
            .find(|(_, v)| !v.iter().all(|&x| x >= lowest && x.abs() <= limit))
        {
            let shown: Vec<String> = v.iter().map(|&x| number(x)).collect();
            return Err(err(format!(
                "{key}[{i}] (corner {i}, row {}, col {}) is [{}] m; each value must be finite{} and at most half the spacing ({} m)",
                i / target.cols,
                i % target.cols,
                shown.join(", "),
                if lowest == 0.0 { ", non-negative" } else { "" },
                number(limit)
            )));
        }
    }
    Ok(BoardGeometry {
        target: *target,
        correction: b.correction,
        correction_std: std,
    })
}

#[cfg(test)]
mod tests {
    use crate::model::board::Method;
    use crate::model::synthetic::{Generator, Preset};
    use crate::solver::calibrate::{calibrate, Request};
    use crate::solver::problem::{SolverSettings, JACOBIANS};

    /// `board.json`'s σ is the calibration's covariance pass's, bit for bit,
    /// scaled by the noise, and reading it evaluates nothing.
    #[test]
    fn board_json_reads_the_sigma_of_the_covariance_pass() {
        let (dataset, _) = Generator::new(Preset::T2, Some(100), 34).generate();
        let request = Request {
            method: Method::Static,
            settings: SolverSettings::default(),
            gauge: None,
        };
        let c = calibrate(&dataset, &request).unwrap();
        let before = JACOBIANS.with(|n| n.get());
        let board = super::of(&c).unwrap();
        assert_eq!(
            JACOBIANS.with(|n| n.get()),
            before,
            "board.json evaluated again"
        );
        let unit = c.covariance.as_ref().unwrap().correction_std.clone();
        assert!(unit.is_some(), "100 images keep the corrections");
        let noise = c.assessment.trust.unwrap().noise_px;
        let scaled = unit.map(|u| u.iter().map(|s| s.map(|v| v * noise)).collect::<Vec<_>>());
        assert_eq!(board.correction_std, scaled);
    }
}
