//! `protocol.csv` (one line per task) and `deformations.csv` (one line per bent image).
#[allow(unused_imports)]
use super::summary::*;
use crate::app::protocol::{Header, Row};
use crate::error::{Error, Result};
use crate::model::metrics::Stat;
use std::fmt::Write;

pub(super) fn cell(v: Option<f64>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

/// `protocol.csv`: one row per subset × method (× camera, with several cameras).
pub fn protocol_csv(header: &Header, rows: &[Row]) -> Result<Vec<u8>> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let to_err = |e: csv::Error| Error::Invalid(format!("protocol.csv: {e}"));
    let mut columns = vec![
        "subset",
        "method",
        "camera",
        "status",
        "error",
        "images",
        "observations",
        "converged",
        "iterations",
        "rmse_px",
        "bias_ratio",
        "auto_choice",
    ];
    columns.extend(CAMERA_METRICS.iter().map(|(n, _)| *n));
    columns.extend(["max_out_of_plane_m_mean", "max_out_of_plane_m_max"]);
    let intrinsics = intrinsics_columns(header);
    columns.extend(intrinsics.iter().copied());
    // The `[sfm]` columns only where the protocol ran the experiment.
    let sfm = rows
        .iter()
        .any(|r| r.loop_closure_px.is_some() || r.sfm_error.is_some());
    if sfm {
        columns.extend(["loop_closure_px", "sfm_error"]);
    }
    w.write_record(&columns).map_err(to_err)?;
    for r in rows {
        let bends = Stat::of(r.max_out_of_plane_m.iter().copied()).map(|s| s.mean);
        let max_bend = r.max_out_of_plane_m.iter().copied().reduce(f64::max);
        for (k, cam) in header.cameras.iter().enumerate() {
            let c = r.cameras.get(k);
            let mut rec = vec![
                r.subset.to_string(),
                r.label().to_string(),
                cam.name.clone(),
                if r.ok() { "ok" } else { "failed" }.to_string(),
                r.error.clone().unwrap_or_default(),
                r.images.to_string(),
                r.observations.to_string(),
                r.converged.to_string(),
                r.iterations.to_string(),
                cell(r.rmse_px),
                cell(r.bias_ratio),
                if r.auto && r.ok() {
                    r.method.name()
                } else {
                    ""
                }
                .to_string(),
            ];
            rec.extend(CAMERA_METRICS.iter().map(|(_, get)| cell(c.and_then(get))));
            rec.extend([cell(bends), cell(max_bend)]);
            rec.extend(
                intrinsics
                    .iter()
                    .map(|name| cell(c.and_then(|c| c.intrinsics.get(name)))),
            );
            if sfm {
                rec.extend([
                    cell(r.loop_closure_px),
                    r.sfm_error.clone().unwrap_or_default(),
                ]);
            }
            w.write_record(&rec).map_err(to_err)?;
        }
    }
    w.into_inner()
        .map_err(|e| Error::Invalid(format!("protocol.csv: {e}")))
}

/// `deformations.csv`: the paraboloid of every image of every subset × method.
pub fn deformations_csv(rows: &[Row]) -> Vec<u8> {
    let mut s = String::from("subset,method,frame,a,b,c,max_out_of_plane_m\n");
    for r in rows {
        for ((f, d), m) in r
            .frames
            .iter()
            .zip(&r.deformations)
            .zip(&r.max_out_of_plane_m)
        {
            let _ = writeln!(
                s,
                "{},{},{f},{},{},{},{m}",
                r.subset,
                r.label(),
                d.a,
                d.b,
                d.c
            );
        }
    }
    s.into_bytes()
}
