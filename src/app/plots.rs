//! The plotting toolkit of every report (plotters, SVG): rendering a figure to an
//! SVG string, strip charts per method, colour maps and colour bars, arrows, and
//! the deformation surface of one image (the paper's Fig. 1). What a figure shows
//! is decided by the reports (`protocol_report`, `html_report`); the drawing
//! primitives they share live here.
use crate::error::{Error, Result};
use crate::model::board::{higher_dz, max_bend, HigherBend, Paraboloid};
use crate::model::target::Target;
use plotters::coord::Shift;
use plotters::prelude::*;

/// What a drawing function returns: plotters' errors as text, named by [`svg`].
pub type Drawn = std::result::Result<(), String>;

/// One data series of a strip chart: a value list per category.
pub struct Series<'a> {
    pub name: &'a str,
    pub color: RGBColor,
    pub groups: Vec<Vec<f64>>,
}

/// A horizontal reference line (e.g. the reference calibration's fx).
pub struct HLine<'a> {
    pub value: f64,
    pub name: &'a str,
    pub color: RGBColor,
}

/// The axis titles of a chart: units and, where a metric is plotted, its definition.
#[derive(Clone, Copy)]
pub struct Axes<'a> {
    pub x: &'a str,
    pub y: &'a str,
}

/// Tick labels (plotters sizes; the SVG shows them at 1/1.24 of this).
pub const LABEL: (&str, u32) = ("sans-serif", 15);
/// Axis titles.
pub const AXIS_DESC: (&str, u32) = ("sans-serif", 16);
/// Figure titles.
pub const TITLE: (&str, u32) = ("sans-serif", 20);

/// Colours of the series, in order.
pub const PALETTE: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
];

/// A plotters error as text.
pub fn pe<E: std::fmt::Debug>(e: E) -> String {
    format!("{e:?}")
}

/// Renders a figure of `size` pixels to an SVG string; `name` names the figure in
/// an error message.
pub fn svg(
    name: &str,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> Drawn,
) -> Result<String> {
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, size).into_drawing_area();
        let drawn = root
            .fill(&WHITE)
            .map_err(pe)
            .and_then(|_| draw(&root))
            .and_then(|_| root.present().map_err(pe));
        drawn.map_err(|e| Error::Invalid(format!("{name}: plotting failed: {e}")))?;
    }
    Ok(out)
}

fn mean_std(v: &[f64]) -> Option<(f64, f64)> {
    crate::model::metrics::Stat::of(v.iter().copied()).map(|s| (s.mean, s.std))
}

/// The value axis of a strip chart: every value, every mean ± std bar and every line.
fn value_range(series: &[Series], lines: &[HLine]) -> (f64, f64) {
    let bars = series.iter().flat_map(|s| s.groups.iter()).flat_map(|g| {
        let finite: Vec<f64> = g.iter().copied().filter(|v| v.is_finite()).collect();
        mean_std(&finite)
            .map(|(m, sd)| [m - sd, m + sd])
            .into_iter()
            .flatten()
    });
    let vals = series
        .iter()
        .flat_map(|s| s.groups.iter().flatten().copied())
        .chain(bars)
        .chain(lines.iter().map(|l| l.value));
    padded_range(vals, 0.08)
}

/// The range of the finite values, widened by `pad` of its span on each side (and
/// never empty, so a constant series still gets an axis).
pub fn padded_range(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * pad).max(1e-9 * hi.abs().max(lo.abs()).max(1e-12));
    (lo - pad, hi + pad)
}

/// The category named at axis position `x`: only whole positions carry a name.
pub fn category_label(cats: &[String], x: f64) -> String {
    let i = x.round();
    if (x - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < cats.len() {
        cats[i as usize].clone()
    } else {
        String::new()
    }
}

/// One series' finite values as points, offset and jittered within its strip.
fn strip_points(s: &Series, offset: f64, width: f64) -> Vec<(f64, f64)> {
    let mut points = Vec::new();
    for (ci, g) in s.groups.iter().enumerate() {
        for (k, &v) in g.iter().enumerate().filter(|(_, v)| v.is_finite()) {
            // Deterministic jitter from the golden ratio sequence.
            let jitter = ((k as f64 * 0.618_033_988_75).fract() - 0.5) * width * 0.6;
            points.push((ci as f64 + offset + jitter, v));
        }
    }
    points
}

/// The key of a strip chart: a dot per series, a line per reference line.
fn strip_key(series: &[Series], lines: &[HLine]) -> Vec<(Mark, String)> {
    let mut items: Vec<(Mark, String)> = series
        .iter()
        .map(|s| (Mark::Dot(s.color), s.name.to_string()))
        .collect();
    items.extend(
        lines
            .iter()
            .map(|l| (Mark::Line(l.color), l.name.to_string())),
    );
    items
}

/// Draws one strip chart on `area`: its title, its key when `key` is set, then a
/// dot per value per category and series, with mean ± std bars.
pub fn strip_chart<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    axes: Axes,
    categories: &[String],
    (series, lines): (&[Series], &[HLine]),
    key: bool,
) -> Drawn {
    let (lo, hi) = value_range(series, lines);
    let n = categories.len() as f64;
    let area = area.titled(title, TITLE).map_err(pe)?;
    let area = if key {
        let (strip, rest) = area.split_vertically(28);
        key_strip(&strip, 90, &strip_key(series, lines))?;
        rest
    } else {
        area
    };
    let mut chart = ChartBuilder::on(&area)
        .margin(12)
        .x_label_area_size(42)
        .y_label_area_size(78)
        .build_cartesian_2d(-0.5f64..n - 0.5, lo..hi)
        .map_err(pe)?;
    let cats = categories.to_vec();
    chart
        .configure_mesh()
        .label_style(LABEL)
        .axis_desc_style(AXIS_DESC)
        .disable_x_mesh()
        .light_line_style(BLACK.mix(0.04))
        .bold_line_style(BLACK.mix(0.15))
        .x_labels(categories.len() + 1)
        .x_label_formatter(&move |x| category_label(&cats, *x))
        .y_label_formatter(&tick)
        .x_desc(axes.x)
        .y_desc(axes.y)
        .draw()
        .map_err(pe)?;
    let width = 0.7 / series.len().max(1) as f64;
    for (si, s) in series.iter().enumerate() {
        let offset = (si as f64 + 0.5) * width - 0.35;
        let points = strip_points(s, offset, width);
        chart
            .draw_series(
                points
                    .iter()
                    .map(|&p| Circle::new(p, 2, s.color.mix(0.45).filled())),
            )
            .map_err(pe)?;
        for (ci, g) in s.groups.iter().enumerate() {
            let finite: Vec<f64> = g.iter().copied().filter(|v| v.is_finite()).collect();
            if let Some((m, sd)) = mean_std(&finite) {
                let x = ci as f64 + offset;
                let style = s.color.stroke_width(2);
                chart
                    .draw_series([
                        PathElement::new(vec![(x - width * 0.4, m), (x + width * 0.4, m)], style),
                        PathElement::new(vec![(x, m - sd), (x, m + sd)], style),
                    ])
                    .map_err(pe)?;
            }
        }
    }
    chart
        .draw_series(lines.iter().map(|l| {
            PathElement::new(
                vec![(-0.5, l.value), (n - 0.5, l.value)],
                l.color.stroke_width(1),
            )
        }))
        .map_err(pe)?;
    Ok(())
}

/// One strip chart as SVG text.
pub fn strip_chart_svg(
    title: &str,
    axes: Axes,
    categories: &[String],
    series: &[Series],
    lines: &[HLine],
) -> Result<String> {
    svg(title, (760, 460), |root| {
        strip_chart(root, title, axes, categories, (series, lines), true)
    })
}

/// One panel of [`panels_svg`]: title, axes, series and reference lines.
pub type Panel<'a> = (String, Axes<'a>, Vec<Series<'a>>, Vec<HLine<'a>>);

/// Strip charts in a grid of `columns` columns under one key, as SVG text; the
/// key is the first panel's (every panel should use the same colours and lines).
pub fn panels_svg(
    name: &str,
    panels: &[Panel],
    categories: &[String],
    columns: usize,
) -> Result<String> {
    let columns = columns.clamp(1, panels.len().max(1));
    let rows = panels.len().div_ceil(columns).max(1);
    let (w, h) = if columns == 1 { (760, 440) } else { (400, 330) };
    let size = (w * columns as u32, h * rows as u32 + 30);
    svg(name, size, |root| {
        let (strip, rest) = root.split_vertically(30);
        if let Some((_, _, series, lines)) = panels.first() {
            key_strip(&strip, 90, &strip_key(series, lines))?;
        }
        let areas = rest.split_evenly((rows, columns));
        for (area, (title, axes, series, lines)) in areas.iter().zip(panels) {
            strip_chart(area, title, *axes, categories, (series, lines), false)?;
        }
        Ok(())
    })
}

/// A diverging colour map, t in [-1, 1]: blue, white at 0, red.
pub fn diverging(t: f64) -> RGBColor {
    let t = if t.is_finite() {
        t.clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let lerp = |a: f64, b: f64, s: f64| (a + (b - a) * s).round() as u8;
    if t < 0.0 {
        let s = -t;
        RGBColor(
            lerp(255.0, 33.0, s),
            lerp(255.0, 102.0, s),
            lerp(255.0, 172.0, s),
        )
    } else {
        RGBColor(
            lerp(255.0, 178.0, t),
            lerp(255.0, 24.0, t),
            lerp(255.0, 43.0, t),
        )
    }
}

/// Viridis at nine evenly spaced points (matplotlib's table, rounded).
const VIRIDIS: [(u8, u8, u8); 9] = [
    (68, 1, 84),
    (71, 44, 122),
    (59, 81, 139),
    (44, 113, 142),
    (33, 144, 141),
    (39, 173, 129),
    (92, 200, 99),
    (170, 220, 50),
    (253, 231, 37),
];

/// A sequential colour map for magnitudes, t in [0, 1] (viridis: dark blue to
/// yellow, even in lightness, readable in grey and by the colour-blind).
pub fn sequential(t: f64) -> RGBColor {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (VIRIDIS.len() - 1) as f64;
    let i = (x.floor() as usize).min(VIRIDIS.len() - 2);
    let s = x - i as f64;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    let lerp = |p: u8, q: u8| (p as f64 + (q as f64 - p as f64) * s).round() as u8;
    RGBColor(lerp(a.0, b.0), lerp(a.1, b.1), lerp(a.2, b.2))
}

/// A vertical colour bar from `lo` to `hi` with `caption` (the quantity and its unit).
pub fn colour_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    caption: &str,
    (lo, hi): (f64, f64),
    colour: impl Fn(f64) -> RGBColor,
) -> Drawn {
    let hi = if hi > lo { hi } else { lo + 1e-12 };
    let mut bar = ChartBuilder::on(area)
        .margin_top(40)
        .margin_bottom(50)
        .margin_right(8)
        .y_label_area_size(58)
        .caption(caption, AXIS_DESC)
        .build_cartesian_2d(0.0..1.0, lo..hi)
        .map_err(pe)?;
    bar.configure_mesh()
        .label_style(LABEL)
        .axis_desc_style(AXIS_DESC)
        .disable_mesh()
        .disable_x_axis()
        .y_label_formatter(&tick)
        .y_label_style(LABEL)
        .draw()
        .map_err(pe)?;
    let steps = 64;
    let step = (hi - lo) / steps as f64;
    bar.draw_series((0..steps).map(|k| {
        let a = lo + step * k as f64;
        Rectangle::new([(0.0, a), (1.0, a + step)], colour(a + step / 2.0).filled())
    }))
    .map_err(pe)?;
    Ok(())
}

/// The polyline of an arrow from `from` along `v` with a head of `head` times its
/// length, in data coordinates (draw it on a chart of equal axis scales).
pub fn arrow(from: (f64, f64), v: (f64, f64), head: f64) -> Vec<(f64, f64)> {
    let tip = (from.0 + v.0, from.1 + v.1);
    let (bx, by) = (-v.0 * head, -v.1 * head);
    // The head's two barbs: the reversed shaft turned by ±25°.
    let (c, s) = (25f64.to_radians().cos(), 25f64.to_radians().sin());
    let left = (tip.0 + c * bx - s * by, tip.1 + s * bx + c * by);
    let right = (tip.0 + c * bx + s * by, tip.1 - s * bx + c * by);
    vec![from, tip, left, tip, right]
}

/// A "nice" number near `x` (1, 2 or 5 times a power of ten), for scales and steps.
pub fn nice(x: f64) -> f64 {
    if !(x.is_finite() && x > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(x.log10().floor());
    let m = x / p;
    let m = if m < 1.5 {
        1.0
    } else if m < 3.5 {
        2.0
    } else if m < 7.5 {
        5.0
    } else {
        10.0
    };
    m * p
}

/// A number in its shortest plain form (`200`, `0.5`, `-3`, `1e-5`), for tick
/// labels, scales and captions.
pub fn short(x: f64) -> String {
    if x.abs() < 1e-12 {
        "0".into()
    } else if x.abs() >= 1e6 || x.abs() < 1e-3 {
        format!("{x:e}")
    } else {
        let s = format!("{x:.6}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// The tick label of an axis value (plotters' label formatter).
pub fn tick(x: &f64) -> String {
    short(*x)
}

/// A mark in a figure's key.
#[derive(Debug, Clone, Copy)]
pub enum Mark {
    /// An arrow this many pixels long.
    Arrow(f64, RGBColor),
    /// A cross.
    Cross(RGBColor),
    /// A short line.
    Line(RGBColor),
    /// A dot.
    Dot(RGBColor),
}

/// A figure's key: one line of marks and their texts, drawn left to right from `x`
/// on `area` (a strip of about 30 pixels).
pub fn key_strip<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    x: i32,
    items: &[(Mark, String)],
) -> Drawn {
    let y = 14i32;
    let mut x = x;
    let text = ("sans-serif", 15).into_font().color(&BLACK);
    for (mark, label) in items {
        let width = match *mark {
            Mark::Arrow(len, colour) => {
                let pts: Vec<(i32, i32)> = arrow((x as f64, y as f64), (len, 0.0), 0.3)
                    .iter()
                    .map(|p| (p.0.round() as i32, p.1.round() as i32))
                    .collect();
                area.draw(&PathElement::new(pts, colour.stroke_width(2)))
                    .map_err(pe)?;
                len.round() as i32
            }
            Mark::Cross(colour) => {
                area.draw(&Cross::new((x + 5, y), 5, colour.stroke_width(2)))
                    .map_err(pe)?;
                10
            }
            Mark::Line(colour) => {
                area.draw(&PathElement::new(
                    vec![(x, y), (x + 18, y)],
                    colour.stroke_width(2),
                ))
                .map_err(pe)?;
                18
            }
            Mark::Dot(colour) => {
                area.draw(&Circle::new((x + 4, y), 4, colour.filled()))
                    .map_err(pe)?;
                8
            }
        };
        x += width + 6;
        area.draw(&Text::new(label.clone(), (x, y - 7), text.clone()))
            .map_err(pe)?;
        // About 7 pixels per character of this sans-serif (12 px in the SVG).
        x += 7 * label.chars().count() as i32 + 24;
    }
    Ok(())
}

/// The board's half extent (x, y) in metres: the outer corners plus half a square.
pub fn board_half_extent(target: &Target) -> (f64, f64) {
    let corners = target.nominal_points();
    let half_w = corners.iter().map(|p| p.x.abs()).fold(0.0, f64::max) + target.spacing / 2.0;
    let half_h = corners.iter().map(|p| p.y.abs()).fold(0.0, f64::max) + target.spacing / 2.0;
    (half_w, half_h)
}

/// Draws the out-of-plane deformation Δz of one image over the board on `root`:
/// a heat map of the whole estimated bend (the paraboloid plus any degree-3 and
/// -4 terms) with the corners marked and a colour bar in millimetres.
pub fn deformation_chart<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    target: &Target,
    bend: &Paraboloid,
    higher: &HigherBend,
) -> Drawn {
    let (half_w, half_h) = board_half_extent(target);
    let cells = 48;
    let (dx, dy) = (2.0 * half_w / cells as f64, 2.0 * half_h / cells as f64);
    let dz = |x: f64, y: f64| bend.dz(x, y) + higher_dz(higher, x, y);
    let centre = |i: usize, j: usize| {
        (
            -half_w + (i as f64 + 0.5) * dx,
            -half_h + (j as f64 + 0.5) * dy,
        )
    };
    // The colour scale covers the cells too: beyond the outer corners a cubic or
    // quartic bend may grow past its largest value at a corner.
    let max = (0..cells * cells)
        .map(|k| {
            let (x, y) = centre(k / cells, k % cells);
            dz(x, y).abs()
        })
        .fold(max_bend(target, bend, higher), f64::max)
        .max(1e-12);
    let width = root.dim_in_pixel().0;
    let (plot, legend) = root.split_horizontally(width.saturating_sub(110));
    let mut chart = ChartBuilder::on(&plot)
        .caption(title, TITLE)
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(-half_w * 1e3..half_w * 1e3, half_h * 1e3..-half_h * 1e3)
        .map_err(pe)?;
    chart
        .configure_mesh()
        .label_style(LABEL)
        .axis_desc_style(AXIS_DESC)
        .disable_mesh()
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .x_desc("board x (mm), along increasing col")
        .y_desc("board y (mm), along increasing row")
        .draw()
        .map_err(pe)?;
    let mut rects = Vec::with_capacity(cells * cells);
    for i in 0..cells {
        for j in 0..cells {
            let x0 = -half_w + i as f64 * dx;
            let y0 = -half_h + j as f64 * dy;
            let (x, y) = centre(i, j);
            let z = dz(x, y);
            rects.push(Rectangle::new(
                [(x0 * 1e3, y0 * 1e3), ((x0 + dx) * 1e3, (y0 + dy) * 1e3)],
                diverging(z / max).filled(),
            ));
        }
    }
    chart.draw_series(rects).map_err(pe)?;
    chart
        .draw_series(
            target
                .nominal_points()
                .iter()
                .map(|p| Circle::new((p.x * 1e3, p.y * 1e3), 2, BLACK.filled())),
        )
        .map_err(pe)?;
    colour_bar(&legend, "Δz (mm)", (-max * 1e3, max * 1e3), |v| {
        diverging(v / (max * 1e3))
    })
}

/// The pixel size of a board plot of `height` pixels whose plot area keeps the
/// board's aspect ratio, with `extra` pixels for axes and colour bar.
pub fn board_figure_size(target: &Target, height: u32, extra: u32) -> (u32, u32) {
    let (half_w, half_h) = board_half_extent(target);
    let width = ((height as f64 - 80.0) * half_w / half_h + extra as f64).clamp(420.0, 1400.0);
    (width as u32, height)
}

/// The out-of-plane deformation Δz of one image over the board as SVG text (the
/// paper's Fig. 1; `higher` is zero for the paper's paraboloid).
pub fn deformation_svg(
    title: &str,
    target: &Target,
    bend: &Paraboloid,
    higher: &HigherBend,
) -> Result<String> {
    let size = board_figure_size(target, 480, 200);
    svg(title, size, |root| {
        deformation_chart(root, title, target, bend, higher)
    })
}

/// The line segments where a scalar field on a grid crosses `level` (marching
/// squares over the cell centres), in fractional cell coordinates. NaN values
/// are holes: no line crosses a square touching one.
pub fn contour_segments(values: &[f64], nx: usize, ny: usize, level: f64) -> Vec<[(f64, f64); 2]> {
    let at = |i: usize, j: usize| values[j * nx + i];
    let mut out = Vec::new();
    for j in 0..ny.saturating_sub(1) {
        for i in 0..nx.saturating_sub(1) {
            // Corners counter-clockwise from (i, j).
            let p = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)];
            let v = p.map(|(a, b)| at(a, b));
            if v.iter().any(|x| !x.is_finite()) {
                continue;
            }
            let mut cuts = Vec::with_capacity(4);
            for e in 0..4 {
                let (a, b) = (e, (e + 1) % 4);
                if (v[a] > level) != (v[b] > level) {
                    let t = (level - v[a]) / (v[b] - v[a]);
                    let (pa, pb) = (p[a], p[b]);
                    cuts.push((
                        pa.0 as f64 + t * (pb.0 as f64 - pa.0 as f64),
                        pa.1 as f64 + t * (pb.1 as f64 - pa.1 as f64),
                    ));
                }
            }
            match cuts.len() {
                2 => out.push([cuts[0], cuts[1]]),
                4 => {
                    // A saddle: the centre decides which opposite corners connect.
                    let centre = v.iter().sum::<f64>() / 4.0;
                    if (centre > level) == (v[0] > level) {
                        out.push([cuts[0], cuts[1]]);
                        out.push([cuts[2], cuts[3]]);
                    } else {
                        out.push([cuts[3], cuts[0]]);
                        out.push([cuts[1], cuts[2]]);
                    }
                }
                _ => {}
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contours_of_a_cone_are_circles_of_the_level_radius() {
        // f = distance from the grid's centre: the contour at r is a circle of radius r.
        let (nx, ny) = (41, 41);
        let values: Vec<f64> = (0..nx * ny)
            .map(|k| {
                let (i, j) = ((k % nx) as f64 - 20.0, (k / nx) as f64 - 20.0);
                (i * i + j * j).sqrt()
            })
            .collect();
        let segs = contour_segments(&values, nx, ny, 12.3);
        assert!(segs.len() > 40);
        for s in segs {
            for (x, y) in s {
                let r = ((x - 20.0).powi(2) + (y - 20.0).powi(2)).sqrt();
                // Linear interpolation of a cone between grid points: within 0.05 cells.
                assert!((r - 12.3).abs() < 0.05, "{r}");
            }
        }
    }

    #[test]
    fn nice_numbers_are_1_2_5_steps() {
        assert_eq!(nice(0.9), 1.0);
        assert_eq!(nice(2.9), 2.0);
        assert_eq!(nice(4.0), 5.0);
        assert_eq!(nice(8.0), 10.0);
        assert!((nice(0.031) - 0.02).abs() < 1e-15);
        assert_eq!(nice(-1.0), 1.0);
    }

    #[test]
    fn an_arrow_ends_at_its_tip_with_symmetric_barbs() {
        let a = arrow((1.0, 2.0), (3.0, 0.0), 0.2);
        assert_eq!(a[0], (1.0, 2.0));
        assert_eq!(a[1], (4.0, 2.0));
        // Barbs mirror each other about the shaft and point back along it.
        assert!((a[2].1 - 2.0 + (a[4].1 - 2.0)).abs() < 1e-12);
        assert!(a[2].0 < 4.0 && (a[2].0 - a[4].0).abs() < 1e-12);
        let len = ((a[2].0 - 4.0).powi(2) + (a[2].1 - 2.0).powi(2)).sqrt();
        assert!((len - 0.6).abs() < 1e-12);
    }
}
