//! The application layer: config, data files, photos and board detection, exports, the evaluation protocol,
//! reports and plots, and the C API. Builds on the model and solver layers.
pub mod calibration_json;
pub mod capi;
pub mod config;
pub mod corners_vnl;
pub mod detect;
pub mod exports;
pub mod fsio;
pub mod html_report;
pub mod observations_csv;
pub mod output;
pub mod photos;
pub mod plots;
pub mod protocol;
pub mod protocol_report;
pub mod report;
pub mod source;
