//! `summary.json`: each method's statistics over the subsets, and the grouping
//! of rows into the report's columns that the tables and figures share.
use crate::app::protocol::{CameraRow, Header, Row};
use crate::model::board::Method;
use crate::model::metrics::Stat;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

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

pub(super) type Getter = fn(&Row) -> Vec<f64>;
pub(super) type CameraGetter = fn(&CameraRow) -> Option<f64>;

pub(super) fn opt(v: Option<f64>) -> Vec<f64> {
    v.into_iter().collect()
}

/// Metrics of the whole calibration, summarised per method.
pub(super) const ROW_METRICS: [(&str, Getter); 5] = [
    ("rmse_px", |r| opt(r.rmse_px)),
    ("loop_closure_px", |r| opt(r.loop_closure_px)),
    ("bias_ratio", |r| opt(r.bias_ratio)),
    ("max_out_of_plane_m", |r| r.max_out_of_plane_m.clone()),
    ("iterations", |r| vec![r.iterations as f64]),
];

/// Metrics of each camera, summarised per method (prefixed `camera/` with several cameras).
pub(super) const CAMERA_METRICS: [(&str, CameraGetter); 7] = [
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
pub(super) fn intrinsics_columns(header: &Header) -> Vec<&'static str> {
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
pub(super) const AUTO: &str = "auto";

/// The statistics of one method's rows.
pub(super) fn method_summary(header: &Header, all: &[&Row]) -> MethodSummary {
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

pub(super) fn groups(
    header: &Header,
    rows: &[Row],
    get: impl Fn(&Row) -> Vec<f64>,
) -> Vec<Vec<f64>> {
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
pub(super) fn columns(h: &Header) -> Vec<String> {
    let mut cats: Vec<String> = h.methods.iter().map(|m| m.name().to_string()).collect();
    if h.auto.is_some() {
        cats.push(AUTO.into());
    }
    cats
}

/// Whether `r` belongs to column `i` of [`columns`].
pub(super) fn in_column(h: &Header, i: usize, r: &Row) -> bool {
    match h.methods.get(i) {
        Some(&m) => r.is_fixed(m),
        None => r.auto,
    }
}

/// Per-camera values of one metric across rows, grouped per method.
pub(super) fn camera_groups(
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
pub(super) fn stat<'a>(summary: &'a Summary, m: Method, key: &str) -> Option<&'a Stat> {
    summary
        .methods
        .get(m.name())
        .and_then(|x| x.metrics.get(key))
}

/// "method" or "method, camera" labels for per-camera table rows.
pub(super) fn row_label(h: &Header, m: Method, k: usize) -> String {
    if h.cameras.len() > 1 {
        format!("{m}, {}", h.cameras[k].name)
    } else {
        m.to_string()
    }
}

/// Decimals of an intrinsic parameter: pixels to 2, coefficients to 5.
pub(super) fn param_digits(model: crate::model::lens::LensModel, name: &str) -> usize {
    if model.param_index(name).is_some_and(|i| i < 4) {
        2
    } else {
        5
    }
}

/// The unit of an intrinsic parameter, for headers and axes.
pub(super) fn param_unit(model: crate::model::lens::LensModel, name: &str) -> &'static str {
    if model.param_index(name).is_some_and(|i| i < 4) {
        "px"
    } else {
        "unitless"
    }
}
