//! Files in and out, safely: bounded reads of regular files only (a FIFO or
//! `/dev/zero` never hangs a run), single files written through a temporary file
//! and a rename, and whole result sets staged beside the output directory and
//! swapped in at once under an advisory lock, so a reader never sees half of one
//! run and half of another. What a run leaves unfinished is removed: on an
//! error, on a signal ([`remove_unfinished`]), and by the next run on the same
//! output when a run died.
use crate::error::{Error, Result};
use fs4::fs_std::FileExt;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// Largest config file read (a config is a few kilobytes).
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;
/// Largest data file read (observations CSV, corners.vnl, calibration.json, shard):
/// 4 GiB, about 100 million observations.
pub const MAX_DATA_BYTES: u64 = 4 << 30;

/// `path` with each `dir/..` taken out where `dir` is a real directory (not a
/// link, whose `..` is its target's parent): the same place, as a user would
/// write it (`configs/../out/a` is `out/a`).
pub fn tidy_path(path: &Path) -> PathBuf {
    use std::path::Component;
    let mut out = PathBuf::new();
    for part in path.components() {
        let is_real_dir =
            |p: &Path| std::fs::symlink_metadata(p).is_ok_and(|m| m.file_type().is_dir());
        match part {
            Component::ParentDir
                if matches!(out.components().next_back(), Some(Component::Normal(_)))
                    && is_real_dir(&out) =>
            {
                out.pop();
            }
            Component::CurDir if !out.as_os_str().is_empty() => {}
            other => out.push(other),
        }
    }
    if out.as_os_str().is_empty() {
        out.push(".");
    }
    out
}

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
/// (or a crash) never sees a half-written file. Into the staging directory of an
/// [`OutputSet`], which no reader sees before its commit, the file is written in
/// place and synced with the rest of the set at the commit.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if let Some(files) = staged().iter_mut().find(|(d, _)| d == dir) {
        return write_staged(path, bytes, &mut files.1);
    }
    let tmp = tempfile::NamedTempFile::new_in(dir).map_err(|e| Error::write(dir, e))?;
    let tmp_path = tmp.path().to_path_buf();
    track(&tmp_path);
    let written = write_temp(tmp, path, bytes);
    untrack(&tmp_path);
    written
}

/// The staging directories of the live output sets, each with the files written
/// into it so far (open, to be synced at the commit).
static STAGED: std::sync::Mutex<Vec<(PathBuf, Vec<std::fs::File>)>> =
    std::sync::Mutex::new(Vec::new());

fn staged() -> std::sync::MutexGuard<'static, Vec<(PathBuf, Vec<std::fs::File>)>> {
    STAGED.lock().unwrap_or_else(|e| e.into_inner())
}

/// [`write_atomic`] into a staging directory: the file itself, no temporary file,
/// its data sent to the disk now and waited for at the commit
/// ([`OutputSet::commit`]).
fn write_staged(path: &Path, bytes: &[u8], files: &mut Vec<std::fs::File>) -> Result<()> {
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create(true).truncate(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o644);
    }
    let mut file = options.open(path).map_err(|e| Error::write(path, e))?;
    file.write_all(bytes).map_err(|e| Error::write(path, e))?;
    start_writeback(&file);
    files.push(file);
    Ok(())
}

/// Starts writing `file`'s data to the disk without waiting for it, so the sync at
/// the commit, milliseconds later, finds it written: only a head start, the sync
/// is what guarantees it (an error here is the sync's to report).
fn start_writeback(file: &std::fs::File) {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        // SAFETY: a valid open file descriptor; the call only schedules writeback.
        unsafe {
            libc::sync_file_range(file.as_raw_fd(), 0, 0, libc::SYNC_FILE_RANGE_WRITE);
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = file;
}

/// Most threads [`sync_files`] syncs with.
const SYNC_THREADS: usize = 8;

/// Flushes the files' data to the disk side by side: concurrent syncs share the
/// file system's journal commits, one after the other each waits for its own
/// (a calibration's 9 files: 20–30 ms one after the other while other processes
/// wrote to the disk, 3–5 ms side by side). Their writeback started as each was
/// written ([`start_writeback`]): 1.3 ms here, against 1.9 ms without.
fn sync_files(files: &[std::fs::File]) -> std::io::Result<()> {
    let per_thread = files.len().div_ceil(SYNC_THREADS).max(1);
    std::thread::scope(|s| {
        let handles: Vec<_> = files
            .chunks(per_thread)
            .map(|chunk| {
                let sync = move || chunk.iter().try_for_each(std::fs::File::sync_data);
                std::thread::Builder::new()
                    .spawn_scoped(s, sync)
                    .map_err(|_| sync)
            })
            .collect();
        handles.into_iter().try_for_each(|h| match h {
            Ok(h) => h
                .join()
                .unwrap_or_else(|_| Err(std::io::Error::other("sync panicked"))),
            // Without a thread to be had, the chunk is synced here.
            Err(sync) => sync(),
        })
    })
}

/// [`write_atomic`]'s part after the temporary file is created.
fn write_temp(mut tmp: tempfile::NamedTempFile, path: &Path, bytes: &[u8]) -> Result<()> {
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

/// What this process is writing and has not committed: staging directories and
/// temporary files, removed by [`remove_unfinished`] when a signal stops the run
/// (a destructor does not run then).
static UNFINISHED: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

fn unfinished() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    UNFINISHED.lock().unwrap_or_else(|e| e.into_inner())
}

fn track(path: &Path) {
    unfinished().push(path.to_path_buf());
}

fn untrack(path: &Path) {
    unfinished().retain(|p| p != path);
}

/// Removes everything this process staged or is writing and has not committed,
/// and blocks any new staging for the rest of the process: for the end of a run
/// stopped by a signal, just before it exits. Returns what it removed.
pub fn remove_unfinished() -> Vec<PathBuf> {
    let list = unfinished();
    let mut removed = Vec::new();
    for path in list.iter() {
        // Workers may still be creating files in it: a few rounds catch them.
        for _ in 0..10 {
            let gone = match std::fs::symlink_metadata(path) {
                Err(_) => true,
                Ok(m) if m.is_dir() => std::fs::remove_dir_all(path).is_ok(),
                Ok(_) => std::fs::remove_file(path).is_ok(),
            };
            if gone {
                break;
            }
        }
        if std::fs::symlink_metadata(path).is_err() {
            removed.push(path.clone());
        }
    }
    // Held until the process exits, so no thread stages anything new.
    std::mem::forget(list);
    removed
}

/// Most symbolic links followed when resolving an output path (the kernel's own limit).
const MAX_LINKS: usize = 40;

/// The directory `target` names, absolute: a symbolic link in its place is
/// followed (even to where nothing exists yet) and the longest existing prefix
/// is canonicalised, so a link stays a link, the link's target receives the
/// results, and every alias of one directory takes the same lock.
fn resolve(target: &Path) -> Result<PathBuf> {
    let mut path = std::path::absolute(target).map_err(|e| Error::io(target, e))?;
    let mut links = 0;
    while std::fs::symlink_metadata(&path).is_ok_and(|m| m.file_type().is_symlink()) {
        links += 1;
        if links > MAX_LINKS {
            return Err(Error::Invalid(format!(
                "{}: more than {MAX_LINKS} symbolic links (a loop?)",
                target.display()
            )));
        }
        let to = std::fs::read_link(&path).map_err(|e| Error::io(&path, e))?;
        path = path.parent().unwrap_or(Path::new("/")).join(to);
    }
    let (mut existing, mut rest) = (path.clone(), Vec::new());
    while std::fs::symlink_metadata(&existing).is_err() {
        match existing.file_name() {
            Some(name) => rest.push(name.to_os_string()),
            None => break,
        }
        existing.pop();
    }
    let mut resolved = existing
        .canonicalize()
        .map_err(|e| Error::io(&existing, e))?;
    resolved.extend(rest.iter().rev());
    Ok(resolved)
}

/// Ownership and mode of a directory, to give the swapped-in set.
#[derive(Debug, Clone, Copy)]
struct DirMode {
    mode: u32,
    owner: Option<(u32, u32)>,
}

#[cfg(unix)]
fn dir_mode(meta: &std::fs::Metadata, with_owner: bool) -> DirMode {
    use std::os::unix::fs::MetadataExt;
    DirMode {
        mode: meta.mode() & 0o7777,
        owner: with_owner.then(|| (meta.uid(), meta.gid())),
    }
}

#[cfg(not(unix))]
fn dir_mode(_: &std::fs::Metadata, _: bool) -> DirMode {
    DirMode {
        mode: 0o755,
        owner: None,
    }
}

/// Gives `dir` the owner (where permitted) and then the mode of `to`: a chown by
/// an ordinary user clears the set-group-id bit, so the mode goes last.
fn apply_mode(dir: &Path, to: DirMode) {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        if let Some((uid, gid)) = to.owner {
            if std::os::unix::fs::chown(dir, Some(uid), Some(gid)).is_err() {
                // Not the owner's to give away: the group alone may still be ours.
                let _ = std::os::unix::fs::chown(dir, None, Some(gid));
            }
        }
        let _ = std::fs::set_permissions(dir, std::fs::Permissions::from_mode(to.mode));
    }
    #[cfg(not(unix))]
    let _ = (dir, to);
}

/// Checks before any work that the swap can happen: a directory can be created
/// in `parent` and renamed there (its mode is what a new output directory gets),
/// and `target`, if it exists, can be renamed away and back (not immutable, not a
/// mount point, not in a sticky directory of another user). Returns the new
/// directory's mode.
fn probe_swap(parent: &Path, name: &str, target: &Path) -> Result<DirMode> {
    let pid = std::process::id();
    let probe = parent.join(format!(".{name}.probe-{pid}"));
    let moved = parent.join(format!(".{name}.probe-{pid}-moved"));
    std::fs::create_dir(&probe).map_err(|e| Error::write(parent, e))?;
    let mode = std::fs::metadata(&probe).map(|m| dir_mode(&m, false));
    let renamed = std::fs::rename(&probe, &moved);
    let _ = std::fs::remove_dir(&probe);
    let _ = std::fs::remove_dir(&moved);
    renamed.map_err(|e| Error::write(parent, e))?;
    let mode = mode.map_err(|e| Error::io(parent, e))?;
    if target.is_dir() {
        let aside = parent.join(format!(".{name}.old-{pid}-probe"));
        std::fs::rename(target, &aside).map_err(|e| {
            Error::write(
                target,
                std::io::Error::new(
                    e.kind(),
                    format!("the output directory cannot be replaced ({e})"),
                ),
            )
        })?;
        std::fs::rename(&aside, target).map_err(|e| {
            Error::write(
                target,
                std::io::Error::new(
                    e.kind(),
                    format!(
                        "moved to {} and cannot be moved back ({e})",
                        aside.display()
                    ),
                ),
            )
        })?;
    }
    Ok(mode)
}

/// Removes what earlier runs on `target` left beside it when they died (a
/// SIGKILL, a power cut): staging and probe directories, and a set-aside old
/// output, which goes back in place if the swap stopped half way. Called under
/// the lock, which no live run on `target` holds: all of these are stale.
fn remove_stale(parent: &Path, name: &str, target: &Path) {
    let Ok(entries) = std::fs::read_dir(parent) else {
        return;
    };
    let (new, old, probe) = (
        format!(".{name}.new-"),
        format!(".{name}.old-"),
        format!(".{name}.probe-"),
    );
    for entry in entries.flatten() {
        let file = entry.file_name().to_string_lossy().to_string();
        let path = entry.path();
        if file.starts_with(&old) && !target.exists() && std::fs::rename(&path, target).is_ok() {
            continue;
        }
        if file.starts_with(&new) || file.starts_with(&old) {
            remove_tree(&path);
        } else if file.starts_with(&probe) {
            let _ = std::fs::remove_dir(&path);
        }
    }
}

/// A result set being written: a staging directory beside the output directory,
/// held under the output directory's advisory lock until [`OutputSet::commit`]
/// swaps it in. Dropped without a commit, it leaves the old output untouched.
pub struct OutputSet {
    /// The output directory, resolved ([`resolve`]).
    target: PathBuf,
    /// The mode of a new output directory (the umask's default in its parent).
    new_mode: DirMode,
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
    /// Takes the lock of `target`, removes what dead runs left, checks that the
    /// swap can happen and creates the staging directory: call it before the
    /// work, so an unwritable, busy or unreplaceable output fails at once.
    pub fn begin(target: &Path, owns: Owns) -> Result<OutputSet> {
        let needs_name = || {
            Error::Invalid(format!(
                "{}: the output directory needs a name (not `.` or `/`)",
                target.display()
            ))
        };
        target
            .file_name()
            .filter(|n| *n != "." && *n != "..")
            .ok_or_else(needs_name)?;
        let given = target;
        let target = resolve(given)?;
        if target.exists() && !target.is_dir() {
            return Err(Error::write(
                given,
                std::io::Error::other("exists and is not a directory"),
            ));
        }
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .ok_or_else(needs_name)?;
        let parent = target.parent().ok_or_else(needs_name)?.to_path_buf();
        std::fs::create_dir_all(&parent).map_err(|e| Error::write(&parent, e))?;
        let lock_file = lock_path(&parent, &name);
        let lock = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&lock_file)
            .map_err(|e| Error::write(&lock_file, e))?;
        match lock.try_lock_exclusive() {
            Ok(true) => {}
            Ok(false) => return Err(Error::Locked(given.into())),
            Err(e) => return Err(Error::write(&lock_file, e)),
        }
        remove_stale(&parent, &name, &target);
        let new_mode = probe_swap(&parent, &name, &target)?;
        // Tracked before it exists: a signal in between finds nothing to remove.
        let mut unfinished = unfinished();
        let staging = tempfile::Builder::new()
            .prefix(&format!(".{name}.new-{}-", std::process::id()))
            .tempdir_in(&parent)
            .map_err(|e| Error::write(&parent, e))?;
        unfinished.push(staging.path().to_path_buf());
        drop(unfinished);
        staged().push((staging.path().to_path_buf(), Vec::new()));
        Ok(OutputSet {
            target,
            new_mode,
            staging: Some(staging),
            owns,
            _lock: lock,
        })
    }

    /// The directory to write the new set into.
    pub fn path(&self) -> &Path {
        self.staging.as_ref().expect("staging until commit").path()
    }

    /// The output directory the set will replace, resolved (a symbolic link
    /// followed, absolute).
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Carries over what the old output holds besides this kind of set, then swaps
    /// the staged set in: old directory aside, new one in place, old one removed.
    /// The new directory keeps the old one's mode and owner (where permitted).
    /// On any failure the staging directory is removed and the old output is
    /// left as it was.
    pub fn commit(mut self) -> Result<()> {
        let staging = self.staging.take().expect("staging until commit");
        let new = staging.path().to_path_buf();
        // The set's files reach the disk before the swap makes them the output.
        let written = forget_staged(&new);
        if let Err(e) = sync_files(&written) {
            untrack(&new);
            return Err(Error::write(&new, e));
        }
        drop(written);
        let target = self.target.clone();
        let mut dirs = Vec::new();
        let mut mode = self.new_mode;
        if target.is_dir() {
            let meta = std::fs::metadata(&target).map_err(|e| Error::io(&target, e))?;
            mode = dir_mode(&meta, true);
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
        apply_mode(&new, mode);
        // Sub-directories move last, just before the swap, and move back if the
        // swap fails, so a failure leaves the old output whole.
        let mut moved = Vec::new();
        let swapped = (|| {
            for (from, to) in &dirs {
                std::fs::rename(from, to).map_err(|e| Error::write(to, e))?;
                moved.push((from, to));
            }
            swap(&new, &target)
        })();
        if swapped.is_err() {
            for (from, to) in moved.iter().rev() {
                let _ = std::fs::rename(to, from);
            }
            // TempDir's drop removes the staging directory.
            drop(staging);
        } else {
            let _ = staging.keep();
        }
        untrack(&new);
        swapped
    }
}

/// Moves `target` (if any) aside, `new` into its place, and removes the old one;
/// if `new` cannot go in place, the old output goes back.
fn swap(new: &Path, target: &Path) -> Result<()> {
    let parent = new.parent().expect("staging has a parent");
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    let aside = if target.exists() {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.subsec_nanos())
            .unwrap_or(0);
        let aside = parent.join(format!(".{name}.old-{}-{nanos}", std::process::id()));
        std::fs::rename(target, &aside).map_err(|e| Error::write(target, e))?;
        Some(aside)
    } else {
        None
    };
    if let Err(e) = std::fs::rename(new, target) {
        if let Some(aside) = &aside {
            let _ = std::fs::rename(aside, target);
        }
        return Err(Error::write(target, e));
    }
    if let Some(old) = aside {
        remove_tree(&old);
    }
    Ok(())
}

/// Most threads [`remove_tree`] unlinks with.
const UNLINK_THREADS: usize = 16;

/// Removes directory `dir` and everything in it, best effort (the set is already
/// swapped in), the entries of its sub-directories side by side: on a file system
/// mounted with `discard` each unlink of a synced file waits for its blocks to be
/// trimmed, 1–9 ms each on this project's machines, and concurrent unlinks share
/// the wait (a calibration's 9 files while other processes wrote to the disk:
/// 20–30 ms one after the other, 4–6 ms side by side).
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

/// Takes staging directory `dir` off [`STAGED`], with the files written into it.
fn forget_staged(dir: &Path) -> Vec<std::fs::File> {
    let mut staged = staged();
    match staged.iter().position(|(d, _)| d == dir) {
        Some(i) => staged.swap_remove(i).1,
        None => Vec::new(),
    }
}

impl Drop for OutputSet {
    fn drop(&mut self) {
        // An uncommitted staging directory is removed by TempDir's own drop.
        if let Some(staging) = self.staging.take() {
            let path = staging.path().to_path_buf();
            forget_staged(&path);
            drop(staging);
            untrack(&path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::tidy_path;
    use std::path::Path;

    #[test]
    fn tidy_paths_name_the_same_place() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::create_dir_all(d.join("configs")).unwrap();
        std::fs::create_dir_all(d.join("elsewhere/inner")).unwrap();
        std::os::unix::fs::symlink(d.join("elsewhere/inner"), d.join("linked")).unwrap();
        let tidy = tidy_path(&d.join("configs/../out/t2"));
        assert_eq!(tidy, d.join("out/t2"));
        // Through a link `..` is the target's parent, so it stays, and the
        // kernel's answer is the same for both spellings.
        let through_link = d.join("linked/../out");
        assert_eq!(tidy_path(&through_link), through_link);
        std::fs::create_dir_all(d.join("elsewhere/out")).unwrap();
        assert_eq!(
            through_link.canonicalize().unwrap(),
            d.join("elsewhere/out").canonicalize().unwrap()
        );
        assert_eq!(tidy_path(Path::new("./x")), Path::new("./x"));
        assert_eq!(tidy_path(Path::new("../x")), Path::new("../x"));
    }
}
