//! A process-wide request to stop, set from a signal handler (the CLI's SIGINT handler) and
//! polled by long offline builds between frames, before anything is written.
//!
//! A build that sees the request returns [`Error::Interrupted`] without writing any output:
//! the output directory keeps what it held before (every file is replaced atomically, and
//! the export itself, once started, is not interrupted), so a stopped build leaves either
//! the previous outputs or complete new ones.
//!
//! Exports: [`request_stop`], and [`check`] for the loops that honour it.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::error::{Error, Result};

static STOP: AtomicBool = AtomicBool::new(false);

/// Asks running builds to stop at their next check. Safe to call from a signal handler.
pub fn request_stop() {
    STOP.store(true, Ordering::SeqCst);
}

/// Whether a stop was requested.
pub(crate) fn stop_requested() -> bool {
    STOP.load(Ordering::SeqCst)
}

/// `Err(Error::Interrupted)` naming `during` if a stop was requested.
pub fn check(during: &str) -> Result<()> {
    if stop_requested() {
        Err(Error::Interrupted(during.to_string()))
    } else {
        Ok(())
    }
}
