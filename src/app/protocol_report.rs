//! Protocol outputs: `protocol.csv`, `deformations.csv`, `summary.json`, `report.md`
//! and its SVG plots. Written from the merged rows alone, so a sharded run and
//! its merge write exactly what one unsharded run writes.
use crate::app::fsio::write_atomic;
use crate::app::plots::{self, HLine, Series, PALETTE};
use crate::app::protocol::{CameraRow, Header, Row};
use crate::error::{Error, Result};
use crate::model::board::Method;
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
    pub methods: BTreeMap<String, MethodSummary>,
}

type Getter = fn(&Row) -> Vec<f64>;
type CameraGetter = fn(&CameraRow) -> Option<f64>;

fn opt(v: Option<f64>) -> Vec<f64> {
    v.into_iter().collect()
}

/// Metrics of the whole calibration, summarised per method.
const ROW_METRICS: [(&str, Getter); 4] = [
    ("rmse_px", |r| opt(r.rmse_px)),
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

/// Summarises rows per method.
pub fn summarise(header: &Header, rows: &[Row]) -> Summary {
    let mut methods = BTreeMap::new();
    for &m in &header.methods {
        let all: Vec<&Row> = rows.iter().filter(|r| r.method == m).collect();
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
    ];
    columns.extend(CAMERA_METRICS.iter().map(|(n, _)| *n));
    columns.extend(["max_out_of_plane_m_mean", "max_out_of_plane_m_max"]);
    let intrinsics = intrinsics_columns(header);
    columns.extend(intrinsics.iter().copied());
    w.write_record(&columns).map_err(to_err)?;
    for r in rows {
        let bends = Stat::of(r.max_out_of_plane_m.iter().copied()).map(|s| s.mean);
        let max_bend = r.max_out_of_plane_m.iter().copied().reduce(f64::max);
        for (k, cam) in header.cameras.iter().enumerate() {
            let c = r.cameras.get(k);
            let mut rec = vec![
                r.subset.to_string(),
                r.method.name().to_string(),
                cam.name.clone(),
                if r.ok() { "ok" } else { "failed" }.to_string(),
                r.error.clone().unwrap_or_default(),
                r.images.to_string(),
                r.observations.to_string(),
                r.converged.to_string(),
                r.iterations.to_string(),
                cell(r.rmse_px),
                cell(r.bias_ratio),
            ];
            rec.extend(CAMERA_METRICS.iter().map(|(_, get)| cell(c.and_then(get))));
            rec.extend([cell(bends), cell(max_bend)]);
            rec.extend(
                intrinsics
                    .iter()
                    .map(|name| cell(c.and_then(|c| c.intrinsics.get(name)))),
            );
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

fn groups(header: &Header, rows: &[Row], get: impl Fn(&Row) -> Vec<f64>) -> Vec<Vec<f64>> {
    header
        .methods
        .iter()
        .map(|&m| {
            rows.iter()
                .filter(|r| r.method == m && r.ok())
                .flat_map(&get)
                .collect()
        })
        .collect()
}

/// Per-camera values of one metric across rows, grouped per method.
fn camera_groups(header: &Header, rows: &[Row], k: usize, get: CameraGetter) -> Vec<Vec<f64>> {
    groups(header, rows, |r| {
        r.cameras.get(k).and_then(get).into_iter().collect()
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

/// One line per camera with its pinhole intrinsics.
fn write_pinholes(s: &mut String, h: &Header, intrinsics: &[crate::model::lens::Intrinsics]) {
    for (k, i) in intrinsics.iter().enumerate() {
        let _ = writeln!(
            s,
            "- {}: fx {:.2}, fy {:.2}, cx {:.2}, cy {:.2}",
            h.cameras[k].name,
            i.fx(),
            i.fy(),
            i.cx(),
            i.cy()
        );
    }
}

/// The report's opening: the dataset, the protocol's sizes, the reference and the truth.
fn write_intro(s: &mut String, h: &Header) {
    let _ = writeln!(s, "## Dataset `{}`\n", h.dataset);
    let cams: Vec<String> = h
        .cameras
        .iter()
        .map(|c| format!("{} {}×{}", c.name, c.width, c.height))
        .collect();
    let _ = writeln!(
        s,
        "{} subsets × {} images drawn from {} images (seed {}); board {} × {} corners, {} m; camera(s) {}.\n",
        h.subsets, h.images_per_subset, h.dataset_images, h.seed, h.target.rows, h.target.cols, h.target.spacing, cams.join(", ")
    );
    if let Some(r) = &h.reference {
        let _ = writeln!(
            s,
            "Reference calibration: `static` on {} images ({} observations), RMSE {:.4} px{}.",
            r.images,
            r.observations,
            r.rmse_px,
            if r.converged {
                ""
            } else {
                " (did not converge)"
            }
        );
        write_pinholes(s, h, &r.intrinsics);
        s.push('\n');
    }
    if let Some(t) = &h.truth {
        let _ = writeln!(s, "Ground truth (synthetic):");
        write_pinholes(s, h, t);
        s.push('\n');
    }
}

/// The train and test error table (paper Fig. 3a).
fn write_rmse_table(s: &mut String, summary: &Summary, prefix: &str) {
    let h = &summary.header;
    let _ = writeln!(s, "### Train and test error (paper Fig. 3a)\n");
    let test_heads: Vec<String> = h
        .cameras
        .iter()
        .map(|c| {
            if h.cameras.len() > 1 {
                format!("test RMSE {} (px)", c.name)
            } else {
                "test RMSE (px)".into()
            }
        })
        .collect();
    let _ = writeln!(
        s,
        "| method | calibrations (failed) | train RMSE (px) | {} |\n|---|---|---|{}",
        test_heads.join(" | "),
        "---|".repeat(h.cameras.len())
    );
    for &m in &h.methods {
        let ms = &summary.methods[m.name()];
        let tests: Vec<String> = (0..h.cameras.len())
            .map(|k| pm(stat(summary, m, &camera_key(h, k, "test_rmse_px")), 1.0, 4))
            .collect();
        let _ = writeln!(
            s,
            "| {m} | {} ({}) | {} | {} |",
            ms.calibrations,
            ms.failed,
            pm(stat(summary, m, "rmse_px"), 1.0, 4),
            tests.join(" | ")
        );
    }
    let _ = writeln!(s, "\n![train and test RMSE]({prefix}rmse.svg)\n");
}

/// Rows of a per-camera × method table of `metrics`, with `digits` decimals.
fn write_camera_rows(s: &mut String, summary: &Summary, metrics: &[&str], digits: usize) {
    let h = &summary.header;
    for k in 0..h.cameras.len() {
        for &m in &h.methods {
            let v: Vec<String> = metrics
                .iter()
                .map(|n| pm(stat(summary, m, &camera_key(h, k, n)), 1.0, digits))
                .collect();
            let _ = writeln!(s, "| {} | {} |", row_label(h, m, k), v.join(" | "));
        }
    }
}

/// The intrinsics (paper Fig. 4a) and mapping error (paper Fig. 4b) tables.
fn write_intrinsics_and_mapping(s: &mut String, summary: &Summary, prefix: &str) {
    let _ = writeln!(s, "### Intrinsics (paper Fig. 4a)\n");
    let _ = writeln!(
        s,
        "| method | fx (px) | fy (px) | cx (px) | cy (px) |\n|---|---|---|---|---|"
    );
    write_camera_rows(s, summary, &["fx", "fy", "cx", "cy"], 2);
    let _ = writeln!(s, "\n![fx and cx]({prefix}intrinsics.svg)\n");
    let _ = writeln!(s, "### Mapping error (paper Fig. 4b)\n");
    let _ = writeln!(
        s,
        "| method | to reference (px) | to reference, rotation removed (px) | to truth (px) | to truth, rotation removed (px) |\n|---|---|---|---|---|"
    );
    write_camera_rows(
        s,
        summary,
        &[
            "mapping_error_px",
            "mapping_error_rot_px",
            "truth_mapping_error_px",
            "truth_mapping_error_rot_px",
        ],
        3,
    );
    let _ = writeln!(s, "\n![mapping error]({prefix}mapping.svg)\n");
}

/// The out-of-plane deformation table (paper Table S2) and Fig. 1's plot, if any method bends.
fn write_bending(s: &mut String, summary: &Summary, rows: &[Row], prefix: &str) {
    let bending: Vec<Method> = summary
        .header
        .methods
        .iter()
        .copied()
        .filter(|m| m.has_paraboloid())
        .collect();
    if bending.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "### Maximum out-of-plane deformation per image (paper Table S2)\n"
    );
    let _ = writeln!(s, "| method | max out-of-plane (mm) |\n|---|---|");
    for m in bending {
        let _ = writeln!(
            s,
            "| {m} | {} |",
            pm(stat(summary, m, "max_out_of_plane_m"), 1e3, 3)
        );
    }
    if let Some((r, j)) = most_bent(rows) {
        let _ = writeln!(
            s,
            "\n![deformation of one image]({prefix}deformation.svg)\n\nThe estimated bend of frame {} in subset {} (`{}`), the most bent image of the first subset (paper Fig. 1).\n",
            r.frames[j], r.subset, r.method
        );
    }
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

/// Predicted against observed spread (SPEC §3a): the expected mapping error of
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
            let ok: Vec<&Row> = rows.iter().filter(|r| r.method == m && r.ok()).collect();
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
         (SPEC §3a); the ratios are observed / predicted. Near 1 to the truth: the noise explains the error. Far above: \
         a bias the model does not capture (a bias ratio above 0.1 says the same from the residuals). Around the mean \
         calibration the subsets' bias is shared and cancels, and subsets that share images scatter less.\n"
    );
}

/// The failed calibrations and their reasons, if any.
fn write_failed(s: &mut String, rows: &[Row]) {
    let failed: Vec<&Row> = rows.iter().filter(|r| !r.ok()).collect();
    if failed.is_empty() {
        return;
    }
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

/// The report's markdown for one dataset; `prefix` is prepended to plot links.
pub fn report_markdown(summary: &Summary, rows: &[Row], prefix: &str) -> String {
    let mut s = String::new();
    write_intro(&mut s, &summary.header);
    write_rmse_table(&mut s, summary, prefix);
    write_intrinsics_and_mapping(&mut s, summary, prefix);
    write_bending(&mut s, summary, rows, prefix);
    write_uncertainty(&mut s, summary, rows);
    write_failed(&mut s, rows);
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

/// `rmse.svg`: train RMSE and each camera's test RMSE per method.
fn plot_rmse(dir: &Path, h: &Header, cats: &[String], rows: &[Row]) -> Result<()> {
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
        &dir.join("rmse.svg"),
        &format!("{}: train and test RMSE", h.dataset),
        "RMSE (px)",
        cats,
        &rmse,
        &[],
    )
}

/// `intrinsics.svg`: fx and cx of camera 0, with the reference and the truth.
fn plot_intrinsics(dir: &Path, h: &Header, cats: &[String], rows: &[Row]) -> Result<()> {
    let lines = |f: fn(&crate::model::lens::Intrinsics) -> f64| {
        let mut lines = Vec::new();
        if let Some(r) = &h.reference {
            lines.push(HLine {
                value: f(&r.intrinsics[0]),
                name: "reference",
                color: BLACK_RGB,
            });
        }
        if let Some(t) = &h.truth {
            lines.push(HLine {
                value: f(&t[0]),
                name: "truth",
                color: PALETTE[3],
            });
        }
        lines
    };
    let (fx_name, cx_name) = (named(h, "fx", 0), named(h, "cx", 0));
    plots::panels_svg(
        &dir.join("intrinsics.svg"),
        &[
            (
                "fx",
                "fx (px)",
                vec![Series {
                    name: &fx_name,
                    color: colour(0),
                    groups: camera_groups(h, rows, 0, |c| Some(c.intrinsics.fx())),
                }],
                lines(|k| k.fx()),
            ),
            (
                "cx",
                "cx (px)",
                vec![Series {
                    name: &cx_name,
                    color: colour(2),
                    groups: camera_groups(h, rows, 0, |c| Some(c.intrinsics.cx())),
                }],
                lines(|k| k.cx()),
            ),
        ],
        cats,
    )
}

/// `mapping.svg`: each camera's mapping error to the reference and to the truth.
fn plot_mapping(dir: &Path, h: &Header, cats: &[String], rows: &[Row]) -> Result<()> {
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
        &dir.join("mapping.svg"),
        &format!("{}: mapping error", h.dataset),
        "mapping error (px)",
        cats,
        &mapping,
        &[],
    )
}

/// Writes the SVG plots of one dataset into `dir`.
pub fn write_plots(dir: &Path, summary: &Summary, rows: &[Row]) -> Result<()> {
    let h = &summary.header;
    let cats: Vec<String> = h.methods.iter().map(|m| m.name().to_string()).collect();
    plot_rmse(dir, h, &cats, rows)?;
    plot_intrinsics(dir, h, &cats, rows)?;
    plot_mapping(dir, h, &cats, rows)?;
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
    write_atomic(&dir.join("protocol.csv"), &protocol_csv(header, rows)?)?;
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
