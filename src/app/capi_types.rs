//! The C structs of `include/deformcal.h`, field for field (`#[repr(C)]`): what
//! `capi` reads and writes across the C interface.
use crate::model::lens::MAX_PARAMS;
use std::ffi::c_char;

/// `DcTarget`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct DcTarget {
    pub rows: u32,
    pub cols: u32,
    pub spacing: f64,
}

/// `DcCamera`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct DcCamera {
    pub name: *const c_char,
    pub width: u32,
    pub height: u32,
    pub model: *const c_char,
}

/// `DcObservation`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct DcObservation {
    pub camera: u32,
    pub frame: i64,
    pub corner: u32,
    pub u: f64,
    pub v: f64,
}

/// `DcOptions`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct DcOptions {
    pub method: *const c_char,
    pub robust: i32,
    pub loss_scale_px: f64,
    pub threads: i32,
    pub max_iterations: i32,
}

/// `DcCameraResult`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct DcCameraResult {
    pub num_params: u32,
    pub params: [f64; MAX_PARAMS],
    pub rotation: [f64; 3],
    pub translation: [f64; 3],
}

/// `DcResult`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct DcResult {
    pub rmse_px: f64,
    pub converged: i32,
    pub iterations: i32,
    pub observations: u64,
    pub frames: u64,
    pub max_out_of_plane_m: f64,
}

/// `DcTolerances`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct DcTolerances {
    pub function_tolerance: f64,
    pub parameter_tolerance: f64,
    pub gradient_tolerance: f64,
    pub max_rmse_px: f64,
}

/// `DcFrameResult`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct DcFrameResult {
    pub frame: i64,
    pub used: i32,
    pub rotation: [f64; 3],
    pub translation: [f64; 3],
    pub bend: [f64; 3],
    pub max_out_of_plane_m: f64,
    pub rmse_px: f64,
    pub observations: u64,
}
