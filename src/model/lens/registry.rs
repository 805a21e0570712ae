//! The registry entry of every lens model: the one `match` on the model, each
//! arm the `INFO` of the model's own file.
use super::info::LensInfo;
use super::model::LensModel;
use super::{ds, kb4, opencv5, opencv8, pinhole, radial3};

impl LensModel {
    /// The registry entry: the one match on the model, each arm the model's own file.
    pub fn info(self) -> &'static LensInfo {
        match self {
            LensModel::Radial3 => &radial3::INFO,
            LensModel::OpenCv5 => &opencv5::INFO,
            LensModel::OpenCv8 => &opencv8::INFO,
            LensModel::Kb4 => &kb4::INFO,
            LensModel::DoubleSphere => &ds::INFO,
            LensModel::Pinhole => &pinhole::INFO,
        }
    }
}
