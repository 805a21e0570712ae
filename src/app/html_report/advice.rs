//! The report's "Where to hold the board next" section: per camera, the picture
//! and the three poses of `app::advise`, from the covariance the calibration
//! already holds (nothing is solved again). Only this section is built here.
use crate::app::advise::{self, Advice};
use crate::app::html_report::page::{self, para};
use crate::solver::calibrate::Calibration;

/// The section's body: per camera, the advice picture and a table of the poses.
pub fn advice_section(c: &Calibration) -> String {
    let mut s = para(
        "Three board poses that would lower the expected mapping error most, each given \
         the ones before it, predicted from this calibration's covariance by adding each \
         candidate view's information (candidates over image positions, two distances and \
         tilts of 35°; the board taken rigid). The map is the projection uncertainty now. \
         `deformcal advise` gives the same from the command line.",
    );
    for (k, cam) in c.dataset.cameras.iter().enumerate() {
        let advice = advise::knowledge_of(c, k).and_then(|kn| Some((advise::advise(&kn, 3)?, kn)));
        let Some((advice, kn)) = advice else {
            s.push_str(&para(&format!(
                "No advice for `{}`: the calibration has no covariance or no noise estimate.",
                cam.name
            )));
            continue;
        };
        let svg = advise::svg(&kn, &advice);
        s.push_str(&format!(
            "<figure>{}<figcaption>{}</figcaption></figure>\n",
            page::svg_image_html(svg.as_bytes(), &format!("where to hold the board next, {}", cam.name)),
            page::inline(&format!(
                "`{}`: projection uncertainty now (σ, px) with the advised boards' outlines, numbered.",
                cam.name
            ))
        ));
        s.push_str(&poses_table(&advice));
    }
    s
}

/// One row per advised pose: where the board's centre falls, how far and how
/// tilted it is, and the expected mapping error after adding it.
fn poses_table(a: &Advice) -> String {
    let head: Vec<String> = [
        "pose",
        "board centre (px)",
        "distance (m)",
        "tilt (°)",
        "corners in view",
        "expected mapping error after (px)",
    ]
    .iter()
    .map(|h| h.to_string())
    .collect();
    let mut rows = vec![vec![
        "now".to_string(),
        String::new(),
        String::new(),
        String::new(),
        String::new(),
        format!("{:.3}", a.current_error_px),
    ]];
    for (i, p) in a.poses.iter().enumerate() {
        let c = p
            .outline
            .iter()
            .fold([0.0, 0.0], |s, q| [s[0] + q[0] / 4.0, s[1] + q[1] / 4.0]);
        let t = p.camera_from_board.translation;
        let tilt = nalgebra::Vector3::from(p.camera_from_board.rotation)
            .norm()
            .to_degrees();
        rows.push(vec![
            format!("{}", i + 1),
            format!("({:.0}, {:.0})", c[0], c[1]),
            format!("{:.2}", (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt()),
            format!("{tilt:.0}"),
            p.corners_in_view.to_string(),
            format!("{:.3}", p.predicted_error_px),
        ]);
    }
    page::table_html(&head, &rows)
}
