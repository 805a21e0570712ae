//! How `auto` chose per subset: its table and `auto.svg`.
#[allow(unused_imports)]
use super::figures::*;
#[allow(unused_imports)]
use super::summary::*;
#[allow(unused_imports)]
use super::tables::*;
use crate::app::html_report::page::Table;
use crate::app::plots::{self, Axes, HLine, Series, PALETTE};
use crate::app::protocol::{Header, Row};
use crate::error::Result;
use crate::model::board::Method;
use crate::model::metrics::Stat;
use std::collections::BTreeMap;

/// What `auto` chose per subset and how its calibrations fared against each
/// fixed method on the same subsets (when the run recorded `auto`).
pub(super) fn auto_table(summary: &Summary, rows: &[Row]) -> Option<Table> {
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
pub(super) const AUTO_SVG: &str = "auto.svg";

/// The mapping error `auto`'s figure and table show: to the truth when known.
pub(super) fn auto_error(h: &Header, r: &Row) -> Option<f64> {
    let c = r.cameras.first()?;
    if h.truth.is_some() {
        c.truth_mapping_error_px
    } else {
        c.mapping_error_px
    }
}

/// `auto.svg`: each subset's error, in the column of the method `auto` chose.
pub(super) fn plot_auto(h: &Header, rows: &[Row]) -> Result<Option<String>> {
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
pub(super) fn worse_than_standard(rows: &[Row], error_of: impl Fn(&Row) -> Option<f64>) -> String {
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
