//! The calibration report page (`report.html`): the summary and verdicts, one
//! section per camera (intrinsics, residuals over the image, per-view RMSE,
//! outliers, distortion field, the projection-uncertainty map), the board (static
//! correction, bends along the sequence, the worst bend), every frame in a table,
//! and the definitions of the metrics shown. Figures come from `figures`; this
//! module only decides what goes where and says what each figure shows.
use crate::app::html_report::fields;
use crate::app::html_report::figures;
use crate::app::html_report::page::{self, escape, para, subsection, Page};
use crate::app::lint::FrameFiles as FrameLabels;
use crate::app::plots;
use crate::app::plots::short;
use crate::app::report;
use crate::error::Result;
use crate::model::board::Method;
use crate::solver::calibrate::Calibration;
use crate::solver::residuals::ViewResidual;
use std::fmt::Write;

/// The file name of camera `camera`'s projection-uncertainty map, which the report
/// embeds when it is in the output directory before the report is written.
pub fn uncertainty_file(camera: &str) -> String {
    format!("uncertainty_{}.svg", crate::app::exports::file_stem(camera))
}

/// Most views in a camera's RMSE bar chart: the worst ones (all are in the frame table).
pub const MAX_BARS: usize = 40;
/// Most rejected outliers listed per camera (all are in `outliers.csv`).
pub const MAX_OUTLIER_ROWS: usize = 50;

/// The whole page of one calibration. `uncertainty[k]` is camera k's
/// projection-uncertainty map (SVG bytes), where one was made.
pub fn calibration_page(
    c: &Calibration,
    labels: &FrameLabels,
    uncertainty: &[Option<Vec<u8>>],
) -> Result<String> {
    let mut p = page_but_advice(c, labels, uncertainty)?;
    p.fill(ADVICE_SECTION, super::advice::advice_section(c));
    Ok(p.render())
}

/// The id of the page's "Where to hold the board next" section.
pub const ADVICE_SECTION: &str = "advice";

/// [`calibration_page`] with the advice section left empty, to be filled
/// ([`Page::fill`] with [`ADVICE_SECTION`]) by [`super::advice::advice_section`]:
/// the longest part of the page, which a caller may compute meanwhile.
pub fn page_but_advice(
    c: &Calibration,
    labels: &FrameLabels,
    uncertainty: &[Option<Vec<u8>>],
) -> Result<Page> {
    let d = &c.dataset;
    let lead = format!(
        "Method `{}` on {} image(s) and {} observations of a {} × {} board ({} m squares); {} camera(s).",
        c.method,
        d.num_frames(),
        d.observations.len(),
        d.target.rows,
        d.target.cols,
        d.target.spacing,
        d.cameras.len()
    );
    let mut p = Page::new("deformcal calibration report", &lead);
    p.section("summary", "Summary and verdicts", summary_section(c));
    let stats = fields::views_worst_first(c);
    for (k, cam) in d.cameras.iter().enumerate() {
        let body = camera_section(c, k, &stats, labels, uncertainty.get(k).cloned().flatten())?;
        p.section(
            &format!("camera-{}", cam.name),
            &format!("Camera `{}`", cam.name),
            body,
        );
    }
    p.section(
        "board",
        "The board: static correction and bends",
        board_section(c)?,
    );
    p.section(
        ADVICE_SECTION,
        "Where to hold the board next",
        String::new(),
    );
    p.section("frames", "Every frame", frames_section(c, &stats, labels));
    p.section("definitions", "Definitions", definitions());
    Ok(p)
}

/// A view's name: its image file where the source knows it, else its frame number.
fn view_label(c: &Calibration, labels: &FrameLabels, camera: usize, frame: usize) -> String {
    let id = c.dataset.frame_ids[frame];
    labels
        .get(&(camera, id))
        .cloned()
        .unwrap_or_else(|| format!("frame {id}"))
}

/// One verdict line: its class (`ok`, `warn`, `bad`) and its text.
type Verdict = (&'static str, String);

/// The verdicts a user checks first: convergence, the bias ratio, outliers, warnings.
fn verdicts(c: &Calibration) -> Vec<Verdict> {
    let mut v = Vec::new();
    let last = c.stages.last();
    v.push(if c.converged {
        (
            "ok",
            format!(
                "The solve converged after {} iterations in {:.3} s.",
                c.iterations(),
                c.seconds
            ),
        )
    } else {
        (
            "bad",
            format!(
                "The solve did NOT converge ({}): do not use these intrinsics.",
                last.map(|s| s.message.as_str()).unwrap_or("")
            ),
        )
    });
    if let Some(t) = c.assessment.trust {
        let class = if t.bias_ratio <= report::BIAS_RATIO_OK {
            "ok"
        } else {
            "warn"
        };
        v.push((
            class,
            format!(
                "Bias ratio {:.2}: {}.",
                t.bias_ratio,
                report::trust_verdict(c, &t)
            ),
        ));
    }
    if let Some(sel) = &c.selection {
        v.push((
            "ok",
            format!("Method `{}` chosen by `auto`: {}.", sel.chosen, sel.reason),
        ));
    }
    let total = c.dataset.observations.len() + c.rejected.len();
    let fraction = c.rejected.len() as f64 / total.max(1) as f64;
    let class = if fraction > crate::solver::robust::WARN_REJECTED_FRACTION {
        "bad"
    } else {
        "ok"
    };
    v.push(if c.settings.outlier_k <= 0.0 {
        (
            "ok",
            "Outlier rejection is off (calibration.outlier_k = 0).".to_string(),
        )
    } else {
        (
            class,
            format!(
                "{} of {total} observations ({}%) rejected as outliers (beyond {}σ of their \
                 neighbours){}.",
                c.rejected.len(),
                percent(fraction),
                c.settings.outlier_k,
                if c.rejected.is_empty() {
                    ""
                } else {
                    "; the result is the calibration of the observations kept alone"
                }
            ),
        )
    });
    for w in &c.warnings {
        v.push(("warn", format!("Warning: {w}")));
    }
    v
}

/// A fraction in percent, with two decimals below 1 % so a few do not read as 0.
fn percent(fraction: f64) -> String {
    let p = 100.0 * fraction;
    if p > 0.0 && p < 1.0 {
        format!("{p:.2}")
    } else {
        format!("{p:.1}")
    }
}

/// The verdicts, the key figures and the printed summary.
fn summary_section(c: &Calibration) -> String {
    let mut s = String::from("<ul class=\"verdicts\">\n");
    for (class, text) in verdicts(c) {
        let _ = writeln!(s, "<li class=\"{class}\">{}</li>", page::inline(&text));
    }
    s.push_str("</ul>\n");
    s.push_str(&page::table_html(
        &["figure".into(), "value".into()],
        &key_figures(c),
    ));
    let _ = write!(
        s,
        "<details open><summary>The summary deformcal printed</summary>\n<pre>{}</pre>\n</details>\n",
        escape(&report::summary(c))
    );
    s
}

/// The key figures of a calibration as (name, value) rows.
fn key_figures(c: &Calibration) -> Vec<Vec<String>> {
    let mut rows = vec![
        vec!["method".into(), format!("`{}`", c.method)],
        vec!["RMSE `rmse_px` (px)".into(), format!("{:.4}", c.rmse_px)],
        vec![
            "images, observations".into(),
            format!(
                "{}, {}",
                c.dataset.num_frames(),
                c.dataset.observations.len()
            ),
        ],
        vec![
            "solver".into(),
            format!(
                "{} after {} iterations, {:.3} s",
                if c.converged {
                    "converged"
                } else {
                    "NOT CONVERGED"
                },
                c.iterations(),
                c.seconds
            ),
        ],
    ];
    if let Some(t) = c.assessment.trust {
        let source = if t.noise_source == "config" {
            "as configured"
        } else {
            "estimated"
        };
        rows.push(vec![
            "noise σ̂ `noise_px` (px)".into(),
            format!("{:.3} ({source})", t.noise_px),
        ]);
        rows.push(vec![
            "bias ratio `bias_ratio`".into(),
            format!("{:.3}", t.bias_ratio),
        ]);
        rows.push(vec![
            "G-AIC `g_aic` (px²), free parameters".into(),
            format!("{:.1}, {}", t.g_aic, t.parameters),
        ]);
    }
    if let Ok(u) = &c.assessment.uncertainty {
        for (cam, u) in c.dataset.cameras.iter().zip(u) {
            rows.push(vec![
                format!(
                    "expected mapping error `expected_mapping_error_px` (px), `{}`",
                    cam.name
                ),
                format!(
                    "{:.3} ({:.3} with the rotation removed)",
                    u.expected_mapping_error_px, u.expected_mapping_error_rot_px
                ),
            ]);
        }
    }
    if c.method.has_paraboloid() {
        rows.push(vec![
            "largest bend `max_out_of_plane_m` (mm)".into(),
            format!("{:.3}", c.max_out_of_plane() * 1e3),
        ]);
    }
    if c.method.has_correction() {
        rows.push(vec![
            "largest static correction (mm)".into(),
            format!("{:.3}", largest_correction(c) * 1e3),
        ]);
    }
    rows
}

/// The length of the largest static correction, metres.
fn largest_correction(c: &Calibration) -> f64 {
    c.state
        .corrections
        .iter()
        .map(|v| v.iter().map(|x| x * x).sum::<f64>().sqrt())
        .fold(0.0, f64::max)
}

/// One camera: intrinsics, residuals, per-view RMSE, outliers, distortion, uncertainty.
fn camera_section(
    c: &Calibration,
    k: usize,
    stats: &[ViewResidual],
    labels: &FrameLabels,
    uncertainty: Option<Vec<u8>>,
) -> Result<String> {
    let cam = &c.dataset.cameras[k];
    let mut s = para(&format!(
        "{} × {} pixels, lens model `{}`.",
        cam.width, cam.height, cam.model
    ));
    s.push_str(&intrinsics_table(c, k));
    let id = page::id_of(&cam.name);
    s.push_str(&subsection(
        &format!("residuals-{id}"),
        "Residuals over the image",
        &residuals_block(c, k)?,
    ));
    s.push_str(&subsection(
        &format!("rmse-{id}"),
        "RMSE per image, worst first",
        &rmse_block(c, k, stats, labels)?,
    ));
    s.push_str(&subsection(
        &format!("outliers-{id}"),
        "Rejected outliers",
        &outliers_block(c, k, labels),
    ));
    s.push_str(&subsection(
        &format!("distortion-{id}"),
        "Distortion field",
        &distortion_block(c, k)?,
    ));
    s.push_str(&subsection(
        &format!("uncertainty-{id}"),
        "Projection uncertainty",
        &uncertainty_section(&cam.name, uncertainty.as_deref()),
    ));
    Ok(s)
}

/// A camera's intrinsics with their 1-σ uncertainty and units, and its pose in
/// the rig.
fn intrinsics_table(c: &Calibration, k: usize) -> String {
    let i = &c.state.intrinsics[k];
    let std = c
        .assessment
        .uncertainty
        .as_ref()
        .ok()
        .and_then(|u| u.get(k));
    let rows: Vec<Vec<String>> = i
        .named()
        .enumerate()
        .map(|(n, (name, v))| {
            let (digits, unit) = if n < 4 { (3, "px") } else { (6, "unitless") };
            let sigma = match std.map(|u| u.intrinsics_std.iter().find(|(p, _)| *p == name)) {
                Some(Some((_, e))) => format!("{e:.digits$}"),
                Some(None) => "held".to_string(),
                None => "–".to_string(),
            };
            vec![
                format!("`{name}`"),
                format!("{v:.digits$}"),
                sigma,
                unit.to_string(),
            ]
        })
        .collect();
    let header = ["parameter", "value", "1-σ", "unit"].map(String::from);
    let mut s = page::table_html(&header, &rows);
    if k > 0 {
        let pose = c.state.camera_poses[k];
        let _ = write!(
            s,
            "{}",
            para(&format!(
                "Pose from camera `{}`: baseline {:.4} m, rotation {:.3}°.",
                c.dataset.cameras[0].name,
                pose.inverse().translation_vector().norm(),
                pose.rotation_matrix().angle().to_degrees()
            ))
        );
    }
    s
}

/// The residual arrows of one camera with the rejected outliers marked.
fn residuals_block(c: &Calibration, k: usize) -> Result<String> {
    let cam = &c.dataset.cameras[k];
    let a = fields::residual_arrows(c, k);
    let scale = plots::nice(0.025 * cam.width as f64 / a.rms_px.max(1e-9));
    let rejected: Vec<[f64; 2]> = c
        .rejected
        .iter()
        .filter(|r| r.camera == cam.name)
        .map(|r| [r.u, r.v])
        .collect();
    let title = format!("{}: residuals, drawn ×{}", cam.name, short(scale));
    let svg = figures::residual_quiver(&title, (cam.width, cam.height), &a, &rejected, scale)?;
    let shown = if a.stride == 1 {
        format!("all {} observations are drawn", a.total)
    } else {
        format!(
            "every {}th of the {} observations is drawn ({} arrows), to keep the report small",
            a.stride,
            a.total,
            a.arrows.len()
        )
    };
    let caption = format!(
        "Each arrow starts at an observed corner and points along its residual, observed − projected pixel, \
         drawn {} times longer than it is (the key gives the length of a residual in pixels); {shown}. \
         RMS residual of this camera: {:.4} px. Red crosses: observations rejected as outliers ({}; \
         not part of the fit; their residuals are in `outliers.csv`). A pattern in the arrows (a swirl, \
         arrows growing toward the edges) is a model error; noise points every way.",
        short(scale),
        a.rms_px,
        rejected.len()
    );
    Ok(page::figure_html(
        &format!("fig-residuals-{}", page::id_of(&cam.name)),
        &svg,
        &caption,
    ))
}

/// The worst views' RMSE as bars, with the overall RMSE and the noise's share.
fn rmse_block(
    c: &Calibration,
    k: usize,
    stats: &[ViewResidual],
    labels: &FrameLabels,
) -> Result<String> {
    let cam = &c.dataset.cameras[k];
    let own: Vec<&ViewResidual> = stats.iter().filter(|v| v.camera == k).collect();
    let bars: Vec<(String, f64)> = own
        .iter()
        .take(MAX_BARS)
        .map(|v| (view_label(c, labels, k, v.frame), v.rmse_px()))
        .collect();
    let camera_rmse = {
        let (n, sq) = own.iter().fold((0usize, 0.0), |(n, sq), v| {
            (n + v.observations, sq + v.sum_sq_px2)
        });
        (sq / n.max(1) as f64).sqrt()
    };
    let noise = c.assessment.trust.map(|t| {
        crate::model::trust::expected_rmse2(t.noise_px, t.parameters, t.residuals)
            .max(0.0)
            .sqrt()
    });
    let title = format!("{}: RMSE per image, worst first", cam.name);
    let svg = figures::rmse_bars(&title, &bars, camera_rmse, noise)?;
    let shown = if own.len() > bars.len() {
        format!(
            "the {} worst of {} images; every image is in the frame table below",
            bars.len(),
            own.len()
        )
    } else {
        format!("all {} images", own.len())
    };
    let caption = format!(
        "RMSE of each image's corners in this camera, √(Σ‖u − p‖² / n) over its n corners, worst first ({shown}). \
         Red line: this camera's RMSE over all images. Green line: the RMSE the detector noise alone would leave, \
         √(2σ̂²(1 − p/N)). An image far above the others may be blurred, mislabelled or badly detected."
    );
    Ok(page::figure_html(
        &format!("fig-rmse-{}", page::id_of(&cam.name)),
        &svg,
        &caption,
    ))
}

/// The rejected outliers of one camera, worst first.
fn outliers_block(c: &Calibration, k: usize, labels: &FrameLabels) -> String {
    let name = &c.dataset.cameras[k].name;
    let mut own: Vec<_> = c.rejected.iter().filter(|r| &r.camera == name).collect();
    if own.is_empty() {
        return para("No observation of this camera was rejected as an outlier.");
    }
    own.sort_by(|a, b| b.residual_px.total_cmp(&a.residual_px));
    let rows: Vec<Vec<String>> = own
        .iter()
        .take(MAX_OUTLIER_ROWS)
        .map(|r| {
            let label = labels.get(&(k, r.frame)).cloned().unwrap_or_default();
            vec![
                r.frame.to_string(),
                label,
                r.corner.to_string(),
                format!("{:.2}", r.u),
                format!("{:.2}", r.v),
                format!("{:.3}", r.residual_px),
            ]
        })
        .collect();
    let mut s = page::table_html(
        &[
            "frame".into(),
            "image".into(),
            "corner".into(),
            "u (px)".into(),
            "v (px)".into(),
            "residual (px)".into(),
        ],
        &rows,
    );
    if own.len() > MAX_OUTLIER_ROWS {
        s.push_str(&para(&format!(
            "The {MAX_OUTLIER_ROWS} worst of {} are listed; `outliers.csv` has them all.",
            own.len()
        )));
    }
    s
}

/// The lens's displacement from its pinhole over the image.
fn distortion_block(c: &Calibration, k: usize) -> Result<String> {
    let cam = &c.dataset.cameras[k];
    let intr = &c.state.intrinsics[k];
    let nx = 64;
    let ny =
        ((nx as f64 * cam.height as f64 / cam.width.max(1) as f64).round() as usize).clamp(8, 64);
    let grid = fields::distortion_field(intr, cam.width, cam.height, nx, ny);
    let every = 4;
    let diagonal = (cam.width as f64).hypot(cam.height as f64);
    let scale = figures::distortion_scale(&grid, diagonal, grid.dx * every as f64);
    let title = format!("{}: distortion, pixel − pinhole image of its ray", cam.name);
    let svg = figures::distortion_map(&title, (cam.width, cam.height), &grid, &scale, every)?;
    let missing = grid.values.iter().filter(|v| v.is_none()).count();
    let mut caption = format!(
        "How far the lens model moves each pixel from where a distortion-free pinhole with the same \
         fx, fy, cx, cy would image its ray: pixel − (fx·x/z + cx, fy·y/z + cy) for the ray (x, y, z) \
         the model unprojects the pixel to, on a {nx} × {ny} grid. Colour and contour lines (every {} px): \
         its length; white arrows: its direction, drawn ×{}. Largest: {:.2} px.",
        short(scale.step_px),
        short(scale.arrow_scale),
        scale.max_px
    );
    if scale.max_px > scale.clip_px {
        let _ = write!(
            caption,
            " The colours and arrows stop at {:.1} px, which {:.0} % of the image stays below \
             (at most the image diagonal): beyond it the colour saturates and arrows keep their direction only.",
            scale.clip_px,
            100.0 * figures::CLIP_QUANTILE
        );
    }
    if missing > 0 {
        let _ = write!(
            caption,
            " Grey: {missing} cells whose ray is 90° or more off axis (no pinhole image) or that the model maps no ray to."
        );
    }
    Ok(page::figure_html(
        &format!("fig-distortion-{}", page::id_of(&cam.name)),
        &svg,
        &caption,
    ))
}

/// THE PLACE FOR THE PROJECTION-UNCERTAINTY MAP: camera `camera`'s map, given as
/// the bytes of an SVG file (`uncertainty_<camera>.svg` in the output directory,
/// see [`crate::app::html_report::uncertainty_file`]), shown as an image; without
/// one, a note that this run has none.
pub fn uncertainty_section(camera: &str, svg: Option<&[u8]>) -> String {
    match svg {
        Some(bytes) => format!(
            "<figure>{}<figcaption>{}</figcaption></figure>\n",
            page::svg_image_html(bytes, &format!("projection uncertainty of {camera}")),
            page::inline(&format!(
                "The projection uncertainty of `{camera}` over the image, from `{}`.",
                uncertainty_file(camera)
            ))
        ),
        None => format!(
            "<div class=\"placeholder\">{}</div>\n",
            page::inline(&format!(
                "No projection-uncertainty map for `{camera}` in this run (`{}` was not written).",
                uncertainty_file(camera)
            ))
        ),
    }
}

/// The static correction and the bends, for the methods that estimate them.
fn board_section(c: &Calibration) -> Result<String> {
    if c.method == Method::Standard {
        return Ok(para(
            "The `standard` method models a rigid, flat board: it estimates no static correction and no bend. \
             If the bias ratio above is large, compare with `dynamic` or `full`.",
        ) + &health_block(c));
    }
    let mut s = health_block(c);
    if c.method.has_correction() {
        s.push_str(&subsection(
            "static-correction",
            "Static correction over the board",
            &correction_block(c)?,
        ));
    }
    if c.method.has_paraboloid() {
        s.push_str(&subsection(
            "bends",
            "Bend of every frame",
            &bends_block(c)?,
        ));
    }
    Ok(s)
}

/// Board health: the frames flagged for a bend over `max_bend_mm` or residuals far
/// above the other frames' (`solver::health`).
fn health_block(c: &Calibration) -> String {
    let h = crate::solver::health::board_health(c, c.settings.board.max_bend_m);
    let rows: Vec<Vec<String>> = h
        .flagged()
        .map(|f| {
            vec![
                f.frame.to_string(),
                format!("{:.3}", f.max_bend_m * 1e3),
                format!("{:.4}", f.rmse_px),
                escape(&f.flags.join("; ")),
            ]
        })
        .collect();
    let intro = format!(
        "Board health: frames are flagged when their largest bend exceeds max_bend_mm = {:.2} mm \
         or their RMSE exceeds {}× the median frame's ({:.4} px).",
        h.max_bend_m * 1e3,
        crate::solver::health::RMSE_FACTOR,
        h.median_rmse_px
    );
    if rows.is_empty() {
        return subsection(
            "board-health",
            "Board health",
            &para(&format!("{intro} No frame is flagged.")),
        );
    }
    let head = ["frame", "max |Δz| (mm)", "RMSE (px)", "why"].map(String::from);
    subsection(
        "board-health",
        "Board health",
        &(para(&format!("{intro} {} frame(s) are flagged:", rows.len()))
            + &page::table_html(&head, &rows)),
    )
}

/// The static correction map and what it shows.
fn correction_block(c: &Calibration) -> Result<String> {
    let t = &c.dataset.target;
    let in_plane = c
        .state
        .corrections
        .iter()
        .map(|v| v[0].hypot(v[1]))
        .fold(0.0, f64::max);
    let scale = plots::nice(0.4 * t.spacing / in_plane.max(1e-12));
    let title = format!("static correction ({}), arrows ×{}", c.method, short(scale));
    let svg = figures::correction_map(
        &title,
        t,
        c.method,
        &c.state.corrections,
        (&c.gauge, &c.frozen),
        scale,
    )?;
    let colour = if c.method == Method::Static {
        "the out-of-plane correction Δz"
    } else {
        "the length of the in-plane correction"
    };
    let caption = format!(
        "The correction Δx_i every corner gets for the whole dataset, in the board frame (x along \
         increasing col, y along increasing row, origin at the board centre). Arrows: the in-plane part \
         (Δx, Δy), drawn ×{}; colour: {colour}. Largest correction: {:.3} mm. Boxed: the gauge corners \
         {:?}, held to fix the gauge (docs/conventions.md §2); crossed: corners seen in fewer than two images, held at zero.",
        short(scale),
        largest_correction(c) * 1e3,
        c.gauge
    );
    Ok(page::figure_html("fig-static-correction", &svg, &caption))
}

/// The bends along the sequence and the worst frame's bend surface.
fn bends_block(c: &Calibration) -> Result<String> {
    let t = &c.dataset.target;
    let max: Vec<f64> = c.frame_bends();
    let worst = (0..max.len())
        .max_by(|&a, &b| max[a].total_cmp(&max[b]))
        .unwrap_or(0);
    let svg = figures::bend_sequence(
        "bend of every frame",
        &c.dataset.frame_ids,
        &c.state.deformations,
        &max,
        worst,
    )?;
    let mut s = page::figure_html(
        "fig-bends",
        &svg,
        "Each frame's paraboloid Δz = a·x² + b·y² + c·xy (x, y in metres from the board centre; a, b, c \
         in mm/m², the bend in mm one metre from the centre) and its largest deflection \
         `max_out_of_plane_m` = max over the corners of |Δz|, in mm.",
    );
    let worst_id = c.dataset.frame_ids.get(worst).copied().unwrap_or(0);
    let bend = c.state.deformations.get(worst).copied().unwrap_or_default();
    let higher = c.state.higher_bends.get(worst).copied().unwrap_or_default();
    let title = format!(
        "frame {worst_id}: Δz over the board, max |Δz| {:.3} mm",
        max.get(worst).copied().unwrap_or(0.0) * 1e3
    );
    let svg = plots::deformation_svg(&title, t, &bend, &higher)?;
    let terms = if higher.iter().any(|&h| h != 0.0) {
        " plus its degree-3 and -4 terms (all drawn)"
    } else {
        ""
    };
    s.push_str(&page::figure_html(
        "fig-worst-bend",
        &svg,
        &format!(
            "The most bent frame, {worst_id}: Δz over the board (colour, mm), the corners as dots \
             (paraboloid a = {:.4}, b = {:.4}, c = {:.4} mm/m²{terms}; the paper's Fig. 1).",
            bend.a * 1e3,
            bend.b * 1e3,
            bend.c * 1e3
        ),
    ));
    Ok(s)
}

/// Every frame: its images, observations, RMSE and bend.
fn frames_section(c: &Calibration, stats: &[ViewResidual], labels: &FrameLabels) -> String {
    let d = &c.dataset;
    let t = &d.target;
    let bends = c.method.has_paraboloid();
    let mut head: Vec<String> = vec![
        "frame".into(),
        "camera".into(),
        "image".into(),
        "corners".into(),
        "RMSE (px)".into(),
    ];
    if bends {
        head.extend(["a (mm/m²)", "b (mm/m²)", "c (mm/m²)", "max |Δz| (mm)"].map(String::from));
    }
    let mut views: Vec<&ViewResidual> = stats.iter().collect();
    views.sort_by_key(|v| (v.frame, v.camera));
    let rows: Vec<Vec<String>> = views
        .iter()
        .map(|v| {
            let mut row = vec![
                d.frame_ids[v.frame].to_string(),
                d.cameras[v.camera].name.clone(),
                labels
                    .get(&(v.camera, d.frame_ids[v.frame]))
                    .cloned()
                    .unwrap_or_default(),
                v.observations.to_string(),
                format!("{:.4}", v.rmse_px()),
            ];
            if bends {
                let b = c.state.deformations[v.frame];
                row.extend([
                    format!("{:.4}", b.a * 1e3),
                    format!("{:.4}", b.b * 1e3),
                    format!("{:.4}", b.c * 1e3),
                    format!(
                        "{:.4}",
                        crate::model::board::max_bend(t, &b, &c.state.higher_bends[v.frame]) * 1e3
                    ),
                ]);
            }
            row
        })
        .collect();
    format!(
        "<details><summary>{} views (camera × frame) in frame order</summary>\n{}</details>\n",
        rows.len(),
        page::table_html(&head, &rows)
    )
}

/// What the figures and numbers mean.
fn definitions() -> String {
    let items = [
        "Pixels: OpenCV's convention, integer coordinates are pixel centres and (0, 0) is the centre of the top-left pixel; u to the right, v down.",
        "Residual: observed − projected pixel of one corner, with the robust loss not applied. `rmse_px` = √(Σ‖u − p‖² / N) over the N observations (per point, as OpenCV reports).",
        "Noise σ̂ (`noise_px`): the detector noise per image coordinate, configured or estimated from the second differences of neighbouring corners' residuals. For a model without systematic error E[rmse²] = 2σ̂²(1 − p/N), with p free parameters and N = 2 × observations residuals.",
        "Bias ratio: max(0, rmse² − 2σ̂²(1 − p/N)) / rmse², the share of the residual the noise does not explain. G-AIC: Σ‖u − p‖² + 2pσ̂² (lower is better, same observations only).",
        "Board frame: origin at the board centre, x along increasing col, y along increasing row, z = x × y; corner i = row·cols + col.",
        "Bend: Δz = a·x² + b·y² + c·xy per frame; `max_out_of_plane_m` is the largest |Δz| over the corners.",
        "Distortion: pixel − pinhole image of the pixel's ray, the pinhole having the same fx, fy, cx, cy and no distortion.",
    ];
    let mut s = String::from("<ul>\n");
    for i in items {
        let _ = writeln!(s, "<li>{}</li>", page::inline(i));
    }
    s.push_str("</ul>\n");
    s
}
