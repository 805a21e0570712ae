//! `deformcal target`: the SVG is at true size for its paper, rasterised (with
//! librsvg's `rsvg-convert`) it is found by our detector and by OpenCV with
//! every corner where the spec puts it, the scale bar is 100 mm, and a board
//! that does not fit is refused with the largest square that would. The last test
//! is the control: the detector alone, on an exactly area-sampled board.
use crate::common;

use deformcal::app::detect::charuco::CharucoSpec;
use deformcal::app::detect::Detector;
use deformcal::app::target_print::{self, Args, BoardType, Paper};
use std::path::Path;
use std::process::Command;

fn args(kind: BoardType, rows: usize, cols: usize, square: f64, out: &Path) -> Args {
    Args {
        kind,
        rows,
        cols,
        square,
        marker: None,
        dictionary: None,
        paper: Paper::A4,
        out: out.to_path_buf(),
    }
}

fn charuco_args(out: &Path) -> Args {
    Args {
        marker: Some(0.022),
        dictionary: Some("DICT_5X5_100".into()),
        ..args(BoardType::Charuco, 7, 5, 0.03, out)
    }
}

/// `rsvg-convert` at `dpi`, or None (with the reason) when librsvg is missing.
///
/// Rendered at 4 × `dpi` and box-averaged down: cairo anti-aliases each shape
/// on its own, so where a white square is drawn after (and abutting) a black
/// one on the white page, the shared edge pixel is painted twice and comes out
/// 2c − c² instead of c bright (c the white coverage). That moves the edge by
/// c − c², up to 0.25 px, into the black square (measured on the 150 dpi
/// chessboard: edges up to 0.25 px off, within 0.005 px once the white squares
/// are left out), which put the corners ~0.19 px off. At 4 × the shift is a
/// quarter of that in final pixels (≤ 0.06 px measured); the box average is
/// the area sampling whose pixel centres are at integer coordinates. A lens's
/// blur (σ = 1 px) then spares the refinement its pixel locking on one-pixel
/// edges (see the last test): corners then land within 0.08 px of the spec.
fn rasterise(svg: &Path, dpi: f64) -> Option<image::DynamicImage> {
    const K: u32 = 4;
    let png = svg.with_extension("png");
    let fine = (K as f64 * dpi).to_string();
    let ok = Command::new("rsvg-convert")
        .args(["--dpi-x", &fine, "--dpi-y", &fine])
        .args(["--background-color", "white", "-o"])
        .arg(&png)
        .arg(svg)
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    if !ok {
        eprintln!("SKIPPED: rsvg-convert failed or is missing (apt-get install librsvg2-bin)");
        return None;
    }
    let big = image::open(&png).unwrap().to_luma8();
    let small = image::GrayImage::from_fn(big.width() / K, big.height() / K, |x, y| {
        let mut acc = 0u32;
        for j in 0..K {
            for i in 0..K {
                acc += big.get_pixel(K * x + i, K * y + j)[0] as u32;
            }
        }
        image::Luma([((acc + K * K / 2) / (K * K)) as u8])
    });
    let small = image::imageops::blur(&small, 1.0);
    small.save(&png).unwrap();
    Some(image::DynamicImage::ImageLuma8(small))
}

/// The page is the paper's size in mm, and the scale bar is 100 mm long.
#[test]
fn svg_is_true_size_with_a_10_cm_bar() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("board.svg");
    let lay = target_print::run(&charuco_args(&out)).unwrap();
    let svg = std::fs::read_to_string(&out).unwrap();
    // 7 × 5 squares of 30 mm: taller than wide, so portrait A4.
    assert_eq!(lay.page_mm, (210.0, 297.0));
    assert!(svg.contains("width=\"210mm\" height=\"297mm\" viewBox=\"0 0 210 297\""));
    assert!((lay.board_mm.0 - 150.0).abs() < 1e-9 && (lay.board_mm.1 - 210.0).abs() < 1e-9);
    let bar = svg
        .lines()
        .find(|l| l.contains("id=\"scale-bar\""))
        .expect("a scale bar");
    assert!(bar.contains("width=\"100\""), "{bar}");
    assert!(svg.contains("dictionary = &quot;DICT_5X5_100&quot;"));
    // A wide chessboard turns the page.
    let wide = target_print::run(&args(BoardType::Chessboard, 6, 9, 0.02, &out)).unwrap();
    assert_eq!(wide.page_mm, (297.0, 210.0));
}

/// Rasterised at 200 dpi, the printed ChArUco board is found by our detector and by
/// OpenCV with every corner id at the position the spec gives it on the page.
#[test]
fn printed_charuco_board_is_detected_where_the_spec_puts_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("board.svg");
    let a = charuco_args(&out);
    let lay = target_print::run(&a).unwrap();
    let dpi = 200.0;
    let Some(img) = rasterise(&out, dpi) else {
        return;
    };
    let px = dpi / 25.4;
    let spec = CharucoSpec {
        rows: 7,
        cols: 5,
        square: 0.03,
        marker: 0.022,
        dictionary: "DICT_5X5_100".into(),
    };
    let t = spec.target();
    // Corner id r·(cols−1)+c sits (c+1, r+1) squares from the board's outer corner;
    // pixel centres are at integer coordinates (the -0.5).
    let expected = |id: usize| {
        let (r, c) = (id / t.cols, id % t.cols);
        [
            (lay.board_origin_mm.0 + (c + 1) as f64 * 30.0) * px - 0.5,
            (lay.board_origin_mm.1 + (r + 1) as f64 * 30.0) * px - 0.5,
        ]
    };
    let det = Detector {
        charuco: Some(spec.clone()),
        ..Detector::default()
    }
    .detect_image(&img, t.rows, t.cols)
    .expect("the printed board is found");
    assert!(
        det.complete,
        "{} of {} corners",
        det.corners.len(),
        t.num_corners()
    );
    for c in &det.corners {
        let e = expected(c.index);
        let d = (c.uv[0] - e[0]).hypot(c.uv[1] - e[1]);
        assert!(d < 0.1, "corner {} at {:?}, expected {e:?}", c.index, c.uv);
    }
    if !common::python_has(&["cv2"]) {
        return;
    }
    let png = out.with_extension("png");
    let input = serde_json::json!({
        "rows": 7, "cols": 5, "square": 0.03, "marker": 0.022,
        "dictionary": "DICT_5X5_100", "images": [png.to_str().unwrap()],
    });
    let cv = common::run_tool("charuco_cv2.py", &[], &input.to_string());
    let found = cv["corners"][0].as_object().unwrap();
    assert_eq!(found.len(), t.num_corners(), "OpenCV finds every corner");
    for (id, uv) in found {
        let e = expected(id.parse().unwrap());
        let d = (uv[0].as_f64().unwrap() - e[0]).hypot(uv[1].as_f64().unwrap() - e[1]);
        assert!(d < 0.5, "OpenCV's corner {id} at {uv}, expected {e:?}");
    }
}

/// The printed chessboard is deformcal's: corner 0 (diagonally inside the dark
/// top-left square) where the spec puts it.
#[test]
fn printed_chessboard_is_detected_where_the_spec_puts_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("chess.svg");
    let lay = target_print::run(&args(BoardType::Chessboard, 6, 9, 0.02, &out)).unwrap();
    let dpi = 150.0;
    let Some(img) = rasterise(&out, dpi) else {
        return;
    };
    let px = dpi / 25.4;
    let det = Detector::default().detect_image(&img, 6, 9).expect("found");
    assert!(det.complete);
    for c in &det.corners {
        let (r, k) = (c.index / 9, c.index % 9);
        let e = [
            (lay.board_origin_mm.0 + (k + 1) as f64 * 20.0) * px - 0.5,
            (lay.board_origin_mm.1 + (r + 1) as f64 * 20.0) * px - 0.5,
        ];
        let d = (c.uv[0] - e[0]).hypot(c.uv[1] - e[1]);
        assert!(d < 0.1, "corner {} at {:?}, expected {e:?}", c.index, c.uv);
    }
}

/// Too large for the paper: refused, naming the paper and the largest square
/// that fits (which then does fit); wrong options are named.
#[test]
fn a_board_that_does_not_fit_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("big.svg");
    let e = target_print::run(&charuco_args(&out).clone_with_square(0.05))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("does not fit on A4") && e.contains("at most"),
        "{e}"
    );
    assert!(!out.exists(), "no partial output");
    let largest: f64 = e
        .rsplit("at most ")
        .next()
        .and_then(|s| s.trim_end_matches(" mm").parse().ok())
        .unwrap_or_else(|| panic!("{e}"));
    target_print::run(&charuco_args(&out).clone_with_square(largest / 1000.0)).unwrap();
    let mut a = charuco_args(&out);
    a.dictionary = Some("DICT_5X5_7".into());
    let e = target_print::run(&a).unwrap_err().to_string();
    assert!(
        e.contains("DICT_5X5_7") && e.contains("DICT_5X5_100"),
        "{e}"
    );
    let mut a = args(BoardType::Chessboard, 6, 9, 0.02, &out);
    a.marker = Some(0.01);
    let e = target_print::run(&a).unwrap_err().to_string();
    assert!(e.contains("--marker"), "{e}");
}

trait WithSquare {
    fn clone_with_square(&self, square: f64) -> Args;
}

impl WithSquare for Args {
    fn clone_with_square(&self, square: f64) -> Args {
        Args {
            square,
            marker: self.marker.map(|_| 0.7 * square),
            ..self.clone()
        }
    }
}

/// Black area of `[a, b]` under a square wave that is +1 on even squares and −1
/// on odd ones, from `start` over `n` squares of side `s` (0 outside), and the
/// length of `[a, b]` inside the board: the two factors of an exact box filter.
fn wave_and_inside(a: f64, b: f64, start: f64, n: usize, s: f64) -> (f64, f64) {
    let w = n as f64 * s;
    let prim = |x: f64| {
        let t = (x - start).clamp(0.0, w);
        let k = (t / s).floor();
        let r = t - k * s;
        if (k as usize).is_multiple_of(2) {
            r
        } else {
            s - r
        }
    };
    let inside = |x: f64| (x - start).clamp(0.0, w);
    (prim(b) - prim(a), inside(b) - inside(a))
}

/// A chessboard of rows × cols inner corners, squares `s` px, its outer
/// top-left corner at `origin` (pixel-edge coordinates), the top-left square
/// black, each pixel the exact area average (an ideal, alias-free box filter).
fn box_filtered_board(rows: usize, cols: usize, s: f64, origin: [f64; 2]) -> image::GrayImage {
    image::GrayImage::from_fn(320, 240, |i, j| {
        let (sx, ix) = wave_and_inside(i as f64, i as f64 + 1.0, origin[0], cols + 1, s);
        let (sy, iy) = wave_and_inside(j as f64, j as f64 + 1.0, origin[1], rows + 1, s);
        let black = 0.5 * (ix * iy + sx * sy);
        image::Luma([(255.0 * (1.0 - black)).round() as u8])
    })
}

/// The control for the two tests above: on an exactly area-sampled board (no
/// rasteriser between the spec and the pixels) the detector has no bias along
/// x or y. Its error depends on each axis's sub-pixel phase alone (the usual
/// "pixel locking" of gradient refinement on an edge one pixel wide): ±0.08 px
/// per axis, 0.11 px at worst, and averaging out over the phases.
#[test]
fn a_box_filtered_board_is_detected_without_bias_at_any_phase() {
    let (rows, cols, s) = (6, 9, 23.37);
    let (mut worst, mut sum, mut n) = ([0.0f64; 2], [0.0; 2], 0.0);
    for k in 0..10 {
        let phase = [0.1 * k as f64, (0.37 * k as f64).fract()];
        let origin = [40.0 + phase[0], 30.0 + phase[1]];
        let img = box_filtered_board(rows, cols, s, origin);
        let det = Detector::default()
            .detect_image(&image::DynamicImage::ImageLuma8(img), rows, cols)
            .expect("found");
        assert!(det.complete, "phase {phase:?}");
        for c in &det.corners {
            let (r, k) = (c.index / cols, c.index % cols);
            let e = [
                origin[0] + (k + 1) as f64 * s - 0.5,
                origin[1] + (r + 1) as f64 * s - 0.5,
            ];
            for a in 0..2 {
                let d = c.uv[a] - e[a];
                worst[a] = worst[a].max(d.abs());
                sum[a] += d;
            }
            n += 1.0;
        }
    }
    let bias = [sum[0] / n, sum[1] / n];
    eprintln!("box-filtered board: bias {bias:?} px, worst per axis {worst:?} px");
    assert!(
        bias[0].abs() < 0.01 && bias[1].abs() < 0.01,
        "bias {bias:?}"
    );
    assert!(worst[0] < 0.1 && worst[1] < 0.1, "worst {worst:?}");
}
