//! The command line's overrides of a config: named flags and `--set section.key=value`
//! become keys of the TOML document, which is then checked exactly as a file is
//! ([`Config::parse`]), so a flag can hold nothing a file could not. A message about
//! a key that a flag set names the flag; one about a key of the file keeps the
//! file's line. The merged document is written back as a config that reruns the
//! same calibration from any folder (its paths made absolute).
//!
//! Which flag sets which key is the command's business (`app::commands`); this
//! module knows only keys.
use super::checked::Config;
use crate::error::Error;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use toml::{Table, Value};

/// How a config without a file is named in messages.
pub const COMMAND_LINE: &str = "the command line";

/// The array of tables that holds the cameras (`[[cameras]]`).
const CAMERAS: &str = "cameras";

/// The keys that hold paths, relative to the config's folder: made absolute in the
/// config written beside a result. (`data.photos` may be a table of paths.)
const PATH_KEYS: [(&str, &str); 7] = [
    ("data", "observations"),
    ("data", "video"),
    ("data", "corners_vnl"),
    ("data", "photos"),
    ("target", "geometry"),
    ("reference", "observations"),
    ("output", "dir"),
];

/// A key or a section header of the document: `(section, index, key)`, the index
/// counting the `[[cameras]]` tables, the key empty for the header itself.
type Place = (String, usize, String);

/// What went wrong with an override: a flag's value or key, or the config as a whole.
#[derive(Debug, thiserror::Error)]
pub enum OverrideError {
    /// A key set by this flag was refused; the message names the key.
    #[error("{flag}: {message}")]
    Flag { flag: String, message: String },
    /// The config file, or the config the flags make, was refused.
    #[error(transparent)]
    Config(#[from] Error),
}

/// Where an override goes: `section.key`, `cameras[i].key`, or every camera's key
/// (`cameras.key`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum KeyPath {
    /// A key of a `[section]`.
    Section { section: String, key: String },
    /// A key of the `index`-th camera, or of every camera when `None`.
    Camera { index: Option<usize>, key: String },
}

impl KeyPath {
    /// `section.key`, `cameras[i].key` or `cameras.key`; `None` for anything else.
    pub fn parse(text: &str) -> Option<KeyPath> {
        let (head, key) = text.split_once('.')?;
        let bare = |s: &str| {
            !s.is_empty()
                && s.chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        };
        if !bare(key) {
            return None;
        }
        let key = key.to_string();
        if let Some(index) = head
            .strip_prefix("cameras[")
            .and_then(|r| r.strip_suffix(']'))
        {
            let index = index.parse().ok()?;
            return Some(KeyPath::Camera {
                index: Some(index),
                key,
            });
        }
        if head == CAMERAS {
            return Some(KeyPath::Camera { index: None, key });
        }
        bare(head).then(|| KeyPath::Section {
            section: head.to_string(),
            key,
        })
    }
}

/// A flag's value as TOML: a number, boolean, quoted string, array or inline
/// table as written, anything else as a string (`full`, `left*.jpg`).
pub fn value_of(text: &str) -> Value {
    match toml::from_str::<Table>(&format!("v = {text}")) {
        Ok(t) if t.len() == 1 => t
            .get("v")
            .cloned()
            .unwrap_or_else(|| Value::String(text.into())),
        _ => Value::String(text.to_string()),
    }
}

/// A config as a TOML document: the file's (if any) with the command line's
/// overrides applied, and which flag set what.
#[derive(Debug, Clone, Default)]
pub struct Document {
    table: Table,
    /// The config file and its text.
    file: Option<(PathBuf, String)>,
    /// The keys and sections flags set, with the flag as the user wrote it.
    flags: BTreeMap<Place, String>,
}

impl Document {
    /// A config from the command line alone.
    pub fn new() -> Document {
        Document::default()
    }

    /// A config file, read and parsed as TOML (its keys are checked later, with the
    /// overrides); a syntax error gives the same message as [`Config::load`].
    pub fn load(path: &Path) -> Result<Document, Error> {
        let text = Config::read_text(path)?;
        let table =
            toml::from_str::<Table>(&text).map_err(|e| match Config::parse(&text, path) {
                Err(config_error) => config_error,
                Ok(_) => Error::Config {
                    path: path.into(),
                    message: crate::app::config_keys::explain(&text, e.message(), e.span()),
                },
            })?;
        Ok(Document {
            table,
            file: Some((path.to_path_buf(), text)),
            flags: BTreeMap::new(),
        })
    }

    /// Whether the document has a `[section]` (or `[[section]]`).
    pub fn has_section(&self, name: &str) -> bool {
        self.table.get(name).is_some_and(is_section)
    }

    /// Whether any flag changed the file's config.
    pub fn is_overridden(&self) -> bool {
        !self.flags.is_empty()
    }

    /// The config file, if there is one.
    pub fn file(&self) -> Option<&Path> {
        self.file.as_ref().map(|(p, _)| p.as_path())
    }

    /// A path given on the command line (relative to the working folder) as the
    /// document holds it: as written when the config's folder is the working
    /// folder (or there is no file), else made absolute.
    pub fn path_value(&self, given: &str) -> Value {
        let base = self.base();
        if base.as_os_str().is_empty() || Path::new(given).is_absolute() {
            return Value::String(given.to_string());
        }
        let cwd = std::env::current_dir().unwrap_or_default();
        Value::String(cwd.join(given).to_string_lossy().into_owned())
    }

    /// The folder relative paths of the document start from.
    pub fn base(&self) -> PathBuf {
        self.file()
            .and_then(Path::parent)
            .unwrap_or(Path::new(""))
            .to_path_buf()
    }

    /// A `[section]` table's value, if set.
    pub fn get(&self, section: &str, key: &str) -> Option<&Value> {
        self.table.get(section)?.as_table()?.get(key)
    }

    /// The cameras' tables (`[[cameras]]`), empty when there are none.
    pub fn cameras(&self) -> Vec<&Table> {
        match self.table.get(CAMERAS).and_then(Value::as_array) {
            Some(a) => a.iter().filter_map(Value::as_table).collect(),
            None => Vec::new(),
        }
    }

    /// Removes a whole section: a flag that names the data source replaces the
    /// file's `[data]`, whichever source it had.
    pub fn replace_section(&mut self, section: &str, flag: &str) {
        self.table.remove(section);
        self.flags.retain(|(s, ..), _| s != section);
        self.flags
            .insert((section.into(), 0, String::new()), flag.into());
    }

    /// `--set section.key=value` (or `cameras[i].key=value`).
    pub fn set_assignment(&mut self, assignment: &str, flag: &str) -> Result<(), OverrideError> {
        let spelled = format!("{flag} {assignment}");
        let fail = |message: String| OverrideError::Flag {
            flag: spelled.clone(),
            message,
        };
        let (key, value) = assignment
            .split_once('=')
            .ok_or_else(|| fail("expected section.key=value".into()))?;
        let path = KeyPath::parse(key.trim()).ok_or_else(|| {
            fail(format!(
                "`{}` is not a key: expected section.key (e.g. calibration.outlier_k) or cameras[i].key",
                crate::app::text::short(key.trim())
            ))
        })?;
        self.set(&path, value_of(value.trim()), &spelled)
    }

    /// Sets one key; `flag` is how the user wrote it, for messages.
    pub fn set(&mut self, path: &KeyPath, value: Value, flag: &str) -> Result<(), OverrideError> {
        match path {
            KeyPath::Section { section, key } => self.set_in_section(section, key, value, flag),
            KeyPath::Camera { index, key } => self.set_in_cameras(*index, key, value, flag),
        }
    }

    fn set_in_section(
        &mut self,
        section: &str,
        key: &str,
        value: Value,
        flag: &str,
    ) -> Result<(), OverrideError> {
        if section == CAMERAS {
            return self.set_in_cameras(None, key, value, flag);
        }
        if !self.table.contains_key(section) {
            self.flags
                .insert((section.into(), 0, String::new()), flag.into());
        }
        let table = self
            .table
            .entry(section)
            .or_insert_with(|| Value::Table(Table::new()))
            .as_table_mut()
            .ok_or_else(|| OverrideError::Flag {
                flag: flag.into(),
                message: format!("`{section}` is a key of the config's top level, not a section"),
            })?;
        table.insert(key.into(), value);
        self.flags
            .insert((section.into(), 0, key.into()), flag.into());
        Ok(())
    }

    /// A camera's key; a missing camera is added when it is the next one (a
    /// config without `[[cameras]]` gets `cam0`).
    fn set_in_cameras(
        &mut self,
        index: Option<usize>,
        key: &str,
        value: Value,
        flag: &str,
    ) -> Result<(), OverrideError> {
        let fail = |message: String| OverrideError::Flag {
            flag: flag.into(),
            message,
        };
        let cameras = self
            .table
            .entry(CAMERAS)
            .or_insert_with(|| Value::Array(Vec::new()))
            .as_array_mut()
            .ok_or_else(|| fail("`cameras` must be an array of tables ([[cameras]])".into()))?;
        let count = cameras.len();
        let wanted = index.unwrap_or(0);
        if wanted > count {
            return Err(fail(format!(
                "cameras[{wanted}]: the config has {count} camera(s); add cameras[{count}] first"
            )));
        }
        let mut added = Vec::new();
        if wanted == count {
            let mut camera = Table::new();
            camera.insert("name".into(), Value::String(format!("cam{count}")));
            cameras.push(Value::Table(camera));
            added.push(count);
        }
        let targets: Vec<usize> = match index {
            Some(i) => vec![i],
            None => (0..cameras.len()).collect(),
        };
        for &i in &targets {
            let camera = cameras[i]
                .as_table_mut()
                .ok_or_else(|| fail(format!("cameras[{i}] is not a table")))?;
            camera.insert(key.into(), value.clone());
        }
        for i in added {
            self.flags
                .insert((CAMERAS.into(), i, String::new()), flag.into());
            self.flags
                .insert((CAMERAS.into(), i, "name".into()), flag.into());
        }
        for i in targets {
            self.flags
                .insert((CAMERAS.into(), i, key.into()), flag.into());
        }
        Ok(())
    }

    /// Makes the cameras one per name, each a copy of the document's only camera
    /// (the one the flags made for every camera, or none), so that what was given
    /// for every camera holds for each; `flag` names where the names came from.
    pub fn cameras_named(&mut self, names: &[String], flag: &str) {
        let template = self
            .cameras()
            .first()
            .map(|t| (*t).clone())
            .unwrap_or_default();
        let template_flags: Vec<(String, String)> = self
            .flags
            .iter()
            .filter(|((s, i, key), _)| s == CAMERAS && *i == 0 && !key.is_empty() && key != "name")
            .map(|((_, _, key), f)| (key.clone(), f.clone()))
            .collect();
        self.flags.retain(|(s, ..), _| s != CAMERAS);
        let cameras = names
            .iter()
            .enumerate()
            .map(|(i, name)| {
                let mut camera = template.clone();
                camera.insert("name".into(), Value::String(name.clone()));
                self.flags
                    .insert((CAMERAS.into(), i, String::new()), flag.into());
                self.flags
                    .insert((CAMERAS.into(), i, "name".into()), flag.into());
                for (key, f) in &template_flags {
                    self.flags
                        .insert((CAMERAS.into(), i, key.clone()), f.clone());
                }
                Value::Table(camera)
            })
            .collect();
        self.table.insert(CAMERAS.into(), Value::Array(cameras));
    }

    /// The checked config. Without overrides the file is parsed as it is, so every
    /// message is exactly [`Config::load`]'s.
    pub fn config(&self) -> Result<Config, OverrideError> {
        if let (Some((path, text)), false) = (&self.file, self.is_overridden()) {
            return Ok(Config::parse(text, path)?);
        }
        let (text, places) = render(&self.table);
        let path = self
            .file()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from(COMMAND_LINE));
        Config::parse(&text, &path).map_err(|e| self.located(e, &places))
    }

    /// An error about the merged text, told where the user wrote the key: the flag
    /// that set it, or its line in the file.
    fn located(&self, error: Error, places: &[Place]) -> OverrideError {
        let (path, message) = match error {
            Error::Config { path, message } => (path, message),
            other => return other.into(),
        };
        let Some((line, rest)) = split_line(&message) else {
            return Error::Config { path, message }.into();
        };
        let place = places.get(line - 1);
        if let Some(flag) = place.and_then(|p| self.flags.get(p)) {
            return OverrideError::Flag {
                flag: flag.clone(),
                message: rest.to_string(),
            };
        }
        let file_line = match (place, &self.file) {
            (Some((section, index, key)), Some((_, text))) => {
                crate::app::config_keys::key_line(text, section, *index, key)
            }
            _ => None,
        };
        let rest = self.headers_in_file(rest, places);
        let message = match file_line {
            Some(n) => format!("line {n}: {rest}"),
            None => rest,
        };
        Error::Config { path, message }.into()
    }

    /// A message's `(line N)` of a section header, told as the file's line.
    fn headers_in_file(&self, message: &str, places: &[Place]) -> String {
        let Some((_, text)) = &self.file else {
            return message.to_string();
        };
        let mut out = String::new();
        let mut rest = message;
        while let Some(i) = rest.find("(line ") {
            out.push_str(&rest[..i + "(line ".len()]);
            let after = &rest[i + "(line ".len()..];
            let digits: String = after.chars().take_while(char::is_ascii_digit).collect();
            let line = digits
                .parse::<usize>()
                .ok()
                .and_then(|n| places.get(n.checked_sub(1)?));
            match line.and_then(|(s, i, k)| crate::app::config_keys::key_line(text, s, *i, k)) {
                Some(n) => out.push_str(&n.to_string()),
                None => out.push_str(&digits),
            }
            rest = &after[digits.len()..];
        }
        out.push_str(rest);
        out
    }

    /// The document as a config file that reruns `config` from any folder: its
    /// paths absolute, its output folder named.
    pub fn rerunnable(&self, config: &Config) -> String {
        let cwd = std::env::current_dir().unwrap_or_default();
        let base = cwd.join(self.base());
        let mut table = self.table.clone();
        for (section, key) in PATH_KEYS {
            let Some(value) = table
                .get_mut(section)
                .and_then(Value::as_table_mut)
                .and_then(|t| t.get_mut(key))
            else {
                continue;
            };
            absolute(value, &base);
        }
        let output = table
            .entry("output")
            .or_insert_with(|| Value::Table(Table::new()));
        if let Some(output) = output.as_table_mut() {
            let dir = cwd.join(&config.output_dir);
            output.insert("dir".into(), Value::String(dir.to_string_lossy().into()));
        }
        let mut text = String::from(
            "# The settings of this calibration: its config and command line as one file.\n\
             # Rerun it with `deformcal calibrate --config config.toml` (paths are absolute).\n",
        );
        text.push_str(&render(&table).0);
        text
    }
}

/// `line N: rest` split into N and rest.
fn split_line(message: &str) -> Option<(usize, &str)> {
    let rest = message.strip_prefix("line ")?;
    let (n, rest) = rest.split_once(": ")?;
    Some((n.parse().ok().filter(|n| *n > 0)?, rest))
}

/// A path value (or a table of them, `data.photos`) made absolute against `base`.
fn absolute(value: &mut Value, base: &Path) {
    match value {
        Value::String(s) => *s = base.join(&*s).to_string_lossy().into_owned(),
        Value::Table(t) => t.iter_mut().for_each(|(_, v)| absolute(v, base)),
        _ => {}
    }
}

/// A key as TOML writes it: bare when it can be, else quoted.
fn key_text(key: &str) -> String {
    let bare = !key.is_empty()
        && key
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if bare {
        key.to_string()
    } else {
        Value::String(key.to_string()).to_string()
    }
}

/// The document as TOML text with one key per line, and each line's place (for
/// naming the flag or file line behind a message about that line).
fn render(table: &Table) -> (String, Vec<Place>) {
    let mut text = String::new();
    let mut places = Vec::new();
    let mut line = |text_line: String, place: Place| {
        text.push_str(&text_line);
        text.push('\n');
        places.push(place);
    };
    let top = String::new();
    for (key, value) in table {
        if !is_section(value) {
            line(
                format!("{} = {value}", key_text(key)),
                (top.clone(), 0, key.clone()),
            );
        }
    }
    for (name, value) in table {
        let sections: Vec<&Table> = match value {
            Value::Table(t) => vec![t],
            Value::Array(a) if is_section(value) => a.iter().filter_map(Value::as_table).collect(),
            _ => continue,
        };
        let array = value.is_array();
        for (index, section) in sections.into_iter().enumerate() {
            let header = if array {
                format!("[[{}]]", key_text(name))
            } else {
                format!("[{}]", key_text(name))
            };
            line(header, (name.clone(), index, String::new()));
            for (key, v) in section {
                line(
                    format!("{} = {v}", key_text(key)),
                    (name.clone(), index, key.clone()),
                );
            }
        }
    }
    (text, places)
}

/// A table, or a non-empty array of tables (`[[cameras]]`).
fn is_section(value: &Value) -> bool {
    match value {
        Value::Table(_) => true,
        Value::Array(a) => !a.is_empty() && a.iter().all(Value::is_table),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_parse_by_section_and_camera() {
        assert_eq!(
            KeyPath::parse("calibration.outlier_k"),
            Some(KeyPath::Section {
                section: "calibration".into(),
                key: "outlier_k".into()
            })
        );
        assert_eq!(
            KeyPath::parse("cameras[1].model"),
            Some(KeyPath::Camera {
                index: Some(1),
                key: "model".into()
            })
        );
        assert_eq!(
            KeyPath::parse("cameras.fix"),
            Some(KeyPath::Camera {
                index: None,
                key: "fix".into()
            })
        );
        for bad in [
            "outlier_k",
            "calibration.",
            ".x",
            "a.b.c",
            "cameras[x].model",
        ] {
            assert_eq!(KeyPath::parse(bad), None, "{bad}");
        }
    }

    #[test]
    fn values_are_toml_or_else_strings() {
        assert_eq!(value_of("4"), Value::Integer(4));
        assert_eq!(value_of("0.025"), Value::Float(0.025));
        assert_eq!(value_of("full"), Value::String("full".into()));
        assert_eq!(value_of("\"full\""), Value::String("full".into()));
        assert_eq!(value_of("left*.jpg"), Value::String("left*.jpg".into()));
        assert_eq!(
            value_of("[\"k3\", \"p1\"]"),
            Value::Array(vec!["k3".into(), "p1".into()])
        );
        // A second key smuggled in by a newline stays part of one string.
        assert_eq!(value_of("1\nx = 2"), Value::String("1\nx = 2".into()));
    }

    #[test]
    fn rendered_text_parses_back_to_the_same_table() {
        let text = "[target]\nrows = 6\ncols = 9\nspacing = 0.025\n[[cameras]]\nname = \"a b\"\nwidth = 640\nheight = 480\n[[cameras]]\nname = \"c\"\nwidth = 1\nheight = 2\n[data]\nphotos = { \"a b\" = \"l*.jpg\", c = \"r*.jpg\" }\n[calibration]\nfunction_tolerance = 1e-12\nloss_scale_px = 0.30000000000000004\n";
        let table: Table = toml::from_str(text).unwrap();
        let (rendered, places) = render(&table);
        assert_eq!(toml::from_str::<Table>(&rendered).unwrap(), table);
        assert_eq!(places.len(), rendered.lines().count());
        let cam1 = rendered.lines().position(|l| l == "name = \"c\"").unwrap();
        assert_eq!(places[cam1], ("cameras".into(), 1, "name".into()));
    }
}
