//! A video's frames through Debian's `ffmpeg` and `ffprobe` binaries (docs/video.md
//! says why the binaries rather than a binding): `ffprobe` gives the size and every
//! frame's presentation time from the packets (no decoding), and `ffmpeg` decodes
//! every `stride`-th frame to 8-bit grey on a pipe, read one frame at a time so a
//! long video never sits in memory. Frames come out upright: ffmpeg turns them by
//! the rotation metadata as players do, and the size given is the turned one.
//! Nothing here knows of boards.
use crate::error::{Error, Result};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};

/// The decoder program (on `PATH`).
pub const FFMPEG: &str = "ffmpeg";
/// The prober program (on `PATH`; Debian's `ffmpeg` package has both).
pub const FFPROBE: &str = "ffprobe";

/// Frames beyond this are refused before decoding (about 9 hours at 30 fps).
pub const MAX_FRAMES: usize = 1_000_000;

/// What `ffprobe` says of the first video stream.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// Frame width in pixels as displayed: rotation metadata applied, as
    /// ffmpeg applies it when decoding.
    pub width: u32,
    /// Frame height in pixels as displayed.
    pub height: u32,
    /// The clockwise quarter turn (0, 90, 180 or 270°) from the stored frames to
    /// the displayed ones.
    pub turned: u32,
    /// Presentation time (s) of every frame, in display order.
    pub times: Vec<f64>,
}

fn video_err(path: &Path, message: impl Into<String>) -> Error {
    Error::Video {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Runs a program to its end; a program that is not installed is named with the
/// package to install.
fn run(program: &str, args: &[&std::ffi::OsStr], path: &Path) -> Result<std::process::Output> {
    Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| missing(program, path, e))
}

fn missing(program: &str, path: &Path, e: std::io::Error) -> Error {
    if e.kind() == std::io::ErrorKind::NotFound {
        video_err(
            path,
            format!(
                "`{program}` is not installed (Debian: apt-get install ffmpeg); it decodes videos"
            ),
        )
    } else {
        video_err(path, format!("cannot run `{program}`: {e}"))
    }
}

/// The first line ffmpeg or ffprobe wrote on stderr, for a one-line message.
fn first_line(stderr: &[u8]) -> String {
    let text = String::from_utf8_lossy(stderr);
    let line = text.lines().find(|l| !l.trim().is_empty()).unwrap_or("");
    let line = line.trim();
    if line.chars().count() > 200 {
        format!("{}…", line.chars().take(200).collect::<String>())
    } else {
        line.to_string()
    }
}

/// The size and frame times of `path`'s first video stream.
pub fn probe(path: &Path) -> Result<Probe> {
    if let Err(e) = std::fs::metadata(path) {
        return Err(Error::io(path, e));
    }
    let stream = ffprobe(
        path,
        "stream=width,height:stream_side_data=rotation:stream_tags=rotate",
        "default=nw=1",
    )?;
    let (width, height, turn) =
        parse_stream(&stream).ok_or_else(|| video_err(path, "has no video stream"))?;
    let (width, height) = if turn % 180 == 90 {
        (height, width)
    } else {
        (width, height)
    };
    crate::app::detect::load::check_size(
        width,
        height,
        crate::app::detect::Detector::default().max_pixels,
    )
    .map_err(|r| video_err(path, r.to_string()))?;
    let times = frame_times(&ffprobe(path, "packet=pts_time", "csv=p=0")?);
    if times.is_empty() {
        return Err(video_err(path, "has no frames"));
    }
    if times.len() > MAX_FRAMES {
        return Err(video_err(
            path,
            format!("has {} frames, more than {MAX_FRAMES}", times.len()),
        ));
    }
    Ok(Probe {
        width,
        height,
        turned: turn,
        times,
    })
}

/// What `ffprobe` prints of `entries` of the first video stream in `format`; an
/// error with its first message when it fails.
fn ffprobe(path: &Path, entries: &str, format: &str) -> Result<String> {
    let os = std::ffi::OsStr::new;
    let out = run(
        FFPROBE,
        &[
            os("-v"),
            os("error"),
            os("-select_streams"),
            os("v:0"),
            os("-show_entries"),
            os(entries),
            os("-of"),
            os(format),
            path.as_os_str(),
        ],
        path,
    )?;
    if !out.status.success() {
        return Err(video_err(
            path,
            format!("not a readable video: {}", first_line(&out.stderr)),
        ));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Stored width, height and the clockwise turn (0, 90, 180 or 270°) that
/// ffmpeg applies for display, from ffprobe's `key=value` lines; None without a
/// video stream. The display matrix's `rotation` is counter-clockwise
/// (libavutil's `av_display_rotation_get`); older files may carry only the
/// `rotate` tag, which is clockwise. ffmpeg turns frames only by quarter turns
/// (within 1°); other angles keep the stored size, so they count as 0 here.
fn parse_stream(text: &str) -> Option<(u32, u32, u32)> {
    let value = |key: &str| {
        text.lines()
            .find_map(|l| l.trim().strip_prefix(key)?.strip_prefix('='))
            .map(str::trim)
    };
    let width: u32 = value("width")?.parse().ok()?;
    let height: u32 = value("height")?.parse().ok()?;
    if width == 0 || height == 0 {
        return None;
    }
    let clockwise = match value("rotation").and_then(|v| v.parse::<f64>().ok()) {
        Some(ccw) => -ccw,
        None => value("TAG:rotate")
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0),
    };
    let c = clockwise.rem_euclid(360.0);
    let turn = [90u32, 180, 270]
        .into_iter()
        .find(|&q| (c - q as f64).abs() < 1.0)
        .unwrap_or(0);
    Some((width, height, turn))
}

/// Frame times from ffprobe's packet times (decode order, so sorted here into
/// display order); a packet without a time gets its neighbour's (it keeps its place).
fn frame_times(csv: &str) -> Vec<f64> {
    let raw: Vec<Option<f64>> = csv
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.trim().trim_end_matches(',').parse::<f64>().ok())
        .collect();
    let mut last = 0.0;
    let mut times: Vec<f64> = raw
        .into_iter()
        .map(|t| {
            let t = t.filter(|t| t.is_finite()).unwrap_or(last);
            last = t;
            t
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times
}

/// A running decode of every `stride`-th frame as 8-bit grey.
pub struct Frames {
    child: Child,
    stdout: ChildStdout,
    stderr: Option<std::thread::JoinHandle<Vec<u8>>>,
    path: PathBuf,
    width: u32,
    height: u32,
    stride: usize,
    next: usize,
    /// The output ended inside a frame: ffmpeg's frames are not of the size
    /// the probe gave.
    torn: bool,
}

/// One decoded frame.
pub struct Frame {
    /// The frame's index in the video (0-based, display order).
    pub index: usize,
    /// Grey levels, row by row.
    pub image: image::GrayImage,
}

impl Frames {
    /// Starts `ffmpeg` on `path` (whose size `probe` gave).
    pub fn start(path: &Path, probe: &Probe, stride: usize) -> Result<Frames> {
        let select = format!("select=not(mod(n\\,{stride}))");
        let mut child = Command::new(FFMPEG)
            .args(["-nostdin", "-v", "error", "-i"])
            .arg(path)
            .args(["-map", "0:v:0", "-vf", &select, "-fps_mode", "passthrough"])
            .args(["-f", "rawvideo", "-pix_fmt", "gray", "-"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| missing(FFMPEG, path, e))?;
        let stdout = child.stdout.take().expect("stdout is piped");
        let mut err = child.stderr.take().expect("stderr is piped");
        // Read stderr on its own thread: a full stderr pipe would stall ffmpeg.
        let stderr = std::thread::spawn(move || {
            let mut buf = Vec::new();
            let _ = (&mut err).take(64 * 1024).read_to_end(&mut buf);
            let _ = std::io::copy(&mut err, &mut std::io::sink());
            buf
        });
        Ok(Frames {
            child,
            stdout,
            stderr: Some(stderr),
            path: path.to_path_buf(),
            width: probe.width,
            height: probe.height,
            stride,
            next: 0,
            torn: false,
        })
    }

    /// The next frame, `None` at the end of the video.
    pub fn next_frame(&mut self) -> Result<Option<Frame>> {
        let mut buf = vec![0u8; self.width as usize * self.height as usize];
        let mut filled = 0;
        while filled < buf.len() {
            match self.stdout.read(&mut buf[filled..]) {
                Ok(0) => break,
                Ok(n) => filled += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(video_err(&self.path, format!("reading from ffmpeg: {e}"))),
            }
        }
        if filled < buf.len() {
            self.torn = filled > 0;
            return Ok(None);
        }
        let image = image::GrayImage::from_raw(self.width, self.height, buf)
            .expect("the buffer has width × height bytes");
        let index = self.next * self.stride;
        self.next += 1;
        Ok(Some(Frame { index, image }))
    }

    /// Waits for ffmpeg; an error with its first message when it failed.
    pub fn finish(mut self) -> Result<()> {
        let _ = std::io::copy(&mut self.stdout, &mut std::io::sink());
        let status = self
            .child
            .wait()
            .map_err(|e| video_err(&self.path, format!("waiting for ffmpeg: {e}")))?;
        let stderr = self
            .stderr
            .take()
            .and_then(|h| h.join().ok())
            .unwrap_or_default();
        if status.success() && self.torn {
            return Err(video_err(
                &self.path,
                format!(
                    "ffmpeg's frames are not {}x{} as ffprobe said",
                    self.width, self.height
                ),
            ));
        }
        if status.success() {
            return Ok(());
        }
        Err(video_err(
            &self.path,
            format!("ffmpeg could not decode it: {}", first_line(&stderr)),
        ))
    }
}

impl Drop for Frames {
    /// A decode abandoned early (an error, a panic) does not leave ffmpeg running.
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packet_times_become_display_order() {
        let t = frame_times("0.066667\n0.000000\n0.033333,\nN/A\n0.1\n");
        assert_eq!(t, vec![0.0, 0.033333, 0.033333, 0.066667, 0.1]);
    }

    #[test]
    fn quarter_turns_from_the_display_matrix_or_the_old_tag() {
        let p = |s: &str| parse_stream(s);
        assert_eq!(p("width=1920\nheight=1080\n"), Some((1920, 1080, 0)));
        // Counter-clockwise 90° in the display matrix is a clockwise turn of 270°.
        assert_eq!(
            p("width=1920\nheight=1080\nrotation=90\n"),
            Some((1920, 1080, 270))
        );
        assert_eq!(
            p("width=1920\nheight=1080\nrotation=-90.00\n"),
            Some((1920, 1080, 90))
        );
        assert_eq!(p("width=8\nheight=6\nrotation=180\n"), Some((8, 6, 180)));
        // Only the legacy tag (clockwise); the matrix wins when both are there.
        assert_eq!(p("width=8\nheight=6\nTAG:rotate=90\n"), Some((8, 6, 90)));
        assert_eq!(
            p("width=8\nheight=6\nrotation=-90\nTAG:rotate=90\n"),
            Some((8, 6, 90))
        );
        // ffmpeg turns only by quarter turns; other angles keep the size.
        assert_eq!(p("width=8\nheight=6\nrotation=30\n"), Some((8, 6, 0)));
        assert_eq!(p("width=0\nheight=6\n"), None);
        assert_eq!(p(""), None);
    }
}
