//! SIGINT (Ctrl-C) and SIGTERM end a `touchdown companion` run with its summary.
//!
//! A user stops a run against a SITL with Ctrl-C long before the recording's end, and a
//! script or a service manager stops it with SIGTERM; both deserve the same summary as a
//! run that finished. So the handlers only record the signal (an atomic store, all a
//! handler may do) and the loop, which checks it every millisecond, stops, prints the
//! summary and returns; `main` exits with the shell's status for that signal (128 + its
//! number: 130 and 143). A second signal while the summary is printed ends the process at
//! once.

use std::io;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use signal_hook::consts::{SIGINT, SIGTERM};

/// The signal that asked us to stop, 0 for none.
static RECEIVED: AtomicUsize = AtomicUsize::new(0);
/// Set by the first signal: from then on a signal terminates at once.
static STOPPING: AtomicBool = AtomicBool::new(false);

/// A signal that stops the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopSignal {
    /// SIGINT (Ctrl-C).
    Interrupt,
    /// SIGTERM.
    Terminate,
}

impl StopSignal {
    /// Its name, for the summary.
    pub fn name(self) -> &'static str {
        match self {
            StopSignal::Interrupt => "SIGINT",
            StopSignal::Terminate => "SIGTERM",
        }
    }

    /// The exit status a shell reports for a process the signal ended: 128 + its number.
    pub fn exit_status(self) -> u8 {
        match self {
            StopSignal::Interrupt => 130,
            StopSignal::Terminate => 143,
        }
    }

    /// Its number (SIGINT 2, SIGTERM 15 on every Unix this builds for: `exit_status`'s
    /// constants are 128 + these, checked by a test).
    fn number(self) -> i32 {
        match self {
            StopSignal::Interrupt => SIGINT,
            StopSignal::Terminate => SIGTERM,
        }
    }
}

/// Installs the handlers (once per process; calling it again adds nothing harmful).
pub fn install() -> io::Result<()> {
    for signal in [StopSignal::Interrupt, StopSignal::Terminate] {
        let number = signal.number();
        // The shutdown must be registered first, so that the first signal finds STOPPING
        // still false and only the second one terminates.
        signal_hook::flag::register_conditional_shutdown(
            number,
            i32::from(signal.exit_status()),
            &STOPPING,
        )?;
        signal_hook::flag::register(number, &STOPPING)?;
        signal_hook::flag::register_usize(number, &RECEIVED, number as usize)?;
    }
    Ok(())
}

/// The signal received since [`install`], if any.
pub fn received() -> Option<StopSignal> {
    let number = RECEIVED.load(Ordering::SeqCst) as i32;
    [StopSignal::Interrupt, StopSignal::Terminate]
        .into_iter()
        .find(|s| s.number() == number)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exit_statuses_are_128_plus_the_signal_number() {
        for signal in [StopSignal::Interrupt, StopSignal::Terminate] {
            assert_eq!(i32::from(signal.exit_status()), 128 + signal.number());
        }
    }
}
