//! # touchdown firmware: STM32H743 camera board
//!
//! Finds the landing pad's fiducial markers in camera frames and (from issue 5 on) streams the
//! pad pose to the flight controller as MAVLink. All algorithms live in `touchdown-core`; this
//! crate only owns hardware: clocks, memory placement, the camera, the UART and the tasks.
//!
//! This is the skeleton: it builds for the NUCLEO-H743ZI2 (STM32H743ZI) and runs, on one
//! cooperative embassy executor,
//! - [`vision::task`]: detector on every frame of the *placeholder* [`frame_source`] (a
//!   rendered test pattern; issue 5 replaces it with the OV7725 on the DCMI), stats via defmt;
//! - [`watchdog::task`]: feeds the independent watchdog while frames keep being processed;
//! - [`heartbeat::task`]: blinks the green user LED.
//!
//! Memory (see the root `memory.x`): stack, `.data`, `.bss` and the task futures in DTCM
//! (fast, not DMA-reachable); the frame buffer and the detector's work memory in AXI SRAM
//! ([`axisram`]); code and the marker tables in flash.
//!
//! Build and flash: `cd firmware && cargo run --release` (or `cargo fw` from the root); see
//! `firmware/README.md` for the wiring.
#![no_std]
#![no_main]
// Run-time errors are handled or logged; `defmt::unwrap!` marks the few init-time invariants.
#![deny(clippy::unwrap_used, clippy::expect_used)]

mod axisram;
mod clocks;
mod families;
mod frame_source;
mod heartbeat;
mod mavlink_check;
// Generated table of the user's own marker family; searched with the `user-family` feature
// (see families.rs), type-checked in every build.
#[cfg_attr(not(feature = "user-family"), allow(dead_code))]
mod user_family;
mod vision;
mod watchdog;

use defmt::{info, unwrap, warn};
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::wdg::IndependentWatchdog;
use panic_probe as _;
use touchdown_core::detect::QvgaWorkspace;

use crate::axisram::axisram_static;
use crate::frame_source::{FrameBuffer, TestPattern};

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(clocks::config());
    info!(
        "touchdown firmware {=str}: core clock {} MHz",
        env!("CARGO_PKG_VERSION"),
        clocks::CPU_HZ / 1_000_000
    );
    enable_caches();

    // AXI SRAM: each call site runs once (main does not loop or return), so each claim
    // succeeds; `unwrap!` documents that invariant rather than handling run-time data.
    let frame: &'static mut FrameBuffer =
        unwrap!(axisram_static!(FrameBuffer = FrameBuffer::new()));
    let workspace: &'static mut QvgaWorkspace =
        unwrap!(axisram_static!(QvgaWorkspace = QvgaWorkspace::new()));

    let source = TestPattern::new(frame, families::test_pattern_family());
    let led = Output::new(p.PB0, Level::Low, Speed::Low);
    let wdg = IndependentWatchdog::new(p.IWDG1, watchdog::TIMEOUT_US);

    // Each task has a pool of one and is spawned exactly once here, so spawning cannot find
    // its pool busy.
    spawner.spawn(unwrap!(watchdog::task(wdg)));
    spawner.spawn(unwrap!(heartbeat::task(led)));
    spawner.spawn(unwrap!(vision::task(source, workspace)));
}

/// Turns on the Cortex-M7's instruction and data caches (16 KB each).
///
/// Without the D-cache every detector access to AXI SRAM goes over the AXI bus at HCLK with
/// wait states; with it row-by-row accesses are served from 32-byte cache lines and the hot
/// parts of the work memory stay cached. DTCM (stack,
/// `.bss`, the RTT log buffer) is never cached, so defmt's buffer stays coherent for the
/// debugger. Any DMA into cacheable memory (issue 5's DCMI frame buffer, UART buffers) needs
/// cache maintenance; see [`frame_source`].
fn enable_caches() {
    // `take` only fails if someone took the core peripherals before; embassy does not.
    let Some(mut core) = cortex_m::Peripherals::take() else {
        warn!("caches: core peripherals already taken, leaving the caches off");
        return;
    };
    core.SCB.enable_icache();
    core.SCB.enable_dcache(&mut core.CPUID);
}
