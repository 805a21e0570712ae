//! The config's `[target]` section: which board (a chessboard, the default, or
//! a ChArUco board in OpenCV's layout), its sizes, and the checks that name the
//! key at fault. The rest of the config is `app::config`; what the board means
//! to the solver is `model::target`, how it is found in photos `app::detect`.

use crate::app::detect::charuco::CharucoSpec;
use crate::model::target::Target;
use serde::Deserialize;
use std::path::PathBuf;

/// The kind of board, `[target] type`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TargetType {
    /// A chessboard: `rows` × `cols` inner corners, `spacing` metres apart.
    #[default]
    Chessboard,
    /// A ChArUco board: `rows` × `cols` squares of `square` metres with
    /// markers of `marker` metres from `dictionary`.
    Charuco,
}

/// `[target]` as written, and optionally a measured board (`board.json`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetSection {
    #[serde(rename = "type", default)]
    pub kind: TargetType,
    pub rows: usize,
    pub cols: usize,
    /// A chessboard's corner spacing, metres.
    pub spacing: Option<f64>,
    /// A ChArUco board's square side, metres.
    pub square: Option<f64>,
    /// A ChArUco board's marker side, metres.
    pub marker: Option<f64>,
    /// A ChArUco board's marker dictionary, OpenCV's name.
    pub dictionary: Option<String>,
    pub geometry: Option<PathBuf>,
}

impl TargetSection {
    /// The board the solver sees (call [`TargetSection::check`] first).
    pub fn target(&self) -> Target {
        match self.charuco() {
            Some(c) => c.target(),
            None => Target {
                rows: self.rows,
                cols: self.cols,
                spacing: self.spacing.unwrap_or(f64::NAN),
            },
        }
    }

    /// The ChArUco board, for `type = "charuco"`.
    pub fn charuco(&self) -> Option<CharucoSpec> {
        (self.kind == TargetType::Charuco).then(|| CharucoSpec {
            rows: self.rows,
            cols: self.cols,
            square: self.square.unwrap_or(f64::NAN),
            marker: self.marker.unwrap_or(f64::NAN),
            dictionary: self.dictionary.clone().unwrap_or_default(),
        })
    }

    /// Which keys the board's type needs and refuses; a message that starts
    /// with `target.<key>` (the config names its line) or `[target]`.
    pub fn check(&self) -> Result<(), String> {
        let given = [
            ("spacing", self.spacing.is_some()),
            ("square", self.square.is_some()),
            ("marker", self.marker.is_some()),
            ("dictionary", self.dictionary.is_some()),
        ];
        let (needed, kind): (&[&str], &str) = match self.kind {
            TargetType::Chessboard => (&["spacing"], "chessboard"),
            TargetType::Charuco => (&["square", "marker", "dictionary"], "charuco"),
        };
        for (key, present) in given {
            if present && !needed.contains(&key) {
                return Err(format!(
                    "target.{key} does not apply to type = \"{kind}\" (it takes {})",
                    needed.join(", ")
                ));
            }
        }
        if let Some((key, _)) = given.iter().find(|(k, p)| needed.contains(k) && !p) {
            return Err(match self.kind {
                TargetType::Chessboard => format!("[target] lacks the required key `{key}`"),
                TargetType::Charuco => format!(
                    "[target] lacks the required key `{key}` (type = \"charuco\" takes rows, cols, {})",
                    needed.join(", ")
                ),
            });
        }
        let Some(c) = self.charuco() else {
            return Ok(());
        };
        if let Some(problem) = crate::model::target::spacing_problem(c.square) {
            return Err(format!("target.square {problem}"));
        }
        c.problem().map_or(Ok(()), |p| Err(format!("target.{p}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn section(text: &str) -> TargetSection {
        toml::from_str(text).unwrap()
    }

    /// A ChArUco board's inner corners are its squares less one, spaced a square apart.
    #[test]
    fn charuco_board_is_its_inner_corners() {
        let s = section(
            "type = \"charuco\"\nrows = 5\ncols = 7\nsquare = 0.04\nmarker = 0.03\ndictionary = \"DICT_4X4_50\"\n",
        );
        s.check().unwrap();
        assert_eq!(
            s.target(),
            Target {
                rows: 4,
                cols: 6,
                spacing: 0.04
            }
        );
    }

    /// Each wrong key is named, with what the type takes.
    #[test]
    fn wrong_keys_are_named() {
        let base = "type = \"charuco\"\nrows = 5\ncols = 7\nsquare = 0.04\n";
        let e = section(&format!("{base}marker = 0.03\ndictionary = \"DICT_9X9\"\n"))
            .check()
            .unwrap_err();
        assert!(
            e.starts_with("target.dictionary") && e.contains("DICT_5X5_100"),
            "{e}"
        );
        let e = section(&format!(
            "{base}marker = 0.05\ndictionary = \"DICT_4X4_50\"\n"
        ))
        .check()
        .unwrap_err();
        assert!(e.starts_with("target.marker"), "{e}");
        let e = section(&format!("{base}dictionary = \"DICT_4X4_50\"\n"))
            .check()
            .unwrap_err();
        assert!(e.contains("lacks the required key `marker`"), "{e}");
        let e = section("rows = 5\ncols = 7\nspacing = 0.04\nmarker = 0.03\n")
            .check()
            .unwrap_err();
        assert!(e.starts_with("target.marker does not apply"), "{e}");
        // 11 × 11 squares hold 60 markers; DICT_4X4_50 has 50.
        let e = section(
            "type = \"charuco\"\nrows = 11\ncols = 11\nsquare = 0.02\nmarker = 0.015\ndictionary = \"DICT_4X4_50\"\n",
        )
        .check()
        .unwrap_err();
        assert!(
            e.contains("has 50 markers") && e.contains("needs 60"),
            "{e}"
        );
    }
}
