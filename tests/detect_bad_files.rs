//! Bad input must give a `Rejection`, never a panic.
use deformcal::app::detect::{detect_file, detect_image, Detector, Rejection};
use image::DynamicImage;
use std::path::PathBuf;

fn tmp(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("deformcal-detect-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn png_bytes(w: u32, h: u32) -> Vec<u8> {
    let mut out = Vec::new();
    let img = DynamicImage::ImageLuma8(image::GrayImage::from_pixel(w, h, image::Luma([128])));
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .unwrap();
    out
}

fn crc32(data: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in data {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// A PNG whose header claims w×h but has no pixel data.
fn png_header_only(w: u32, h: u32) -> Vec<u8> {
    let mut v = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut chunk = b"IHDR".to_vec();
    chunk.extend_from_slice(&w.to_be_bytes());
    chunk.extend_from_slice(&h.to_be_bytes());
    chunk.extend_from_slice(&[8, 0, 0, 0, 0]);
    v.extend_from_slice(&13u32.to_be_bytes());
    v.extend_from_slice(&chunk);
    v.extend_from_slice(&crc32(&chunk).to_be_bytes());
    // An empty IDAT so header parsers reach the data, then IEND.
    for tag in [b"IDAT", b"IEND"] {
        v.extend_from_slice(&0u32.to_be_bytes());
        v.extend_from_slice(tag);
        v.extend_from_slice(&crc32(tag).to_be_bytes());
    }
    v
}

#[test]
fn unreadable_files_are_errors() {
    let good = png_bytes(64, 48);
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("empty.png", vec![]),
        ("text.jpg", b"this is not an image".to_vec()),
        (
            "garbage.tif",
            (0..5000u32)
                .map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8)
                .collect(),
        ),
        ("truncated.png", good[..good.len() / 2].to_vec()),
        ("header_only.png", png_header_only(640, 480)),
        (
            "truncated.jpg",
            b"\xff\xd8\xff\xe0\x00\x10JFIF\x00".to_vec(),
        ),
    ];
    for (name, bytes) in cases {
        let r = detect_file(&tmp(name, &bytes), 6, 9);
        assert!(matches!(r, Err(Rejection::Unreadable(_))), "{name}: {r:?}");
    }
    let r = detect_file(std::path::Path::new("/nonexistent/file.png"), 6, 9);
    assert!(matches!(r, Err(Rejection::Unreadable(_))), "{r:?}");
}

#[test]
fn huge_images_are_refused_before_decoding() {
    let r = detect_file(&tmp("huge.png", &png_header_only(20_000, 20_000)), 6, 9);
    assert!(
        matches!(
            r,
            Err(Rejection::TooLarge {
                width: 20_000,
                height: 20_000,
                ..
            })
        ),
        "{r:?}"
    );
    let small_budget = Detector {
        max_pixels: 1000,
        ..Detector::default()
    };
    let img = DynamicImage::ImageLuma8(image::GrayImage::new(100, 100));
    assert!(matches!(
        small_budget.detect_image(&img, 6, 9),
        Err(Rejection::TooLarge { .. })
    ));
}

#[test]
fn tiny_and_flat_images_are_errors() {
    for (w, h) in [(1, 1), (2, 7), (7, 2), (8, 8), (40, 30)] {
        let img = DynamicImage::ImageLuma8(image::GrayImage::new(w, h));
        assert!(detect_image(&img, 6, 9).is_err(), "{w}x{h}");
    }
    let r = detect_file(&tmp("one.png", &png_bytes(1, 1)), 6, 9);
    assert!(r.is_err());
}

#[test]
fn invalid_pattern_is_an_error() {
    let img = DynamicImage::ImageLuma8(image::GrayImage::new(64, 64));
    assert_eq!(
        detect_image(&img, 1, 9),
        Err(Rejection::InvalidPattern { rows: 1, cols: 9 })
    );
    assert_eq!(
        detect_image(&img, 0, 0),
        Err(Rejection::InvalidPattern { rows: 0, cols: 0 })
    );
}
