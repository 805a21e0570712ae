//! The chessboard target and its nominal corner grid (docs/conventions.md §1).
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// The plausible corner spacing, metres: 0.1 mm to 10 m. Outside it the board
/// is in the wrong units (millimetres given as metres gives 1000× the board)
/// and the solve is badly scaled: at 1e11 m the translations dwarf every other
/// parameter and Ceres stopped far from the optimum (RMSE 1.05 px for 0.21).
pub const SPACING_RANGE_M: (f64, f64) = (1e-4, 10.0);

/// Why `spacing` (metres) cannot be a board's, as the end of a sentence that
/// starts with the key; `None` when it is in [`SPACING_RANGE_M`].
pub fn spacing_problem(spacing: f64) -> Option<String> {
    let (lo, hi) = SPACING_RANGE_M;
    (!(lo..=hi).contains(&spacing)).then(|| {
        // Exponent form where plain digits would run long (1e11, 1e-300).
        let got = if spacing != 0.0 && spacing.is_finite() && !(1e-5..1e6).contains(&spacing.abs())
        {
            format!("{spacing:e}")
        } else {
            format!("{spacing}")
        };
        format!("must be a length in metres from {lo} to {hi} (got {got}); millimetres must be converted")
    })
}

/// A board of `rows × cols` inner corners, `spacing` metres apart.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Target {
    pub rows: usize,
    pub cols: usize,
    pub spacing: f64,
}

impl Target {
    /// Number of corners.
    pub fn num_corners(&self) -> usize {
        self.rows * self.cols
    }

    /// Nominal corner `i = row·cols + col`, origin at the board centre.
    pub fn nominal(&self, i: usize) -> Vector3<f64> {
        let (row, col) = (i / self.cols, i % self.cols);
        Vector3::new(
            (col as f64 - (self.cols as f64 - 1.0) / 2.0) * self.spacing,
            (row as f64 - (self.rows as f64 - 1.0) / 2.0) * self.spacing,
            0.0,
        )
    }

    /// All nominal corners in index order.
    pub fn nominal_points(&self) -> Vec<Vector3<f64>> {
        (0..self.num_corners()).map(|i| self.nominal(i)).collect()
    }

    /// The default (docs/conventions.md §2) gauge corners: 0, cols−1 and (rows−1)·cols.
    pub fn default_gauge(&self) -> [usize; 3] {
        [0, self.cols - 1, (self.rows - 1) * self.cols]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The range's ends are accepted; beyond them, and non-numbers, refused
    /// with the value readable.
    #[test]
    fn spacing_outside_its_range_is_named() {
        for ok in [1e-4, 0.07, 10.0] {
            assert_eq!(spacing_problem(ok), None, "{ok}");
        }
        for (bad, shown) in [
            (1e11, "got 1e11"),
            (1e-300, "got 1e-300"),
            (0.0, "got 0"),
            (-0.07, "got -0.07"),
            (70.0, "got 70"),
            (f64::NAN, "got NaN"),
            (f64::INFINITY, "got inf"),
        ] {
            let m = spacing_problem(bad).unwrap_or_else(|| panic!("{bad} accepted"));
            assert!(m.contains(shown) && m.contains("0.0001 to 10"), "{m}");
        }
    }
}
