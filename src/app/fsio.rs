//! Files in and out, safely: bounded reads of regular files only (a FIFO or
//! `/dev/zero` never hangs a run), single files written through a temporary file
//! and a rename, and whole result sets staged beside the output directory and
//! swapped in at once under an advisory lock, so a reader never sees half of one
//! run and half of another.
use crate::error::{Error, Result};
use fs4::fs_std::FileExt;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// Largest config file read (a config is a few kilobytes).
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;
/// Largest data file read (observations CSV, corners.vnl, calibration.json, shard):
/// 4 GiB, about 100 million observations.
pub const MAX_DATA_BYTES: u64 = 4 << 30;

/// Reads a regular file of at most `limit` bytes; anything else (a FIFO, a device,
/// a directory, a larger file) is refused before reading, so a read always ends.
pub fn read_limited(path: &Path, limit: u64) -> Result<Vec<u8>> {
    // Checked before opening: opening a FIFO blocks until a writer appears.
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(Error::Invalid(format!(
            "{}: not a regular file (a directory, FIFO or device cannot be read as input)",
            path.display()
        )));
    }
    if meta.len() > limit {
        return Err(Error::TooLarge(format!(
            "{}: {} bytes is more than the limit of {limit} bytes",
            path.display(),
            meta.len()
        )));
    }
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    // The file may grow while it is read: never read more than the limit.
    file.take(limit + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > limit {
        return Err(Error::TooLarge(format!(
            "{}: more than the limit of {limit} bytes",
            path.display()
        )));
    }
    Ok(bytes)
}

/// Writes `bytes` to `path` through a temporary file and a rename, so a reader
/// (or a crash) never sees a half-written file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(|e| Error::write(dir, e))?;
    tmp.write_all(bytes).map_err(|e| Error::write(path, e))?;
    tmp.as_file()
        .sync_all()
        .map_err(|e| Error::write(path, e))?;
    // Temporary files are private; results are ordinary files.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let _ = tmp
            .as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644));
    }
    tmp.persist(path).map_err(|e| Error::write(path, e.error))?;
    Ok(())
}

/// The HTML report of a calibration or a protocol run, in its output directory.
pub const REPORT_HTML: &str = "report.html";

/// Which entries of an output directory belong to a kind of result set: those are
/// replaced by the new set, every other entry is kept.
pub type Owns = Box<dyn Fn(&str) -> bool>;

/// How each camera's projection-uncertainty map's file name begins
/// (`uncertainty_<camera>.svg`, written by `app::uncertainty_plot`).
pub const UNCERTAINTY_MAP_PREFIX: &str = "uncertainty_";

/// The files of one protocol run.
pub fn protocol_files() -> Owns {
    Box::new(|name| {
        matches!(
            name,
            "protocol.csv" | "deformations.csv" | "summary.json" | "report.md"
        ) || name == REPORT_HTML
            || name.ends_with(".svg")
    })
}

/// A result set being written: a staging directory beside the output directory,
/// held under the output directory's advisory lock until [`OutputSet::commit`]
/// swaps it in. Dropped without a commit, it leaves the old output untouched.
pub struct OutputSet {
    target: PathBuf,
    staging: Option<tempfile::TempDir>,
    owns: Owns,
    // Held for the lifetime of the set; the OS releases it on drop or exit.
    _lock: std::fs::File,
}

impl std::fmt::Debug for OutputSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OutputSet")
            .field("target", &self.target)
            .finish_non_exhaustive()
    }
}

/// The lock file of output directory `target`: beside it, not in it, because the
/// directory itself is replaced by the swap (a lock on it would be lost).
fn lock_path(parent: &Path, name: &str) -> PathBuf {
    parent.join(format!(".{name}.lock"))
}

impl OutputSet {
    /// Takes the lock of `target` and creates the staging directory: call it before
    /// the work, so an unwritable or busy output fails at once.
    pub fn begin(target: &Path, owns: Owns) -> Result<OutputSet> {
        if target.exists() && !target.is_dir() {
            return Err(Error::write(
                target,
                std::io::Error::other("exists and is not a directory"),
            ));
        }
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .filter(|n| n != "." && n != "..")
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "{}: the output directory needs a name (not `.` or `/`)",
                    target.display()
                ))
            })?;
        let parent = target
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        std::fs::create_dir_all(parent).map_err(|e| Error::write(parent, e))?;
        let lock_file = lock_path(parent, &name);
        let lock = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&lock_file)
            .map_err(|e| Error::write(&lock_file, e))?;
        match lock.try_lock_exclusive() {
            Ok(true) => {}
            Ok(false) => return Err(Error::Locked(target.into())),
            Err(e) => return Err(Error::write(&lock_file, e)),
        }
        let staging = tempfile::Builder::new()
            .prefix(&format!(".{name}.new-"))
            .tempdir_in(parent)
            .map_err(|e| Error::write(parent, e))?;
        Ok(OutputSet {
            target: target.into(),
            staging: Some(staging),
            owns,
            _lock: lock,
        })
    }

    /// The directory to write the new set into.
    pub fn path(&self) -> &Path {
        self.staging.as_ref().expect("staging until commit").path()
    }

    /// The output directory the set will replace.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Carries over what the old output holds besides this kind of set, then swaps
    /// the staged set in: old directory aside, new one in place, old one removed.
    pub fn commit(mut self) -> Result<()> {
        let staging = self.staging.take().expect("staging until commit");
        let new = staging.path().to_path_buf();
        let target = self.target.clone();
        let mut dirs = Vec::new();
        if target.is_dir() {
            for entry in std::fs::read_dir(&target).map_err(|e| Error::io(&target, e))? {
                let entry = entry.map_err(|e| Error::io(&target, e))?;
                let name = entry.file_name();
                if (self.owns)(&name.to_string_lossy()) || new.join(&name).exists() {
                    continue;
                }
                let (from, to) = (entry.path(), new.join(&name));
                if entry.file_type().map_err(|e| Error::io(&from, e))?.is_dir() {
                    dirs.push((from, to));
                } else if std::fs::hard_link(&from, &to).is_err() {
                    std::fs::copy(&from, &to).map_err(|e| Error::write(&to, e))?;
                }
            }
        }
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let _ = std::fs::set_permissions(&new, std::fs::Permissions::from_mode(0o755));
        }
        // Sub-directories move last, just before the swap, so a failure above
        // leaves the old output whole.
        for (from, to) in dirs {
            std::fs::rename(&from, &to).map_err(|e| Error::write(&to, e))?;
        }
        let new = staging.keep();
        let old = if target.exists() {
            let parent = new.parent().expect("staging has a parent");
            let aside = tempfile::Builder::new()
                .prefix(".deformcal-old-")
                .tempdir_in(parent)
                .map_err(|e| Error::write(parent, e))?
                .keep();
            let old = aside.join("old");
            std::fs::rename(&target, &old).map_err(|e| Error::write(&target, e))?;
            Some(aside)
        } else {
            None
        };
        std::fs::rename(&new, &target).map_err(|e| Error::write(&target, e))?;
        if let Some(old) = old {
            remove_tree(&old);
        }
        Ok(())
    }
}

/// Most threads [`remove_tree`] unlinks with.
const UNLINK_THREADS: usize = 16;

/// Removes directory `dir` and everything in it, best effort (the set is already
/// swapped in), the entries of its sub-directories side by side: on a file system
/// mounted with `discard` each unlink of a synced file waits for its blocks to be
/// trimmed, 1–9 ms each on this project's machines, and concurrent unlinks share
/// the wait.
fn remove_tree(dir: &Path) {
    let mut files = Vec::new();
    let mut dirs = vec![dir.to_path_buf()];
    let mut i = 0;
    while i < dirs.len() {
        if let Ok(entries) = std::fs::read_dir(&dirs[i]) {
            for entry in entries.flatten() {
                match entry.file_type() {
                    Ok(t) if t.is_dir() => dirs.push(entry.path()),
                    _ => files.push(entry.path()),
                }
            }
        }
        i += 1;
    }
    let per_thread = files.len().div_ceil(UNLINK_THREADS).max(1);
    std::thread::scope(|s| {
        for chunk in files.chunks(per_thread) {
            let unlink = move || {
                for f in chunk {
                    let _ = std::fs::remove_file(f);
                }
            };
            // Without a thread to be had, the files go one after the other.
            if std::thread::Builder::new().spawn_scoped(s, unlink).is_err() {
                unlink();
            }
        }
    });
    // Deepest first; whatever is left (a file that appeared meanwhile) goes the plain way.
    for d in dirs.iter().rev() {
        let _ = std::fs::remove_dir(d);
    }
    if dir.exists() {
        let _ = std::fs::remove_dir_all(dir);
    }
}

impl Drop for OutputSet {
    fn drop(&mut self) {
        // An uncommitted staging directory is removed by TempDir's own drop.
        self.staging.take();
    }
}
