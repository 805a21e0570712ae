//! The application layer: config, data files, photos and board detection, exports, the evaluation protocol,
//! reports and plots, and the C API. Builds on the model and solver layers.
pub mod board_json;
pub mod calibration_json;
pub mod capi;
pub mod capi_types;
pub mod compare;
pub mod config;
pub mod config_keys;
pub mod corners_vnl;
pub mod detect;
pub mod exports;
pub mod fsio;
pub mod guard;
pub mod html_report;
pub mod lint;
pub mod observations_csv;
pub mod output;
pub mod photos;
pub mod plots;
pub mod protocol;
pub mod protocol_report;
pub mod report;
pub mod sfm;
pub mod sfm_report;
pub mod source;
pub mod text;
pub mod uncertainty_plot;
