//! The lens models by name: [`LensModel`], every model in [`LensModel::ALL`], and
//! what follows from a model's registry entry ([`LensModel::info`], `registry.rs`).
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

/// The largest parameter count of any lens model.
pub const MAX_PARAMS: usize = 12;

/// A lens model from the registry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub enum LensModel {
    /// The paper's model: OpenCV's with p1 = p2 = 0.
    #[default]
    Radial3,
    /// OpenCV's default five coefficients (ROS `plumb_bob`).
    OpenCv5,
    /// OpenCV's rational model (ROS `rational_polynomial`, mrcal `LENSMODEL_OPENCV8`).
    OpenCv8,
    /// Kannala-Brandt equidistant fisheye (OpenCV `fisheye`, Kalibr `pinhole-equi`).
    Kb4,
    /// Double sphere (Usenko et al. 2018), beyond 180°.
    DoubleSphere,
    /// A pinhole camera without distortion.
    Pinhole,
}

impl LensModel {
    /// Every registered model.
    pub const ALL: [LensModel; 6] = [
        LensModel::Radial3,
        LensModel::OpenCv5,
        LensModel::OpenCv8,
        LensModel::Kb4,
        LensModel::DoubleSphere,
        LensModel::Pinhole,
    ];

    /// The widest perspective and the widest fisheye model: what a calibration
    /// that fits badly is tried again with, to tell the user whether the lens
    /// model is the problem.
    pub const WIDEST: [LensModel; 2] = [LensModel::Kb4, LensModel::OpenCv8];

    /// The config name.
    pub fn name(self) -> &'static str {
        self.info().name
    }

    /// Parameter names in solver order.
    pub fn param_names(self) -> &'static [&'static str] {
        self.info().params
    }

    /// Number of parameters.
    pub fn num_params(self) -> usize {
        self.info().params.len()
    }

    /// The model of a config name.
    pub fn parse(name: &str) -> Option<LensModel> {
        LensModel::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Every model's name, for messages.
    pub fn names() -> String {
        LensModel::ALL.map(LensModel::name).join(", ")
    }

    /// Index of a parameter name.
    pub fn param_index(self, name: &str) -> Option<usize> {
        self.param_names().iter().position(|p| *p == name)
    }

    /// One line per model for a `--model` help: its name, its parameters and
    /// what it is.
    pub fn help_lines() -> Vec<String> {
        let width = LensModel::ALL.map(|m| m.name().len()).into_iter().max();
        LensModel::ALL
            .into_iter()
            .map(|m| {
                let info = m.info();
                format!(
                    "{:width$}  {}: {}",
                    info.name,
                    info.params.join(" "),
                    info.help,
                    width = width.unwrap_or(0)
                )
            })
            .collect()
    }

    /// The model whose parameters mrcal's model of this one has, in mrcal's order:
    /// itself where mrcal has it, the model it is a special case of otherwise
    /// (`LensInfo::mrcal_via`), `None` where mrcal has no such model.
    pub fn mrcal_equivalent(self) -> Option<LensModel> {
        match self.info().mrcal {
            Some(_) => Some(self),
            None => self.info().mrcal_via,
        }
    }
}

impl fmt::Display for LensModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl Serialize for LensModel {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for LensModel {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        LensModel::parse(&name).ok_or_else(|| {
            serde::de::Error::custom(format!(
                "unknown lens model `{name}`; expected one of {}",
                LensModel::names()
            ))
        })
    }
}
