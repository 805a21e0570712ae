//! The command line's commands, one module per command or group: each has its
//! clap `Args` and a `run` function; `src/main.rs` only parses and dispatches.
//! This is the application's outer edge: errors are `anyhow`, messages name the
//! file, line, key or flag, and progress goes to stderr.
pub mod calibrate;
pub mod data;
pub mod flags;
pub mod models;
pub mod protocol;
pub mod sfm;
pub mod signals;

/// How long a step runs before [`with_progress_line`] shows that it is running.
pub(crate) const PROGRESS_AFTER: std::time::Duration = std::time::Duration::from_secs(2);

/// Runs `work` and, once it has run for [`PROGRESS_AFTER`], a progress line on
/// stderr (`message` and the time elapsed) until it ends: a short run prints
/// nothing, and indicatif draws only on a terminal. The work itself (one solve)
/// cannot report how far it is, so the line says that it is running and since
/// when.
pub(crate) fn with_progress_line<T>(message: &str, work: impl FnOnce() -> T) -> T {
    with_progress_after(
        message,
        PROGRESS_AFTER,
        indicatif::ProgressDrawTarget::stderr(),
        work,
    )
}

/// [`with_progress_line`] with its delay and draw target given.
///
/// The line's thread is waited for only if it drew the line (which it then
/// clears): after a short step it ends on its own, and the run does not wait
/// for it to be scheduled (1–2 ms on a loaded machine).
pub(crate) fn with_progress_after<T>(
    message: &str,
    after: std::time::Duration,
    target: indicatif::ProgressDrawTarget,
    work: impl FnOnce() -> T,
) -> T {
    use std::sync::mpsc::{channel, RecvTimeoutError};
    use std::sync::{Arc, Mutex};
    // (the work ended, the line was drawn)
    let state = Arc::new(Mutex::new((false, false)));
    let (done, finished) = channel::<()>();
    let (shared, message) = (Arc::clone(&state), message.to_string());
    let draw = move || {
        // Dropping `done` (the work ended, or panicked) disconnects the channel.
        if finished.recv_timeout(after) != Err(RecvTimeoutError::Timeout) {
            return;
        }
        {
            let mut s = shared.lock().unwrap_or_else(|e| e.into_inner());
            if s.0 {
                return;
            }
            s.1 = true;
        }
        let style = indicatif::ProgressStyle::with_template("{spinner} {msg} ({elapsed})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner());
        let line = indicatif::ProgressBar::with_draw_target(None, target)
            .with_style(style)
            .with_message(message)
            .with_elapsed(after);
        line.enable_steady_tick(std::time::Duration::from_millis(200));
        let _ = finished.recv();
        line.finish_and_clear();
    };
    let thread = std::thread::Builder::new().spawn(draw).ok();
    let end = End(state, Some(done), thread);
    let out = work();
    drop(end);
    out
}

/// The end of [`with_progress_after`]'s work, also when it panics: marks it
/// ended, disconnects the line's thread and waits for it only if it drew the line
/// (to be cleared before anything else is printed).
struct End(
    std::sync::Arc<std::sync::Mutex<(bool, bool)>>,
    Option<std::sync::mpsc::Sender<()>>,
    Option<std::thread::JoinHandle<()>>,
);

impl Drop for End {
    fn drop(&mut self) {
        let drawn = {
            let mut s = self.0.lock().unwrap_or_else(|e| e.into_inner());
            s.0 = true;
            s.1
        };
        drop(self.1.take());
        if let (true, Some(thread)) = (drawn, self.2.take()) {
            let _ = thread.join();
        }
    }
}

/// A progress bar on stderr with `template` (indicatif's syntax).
pub(crate) fn progress_bar(len: u64, template: &str) -> indicatif::ProgressBar {
    let style = indicatif::ProgressStyle::with_template(template)
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> ");
    indicatif::ProgressBar::new(len).with_style(style)
}

#[cfg(test)]
mod tests {
    use super::with_progress_after;
    use std::io;
    use std::sync::{Arc, Mutex};
    use std::time::Duration;

    /// A terminal that keeps what was written to it.
    #[derive(Debug, Clone, Default)]
    struct Recorder(Arc<Mutex<String>>);

    impl indicatif::TermLike for Recorder {
        fn width(&self) -> u16 {
            100
        }
        fn move_cursor_up(&self, _: usize) -> io::Result<()> {
            Ok(())
        }
        fn move_cursor_down(&self, _: usize) -> io::Result<()> {
            Ok(())
        }
        fn move_cursor_right(&self, _: usize) -> io::Result<()> {
            Ok(())
        }
        fn move_cursor_left(&self, _: usize) -> io::Result<()> {
            Ok(())
        }
        fn write_line(&self, s: &str) -> io::Result<()> {
            self.write_str(&format!("{s}\n"))
        }
        fn write_str(&self, s: &str) -> io::Result<()> {
            self.0.lock().unwrap().push_str(s);
            Ok(())
        }
        fn clear_line(&self) -> io::Result<()> {
            Ok(())
        }
        fn flush(&self) -> io::Result<()> {
            Ok(())
        }
    }

    fn run(work: Duration) -> (u32, String) {
        let term = Recorder::default();
        let target = indicatif::ProgressDrawTarget::term_like(Box::new(term.clone()));
        let out = with_progress_after("solving", Duration::from_millis(100), target, || {
            std::thread::sleep(work);
            7
        });
        let written = term.0.lock().unwrap().clone();
        (out, written)
    }

    #[test]
    fn a_long_step_shows_its_progress_line_and_a_short_one_nothing() {
        let (out, written) = run(Duration::from_millis(700));
        assert_eq!(out, 7);
        assert!(written.contains("solving"), "{written:?}");
        let (out, written) = run(Duration::ZERO);
        assert_eq!(out, 7);
        assert!(written.is_empty(), "{written:?}");
    }
}
