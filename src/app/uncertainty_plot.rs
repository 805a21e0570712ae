//! The projection-uncertainty map of each camera as an SVG heat map
//! (`uncertainty_<camera>.svg` beside `calibration.json`): the predicted 1-σ
//! projection error over the image (its cells one embedded PNG, `app::raster`),
//! with contour lines and a colour bar. The
//! numbers are `model::uncertainty`'s; this file only draws them.
use crate::app::exports::file_stem;
use crate::app::fsio::{write_atomic, UNCERTAINTY_MAP_PREFIX};
use crate::app::plots;
use crate::app::raster;
use crate::error::{Error, Result};
use crate::model::uncertainty::{projection_uncertainty_map, UncertaintyMap};
use crate::solver::calibrate::Calibration;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Cells across the image in the map.
pub const MAP_COLUMNS: usize = 64;

/// The map's file name for a camera.
pub fn file_name(camera: &str) -> String {
    format!("{UNCERTAINTY_MAP_PREFIX}{}.svg", file_stem(camera))
}

/// Writes every camera's map into `dir`; nothing when the calibration has no
/// uncertainty (its summary and `calibration.json` say why).
pub fn write_maps(dir: &Path, c: &Calibration) -> Result<()> {
    for (path, svg) in render_maps(dir, c)?.into_iter().flatten() {
        write_atomic(&path, svg.as_bytes())?;
    }
    Ok(())
}

/// Every camera's map as SVG with the path it goes to in `dir` (`None` for every
/// camera when the calibration has no uncertainty), without writing it: the
/// report embeds the same text.
pub fn render_maps(dir: &Path, c: &Calibration) -> Result<Vec<Option<(PathBuf, String)>>> {
    let trust = c.assessment.trust.as_ref();
    let Ok(covariance) = c.intrinsics_covariance_at(trust) else {
        return Ok(vec![None; c.dataset.cameras.len()]);
    };
    let noise = trust.map_or(f64::NAN, |t| t.noise_px);
    let cameras = c.dataset.cameras.iter().zip(&c.state.intrinsics);
    let mut out: Vec<Option<(PathBuf, String)>> = cameras
        .zip(&covariance)
        .map(|((cam, k), sigma)| {
            let map = projection_uncertainty_map(k, sigma, cam.width, cam.height, MAP_COLUMNS);
            let title = format!(
                "{}: predicted 1-σ projection error, worst direction (px); noise {noise:.3} px",
                cam.name
            );
            let path = dir.join(file_name(&cam.name));
            let mut svg = String::new();
            draw(&mut svg, &title, &map)
                .map_err(|e| Error::Invalid(format!("{}: plotting failed: {e}", path.display())))?;
            Ok(Some((path, svg)))
        })
        .collect::<Result<_>>()?;
    out.resize(c.dataset.cameras.len(), None);
    Ok(out)
}

/// Contour levels at a round step (1, 2, 2.5 or 5 × 10ⁿ), about eight from below
/// `lo` to above `hi`: the colours then span the map's own range, which for a
/// well-calibrated camera is narrow and far from zero.
pub fn levels(lo: f64, hi: f64) -> Vec<f64> {
    if !(hi > 0.0 && hi.is_finite() && lo.is_finite()) {
        return vec![0.0, 1.0];
    }
    // A nearly flat map is shown from zero, where its level is the news.
    let lo = if hi - lo < 0.05 * hi {
        0.0
    } else {
        lo.max(0.0)
    };
    let raw = (hi - lo) / 8.0;
    let magnitude = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * magnitude)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * magnitude);
    let first = (lo / step).floor() as i64;
    let last = ((hi / step).ceil() as i64).max(first + 1);
    (first..=last).map(|i| i as f64 * step).collect()
}

/// Contour segments of `level` over the map's cell centres, in pixels.
fn contour(map: &UncertaintyMap, level: f64) -> Vec<[(f64, f64); 2]> {
    let (sx, sy) = (
        map.width as f64 / map.columns as f64,
        map.height as f64 / map.rows as f64,
    );
    let pixel = |(c, r): (f64, f64)| ((c + 0.5) * sx - 0.5, (r + 0.5) * sy - 0.5);
    plots::contour_segments(&map.sigma_px, map.columns, map.rows, level)
        .into_iter()
        .map(|[a, b]| [pixel(a), pixel(b)])
        .collect()
}

fn err<E: std::fmt::Debug>(e: E) -> String {
    format!("{e:?}")
}

/// Draws the heat map, its contours and the colour bar into `svg`.
fn draw(svg: &mut String, title: &str, map: &UncertaintyMap) -> std::result::Result<(), String> {
    let levels = levels(map.min(), map.max());
    draw_vector(svg, title, map, &levels)?;
    let (bottom, top) = (levels[0], *levels.last().unwrap_or(&1.0));
    let colours = map
        .sigma_px
        .iter()
        .map(|v| {
            if v.is_finite() {
                crate::app::plots::sequential((v - bottom) / (top - bottom))
            } else {
                RGBColor(220, 220, 220)
            }
        })
        .collect();
    let cells = raster::Cells {
        columns: map.columns,
        rows: map.rows,
        colours,
    };
    raster::embed(svg, &cells)
}

/// [`draw`] but the cells, which are left as [`raster::placeholder`].
fn draw_vector(
    svg: &mut String,
    title: &str,
    map: &UncertaintyMap,
    levels: &[f64],
) -> std::result::Result<(), String> {
    let (w, h) = (map.width as f64, map.height as f64);
    let plot_w = 760u32;
    let plot_h = ((plot_w - 90) as f64 * h / w.max(1.0) + 90.0).clamp(240.0, 1200.0) as u32;
    let root = SVGBackend::with_string(svg, (plot_w + 130, plot_h)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (plot, legend) = root.split_horizontally(plot_w);
    let mut chart = ChartBuilder::on(&plot)
        .caption(title, ("sans-serif", 15))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(-0.5..w - 0.5, h - 0.5..-0.5)
        .map_err(err)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("u (px)")
        .y_desc("v (px)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| format!("{y:.0}"))
        .draw()
        .map_err(err)?;
    raster::placeholder(&mut chart, (-0.5, -0.5), (w - 0.5, h - 0.5))?;
    for &level in &levels[1..levels.len().saturating_sub(1).max(1)] {
        chart
            .draw_series(
                contour(map, level)
                    .into_iter()
                    .map(|s| PathElement::new(s.to_vec(), BLACK.mix(0.55).stroke_width(1))),
            )
            .map_err(err)?;
    }
    draw_bar(&legend, levels).map_err(err)?;
    root.present().map_err(err)
}

/// The colour bar, in pixels, with a line at each contour level.
fn draw_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    levels: &[f64],
) -> std::result::Result<(), String> {
    let (bottom, top) = (levels[0], *levels.last().unwrap_or(&1.0));
    let mut bar = ChartBuilder::on(area)
        .margin_top(40)
        .margin_bottom(50)
        .margin_right(10)
        .y_label_area_size(60)
        .caption("1-σ (px)", ("sans-serif", 14))
        .build_cartesian_2d(0.0..1.0, bottom..top)
        .map_err(err)?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_labels(levels.len())
        .y_label_style(("sans-serif", 12))
        .draw()
        .map_err(err)?;
    let steps = 64;
    let span = top - bottom;
    bar.draw_series((0..steps).map(|k| {
        let (a, b) = (k as f64 / steps as f64, (k + 1) as f64 / steps as f64);
        let (ya, yb) = (bottom + span * a, bottom + span * b);
        Rectangle::new(
            [(0.0, ya), (1.0, yb)],
            crate::app::plots::sequential((a + b) / 2.0).filled(),
        )
    }))
    .map_err(err)?;
    bar.draw_series(
        levels
            .iter()
            .map(|&l| PathElement::new(vec![(0.0, l), (1.0, l)], BLACK.mix(0.55).stroke_width(1))),
    )
    .map_err(err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_are_round_and_cover_the_range() {
        let l = levels(0.0, 0.73);
        assert_eq!(l.len(), 9);
        for (i, v) in l.iter().enumerate() {
            assert!((v - 0.1 * i as f64).abs() < 1e-12, "{l:?}");
        }
        // A map from 0.22 to 0.36 px gets steps of 0.02 from 0.22.
        let l = levels(0.22, 0.36);
        assert!(
            (l[1] - l[0] - 0.02).abs() < 1e-12 && (l[0] - 0.22).abs() < 1e-12,
            "{l:?}"
        );
        assert!(*l.last().unwrap() >= 0.36 && l.len() <= 10);
        // A flat map starts at zero.
        assert_eq!(levels(0.3, 0.301)[0], 0.0);
    }

    #[test]
    fn contour_of_a_ramp_is_a_straight_line_at_the_level() {
        // σ = u/100: the 3 px contour is the column u = 300.
        let mut map = UncertaintyMap {
            width: 640,
            height: 480,
            columns: 16,
            rows: 12,
            sigma_px: Vec::new(),
        };
        for r in 0..12 {
            for c in 0..16 {
                let v = map.centre(c, r).x / 100.0;
                map.sigma_px.push(v);
            }
        }
        let segments = contour(&map, 3.0);
        assert_eq!(segments.len(), 11);
        for s in segments {
            for p in s {
                assert!((p.0 - 300.0).abs() < 1e-9, "{p:?}");
            }
        }
    }
}
