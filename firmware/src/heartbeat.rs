//! Heartbeat LED: the green user LED (LD1, PB0 on the NUCLEO-H743ZI2) blinks at 1 Hz.
//!
//! It runs on the same cooperative executor as everything else, so a steady blink also shows
//! that no task hogs the CPU for long (the vision task yields between frames).

use embassy_stm32::gpio::Output;
use embassy_time::{Duration, Ticker};

/// Half of the blink period.
const HALF_PERIOD: Duration = Duration::from_millis(500);

/// Toggles `led` forever.
#[embassy_executor::task]
pub async fn task(mut led: Output<'static>) {
    let mut ticker = Ticker::every(HALF_PERIOD);
    loop {
        led.toggle();
        ticker.next().await;
    }
}
