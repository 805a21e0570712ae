//! The grid `method = "auto"` is judged on: synthetic boards that are rigid, bend
//! as paraboloids or beyond them (cubic, quartic, twist), with and without print
//! error, at several frame counts, noise levels and lens models. For each case
//! every candidate is calibrated on its own (what `auto` computes, by the same
//! code), so the chosen method's mapping error to the true lens can be set
//! against the best candidate's: the regret.
#![allow(dead_code)]
use deformcal::model::lens::LensModel;
use deformcal::model::metrics::mapping_error;
use deformcal::model::selection::AutoSettings;
use deformcal::model::synthetic::{BendShape, Generator, Preset};
use deformcal::solver::problem::SolverSettings;
use deformcal::solver::select::calibrate_auto;
use deformcal::{calibrate, Method, Request};

/// How the case's board deviates from the nominal one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Board {
    Rigid,
    /// The paper's paraboloid, this many mm at most on average.
    Paraboloid(f64),
    /// Cubic, quartic and twist terms on top (a plate bent unevenly), mm.
    Plate(f64),
}

impl Board {
    pub fn label(self) -> String {
        match self {
            Board::Rigid => "rigid".into(),
            Board::Paraboloid(mm) => format!("parab {mm} mm"),
            Board::Plate(mm) => format!("plate {mm} mm"),
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
        Board::Paraboloid(mm) | Board::Plate(mm) => {
            g.spec.bend_mean_m = mm * 1e-3;
            g.spec.bend_std_m = 0.3 * mm * 1e-3;
            if let Board::Plate(_) = case.board {
                g.spec.bend_shape = BendShape::Warped;
            }
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
    let request = |method| Request {
        method,
        settings: settings.clone(),
        gauge: None,
    };
    let cam = &dataset.cameras[0];
    let error = |c: &deformcal::Calibration| {
        mapping_error(
            &truth.intrinsics[0],
            &c.state.intrinsics[0],
            cam.width,
            cam.height,
        )
    };
    let errors = CANDIDATES
        .iter()
        .map(|&m| calibrate(&dataset, &request(m)).map_or(f64::INFINITY, |c| error(&c)))
        .collect();
    let auto = AutoSettings {
        candidates: CANDIDATES.to_vec(),
        ..AutoSettings::default()
    };
    let c = calibrate_auto(&dataset, &request(Method::Standard), &auto, &|| {})
        .unwrap_or_else(|e| panic!("{case:?}: auto failed: {e}"));
    let sel = c.selection.clone().expect("auto records its choice");
    Outcome {
        case,
        chosen: c.method,
        errors,
        reason: sel.reason,
    }
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
