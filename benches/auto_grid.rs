//! `method = "auto"` over the evaluation grid: rigid, paraboloid and plate bends
//! of 0.5–5 mm, print error 0 and 0.2 mm, 12/25/40/100 frames, noise 0.1 and 0.3 px,
//! every lens model; prints the confusion matrix (best candidate × chosen) and the
//! regret (chosen method's mapping error to the true lens over the best
//! candidate's), and every case that misses a target. The rule has no threshold
//! fitted to data; the seeds here (100 + k) are used by no test.
//! `cargo bench --bench auto_grid` (about an hour on 2 cores);
//! `GRID=quick cargo bench --bench auto_grid` for a 25-frame slice.
#[path = "../tests/common/auto_grid.rs"]
mod grid;
use deformcal::model::lens::LensModel;
use grid::{Board, Case};
use rayon::prelude::*;

fn main() {
    let quick = std::env::var("GRID").is_ok_and(|v| v == "quick");
    let boards = [
        Board::Rigid,
        Board::Paraboloid(0.5),
        Board::Paraboloid(2.0),
        Board::Paraboloid(5.0),
        Board::Plate(1.0),
        Board::Plate(4.0),
    ];
    let frames: &[usize] = if quick { &[25] } else { &[12, 25, 40, 100] };
    let models = [
        LensModel::Radial3,
        LensModel::OpenCv5,
        LensModel::OpenCv8,
        LensModel::Kb4,
        LensModel::DoubleSphere,
    ];
    let seeds: u64 = if quick { 1 } else { 2 };
    let mut cases = Vec::new();
    for &board in &boards {
        for print_mm in [0.0, 0.2] {
            for &n in frames {
                for noise_px in [0.1, 0.3] {
                    for &model in &models {
                        for k in 0..seeds {
                            cases.push(Case {
                                board,
                                print_mm,
                                frames: n,
                                noise_px,
                                model,
                                seed: 100 + k,
                            });
                        }
                    }
                }
            }
        }
    }
    let bar = indicatif::ProgressBar::new(cases.len() as u64);
    let outcomes: Vec<grid::Outcome> = cases
        .par_iter()
        .map(|&c| {
            let o = grid::run(c);
            bar.inc(1);
            o
        })
        .collect();
    bar.finish_and_clear();
    println!(
        "auto over {} cases ({}):",
        outcomes.len(),
        if quick { "quick" } else { "full grid" }
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
        println!(
            "  {:<14} median regret {:.3}, worst {:.3}; chose standard {}, dynamic {}, full {}",
            board.label(),
            r[r.len() / 2],
            r[r.len() - 1],
            chose(deformcal::Method::Standard),
            chose(deformcal::Method::Dynamic),
            chose(deformcal::Method::Full)
        );
    }
    let failures = grid::failures(&outcomes);
    println!("{} case(s) miss a target", failures.len());
    for f in failures {
        println!("  {f}");
    }
}
