//! # touchdown firmware: STM32H743 camera board
//!
//! Finds the landing pad's fiducial markers in camera frames and streams the pad pose to the
//! flight controller as MAVLink. All algorithms live in `touchdown-core` (detector, pose,
//! filter, the companion MAVLink state machine, the OV7725 and OV2640 drivers and the probe
//! that tells them apart, the exposure loop, the parameter log format); this crate only owns
//! hardware and wiring. Tasks, on two embassy executors: [`link::task`] on an interrupt
//! executor ([`LINK_EXECUTOR`]) that preempts the others, the rest cooperatively in thread
//! mode:
//!
//! - [`vision::task`]: the camera (an OV7725 or an OV2640, whichever answers on the SCCB bus
//!   at start) over DCMI + DMA into two frame buffers (capture of frame n+1 overlaps
//!   processing of frame n), detector, pad pose with that sensor's lens model, software
//!   auto-exposure, camera re-initialisation after repeated capture errors;
//! - [`link::task`]: the UART to the flight controller and the [`Companion`] state machine
//!   (HEARTBEAT, LANDING_TARGET, TIMESYNC, parameters, STATUSTEXT);
//! - [`param_store::task`]: saves changed MAVLink parameters to flash;
//! - [`watchdog::task`]: feeds the independent watchdog while both vision and link progress;
//! - [`heartbeat::task`]: blinks the user LED.
//!
//! They talk only through the channels, signals and progress counters of [`channels`], whose
//! docs draw the task graph.
//!
//! Boards ([`board`]): NUCLEO-H743ZI2 (default feature `board-nucleo`) or OpenMV Cam H7
//! (`board-openmv`). Memory (see the root `memory.x` and `firmware/README.md`): stack,
//! `.data`, `.bss` and the task futures in DTCM (fast, not DMA-reachable); frame buffers,
//! detector work memory and the SCCB bounce buffer in AXI SRAM ([`axisram`]); code and the
//! marker tables in flash, parameters in flash bank 2's last two sectors (used alternately,
//! see [`param_store`]).
//!
//! Build and flash: `cd firmware && cargo run --release` (or `cargo fw` from the root); see
//! `firmware/README.md` for the wiring.
#![no_std]
#![no_main]
// Run-time errors are handled or logged; `defmt::unwrap!` marks the few init-time invariants.
#![deny(clippy::unwrap_used, clippy::expect_used)]

mod axisram;
mod board;
mod capture;
mod channels;
mod clocks;
mod config;
mod families;
mod heartbeat;
mod link;
mod param_store;
mod sccb;
// Generated table of the user's own marker family; searched with the `user-family` feature
// (see families.rs), type-checked in every build.
#[cfg_attr(not(feature = "user-family"), allow(dead_code))]
mod user_family;
mod view;
mod vision;
mod watchdog;

use defmt::{info, unwrap, warn};
use embassy_executor::{InterruptExecutor, Spawner};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use panic_probe as _;
use touchdown_core::companion::{Companion, CompanionConfig};
use touchdown_core::params::{ParamId, PipelineSettings};

use crate::axisram::axisram_static;
use crate::capture::{Capture, FrameBuffer};
use crate::sccb::{Bounce, Sccb};

/// The detector's frame-sized work memory for this build's frame size.
#[cfg(not(feature = "camera-vga"))]
pub type Workspace = touchdown_core::detect::QvgaWorkspace;
/// The detector's frame-sized work memory for this build's frame size.
#[cfg(feature = "camera-vga")]
pub type Workspace = touchdown_core::detect::VgaWorkspace;

/// The link's executor: the MAVLink link preempts the thread-mode tasks, above all the vision
/// task, whose frame is one long computation that never yields (its cost:
/// `docs/performance.md`). On the thread executor the link would answer PX4's TIMESYNC
/// requests only between frames, up to a frame late: a VGA frame takes about as long as
/// PX4's limit on a round trip (10 ms, `MAX_RTT_SAMPLE`: slower answers are not used, and
/// PX4 then cannot put our `time_usec` in its clock); LANDING_TARGETs and HEARTBEATs would
/// wait the same way. Its tasks
/// share nothing with the others but [`channels`], whose mutexes are critical sections.
static LINK_EXECUTOR: InterruptExecutor = InterruptExecutor::new();

/// The interrupt the link's executor runs in: SPDIF_RX's, a peripheral neither board uses
/// (the executor pends it from software when a link task is woken).
const LINK_IRQ: interrupt::Interrupt = interrupt::SPDIF_RX;

/// Its priority: less urgent than the peripherals' (0: the NVIC's reset value, which
/// embassy's drivers keep, and its DMA default), so the UART's and the DMA's handlers, which
/// wake the link, are never held up by it; more urgent than thread mode.
const LINK_PRIORITY: Priority = Priority::P6;

#[interrupt]
unsafe fn SPDIF_RX() {
    // SAFETY: InterruptExecutor's contract: this handler of LINK_IRQ is the only caller, and
    // nothing but `LINK_EXECUTOR.start` unmasks the interrupt, after initialising the
    // executor, so it never runs before `start`.
    unsafe { LINK_EXECUTOR.on_interrupt() }
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // RTT first, so that no log line is lost: up channel 0 carries defmt's logs, channel 1
    // the frames for a host viewer both ways (frames up, the viewer's requests down; one
    // number, because a debugger's RTT server serves a channel number both ways; see `view`).
    let rtt = rtt_target::rtt_init! {
        up: {
            0: { size: 1024, name: "defmt" }
            1: { size: view::RTT_BUFFER, mode: rtt_target::ChannelMode::NoBlockTrim, name: "frames" }
        }
        down: {
            0: { }
            1: { size: 64, name: "frames" }
        }
    };
    rtt_target::set_defmt_channel(rtt.up.0);
    let p = embassy_stm32::init(clocks::config());
    info!(
        "touchdown firmware {=str} on {=str}: core clock {} MHz",
        env!("CARGO_PKG_VERSION"),
        board::NAME,
        clocks::CPU_HZ / 1_000_000
    );
    let board = board::init(p, config::DEFAULT_BAUD, watchdog::TIMEOUT_US);
    enable_caches();

    // Large buffers. Each call site runs once (main does not loop or return), so each claim
    // succeeds; `unwrap!` documents that invariant rather than handling run-time data.
    let front: &'static mut FrameBuffer =
        unwrap!(axisram_static!(FrameBuffer = FrameBuffer::new()));
    #[cfg(not(feature = "camera-vga"))]
    let back: &'static mut FrameBuffer = unwrap!(axisram_static!(FrameBuffer = FrameBuffer::new()));
    // Two VGA frames (2 x 250 KiB) and the VGA work memory do not fit the 512 KiB AXI SRAM
    // together: the second frame goes to SRAM1..3 (D2, also reachable by DMA1).
    #[cfg(feature = "camera-vga")]
    let back: &'static mut FrameBuffer = {
        enable_sram123();
        unwrap!(axisram_static!(
            ".sram123",
            FrameBuffer = FrameBuffer::new()
        ))
    };
    let workspace: &'static mut Workspace = unwrap!(axisram_static!(Workspace = Workspace::new()));
    let bounce: &'static mut Bounce = unwrap!(axisram_static!(Bounce = Bounce::new()));
    let view_frame: &'static mut view::ViewFrame =
        unwrap!(axisram_static!(view::ViewFrame = view::ViewFrame::new()));

    // Parameters from flash, then the UART at the stored baud rate.
    let mut flash = board.flash;
    let (params, store) = param_store::load(&mut flash);
    let baud = params.get_int(ParamId::Baud) as u32;
    if baud != config::DEFAULT_BAUD {
        if let Err(e) = board.uart.set_baudrate(baud) {
            warn!(
                "TD_BAUD {} refused ({}), staying at {}",
                baud,
                e,
                config::DEFAULT_BAUD
            );
        }
    }
    info!("link: {} baud", baud);
    // The vision task starts with the restored parameters; later changes come from the link.
    let pipeline_settings = PipelineSettings::from_params(&params);
    let companion = Companion::new(CompanionConfig {
        params,
        ..CompanionConfig::default()
    });

    // The DCMI set-up is the same for both supported sensors, so it is done before the vision
    // task has probed the SCCB bus for the one that is fitted.
    capture::configure_dcmi();
    let camera = board.camera;
    let sensor_pins = vision::SensorPins {
        reset_n: camera.reset_n,
        power_down: camera.power_down,
    };
    let sccb = Sccb::new(camera.sccb, bounce);
    // MCO1 keeps running on its own once configured; the driver needs no further calls.
    let _xclk = camera.xclk;

    // Each task has a pool of one and is spawned exactly once here, so spawning cannot find
    // its pool busy.
    spawner.spawn(unwrap!(watchdog::task(board.watchdog)));
    spawner.spawn(unwrap!(heartbeat::task(board.led)));
    spawner.spawn(unwrap!(view::task(rtt.up.1, rtt.down.1, view_frame)));
    spawner.spawn(unwrap!(param_store::task(flash, store)));
    LINK_IRQ.set_priority(LINK_PRIORITY);
    let link_spawner = LINK_EXECUTOR.start(LINK_IRQ);
    link_spawner.spawn(unwrap!(link::task(board.uart, companion)));
    spawner.spawn(unwrap!(vision::task(
        sensor_pins,
        sccb,
        Capture::new(camera.dcmi),
        [front, back],
        workspace,
        pipeline_settings
    )));
}

/// Turns on the Cortex-M7's instruction and data caches (16 KB each).
///
/// Without the D-cache every detector access to AXI SRAM goes over the AXI bus at HCLK with
/// wait states; with it row-by-row accesses are served from 32-byte cache lines and the hot
/// parts of the work memory stay cached. DTCM (stack, `.bss`, the RTT log buffer) is never
/// cached, so defmt's buffer stays coherent for the debugger. DMA into cacheable memory (the
/// frame buffers, the SCCB bounce buffer) is kept coherent by cache maintenance in
/// [`capture`] and [`sccb`].
fn enable_caches() {
    // `take` only fails if someone took the core peripherals before; embassy does not.
    let Some(mut core) = cortex_m::Peripherals::take() else {
        warn!("caches: core peripherals already taken, leaving the caches off");
        return;
    };
    core.SCB.enable_icache();
    core.SCB.enable_dcache(&mut core.CPUID);
}

/// Clocks SRAM1, SRAM2 and SRAM3 (off after reset; an access before this faults).
#[cfg(feature = "camera-vga")]
fn enable_sram123() {
    // RM0433 §8.7 RCC registers, RCC_AHB2ENR: SRAM1EN (bit 29), SRAM2EN (bit 30),
    // SRAM3EN (bit 31) = 1 enable the D2 SRAM clocks.
    embassy_stm32::pac::RCC.ahb2enr().modify(|w| {
        w.set_sram1en(true);
        w.set_sram2en(true);
        w.set_sram3en(true);
    });
}
