//! `method = "auto"` over the evaluation grid: rigid, paraboloid, plate and
//! twisted bends of 0.5–5 mm, print error 0 and 0.2 mm, 12/25/40/100 frames, noise 0.1 and 0.3 px,
//! every lens model; prints the confusion matrix (best candidate × chosen) and the
//! regret (chosen method's mapping error to the true lens over the best
//! candidate's), and every case that misses a target. The seeds here (100 and
//! 200) are used neither by a test nor to fit the rule's thresholds (seeds 1-3).
//! `cargo bench --bench auto_grid` (the whole grid, hours on 2 cores);
//! `GRID=quick` for a 25-frame slice (one seed), `GRID=medium` for 12/25/40 frames;
//! `PRIORS=none` runs every candidate with the paper's prior-free model instead of
//! the default priors, for comparison. `SEEDS=1,2,3` and `FRAMES=12,25` override
//! the grid's seeds and frame counts; `EVIDENCE=path` appends every case's
//! evidence (one JSON line) to `path`.
#[path = "../tests/common/auto_grid.rs"]
mod grid;
use deformcal::model::lens::LensModel;
use grid::{Board, Case};
use rayon::prelude::*;

/// A comma-separated list from the environment variable `name`, or `default`.
fn list<T: std::str::FromStr + Copy>(name: &str, default: &[T]) -> Vec<T> {
    match std::env::var(name) {
        Ok(v) if !v.is_empty() => v
            .split(',')
            .map(|x| {
                x.trim()
                    .parse()
                    .unwrap_or_else(|_| panic!("{name}: cannot read `{x}`"))
            })
            .collect(),
        _ => default.to_vec(),
    }
}

fn main() {
    let grid_kind = std::env::var("GRID").unwrap_or_default();
    let paper = std::env::var("PRIORS").is_ok_and(|v| v == "none");
    let boards = [
        Board::Rigid,
        Board::Paraboloid(0.5),
        Board::Paraboloid(2.0),
        Board::Paraboloid(5.0),
        Board::Plate(1.0),
        Board::Plate(4.0),
        Board::Twist(1.0),
        Board::Twist(4.0),
    ];
    let frames: Vec<usize> = list(
        "FRAMES",
        match grid_kind.as_str() {
            "quick" => &[25],
            "medium" => &[12, 25, 40],
            _ => &[12, 25, 40, 100],
        },
    );
    let models = [
        LensModel::Radial3,
        LensModel::OpenCv5,
        LensModel::OpenCv8,
        LensModel::Kb4,
        LensModel::DoubleSphere,
    ];
    let seeds: Vec<u64> = list(
        "SEEDS",
        if grid_kind.is_empty() {
            &[100, 200]
        } else {
            &[100]
        },
    );
    let mut cases = Vec::new();
    for &board in &boards {
        for print_mm in [0.0, 0.2] {
            for &n in &frames {
                for noise_px in [0.1, 0.3] {
                    for &model in &models {
                        for &seed in &seeds {
                            cases.push(Case {
                                board,
                                print_mm,
                                frames: n,
                                noise_px,
                                model,
                                seed,
                            });
                        }
                    }
                }
            }
        }
    }
    // Cheap cases first, so that a run cut short has whole slices.
    cases.sort_by_key(|c| c.frames);
    // EVIDENCE=path: every case's evidence, one JSON line each, as it finishes.
    let evidence = std::env::var("EVIDENCE").ok().map(|p| {
        std::sync::Mutex::new(
            std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&p)
                .unwrap_or_else(|e| panic!("EVIDENCE={p}: {e}")),
        )
    });
    let bar = indicatif::ProgressBar::new(cases.len() as u64);
    let outcomes: Vec<grid::Outcome> = cases
        .par_iter()
        .map(|&c| {
            let o = grid::run_with(c, paper);
            if let Some(f) = &evidence {
                use std::io::Write;
                let mut f = f.lock().unwrap_or_else(|e| e.into_inner());
                writeln!(f, "{}", o.evidence).expect("EVIDENCE is writable");
            }
            bar.inc(1);
            o
        })
        .collect();
    bar.finish_and_clear();
    println!(
        "auto over {} cases ({}, {}):",
        outcomes.len(),
        if grid_kind.is_empty() {
            "full grid"
        } else {
            grid_kind.as_str()
        },
        if paper {
            "the paper's prior-free model"
        } else {
            "default priors"
        }
    );
    print!("{}", grid::table(&outcomes));
    for board in boards {
        let of: Vec<grid::Outcome> = outcomes
            .iter()
            .filter(|o| o.case.board == board)
            .cloned()
            .collect();
        let mut r: Vec<f64> = of.iter().map(grid::Outcome::regret).collect();
        r.sort_by(f64::total_cmp);
        let chose = |m| of.iter().filter(|o| o.chosen == m).count();
        // Geometric means: the errors span orders of magnitude across lens models.
        let mean = |f: &dyn Fn(&grid::Outcome) -> f64| {
            (of.iter().map(|o| f(o).ln()).sum::<f64>() / of.len() as f64).exp()
        };
        use deformcal::Method::{Dynamic, Full, Standard};
        println!(
            "  {:<14} median regret {:.3}, worst {:.3}; chose standard {}, dynamic {}, full {}; \
             geometric mean error px: standard {:.3}, dynamic {:.3}, full {:.3}, auto {:.3}",
            board.label(),
            r[r.len() / 2],
            r[r.len() - 1],
            chose(Standard),
            chose(Dynamic),
            chose(Full),
            mean(&|o| o.error_of(Standard)),
            mean(&|o| o.error_of(Dynamic)),
            mean(&|o| o.error_of(Full)),
            mean(&|o| o.error_of(o.chosen)),
        );
    }
    let failures = grid::failures(&outcomes);
    println!("{} case(s) miss a target", failures.len());
    for f in failures {
        println!("  {f}");
    }
}
