//! Protocol outputs: `protocol.csv`, `deformations.csv`, `summary.json`, the
//! report's tables and SVG plots, written as `report.md` and `report.html`.
//! Written from the merged rows alone, so a sharded run and its merge write
//! exactly what one unsharded run writes.
use crate::app::fsio::write_atomic;
use crate::app::html_report::page::{Figure, Table};
use crate::app::html_report::protocol::{protocol_page, DatasetReport};
use crate::app::html_report::REPORT_FILE;
use crate::app::plots::{self, Axes, HLine, Series, PALETTE};
use crate::app::protocol::{CameraRow, Header, Row};
use crate::error::{Error, Result};
use crate::model::board::{Method, HIGHER_BEND_PARAMS};
use crate::model::metrics::Stat;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::Path;

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
    /// Per fixed method, and `auto` (its chosen calibrations) when recorded.
    pub methods: BTreeMap<String, MethodSummary>,
    /// How many subsets `auto` gave to each method.
    #[serde(default)]
    pub auto_choices: BTreeMap<String, usize>,
}

type Getter = fn(&Row) -> Vec<f64>;
type CameraGetter = fn(&CameraRow) -> Option<f64>;

fn opt(v: Option<f64>) -> Vec<f64> {
    v.into_iter().collect()
}

/// Metrics of the whole calibration, summarised per method.
const ROW_METRICS: [(&str, Getter); 5] = [
    ("rmse_px", |r| opt(r.rmse_px)),
    ("loop_closure_px", |r| opt(r.loop_closure_px)),
    ("bias_ratio", |r| opt(r.bias_ratio)),
    ("max_out_of_plane_m", |r| r.max_out_of_plane_m.clone()),
    ("iterations", |r| vec![r.iterations as f64]),
];

/// Metrics of each camera, summarised per method (prefixed `camera/` with several cameras).
const CAMERA_METRICS: [(&str, CameraGetter); 7] = [
    ("test_rmse_px", |c| c.test_rmse_px),
    ("mapping_error_px", |c| c.mapping_error_px),
    ("mapping_error_rot_px", |c| c.mapping_error_rot_px),
    ("truth_mapping_error_px", |c| c.truth_mapping_error_px),
    ("truth_mapping_error_rot_px", |c| {
        c.truth_mapping_error_rot_px
    }),
    ("expected_mapping_error_px", |c| c.expected_mapping_error_px),
    ("expected_mapping_error_rot_px", |c| {
        c.expected_mapping_error_rot_px
    }),
];

/// The intrinsics columns: every camera's lens parameters, each name once, in
/// the order the cameras' models list them.
fn intrinsics_columns(header: &Header) -> Vec<&'static str> {
    let mut out: Vec<&'static str> = Vec::new();
    for cam in &header.cameras {
        for name in cam.model.param_names() {
            if !out.contains(name) {
                out.push(name);
            }
        }
    }
    out
}

/// The summary key of a per-camera metric: bare for one camera, `camera/metric` otherwise.
pub fn camera_key(header: &Header, k: usize, metric: &str) -> String {
    if header.cameras.len() == 1 {
        metric.to_string()
    } else {
        format!("{}/{metric}", header.cameras[k].name)
    }
}

/// Summarises rows per method (and `auto`'s rows under `auto`).
pub fn summarise(header: &Header, rows: &[Row]) -> Summary {
    let mut methods = BTreeMap::new();
    for &m in &header.methods {
        let all: Vec<&Row> = rows.iter().filter(|r| r.is_fixed(m)).collect();
        methods.insert(m.name().to_string(), method_summary(header, &all));
    }
    let mut auto_choices = BTreeMap::new();
    if header.auto.is_some() {
        let all: Vec<&Row> = rows.iter().filter(|r| r.auto).collect();
        methods.insert(AUTO.to_string(), method_summary(header, &all));
        for r in all.iter().filter(|r| r.ok()) {
            *auto_choices.entry(r.method.name().to_string()).or_insert(0) += 1;
        }
    }
    Summary {
        header: header.clone(),
        methods,
        auto_choices,
    }
}

/// The name `auto`'s rows carry in the outputs.
const AUTO: &str = "auto";

/// The statistics of one method's rows.
fn method_summary(header: &Header, all: &[&Row]) -> MethodSummary {
    {
        let ok: Vec<&Row> = all.iter().copied().filter(|r| r.ok()).collect();
        let mut metrics = BTreeMap::new();
        for (name, get) in ROW_METRICS {
            if let Some(s) = Stat::of(ok.iter().flat_map(|r| get(r))) {
                metrics.insert(name.to_string(), s);
            }
        }
        for k in 0..header.cameras.len() {
            for (name, get) in CAMERA_METRICS {
                if let Some(s) = Stat::of(ok.iter().filter_map(|r| r.cameras.get(k).and_then(get)))
                {
                    metrics.insert(camera_key(header, k, name), s);
                }
            }
            for name in header.cameras[k].model.param_names() {
                let values = ok
                    .iter()
                    .filter_map(|r| r.cameras.get(k).and_then(|c| c.intrinsics.get(name)));
                if let Some(s) = Stat::of(values) {
                    metrics.insert(camera_key(header, k, name), s);
                }
            }
        }
        MethodSummary {
            calibrations: all.len(),
            failed: all.len() - ok.len(),
            not_converged: ok.iter().filter(|r| !r.converged).count(),
            metrics,
        }
    }
}

fn cell(v: Option<f64>) -> String {
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

fn groups(header: &Header, rows: &[Row], get: impl Fn(&Row) -> Vec<f64>) -> Vec<Vec<f64>> {
    (0..columns(header).len())
        .map(|i| {
            rows.iter()
                .filter(|r| r.ok() && in_column(header, i, r))
                .flat_map(&get)
                .collect()
        })
        .collect()
}

/// The plots' columns: every fixed method, then `auto` when the run recorded it.
fn columns(h: &Header) -> Vec<String> {
    let mut cats: Vec<String> = h.methods.iter().map(|m| m.name().to_string()).collect();
    if h.auto.is_some() {
        cats.push(AUTO.into());
    }
    cats
}

/// Whether `r` belongs to column `i` of [`columns`].
fn in_column(h: &Header, i: usize, r: &Row) -> bool {
    match h.methods.get(i) {
        Some(&m) => r.is_fixed(m),
        None => r.auto,
    }
}

/// Per-camera values of one metric across rows, grouped per method.
fn camera_groups(
    header: &Header,
    rows: &[Row],
    k: usize,
    get: impl Fn(&CameraRow) -> Option<f64>,
) -> Vec<Vec<f64>> {
    groups(header, rows, |r| {
        r.cameras.get(k).and_then(&get).into_iter().collect()
    })
}

/// A method's statistic of one summary key, if any subset produced it.
fn stat<'a>(summary: &'a Summary, m: Method, key: &str) -> Option<&'a Stat> {
    summary
        .methods
        .get(m.name())
        .and_then(|x| x.metrics.get(key))
}

/// "method" or "method, camera" labels for per-camera table rows.
fn row_label(h: &Header, m: Method, k: usize) -> String {
    if h.cameras.len() > 1 {
        format!("{m}, {}", h.cameras[k].name)
    } else {
        m.to_string()
    }
}

/// The report's opening paragraphs: the dataset, the protocol's sizes, the reference.
fn intro(h: &Header) -> Vec<String> {
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

/// A figure of the report.
fn figure(file: &str, alt: &str, caption: &str) -> Figure {
    Figure {
        file: file.into(),
        alt: alt.into(),
        caption: caption.into(),
    }
}

/// The train and test error table (paper Fig. 3a).
fn rmse_table(summary: &Summary) -> Table {
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

/// Decimals of an intrinsic parameter: pixels to 2, coefficients to 5.
fn param_digits(model: crate::model::lens::LensModel, name: &str) -> usize {
    if model.param_index(name).is_some_and(|i| i < 4) {
        2
    } else {
        5
    }
}

/// The unit of an intrinsic parameter, for headers and axes.
fn param_unit(model: crate::model::lens::LensModel, name: &str) -> &'static str {
    if model.param_index(name).is_some_and(|i| i < 4) {
        "px"
    } else {
        "unitless"
    }
}

/// The intrinsics of camera k: every parameter per method, with the reference and
/// the truth (paper Fig. 4a).
fn intrinsics_table(summary: &Summary, k: usize) -> Table {
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
fn intrinsics_tables(summary: &Summary) -> Vec<Table> {
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
fn camera_rows(summary: &Summary, metrics: &[&str], digits: usize) -> Vec<Vec<String>> {
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
fn mapping_table(summary: &Summary) -> Table {
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
fn bending_table(summary: &Summary, rows: &[Row]) -> Option<Table> {
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
fn rms(values: impl Iterator<Item = f64>) -> Option<f64> {
    let v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    (!v.is_empty()).then(|| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt())
}

/// RMS over the rows of camera `k`'s mapping error to the rows' mean intrinsics:
/// the spread of the calibrations among themselves, which needs no truth.
fn spread_around_mean(h: &Header, rows: &[&Row], k: usize) -> Option<f64> {
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
    let errors = all
        .iter()
        .map(|x| crate::model::metrics::mapping_error(&mean, x, cam.width, cam.height));
    rms(errors)
}

/// "x.xxx (r.rr×)": an observed RMS and its ratio to the predicted one.
fn observed(value: Option<f64>, predicted: Option<f64>) -> String {
    match (value, predicted) {
        (Some(v), Some(p)) if p > 0.0 => format!("{v:.3} ({:.2}×)", v / p),
        (Some(v), _) => format!("{v:.3}"),
        _ => "–".into(),
    }
}

/// Predicted against observed spread (docs/conventions.md §3a): the expected mapping error of
/// each subset's calibration beside the mapping errors the subsets actually show.
fn write_uncertainty(s: &mut String, summary: &Summary, rows: &[Row]) {
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

/// What `auto` chose per subset and how its calibrations fared against each
/// fixed method on the same subsets (when the run recorded `auto`).
fn auto_table(summary: &Summary, rows: &[Row]) -> Option<Table> {
    let h = &summary.header;
    let a = h.auto.as_ref()?;
    let auto_rows: Vec<&Row> = rows.iter().filter(|r| r.auto).collect();
    let key = if h.truth.is_some() {
        "truth_mapping_error_px"
    } else {
        "mapping_error_px"
    };
    let error_of = |r: &Row| auto_error(h, r);
    let mut table_rows = Vec::new();
    for m in Method::ALL {
        let chose: Vec<&Row> = auto_rows
            .iter()
            .copied()
            .filter(|r| r.ok() && r.method == m)
            .collect();
        if chose.is_empty() {
            continue;
        }
        table_rows.push(vec![
            format!("`{m}`"),
            chose.len().to_string(),
            pm(
                Stat::of(chose.iter().filter_map(|r| error_of(r))).as_ref(),
                1.0,
                3,
            ),
        ]);
    }
    table_rows.push(vec![
        "all subsets".into(),
        auto_rows.iter().filter(|r| r.ok()).count().to_string(),
        pm(
            summary.methods.get(AUTO).and_then(|s| s.metrics.get(key)),
            1.0,
            3,
        ),
    ]);
    let worse = worse_than_standard(rows, error_of);
    Some(Table {
        title: "The method `auto` chooses per subset".into(),
        head: vec![
            "chosen".into(),
            "subsets".into(),
            format!(
                "mapping error to {} of {} (px)",
                if h.truth.is_some() { "truth" } else { "reference" },
                h.cameras[0].name
            ),
        ],
        rows: table_rows,
        figures: vec![figure(
            AUTO_SVG,
            "auto's choices",
            &format!(
                "One dot per subset, in the column of the method `auto` chose; the line is `standard`'s \
                 mean. `auto` cross-validates {} over {} folds (seed {}) on each subset and keeps the \
                 best unless a simpler method is within its noise. {}",
                a.candidates.iter().map(|m| format!("`{m}`")).collect::<Vec<_>>().join(", "),
                a.folds,
                a.seed,
                worse
            ),
        )],
    })
}

/// The file of the `auto` figure.
const AUTO_SVG: &str = "auto.svg";

/// The mapping error `auto`'s figure and table show: to the truth when known.
fn auto_error(h: &Header, r: &Row) -> Option<f64> {
    let c = r.cameras.first()?;
    if h.truth.is_some() {
        c.truth_mapping_error_px
    } else {
        c.mapping_error_px
    }
}

/// `auto.svg`: each subset's error, in the column of the method `auto` chose.
fn plot_auto(h: &Header, rows: &[Row]) -> Result<Option<String>> {
    if h.auto.is_none() {
        return Ok(None);
    }
    let cats: Vec<String> = Method::ALL.iter().map(|m| m.name().to_string()).collect();
    let groups = Method::ALL
        .iter()
        .map(|&m| {
            rows.iter()
                .filter(|r| r.auto && r.ok() && r.method == m)
                .filter_map(|r| auto_error(h, r))
                .collect()
        })
        .collect();
    let standard = Stat::of(
        rows.iter()
            .filter(|r| r.ok() && r.is_fixed(Method::Standard))
            .filter_map(|r| auto_error(h, r)),
    );
    let lines: Vec<HLine> = standard
        .map(|s| HLine {
            value: s.mean,
            name: "standard, mean",
            color: BLACK_RGB,
        })
        .into_iter()
        .collect();
    let axis = if h.truth.is_some() {
        "mapping error to truth (px)"
    } else {
        "mapping error to reference (px)"
    };
    let series = [Series {
        name: "auto",
        color: PALETTE[0],
        groups,
    }];
    plots::strip_chart_svg(
        &format!("{}: the method auto chose", h.dataset),
        Axes {
            x: "method chosen",
            y: axis,
        },
        &cats,
        &series,
        &lines,
    )
    .map(Some)
}

/// How often `auto`'s calibration has a larger error than `standard`'s on the same subset.
fn worse_than_standard(rows: &[Row], error_of: impl Fn(&Row) -> Option<f64>) -> String {
    let standard: BTreeMap<usize, f64> = rows
        .iter()
        .filter(|r| r.is_fixed(Method::Standard) && r.ok())
        .filter_map(|r| Some((r.subset, error_of(r)?)))
        .collect();
    if standard.is_empty() {
        return String::new();
    }
    let pairs: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.auto && r.ok())
        .filter_map(|r| Some((error_of(r)?, *standard.get(&r.subset)?)))
        .collect();
    let worse = pairs.iter().filter(|(a, s)| a > s).count();
    format!(
        "On {worse} of {} subsets its error is larger than `standard`'s on the same subset.",
        pairs.len()
    )
}

/// The failed calibrations and their reasons, if any.
fn failed_table(rows: &[Row]) -> Option<Table> {
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

/// Every table of one dataset's report, in order.
pub fn report_tables(summary: &Summary, rows: &[Row]) -> Vec<Table> {
    let mut tables = vec![rmse_table(summary)];
    tables.extend(intrinsics_tables(summary));
    tables.push(mapping_table(summary));
    tables.extend(bending_table(summary, rows));
    tables.extend(auto_table(summary, rows));
    tables.extend(crate::app::sfm_report::sfm_table(&summary.header, rows));
    tables.extend(failed_table(rows));
    tables
}

/// One table as markdown, its figures linked with `prefix` before their file names.
fn table_markdown(s: &mut String, t: &Table, prefix: &str) {
    let _ = writeln!(s, "### {}\n", t.title);
    let _ = writeln!(
        s,
        "| {} |\n|{}",
        t.head.join(" | "),
        "---|".repeat(t.head.len())
    );
    for r in &t.rows {
        let _ = writeln!(s, "| {} |", r.join(" | "));
    }
    s.push('\n');
    for f in &t.figures {
        let _ = writeln!(s, "![{}]({prefix}{})\n\n{}\n", f.alt, f.file, f.caption);
    }
}

/// The report's markdown for one dataset; `prefix` is prepended to plot links.
pub fn report_markdown(summary: &Summary, rows: &[Row], prefix: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "## Dataset `{}`\n", summary.header.dataset);
    for p in intro(&summary.header) {
        let _ = writeln!(s, "{p}\n");
    }
    for t in report_tables(summary, rows) {
        table_markdown(&mut s, &t, prefix);
    }
    write_uncertainty(&mut s, summary, rows);
    s
}

/// One dataset's report for the HTML page: its tables and its figures drawn.
pub fn dataset_report(summary: &Summary, rows: &[Row]) -> Result<DatasetReport> {
    Ok(DatasetReport {
        name: summary.header.dataset.clone(),
        intro: intro(&summary.header),
        tables: report_tables(summary, rows),
        figures: plots(summary, rows)?.into_iter().collect(),
    })
}

/// The row and image whose bend the Fig. 1 plot shows: `full` (else `dynamic`) of the
/// first subset that has one, its most bent image.
fn most_bent(rows: &[Row]) -> Option<(&Row, usize)> {
    let pick = |m: Method| {
        rows.iter()
            .filter(|r| r.ok() && r.is_fixed(m) && !r.deformations.is_empty())
            .min_by_key(|r| r.subset)
    };
    let r = pick(Method::Full).or_else(|| pick(Method::Dynamic))?;
    let j = (0..r.max_out_of_plane_m.len())
        .max_by(|&a, &b| r.max_out_of_plane_m[a].total_cmp(&r.max_out_of_plane_m[b]))?;
    Some((r, j))
}

/// A series label, with the camera's name when there are several cameras.
fn named(h: &Header, base: &str, k: usize) -> String {
    if h.cameras.len() > 1 {
        format!("{base} {}", h.cameras[k].name)
    } else {
        base.to_string()
    }
}

/// The `i`-th series colour, cycling through the palette.
fn colour(i: usize) -> plotters::style::RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// The x axis of every strip chart.
const METHOD_AXIS: &str = "method";

/// `rmse.svg`: train RMSE and each camera's test RMSE per method.
fn plot_rmse(h: &Header, cats: &[String], rows: &[Row]) -> Result<String> {
    // Series names must outlive the charts.
    let test_names: Vec<String> = (0..h.cameras.len()).map(|k| named(h, "test", k)).collect();
    let mut rmse = vec![Series {
        name: "train",
        color: colour(0),
        groups: groups(h, rows, |r| opt(r.rmse_px)),
    }];
    for (k, name) in test_names.iter().enumerate() {
        rmse.push(Series {
            name,
            color: colour(k + 1),
            groups: camera_groups(h, rows, k, |c| c.test_rmse_px),
        });
    }
    plots::strip_chart_svg(
        &format!("{}: train and test RMSE", h.dataset),
        Axes {
            x: METHOD_AXIS,
            y: "RMSE (px) = √(Σ‖u − p‖² / N)",
        },
        cats,
        &rmse,
        &[],
    )
}

/// The reference and truth lines of one intrinsic parameter of camera k.
fn intrinsic_lines<'a>(h: &Header, k: usize, name: &str) -> Vec<HLine<'a>> {
    let mut lines = Vec::new();
    if let Some(v) = h
        .reference
        .as_ref()
        .and_then(|r| r.intrinsics.get(k))
        .and_then(|i| i.get(name))
    {
        lines.push(HLine {
            value: v,
            name: "reference",
            color: BLACK_RGB,
        });
    }
    if let Some(v) = h
        .truth
        .as_ref()
        .and_then(|t| t.get(k))
        .and_then(|i| i.get(name))
    {
        lines.push(HLine {
            value: v,
            name: "truth",
            color: PALETTE[3],
        });
    }
    lines
}

/// `intrinsics.svg`: every intrinsic parameter of every camera, one panel each,
/// with the reference and the truth.
fn plot_intrinsics(h: &Header, cats: &[String], rows: &[Row]) -> Result<String> {
    let mut keys: Vec<(usize, &'static str, String, String)> = Vec::new();
    for (k, cam) in h.cameras.iter().enumerate() {
        for name in cam.model.param_names() {
            let title = named(h, name, k);
            let axis = format!("{name} ({})", param_unit(cam.model, name));
            keys.push((k, name, title, axis));
        }
    }
    let panels: Vec<plots::Panel> = keys
        .iter()
        .map(|(k, name, title, axis)| {
            let series = vec![Series {
                name: "one subset (bars: mean ± std)",
                color: colour(0),
                groups: camera_groups(h, rows, *k, |c| c.intrinsics.get(name)),
            }];
            (
                title.clone(),
                Axes {
                    x: METHOD_AXIS,
                    y: axis,
                },
                series,
                intrinsic_lines(h, *k, name),
            )
        })
        .collect();
    plots::panels_svg("intrinsics.svg", &panels, cats, 3)
}

/// `mapping.svg`: each camera's mapping error to the reference and to the truth.
fn plot_mapping(h: &Header, cats: &[String], rows: &[Row]) -> Result<String> {
    let mut names = Vec::new();
    for k in 0..h.cameras.len() {
        if h.reference.is_some() {
            names.push((
                named(h, "to reference", k),
                k,
                (|c| c.mapping_error_px) as CameraGetter,
            ));
        }
        if h.truth.is_some() {
            names.push((named(h, "to truth", k), k, |c| c.truth_mapping_error_px));
            names.push((named(h, "to truth, rotation removed", k), k, |c| {
                c.truth_mapping_error_rot_px
            }));
        }
    }
    let mapping: Vec<Series> = names
        .iter()
        .enumerate()
        .map(|(i, (name, k, get))| Series {
            name,
            color: colour(i),
            groups: camera_groups(h, rows, *k, *get),
        })
        .collect();
    plots::strip_chart_svg(
        &format!("{}: mapping error", h.dataset),
        Axes {
            x: METHOD_AXIS,
            y: "mapping error (px): RMS over a 20 px grid",
        },
        cats,
        &mapping,
        &[],
    )
}

/// `bend.svg`: every image's largest bend per method that estimates one.
fn plot_bend(h: &Header, rows: &[Row]) -> Result<Option<String>> {
    let methods: Vec<Method> = h
        .methods
        .iter()
        .copied()
        .filter(|m| m.has_paraboloid())
        .collect();
    if methods.is_empty() {
        return Ok(None);
    }
    let cats: Vec<String> = methods.iter().map(|m| m.name().to_string()).collect();
    let groups: Vec<Vec<f64>> = methods
        .iter()
        .map(|&m| {
            rows.iter()
                .filter(|r| r.is_fixed(m) && r.ok())
                .flat_map(|r| r.max_out_of_plane_m.iter().map(|v| v * 1e3))
                .collect()
        })
        .collect();
    let series = [Series {
        name: "one image of a subset (bars: mean ± std)",
        color: colour(0),
        groups,
    }];
    plots::strip_chart_svg(
        &format!("{}: largest bend per image", h.dataset),
        Axes {
            x: METHOD_AXIS,
            y: "max |Δz| over the corners (mm)",
        },
        &cats,
        &series,
        &[],
    )
    .map(Some)
}

/// Every SVG plot of one dataset, by file name.
pub fn plots(summary: &Summary, rows: &[Row]) -> Result<Vec<(String, String)>> {
    let h = &summary.header;
    let cats = columns(h);
    let mut out = vec![
        ("rmse.svg".to_string(), plot_rmse(h, &cats, rows)?),
        (
            "intrinsics.svg".to_string(),
            plot_intrinsics(h, &cats, rows)?,
        ),
        ("mapping.svg".to_string(), plot_mapping(h, &cats, rows)?),
    ];
    if let Some(svg) = plot_bend(h, rows)? {
        out.push(("bend.svg".to_string(), svg));
    }
    if let Some(svg) = plot_auto(h, rows)? {
        out.push((AUTO_SVG.to_string(), svg));
    }
    if let Some(svg) = crate::app::sfm_report::sfm_plot(h, rows)? {
        out.push((crate::app::sfm_report::SFM_PLOT.to_string(), svg));
    }
    if let Some((r, j)) = most_bent(rows) {
        let svg = plots::deformation_svg(
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
            r.higher_bends.get(j).unwrap_or(&[0.0; HIGHER_BEND_PARAMS]),
        )?;
        out.push(("deformation.svg".to_string(), svg));
    }
    Ok(out)
}

const BLACK_RGB: plotters::style::RGBColor = plotters::style::RGBColor(0, 0, 0);

/// Writes every protocol output of one dataset into `dir`: the CSV files, the
/// summary, the plots, `report.md` and `report.html`.
pub fn write_outputs(dir: &Path, header: &Header, rows: &[Row]) -> Result<Summary> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let summary = summarise(header, rows);
    let report = dataset_report(&summary, rows)?;
    for (file, svg) in &report.figures {
        write_atomic(&dir.join(file), svg.as_bytes())?;
    }
    write_atomic(&dir.join("protocol.csv"), &protocol_csv(header, rows)?)?;
    write_atomic(&dir.join("deformations.csv"), &deformations_csv(rows))?;
    if let Some(b) = header.reference.as_ref().and_then(|r| r.board.as_ref()) {
        let path = dir.join(crate::app::protocol::REFERENCE_BOARD_JSON);
        crate::app::board_json::write_file(&path, b)?;
    }
    let json = serde_json::to_string_pretty(&summary).expect("summary serialises");
    write_atomic(&dir.join("summary.json"), json.as_bytes())?;
    let markdown = format!(
        "# deformcal evaluation protocol\n\n{}",
        report_markdown(&summary, rows, "")
    );
    write_atomic(&dir.join("report.md"), markdown.as_bytes())?;
    let html = protocol_page("deformcal evaluation protocol", &[report]);
    write_atomic(&dir.join(REPORT_FILE), html.as_bytes())?;
    Ok(summary)
}
