//! Whether a method's unknowns can be determined from the data at all, by
//! counting: refused before a solve when the residuals (two per corner, plus
//! one per prior value) do not outnumber the unknowns, overall or within a
//! frame. An under-determined least-squares problem still "converges": Ceres'
//! damping picks one of the many exact fits, the RMSE drops below the noise and
//! the intrinsics are whatever that fit needed (30 views of 4 corners each gave
//! `dynamic` a k3 of 4.7 for a true −0.05). Counting is necessary, not
//! sufficient: degenerate geometry is left to the other checks.
use crate::error::{Error, Result};
use crate::model::board::Method;
use crate::model::dataset::Dataset;
use crate::solver::problem::SolverSettings;

/// The unknowns and residuals of one problem, by where they come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Count {
    /// Free lens parameters of all cameras (`fix`ed ones excluded).
    pub lens: usize,
    /// Camera-from-camera-0 poses of the other cameras.
    pub rig: usize,
    /// Board poses and bends of all frames.
    pub frames: usize,
    /// Per-corner corrections, frozen corners and the gauge excluded.
    pub corrections: usize,
    /// Two per observation.
    pub observed: usize,
    /// One per value a prior with a given σ holds (lens, bend, static).
    pub priors: usize,
}

impl Count {
    /// All unknowns.
    pub fn unknowns(&self) -> usize {
        self.lens + self.rig + self.frames + self.corrections
    }

    /// All residuals.
    pub fn residuals(&self) -> usize {
        self.observed + self.priors
    }
}

/// The count of `method` on `dataset` with `frozen` corners keeping their
/// correction. A prior counts only with a σ given: an `"auto"` one is first
/// solved without (`calibrate::with_auto_priors`), and the smoothness prior may
/// be dropped by its order test, so neither can be relied on to determine a bend.
pub fn count(
    dataset: &Dataset,
    method: Method,
    settings: &SolverSettings,
    frozen: &[usize],
) -> Count {
    let info = method.info();
    let b = &settings.board;
    let mut lens = 0;
    let mut priors = 0;
    for cam in &dataset.cameras {
        let names = cam.model.param_names();
        let held = cam.held();
        lens += held.iter().filter(|h| !**h).count();
        if settings.lens_prior_sigma.is_some() {
            let prior = cam.model.info().prior_params;
            priors += names
                .iter()
                .zip(&held)
                .filter(|(n, h)| !**h && prior.contains(n))
                .count();
        }
    }
    let frames = dataset.num_frames();
    if info.frame_params > 0 && b.bend_sigma_m.is_some() {
        priors += info.frame_params * frames;
    }
    let corrections = if info.corner_params == 0 {
        0
    } else {
        let free = free_corners(dataset, frozen);
        if b.static_sigma_m.is_some() || b.geometry.is_some() {
            priors += info.corner_params * free;
        }
        (info.corner_params * free).saturating_sub(info.gauge_dof)
    };
    Count {
        lens,
        rig: 6 * dataset.cameras.len().saturating_sub(1),
        frames: (6 + info.frame_params) * frames,
        corrections,
        observed: 2 * dataset.observations.len(),
        priors,
    }
}

/// Corners observed at least once and not frozen.
fn free_corners(dataset: &Dataset, frozen: &[usize]) -> usize {
    let mut seen = vec![false; dataset.target.num_corners()];
    for o in &dataset.observations {
        if let Some(s) = seen.get_mut(o.corner) {
            *s = true;
        }
    }
    for &c in frozen {
        if let Some(s) = seen.get_mut(c) {
            *s = false;
        }
    }
    seen.iter().filter(|s| **s).count()
}

/// Refuses `method` on `dataset` when its unknowns cannot all be determined:
/// a frame whose own pose and bend are not outnumbered by its corners'
/// residuals (with a bend prior, by those and the prior's), or more unknowns
/// overall than residuals.
///
/// Refused rather than solved with a simpler method: the user (or the
/// protocol, which compares methods) asked for this one, and a silent switch
/// would deliver another method's result under its name; `auto` records the
/// refusal as the candidate's failure and picks among the others.
pub fn check(
    dataset: &Dataset,
    method: Method,
    settings: &SolverSettings,
    frozen: &[usize],
) -> Result<()> {
    let info = method.info();
    let remedy = if method == Method::Standard {
        "add images or corners per image"
    } else {
        "show more corners per image, or use method `standard` (6 unknowns per image)"
    };
    let own = 6 + info.frame_params;
    let bend_prior = if info.frame_params > 0 && settings.board.bend_sigma_m.is_some() {
        info.frame_params
    } else {
        0
    };
    let mut corners = vec![0usize; dataset.num_frames()];
    for o in &dataset.observations {
        corners[o.frame] += 1;
    }
    let short: Vec<usize> = (0..corners.len())
        .filter(|&j| 2 * corners[j] + bend_prior <= own)
        .collect();
    if let Some(&j) = short.first() {
        let need = (own - bend_prior) / 2 + 1;
        let others = match short.len() {
            1 => String::new(),
            n => format!(" (and {} other frame(s))", n - 1),
        };
        return Err(Error::Degenerate(format!(
            "frame {}{others} has {} corner(s): {} residuals for its {own} unknowns under `{method}` \
             (6 pose + {} bend), so its bend is not determined and the fit says nothing of the lens; \
             show at least {need} corners in each image, or use method `standard` (6 unknowns per image)",
            dataset.frame_ids[j],
            corners[j],
            2 * corners[j],
            info.frame_params,
        )));
    }
    let c = count(dataset, method, settings, frozen);
    if c.unknowns() >= c.residuals() {
        let mut parts = vec![format!("{} lens", c.lens)];
        if c.rig > 0 {
            parts.push(format!("{} rig", c.rig));
        }
        parts.push(format!(
            "{} pose{} of {} image(s)",
            c.frames,
            if info.frame_params > 0 {
                " and bend"
            } else {
                ""
            },
            dataset.num_frames()
        ));
        if c.corrections > 0 {
            parts.push(format!("{} corner correction", c.corrections));
        }
        let priors = if c.priors > 0 {
            format!(" and {} prior", c.priors)
        } else {
            String::new()
        };
        return Err(Error::Degenerate(format!(
            "`{method}` has {} unknowns ({}) but only {} residuals ({} corners × 2{priors}): \
             the fit would match the noise and its intrinsics would mean nothing; {remedy}",
            c.unknowns(),
            parts.join(", "),
            c.residuals(),
            dataset.observations.len(),
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::synthetic::{Generator, Preset};

    /// Keeps only the observations of the corners `keep` (a sparse detector's).
    fn sparse(d: &mut Dataset, keep: &[usize]) {
        d.observations.retain(|o| keep.contains(&o.corner));
    }

    /// The counts against the registry's sizes, worked by hand for a 13 × 13
    /// board seen at 4 corners in 10 frames, one radial3 camera.
    #[test]
    fn counts_follow_the_method_and_the_priors() {
        let (mut d, _) = Generator::new(Preset::T2, Some(10), 1).generate();
        d.observations
            .retain(|o| [70, 72, 96, 98].contains(&o.corner));
        let frames = d.num_frames();
        let n = d.observations.len();
        assert!(frames >= 8 && n >= 4 * 8, "{frames} frames, {n} corners");
        let s = SolverSettings::default();
        let standard = count(&d, Method::Standard, &s, &[]);
        assert_eq!(standard.lens, 7);
        assert_eq!(standard.frames, 6 * frames);
        assert_eq!(standard.observed, 2 * n);
        assert_eq!(standard.priors, 0, "radial3 has no lens prior");
        let full = count(&d, Method::Full, &s, &[70]);
        assert_eq!(full.frames, 9 * frames);
        assert_eq!(full.corrections, 2 * 3 - 4);
        let stat = count(&d, Method::Static, &s, &[]);
        assert_eq!(stat.corrections, 3 * 4 - 7);
        let mut with_prior = s.clone();
        with_prior.board.bend_sigma_m = Some(1e-3);
        assert_eq!(
            count(&d, Method::Dynamic, &with_prior, &[]).priors,
            3 * frames
        );
        with_prior.board.bend_sigma_auto = true;
        with_prior.board.bend_sigma_m = None;
        assert_eq!(count(&d, Method::Dynamic, &with_prior, &[]).priors, 0);
    }

    /// Four corners per image: 8 residuals for a bent frame's 9 unknowns is
    /// refused, naming the frame and the way out; a bend prior makes up the
    /// difference, and `standard` (6 per frame) is accepted.
    #[test]
    fn a_frame_with_fewer_residuals_than_unknowns_is_refused() {
        let (mut d, _) = Generator::new(Preset::T2, Some(10), 1).generate();
        sparse(&mut d, &[70, 72, 96, 98]);
        let s = SolverSettings::default();
        let e = check(&d, Method::Dynamic, &s, &[]).unwrap_err().to_string();
        assert!(
            e.contains(&format!("frame {} ", d.frame_ids[0]))
                && e.contains("8 residuals for its 9 unknowns")
                && e.contains("method `standard`")
                && e.contains("at least 5 corners in each image"),
            "{e}"
        );
        assert!(check(&d, Method::Standard, &s, &[]).is_ok());
        let mut prior = s.clone();
        prior.board.bend_sigma_m = Some(1e-3);
        assert!(check(&d, Method::Dynamic, &prior, &[]).is_ok());
    }

    /// Three images of four corners: 24 residuals for `standard`'s 7 + 18
    /// unknowns, refused with the figures; a fourth image (32 for 31) passes.
    #[test]
    fn more_unknowns_than_residuals_overall_is_refused() {
        let (d, _) = Generator::new(Preset::T2, Some(10), 1).generate();
        let mut d4 = d.subset(&[0, 1, 2, 3]);
        sparse(&mut d4, &[70, 72, 96, 98]);
        assert_eq!(
            d4.observations.len(),
            16,
            "the corners near the centre are seen"
        );
        let s = SolverSettings::default();
        assert!(check(&d4, Method::Standard, &s, &[]).is_ok());
        let d3 = d4.subset(&[0, 1, 2]);
        let e = check(&d3, Method::Standard, &s, &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("25 unknowns (7 lens, 18 pose of 3 image(s))")
                && e.contains("only 24 residuals (12 corners × 2)"),
            "{e}"
        );
    }
}
