//! OpenCV's sample stereo photos (left01…right14.jpg: a hand-held 9×6 board,
//! 640×480, from Debian's opencv-doc), fetched once for the tests and benches that
//! use them.
//!
//! The package is 96 MB; it is fetched with `apt-get download`, only the photos are
//! kept (extracted with `dpkg-deb`) under target/, and a caller skips, with the
//! reason printed, when the download is impossible (no network, no apt).
use std::path::{Path, PathBuf};
use std::process::Command;

/// Where the package keeps the photos.
const DATA: &str = "./usr/share/doc/opencv-doc/examples/data";

/// The photos' folder, fetched and extracted if needed; Err with the reason.
pub fn sample_photos() -> Result<PathBuf, String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-data/opencv-doc");
    let done = dir.join("photos/.complete");
    if done.exists() {
        return Ok(dir.join("photos"));
    }
    let work = dir.join("download");
    let _ = std::fs::remove_dir_all(&work);
    std::fs::create_dir_all(&work).map_err(|e| e.to_string())?;
    let run = |cmd: &mut Command| -> Result<(), String> {
        let out = cmd.output().map_err(|e| format!("{cmd:?}: {e}"))?;
        if out.status.success() {
            Ok(())
        } else {
            Err(format!(
                "{cmd:?} failed: {}",
                String::from_utf8_lossy(&out.stderr).trim()
            ))
        }
    };
    run(Command::new("apt-get")
        .args(["download", "opencv-doc"])
        .current_dir(&work))?;
    let deb = std::fs::read_dir(&work)
        .map_err(|e| e.to_string())?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "deb"))
        .ok_or("apt-get download left no .deb")?;
    // Only the photos: dpkg-deb streams the package's files, tar keeps the few we need.
    let script = format!(
        "dpkg-deb --fsys-tarfile '{}' | tar -x -C '{}' --wildcards '{DATA}/left[0-9][0-9].jpg' '{DATA}/right[0-9][0-9].jpg'",
        deb.display(),
        work.display()
    );
    run(Command::new("sh").args(["-c", &script]))?;
    let photos = dir.join("photos");
    let _ = std::fs::remove_dir_all(&photos);
    std::fs::rename(work.join(DATA), &photos).map_err(|e| e.to_string())?;
    let _ = std::fs::remove_dir_all(&work);
    std::fs::write(&done, b"").map_err(|e| e.to_string())?;
    Ok(photos)
}
