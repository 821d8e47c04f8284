//! What the command line puts around the core's work: a progress bar on stderr, and
//! Ctrl-C or SIGTERM turned into a cancel. An interrupted command then leaves the way a
//! cancelled host call does (temporary files and spools removed, an earlier output
//! untouched, the terminal's settings restored) instead of dying where it stood.

use crate::error::{Error, Result};
use crate::progress::Progress;
use indicatif::{ProgressBar, ProgressStyle};
use std::sync::atomic::{AtomicBool, Ordering};

/// Exit status of a command stopped by an interrupt (the shell's 128 + SIGINT).
const INTERRUPTED_STATUS: u8 = 130;

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_interrupt(_signal: libc::c_int) {
    // Only async-signal-safe work here: an atomic store, or _exit.
    if INTERRUPTED.swap(true, Ordering::SeqCst) {
        // The second interrupt: the user wants out now, cleaned up or not.
        unsafe { libc::_exit(INTERRUPTED_STATUS as libc::c_int) };
    }
}

/// Makes SIGINT and SIGTERM set [`interrupted`] instead of ending the process; a second
/// one ends it at once. Called once, at the start of `main`. System calls are not
/// restarted after the handler (no `SA_RESTART`): a read waiting for a key returns, so
/// the interactive slider can quit and restore the terminal.
pub fn catch_interrupts() {
    // SAFETY: a zeroed sigaction is valid (empty mask, no flags), and the handler only
    // touches an atomic or calls _exit.
    unsafe {
        let mut action: libc::sigaction = std::mem::zeroed();
        action.sa_sigaction = on_interrupt as extern "C" fn(libc::c_int) as libc::sighandler_t;
        libc::sigemptyset(&mut action.sa_mask);
        for signal in [libc::SIGINT, libc::SIGTERM] {
            libc::sigaction(signal, &action, std::ptr::null_mut());
        }
    }
}

/// The exit status of a command that an interrupt stopped (130, as shells give).
pub fn interrupted_exit_code() -> std::process::ExitCode {
    std::process::ExitCode::from(INTERRUPTED_STATUS)
}

/// True once SIGINT or SIGTERM has arrived (after [`catch_interrupts`]).
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

/// Runs `work` with a progress bar on stderr (hidden when `quiet`, and by indicatif when
/// stderr is not a terminal), cleared afterwards. Its progress answers "stop" once the
/// command is interrupted, so the work ends with [`Error::Cancelled`].
pub fn with_progress<T>(quiet: bool, work: impl FnOnce(&mut Progress) -> Result<T>) -> Result<T> {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(1000)
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {percent:>3}% {msg}")
            .map_err(|e| Error::InvalidInput(format!("progress bar: {e}")))?,
    );
    let mut report = |fraction: f64, phase: &str| {
        bar.set_position((fraction * 1000.0) as u64);
        bar.set_message(phase.to_string());
        !interrupted()
    };
    let out = work(&mut Progress::new(&mut report));
    bar.finish_and_clear();
    out
}
