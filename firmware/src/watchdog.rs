//! Independent watchdog (IWDG1), fed only while the vision pipeline *and* the MAVLink link
//! make progress.
//!
//! The IWDG runs from the 32 kHz LSI, independent of the PLL, so it also catches a clock
//! failure. A task pets it every [`PET_PERIOD`], but only while the vision task has finished a
//! frame within the last [`STALL_LIMIT`] and the link task has run its loop within the same
//! limit (it runs at least every 5 ms); both report through the progress counters in
//! [`crate::channels`] ([`FRAMES_DONE`], [`LINK_LOOPS`]): a hung executor (a task that never yields), a stalled
//! camera that re-initialisation cannot revive, and a wedged link all end in a reset after at
//! most `STALL_LIMIT + TIMEOUT`. A camera restart (the failed captures before it, power cycle,
//! set-up, settling, first frame: about 0.7 s at 30 fps, see [`crate::vision`]) fits well
//! inside the limit. The
//! flight controller sees the companion's heartbeat stop and
//! resume, which is what it is built to handle.
//!
//! Once started the IWDG cannot be stopped, and it keeps counting while a debugger halts the
//! core: expect a reset about one second after hitting a breakpoint.

use core::sync::atomic::{AtomicU32, Ordering};

use embassy_stm32::peripherals::IWDG1;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_time::{Duration, Instant, Ticker};

use crate::channels::{FRAMES_DONE, LINK_LOOPS};

/// Hardware timeout: the reset comes this long after the last pet.
pub const TIMEOUT: Duration = Duration::from_millis(1000);
/// How often the task pets the watchdog.
pub const PET_PERIOD: Duration = Duration::from_millis(250);
/// How long the vision task may go without finishing a frame before petting stops.
pub const STALL_LIMIT: Duration = Duration::from_millis(2000);

/// Progress of one counter.
struct Progress {
    name: &'static str,
    counter: &'static AtomicU32,
    last_count: u32,
    last_progress: Instant,
}

impl Progress {
    fn new(name: &'static str, counter: &'static AtomicU32) -> Self {
        Progress {
            name,
            counter,
            last_count: counter.load(Ordering::Relaxed),
            last_progress: Instant::now(),
        }
    }

    /// True while the counter moved within [`STALL_LIMIT`].
    fn alive(&mut self, now: Instant) -> bool {
        let count = self.counter.load(Ordering::Relaxed);
        if count != self.last_count {
            self.last_count = count;
            self.last_progress = now;
        }
        now.duration_since(self.last_progress) <= STALL_LIMIT
    }
}

/// The watchdog's constructor takes the timeout in microseconds.
pub const TIMEOUT_US: u32 = TIMEOUT.as_micros() as u32;

/// Starts the watchdog and feeds it while frames keep coming.
#[embassy_executor::task]
pub async fn task(mut wdg: IndependentWatchdog<'static, IWDG1>) {
    wdg.unleash();
    let mut ticker = Ticker::every(PET_PERIOD);
    let mut watched = [
        Progress::new("vision (no frame)", &FRAMES_DONE),
        Progress::new("link (MAVLink loop)", &LINK_LOOPS),
    ];
    let mut warned = false;
    loop {
        ticker.next().await;
        let now = Instant::now();
        let mut all_alive = true;
        for p in watched.iter_mut() {
            if !p.alive(now) {
                all_alive = false;
                if !warned {
                    defmt::error!(
                        "watchdog: {=str} stalled for {} ms, letting the IWDG reset the board",
                        p.name,
                        now.duration_since(p.last_progress).as_millis()
                    );
                    warned = true;
                }
            }
        }
        if all_alive {
            wdg.pet();
        }
    }
}
