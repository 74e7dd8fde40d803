//! Ctrl-C (SIGINT) as a request, not a kill: [`install`] makes it set a flag that the
//! training loop reads after each step; the run then saves its checkpoint, says how to resume
//! and ends with [`crate::Error::Interrupted`] (the binaries exit with 130, as a shell does).
//! A second Ctrl-C while the first is being honoured ends the process at once.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

static FLAG: std::sync::OnceLock<Arc<AtomicBool>> = std::sync::OnceLock::new();

/// Route SIGINT to the flag (once per process; later calls do nothing).
pub fn install() {
    FLAG.get_or_init(|| {
        let flag = Arc::new(AtomicBool::new(false));
        // The second signal terminates: registered first, it acts only once the flag is set.
        let _ = signal_hook::flag::register_conditional_shutdown(
            signal_hook::consts::SIGINT,
            130,
            flag.clone(),
        );
        let _ = signal_hook::flag::register(signal_hook::consts::SIGINT, flag.clone());
        flag
    });
}

/// Whether Ctrl-C was pressed since [`install`].
pub fn requested() -> bool {
    FLAG.get().is_some_and(|f| f.load(Ordering::Relaxed))
}

/// `Err(Interrupted)` saying where the work `stopped` if Ctrl-C was pressed, for the long
/// reads and writes that look between pieces (a targets file, an `.npz`).
pub fn check(stopped: impl FnOnce() -> String) -> crate::core::error::Result<()> {
    if requested() {
        Err(crate::core::error::Error::Interrupted(stopped()))
    } else {
        Ok(())
    }
}

/// Rows of a table read between two looks at Ctrl-C (a few milliseconds of parsing).
pub const ROWS_BETWEEN_CHECKS: usize = 1 << 14;
