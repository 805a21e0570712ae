//! HTML building blocks of the reports: escaping, the page shell with its inline
//! style sheet and table of contents, sections, tables and figures. A page built
//! here is self-contained by construction: it refers to no network resource,
//! script or font file, so it opens the same offline, in a mail or an archive.
use crate::app::raster::base64;
use std::fmt::Write;

/// `s` with the five characters HTML gives a meaning escaped.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '&' => out.push_str("&amp;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// A sentence with `code` spans (the one markup the reports' sentences use) as HTML.
pub fn inline(s: &str) -> String {
    let parts: Vec<&str> = s.split('`').collect();
    let ticks = parts.len() - 1;
    let mut out = String::new();
    for (i, part) in parts.iter().enumerate() {
        if i % 2 == 1 && i < ticks {
            let _ = write!(out, "<code>{}</code>", escape(part));
        } else {
            // The last of an odd number of backticks opens nothing: keep it as text.
            if i % 2 == 1 {
                out.push('`');
            }
            out.push_str(&escape(part));
        }
    }
    out
}

/// An HTML `id` made of a name: letters, digits, `-` and `_` kept, the rest `_`.
pub fn id_of(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// A figure a table refers to: its SVG file, its alternative text and its caption.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// The SVG file's name, beside the report.
    pub file: String,
    /// Alternative text (the markdown report's image text).
    pub alt: String,
    /// What the figure shows: plain text with `code` spans.
    pub caption: String,
}

/// A table with a title, header cells, rows of cells and the figures that go with it.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// The heading above the table.
    pub title: String,
    /// Header cells (with units).
    pub head: Vec<String>,
    /// Body rows, as many cells as the header.
    pub rows: Vec<Vec<String>>,
    /// Figures shown below the table.
    pub figures: Vec<Figure>,
}

/// A table's cells as HTML; cells are plain text (with `code` spans).
pub fn table_html(head: &[String], rows: &[Vec<String>]) -> String {
    let mut s = String::from("<table>\n<thead><tr>");
    for h in head {
        let _ = write!(s, "<th>{}</th>", inline(h));
    }
    s.push_str("</tr></thead>\n<tbody>\n");
    for r in rows {
        s.push_str("<tr>");
        for c in r {
            let _ = write!(s, "<td>{}</td>", inline(c));
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</tbody>\n</table>\n");
    s
}

/// An inline SVG figure with its caption (plain text with `code` spans).
pub fn figure_html(id: &str, svg: &str, caption: &str) -> String {
    format!(
        "<figure id=\"{}\">\n{}\n<figcaption>{}</figcaption>\n</figure>\n",
        id_of(id),
        strip_prolog(svg).trim(),
        inline(caption)
    )
}

/// An SVG document without its XML declaration and doctype, for inlining.
fn strip_prolog(svg: &str) -> &str {
    let mut s = svg.trim_start();
    while s.starts_with("<?") || s.starts_with("<!") {
        match s.find('>') {
            Some(i) => s = s[i + 1..].trim_start(),
            None => break,
        }
    }
    s
}

/// An SVG file from elsewhere as an `<img>` with a data URI: an image element
/// runs no script and shares no ids or styles with the page.
pub fn svg_image_html(svg: &[u8], alt: &str) -> String {
    format!(
        "<img class=\"embedded\" alt=\"{}\" src=\"data:image/svg+xml;base64,{}\">",
        escape(alt),
        base64(svg)
    )
}

/// A report page: a title, a lead paragraph and top-level sections, listed in a
/// table of contents.
#[derive(Debug, Clone, Default)]
pub struct Page {
    title: String,
    lead: String,
    sections: Vec<(String, String, String)>,
}

impl Page {
    /// An empty page with a title and a lead paragraph (plain text).
    pub fn new(title: &str, lead: &str) -> Page {
        Page {
            title: title.to_string(),
            lead: lead.to_string(),
            sections: Vec::new(),
        }
    }

    /// Adds a top-level section: its id, its heading (plain text) and its HTML body.
    pub fn section(&mut self, id: &str, heading: &str, body: String) {
        self.sections.push((id_of(id), heading.to_string(), body));
    }

    /// Sets the body of section `id`, added earlier with a placeholder: a section
    /// computed on another thread keeps its place in the page.
    pub fn fill(&mut self, id: &str, body: String) {
        let id = id_of(id);
        if let Some(section) = self.sections.iter_mut().find(|s| s.0 == id) {
            section.2 = body;
        }
    }

    /// The whole page.
    pub fn render(&self) -> String {
        let mut s = String::new();
        let _ = write!(
            s,
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
             <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
             <title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n<header><h1>{}</h1>\n<p class=\"lead\">{}</p>\n",
            escape(&self.title),
            escape(&self.title),
            inline(&self.lead)
        );
        s.push_str("<nav><ol>\n");
        for (id, heading, _) in &self.sections {
            let _ = writeln!(s, "<li><a href=\"#{id}\">{}</a></li>", inline(heading));
        }
        s.push_str("</ol></nav>\n</header>\n<main>\n");
        for (id, heading, body) in &self.sections {
            let _ = write!(
                s,
                "<section id=\"{id}\">\n<h2>{}</h2>\n{body}</section>\n",
                inline(heading)
            );
        }
        s.push_str("</main>\n</body>\n</html>\n");
        s
    }
}

/// A subsection: an `<h3>` with an id and its body.
pub fn subsection(id: &str, heading: &str, body: &str) -> String {
    format!(
        "<div class=\"sub\" id=\"{}\">\n<h3>{}</h3>\n{body}</div>\n",
        id_of(id),
        inline(heading)
    )
}

/// A paragraph of plain text (with `code` spans).
pub fn para(text: &str) -> String {
    format!("<p>{}</p>\n", inline(text))
}

/// The inline style sheet: readable type, figures that fit the window, plain tables.
const STYLE: &str = "
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,'DejaVu Sans',sans-serif;margin:0;color:#1b1b1b;background:#fff;line-height:1.45}
header{background:#f3f5f8;border-bottom:1px solid #d8dde5;padding:12px 28px}
h1{font-size:1.5em;margin:4px 0}
h2{font-size:1.25em;border-bottom:2px solid #d8dde5;padding-bottom:4px;margin-top:34px}
h3{font-size:1.05em;margin-top:24px}
main{padding:0 28px 40px;max-width:1200px}
nav ol{margin:4px 0;padding-left:20px;columns:2}
.lead{margin:4px 0;color:#444}
figure{margin:12px 0;max-width:100%}
figure svg,img.embedded{max-width:100%;height:auto;display:block;border:1px solid #e3e6ea}
figcaption{font-size:.9em;color:#444;max-width:900px;margin-top:4px}
table{border-collapse:collapse;margin:8px 0;font-size:.92em}
th,td{border:1px solid #d0d5dc;padding:3px 8px;text-align:left;vertical-align:top}
th{background:#f3f5f8}
td{font-variant-numeric:tabular-nums}
pre{background:#f6f7f9;border:1px solid #e3e6ea;padding:10px;white-space:pre-wrap;font-size:.88em}
code{background:#f1f2f4;padding:0 3px;border-radius:3px}
ul.verdicts{list-style:none;padding:0}
ul.verdicts li{margin:4px 0;padding:6px 10px;border-left:6px solid #999;background:#f6f7f9}
ul.verdicts li.ok{border-color:#2ca02c}
ul.verdicts li.warn{border-color:#ff7f0e}
ul.verdicts li.bad{border-color:#d62728;background:#fdeeee}
.placeholder{border:1px dashed #aab;padding:10px;color:#555;background:#fafbfc}
details{margin:8px 0}
summary{cursor:pointer;color:#1f4e9c}
";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_is_escaped_and_code_spans_kept() {
        assert_eq!(
            inline("a <b> & `c<d>` e"),
            "a &lt;b&gt; &amp; <code>c&lt;d&gt;</code> e"
        );
        assert_eq!(inline("one ` tick"), "one ` tick");
        assert_eq!(id_of("cam 0/x"), "cam_0_x");
    }

    #[test]
    fn an_inlined_svg_loses_its_prolog() {
        let f = figure_html("f", "<?xml version=\"1.0\"?>\n<svg></svg>", "c");
        assert!(f.contains("<figure id=\"f\">\n<svg></svg>"), "{f}");
    }
}
