//! Board-health diagnostics of a calibration: each frame's largest bend and
//! RMSE, and the frames flagged because their bend exceeds the configured limit
//! or their residuals are far above the other frames'. Reads a finished
//! calibration only; the summary and the report (app layer) show what it finds.
use crate::solver::calibrate::Calibration;

/// Default of `[calibration] max_bend_mm`, metres.
pub const DEFAULT_MAX_BEND_M: f64 = 5e-3;
/// A frame whose RMSE exceeds this many times the median frame's is flagged.
pub const RMSE_FACTOR: f64 = 3.0;

/// One frame's figures.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FrameHealth {
    /// The user's frame id.
    pub frame: i64,
    /// Largest |Δz| of its bend over the corners, metres (0 without a bend).
    pub max_bend_m: f64,
    /// RMSE of its observations (all cameras), pixels.
    pub rmse_px: f64,
    /// Why it is flagged (empty when it is not).
    pub flags: Vec<String>,
}

/// Every frame's figures and the thresholds that flagged some.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BoardHealth {
    pub max_bend_m: f64,
    pub median_rmse_px: f64,
    pub frames: Vec<FrameHealth>,
}

impl BoardHealth {
    /// The flagged frames.
    pub fn flagged(&self) -> impl Iterator<Item = &FrameHealth> {
        self.frames.iter().filter(|f| !f.flags.is_empty())
    }
}

/// The board health of a calibration, with bends over `max_bend_m` flagged
/// (`None`: [`DEFAULT_MAX_BEND_M`]).
pub fn board_health(c: &Calibration, max_bend_m: Option<f64>) -> BoardHealth {
    let limit = max_bend_m.unwrap_or(DEFAULT_MAX_BEND_M);
    let n = c.dataset.num_frames();
    let (mut sq, mut count) = (vec![0.0; n], vec![0usize; n]);
    for (o, r) in c
        .dataset
        .observations
        .iter()
        .zip(c.residuals.chunks_exact(2))
    {
        sq[o.frame] += r[0] * r[0] + r[1] * r[1];
        count[o.frame] += 1;
    }
    let rmse: Vec<f64> = (0..n)
        .map(|j| (sq[j] / count[j].max(1) as f64).sqrt())
        .collect();
    let mut sorted = rmse.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted.get(n / 2).copied().unwrap_or(f64::NAN);
    let bends = c.frame_bends();
    let frames = (0..n)
        .map(|j| {
            let mut flags = Vec::new();
            if bends[j] > limit {
                flags.push(format!(
                    "bend {:.2} mm over max_bend_mm {:.2}",
                    bends[j] * 1e3,
                    limit * 1e3
                ));
            }
            if rmse[j] > RMSE_FACTOR * median {
                flags.push(format!(
                    "RMSE {:.3} px over {RMSE_FACTOR}× the median frame's {median:.3} px",
                    rmse[j]
                ));
            }
            FrameHealth {
                frame: c.dataset.frame_ids[j],
                max_bend_m: bends[j],
                rmse_px: rmse[j],
                flags,
            }
        })
        .collect();
    BoardHealth {
        max_bend_m: limit,
        median_rmse_px: median,
        frames,
    }
}
