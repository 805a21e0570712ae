//! The calibration report's figures, drawn with plotters as SVG text: residual
//! arrows over the image, the per-view RMSE bars, the lens's distortion field, the
//! static correction over the board and the bends along the sequence. What is
//! drawn comes from `fields`; the shared primitives (arrows, colour maps, colour
//! bars, the bend surface) from `app::plots`.
use crate::app::html_report::fields::{Arrows, Grid};
use crate::app::plots::contour_segments;
use crate::app::plots::{self, pe, short, Drawn, Mark, AXIS_DESC, LABEL, PALETTE, TITLE};
use crate::app::raster;
use crate::error::Result;
use crate::model::board::{Method, Paraboloid};
use crate::model::target::Target;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// Width of the image-sized figures, pixels.
const FIGURE_WIDTH: u32 = 900;
/// Left axis area of the image-sized figures, pixels.
const Y_AXIS: u32 = 70;
/// Margin around a chart, pixels.
const MARGIN: u32 = 10;
/// Caption height of a chart, pixels.
const CAPTION: u32 = 34;
/// Bottom axis area, pixels.
const X_AXIS: u32 = 44;
/// Key strip below a figure, pixels.
const KEY: u32 = 30;
/// Where a key strip starts, pixels from the left.
const KEY_X: i32 = (Y_AXIS + MARGIN) as i32;
/// Width of a colour bar beside a map, pixels.
const BAR: u32 = 130;

/// The figure size and plot area of an image-sized chart whose plot area keeps the
/// image's aspect ratio, `right` pixels reserved for a colour bar.
fn image_figure(width: u32, height: u32, right: u32) -> (u32, u32) {
    let plot_w = FIGURE_WIDTH - Y_AXIS - 2 * MARGIN - right;
    let plot_h = (plot_w as f64 * height as f64 / width.max(1) as f64).round() as u32;
    (FIGURE_WIDTH, plot_h + CAPTION + X_AXIS + 2 * MARGIN + KEY)
}

/// A chart over the image in pixel coordinates, v downwards as in the image.
fn image_chart<'a, DB: DrawingBackend + 'a>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    width: u32,
    height: u32,
) -> std::result::Result<
    ChartContext<
        'a,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    String,
> {
    let (w, h) = (width as f64, height as f64);
    let mut chart = ChartBuilder::on(area)
        .caption(title, TITLE)
        .margin(MARGIN)
        .x_label_area_size(X_AXIS)
        .y_label_area_size(Y_AXIS)
        .build_cartesian_2d(-0.5..w - 0.5, h - 0.5..-0.5)
        .map_err(pe)?;
    chart
        .configure_mesh()
        .label_style(LABEL)
        .axis_desc_style(AXIS_DESC)
        .disable_mesh()
        .x_label_formatter(&plots::tick)
        .y_label_formatter(&plots::tick)
        .x_desc("u (px), pixel centres at integers")
        .y_desc("v (px), downwards")
        .draw()
        .map_err(pe)?;
    chart
        .draw_series([Rectangle::new(
            [(-0.5, -0.5), (w - 0.5, h - 0.5)],
            BLACK.mix(0.5).stroke_width(1),
        )])
        .map_err(pe)?;
    Ok(chart)
}

/// Residual arrows (observed − projected, × `scale`) at every drawn corner, with
/// the rejected outliers as red crosses.
pub fn residual_quiver(
    title: &str,
    (width, height): (u32, u32),
    a: &Arrows,
    rejected: &[[f64; 2]],
    scale: f64,
) -> Result<String> {
    let size = image_figure(width, height, 0);
    // Thousands of arrows: one <path> spliced in for them (`raster`), not one
    // element each.
    let mut arrows = String::new();
    let mut svg = plots::svg(title, size, |root| {
        let (top, key) = root.split_vertically(size.1 - KEY);
        let mut chart = image_chart(&top, title, width, height)?;
        arrows = raster::polylines_path(
            a.arrows.iter().map(|(p, r)| {
                plots::arrow((p[0], p[1]), (r[0] * scale, r[1] * scale), 0.3)
                    .iter()
                    .map(|q| chart.backend_coord(q))
                    .collect()
            }),
            PALETTE[0],
            0.8,
            1,
        );
        raster::placeholder(&mut chart, (-0.5, -0.5), (-0.5, -0.5))?;
        chart
            .draw_series(
                rejected
                    .iter()
                    .map(|p| Cross::new((p[0], p[1]), 5, RED.stroke_width(2))),
            )
            .map_err(pe)?;
        // The key's arrow: a residual of `unit` pixels at the plot's scale.
        let plot_px_per_image_px = (size.0 - Y_AXIS - 2 * MARGIN) as f64 / width as f64;
        let unit = plots::nice(60.0 / (scale * plot_px_per_image_px));
        let items = [
            (
                Mark::Arrow(unit * scale * plot_px_per_image_px, PALETTE[0]),
                format!("{} px residual (drawn ×{})", short(unit), short(scale)),
            ),
            (
                Mark::Cross(RED),
                format!("rejected outlier ({})", rejected.len()),
            ),
        ];
        plots::key_strip(&key, KEY_X, &items)
    })?;
    raster::splice(&mut svg, |_| Ok(arrows))
        .map_err(|e| crate::error::Error::Invalid(format!("{title}: plotting failed: {e}")))?;
    Ok(svg)
}

/// A label cut to at most `n` characters, keeping its end (a file name's tail
/// tells images apart).
fn tail(label: &str, n: usize) -> String {
    let count = label.chars().count();
    if count <= n {
        label.to_string()
    } else {
        let kept: String = label.chars().skip(count - (n - 1)).collect();
        format!("…{kept}")
    }
}

/// Horizontal bars of per-view RMSE, in the order given (worst first), with the
/// overall RMSE and, where known, the RMSE noise alone would give.
pub fn rmse_bars(
    title: &str,
    bars: &[(String, f64)],
    overall: f64,
    noise_rmse: Option<f64>,
) -> Result<String> {
    let n = bars.len().max(1);
    let labels: Vec<String> = bars.iter().map(|(l, _)| tail(l, 40)).collect();
    let longest = labels.iter().map(|l| l.chars().count()).max().unwrap_or(5);
    // Room for the labels and the axis title beside them.
    let label_w = (longest as u32 * 8 + 40).clamp(90, 360);
    let size = (FIGURE_WIDTH, 18 * n as u32 + 150);
    let max = bars
        .iter()
        .map(|b| b.1)
        .chain([overall])
        .chain(noise_rmse)
        .fold(0.0, f64::max)
        .max(1e-9);
    plots::svg(title, size, |root| {
        let (top, key) = root.split_vertically(size.1 - KEY);
        let mut chart = ChartBuilder::on(&top)
            .caption(title, TITLE)
            .margin(MARGIN)
            .x_label_area_size(X_AXIS)
            .y_label_area_size(label_w)
            .build_cartesian_2d(0.0..max * 1.08, (n as f64 - 0.5)..-0.5)
            .map_err(pe)?;
        chart
            .configure_mesh()
            .label_style(LABEL)
            .axis_desc_style(AXIS_DESC)
            .disable_y_mesh()
            .y_labels(n + 1)
            .y_label_formatter(&|y| plots::category_label(&labels, *y))
            .y_label_style(LABEL)
            .x_label_formatter(&plots::tick)
            .x_desc("RMSE of the image's corners (px) = √(Σ‖u − p‖² / n)")
            .y_desc("image, worst first")
            .draw()
            .map_err(pe)?;
        chart
            .draw_series(bars.iter().enumerate().map(|(i, (_, v))| {
                let i = i as f64;
                Rectangle::new([(0.0, i - 0.35), (*v, i + 0.35)], PALETTE[0].filled())
            }))
            .map_err(pe)?;
        let (top_y, bottom_y) = (-0.5, n as f64 - 0.5);
        let mut items = vec![(
            Mark::Line(PALETTE[3]),
            format!("this camera, all images: {overall:.3} px"),
        )];
        let mut lines = vec![(overall, PALETTE[3])];
        if let Some(e) = noise_rmse {
            items.push((
                Mark::Line(PALETTE[2]),
                format!("noise alone: √(2σ̂²(1 − p/N)) = {e:.3} px"),
            ));
            lines.push((e, PALETTE[2]));
        }
        chart
            .draw_series(lines.iter().map(|&(x, c)| {
                PathElement::new(vec![(x, top_y), (x, bottom_y)], c.stroke_width(2))
            }))
            .map_err(pe)?;
        plots::key_strip(&key, label_w as i32 + MARGIN as i32, &items)
    })
}

/// What the distortion figure shows, for its caption.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DistortionScale {
    /// Largest displacement over the image (finite values), pixels.
    pub max_px: f64,
    /// The colour scale's top; larger values are drawn in its colour.
    pub clip_px: f64,
    /// Contour step, pixels.
    pub step_px: f64,
    /// Arrow length per pixel of displacement.
    pub arrow_scale: f64,
}

/// The share of the image whose displacement the colour scale spans.
pub const CLIP_QUANTILE: f64 = 0.97;

/// The scales of a distortion field: the colour range up to the displacement
/// [`CLIP_QUANTILE`] of the image stays below (at most the image diagonal), about
/// six contour levels, arrows about one cell long at most.
pub fn distortion_scale(
    grid: &Grid<Option<[f64; 2]>>,
    diagonal: f64,
    arrow_cell: f64,
) -> DistortionScale {
    let mut lengths: Vec<f64> = grid
        .values
        .iter()
        .flatten()
        .map(|d| d[0].hypot(d[1]))
        .collect();
    lengths.sort_by(f64::total_cmp);
    let max_px = lengths.last().copied().unwrap_or(0.0);
    // A polynomial lens can run away in the corners it was not fitted on: the
    // scales follow the bulk of the image, not its most extreme cells.
    let bulk = lengths
        .get((lengths.len() as f64 * CLIP_QUANTILE) as usize)
        .copied()
        .unwrap_or(max_px);
    let clip_px = bulk.min(diagonal).max(1e-9);
    let step_px = plots::nice(clip_px / 6.0);
    let arrow_scale = plots::nice(0.9 * arrow_cell / clip_px.max(1e-9));
    DistortionScale {
        max_px,
        clip_px,
        step_px,
        arrow_scale,
    }
}

/// The lens's displacement from its pinhole over the image: magnitude as colour
/// with contour lines, and the direction as arrows on a coarser grid.
pub fn distortion_map(
    title: &str,
    (width, height): (u32, u32),
    grid: &Grid<Option<[f64; 2]>>,
    s: &DistortionScale,
    arrow_every: usize,
) -> Result<String> {
    let bar = BAR;
    let size = image_figure(width, height, bar);
    let magnitude: Vec<f64> = grid
        .values
        .iter()
        .map(|d| d.map_or(f64::NAN, |d| d[0].hypot(d[1])))
        .collect();
    let mut svg = plots::svg(title, size, |root| {
        let (main, legend) = root.split_horizontally(size.0 - bar);
        let (top, key) = main.split_vertically(size.1 - KEY);
        let mut chart = image_chart(&top, title, width, height)?;
        let extent = (
            grid.nx as f64 * grid.dx - 0.5,
            grid.ny as f64 * grid.dy - 0.5,
        );
        raster::placeholder(&mut chart, (-0.5, -0.5), extent)?;
        draw_contours(&mut chart, grid, &magnitude, s)?;
        let arrows = (0..grid.ny)
            .skip(arrow_every / 2)
            .step_by(arrow_every.max(1))
            .flat_map(|j| {
                (0..grid.nx)
                    .skip(arrow_every / 2)
                    .step_by(arrow_every.max(1))
                    .map(move |i| (i, j))
            })
            .filter_map(|(i, j)| {
                let d = grid.values[j * grid.nx + i]?;
                let p = grid.centre(i, j);
                // Beyond the colour scale's top an arrow keeps its direction, not its length.
                let cut = (s.clip_px / d[0].hypot(d[1]).max(1e-12)).min(1.0);
                let v = (d[0] * s.arrow_scale * cut, d[1] * s.arrow_scale * cut);
                Some(PathElement::new(
                    plots::arrow(p, v, 0.3),
                    WHITE.stroke_width(2),
                ))
            });
        chart.draw_series(arrows).map_err(pe)?;
        let plot_px_per_image_px = (size.0 - bar - Y_AXIS - 2 * MARGIN) as f64 / width as f64;
        let unit = plots::nice(60.0 / (s.arrow_scale * plot_px_per_image_px));
        let items = [(
            Mark::Arrow(unit * s.arrow_scale * plot_px_per_image_px, PALETTE[0]),
            format!(
                "{} px displacement (drawn ×{}; white on the map)",
                short(unit),
                short(s.arrow_scale)
            ),
        )];
        plots::key_strip(&key, KEY_X, &items)?;
        plots::colour_bar(&legend, "length (px)", (0.0, s.clip_px), |v| {
            plots::sequential(v / s.clip_px)
        })
    })?;
    raster::embed(&mut svg, &heat_cells(grid, &magnitude, s.clip_px))
        .map_err(|e| crate::error::Error::Invalid(format!("{title}: plotting failed: {e}")))?;
    Ok(svg)
}

type PixelChart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// A grid's values as coloured cells (grey where a value is missing), one
/// embedded image put in place of [`raster::placeholder`] by [`raster::embed`].
fn heat_cells<T>(grid: &Grid<T>, values: &[f64], clip: f64) -> raster::Cells {
    let colours = values
        .iter()
        .map(|&value| {
            if value.is_finite() {
                plots::sequential(value / clip)
            } else {
                RGBColor(200, 200, 200)
            }
        })
        .collect();
    raster::Cells {
        columns: grid.nx,
        rows: grid.ny,
        colours,
    }
}

/// Contour lines of a magnitude at every multiple of the step below the clip,
/// each labelled once (see [`label_spot`]).
fn draw_contours<DB: DrawingBackend, T>(
    chart: &mut PixelChart<'_, DB>,
    grid: &Grid<T>,
    values: &[f64],
    s: &DistortionScale,
) -> Drawn {
    let levels = (1..)
        .map(|k| k as f64 * s.step_px)
        .take_while(|l| *l < s.clip_px);
    let bounds = (grid.nx as f64 * grid.dx, grid.ny as f64 * grid.dy);
    let mut placed: Vec<(f64, f64)> = Vec::new();
    for level in levels {
        let px: Vec<[(f64, f64); 2]> = contour_segments(values, grid.nx, grid.ny, level)
            .iter()
            .map(|s| [grid.pixel(s[0]), grid.pixel(s[1])])
            .collect();
        chart
            .draw_series(
                px.iter()
                    .map(|s| PathElement::new(s.to_vec(), BLACK.mix(0.7).stroke_width(1))),
            )
            .map_err(pe)?;
        let mids: Vec<(f64, f64)> = px
            .iter()
            .map(|s| ((s[0].0 + s[1].0) / 2.0, (s[0].1 + s[1].1) / 2.0))
            .collect();
        if let Some(p) = label_spot(&mids, &placed, bounds) {
            placed.push(p);
            // Viridis is dark below about half its range and light above.
            let ink = if level / s.clip_px > 0.55 {
                BLACK
            } else {
                WHITE
            };
            let style = ("sans-serif", 16)
                .into_font()
                .color(&ink)
                .pos(Pos::new(HPos::Center, VPos::Center));
            chart
                .draw_series([Text::new(format!("{} px", short(level)), p, style)])
                .map_err(pe)?;
        }
    }
    Ok(())
}

/// Where to label a contour: among its points at least 8 % of the image inside the
/// border, the one farthest from the labels placed so far (the first label: the
/// one nearest the ray from the centre to the upper right), so labels spread out.
fn label_spot(
    points: &[(f64, f64)],
    placed: &[(f64, f64)],
    (w, h): (f64, f64),
) -> Option<(f64, f64)> {
    let margin = 0.08 * w.min(h);
    let inside = points
        .iter()
        .copied()
        .filter(|p| p.0 > margin && p.0 < w - margin && p.1 > margin && p.1 < h - margin);
    let score = |p: (f64, f64)| {
        if placed.is_empty() {
            let (x, y) = (p.0 - w / 2.0, p.1 - h / 2.0);
            let (along, across) = (x * 0.866 - y * 0.5, (x * 0.5 + y * 0.866).abs());
            if along > 0.0 {
                -across
            } else {
                f64::NEG_INFINITY
            }
        } else {
            placed
                .iter()
                .map(|q| (p.0 - q.0).hypot(p.1 - q.1))
                .fold(f64::INFINITY, f64::min)
        }
    };
    inside.max_by(|a, b| score(*a).total_cmp(&score(*b)))
}

/// The static correction over the board: in-plane arrows (× `scale`) at every
/// corner, the cell coloured by Δz (`static`) or the in-plane size (`full`);
/// gauge corners boxed, corners held at zero crossed.
pub fn correction_map(
    title: &str,
    target: &Target,
    method: Method,
    corrections: &[[f64; 3]],
    held: (&[usize], &[usize]),
    scale: f64,
) -> Result<String> {
    let bar = BAR;
    let size = plots::board_figure_size(target, 540, bar + 100);
    let (half_w, half_h) = plots::board_half_extent(target);
    let (gauge, frozen) = held;
    let with_z = method == Method::Static;
    let colour_value = |c: &[f64; 3]| if with_z { c[2] } else { c[0].hypot(c[1]) };
    let limit = corrections
        .iter()
        .map(|c| colour_value(c).abs())
        .fold(0.0, f64::max)
        .max(1e-12);
    let colour = move |v: f64| {
        if with_z {
            plots::diverging(v / limit)
        } else {
            plots::sequential(v / limit)
        }
    };
    plots::svg(title, size, |root| {
        let (main, legend) = root.split_horizontally(size.0 - bar);
        let mut chart = ChartBuilder::on(&main)
            .caption(title, TITLE)
            .margin(MARGIN)
            .x_label_area_size(X_AXIS)
            .y_label_area_size(Y_AXIS)
            .build_cartesian_2d(-half_w * 1e3..half_w * 1e3, half_h * 1e3..-half_h * 1e3)
            .map_err(pe)?;
        chart
            .configure_mesh()
            .label_style(LABEL)
            .axis_desc_style(AXIS_DESC)
            .disable_mesh()
            .x_label_formatter(&plots::tick)
            .y_label_formatter(&plots::tick)
            .x_desc("board x (mm), along increasing col")
            .y_desc("board y (mm), along increasing row")
            .draw()
            .map_err(pe)?;
        let s = target.spacing * 1e3 / 2.0;
        let points = target.nominal_points();
        chart
            .draw_series(points.iter().zip(corrections).map(|(p, c)| {
                let (x, y) = (p.x * 1e3, p.y * 1e3);
                // Pale cells keep the black arrows readable.
                Rectangle::new(
                    [(x - s, y - s), (x + s, y + s)],
                    pale(colour(colour_value(c))).filled(),
                )
            }))
            .map_err(pe)?;
        chart
            .draw_series(points.iter().zip(corrections).map(|(p, c)| {
                let v = (c[0] * 1e3 * scale, c[1] * 1e3 * scale);
                PathElement::new(
                    plots::arrow((p.x * 1e3, p.y * 1e3), v, 0.3),
                    BLACK.stroke_width(1),
                )
            }))
            .map_err(pe)?;
        mark_held(&mut chart, target, gauge, frozen)?;
        let caption = if with_z { "Δz (mm)" } else { "in-plane (mm)" };
        let range = if with_z {
            (-limit * 1e3, limit * 1e3)
        } else {
            (0.0, limit * 1e3)
        };
        plots::colour_bar(&legend, caption, range, |v| pale(colour(v / 1e3)))
    })
}

/// Boxes the gauge corners and crosses the corners held at zero, on a board chart in mm.
fn mark_held<DB: DrawingBackend>(
    chart: &mut PixelChart<'_, DB>,
    target: &Target,
    gauge: &[usize],
    frozen: &[usize],
) -> Drawn {
    let points = target.nominal_points();
    let mark = target.spacing * 1e3 / 2.0 * 0.45;
    chart
        .draw_series(gauge.iter().filter_map(|&i| points.get(i)).map(|p| {
            let (x, y) = (p.x * 1e3, p.y * 1e3);
            Rectangle::new(
                [(x - mark, y - mark), (x + mark, y + mark)],
                RED.stroke_width(2),
            )
        }))
        .map_err(pe)?;
    chart
        .draw_series(frozen.iter().filter_map(|&i| points.get(i)).map(|p| {
            Cross::new(
                (p.x * 1e3, p.y * 1e3),
                5,
                RGBColor(90, 90, 90).stroke_width(2),
            )
        }))
        .map_err(pe)?;
    Ok(())
}

/// A colour as it shows at 60 % opacity on white.
fn pale(c: RGBColor) -> RGBColor {
    let mix = |v: u8| (0.6 * v as f64 + 0.4 * 255.0).round() as u8;
    RGBColor(mix(c.0), mix(c.1), mix(c.2))
}

/// Every frame's bend along the sequence: a, b, c (mm/m²) above and the largest
/// out-of-plane deflection (mm) below, the worst frame marked.
pub fn bend_sequence(
    title: &str,
    frame_ids: &[i64],
    bends: &[Paraboloid],
    max_oop_m: &[f64],
    worst: usize,
) -> Result<String> {
    let xs: Vec<f64> = frame_ids.iter().map(|&f| f as f64).collect();
    let x_range = plots::padded_range(xs.iter().copied(), 0.02);
    let names = ["a (x² term)", "b (y² term)", "c (xy term)"];
    let coeffs: Vec<Vec<f64>> = vec![
        bends.iter().map(|b| b.a * 1e3).collect(),
        bends.iter().map(|b| b.b * 1e3).collect(),
        bends.iter().map(|b| b.c * 1e3).collect(),
    ];
    plots::svg(title, (FIGURE_WIDTH, 680), |root| {
        let root = root.titled(title, TITLE).map_err(pe)?;
        let (key, rest) = root.split_vertically(KEY);
        let items: Vec<(Mark, String)> = names
            .iter()
            .enumerate()
            .map(|(k, n)| (Mark::Dot(PALETTE[k]), n.to_string()))
            .collect();
        plots::key_strip(&key, KEY_X + 10, &items)?;
        let (upper, lower) = rest.split_vertically(310);
        let (lo, hi) = plots::padded_range(coeffs.iter().flatten().copied(), 0.08);
        let mut chart = sequence_chart(
            &upper,
            x_range,
            (lo, hi),
            "coefficient (mm/m²); Δz = a·x² + b·y² + c·xy",
        )?;
        for (k, ys) in coeffs.iter().enumerate() {
            let c = PALETTE[k];
            let pts: Vec<(f64, f64)> = xs.iter().copied().zip(ys.iter().copied()).collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), c.stroke_width(1)))
                .map_err(pe)?;
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 2, c.filled())))
                .map_err(pe)?;
        }
        deflection_chart(&lower, &xs, x_range, max_oop_m, worst)
    })
}

/// A chart over the frame sequence, integer frame ticks, a light grid.
fn sequence_chart<'a, DB: DrawingBackend + 'a>(
    area: &DrawingArea<DB, Shift>,
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
    y_desc: &str,
) -> std::result::Result<PixelChart<'a, DB>, String> {
    let mut chart = ChartBuilder::on(area)
        .margin(MARGIN)
        .x_label_area_size(X_AXIS)
        .y_label_area_size(Y_AXIS + 10)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(pe)?;
    chart
        .configure_mesh()
        .label_style(LABEL)
        .axis_desc_style(AXIS_DESC)
        .light_line_style(WHITE)
        .bold_line_style(BLACK.mix(0.12))
        // Frames are whole numbers: no tick between two of them.
        .x_label_formatter(&|x| {
            if (x - x.round()).abs() < 1e-9 {
                plots::short(*x)
            } else {
                String::new()
            }
        })
        .y_label_formatter(&plots::tick)
        .x_desc("frame (time step)")
        .y_desc(y_desc)
        .draw()
        .map_err(pe)?;
    Ok(chart)
}

/// The lower half of [`bend_sequence`]: max |Δz| per frame, the worst one marked.
fn deflection_chart<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    xs: &[f64],
    x_range: (f64, f64),
    max_oop_m: &[f64],
    worst: usize,
) -> Drawn {
    let mm: Vec<f64> = max_oop_m.iter().map(|m| m * 1e3).collect();
    let hi = mm.iter().copied().fold(0.0, f64::max).max(1e-6) * 1.12;
    let mut chart = sequence_chart(area, x_range, (0.0, hi), "max |Δz| over the corners (mm)")?;
    let pts: Vec<(f64, f64)> = xs.iter().copied().zip(mm.iter().copied()).collect();
    chart
        .draw_series(LineSeries::new(pts.clone(), PALETTE[0].stroke_width(1)))
        .map_err(pe)?;
    chart
        .draw_series(pts.iter().map(|&p| Circle::new(p, 2, PALETTE[0].filled())))
        .map_err(pe)?;
    if let Some(&p) = pts.get(worst) {
        // The label goes left of a point in the right third, so it stays in the figure.
        let right = p.0 > x_range.0 + 0.66 * (x_range.1 - x_range.0);
        let (h, dx) = if right {
            (HPos::Right, -10)
        } else {
            (HPos::Left, 10)
        };
        let style = ("sans-serif", 16)
            .into_font()
            .color(&PALETTE[3])
            .pos(Pos::new(h, VPos::Center));
        chart
            .draw_series([Circle::new(p, 6, PALETTE[3].stroke_width(2))])
            .map_err(pe)?;
        chart
            .draw_series([
                EmptyElement::at(p) + Text::new(format!("worst: frame {}", p.0), (dx, 0), style)
            ])
            .map_err(pe)?;
    }
    Ok(())
}
