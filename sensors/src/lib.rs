//! # touchdown-sensors
//!
//! The camera sensor drivers of touchdown, independent of the microcontroller.
//!
//! A sensor is configured over its SCCB port (OmniVision's I2C-compatible control bus) and
//! streams pixels over a parallel bus (8 data lines, HREF, VSYNC, PCLK) into the MCU's camera
//! interface. The drivers here own only the control side: they are generic over
//! [`embedded_hal_async::i2c::I2c`] (embassy-stm32's I2C implements it on the board, a mock
//! bus in the tests) and [`embedded_hal_async::delay::DelayNs`], allocate nothing and return
//! every failure as an error value. Which register holds what, and why each value is written,
//! is documented next to the register constants.
//!
//! - [`ov7725`]: OmniVision OV7725 (VGA, the OpenMV Cam H7's sensor and the common DCMI
//!   module for the NUCLEO).
//! - [`ov2640`]: OmniVision OV2640 (2 MP, the other common DCMI module), run from its
//!   800x600 mode and scaled by its own DSP to QVGA or VGA.
//! - [`any`]: one type for whichever of the two is connected: probes the SCCB addresses
//!   ([`any::Camera::detect`]) and forwards the operations the vision task needs.
//!
//! The frame the sensor produces is YUV 4:2:2 (Y, U, Y, V, ... one byte per pixel clock); the
//! detector only wants Y, which the camera interface keeps by capturing every other byte
//! (STM32 DCMI byte select), so the frame buffer receives 8-bit grey directly. Both drivers
//! configure the same byte order (Y first) and the same sync polarities, so one camera
//! interface set-up serves either sensor.
//!
//! ## Why a crate of its own
//!
//! A driver is I/O against a bus: register writes and reads, in order, with delays between
//! them. `touchdown-core` is the algorithms (detection, pose, filters, MAVLink logic, the
//! exposure loop) that run on plain values and are tested on the host; it touches no
//! hardware and depends on no hardware trait. The drivers live here so that stays true, and
//! the firmware wires the two together: it hands a driver its SCCB bus, and the frames and the
//! [`FrameTiming`] the driver reports to core. What both sides share, the units and timing
//! of a sensor and the software auto-exposure loop, stays in `touchdown_core::sensor`; this
//! crate depends on core for them (re-exported here: [`GainX16`], [`FrameTiming`]), never the
//! other way round.
//!
//! Like core, the crate is `no_std`, allocates nothing, contains no `unsafe`, and its
//! library code neither unwraps nor indexes: the driver tests (against the mock SCCB bus in
//! `mock`) run on the host with `cargo test`.
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing
    )
)]

pub mod any;
#[cfg(test)]
mod mock;
pub mod ov2640;
pub mod ov7725;

/// The sensor quantities the drivers are set in and report, shared with the algorithms in
/// core (the exposure loop, the frame time stamps).
pub use touchdown_core::sensor::{FrameTiming, GainX16};

/// Output frame size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Resolution {
    /// 320 x 240.
    Qvga,
    /// 640 x 480.
    Vga,
}

impl Resolution {
    /// Width in pixels.
    pub const fn width(self) -> u32 {
        match self {
            Resolution::Qvga => 320,
            Resolution::Vga => 640,
        }
    }

    /// Height in pixels.
    pub const fn height(self) -> u32 {
        match self {
            Resolution::Qvga => 240,
            Resolution::Vga => 480,
        }
    }
}

/// Exposure and gain control, for any sensor (see [`any::Camera`] and [`ov2640`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Exposure {
    /// The sensor's own AEC and AGC. The gain is limited to the highest ceiling the sensor
    /// offers that does not exceed `max_gain` (ceilings are powers of two from 2x to 32x;
    /// anything below 2x gives 2x). The exposure can grow to the whole frame period.
    Auto {
        /// Highest gain the sensor's AGC may use.
        max_gain: GainX16,
    },
    /// Fixed exposure and gain (also what
    /// [`touchdown_core::sensor::AutoExposure`] drives).
    Manual {
        /// Exposure in sensor line periods ([`FrameTiming::line_ns`]), at least 1.
        lines: u16,
        /// Analog gain.
        gain: GainX16,
    },
}

/// What a sensor is set up for, independent of which sensor it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// Output size.
    pub resolution: Resolution,
    /// Frequency of the clock the MCU drives into the sensor's XCLK pin, Hz.
    pub xclk_hz: u32,
    /// Frame rate, frames per second.
    pub fps: u32,
    /// Exposure and gain.
    pub exposure: Exposure,
    /// Flip the image vertically, e.g. for a module mounted upside down.
    pub vflip: bool,
    /// Mirror the image horizontally.
    pub mirror: bool,
}

impl Default for Config {
    /// QVGA at 30 fps from a 24 MHz clock, the sensor's AEC/AGC with an 8x gain ceiling.
    fn default() -> Self {
        Config {
            resolution: Resolution::Qvga,
            xclk_hz: 24_000_000,
            fps: 30,
            exposure: Exposure::Auto {
                max_gain: GainX16(16 * 8),
            },
            vflip: false,
            mirror: false,
        }
    }
}

/// A configuration a sensor cannot realise.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// The input clock is outside the sensor's range.
    XclkOutOfRange,
    /// No clock setting gives this frame rate (0 fps, or faster than the sensor can run).
    FrameRateUnreachable,
    /// Manual exposure of 0 lines.
    ZeroExposure,
}

/// The AGC gain ceiling for `max_gain` as a power of two, `k` in `1..=5` (2x ... 32x): the
/// largest ceiling not above `max_gain`, at least 2x. Both OmniVision sensors here encode
/// their ceiling as `k - 1` in a 3-bit field of COM9.
pub(crate) fn gain_ceiling_log2(max_gain: GainX16) -> u8 {
    // max_gain / 16 is the gain factor; its integer log2, limited to 1..=5.
    let factor = (max_gain.0 / 16).max(1);
    let log2 = (u16::BITS - 1 - factor.leading_zeros()) as u8;
    log2.clamp(1, 5)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gain_ceiling_is_the_largest_power_of_two_not_above_the_limit() {
        assert_eq!(gain_ceiling_log2(GainX16(0)), 1); // below 2x: 2x
        assert_eq!(gain_ceiling_log2(GainX16::ONE), 1);
        assert_eq!(gain_ceiling_log2(GainX16(16 * 2)), 1);
        assert_eq!(gain_ceiling_log2(GainX16(16 * 3)), 1); // 3x: 2x
        assert_eq!(gain_ceiling_log2(GainX16(16 * 8)), 3);
        assert_eq!(gain_ceiling_log2(GainX16(16 * 8 - 1)), 2); // just below 8x: 4x
        assert_eq!(gain_ceiling_log2(GainX16(16 * 32)), 5);
        assert_eq!(gain_ceiling_log2(GainX16(u16::MAX)), 5); // above 32x: 32x
    }

    /// The rolling shutter's row-to-row time of the 30 fps set-ups from the board clocks
    /// (12 MHz OpenMV, 24 MHz NUCLEO), ns: the readout of the array lines spread over the
    /// output rows. The firmware's camera models (firmware/src/config.rs,
    /// OV7725_LINE_TIME_US and OV2640_LINE_TIME_US) carry these figures; a changed clock
    /// plan must change them too.
    #[test]
    fn row_times_of_the_30_fps_plans_are_the_firmwares_line_times() {
        let row_ns = |timing: FrameTiming, resolution: Resolution| {
            u64::from(timing.line_ns) * u64::from(timing.active_lines)
                / u64::from(resolution.height())
        };
        for xclk_hz in [12_000_000, 24_000_000] {
            let ov7725 = |r| row_ns(ov7725::plan_clock(xclk_hz, r, 30).unwrap().timing, r);
            let ov2640 = |r| row_ns(ov2640::plan_clock(xclk_hz, r, 30).unwrap().timing, r);
            // 1152 clocks at 9.6 MHz; 1568 at 24 MHz.
            assert_eq!(ov7725(Resolution::Qvga), 120_000);
            assert_eq!(ov7725(Resolution::Vga), 65_333);
            // 600 lines of 1190 clocks at 24 MHz (49,583 ns, truncated) over 240 or 480 rows.
            assert_eq!(ov2640(Resolution::Qvga), 123_957);
            assert_eq!(ov2640(Resolution::Vga), 61_978);
        }
    }
}
