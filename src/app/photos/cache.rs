//! The detection cache: a rerun on unchanged images reuses their detections.
//!
//! One JSON file in the output dir holds, per image (by its name relative to the
//! config), the file's size, modification time and content hash with the outcome.
//! A file whose size and mtime are unchanged is trusted without reading it (the
//! fast path, as `git` does for its index); otherwise its content is hashed, so a
//! copied or touched but identical file is still a hit. The whole cache is valid
//! only for its own format [`VERSION`], the detector version and settings and the
//! board it was made with; a cache of another format or a broken file is a miss
//! for every image, never an error.
use crate::app::detect::Corner;
use crate::app::fsio::write_atomic;
use crate::error::Result;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// The cache file's name in the output dir.
pub const FILE_NAME: &str = "detections.cache.json";

/// The format of the cache file; raise it whenever what an entry holds changes,
/// so that older files are read as misses. 2: typed corners with their weight.
pub const VERSION: u32 = 2;

/// What a detection produced for one image, as kept in the cache.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Outcome {
    /// Image size (0 × 0 when it could not be read).
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// `complete`, `partial`, `rejected` or `unreadable`.
    pub status: Status,
    /// Why the image was rejected or unreadable; empty otherwise.
    pub reason: String,
    /// The corners exactly as the detector gave them (id, pixel, weight, σ).
    pub corners: Vec<Corner>,
    /// The board looks alike turned by 180° and the view was labelled by its
    /// orientation in the image (`Detection::labelled_by_symmetry`).
    #[serde(default)]
    pub by_symmetry: bool,
}

/// The status column of `detections.csv`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Every corner of the board found.
    Complete,
    /// Part of the board found, unambiguously indexed.
    Partial,
    /// A readable image without a usable board.
    Rejected,
    /// A file that is not a readable image.
    Unreadable,
}

impl Status {
    /// The name written to `detections.csv`.
    pub fn name(self) -> &'static str {
        match self {
            Status::Complete => "complete",
            Status::Partial => "partial",
            Status::Rejected => "rejected",
            Status::Unreadable => "unreadable",
        }
    }

    /// Whether the image contributes observations.
    pub fn usable(self) -> bool {
        matches!(self, Status::Complete | Status::Partial)
    }
}

/// A file's identity: a hit needs the same size and either the same mtime or the
/// same content hash.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Stamp {
    /// File size in bytes.
    pub size: u64,
    /// Modification time, nanoseconds since the Unix epoch (0 if unknown).
    pub mtime_ns: u64,
    /// FNV-1a 64 of the content; 0 when not computed yet.
    pub hash: u64,
}

/// One cached image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Entry {
    /// The file's identity when it was detected.
    pub stamp: Stamp,
    /// The detection.
    pub outcome: Outcome,
    /// A video frame's sharpness (`app::video`), so a rerun need not decode it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sharpness: Option<f64>,
}

/// The cache file: the settings it is valid for and the entries.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Cache {
    /// The file's format, [`VERSION`] (0 in a file from before it was recorded).
    #[serde(default)]
    pub version: u32,
    /// Detector version, settings and board; any change voids every entry.
    pub settings: String,
    /// By image name relative to the config's folder.
    pub images: BTreeMap<String, Entry>,
}

impl Cache {
    /// The cache in `dir` if it exists, is readable, of this [`VERSION`] and
    /// made with `settings`; otherwise an empty one (an old or broken cache only
    /// costs a new detection).
    pub fn load(dir: &Path, settings: &str) -> Cache {
        let fresh = Cache {
            version: VERSION,
            settings: settings.to_string(),
            images: BTreeMap::new(),
        };
        let Ok(text) = std::fs::read(dir.join(FILE_NAME)) else {
            return fresh;
        };
        match serde_json::from_slice::<Cache>(&text) {
            Ok(c) if c.version == VERSION && c.settings == settings => c,
            _ => fresh,
        }
    }

    /// The cached outcome of `name`, if its file is unchanged. `stamp` has the
    /// current size and mtime; `hash` computes the content hash on demand.
    pub fn lookup(&self, name: &str, stamp: Stamp, hash: impl FnOnce() -> u64) -> Lookup {
        let Some(entry) = self.images.get(name) else {
            return Lookup::Miss(None);
        };
        if entry.stamp.size != stamp.size {
            return Lookup::Miss(None);
        }
        if entry.stamp.mtime_ns == stamp.mtime_ns && stamp.mtime_ns != 0 {
            return Lookup::Hit(entry.clone());
        }
        let h = hash();
        if h == entry.stamp.hash {
            return Lookup::Hit(Entry {
                stamp: Stamp { hash: h, ..stamp },
                ..entry.clone()
            });
        }
        Lookup::Miss(Some(h))
    }

    /// Writes the cache into `dir` atomically.
    pub fn save(&self, dir: &Path) -> Result<()> {
        let json = serde_json::to_vec(self).expect("the cache serialises");
        write_atomic(&dir.join(FILE_NAME), &json)
    }
}

/// The result of a cache lookup.
pub enum Lookup {
    /// Unchanged: the entry to reuse (with the stamp brought up to date).
    Hit(Entry),
    /// Changed or new; the content hash when it was computed on the way.
    Miss(Option<u64>),
}

/// The size and mtime of a file (mtime 0 when the platform has none).
pub fn stamp_of(meta: &std::fs::Metadata) -> Stamp {
    let mtime_ns = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos() as u64);
    Stamp {
        size: meta.len(),
        mtime_ns,
        hash: 0,
    }
}

/// FNV-1a, 64 bit: simple, stable across Rust versions (unlike std's hasher)
/// and fast enough next to decoding the image; collisions only matter by
/// accident here, nobody gains by forging one.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    fnv1a_extend(FNV_START, bytes)
}

/// FNV-1a's starting value, for [`fnv1a_extend`].
pub const FNV_START: u64 = 0xcbf2_9ce4_8422_2325;

/// FNV-1a of what `h` hashed followed by `bytes`: a file hashed piece by piece.
pub fn fnv1a_extend(mut h: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(size: u64, mtime_ns: u64, hash: u64) -> Entry {
        Entry {
            stamp: Stamp {
                size,
                mtime_ns,
                hash,
            },
            outcome: Outcome {
                width: 1,
                height: 1,
                status: Status::Rejected,
                reason: "no chessboard found".into(),
                corners: vec![],
                by_symmetry: false,
            },
            sharpness: None,
        }
    }

    #[test]
    fn hits_need_the_same_size_and_mtime_or_content() {
        let mut c = Cache::default();
        c.images.insert("a.png".into(), entry(10, 5, 99));
        let s = |size, mtime_ns| Stamp {
            size,
            mtime_ns,
            hash: 0,
        };
        assert!(matches!(
            c.lookup("a.png", s(10, 5), || panic!("no hash on the fast path")),
            Lookup::Hit(_)
        ));
        assert!(matches!(c.lookup("a.png", s(10, 6), || 99), Lookup::Hit(_)));
        assert!(matches!(
            c.lookup("a.png", s(10, 6), || 98),
            Lookup::Miss(Some(98))
        ));
        assert!(matches!(
            c.lookup("a.png", s(11, 5), || 99),
            Lookup::Miss(None)
        ));
        assert!(matches!(
            c.lookup("b.png", s(10, 5), || 99),
            Lookup::Miss(None)
        ));
    }

    #[test]
    fn an_old_or_broken_cache_file_is_empty() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = Cache::load(dir.path(), "s");
        assert_eq!(c.version, VERSION);
        let mut e = entry(10, 5, 99);
        e.outcome.status = Status::Complete;
        e.outcome.corners = vec![Corner::new(3, [1.5, 2.25], 0.2)];
        c.images.insert("a.png".into(), e.clone());
        c.save(dir.path()).unwrap();
        let back = Cache::load(dir.path(), "s");
        assert_eq!(back.images["a.png"], e);
        assert!(Cache::load(dir.path(), "other settings").images.is_empty());
        // The format before typed corners: no version, a corner as 4 floats.
        let old = r#"{"settings":"s","images":{"a.png":{"stamp":{"size":10,"mtime_ns":5,"hash":99},
            "outcome":{"width":1,"height":1,"status":"complete","reason":"","corners":[[3.0,1.5,2.25,0.2]]}}}}"#;
        std::fs::write(dir.path().join(FILE_NAME), old).unwrap();
        assert!(Cache::load(dir.path(), "s").images.is_empty());
        // The same with a version number of the current format but the old corners.
        let mixed = old.replacen('{', &format!("{{\"version\":{VERSION},"), 1);
        std::fs::write(dir.path().join(FILE_NAME), mixed).unwrap();
        assert!(Cache::load(dir.path(), "s").images.is_empty());
        std::fs::write(dir.path().join(FILE_NAME), b"{\"version\":2,\"sett").unwrap();
        assert!(Cache::load(dir.path(), "s").images.is_empty());
    }

    #[test]
    fn fnv_matches_its_reference_values() {
        assert_eq!(fnv1a(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a(b"a"), 0xaf63_dc4c_8601_ec8c);
    }
}
