//! Protocol outputs: `protocol.csv`, `deformations.csv`, `summary.json`, the
//! report's tables and SVG plots, written as `report.md` and `report.html`.
//! Written from the merged rows alone, so a sharded run and its merge write
//! exactly what one unsharded run writes.
//!
//! `summary` computes the statistics, `csv` writes the per-task files, `tables`,
//! `auto` and `figures` make the report's parts; this file puts the report
//! together and writes every output.
mod auto;
mod csv;
mod figures;
mod summary;
mod tables;

use crate::app::fsio::write_atomic;
use crate::app::html_report::page::Table;
use crate::app::html_report::protocol::{protocol_page, DatasetReport};
use crate::app::html_report::REPORT_FILE;
use crate::app::plots::{self};
use crate::app::protocol::{Header, Row};
use crate::error::{Error, Result};
use crate::model::board::HIGHER_BEND_PARAMS;
use auto::{auto_table, plot_auto, AUTO_SVG};
pub use csv::{deformations_csv, protocol_csv};
use figures::*;
use std::fmt::Write;
use std::path::Path;
use summary::columns;
pub use summary::{camera_key, summarise, MethodSummary, Summary};
use tables::*;

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
