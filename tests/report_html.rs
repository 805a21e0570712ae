//! `report.html`, the calibration's and the protocol's, opened in a real headless
//! browser (Debian's `chromium`): every section is in the rendered DOM, the page
//! logs nothing to the console, refers to no file or network resource, and a
//! screenshot is saved. Without chromium the browser checks are skipped, with the
//! reason printed; the checks on the file itself always run.
use crate::common;

use deformcal::app::html_report;
use deformcal::app::lint::FrameFiles as FrameLabels;
use deformcal::model::synthetic::Preset;
use deformcal::solver::problem::Loss;
use deformcal::Method;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The chromium binary: `$CHROMIUM`, else the first of the usual names that runs.
fn chromium() -> Option<String> {
    let candidates = std::env::var("CHROMIUM")
        .into_iter()
        .chain(["chromium", "chromium-browser", "google-chrome"].map(String::from));
    for name in candidates {
        let ok = Command::new(&name)
            .arg("--version")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if ok {
            return Some(name);
        }
    }
    None
}

/// What one headless chromium run produced.
struct Rendered {
    dom: String,
    console: Vec<String>,
}

/// Opens `page` in headless chromium with `extra` arguments (a screenshot, the
/// DOM); returns the DOM it printed and every console line it logged.
fn render(browser: &str, page: &Path, extra: &[String]) -> Rendered {
    let profile = tempfile::tempdir().unwrap();
    let out = tempfile::NamedTempFile::new().unwrap();
    let err = tempfile::NamedTempFile::new().unwrap();
    let mut child = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            "--enable-logging=stderr",
            "--v=0",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .args(extra)
        .arg(format!("file://{}", page.canonicalize().unwrap().display()))
        .stdout(out.reopen().unwrap())
        .stderr(err.reopen().unwrap())
        .spawn()
        .expect("start chromium");
    // Generous: only to turn a hung browser into a failure instead of a stall.
    let deadline = Instant::now() + Duration::from_secs(180);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("chromium did not finish within 180 s on {}", page.display());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let stderr = std::fs::read_to_string(err.path()).unwrap();
    let console = stderr
        .lines()
        .filter(|l| l.contains(":CONSOLE") || l.contains("Uncaught"))
        .map(String::from)
        .collect();
    Rendered {
        dom: std::fs::read_to_string(out.path()).unwrap(),
        console,
    }
}

/// The DOM of `page` and its console lines.
fn dump_dom(browser: &str, page: &Path) -> Rendered {
    render(browser, page, &["--dump-dom".to_string()])
}

/// Saves a screenshot of `page` to `png` and checks it shows something.
fn screenshot(browser: &str, page: &Path, png: &Path, size: (u32, u32)) {
    let r = render(
        browser,
        page,
        &[
            format!("--screenshot={}", png.display()),
            format!("--window-size={},{}", size.0, size.1),
        ],
    );
    assert!(r.console.is_empty(), "console output: {:?}", r.console);
    let img = image::open(png)
        .unwrap_or_else(|e| panic!("{}: {e}", png.display()))
        .to_rgb8();
    assert_eq!(img.dimensions(), size);
    // A blank page is one colour; a report has text, plots and colour maps.
    let colours: std::collections::HashSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    assert!(colours.len() > 200, "{} colours only", colours.len());
    println!("screenshot: {}", png.display());
}

/// The page refers to nothing outside itself: no script, no linked style sheet,
/// every `src` and `href` a data URI or an anchor on the page.
fn assert_self_contained(html: &str) {
    for forbidden in ["<script", "<link", "@import", "url(", "<iframe"] {
        assert!(!html.contains(forbidden), "report contains `{forbidden}`");
    }
    for attr in ["src=\"", "href=\""] {
        for (i, _) in html.match_indices(attr) {
            let value = &html[i + attr.len()..];
            assert!(
                value.starts_with("data:") || value.starts_with('#'),
                "external reference: {}",
                &value[..value.len().min(60)]
            );
        }
    }
}

fn deformcal(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_deformcal"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Where the screenshots go: kept after the test for a person to look at.
fn shots() -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("report_html");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The console check itself: a page with a console error and an uncaught
/// exception is caught, so a clean report's empty console means something.
#[test]
fn the_console_check_catches_errors() {
    let Some(browser) = chromium() else {
        println!("skipped: no chromium on this machine (apt-get install chromium)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let page = dir.path().join("bad.html");
    std::fs::write(
        &page,
        "<!DOCTYPE html><html><body><p id=\"x\">x</p><script>console.error('boom'); missing();</script></body></html>",
    )
    .unwrap();
    let r = dump_dom(&browser, &page);
    assert!(r.dom.contains("id=\"x\""), "{}", r.dom);
    assert!(
        r.console.iter().any(|l| l.contains("boom")),
        "{:?}",
        r.console
    );
    assert!(
        r.console.iter().any(|l| l.contains("Uncaught")),
        "{:?}",
        r.console
    );
}

/// A two-camera `full` calibration through the CLI: report.html beside
/// calibration.json, every section rendered, no console output, a screenshot.
#[test]
fn calibration_report_renders_in_chromium() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("c.toml");
    std::fs::write(
        &config,
        "[[cameras]]\nname = \"left\"\nwidth = 1936\nheight = 1216\n\
         [[cameras]]\nname = \"right\"\nwidth = 1936\nheight = 1216\n\
         [data]\nsynthetic = \"stereo\"\nimages = 12\nseed = 5\n\
         [calibration]\nmethod = \"full\"\n[output]\ndir = \"out\"\n",
    )
    .unwrap();
    deformcal(&["--config", config.to_str().unwrap()]);
    let page = dir.path().join("out/report.html");
    let html = std::fs::read_to_string(&page).unwrap();
    assert_self_contained(&html);
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("out/calibration.json")).unwrap(),
    )
    .unwrap();
    // The key figures are the calibration's own.
    let rmse = json["rmse_px"].as_f64().unwrap();
    assert!(
        html.contains(&format!("<td>{rmse:.4}</td>")),
        "RMSE {rmse:.4} not in the report"
    );
    let Some(browser) = chromium() else {
        println!(
            "skipped the browser checks: no chromium on this machine (apt-get install chromium)"
        );
        return;
    };
    let r = dump_dom(&browser, &page);
    assert!(r.console.is_empty(), "console output: {:?}", r.console);
    let mut ids = vec![
        "summary",
        "board",
        "static-correction",
        "bends",
        "fig-bends",
        "fig-worst-bend",
        "frames",
        "definitions",
    ]
    .into_iter()
    .map(String::from)
    .collect::<Vec<_>>();
    for cam in ["left", "right"] {
        for part in [
            "camera",
            "residuals",
            "rmse",
            "outliers",
            "distortion",
            "uncertainty",
        ] {
            ids.push(format!("{part}-{cam}"));
        }
        for fig in ["fig-residuals", "fig-rmse", "fig-distortion"] {
            ids.push(format!("{fig}-{cam}"));
        }
    }
    for id in &ids {
        assert!(
            r.dom.contains(&format!("id=\"{id}\"")),
            "section `{id}` not rendered"
        );
    }
    // Nine plots: three per camera, the correction, the bends and the worst bend.
    assert_eq!(r.dom.matches("<svg").count(), 9);
    // Every frame of both cameras in the frame table: 12 frames × 2 cameras.
    let frames = &r.dom[r.dom.find("id=\"frames\"").unwrap()..];
    assert_eq!(frames.matches("<tr>").count(), 1 + 24);
    screenshot(
        &browser,
        &page,
        &shots().join("calibration.png"),
        (1280, 2400),
    );
}

/// The protocol's report.html next to report.md: every table and plot, all
/// intrinsics with units, no console output, a screenshot.
#[test]
fn protocol_report_renders_in_chromium() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("p.toml");
    std::fs::write(
        &config,
        "[data]\nsynthetic = \"t2\"\nimages = 40\n\
         [reference]\nsynthetic = \"reference\"\nimages = 20\n\
         [protocol]\nsubsets = 2\nimages_per_subset = 8\nmethods = [\"standard\", \"dynamic\"]\n\
         [output]\ndir = \"out\"\n",
    )
    .unwrap();
    deformcal(&["protocol", "--config", config.to_str().unwrap()]);
    let page = dir.path().join("out/report.html");
    let html = std::fs::read_to_string(&page).unwrap();
    assert_self_contained(&html);
    assert!(dir.path().join("out/report.md").exists());
    // Every radial3 parameter with its unit, in the table and as a plot panel.
    for head in ["fx (px)", "cy (px)", "k1 (unitless)", "k3 (unitless)"] {
        assert!(
            html.contains(&format!("<th>{head}</th>")),
            "no column {head}"
        );
        assert!(
            html.contains(&format!(">\n{head}\n</text>")),
            "no axis {head}"
        );
    }
    let Some(browser) = chromium() else {
        println!(
            "skipped the browser checks: no chromium on this machine (apt-get install chromium)"
        );
        return;
    };
    let r = dump_dom(&browser, &page);
    assert!(r.console.is_empty(), "console output: {:?}", r.console);
    for id in [
        "dataset-t2",
        "t2-rmse",
        "t2-intrinsics",
        "t2-mapping",
        "t2-bend",
        "t2-deformation",
        "definitions",
    ] {
        assert!(
            r.dom.contains(&format!("id=\"{id}\"")),
            "`{id}` not rendered"
        );
    }
    screenshot(&browser, &page, &shots().join("protocol.png"), (1280, 2000));
}

/// The library's report: the per-image RMSE agrees with the overall RMSE, image
/// names label the frames, and an uncertainty map beside it is embedded as an
/// image (its absence noted).
#[test]
fn report_embeds_the_uncertainty_map_and_names_the_images() {
    let (d, _) = common::data(Preset::T2, 8, 3, 1.0, 1.0);
    let c = common::run(&d, Method::Dynamic, Loss::Cauchy);
    // Σ n·rmse² over the images is the total squared residual.
    let stats = html_report::fields::views_worst_first(&c);
    let n: usize = stats.iter().map(|v| v.observations).sum();
    let total: f64 = stats
        .iter()
        .map(|v| v.observations as f64 * v.rmse_px().powi(2))
        .sum();
    assert_eq!(n, c.dataset.observations.len());
    assert!(((total / n as f64).sqrt() - c.rmse_px).abs() < 1e-12);
    assert!(stats.windows(2).all(|w| w[0].rmse_px() >= w[1].rmse_px()));
    let worst = c.dataset.frame_ids[stats[0].frame];
    let labels: FrameLabels = [((0, worst), "photos/the-worst-one.png".to_string())].into();
    let dir = tempfile::tempdir().unwrap();
    html_report::write_calibration_report(dir.path(), &c, &labels).unwrap();
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(html.contains("No projection-uncertainty map for <code>cam0</code>"));
    assert!(html.contains("photos/the-worst-one.png"));
    let svg = b"<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"4\" height=\"4\"></svg>";
    std::fs::write(dir.path().join(html_report::uncertainty_file("cam0")), svg).unwrap();
    html_report::write_calibration_report(dir.path(), &c, &labels).unwrap();
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    let uri = format!(
        "data:image/svg+xml;base64,{}",
        deformcal::app::raster::base64(svg)
    );
    assert!(html.contains(&uri), "the map is not embedded");
    assert!(!html.contains("No projection-uncertainty map"));
    assert_self_contained(&html);
}

/// The result files written side by side (the CLI's writer) are byte for byte
/// those of the one-at-a-time writers: the models and exports, `outliers.csv`,
/// `board.json`, the uncertainty map and the report that embeds it.
#[test]
fn parallel_writer_equals_the_writers_one_at_a_time() {
    use deformcal::app::{board_json, calibration_json::CalibrationJson, exports, output};
    let (d, _) = common::data(Preset::T2, 8, 3, 1.0, 1.0);
    let c = common::run(&d, Method::Full, Loss::Cauchy);
    let labels: FrameLabels = [((0, d.frame_ids[0]), "photos/first.png".to_string())].into();
    let (parallel, serial) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let written = output::write_calibration_labelled(parallel.path(), &c, &labels).unwrap();
    let inputs = exports::optimization_inputs(&c);
    let one = output::write_models(serial.path(), &CalibrationJson::from(&c), &inputs).unwrap();
    assert_eq!(written.warnings, one.warnings);
    let outliers = output::suspects_csv(&c).unwrap();
    std::fs::write(serial.path().join("outliers.csv"), outliers).unwrap();
    board_json::write(serial.path(), &c).unwrap();
    deformcal::app::uncertainty_plot::write_maps(serial.path(), &c).unwrap();
    html_report::write_calibration_report(serial.path(), &c, &labels).unwrap();
    let files = |dir: &Path| {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    };
    let names = files(parallel.path());
    assert_eq!(names, files(serial.path()));
    for needed in [
        "board.json",
        "report.html",
        "uncertainty_cam0.svg",
        "calibration.json",
    ] {
        assert!(
            names.iter().any(|n| n == needed),
            "{needed} missing: {names:?}"
        );
    }
    for name in &names {
        let a = std::fs::read(parallel.path().join(name)).unwrap();
        let b = std::fs::read(serial.path().join(name)).unwrap();
        assert!(a == b, "{name} differs between the two writers");
    }
}

/// Images read from a corners.vnl keep their file names for the report: each
/// name labels the frame that holds exactly that image's corners.
#[test]
fn corners_vnl_names_label_their_frames() {
    let (d, _) = common::data(Preset::T2, 5, 4, 1.0, 1.0);
    let text = deformcal::app::corners_vnl::write_corners_vnl(&d);
    let table = deformcal::app::corners_vnl::parse_table(
        text.as_bytes(),
        Path::new("corners.vnl"),
        d.target,
        d.cameras.clone(),
        &Default::default(),
    )
    .unwrap();
    let read = table.dataset;
    let names: FrameLabels = table
        .files
        .into_iter()
        .map(|(k, f, n)| ((k, f), n))
        .collect();
    assert_eq!(names.len(), d.num_frames());
    let corners = |ds: &deformcal::Dataset, frame: usize| -> Vec<(usize, [f64; 2])> {
        ds.observations
            .iter()
            .filter(|o| o.frame == frame)
            .map(|o| (o.corner, o.uv))
            .collect()
    };
    for ((camera, frame), name) in &names {
        assert_eq!(*camera, 0);
        // The writer names an image `<camera>-<original frame id>.png`.
        let id: i64 = name
            .trim_start_matches("cam0-")
            .trim_end_matches(".png")
            .parse()
            .unwrap();
        let original = d.frame_ids.iter().position(|&f| f == id).unwrap();
        let dense = read.frame_ids.iter().position(|f| f == frame).unwrap();
        assert_eq!(corners(&read, dense), corners(&d, original), "{name}");
    }
}

#[test]
fn the_bend_figure_draws_the_whole_surface() {
    use deformcal::app::plots::deformation_svg;
    use deformcal::model::board::{Paraboloid, HIGHER_BEND_PARAMS};
    use std::collections::BTreeSet;
    let t = deformcal::model::target::Target {
        rows: 13,
        cols: 13,
        spacing: 0.07,
    };
    let fills = |higher: &[f64; HIGHER_BEND_PARAMS]| -> BTreeSet<String> {
        let svg = deformation_svg("bend", &t, &Paraboloid::default(), higher).unwrap();
        svg.match_indices("fill=\"#")
            .map(|(i, _)| svg[i + 7..i + 13].to_string())
            .collect()
    };
    // A pure cubic x³ and a twist x³y, no paraboloid: the map must not be flat.
    let mut h = [0.0; HIGHER_BEND_PARAMS];
    h[0] = 0.01;
    h[5] = 0.02;
    let flat = fills(&[0.0; HIGHER_BEND_PARAMS]).len();
    let bent = fills(&h).len();
    assert!(bent > flat + 20, "{flat} colours flat, {bent} bent");
}
