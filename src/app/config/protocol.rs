//! `[protocol]`: the evaluation protocol's settings (docs/conventions.md §4) and
//! their defaults; `auto` among the methods is a task of its own.
use crate::model::board::Method;
use crate::model::selection::MethodChoice;
use serde::Deserialize;

/// `[protocol]`: the evaluation protocol (docs/conventions.md §4).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(try_from = "RawProtocol")]
pub struct ProtocolConfig {
    pub subsets: usize,
    pub images_per_subset: usize,
    pub seed: u64,
    /// The fixed methods, each calibrated on every subset.
    pub methods: Vec<Method>,
    /// `"auto"` among the config's methods: every subset also records the method
    /// `auto` picks (with `[calibration]`'s candidates, folds and seed).
    pub auto: bool,
}

impl Default for ProtocolConfig {
    fn default() -> Self {
        ProtocolConfig {
            subsets: 50,
            images_per_subset: 25,
            seed: 7,
            methods: Method::ALL.to_vec(),
            auto: false,
        }
    }
}

/// `[protocol]` as written: `methods` may name `auto` beside the fixed methods.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawProtocol {
    pub(super) subsets: Option<usize>,
    pub(super) images_per_subset: Option<usize>,
    pub(super) seed: Option<u64>,
    pub(super) methods: Option<Vec<MethodChoice>>,
}

impl TryFrom<RawProtocol> for ProtocolConfig {
    type Error = String;

    fn try_from(r: RawProtocol) -> std::result::Result<Self, String> {
        let d = ProtocolConfig::default();
        let (methods, auto) = match r.methods {
            None => (d.methods, false),
            Some(choices) => {
                let autos = choices.iter().filter(|c| **c == MethodChoice::Auto).count();
                if autos > 1 {
                    return Err("protocol.methods lists `auto` twice".into());
                }
                let fixed = choices
                    .iter()
                    .filter_map(|c| match c {
                        MethodChoice::Fixed(m) => Some(*m),
                        MethodChoice::Auto => None,
                    })
                    .collect();
                (fixed, autos == 1)
            }
        };
        Ok(ProtocolConfig {
            subsets: r.subsets.unwrap_or(d.subsets),
            images_per_subset: r.images_per_subset.unwrap_or(d.images_per_subset),
            seed: r.seed.unwrap_or(d.seed),
            methods,
            auto,
        })
    }
}
