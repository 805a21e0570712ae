//! `deformcal target`: a printable board as an SVG page at true size (millimetre
//! units), so the board a user prints is the board the config describes. The
//! board's black and white rectangles come from calib-targets' printable-target
//! generator (OpenCV's ChArUco layout, the chessboard of docs/conventions.md);
//! this module lays them on the paper with a white border, a caption that gives
//! the config's `[target]` section, and a 10 cm scale bar to check the printer's
//! scale. No detection, no config reading.

use crate::app::detect::charuco::CharucoSpec;
use crate::error::{Error, Result};
use calib_targets::printable::{
    board_primitives, ChessboardTargetSpec, Fill, Primitive, TargetSpec,
};
use std::fmt::Write as _;
use std::path::PathBuf;

/// The printer's unprintable edge kept clear on every side, mm.
pub const PAGE_MARGIN_MM: f64 = 10.0;
/// Height of the caption block under the board (text and scale bar), mm.
pub const CAPTION_MM: f64 = 24.0;
/// Length of the scale bar, mm.
pub const SCALE_BAR_MM: f64 = 100.0;

/// The kind of board to print.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BoardType {
    /// A chessboard: --rows × --cols inner corners.
    Chessboard,
    /// A ChArUco board in OpenCV's layout: --rows × --cols squares.
    Charuco,
}

/// Paper formats, portrait width × height in mm.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Paper {
    /// ISO A4, 210 × 297 mm.
    #[value(name = "A4", alias = "a4")]
    A4,
    /// ISO A3, 297 × 420 mm.
    #[value(name = "A3", alias = "a3")]
    A3,
    /// US Letter, 215.9 × 279.4 mm.
    #[value(name = "Letter", alias = "letter")]
    Letter,
}

impl Paper {
    /// Portrait width and height, mm.
    pub fn size_mm(self) -> (f64, f64) {
        match self {
            Paper::A4 => (210.0, 297.0),
            Paper::A3 => (297.0, 420.0),
            Paper::Letter => (215.9, 279.4),
        }
    }

    fn name(self) -> &'static str {
        match self {
            Paper::A4 => "A4",
            Paper::A3 => "A3",
            Paper::Letter => "Letter",
        }
    }
}

/// `deformcal target`'s arguments.
#[derive(Clone, Debug, clap::Args)]
pub struct Args {
    /// The board: `chessboard` (rows × cols inner corners) or `charuco`
    /// (rows × cols squares, OpenCV's layout).
    #[arg(long = "type", value_enum, default_value = "chessboard")]
    pub kind: BoardType,
    /// Inner corners per column (chessboard) or squares per column (charuco).
    #[arg(long)]
    pub rows: usize,
    /// Inner corners per row (chessboard) or squares per row (charuco).
    #[arg(long)]
    pub cols: usize,
    /// Square side in metres (the config's `spacing` or `square`).
    #[arg(long)]
    pub square: f64,
    /// ChArUco marker side in metres.
    #[arg(long)]
    pub marker: Option<f64>,
    /// ChArUco marker dictionary, OpenCV's name (e.g. DICT_5X5_100).
    #[arg(long)]
    pub dictionary: Option<String>,
    /// Paper format.
    #[arg(long, value_enum, default_value = "A4")]
    pub paper: Paper,
    /// Where to write the SVG.
    #[arg(long)]
    pub out: PathBuf,
}

/// Where the board landed on the page (mm, from the page's top-left corner).
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    /// Page width and height, mm (landscape when the board is wider than tall).
    pub page_mm: (f64, f64),
    /// The board's top-left outer corner (of its squares), mm.
    pub board_origin_mm: (f64, f64),
    /// The board's squares' width and height, mm.
    pub board_mm: (f64, f64),
}

impl std::fmt::Display for Layout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "board {:.1} × {:.1} mm on a {} × {} mm page, its top-left square at ({:.1}, {:.1}) mm; print at 100 % and check the 100 mm bar",
            self.board_mm.0,
            self.board_mm.1,
            self.page_mm.0,
            self.page_mm.1,
            self.board_origin_mm.0,
            self.board_origin_mm.1
        )
    }
}

/// Writes the SVG and returns where the board is on the page.
pub fn run(args: &Args) -> Result<Layout> {
    let (svg, layout) = svg(args)?;
    crate::app::fsio::write_atomic(&args.out, svg.as_bytes())?;
    Ok(layout)
}

/// The board's rectangles (mm, origin at its outer top-left corner), its size,
/// and the caption's `[target]` lines.
fn board(args: &Args) -> Result<(Vec<Primitive>, (f64, f64), String)> {
    let bad = |m: String| Error::Invalid(format!("target: {m}"));
    if let Some(p) = crate::model::target::spacing_problem(args.square) {
        return Err(bad(format!("--square {p}")));
    }
    let square_mm = args.square * 1000.0;
    match args.kind {
        BoardType::Chessboard => {
            if args.marker.is_some() || args.dictionary.is_some() {
                return Err(bad(
                    "--marker and --dictionary are for --type charuco".into()
                ));
            }
            if args.rows < 2 || args.cols < 2 || args.rows > 1000 || args.cols > 1000 {
                return Err(bad(format!(
                    "a chessboard needs 2 to 1000 inner corners a side (got {} × {})",
                    args.rows, args.cols
                )));
            }
            let spec = ChessboardTargetSpec::new(args.rows as u32, args.cols as u32, square_mm);
            let prims =
                board_primitives(&TargetSpec::Chessboard(spec)).map_err(|e| bad(e.to_string()))?;
            let size = (
                (args.cols + 1) as f64 * square_mm,
                (args.rows + 1) as f64 * square_mm,
            );
            let config = format!(
                "[target] rows = {} cols = {} spacing = {}",
                args.rows, args.cols, args.square
            );
            Ok((prims, size, config))
        }
        BoardType::Charuco => {
            let (Some(marker), Some(dictionary)) = (args.marker, args.dictionary.clone()) else {
                return Err(bad("--type charuco needs --marker and --dictionary".into()));
            };
            let spec = CharucoSpec {
                rows: args.rows,
                cols: args.cols,
                square: args.square,
                marker,
                dictionary,
            };
            if let Some(p) = spec.problem() {
                return Err(bad(p));
            }
            let prims = spec
                .primitives()
                .ok_or_else(|| bad("calib-targets refused the board".into()))?;
            let size = (args.cols as f64 * square_mm, args.rows as f64 * square_mm);
            let config = format!(
                "[target] type = \"charuco\" rows = {} cols = {} square = {} marker = {} dictionary = \"{}\"",
                spec.rows, spec.cols, spec.square, spec.marker, spec.dictionary
            );
            Ok((prims, size, config))
        }
    }
}

/// The page: the board centred in the space above the caption, with a white
/// border of half a square (detectors need the outer squares' edges) inside the
/// printer's margins.
fn layout(args: &Args, board_mm: (f64, f64)) -> Result<Layout> {
    let quiet = 0.5 * args.square * 1000.0;
    let (pw, ph) = args.paper.size_mm();
    let need = |(w, h): (f64, f64)| {
        let (bw, bh) = (board_mm.0 + 2.0 * quiet, board_mm.1 + 2.0 * quiet);
        let free_w = w - 2.0 * PAGE_MARGIN_MM;
        let free_h = h - 2.0 * PAGE_MARGIN_MM - CAPTION_MM;
        (bw <= free_w && bh <= free_h).then_some((free_w, free_h))
    };
    let landscape = board_mm.0 > board_mm.1;
    let pages = if landscape {
        [(ph, pw), (pw, ph)]
    } else {
        [(pw, ph), (ph, pw)]
    };
    for page in pages {
        if let Some((free_w, free_h)) = need(page) {
            let x = PAGE_MARGIN_MM + (free_w - board_mm.0) / 2.0;
            let y = PAGE_MARGIN_MM + (free_h - board_mm.1) / 2.0;
            return Ok(Layout {
                page_mm: page,
                board_origin_mm: (x, y),
                board_mm,
            });
        }
    }
    let squares = match args.kind {
        BoardType::Chessboard => ((args.cols + 2) as f64, (args.rows + 2) as f64),
        BoardType::Charuco => ((args.cols + 1) as f64, (args.rows + 1) as f64),
    };
    let largest = [(pw, ph), (ph, pw)]
        .iter()
        .map(|(w, h)| {
            ((w - 2.0 * PAGE_MARGIN_MM) / squares.0)
                .min((h - 2.0 * PAGE_MARGIN_MM - CAPTION_MM) / squares.1)
        })
        .fold(0.0, f64::max);
    Err(Error::Invalid(format!(
        "target: the board is {:.1} × {:.1} mm, with its white border of half a square {:.1} × {:.1} mm: it does not fit on {} ({} × {} mm) inside {} mm margins and the caption; use a larger paper or a square of at most {:.1} mm",
        board_mm.0,
        board_mm.1,
        board_mm.0 + 2.0 * quiet,
        board_mm.1 + 2.0 * quiet,
        args.paper.name(),
        pw,
        ph,
        PAGE_MARGIN_MM,
        (largest * 10.0).floor() / 10.0
    )))
}

/// The SVG text and the layout.
pub fn svg(args: &Args) -> Result<(String, Layout)> {
    let (prims, board_mm, config) = board(args)?;
    let lay = layout(args, board_mm)?;
    let (pw, ph) = lay.page_mm;
    let (ox, oy) = lay.board_origin_mm;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{pw}mm\" height=\"{ph}mm\" viewBox=\"0 0 {pw} {ph}\">"
    );
    let _ = writeln!(s, "<rect width=\"{pw}\" height=\"{ph}\" fill=\"#ffffff\"/>");
    let _ = writeln!(
        s,
        "<g id=\"board\" transform=\"translate({ox:.4} {oy:.4})\">"
    );
    let mut black_drawn: Vec<[f64; 4]> = Vec::new();
    for p in &prims {
        let Primitive::Rect {
            x_mm,
            y_mm,
            width_mm,
            height_mm,
            fill,
        } = p
        else {
            continue;
        };
        let rect = [*x_mm, *y_mm, *x_mm + *width_mm, *y_mm + *height_mm];
        let colour = if *fill == Fill::Black {
            black_drawn.push(rect);
            "#000000"
        } else if black_drawn.iter().any(|b| overlap(b, &rect)) {
            "#ffffff"
        } else {
            // White on the white page already. Painting it again makes
            // anti-aliasing renderers (cairo) cover the seam it shares with a
            // black square twice, which moves the edge up to 0.25 px into the
            // black square in a raster of the SVG.
            continue;
        };
        let _ = writeln!(
            s,
            "<rect x=\"{x_mm:.4}\" y=\"{y_mm:.4}\" width=\"{width_mm:.4}\" height=\"{height_mm:.4}\" fill=\"{colour}\"/>"
        );
    }
    s.push_str("</g>\n");
    caption(&mut s, args, &lay, &config);
    s.push_str("</svg>\n");
    Ok((s, lay))
}

/// Whether two rectangles `[x0, y0, x1, y1]` share some area (a shared edge
/// alone is no overlap).
fn overlap(a: &[f64; 4], b: &[f64; 4]) -> bool {
    a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3]
}

/// The caption block at the page's foot: the board, the config lines, how to
/// print, and the scale bar with a tick per centimetre.
fn caption(s: &mut String, args: &Args, lay: &Layout, config: &str) {
    let (_, ph) = lay.page_mm;
    let x0 = PAGE_MARGIN_MM;
    let top = ph - PAGE_MARGIN_MM - CAPTION_MM;
    let what = match args.kind {
        BoardType::Chessboard => format!(
            "deformcal chessboard: {} × {} inner corners, squares {:.2} mm",
            args.rows,
            args.cols,
            args.square * 1000.0
        ),
        BoardType::Charuco => format!(
            "deformcal ChArUco (OpenCV layout): {} × {} squares of {:.2} mm, markers {:.2} mm, {}",
            args.rows,
            args.cols,
            args.square * 1000.0,
            args.marker.unwrap_or(0.0) * 1000.0,
            args.dictionary.as_deref().unwrap_or("")
        ),
    };
    let lines = [
        what,
        config.to_string(),
        format!(
            "Print on {} at 100 % (no \"fit to page\"); the bar must measure 100 mm. Glue it flat or measure it (board.json).",
            args.paper.name()
        ),
    ];
    let font = "font-family=\"DejaVu Sans, Helvetica, Arial, sans-serif\" font-size=\"3\"";
    for (i, line) in lines.iter().enumerate() {
        let _ = writeln!(
            s,
            "<text x=\"{x0}\" y=\"{:.2}\" {font}>{}</text>",
            top + 3.5 + 4.0 * i as f64,
            xml_escape(line)
        );
    }
    let bar_y = top + 17.0;
    let _ = writeln!(
        s,
        "<rect id=\"scale-bar\" x=\"{x0}\" y=\"{bar_y}\" width=\"{SCALE_BAR_MM}\" height=\"1.5\" fill=\"#000000\"/>"
    );
    for cm in 0..=10 {
        let x = x0 + cm as f64 * 10.0;
        let h = if cm % 5 == 0 { 4.0 } else { 2.5 };
        let _ = writeln!(
            s,
            "<rect x=\"{:.2}\" y=\"{:.2}\" width=\"0.3\" height=\"{h}\" fill=\"#000000\"/>",
            x - 0.15,
            bar_y - h + 1.5
        );
    }
    let _ = writeln!(
        s,
        "<text x=\"{:.2}\" y=\"{:.2}\" {font}>100 mm</text>",
        x0 + SCALE_BAR_MM + 3.0,
        bar_y + 1.5
    );
}

fn xml_escape(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}
