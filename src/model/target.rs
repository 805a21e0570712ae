//! The chessboard target and its nominal corner grid (SPEC §1).
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

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

    /// The SPEC's default gauge corners: 0, cols−1 and (rows−1)·cols.
    pub fn default_gauge(&self) -> [usize; 3] {
        [0, self.cols - 1, (self.rows - 1) * self.cols]
    }
}
