//! Camera sensor drivers, independent of the microcontroller.
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
//! - [`exposure`]: a software auto-exposure loop with hard limits (maximum exposure time for
//!   motion blur in bright sun, maximum gain for noise), for sensors whose own AEC has no
//!   exposure ceiling.
//!
//! The frame the sensor produces is YUV 4:2:2 (Y, U, Y, V, ... one byte per pixel clock); the
//! detector only wants Y, which the camera interface keeps by capturing every other byte
//! (STM32 DCMI byte select), so the frame buffer receives 8-bit grey directly.

pub mod exposure;
pub mod ov7725;

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

/// Analog gain as a multiple of 1/16 (16 = 1x, 32 = 2x, ...).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GainX16(pub u16);

impl GainX16 {
    /// Unity gain.
    pub const ONE: GainX16 = GainX16(16);
}

/// The line and frame timing a configuration results in, for time stamps and exposure maths.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameTiming {
    /// Pixel clock, Hz.
    pub pclk_hz: u32,
    /// Duration of one line (active pixels plus horizontal blanking), nanoseconds.
    pub line_ns: u32,
    /// Lines per frame, blanking and dummy lines included.
    pub frame_lines: u32,
    /// Active (image) lines per frame.
    pub active_lines: u32,
}

impl FrameTiming {
    /// Frame period, microseconds.
    pub fn frame_period_us(&self) -> u32 {
        let ns = u64::from(self.line_ns) * u64::from(self.frame_lines);
        u32::try_from(ns / 1000).unwrap_or(u32::MAX)
    }

    /// Time to read out the active lines (the rolling shutter's top-to-bottom skew), µs.
    pub fn readout_us(&self) -> u32 {
        let ns = u64::from(self.line_ns) * u64::from(self.active_lines);
        u32::try_from(ns / 1000).unwrap_or(u32::MAX)
    }

    /// Frames per second (0.0 for a degenerate timing).
    pub fn fps(&self) -> f32 {
        let period = self.frame_period_us();
        if period == 0 {
            0.0
        } else {
            1.0e6 / period as f32
        }
    }
}
