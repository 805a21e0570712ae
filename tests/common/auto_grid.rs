//! The grid `method = "auto"` is judged on: synthetic boards that are rigid, bend
//! as paraboloids or beyond them (cubic, quartic, twist), or twist, with and without print
//! error, at several frame counts, noise levels and lens models. For each case
//! `auto`'s own fit of every candidate to all the data is set against the true
//! lens, so the chosen method's mapping error can be set against the best
//! candidate's: the regret.
#![allow(dead_code)]
use deformcal::model::lens::LensModel;
use deformcal::model::metrics::{mapping_error, mapping_error_rot};
use deformcal::model::selection::AutoSettings;
use deformcal::model::synthetic::{BendShape, Generator, Preset};
use deformcal::solver::calibrate::SharedWarmStart;
use deformcal::solver::problem::SolverSettings;
use deformcal::solver::select::{trial, Trial};
use deformcal::{Calibration, Method, Request};

/// How the case's board deviates from the nominal one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Board {
    Rigid,
    /// The paper's paraboloid, this many mm at most on average.
    Paraboloid(f64),
    /// Cubic, quartic and twist terms on top (a plate bent unevenly), mm.
    Plate(f64),
    /// A twist about the board's centre with degree-4 twist terms, mm.
    Twist(f64),
}

impl Board {
    pub fn label(self) -> String {
        match self {
            Board::Rigid => "rigid".into(),
            Board::Paraboloid(mm) => format!("parab {mm} mm"),
            Board::Plate(mm) => format!("plate {mm} mm"),
            Board::Twist(mm) => format!("twist {mm} mm"),
        }
    }
}

#[derive(Debug, Clone, Copy)]
pub struct Case {
    pub board: Board,
    /// Static print error σ, in-plane and out-of-plane, mm.
    pub print_mm: f64,
    pub frames: usize,
    pub noise_px: f64,
    pub model: LensModel,
    pub seed: u64,
}

/// What one case gave.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub case: Case,
    pub chosen: Method,
    /// Mapping error to the true lens of every candidate, px, in `CANDIDATES` order.
    pub errors: Vec<f64>,
    pub reason: String,
    /// Every candidate's evidence, one JSON line (for a study of the rule).
    pub evidence: String,
}

pub const CANDIDATES: [Method; 3] = [Method::Standard, Method::Dynamic, Method::Full];

impl Outcome {
    pub fn error_of(&self, m: Method) -> f64 {
        self.errors[CANDIDATES.iter().position(|&c| c == m).unwrap()]
    }
    pub fn best(&self) -> (Method, f64) {
        CANDIDATES
            .iter()
            .zip(&self.errors)
            .map(|(&m, &e)| (m, e))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap()
    }
    /// The chosen method's mapping error over the best candidate's.
    pub fn regret(&self) -> f64 {
        self.error_of(self.chosen) / self.best().1
    }
}

/// Runs one case with the project's default settings (priors estimated).
pub fn run(case: Case) -> Outcome {
    run_with(case, false)
}

/// [`run`], or with the paper's prior-free model where `paper`.
pub fn run_with(case: Case, paper: bool) -> Outcome {
    let mut g = Generator::new(Preset::T2, Some(case.frames), case.seed).with_models(&[case.model]);
    match case.board {
        Board::Rigid => g.bend_scale = 0.0,
        Board::Paraboloid(mm) | Board::Plate(mm) | Board::Twist(mm) => {
            g.spec.bend_mean_m = mm * 1e-3;
            g.spec.bend_std_m = 0.3 * mm * 1e-3;
            g.spec.bend_shape = match case.board {
                Board::Plate(_) => BendShape::Warped,
                Board::Twist(_) => BendShape::Twisted,
                _ => BendShape::Paraboloid,
            };
        }
    }
    g.spec.print_sigma_xy_m = case.print_mm * 1e-3;
    g.spec.print_sigma_z_m = case.print_mm * 1e-3;
    g.noise_px = case.noise_px;
    let (dataset, truth) = g.generate();
    let settings = if paper {
        SolverSettings::default()
    } else {
        SolverSettings::recommended()
    };
    let request = Request {
        method: Method::Standard,
        settings,
        gauge: None,
    };
    let auto = AutoSettings {
        candidates: CANDIDATES.to_vec(),
        ..AutoSettings::default()
    };
    let warm = SharedWarmStart::default();
    let t = trial(&dataset, &request, &auto, &warm, &|| {})
        .unwrap_or_else(|e| panic!("{case:?}: auto failed: {e}"));
    let cam = &dataset.cameras[0];
    let error = |c: &Calibration| {
        mapping_error(
            &truth.intrinsics[0],
            &c.state.intrinsics[0],
            cam.width,
            cam.height,
        )
    };
    // `auto`'s own fits of every candidate to all the data, where it made them.
    let errors: Vec<f64> = CANDIDATES
        .iter()
        .map(|&m| match t.fits.iter().find(|(f, _)| *f == m) {
            Some((_, r)) => r.as_ref().map_or(f64::INFINITY, error),
            None => {
                let r = warm.calibrate(
                    &dataset,
                    &Request {
                        method: m,
                        ..request.clone()
                    },
                );
                r.map_or(f64::INFINITY, |c| error(&c))
            }
        })
        .collect();
    let sel = t.result.selection.clone().expect("auto records its choice");
    Outcome {
        case,
        chosen: t.result.method,
        evidence: evidence(&case, &t, &errors),
        errors,
        reason: sel.reason,
    }
}

/// One JSON line: the case, each candidate's truth error, noise, uncertainty,
/// trust figures and held-out record, and the mapping error between every two
/// candidates' lenses (plain and with the rotation removed), px.
fn evidence(case: &Case, t: &Trial, errors: &[f64]) -> String {
    let fit = |i: usize| t.fits.get(i).and_then(|(_, r)| r.as_ref().ok());
    let cand: Vec<serde_json::Value> = (0..t.fits.len())
        .map(|i| {
            let c = fit(i);
            let u = c.and_then(|c| c.uncertainty().ok());
            let tr = c.and_then(|c| c.trust(None));
            let h = t.held.get(i).cloned().flatten();
            serde_json::json!({
                "method": t.fits[i].0.name(),
                "e2": u.as_ref().map(|u| u.iter().map(|x| x.expected_mapping_error_px.powi(2)).sum::<f64>()),
                "e2_rot": u.as_ref().map(|u| u.iter().map(|x| x.expected_mapping_error_rot_px.powi(2)).sum::<f64>()),
                "noise": tr.map(|t| t.noise_px),
                "bias": tr.map(|t| t.bias_ratio),
                "g_aic": tr.map(|t| t.g_aic),
                "rmse": c.map(|c| c.rmse_px),
                "params": c.map(|c| c.free_parameters()),
                "cv_sq": h.as_ref().map(|h| h.squared.clone()),
                "cv_n": h.as_ref().map(|h| h.points.clone()),
            })
        })
        .collect();
    let shift = |rot: bool| -> Vec<Vec<Option<f64>>> {
        (0..t.fits.len())
            .map(|i| {
                (0..t.fits.len())
                    .map(|j| {
                        let (a, b) = (fit(i)?, fit(j)?);
                        let cams = a.dataset.cameras.iter();
                        let pairs = cams.zip(a.state.intrinsics.iter().zip(&b.state.intrinsics));
                        Some(
                            pairs
                                .map(|(cam, (x, y))| {
                                    let e = if rot {
                                        mapping_error_rot(x, y, cam.width, cam.height)
                                    } else {
                                        mapping_error(x, y, cam.width, cam.height)
                                    };
                                    e * e
                                })
                                .sum::<f64>()
                                .sqrt(),
                        )
                    })
                    .collect()
            })
            .collect()
    };
    serde_json::json!({
        "board": case.board.label(),
        "print_mm": case.print_mm,
        "frames": case.frames,
        "noise_px": case.noise_px,
        "model": format!("{:?}", case.model),
        "seed": case.seed,
        "chosen": t.result.method.name(),
        "errors": errors,
        "candidates": cand,
        "shift": shift(false),
        "shift_rot": shift(true),
    })
    .to_string()
}

/// The targets' verdicts on a set of outcomes, one line each where one fails.
pub fn failures(outcomes: &[Outcome]) -> Vec<String> {
    let mut out = Vec::new();
    for o in outcomes {
        let std = o.error_of(Method::Standard);
        let (best_m, best) = o.best();
        let chosen = o.error_of(o.chosen);
        let what = format!(
            "{:?} chose {} ({:.3} px; standard {:.3}, best {} {:.3})",
            o.case, o.chosen, chosen, std, best_m, best
        );
        if o.regret() > 1.3 {
            out.push(format!("regret {:.2} > 1.3: {what}", o.regret()));
        }
        if o.case.board == Board::Rigid && o.case.print_mm == 0.0 && chosen > 1.1 * std {
            out.push(format!(
                "rigid board, more than 10 % worse than standard: {what}"
            ));
        }
        if o.chosen == Method::Standard && std > 2.0 * best {
            out.push(format!(
                "standard where it is 2x worse than the best: {what}"
            ));
        }
    }
    out
}

/// The confusion matrix (best candidate × chosen) and the regret's median and
/// worst, as text.
pub fn table(outcomes: &[Outcome]) -> String {
    let mut s = String::from("best \\ chosen   standard  dynamic  full\n");
    for best in CANDIDATES {
        let row: Vec<usize> = CANDIDATES
            .iter()
            .map(|&c| {
                outcomes
                    .iter()
                    .filter(|o| o.best().0 == best && o.chosen == c)
                    .count()
            })
            .collect();
        s += &format!(
            "{:<15} {:>8} {:>8} {:>5}\n",
            best.name(),
            row[0],
            row[1],
            row[2]
        );
    }
    let mut r: Vec<f64> = outcomes.iter().map(Outcome::regret).collect();
    r.sort_by(f64::total_cmp);
    if !r.is_empty() {
        s += &format!(
            "regret over {} cases: median {:.3}, 90th percentile {:.3}, worst {:.3}\n",
            r.len(),
            r[r.len() / 2],
            r[(r.len() * 9 / 10).min(r.len() - 1)],
            r[r.len() - 1]
        );
    }
    s
}
