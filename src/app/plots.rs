//! SVG plots of protocol results (plotters): strip charts per method and the
//! deformation surface of one image (the paper's Fig. 1).
use crate::error::{Error, Result};
use crate::model::board::Paraboloid;
use crate::model::target::Target;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

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

/// Colours of the series, in order.
pub const PALETTE: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
];

fn plot_err<E: std::fmt::Debug>(path: &Path) -> impl Fn(E) -> Error + '_ {
    move |e| Error::Invalid(format!("{}: plotting failed: {e:?}", path.display()))
}

fn mean_std(v: &[f64]) -> Option<(f64, f64)> {
    crate::model::metrics::Stat::of(v.iter().copied()).map(|s| (s.mean, s.std))
}

fn value_range(series: &[Series], lines: &[HLine]) -> (f64, f64) {
    let vals = series
        .iter()
        .flat_map(|s| s.groups.iter().flatten().copied())
        .chain(lines.iter().map(|l| l.value))
        .filter(|v| v.is_finite());
    let (lo, hi) = vals.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.08).max(1e-9 * hi.abs().max(1.0));
    (lo - pad, hi + pad)
}

/// The category named at axis position `x`: only whole positions carry a name.
fn category_label(cats: &[String], x: f64) -> String {
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

/// Draws one strip chart (points per category and series, mean ± std bars) on `area`.
pub fn strip_chart<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    y_label: &str,
    categories: &[String],
    series: &[Series],
    lines: &[HLine],
) -> std::result::Result<(), String> {
    let (lo, hi) = value_range(series, lines);
    let n = categories.len() as f64;
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5f64..n - 0.5, lo..hi)
        .map_err(|e| format!("{e:?}"))?;
    let cats = categories.to_vec();
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(categories.len() + 1)
        .x_label_formatter(&move |x| category_label(&cats, *x))
        .y_desc(y_label)
        .draw()
        .map_err(|e| format!("{e:?}"))?;
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
            .map_err(|e| format!("{e:?}"))?
            .label(s.name)
            .legend(move |(x, y)| Circle::new((x, y), 4, s.color.filled()));
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
                    .map_err(|e| format!("{e:?}"))?;
            }
        }
    }
    for l in lines {
        let color = l.color;
        chart
            .draw_series([PathElement::new(
                vec![(-0.5, l.value), (n - 0.5, l.value)],
                color.stroke_width(1),
            )])
            .map_err(|e| format!("{e:?}"))?
            .label(l.name)
            .legend(move |(x, y)| PathElement::new(vec![(x - 6, y), (x + 6, y)], color));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| format!("{e:?}"))?;
    Ok(())
}

/// One strip chart as an SVG file.
pub fn strip_chart_svg(
    path: &Path,
    title: &str,
    y_label: &str,
    categories: &[String],
    series: &[Series],
    lines: &[HLine],
) -> Result<()> {
    let root = SVGBackend::new(path, (760, 440)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err(path))?;
    strip_chart(&root, title, y_label, categories, series, lines).map_err(plot_err(path))?;
    root.present().map_err(plot_err(path))
}

/// Several strip charts side by side in one SVG file.
pub fn panels_svg(
    path: &Path,
    panels: &[(&str, &str, Vec<Series>, Vec<HLine>)],
    categories: &[String],
) -> Result<()> {
    let root = SVGBackend::new(path, (520 * panels.len() as u32, 440)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err(path))?;
    let areas = root.split_evenly((1, panels.len()));
    for (area, (title, label, series, lines)) in areas.iter().zip(panels) {
        strip_chart(area, title, label, categories, series, lines).map_err(plot_err(path))?;
    }
    root.present().map_err(plot_err(path))
}

fn diverging(t: f64) -> RGBColor {
    // t in [-1, 1]: blue — white — red.
    let t = t.clamp(-1.0, 1.0);
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

/// The out-of-plane deformation Δz of one image over the board, as a heat map with
/// the corners marked (the paper's Fig. 1).
pub fn deformation_svg(path: &Path, title: &str, target: &Target, bend: &Paraboloid) -> Result<()> {
    let corners = target.nominal_points();
    let half_w = corners.iter().map(|p| p.x.abs()).fold(0.0, f64::max) + target.spacing / 2.0;
    let half_h = corners.iter().map(|p| p.y.abs()).fold(0.0, f64::max) + target.spacing / 2.0;
    let max = bend.max_out_of_plane(target).max(1e-12);
    let aspect = half_w / half_h;
    let height = 480u32;
    let width = ((height as f64 - 60.0) * aspect + 190.0).clamp(400.0, 1400.0) as u32;
    let root = SVGBackend::new(path, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err(path))?;
    let (plot, legend) = root.split_horizontally(width - 110);
    let mut chart = ChartBuilder::on(&plot)
        .caption(title, ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(-half_w..half_w, half_h..-half_h)
        .map_err(plot_err(path))?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("board x (m)")
        .y_desc("board y (m)")
        .draw()
        .map_err(plot_err(path))?;
    let cells = 48;
    let (dx, dy) = (2.0 * half_w / cells as f64, 2.0 * half_h / cells as f64);
    let mut rects = Vec::with_capacity(cells * cells);
    for i in 0..cells {
        for j in 0..cells {
            let x0 = -half_w + i as f64 * dx;
            let y0 = -half_h + j as f64 * dy;
            let z = bend.dz(x0 + dx / 2.0, y0 + dy / 2.0);
            rects.push(Rectangle::new(
                [(x0, y0), (x0 + dx, y0 + dy)],
                diverging(z / max).filled(),
            ));
        }
    }
    chart.draw_series(rects).map_err(plot_err(path))?;
    chart
        .draw_series(
            corners
                .iter()
                .map(|p| Circle::new((p.x, p.y), 2, BLACK.filled())),
        )
        .map_err(plot_err(path))?;
    // Colour bar in millimetres.
    let mut bar = ChartBuilder::on(&legend)
        .margin_top(40)
        .margin_bottom(40)
        .margin_right(10)
        .y_label_area_size(60)
        .caption("Δz (mm)", ("sans-serif", 14))
        .build_cartesian_2d(0.0..1.0, -max * 1e3..max * 1e3)
        .map_err(plot_err(path))?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_label_style(("sans-serif", 12))
        .draw()
        .map_err(plot_err(path))?;
    let steps = 64;
    bar.draw_series((0..steps).map(|k| {
        let a = -max + 2.0 * max * k as f64 / steps as f64;
        let b = a + 2.0 * max / steps as f64;
        Rectangle::new(
            [(0.0, a * 1e3), (1.0, b * 1e3)],
            diverging((a + b) / 2.0 / max).filled(),
        )
    }))
    .map_err(plot_err(path))?;
    root.present().map_err(plot_err(path))
}
