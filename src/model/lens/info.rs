//! What the registry knows of a lens model ([`LensInfo`]) and the forms in which
//! the tools around deformcal hold it. Pure data: each model's file fills one.
use super::intrinsics::Intrinsics;
use super::model::LensModel;
use super::projection::Projection;

/// OpenCV's form of a model: `calibrateCamera`'s distortion vector (k1 k2 p1 p2
/// k3 [k4 k5 k6]) or `cv::fisheye`'s (k1 k2 k3 k4).
#[derive(Debug, Clone, Copy)]
pub struct OpenCvForm {
    /// opencv.yaml's `distortion_model`: `plumb_bob`, `rational_polynomial` or `fisheye`.
    pub distortion_model: &'static str,
    /// The coefficients in OpenCV's order, by our parameter names; a name the model
    /// lacks is written as 0 (radial3's p1 and p2).
    pub coefficients: &'static [&'static str],
    /// `cv::fisheye` rather than `calibrateCamera`: no `stereoRectify`.
    pub fisheye: bool,
}

/// Kalibr's form of a model in `camchain.yaml`.
#[derive(Debug, Clone, Copy)]
pub struct KalibrForm {
    /// Kalibr's name of the model, for messages: `pinhole-radtan`, `ds-none`, ….
    pub name: &'static str,
    /// `camera_model`: `pinhole` or `ds`.
    pub camera_model: &'static str,
    /// `intrinsics`, by our parameter names in Kalibr's order.
    pub intrinsics: &'static [&'static str],
    /// `distortion_model`: `radtan`, `equidistant` or `none`.
    pub distortion_model: &'static str,
    /// `distortion_coeffs`, by our parameter names (a name the model lacks is 0).
    pub coefficients: &'static [&'static str],
    /// Parameters Kalibr's model lacks: the camera is written only where they are
    /// exactly 0.
    pub requires_zero: &'static [&'static str],
}

/// One of COLMAP's models that can hold a lens model in `cameras.txt`.
#[derive(Debug, Clone, Copy)]
pub struct ColmapForm {
    /// COLMAP's model name: `PINHOLE`, `OPENCV`, `FULL_OPENCV`, `OPENCV_FISHEYE`.
    pub model: &'static str,
    /// The parameters after fx fy cx cy, by our names (a name the model lacks is 0).
    pub params: &'static [&'static str],
    /// Parameters the COLMAP model lacks: it holds the camera only where they are 0.
    pub requires_zero: &'static [&'static str],
}

/// What the registry knows of a lens model: everything generic code needs, so
/// that no model is named outside its own file.
#[derive(Debug, Clone, Copy)]
pub struct LensInfo {
    /// The config's `model` name, also the C++ model's `kName`.
    pub name: &'static str,
    /// Parameter names in solver order, fx fy cx cy first; `calibration.json` keys.
    pub params: &'static [&'static str],
    /// What the model is, in a few words (the CLI's `--model` help).
    pub help: &'static str,
    /// A pinhole image with distortion around it (Zhang's initialisation
    /// applies): exactly the models whose `projection` is `PinholeLike`.
    pub pinhole_like: bool,
    /// Projection and unprojection in normalised image coordinates.
    pub projection: Projection,
    /// The parameters after fx fy cx cy of a lens without distortion (zeros, or
    /// for `ds` a stereographic lens): the initialisation's start.
    pub undistorted: &'static [f64],
    /// The simulated camera's true parameters under this model (`model::synthetic`).
    pub synthetic: &'static [f64],
    /// Parameters the lens prior (`[calibration] lens_prior`) pulls towards zero:
    /// those the data leave nearly free, such as the rational model's denominator,
    /// which trades off against its numerator over the range the corners cover.
    pub prior_params: &'static [&'static str],
    /// A second start for the first solve, for a model whose cost has two basins
    /// that the initialisation cannot tell apart; the calibration keeps the start
    /// that ends at the lower cost (`solver::calibrate`).
    pub second_start: Option<fn(&Intrinsics) -> Intrinsics>,
    /// OpenCV's form (opencv.yaml; also ROS's coefficients and `stereoRectify`).
    pub opencv: Option<OpenCvForm>,
    /// ROS `distortion_model`, where ROS has the model.
    pub ros: Option<&'static str>,
    /// Kalibr's form, where Kalibr has the model.
    pub kalibr: Option<KalibrForm>,
    /// COLMAP's models that can hold this one, tried in order.
    pub colmap: &'static [ColmapForm],
    /// mrcal's lens model, where mrcal has it.
    pub mrcal: Option<&'static str>,
    /// Where mrcal lacks the model but has one that holds it exactly with some
    /// parameters at 0 (radial3 is opencv5 with p1 = p2 = 0): that model.
    pub mrcal_via: Option<LensModel>,
}
