//! SIGINT and SIGTERM during `gatetrace render`: the first signal asks the render to stop after
//! the pass in flight, write the image of the samples traced so far and a checkpoint
//! (`--resume` continues it), and exit with status 128 + the signal's number; a second signal
//! exits at once with that status.

use std::sync::atomic::{AtomicI32, Ordering};

use anyhow::Result;
use signal_hook::consts::{SIGINT, SIGTERM};

/// The first signal received (0: none yet).
static RECEIVED: AtomicI32 = AtomicI32::new(0);

/// Starts a thread that records SIGINT and SIGTERM (instead of their default, which ends the
/// process at once and loses the render).
pub fn install() -> Result<()> {
    let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM])?;
    std::thread::Builder::new().name("signals".into()).spawn(move || {
        for signal in signals.forever() {
            if RECEIVED.compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst).is_ok() {
                eprintln!(
                    "\n{}: finishing the pass in flight, then writing the image and a checkpoint (send it again to \
                     abort at once)",
                    name(signal)
                );
            } else {
                eprintln!("\n{}: aborted", name(signal));
                std::process::exit(128 + RECEIVED.load(Ordering::SeqCst));
            }
        }
    })?;
    Ok(())
}

/// The signal that asked the render to stop, if one did.
pub fn received() -> Option<i32> {
    match RECEIVED.load(Ordering::SeqCst) {
        0 => None,
        s => Some(s),
    }
}

/// The signal's name.
pub fn name(signal: i32) -> &'static str {
    match signal {
        SIGINT => "SIGINT",
        SIGTERM => "SIGTERM",
        _ => "signal",
    }
}

/// The error a render stopped by a signal ends with: the process exits with 128 + `signal`.
#[derive(Debug)]
pub struct Interrupted {
    /// The signal's number.
    pub signal: i32,
}

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "interrupted by {}", name(self.signal))
    }
}

impl std::error::Error for Interrupted {}
