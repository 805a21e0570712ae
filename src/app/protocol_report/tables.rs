//! The report's tables: train and test error, intrinsics, mapping error, bends,
//! the uncertainty check and the failed tasks.
#[allow(unused_imports)]
use super::figures::*;
#[allow(unused_imports)]
use super::summary::*;
use crate::app::html_report::page::Table;
use crate::app::protocol::{Header, Row};
use crate::model::board::Method;
use crate::model::metrics::Stat;
use std::fmt::Write;

pub(super) fn pm(s: Option<&Stat>, scale: f64, digits: usize) -> String {
    match s {
        Some(s) => format!(
            "{:.*} ± {:.*}",
            digits,
            s.mean * scale,
            digits,
            s.std * scale
        ),
        None => "–".into(),
    }
}

/// The report's opening paragraphs: the dataset, the protocol's sizes, the reference.
pub(super) fn intro(h: &Header) -> Vec<String> {
    let cams: Vec<String> = h
        .cameras
        .iter()
        .map(|c| format!("{} {}×{}", c.name, c.width, c.height))
        .collect();
    let mut out = vec![format!(
        "{} subsets × {} images drawn from {} images (seed {}); board {} × {} corners, {} m; camera(s) {}.",
        h.subsets, h.images_per_subset, h.dataset_images, h.seed, h.target.rows, h.target.cols, h.target.spacing, cams.join(", ")
    )];
    if let Some(r) = &h.reference {
        out.push(format!(
            "Reference calibration: `static` on {} images ({} observations), RMSE {:.4} px{}; its intrinsics are in the intrinsics table{}.",
            r.images,
            r.observations,
            r.rmse_px,
            if r.converged {
                ""
            } else {
                " (did not converge)"
            },
            if r.board.is_some() {
                format!(
                    ", its static correction in `{}` (`board.json`'s format: `[target] geometry` reads it)",
                    crate::app::protocol::REFERENCE_BOARD_JSON
                )
            } else {
                String::new()
            }
        ));
    }
    if h.truth.is_some() {
        out.push("Synthetic data: the true intrinsics are in the intrinsics table.".into());
    }
    out
}

/// The train and test error table (paper Fig. 3a).
pub(super) fn rmse_table(summary: &Summary) -> Table {
    let h = &summary.header;
    let mut head: Vec<String> = vec![
        "method".into(),
        "calibrations (failed)".into(),
        "train RMSE (px)".into(),
    ];
    head.extend(h.cameras.iter().map(|c| {
        if h.cameras.len() > 1 {
            format!("test RMSE {} (px)", c.name)
        } else {
            "test RMSE (px)".into()
        }
    }));
    let rows = h
        .methods
        .iter()
        .map(|&m| {
            let ms = &summary.methods[m.name()];
            let mut row = vec![
                m.to_string(),
                format!("{} ({})", ms.calibrations, ms.failed),
                pm(stat(summary, m, "rmse_px"), 1.0, 4),
            ];
            row.extend(
                (0..h.cameras.len())
                    .map(|k| pm(stat(summary, m, &camera_key(h, k, "test_rmse_px")), 1.0, 4)),
            );
            row
        })
        .collect();
    Table {
        title: "Train and test error (paper Fig. 3a)".into(),
        head,
        rows,
        figures: vec![figure(
            "rmse.svg",
            "train and test RMSE",
            "One dot per subset; bars: mean ± standard deviation. Train: the RMSE √(Σ‖u − p‖² / N) of the \
             subset's own observations. Test: the RMSE on the reference set with the subset's intrinsics held \
             and only the board poses fitted.",
        )],
    }
}

/// The intrinsics of camera k: every parameter per method, with the reference and
/// the truth (paper Fig. 4a).
pub(super) fn intrinsics_table(summary: &Summary, k: usize) -> Table {
    let h = &summary.header;
    let cam = &h.cameras[k];
    let names = cam.model.param_names();
    let mut head = vec!["method".to_string()];
    head.extend(
        names
            .iter()
            .map(|n| format!("{n} ({})", param_unit(cam.model, n))),
    );
    let mut rows: Vec<Vec<String>> = h
        .methods
        .iter()
        .map(|&m| {
            let mut row = vec![m.to_string()];
            row.extend(names.iter().map(|n| {
                pm(
                    stat(summary, m, &camera_key(h, k, n)),
                    1.0,
                    param_digits(cam.model, n),
                )
            }));
            row
        })
        .collect();
    let fixed = |label: &str, i: &crate::model::lens::Intrinsics| {
        let mut row = vec![label.to_string()];
        row.extend(names.iter().map(|n| {
            i.get(n)
                .map(|v| format!("{v:.*}", param_digits(cam.model, n)))
                .unwrap_or_else(|| "–".into())
        }));
        row
    };
    if let Some(i) = h.reference.as_ref().and_then(|r| r.intrinsics.get(k)) {
        rows.push(fixed("reference", i));
    }
    if let Some(i) = h.truth.as_ref().and_then(|t| t.get(k)) {
        rows.push(fixed("truth", i));
    }
    let title = if h.cameras.len() > 1 {
        format!("Intrinsics of {} (paper Fig. 4a)", cam.name)
    } else {
        "Intrinsics (paper Fig. 4a)".into()
    };
    Table {
        title,
        head,
        rows,
        figures: Vec::new(),
    }
}

/// Every camera's intrinsics tables, the last one with the intrinsics figure.
pub(super) fn intrinsics_tables(summary: &Summary) -> Vec<Table> {
    let mut tables: Vec<Table> = (0..summary.header.cameras.len())
        .map(|k| intrinsics_table(summary, k))
        .collect();
    if let Some(last) = tables.last_mut() {
        last.figures.push(figure(
            "intrinsics.svg",
            "intrinsics",
            "Every intrinsic parameter of every camera, one panel each: one dot per subset, bars mean ± \
             standard deviation; lines: the reference calibration and, for synthetic data, the truth. \
             fx, fy, cx, cy in pixels; distortion coefficients unitless.",
        ));
    }
    tables
}

/// Rows of a per-camera × method table of `metrics`, with `digits` decimals.
pub(super) fn camera_rows(summary: &Summary, metrics: &[&str], digits: usize) -> Vec<Vec<String>> {
    let h = &summary.header;
    let mut rows = Vec::new();
    for k in 0..h.cameras.len() {
        for &m in &h.methods {
            let mut row = vec![row_label(h, m, k)];
            row.extend(
                metrics
                    .iter()
                    .map(|n| pm(stat(summary, m, &camera_key(h, k, n)), 1.0, digits)),
            );
            rows.push(row);
        }
    }
    rows
}

/// The mapping error table (paper Fig. 4b).
pub(super) fn mapping_table(summary: &Summary) -> Table {
    Table {
        title: "Mapping error (paper Fig. 4b)".into(),
        head: [
            "method",
            "to reference (px)",
            "to reference, rotation removed (px)",
            "to truth (px)",
            "to truth, rotation removed (px)",
        ]
        .map(String::from)
        .to_vec(),
        rows: camera_rows(
            summary,
            &[
                "mapping_error_px",
                "mapping_error_rot_px",
                "truth_mapping_error_px",
                "truth_mapping_error_rot_px",
            ],
            3,
        ),
        figures: vec![figure(
            "mapping.svg",
            "mapping error",
            "Mapping error: a 20 px grid over the image unprojected with the subset's intrinsics and \
             projected with the reference's (or the truth's); the RMSE of the pixel differences. \
             \"Rotation removed\": after the best virtual camera rotation, which is no calibration error.",
        )],
    }
}

/// The out-of-plane deformation table (paper Table S2) with its figures, if any method bends.
pub(super) fn bending_table(summary: &Summary, rows: &[Row]) -> Option<Table> {
    let bending: Vec<Method> = summary
        .header
        .methods
        .iter()
        .copied()
        .filter(|m| m.has_paraboloid())
        .collect();
    if bending.is_empty() {
        return None;
    }
    let table_rows = bending
        .iter()
        .map(|&m| {
            vec![
                m.to_string(),
                pm(stat(summary, m, "max_out_of_plane_m"), 1e3, 3),
            ]
        })
        .collect();
    let mut figures = vec![figure(
        "bend.svg",
        "largest bend per image",
        "The largest out-of-plane deflection of every image of every subset, max over the corners of \
         |a·x² + b·y² + c·xy|, in mm; bars: mean ± standard deviation.",
    )];
    if let Some((r, j)) = most_bent(rows) {
        figures.push(figure(
            "deformation.svg",
            "deformation of one image",
            &format!(
                "The estimated bend Δz of frame {} in subset {} (`{}`), the most bent image of the first subset (paper Fig. 1).",
                r.frames[j], r.subset, r.method
            ),
        ));
    }
    Some(Table {
        title: "Maximum out-of-plane deformation per image (paper Table S2)".into(),
        head: vec!["method".into(), "max out-of-plane (mm)".into()],
        rows: table_rows,
        figures,
    })
}

/// RMS of the finite values (`None` without any).
pub(super) fn rms(values: impl Iterator<Item = f64>) -> Option<f64> {
    let v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    (!v.is_empty()).then(|| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt())
}

/// RMS over the rows of camera `k`'s mapping error to the rows' mean intrinsics:
/// the spread of the calibrations among themselves, which needs no truth.
pub(super) fn spread_around_mean(h: &Header, rows: &[&Row], k: usize) -> Option<f64> {
    let cam = &h.cameras[k];
    let all: Vec<&crate::model::lens::Intrinsics> = rows
        .iter()
        .filter_map(|r| r.cameras.get(k).map(|c| &c.intrinsics))
        .filter(|i| i.model() == cam.model)
        .collect();
    let first = all.first()?;
    let mut mean = **first;
    for (i, p) in mean.params_mut().iter_mut().enumerate() {
        *p = all.iter().map(|x| x.params()[i]).sum::<f64>() / all.len() as f64;
    }
    // The mean's grid unprojected once, not once per subset (that was most of
    // the time spent writing the outputs).
    let rays = crate::model::metrics::grid_rays(&mean, cam.width, cam.height);
    rms(all
        .iter()
        .map(|x| crate::model::metrics::mapping_error_of(&rays, x)))
}

/// "x.xxx (r.rr×)": an observed RMS and its ratio to the predicted one.
pub(super) fn observed(value: Option<f64>, predicted: Option<f64>) -> String {
    match (value, predicted) {
        (Some(v), Some(p)) if p > 0.0 => format!("{v:.3} ({:.2}×)", v / p),
        (Some(v), _) => format!("{v:.3}"),
        _ => "–".into(),
    }
}

/// Predicted against observed spread (docs/conventions.md §3a): the expected mapping error of
/// each subset's calibration beside the mapping errors the subsets actually show.
pub(super) fn write_uncertainty(s: &mut String, summary: &Summary, rows: &[Row]) {
    let h = &summary.header;
    let truth = h.truth.is_some();
    let _ = writeln!(
        s,
        "### Predicted and observed spread
"
    );
    let _ = writeln!(
        s,
        "| method | bias ratio | predicted: expected mapping error, RMS (px) |{} around the mean calibration, RMS (px) |\n|---|---|---|---|{}",
        if truth { " to truth, RMS (px) |" } else { "" },
        if truth { "---|" } else { "" }
    );
    for k in 0..h.cameras.len() {
        for &m in &h.methods {
            let ok: Vec<&Row> = rows.iter().filter(|r| r.is_fixed(m) && r.ok()).collect();
            let of =
                |get: CameraGetter| rms(ok.iter().filter_map(|r| r.cameras.get(k).and_then(get)));
            let predicted = of(|c| c.expected_mapping_error_px);
            let to_truth = if truth {
                format!(
                    " {} |",
                    observed(of(|c| c.truth_mapping_error_px), predicted)
                )
            } else {
                String::new()
            };
            let _ = writeln!(
                s,
                "| {} | {} | {} |{to_truth} {} |",
                row_label(h, m, k),
                pm(stat(summary, m, "bias_ratio"), 1.0, 3),
                predicted.map_or("–".into(), |p| format!("{p:.3}")),
                observed(spread_around_mean(h, &ok, k), predicted)
            );
        }
    }
    let _ = writeln!(
        s,
        "\nThe expected mapping error is what the detector noise alone leaves between a calibration and the truth \
         (docs/conventions.md §3a); the ratios are observed / predicted. Near 1 to the truth: the noise explains the error. Far above: \
         a bias the model does not capture (a bias ratio above 0.1 says the same from the residuals). Around the mean \
         calibration the subsets' bias is shared and cancels, and subsets that share images scatter less.\n"
    );
}

/// The failed calibrations and their reasons, if any.
pub(super) fn failed_table(rows: &[Row]) -> Option<Table> {
    let failed: Vec<Vec<String>> = rows
        .iter()
        .filter(|r| !r.ok())
        .map(|r| {
            vec![
                r.subset.to_string(),
                r.label().to_string(),
                r.error.as_deref().unwrap_or("").replace('|', "/"),
            ]
        })
        .collect();
    (!failed.is_empty()).then(|| Table {
        title: "Failed calibrations".into(),
        head: vec!["subset".into(), "method".into(), "reason".into()],
        rows: failed,
        figures: Vec::new(),
    })
}
