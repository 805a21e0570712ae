//! How the process ends on a stop signal (Ctrl-C, `kill`, a closed terminal):
//! the unfinished output removed, one `error:` line, exit 128 + the signal.
use crate::app::fsio;

/// The signals that stop a run: Ctrl-C, `kill`, a closed terminal.
const STOP_SIGNALS: [(libc::c_int, &str); 3] = [
    (libc::SIGINT, "SIGINT"),
    (libc::SIGTERM, "SIGTERM"),
    (libc::SIGHUP, "SIGHUP"),
];

/// Stops the run cleanly on [`STOP_SIGNALS`]: they are blocked in every thread
/// (threads inherit the mask, so this runs before any is started) and taken by
/// one thread with `sigwait`, which then runs ordinary code, not a handler: it
/// removes the unfinished output, says so on one `error:` line and exits
/// 128 + the signal, as a shell reports it. SIGXFSZ (a file size limit) is
/// ignored, so the write fails with "File too large" and the run ends through
/// its ordinary error path.
pub fn handle_signals() {
    // SAFETY: an empty sigset_t filled by sigemptyset/sigaddset, and masks and
    // dispositions changed before any other thread exists.
    let set = unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        for (signal, _) in STOP_SIGNALS {
            libc::sigaddset(&mut set, signal);
        }
        libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut());
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
        set
    };
    let watch = move || loop {
        let mut signal: libc::c_int = 0;
        // SAFETY: `set` is initialised and its signals are blocked in this thread.
        if unsafe { libc::sigwait(&set, &mut signal) } != 0 {
            continue;
        }
        let name = STOP_SIGNALS
            .iter()
            .find(|(s, _)| *s == signal)
            .map_or("a signal", |(_, n)| n);
        let removed = fsio::remove_unfinished();
        let what = if removed.is_empty() {
            String::new()
        } else {
            "; removed the unfinished output".to_string()
        };
        eprintln!("error: stopped by {name}{what}");
        // SAFETY: _exit ends the process without running atexit handlers, which
        // could race the solver threads still running.
        unsafe { libc::_exit(128 + signal) };
    };
    // Without the thread the signals stay blocked; better to let them act.
    if std::thread::Builder::new()
        .name("signals".into())
        .spawn(watch)
        .is_err()
    {
        // SAFETY: as above.
        unsafe { libc::pthread_sigmask(libc::SIG_UNBLOCK, &set, std::ptr::null_mut()) };
    }
}
