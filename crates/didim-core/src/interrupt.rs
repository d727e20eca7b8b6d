//! Cancellation of long computations.
//!
//! The closed-loop loops call [`check`] every [`EVERY`] samples; it fails once [`raise`] has been
//! called, on any thread, so a parallel batch stops as a whole. The embedding program decides when
//! to raise (the Python binding does on Ctrl-C and SIGTERM, which it watches from the calling
//! thread while the core runs on another); the core itself knows nothing of signals.

use crate::error::{Error, Result};
use std::sync::atomic::{AtomicBool, Ordering};

/// Samples between two checks in the simulation loops.
pub const EVERY: usize = 2048;

static RAISED: AtomicBool = AtomicBool::new(false);

/// Asks every running computation to stop at its next check.
pub fn raise() {
    RAISED.store(true, Ordering::Relaxed);
}

/// Clears a previous interruption, at the start of a new top-level call.
pub fn reset() {
    RAISED.store(false, Ordering::Relaxed);
}

/// `Err(Error::Interrupted)` once [`raise`] has been called.
#[inline]
pub fn check() -> Result<()> {
    if RAISED.load(Ordering::Relaxed) {
        Err(Error::Interrupted)
    } else {
        Ok(())
    }
}
