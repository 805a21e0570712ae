//! The checker of one config text: where its relative paths start, and messages
//! that name the key's line in the file.
use crate::app::config_keys::{key_line, message_key};
use crate::error::Error;
use std::path::{Path, PathBuf};

/// Checks one parsed config text; `base` is the folder relative paths start from.
pub(super) struct Checker<'a> {
    pub(super) path: &'a Path,
    pub(super) base: PathBuf,
    pub(super) text: &'a str,
}

impl Checker<'_> {
    /// A config error; when the message starts with a key, its line is named too.
    pub(super) fn err(&self, message: String) -> Error {
        let line = message_key(&message).and_then(|(t, i, k)| key_line(self.text, &t, i, &k));
        Error::Config {
            path: self.path.into(),
            message: match line {
                Some(n) => format!("line {n}: {message}"),
                None => message,
            },
        }
    }
}
