//! What plotters would draw as thousands of SVG elements, drawn as one: a heat
//! map as one embedded PNG instead of one rectangle per cell (a 64 × 40 map was
//! 2 560 elements and a quarter of a megabyte), many arrows as one `<path>`.
//! These were the most expensive part of writing a calibration's results. The
//! chart draws a placeholder rectangle where the element goes (so plotters places
//! it, and what is drawn after it stays on top); [`splice`] swaps it for the
//! element. A heat map's image is shown unsmoothed, so every cell keeps its one
//! colour as before.
use crate::app::html_report::page::base64;
use crate::app::plots::{pe, Drawn};
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

/// The placeholder's fill: no figure draws this colour (`#010203`).
const MARK: RGBColor = RGBColor(1, 2, 3);

/// A grid of cells, row by row from the top, one colour each.
#[derive(Debug, Clone, PartialEq)]
pub struct Cells {
    pub columns: usize,
    pub rows: usize,
    pub colours: Vec<RGBColor>,
}

/// Draws the placeholder of the cells over `[x0, x1] × [y0, y1]` in chart
/// coordinates.
pub fn placeholder<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    (x0, y0): (f64, f64),
    (x1, y1): (f64, f64),
) -> Drawn {
    chart
        .draw_series([Rectangle::new([(x0, y0), (x1, y1)], MARK.filled())])
        .map_err(pe)?;
    Ok(())
}

/// The cells as a PNG file.
fn png(cells: &Cells) -> Result<Vec<u8>, String> {
    let (w, h) = (cells.columns, cells.rows);
    if w == 0 || h == 0 || cells.colours.len() != w * h {
        return Err(format!(
            "a {w} × {h} heat map with {} cells",
            cells.colours.len()
        ));
    }
    let rgb: Vec<u8> = cells.colours.iter().flat_map(|c| [c.0, c.1, c.2]).collect();
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Sub)
        .write_image(&rgb, w as u32, h as u32, ExtendedColorType::Rgb8)
        .map_err(pe)?;
    Ok(out)
}

/// The value of attribute `name` in one SVG tag.
fn attribute<'a>(tag: &'a str, name: &str) -> Option<&'a str> {
    let key = format!(" {name}=\"");
    let start = tag.find(&key)? + key.len();
    let len = tag[start..].find('"')?;
    Some(&tag[start..start + len])
}

/// Replaces the placeholder [`placeholder`] drew in `svg` with the element `make`
/// returns for the placeholder's tag.
pub fn splice(
    svg: &mut String,
    make: impl FnOnce(&str) -> Result<String, String>,
) -> Result<(), String> {
    let mark = format!("fill=\"#{:02X}{:02X}{:02X}\"", MARK.0, MARK.1, MARK.2);
    let missing = || "a placeholder is missing from the SVG".to_string();
    let at = svg.find(&mark).ok_or_else(missing)?;
    let start = svg[..at].rfind("<rect").ok_or_else(missing)?;
    let end = at + svg[at..].find("/>").ok_or_else(missing)? + 2;
    let element = make(&svg[start..end])?;
    svg.replace_range(start..end, &element);
    Ok(())
}

/// Replaces the placeholder [`placeholder`] drew in `svg` with the cells as an
/// embedded PNG at the same place and size.
pub fn embed(svg: &mut String, cells: &Cells) -> Result<(), String> {
    let png = png(cells)?;
    splice(svg, |tag| {
        let [x, y, w, h] = ["x", "y", "width", "height"].map(|a| attribute(tag, a).unwrap_or("0"));
        Ok(format!(
            "<image x=\"{x}\" y=\"{y}\" width=\"{w}\" height=\"{h}\" preserveAspectRatio=\"none\" \
             image-rendering=\"optimizeSpeed\" style=\"image-rendering:pixelated\" \
             href=\"data:image/png;base64,{}\"/>",
            base64(&png)
        ))
    })
}

/// One `<path>` of polylines given in pixels (each drawn as plotters draws a
/// `PathElement`, in one element), stroked in `colour` at `opacity` and `width`.
pub fn polylines_path(
    lines: impl IntoIterator<Item = Vec<(i32, i32)>>,
    colour: RGBColor,
    opacity: f64,
    width: u32,
) -> String {
    use std::fmt::Write;
    let mut d = String::new();
    for line in lines {
        for (k, (x, y)) in line.into_iter().enumerate() {
            let _ = write!(d, "{}{x} {y}", if k == 0 { "M" } else { "L" });
        }
    }
    format!(
        "<path fill=\"none\" opacity=\"{opacity}\" stroke=\"#{:02X}{:02X}{:02X}\" stroke-width=\"{width}\" d=\"{d}\"/>",
        colour.0, colour.1, colour.2
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_png_holds_the_cells_in_order() {
        let colours = vec![
            RGBColor(255, 0, 0),
            RGBColor(0, 255, 0),
            RGBColor(0, 0, 255),
            RGBColor(10, 20, 30),
            RGBColor(200, 200, 200),
            RGBColor(0, 0, 0),
        ];
        let cells = Cells {
            columns: 3,
            rows: 2,
            colours: colours.clone(),
        };
        // Decoded by the image crate's PNG decoder, an independent reader.
        let decoded = image::load_from_memory(&png(&cells).unwrap())
            .unwrap()
            .to_rgb8();
        assert_eq!(decoded.dimensions(), (3, 2));
        for (i, c) in colours.iter().enumerate() {
            let p = decoded.get_pixel((i % 3) as u32, (i / 3) as u32);
            assert_eq!(p.0, [c.0, c.1, c.2], "cell {i}");
        }
        assert!(png(&Cells {
            columns: 2,
            rows: 2,
            colours
        })
        .is_err());
    }

    #[test]
    fn the_placeholder_becomes_an_image_at_its_place() {
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, (200, 100)).into_drawing_area();
            let mut chart = ChartBuilder::on(&root)
                .build_cartesian_2d(0.0..10.0, 0.0..5.0)
                .unwrap();
            placeholder(&mut chart, (0.0, 0.0), (10.0, 5.0)).unwrap();
            chart
                .draw_series([PathElement::new(vec![(0.0, 0.0), (10.0, 5.0)], BLACK)])
                .unwrap();
            root.present().unwrap();
        }
        let cells = Cells {
            columns: 1,
            rows: 1,
            colours: vec![RGBColor(9, 9, 9)],
        };
        embed(&mut svg, &cells).unwrap();
        assert!(!svg.contains("#010203"), "{svg}");
        // The chart spans the whole 200 × 100 drawing (plotters' last pixel is 199 × 99).
        let image = svg.find("<image ").expect("an image");
        let tag = &svg[image..image + svg[image..].find("/>").unwrap()];
        for (name, lo, hi) in [
            ("x", 0, 0),
            ("y", 0, 0),
            ("width", 199, 200),
            ("height", 99, 100),
        ] {
            let v: i32 = attribute(tag, name).unwrap().parse().unwrap();
            assert!((lo..=hi).contains(&v), "{name} = {v} in {tag}");
        }
        // What was drawn after the cells stays on top of them.
        assert!(svg.find("<polyline").unwrap() > image, "{svg}");
        assert!(embed(&mut svg, &cells).is_err());
        let path = polylines_path(
            [vec![(1, 2), (3, 4)], vec![(5, 6), (7, 8), (9, 10)]],
            BLACK,
            0.8,
            1,
        );
        assert!(path.contains("d=\"M1 2L3 4M5 6L7 8L9 10\""), "{path}");
    }
}
