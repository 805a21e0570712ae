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

/// 8-bit grey for the ChESS detector, contrast-stretched between the 0.5 and
/// 99.5 percentiles so dim 16-bit data (e.g. 12-bit sensors) and low-contrast
/// photos still reach the detector's response threshold.
pub fn to_gray8(f: &FloatImage) -> GrayImage {
    let mut hist = [0usize; 1024];
    for &v in &f.data {
        hist[((v / 255.0 * 1023.0).clamp(0.0, 1023.0)) as usize] += 1;
    }
    let n = f.data.len();
    let pct = |q: f64| {
        let target = (q * n as f64) as usize;
        let mut acc = 0;
        hist.iter()
            .position(|&c| {
                acc += c;
                acc > target
            })
            .unwrap_or(1023) as f32
            * 255.0
            / 1023.0
    };
    let (lo, hi) = (pct(0.005), pct(0.995));
    let scale = if hi - lo > 1.0 {
        255.0 / (hi - lo)
    } else {
        1.0
    };
    let data = f
        .data
        .iter()
        .map(|&v| ((v - lo) * scale).round().clamp(0.0, 255.0) as u8)
        .collect();
    GrayImage::from_raw(f.width as u32, f.height as u32, data)
        .expect("buffer has width*height bytes")
}
