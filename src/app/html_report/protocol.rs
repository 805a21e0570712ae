//! The protocol's `report.html`: per dataset its opening paragraphs, the paper's
//! tables and the figures that go with them, inlined, then the definitions of the
//! metrics. The tables and figures are built by `app::protocol_report`, which also
//! renders the same tables as `report.md`; this module only lays them out as HTML.
use crate::app::html_report::page::{self, para, subsection, Page, Table};
use std::collections::BTreeMap;
use std::fmt::Write;

/// The report of one dataset: its name, opening paragraphs, tables, and the SVG
/// text of every figure the tables name, by file name.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetReport {
    /// The dataset's name (its section heading).
    pub name: String,
    /// Opening paragraphs, plain text with `code` spans.
    pub intro: Vec<String>,
    /// The tables, in order.
    pub tables: Vec<Table>,
    /// SVG text by file name.
    pub figures: BTreeMap<String, String>,
}

/// The whole protocol page for one or more datasets.
pub fn protocol_page(title: &str, datasets: &[DatasetReport]) -> String {
    let lead = "The evaluation protocol of Hagemann, Knorr and Stiller (WACV 2022): random subsets of the \
                images calibrated with every method; mean ± standard deviation over the subsets.";
    let mut p = Page::new(title, lead);
    for d in datasets {
        p.section(
            &format!("dataset-{}", d.name),
            &format!("Dataset `{}`", d.name),
            dataset_body(d),
        );
    }
    p.section("definitions", "Definitions", definitions());
    p.render()
}

/// One dataset: its paragraphs, then each table with its figures.
fn dataset_body(d: &DatasetReport) -> String {
    let mut s: String = d.intro.iter().map(|t| para(t)).collect();
    for (i, t) in d.tables.iter().enumerate() {
        let mut body = page::table_html(&t.head, &t.rows);
        for f in &t.figures {
            let id = format!("{}-{}", d.name, f.file.trim_end_matches(".svg"));
            match d.figures.get(&f.file) {
                Some(svg) => body.push_str(&page::figure_html(&id, svg, &f.caption)),
                None => body.push_str(&para(&format!("(figure `{}` was not drawn)", f.file))),
            }
        }
        s.push_str(&subsection(
            &format!("{}-table-{i}", d.name),
            &t.title,
            &body,
        ));
    }
    s
}

/// What the protocol's metrics mean.
fn definitions() -> String {
    let items = [
        "Train RMSE `rmse_px`: √(Σ‖u − p‖² / N) over the N observations of the subset, after its calibration.",
        "Test RMSE `test_rmse_px`: the subset's intrinsics held; on the reference set only the board poses are fitted, with the reference calibration's static correction applied; the RMSE of that fit.",
        "Mapping error `mapping_error_px` between intrinsics a and b: a grid of pixels (20 px step over the whole image) unprojected with a and projected with b; the RMSE of the pixel differences. `mapping_error_rot_px`: the same after the best virtual camera rotation. Against the reference calibration, or the truth for synthetic data.",
        "`max_out_of_plane_m` of an image: the largest |a·x² + b·y² + c·xy| over the corners.",
        "Intrinsics: fx, fy, cx, cy in pixels; the distortion coefficients are unitless.",
    ];
    let mut s = String::from("<ul>\n");
    for i in items {
        let _ = writeln!(s, "<li>{}</li>", page::inline(i));
    }
    s.push_str("</ul>\n");
    s
}
