//! Independent watchdog (IWDG1), fed only while the vision pipeline makes progress.
//!
//! The IWDG runs from the 32 kHz LSI, independent of the PLL, so it also catches a clock
//! failure. A task pets it every [`PET_PERIOD`], but only while the vision task has finished a
//! frame within the last [`STALL_LIMIT`]: a hung executor (a task that never yields) and a
//! stalled frame source (e.g. a camera that stopped delivering frames) both end in a reset
//! after at most `STALL_LIMIT + TIMEOUT`. The flight controller sees the companion's
//! heartbeat stop and resume, which is what it is built to handle.
//!
//! Once started the IWDG cannot be stopped, and it keeps counting while a debugger halts the
//! core: expect a reset about one second after hitting a breakpoint.

use core::sync::atomic::{AtomicU32, Ordering};

use embassy_stm32::peripherals::IWDG1;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_time::{Duration, Instant, Ticker};

/// Hardware timeout: the reset comes this long after the last pet.
pub const TIMEOUT: Duration = Duration::from_millis(1000);
/// How often the task pets the watchdog.
pub const PET_PERIOD: Duration = Duration::from_millis(250);
/// How long the vision task may go without finishing a frame before petting stops.
pub const STALL_LIMIT: Duration = Duration::from_millis(2000);

/// Frames the vision task has finished (it calls [`frame_done`]).
static FRAMES_DONE: AtomicU32 = AtomicU32::new(0);

/// Reports one finished frame (called by the vision task).
pub fn frame_done() {
    FRAMES_DONE.fetch_add(1, Ordering::Relaxed);
}

/// The watchdog's constructor takes the timeout in microseconds.
pub const TIMEOUT_US: u32 = TIMEOUT.as_micros() as u32;

/// Starts the watchdog and feeds it while frames keep coming.
#[embassy_executor::task]
pub async fn task(mut wdg: IndependentWatchdog<'static, IWDG1>) {
    wdg.unleash();
    let mut ticker = Ticker::every(PET_PERIOD);
    let mut last_count = FRAMES_DONE.load(Ordering::Relaxed);
    let mut last_progress = Instant::now();
    let mut warned = false;
    loop {
        ticker.next().await;
        let now = Instant::now();
        let count = FRAMES_DONE.load(Ordering::Relaxed);
        if count != last_count {
            last_count = count;
            last_progress = now;
            warned = false;
        }
        if now.duration_since(last_progress) <= STALL_LIMIT {
            wdg.pet();
        } else if !warned {
            defmt::error!(
                "watchdog: no frame for {} ms, letting the IWDG reset the board",
                now.duration_since(last_progress).as_millis()
            );
            warned = true;
        }
    }
}
