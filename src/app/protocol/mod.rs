//! The evaluation protocol (docs/conventions.md §3–4, the paper's section 4): reference calibration,
//! reproducible subsets, every subset × method calibrated and measured, in parallel,
//! sharded if asked.
//!
//! `plan` loads the data and draws the subsets, `run` calibrates the reference
//! and every task, `refit` measures the test error, `record` holds what a run
//! writes, `shard` splits the task grid and merges the pieces.
mod plan;
mod record;
mod refit;
mod run;
mod shard;

pub use crate::app::config::MAX_SUBSETS;
pub use plan::{draw_subsets, plan, prepare, sfm_for_config};
pub use record::{
    data_fingerprint, AutoRun, CameraRow, Header, ReferenceInfo, Row, Task, REFERENCE_BOARD_JSON,
};
pub use refit::{test_rmse, TestError};
pub use run::{sfm_experiment, Plan, Setup};
pub use shard::{merge, merge_named, parse_shard, read_shard, Shard, ShardFile};
