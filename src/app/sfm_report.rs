//! The structure-from-motion part of the protocol report: the paper's Table 1
//! (loop-closure error, mean ± std per method) and the plot of loop-closure error
//! against mapping error. Drawn from the protocol's rows only; `protocol_report`
//! places them in the report.
use crate::app::html_report::page::{Figure, Table};
use crate::app::plots::{self, pe, PALETTE};
use crate::app::protocol::{Header, Row};
use crate::error::Result;
use crate::model::metrics::Stat;
use plotters::prelude::*;

/// The figure's file name.
pub const SFM_PLOT: &str = "loop_closure.svg";

/// Whether any row ran the experiment.
fn has_sfm(rows: &[Row]) -> bool {
    rows.iter()
        .any(|r| r.loop_closure_px.is_some() || r.sfm_error.is_some())
}

/// The mapping error the plot and table set the loop closure against: to the
/// truth where known, else to the reference (camera 0, as the experiment).
fn mapping(r: &Row) -> Option<f64> {
    let c = r.cameras.first()?;
    c.truth_mapping_error_px.or(c.mapping_error_px)
}

fn pm(s: Option<Stat>, digits: usize) -> String {
    s.map_or("–".into(), |s| {
        format!("{:.*} ± {:.*}", digits, s.mean, digits, s.std)
    })
}

/// The paper's Table 1 for this dataset, if the protocol ran `[sfm]`.
pub fn sfm_table(h: &Header, rows: &[Row]) -> Option<Table> {
    if !has_sfm(rows) {
        return None;
    }
    let to = if h.truth.is_some() {
        "truth"
    } else {
        "reference"
    };
    let body = h
        .methods
        .iter()
        .map(|&m| {
            let of = |r: &&Row| r.method == m && r.ok();
            let mine: Vec<&Row> = rows.iter().filter(of).collect();
            let lc = Stat::of(mine.iter().filter_map(|r| r.loop_closure_px));
            let me = Stat::of(mine.iter().filter_map(|r| mapping(r)));
            let broke = mine.iter().filter(|r| r.sfm_error.is_some()).count();
            vec![
                m.to_string(),
                pm(lc, 2),
                pm(me, 3),
                format!("{} ({broke})", mine.len()),
            ]
        })
        .collect();
    Some(Table {
        title: "Structure from motion: loop-closure error (paper Table 1)".into(),
        head: vec![
            "method".into(),
            "loop-closure RMSE (px)".into(),
            format!("mapping error to {to} (px)"),
            "reconstructions (broke off)".into(),
        ],
        rows: body,
        figures: vec![Figure {
            file: SFM_PLOT.into(),
            alt: "loop-closure error against mapping error".into(),
            caption: "Every calibration's intrinsics held fixed in an incremental structure from \
                      motion around a synthetic building (sequential matching only, no loop \
                      detection); the loop-closure error is the RMSE between the first image's \
                      features and their 3D points projected with the estimated pose of the last \
                      image, which is the first image again."
                .into(),
        }],
    })
}

/// One method's dots: its name, colour and (mapping error, loop closure) points.
type Scatter = (String, RGBColor, Vec<(f64, f64)>);

/// `loop_closure.svg`: loop-closure error against mapping error, one dot per
/// subset, a colour per method; `None` without `[sfm]` results.
pub fn sfm_plot(h: &Header, rows: &[Row]) -> Result<Option<String>> {
    if !has_sfm(rows) {
        return Ok(None);
    }
    let series: Vec<Scatter> = h
        .methods
        .iter()
        .enumerate()
        .map(|(i, &m)| {
            let pts = rows
                .iter()
                .filter(|r| r.method == m && r.ok())
                .filter_map(|r| Some((mapping(r)?, r.loop_closure_px?)))
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .collect();
            (m.to_string(), PALETTE[i % PALETTE.len()], pts)
        })
        .collect();
    let all = || series.iter().flat_map(|s| s.2.iter());
    let (x0, x1) = plots::padded_range(all().map(|p| p.0).chain([0.0]), 0.05);
    let (y0, y1) = plots::padded_range(all().map(|p| p.1).chain([0.0]), 0.05);
    let to = if h.truth.is_some() {
        "truth"
    } else {
        "reference"
    };
    let title = format!("{}: loop closure against mapping error", h.dataset);
    plots::svg(SFM_PLOT, (760, 520), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(&title, plots::TITLE)
            .margin(12)
            .x_label_area_size(48)
            .y_label_area_size(64)
            .build_cartesian_2d(x0.max(0.0)..x1, y0.max(0.0)..y1)
            .map_err(pe)?;
        chart
            .configure_mesh()
            .x_desc(format!("mapping error to the {to} (px)"))
            .y_desc("loop-closure RMSE (px)")
            .label_style(plots::LABEL)
            .axis_desc_style(plots::AXIS_DESC)
            .draw()
            .map_err(pe)?;
        for (name, colour, pts) in &series {
            let c = *colour;
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.mix(0.7).filled())))
                .map_err(pe)?
                .label(name.as_str())
                .legend(move |(x, y)| Circle::new((x + 6, y), 4, c.filled()));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(plots::LABEL)
            .draw()
            .map_err(pe)
    })
    .map(Some)
}
