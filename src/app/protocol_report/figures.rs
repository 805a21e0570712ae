//! The report's SVG figures: errors, intrinsics and mapping error per method,
//! the bends over the images, the most bent board.
#[allow(unused_imports)]
use super::summary::*;
use crate::app::html_report::page::Figure;
use crate::app::plots::{self, Axes, HLine, Series, PALETTE};
use crate::app::protocol::{Header, Row};
use crate::error::Result;
use crate::model::board::Method;

/// A figure of the report.
pub(super) fn figure(file: &str, alt: &str, caption: &str) -> Figure {
    Figure {
        file: file.into(),
        alt: alt.into(),
        caption: caption.into(),
    }
}

/// The row and image whose bend the Fig. 1 plot shows: `full` (else `dynamic`) of the
/// first subset that has one, its most bent image.
pub(super) fn most_bent(rows: &[Row]) -> Option<(&Row, usize)> {
    let pick = |m: Method| {
        rows.iter()
            .filter(|r| r.ok() && r.is_fixed(m) && !r.deformations.is_empty())
            .min_by_key(|r| r.subset)
    };
    let r = pick(Method::Full).or_else(|| pick(Method::Dynamic))?;
    let j = (0..r.max_out_of_plane_m.len())
        .max_by(|&a, &b| r.max_out_of_plane_m[a].total_cmp(&r.max_out_of_plane_m[b]))?;
    Some((r, j))
}

/// A series label, with the camera's name when there are several cameras.
pub(super) fn named(h: &Header, base: &str, k: usize) -> String {
    if h.cameras.len() > 1 {
        format!("{base} {}", h.cameras[k].name)
    } else {
        base.to_string()
    }
}

/// The `i`-th series colour, cycling through the palette.
pub(super) fn colour(i: usize) -> plotters::style::RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// The x axis of every strip chart.
pub(super) const METHOD_AXIS: &str = "method";

/// `rmse.svg`: train RMSE and each camera's test RMSE per method.
pub(super) fn plot_rmse(h: &Header, cats: &[String], rows: &[Row]) -> Result<String> {
    // Series names must outlive the charts.
    let test_names: Vec<String> = (0..h.cameras.len()).map(|k| named(h, "test", k)).collect();
    let mut rmse = vec![Series {
        name: "train",
        color: colour(0),
        groups: groups(h, rows, |r| opt(r.rmse_px)),
    }];
    for (k, name) in test_names.iter().enumerate() {
        rmse.push(Series {
            name,
            color: colour(k + 1),
            groups: camera_groups(h, rows, k, |c| c.test_rmse_px),
        });
    }
    plots::strip_chart_svg(
        &format!("{}: train and test RMSE", h.dataset),
        Axes {
            x: METHOD_AXIS,
            y: "RMSE (px) = √(Σ‖u − p‖² / N)",
        },
        cats,
        &rmse,
        &[],
    )
}

/// The reference and truth lines of one intrinsic parameter of camera k.
pub(super) fn intrinsic_lines<'a>(h: &Header, k: usize, name: &str) -> Vec<HLine<'a>> {
    let mut lines = Vec::new();
    if let Some(v) = h
        .reference
        .as_ref()
        .and_then(|r| r.intrinsics.get(k))
        .and_then(|i| i.get(name))
    {
        lines.push(HLine {
            value: v,
            name: "reference",
            color: BLACK_RGB,
        });
    }
    if let Some(v) = h
        .truth
        .as_ref()
        .and_then(|t| t.get(k))
        .and_then(|i| i.get(name))
    {
        lines.push(HLine {
            value: v,
            name: "truth",
            color: PALETTE[3],
        });
    }
    lines
}

/// `intrinsics.svg`: every intrinsic parameter of every camera, one panel each,
/// with the reference and the truth.
pub(super) fn plot_intrinsics(h: &Header, cats: &[String], rows: &[Row]) -> Result<String> {
    let mut keys: Vec<(usize, &'static str, String, String)> = Vec::new();
    for (k, cam) in h.cameras.iter().enumerate() {
        for name in cam.model.param_names() {
            let title = named(h, name, k);
            let axis = format!("{name} ({})", param_unit(cam.model, name));
            keys.push((k, name, title, axis));
        }
    }
    let panels: Vec<plots::Panel> = keys
        .iter()
        .map(|(k, name, title, axis)| {
            let series = vec![Series {
                name: "one subset (bars: mean ± std)",
                color: colour(0),
                groups: camera_groups(h, rows, *k, |c| c.intrinsics.get(name)),
            }];
            (
                title.clone(),
                Axes {
                    x: METHOD_AXIS,
                    y: axis,
                },
                series,
                intrinsic_lines(h, *k, name),
            )
        })
        .collect();
    plots::panels_svg("intrinsics.svg", &panels, cats, 3)
}

/// `mapping.svg`: each camera's mapping error to the reference and to the truth.
pub(super) fn plot_mapping(h: &Header, cats: &[String], rows: &[Row]) -> Result<String> {
    let mut names = Vec::new();
    for k in 0..h.cameras.len() {
        if h.reference.is_some() {
            names.push((
                named(h, "to reference", k),
                k,
                (|c| c.mapping_error_px) as CameraGetter,
            ));
        }
        if h.truth.is_some() {
            names.push((named(h, "to truth", k), k, |c| c.truth_mapping_error_px));
            names.push((named(h, "to truth, rotation removed", k), k, |c| {
                c.truth_mapping_error_rot_px
            }));
        }
    }
    let mapping: Vec<Series> = names
        .iter()
        .enumerate()
        .map(|(i, (name, k, get))| Series {
            name,
            color: colour(i),
            groups: camera_groups(h, rows, *k, *get),
        })
        .collect();
    plots::strip_chart_svg(
        &format!("{}: mapping error", h.dataset),
        Axes {
            x: METHOD_AXIS,
            y: "mapping error (px): RMS over a 20 px grid",
        },
        cats,
        &mapping,
        &[],
    )
}

/// `bend.svg`: every image's largest bend per method that estimates one.
pub(super) fn plot_bend(h: &Header, rows: &[Row]) -> Result<Option<String>> {
    let methods: Vec<Method> = h
        .methods
        .iter()
        .copied()
        .filter(|m| m.has_paraboloid())
        .collect();
    if methods.is_empty() {
        return Ok(None);
    }
    let cats: Vec<String> = methods.iter().map(|m| m.name().to_string()).collect();
    let groups: Vec<Vec<f64>> = methods
        .iter()
        .map(|&m| {
            rows.iter()
                .filter(|r| r.is_fixed(m) && r.ok())
                .flat_map(|r| r.max_out_of_plane_m.iter().map(|v| v * 1e3))
                .collect()
        })
        .collect();
    let series = [Series {
        name: "one image of a subset (bars: mean ± std)",
        color: colour(0),
        groups,
    }];
    plots::strip_chart_svg(
        &format!("{}: largest bend per image", h.dataset),
        Axes {
            x: METHOD_AXIS,
            y: "max |Δz| over the corners (mm)",
        },
        &cats,
        &series,
        &[],
    )
    .map(Some)
}

pub(super) const BLACK_RGB: plotters::style::RGBColor = plotters::style::RGBColor(0, 0, 0);
