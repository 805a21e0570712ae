//! A ChArUco board's description in OpenCV's layout (squares, sizes, marker
//! dictionary): its checks, the inner-corner target the solver sees and its
//! printable rectangles. No detection here (that is `charuco`).

use crate::model::target::Target;
use calib_targets::aruco::builtins::{builtin_dictionary, BUILTIN_DICTIONARY_NAMES};
use calib_targets::charuco::CharucoBoardSpec;
use calib_targets::printable::{board_primitives, CharucoTargetSpec, Primitive, TargetSpec};

/// A ChArUco board: squares, their size and the markers' (metres), and the
/// marker dictionary in OpenCV's spelling (`DICT_5X5_100`).
#[derive(Clone, Debug, PartialEq)]
pub struct CharucoSpec {
    /// Squares per column.
    pub rows: usize,
    /// Squares per row.
    pub cols: usize,
    /// Square side, metres.
    pub square: f64,
    /// Marker side, metres.
    pub marker: f64,
    /// Dictionary name as OpenCV spells it.
    pub dictionary: String,
}

/// Most squares a side may have: a dictionary of 1000 markers fills 44 × 44.
pub const MAX_SQUARES: usize = 200;

impl CharucoSpec {
    /// The inner-corner board the solver sees (ids are its corner indices).
    pub fn target(&self) -> Target {
        Target {
            rows: self.rows.saturating_sub(1),
            cols: self.cols.saturating_sub(1),
            spacing: self.square,
        }
    }

    /// Number of markers: one on every white square.
    pub fn num_markers(&self) -> usize {
        self.rows * self.cols / 2
    }

    /// Why this cannot be a ChArUco board, as `key message` for `[target]`.
    pub fn problem(&self) -> Option<String> {
        if self.rows < 3 || self.cols < 3 || self.rows > MAX_SQUARES || self.cols > MAX_SQUARES {
            return Some(format!(
                "rows and cols count squares and must be 3 to {MAX_SQUARES} (got {} × {})",
                self.rows, self.cols
            ));
        }
        let Some(dict) = builtin_dictionary(&self.dictionary) else {
            return Some(format!(
                "dictionary `{}` is not one of OpenCV's: {}",
                self.dictionary,
                BUILTIN_DICTIONARY_NAMES.join(", ")
            ));
        };
        if dict.codes().len() < self.num_markers() {
            return Some(format!(
                "dictionary `{}` has {} markers, a board of {} × {} squares needs {}",
                self.dictionary,
                dict.codes().len(),
                self.rows,
                self.cols,
                self.num_markers()
            ));
        }
        if !(self.marker > 0.0 && self.marker < self.square) {
            return Some(format!(
                "marker must be larger than 0 and smaller than square ({} m), got {} m",
                self.square, self.marker
            ));
        }
        None
    }

    /// calib-targets' description of the board (sizes in millimetres).
    pub(crate) fn board_spec(&self) -> Option<CharucoBoardSpec> {
        let dict = builtin_dictionary(&self.dictionary)?;
        Some(CharucoBoardSpec::new(
            self.rows as u32,
            self.cols as u32,
            (self.square * 1000.0) as f32,
            (self.marker / self.square) as f32,
            dict,
        ))
    }

    /// The printable board's black and white rectangles in millimetres, origin
    /// at the board's top-left outer corner (x right, y down), from calib-targets'
    /// printable-target generator.
    pub fn primitives(&self) -> Option<Vec<Primitive>> {
        let dict = builtin_dictionary(&self.dictionary)?;
        let spec = CharucoTargetSpec::new(
            self.rows as u32,
            self.cols as u32,
            self.square * 1000.0,
            self.marker / self.square,
            dict,
        );
        board_primitives(&TargetSpec::Charuco(spec)).ok()
    }
}
