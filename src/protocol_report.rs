//! Protocol outputs: `protocol.csv`, `deformations.csv`, `summary.json`, `report.md`
//! and its SVG plots. Written from the merged rows alone, so a sharded run and
//! its merge write exactly what one unsharded run writes.
use crate::deformation::Method;
use crate::error::{Error, Result};
use crate::output::write_atomic;
use crate::plots::{self, HLine, Series, PALETTE};
use crate::protocol::{Header, Row};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::Path;

/// Mean and sample standard deviation of a metric.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Stat {
    pub mean: f64,
    pub std: f64,
    pub n: usize,
}

impl Stat {
    /// Statistics of the finite values; `None` when there are none.
    pub fn of(values: impl IntoIterator<Item = f64>) -> Option<Stat> {
        let v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let std = if v.len() > 1 {
            (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
        } else {
            0.0
        };
        Some(Stat {
            mean,
            std,
            n: v.len(),
        })
    }
}

/// Per-method block of `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MethodSummary {
    pub calibrations: usize,
    pub failed: usize,
    pub not_converged: usize,
    /// Metric name → statistics over the successful subsets.
    pub metrics: BTreeMap<String, Stat>,
}

/// `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub header: Header,
    pub methods: BTreeMap<String, MethodSummary>,
}

type Getter = fn(&Row) -> Vec<f64>;

fn opt(v: Option<f64>) -> Vec<f64> {
    v.into_iter().collect()
}

/// The metrics summarised per method, in report order.
const METRICS: [(&str, Getter); 15] = [
    ("rmse_px", |r| opt(r.rmse_px)),
    ("test_rmse_px", |r| opt(r.test_rmse_px)),
    ("mapping_error_px", |r| opt(r.mapping_error_px)),
    ("mapping_error_rot_px", |r| opt(r.mapping_error_rot_px)),
    ("truth_mapping_error_px", |r| opt(r.truth_mapping_error_px)),
    ("truth_mapping_error_rot_px", |r| {
        opt(r.truth_mapping_error_rot_px)
    }),
    ("max_out_of_plane_m", |r| r.max_out_of_plane_m.clone()),
    ("fx", |r| opt(r.intrinsics.map(|k| k.fx))),
    ("fy", |r| opt(r.intrinsics.map(|k| k.fy))),
    ("cx", |r| opt(r.intrinsics.map(|k| k.cx))),
    ("cy", |r| opt(r.intrinsics.map(|k| k.cy))),
    ("k1", |r| opt(r.intrinsics.map(|k| k.k1))),
    ("k2", |r| opt(r.intrinsics.map(|k| k.k2))),
    ("k3", |r| opt(r.intrinsics.map(|k| k.k3))),
    ("iterations", |r| vec![r.iterations as f64]),
];

/// Summarises rows per method.
pub fn summarise(header: &Header, rows: &[Row]) -> Summary {
    let mut methods = BTreeMap::new();
    for &m in &header.methods {
        let all: Vec<&Row> = rows.iter().filter(|r| r.method == m).collect();
        let ok: Vec<&Row> = all.iter().copied().filter(|r| r.ok()).collect();
        let mut metrics = BTreeMap::new();
        for (name, get) in METRICS {
            if let Some(s) = Stat::of(ok.iter().flat_map(|r| get(r))) {
                metrics.insert(name.to_string(), s);
            }
        }
        methods.insert(
            m.name().to_string(),
            MethodSummary {
                calibrations: all.len(),
                failed: all.len() - ok.len(),
                not_converged: ok.iter().filter(|r| !r.converged).count(),
                metrics,
            },
        );
    }
    Summary {
        header: header.clone(),
        methods,
    }
}

fn cell(v: Option<f64>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

/// `protocol.csv`: one row per subset × method.
pub fn protocol_csv(rows: &[Row]) -> Result<Vec<u8>> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let to_err = |e: csv::Error| Error::Invalid(format!("protocol.csv: {e}"));
    w.write_record([
        "subset",
        "method",
        "status",
        "error",
        "images",
        "observations",
        "converged",
        "iterations",
        "rmse_px",
        "test_rmse_px",
        "mapping_error_px",
        "mapping_error_rot_px",
        "truth_mapping_error_px",
        "truth_mapping_error_rot_px",
        "max_out_of_plane_m_mean",
        "max_out_of_plane_m_max",
        "fx",
        "fy",
        "cx",
        "cy",
        "k1",
        "k2",
        "k3",
    ])
    .map_err(to_err)?;
    for r in rows {
        let bends = Stat::of(r.max_out_of_plane_m.iter().copied()).map(|s| s.mean);
        let max_bend = r.max_out_of_plane_m.iter().copied().reduce(f64::max);
        let k = r.intrinsics;
        let mut rec = vec![
            r.subset.to_string(),
            r.method.name().to_string(),
            if r.ok() { "ok" } else { "failed" }.to_string(),
            r.error.clone().unwrap_or_default(),
            r.images.to_string(),
            r.observations.to_string(),
            r.converged.to_string(),
            r.iterations.to_string(),
        ];
        rec.extend(
            [
                r.rmse_px,
                r.test_rmse_px,
                r.mapping_error_px,
                r.mapping_error_rot_px,
                r.truth_mapping_error_px,
                r.truth_mapping_error_rot_px,
                bends,
                max_bend,
                k.map(|k| k.fx),
                k.map(|k| k.fy),
                k.map(|k| k.cx),
                k.map(|k| k.cy),
                k.map(|k| k.k1),
                k.map(|k| k.k2),
                k.map(|k| k.k3),
            ]
            .into_iter()
            .map(cell),
        );
        w.write_record(&rec).map_err(to_err)?;
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
                r.subset, r.method, d.a, d.b, d.c
            );
        }
    }
    s.into_bytes()
}

fn pm(s: Option<&Stat>, scale: f64, digits: usize) -> String {
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

fn groups(header: &Header, rows: &[Row], get: Getter) -> Vec<Vec<f64>> {
    header
        .methods
        .iter()
        .map(|&m| {
            rows.iter()
                .filter(|r| r.method == m && r.ok())
                .flat_map(get)
                .collect()
        })
        .collect()
}

/// The report's markdown for one dataset; `prefix` is prepended to plot links.
pub fn report_markdown(summary: &Summary, rows: &[Row], prefix: &str) -> String {
    let h = &summary.header;
    let mut s = String::new();
    let get = |m: Method, k: &str| summary.methods.get(m.name()).and_then(|x| x.metrics.get(k));
    let _ = writeln!(s, "## Dataset `{}`\n", h.dataset);
    let _ = writeln!(
        s,
        "{} subsets × {} images drawn from {} images (seed {}); board {} × {} corners, {} m; camera {}×{}.\n",
        h.subsets, h.images_per_subset, h.dataset_images, h.seed, h.target.rows, h.target.cols, h.target.spacing, h.width, h.height
    );
    if let Some(r) = &h.reference {
        let _ = writeln!(
            s,
            "Reference calibration: `static` on {} images ({} observations), RMSE {:.4} px{}; fx {:.2}, fy {:.2}, cx {:.2}, cy {:.2}.\n",
            r.images,
            r.observations,
            r.rmse_px,
            if r.converged { "" } else { " (did not converge)" },
            r.intrinsics.fx,
            r.intrinsics.fy,
            r.intrinsics.cx,
            r.intrinsics.cy
        );
    }
    if let Some(t) = &h.truth {
        let _ = writeln!(
            s,
            "Ground truth (synthetic): fx {:.2}, fy {:.2}, cx {:.2}, cy {:.2}.\n",
            t.fx, t.fy, t.cx, t.cy
        );
    }
    let _ = writeln!(s, "### Train and test error (paper Fig. 3a)\n");
    let _ = writeln!(
        s,
        "| method | calibrations (failed) | train RMSE (px) | test RMSE (px) |\n|---|---|---|---|"
    );
    for &m in &h.methods {
        let ms = &summary.methods[m.name()];
        let _ = writeln!(
            s,
            "| {m} | {} ({}) | {} | {} |",
            ms.calibrations,
            ms.failed,
            pm(get(m, "rmse_px"), 1.0, 4),
            pm(get(m, "test_rmse_px"), 1.0, 4)
        );
    }
    let _ = writeln!(s, "\n![train and test RMSE]({prefix}rmse.svg)\n");
    let _ = writeln!(s, "### Intrinsics (paper Fig. 4a)\n");
    let _ = writeln!(
        s,
        "| method | fx (px) | fy (px) | cx (px) | cy (px) |\n|---|---|---|---|---|"
    );
    for &m in &h.methods {
        let _ = writeln!(
            s,
            "| {m} | {} | {} | {} | {} |",
            pm(get(m, "fx"), 1.0, 2),
            pm(get(m, "fy"), 1.0, 2),
            pm(get(m, "cx"), 1.0, 2),
            pm(get(m, "cy"), 1.0, 2)
        );
    }
    let _ = writeln!(s, "\n![fx and cx]({prefix}intrinsics.svg)\n");
    let _ = writeln!(s, "### Mapping error (paper Fig. 4b)\n");
    let _ = writeln!(
        s,
        "| method | to reference (px) | to reference, rotation removed (px) | to truth (px) | to truth, rotation removed (px) |\n|---|---|---|---|---|"
    );
    for &m in &h.methods {
        let _ = writeln!(
            s,
            "| {m} | {} | {} | {} | {} |",
            pm(get(m, "mapping_error_px"), 1.0, 3),
            pm(get(m, "mapping_error_rot_px"), 1.0, 3),
            pm(get(m, "truth_mapping_error_px"), 1.0, 3),
            pm(get(m, "truth_mapping_error_rot_px"), 1.0, 3)
        );
    }
    let _ = writeln!(s, "\n![mapping error]({prefix}mapping.svg)\n");
    let bending: Vec<Method> = h
        .methods
        .iter()
        .copied()
        .filter(|m| m.has_paraboloid())
        .collect();
    if !bending.is_empty() {
        let _ = writeln!(
            s,
            "### Maximum out-of-plane deformation per image (paper Table S2)\n"
        );
        let _ = writeln!(s, "| method | max out-of-plane (mm) |\n|---|---|");
        for m in bending {
            let _ = writeln!(s, "| {m} | {} |", pm(get(m, "max_out_of_plane_m"), 1e3, 3));
        }
        if let Some((r, j)) = most_bent(rows) {
            let _ = writeln!(
                s,
                "\n![deformation of one image]({prefix}deformation.svg)\n\nThe estimated bend of frame {} in subset {} (`{}`), the most bent image of the first subset (paper Fig. 1).\n",
                r.frames[j], r.subset, r.method
            );
        }
    }
    let failed: Vec<&Row> = rows.iter().filter(|r| !r.ok()).collect();
    if !failed.is_empty() {
        let _ = writeln!(
            s,
            "### Failed calibrations\n\n| subset | method | reason |\n|---|---|---|"
        );
        for r in failed {
            let reason = r.error.as_deref().unwrap_or("").replace('|', "/");
            let _ = writeln!(s, "| {} | {} | {reason} |", r.subset, r.method);
        }
        s.push('\n');
    }
    s
}

/// The row and image whose bend the Fig. 1 plot shows: `full` (else `dynamic`) of the
/// first subset that has one, its most bent image.
fn most_bent(rows: &[Row]) -> Option<(&Row, usize)> {
    let pick = |m: Method| {
        rows.iter()
            .filter(|r| r.ok() && r.method == m && !r.deformations.is_empty())
            .min_by_key(|r| r.subset)
    };
    let r = pick(Method::Full).or_else(|| pick(Method::Dynamic))?;
    let j = (0..r.max_out_of_plane_m.len())
        .max_by(|&a, &b| r.max_out_of_plane_m[a].total_cmp(&r.max_out_of_plane_m[b]))?;
    Some((r, j))
}

/// Writes the SVG plots of one dataset into `dir`.
pub fn write_plots(dir: &Path, summary: &Summary, rows: &[Row]) -> Result<()> {
    let h = &summary.header;
    let cats: Vec<String> = h.methods.iter().map(|m| m.name().to_string()).collect();
    let series = |name: &'static str, color, get: Getter| Series {
        name,
        color,
        groups: groups(h, rows, get),
    };
    plots::strip_chart_svg(
        &dir.join("rmse.svg"),
        &format!("{}: train and test RMSE", h.dataset),
        "RMSE (px)",
        &cats,
        &[
            series("train", PALETTE[0], |r| opt(r.rmse_px)),
            series("test", PALETTE[1], |r| opt(r.test_rmse_px)),
        ],
        &[],
    )?;
    let ref_lines = |f: fn(&crate::camera::Intrinsics) -> f64| {
        let mut lines = Vec::new();
        if let Some(r) = &h.reference {
            lines.push(HLine {
                value: f(&r.intrinsics),
                name: "reference",
                color: BLACK_RGB,
            });
        }
        if let Some(t) = &h.truth {
            lines.push(HLine {
                value: f(t),
                name: "truth",
                color: PALETTE[3],
            });
        }
        lines
    };
    let fx_lines = ref_lines(|k| k.fx);
    let cx_lines = ref_lines(|k| k.cx);
    plots::panels_svg(
        &dir.join("intrinsics.svg"),
        &[
            (
                "fx",
                "fx (px)",
                vec![series("fx", PALETTE[0], |r| {
                    opt(r.intrinsics.map(|k| k.fx))
                })],
                fx_lines,
            ),
            (
                "cx",
                "cx (px)",
                vec![series("cx", PALETTE[2], |r| {
                    opt(r.intrinsics.map(|k| k.cx))
                })],
                cx_lines,
            ),
        ],
        &cats,
    )?;
    let mut mapping = Vec::new();
    if h.reference.is_some() {
        mapping.push(series("to reference", PALETTE[0], |r| {
            opt(r.mapping_error_px)
        }));
    }
    if h.truth.is_some() {
        mapping.push(series("to truth", PALETTE[3], |r| {
            opt(r.truth_mapping_error_px)
        }));
        mapping.push(series("to truth, rotation removed", PALETTE[2], |r| {
            opt(r.truth_mapping_error_rot_px)
        }));
    }
    plots::strip_chart_svg(
        &dir.join("mapping.svg"),
        &format!("{}: mapping error", h.dataset),
        "mapping error (px)",
        &cats,
        &mapping,
        &[],
    )?;
    if let Some((r, j)) = most_bent(rows) {
        plots::deformation_svg(
            &dir.join("deformation.svg"),
            &format!(
                "{}: frame {} of subset {} ({}), max |Δz| {:.2} mm",
                h.dataset,
                r.frames[j],
                r.subset,
                r.method,
                r.max_out_of_plane_m[j] * 1e3
            ),
            &h.target,
            &r.deformations[j],
        )?;
    }
    Ok(())
}

const BLACK_RGB: plotters::style::RGBColor = plotters::style::RGBColor(0, 0, 0);

/// Writes every protocol output of one dataset into `dir`.
pub fn write_outputs(dir: &Path, header: &Header, rows: &[Row]) -> Result<Summary> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let summary = summarise(header, rows);
    write_plots(dir, &summary, rows)?;
    write_atomic(&dir.join("protocol.csv"), &protocol_csv(rows)?)?;
    write_atomic(&dir.join("deformations.csv"), &deformations_csv(rows))?;
    let json = serde_json::to_string_pretty(&summary).expect("summary serialises");
    write_atomic(&dir.join("summary.json"), json.as_bytes())?;
    let report = format!(
        "# deformcal evaluation protocol\n\n{}",
        report_markdown(&summary, rows, "")
    );
    write_atomic(&dir.join("report.md"), report.as_bytes())?;
    Ok(summary)
}
