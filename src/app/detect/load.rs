//! Image loading and conversion, with a size bound.
//!
//! Everything a caller may throw at us (truncated files, non-images, huge
//! headers) must come back as a `Rejection`, never a panic or an allocation
//! of gigabytes. So we read the header first, refuse anything over the pixel
//! budget before decoding, and also cap the decoder's allocation in case the
//! header lies.

use crate::app::detect::refine::FloatImage;
use crate::app::detect::types::Rejection;
use image::{DynamicImage, GrayImage, ImageReader, Limits};
use std::io::Cursor;
use std::path::Path;

/// Bytes per pixel the decoder may allocate: 16-bit RGBA plus slack.
const ALLOC_PER_PIXEL: u64 = 16;

/// Largest image file read: the whole file is held in memory while decoding, and
/// no photo comes near this.
pub const MAX_FILE_BYTES: u64 = 1 << 30;

/// Decode `path`, refusing images over `max_pixels`.
pub fn load(path: &Path, max_pixels: u64) -> Result<DynamicImage, Rejection> {
    let bytes = read_file(path)?;
    load_bytes(&bytes, max_pixels)
}

/// The bytes of an image file, refusing files over [`MAX_FILE_BYTES`].
pub fn read_file(path: &Path) -> Result<Vec<u8>, Rejection> {
    let unreadable = |e: &dyn std::fmt::Display| Rejection::Unreadable(e.to_string());
    let size = std::fs::metadata(path).map_err(|e| unreadable(&e))?.len();
    if size > MAX_FILE_BYTES {
        return Err(unreadable(&format!(
            "file of {size} bytes exceeds {MAX_FILE_BYTES}"
        )));
    }
    std::fs::read(path).map_err(|e| unreadable(&e))
}

/// Decode an image file's bytes, refusing images over `max_pixels`. The format
/// comes from the content, not the file name. Messages do not repeat the file
/// name: the caller knows it.
pub fn load_bytes(bytes: &[u8], max_pixels: u64) -> Result<DynamicImage, Rejection> {
    let unreadable = |e: &dyn std::fmt::Display| Rejection::Unreadable(e.to_string());
    let open = || -> Result<ImageReader<_>, Rejection> {
        ImageReader::new(Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| unreadable(&e))
    };
    let (w, h) = open()?.into_dimensions().map_err(|e| unreadable(&e))?;
    check_size(w, h, max_pixels)?;
    let mut reader = open()?;
    let mut limits = Limits::default();
    limits.max_image_width = Some(w);
    limits.max_image_height = Some(h);
    limits.max_alloc = Some((w as u64 * h as u64 * ALLOC_PER_PIXEL).max(1 << 20));
    reader.limits(limits);
    reader.decode().map_err(|e| unreadable(&e))
}

/// Refuse empty images and images over the pixel budget.
pub fn check_size(width: u32, height: u32, max_pixels: u64) -> Result<(), Rejection> {
    if width == 0 || height == 0 {
        return Err(Rejection::Unreadable(format!(
            "empty image {width}x{height}"
        )));
    }
    if width as u64 * height as u64 > max_pixels {
        return Err(Rejection::TooLarge {
            width,
            height,
            max_pixels,
        });
    }
    Ok(())
}

/// Grey f32 image on a 0..255 scale at the source's full precision.
pub fn to_float(img: &DynamicImage) -> FloatImage {
    let g = img.to_luma32f();
    FloatImage {
        width: g.width() as usize,
        height: g.height() as usize,
        data: g.into_raw().into_iter().map(|v| v * 255.0).collect(),
    }
}

/// [`to_float`] and [`to_gray8`] of `img` at once. An 8-bit grey image (rendered
/// boards, grey JPEGs, video frames) has only 256 levels, so both conversions
/// become table lookups built by the general functions themselves: the same
/// images, bit for bit, at a fraction of the cost (callgrind: the stretch was a
/// third of a rendered board's detection).
pub fn grey_images(img: &DynamicImage) -> (FloatImage, GrayImage) {
    let DynamicImage::ImageLuma8(g) = img else {
        let f = to_float(img);
        let gray = to_gray8(&f);
        return (f, gray);
    };
    let ramp = GrayImage::from_fn(256, 1, |x, _| image::Luma([x as u8]));
    let ramp = to_float(&DynamicImage::ImageLuma8(ramp)).data;
    // Arrays indexed by a u8: no bounds checks in the per-pixel loops.
    let level: [f32; 256] = std::array::from_fn(|k| ramp[k]);
    let mut counts = [0usize; 256];
    for &k in g.as_raw() {
        counts[k as usize] += 1;
    }
    let mut hist = [0usize; BINS];
    for (v, n) in level.iter().zip(counts) {
        hist[bin(*v)] += n;
    }
    let (lo, scale) = stretch(&hist, g.as_raw().len());
    let grey: [u8; 256] = std::array::from_fn(|k| stretched(level[k], lo, scale));
    let f = FloatImage {
        width: g.width() as usize,
        height: g.height() as usize,
        data: g.as_raw().iter().map(|&k| level[k as usize]).collect(),
    };
    let gray = GrayImage::from_raw(
        g.width(),
        g.height(),
        g.as_raw().iter().map(|&k| grey[k as usize]).collect(),
    )
    .expect("buffer has width*height bytes");
    (f, gray)
}

/// Bins of the grey-level histogram the stretch reads its percentiles from.
const BINS: usize = 1024;

/// The histogram bin of grey level `v` (0..255).
fn bin(v: f32) -> usize {
    ((v * ((BINS - 1) as f32 / 255.0)).clamp(0.0, (BINS - 1) as f32)) as usize
}

/// The stretch's low end and scale from the histogram of `n` pixels: the 0.5
/// and 99.5 percentiles go to 0 and 255.
fn stretch(hist: &[usize; BINS], n: usize) -> (f32, f32) {
    let pct = |q: f64| {
        let target = (q * n as f64) as usize;
        let mut acc = 0;
        hist.iter()
            .position(|&c| {
                acc += c;
                acc > target
            })
            .unwrap_or(BINS - 1) as f32
            * 255.0
            / (BINS - 1) as f32
    };
    let (lo, hi) = (pct(0.005), pct(0.995));
    let scale = if hi - lo > 1.0 {
        255.0 / (hi - lo)
    } else {
        1.0
    };
    (lo, scale)
}

/// Grey level `v` stretched; +0.5 and truncation rounds as `round` does on
/// [0, 255] without a libm call per pixel.
fn stretched(v: f32, lo: f32, scale: f32) -> u8 {
    ((v - lo) * scale + 0.5).clamp(0.0, 255.0) as u8
}

/// 8-bit grey for the ChESS detector, contrast-stretched between the 0.5 and
/// 99.5 percentiles so dim 16-bit data (e.g. 12-bit sensors) and low-contrast
/// photos still reach the detector's response threshold.
pub fn to_gray8(f: &FloatImage) -> GrayImage {
    let mut hist = [0usize; BINS];
    for &v in &f.data {
        hist[bin(v)] += 1;
    }
    let (lo, scale) = stretch(&hist, f.data.len());
    let data = f.data.iter().map(|&v| stretched(v, lo, scale)).collect();
    GrayImage::from_raw(f.width as u32, f.height as u32, data)
        .expect("buffer has width*height bytes")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grey_images_of_8_bit_grey_are_the_general_conversions() {
        // Every level, a dim patch (so the stretch does something) and noise.
        let img = GrayImage::from_fn(97, 61, |x, y| {
            let k = (x * 61 + y) as u64;
            let noisy = (k.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 56) as u8;
            image::Luma([if y < 20 {
                (k % 256) as u8
            } else {
                40 + noisy / 8
            }])
        });
        let img = DynamicImage::ImageLuma8(img);
        let (f, g) = grey_images(&img);
        let f0 = to_float(&img);
        assert_eq!((f.width, f.height), (f0.width, f0.height));
        assert!(f
            .data
            .iter()
            .zip(&f0.data)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        assert_eq!(g, to_gray8(&f0));
        assert_ne!(
            g.as_raw(),
            img.to_luma8().as_raw(),
            "the stretch changed levels"
        );
    }
}
