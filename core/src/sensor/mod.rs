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
//! - [`ov2640`]: OmniVision OV2640 (2 MP, the other common DCMI module), run from its
//!   800x600 mode and scaled by its own DSP to QVGA or VGA.
//! - [`any`]: one type for whichever of the two is connected: probes the SCCB addresses
//!   ([`any::Camera::detect`]) and forwards the operations the vision task needs.
//! - [`exposure`]: a software auto-exposure loop with hard limits (maximum exposure time for
//!   motion blur in bright sun, maximum gain for noise), for sensors whose own AEC has no
//!   exposure ceiling.
//!
//! The frame the sensor produces is YUV 4:2:2 (Y, U, Y, V, ... one byte per pixel clock); the
//! detector only wants Y, which the camera interface keeps by capturing every other byte
//! (STM32 DCMI byte select), so the frame buffer receives 8-bit grey directly. Both drivers
//! configure the same byte order (Y first) and the same sync polarities, so one camera
//! interface set-up serves either sensor.

pub mod any;
pub mod exposure;
pub mod ov2640;
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
///
/// Lines are the *sensor's* lines, the unit its exposure registers count in. For a sensor
/// that outputs its array rows one to one (the OV7725) they are the output rows; for one
/// whose DSP scales the image (the OV2640 reads 600 rows and outputs 240 or 480) they are
/// not, and `active_lines` is the number of array rows read per frame, which is what sets
/// the rolling shutter's top-to-bottom skew.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameTiming {
    /// Pixel clock on the parallel bus (one byte per clock), Hz.
    pub pclk_hz: u32,
    /// Duration of one sensor line (active pixels plus horizontal blanking), nanoseconds:
    /// the unit of the exposure registers.
    pub line_ns: u32,
    /// Sensor lines per frame, blanking and dummy lines included.
    pub frame_lines: u32,
    /// Sensor lines read out per frame (the image rows before any scaling).
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
    /// Fixed exposure and gain (also what [`exposure::AutoExposure`] drives).
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
pub(crate) mod mock {
    //! A mock SCCB bus with any number of register-file devices, for the driver tests.
    //!
    //! Each device answers at one 7-bit address. A one-byte write sets its register
    //! pointer, a two-byte write stores a value, a one-byte read returns the pointed
    //! register. A banked device (the OV2640) has two register files, and a write to its
    //! bank-select register (0xFF) picks the file the other accesses go to. Any transaction
    //! with more than one operation (a repeated start, which SCCB lacks) fails, as does any
    //! access to an address no device answers at.

    extern crate std;
    use std::vec::Vec;

    use embedded_hal_async::delay::DelayNs;
    use embedded_hal_async::i2c::{ErrorKind, ErrorType, I2c, NoAcknowledgeSource, Operation};

    /// The bank-select register of a banked device.
    pub const BANK_SELECT: u8 = 0xFF;

    /// What the bus saw: (address, register, value) for writes, (address, register) for
    /// reads. Bank selects are logged as writes to [`BANK_SELECT`].
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum Access {
        /// A register write.
        Write(u8, u8, u8),
        /// A register read.
        Read(u8, u8),
    }

    /// One device on the bus.
    #[derive(Debug)]
    pub struct Device {
        /// 7-bit address.
        pub address: u8,
        /// Register files (bank 0 and bank 1; an unbanked device uses bank 0 only).
        pub regs: [[u8; 256]; 2],
        /// Whether register 0xFF selects the bank.
        pub banked: bool,
        /// Selected bank.
        pub bank: usize,
        pointer: u8,
    }

    impl Device {
        /// An unbanked device with all registers 0.
        pub fn new(address: u8) -> Self {
            Device {
                address,
                regs: [[0; 256]; 2],
                banked: false,
                bank: 0,
                pointer: 0,
            }
        }

        /// A banked device with all registers 0, bank 0 selected.
        pub fn banked(address: u8) -> Self {
            Device {
                banked: true,
                ..Device::new(address)
            }
        }
    }

    /// The bus: its devices and the log of every register access.
    #[derive(Debug, Default)]
    pub struct MockBus {
        /// Devices on the bus.
        pub devices: Vec<Device>,
        /// Every completed register access, in order.
        pub log: Vec<Access>,
    }

    impl MockBus {
        /// A bus with these devices.
        pub fn with(devices: Vec<Device>) -> Self {
            MockBus {
                devices,
                log: Vec::new(),
            }
        }

        /// The device at `address`.
        pub fn device(&mut self, address: u8) -> &mut Device {
            self.devices
                .iter_mut()
                .find(|d| d.address == address)
                .unwrap()
        }

        /// The writes, as (register, value), bank selects included.
        pub fn writes(&self) -> Vec<(u8, u8)> {
            self.log
                .iter()
                .filter_map(|a| match *a {
                    Access::Write(_, r, v) => Some((r, v)),
                    Access::Read(..) => None,
                })
                .collect()
        }
    }

    /// The error of every failed transfer: no acknowledge.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub struct Nack;

    impl embedded_hal_async::i2c::Error for Nack {
        fn kind(&self) -> ErrorKind {
            ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address)
        }
    }

    impl ErrorType for MockBus {
        type Error = Nack;
    }

    impl I2c for MockBus {
        async fn transaction(
            &mut self,
            address: u8,
            operations: &mut [Operation<'_>],
        ) -> Result<(), Nack> {
            let [operation] = operations else {
                return Err(Nack);
            };
            let Some(device) = self.devices.iter_mut().find(|d| d.address == address) else {
                return Err(Nack);
            };
            match operation {
                Operation::Write([r]) => device.pointer = *r,
                Operation::Write([r, v]) => {
                    if device.banked && *r == BANK_SELECT {
                        device.bank = usize::from(*v & 1);
                    } else {
                        device.regs[device.bank][usize::from(*r)] = *v;
                    }
                    self.log.push(Access::Write(address, *r, *v));
                }
                Operation::Read([out]) => {
                    *out = device.regs[device.bank][usize::from(device.pointer)];
                    self.log.push(Access::Read(address, device.pointer));
                }
                _ => return Err(Nack),
            }
            Ok(())
        }
    }

    /// A delay that only adds up what it was asked to wait.
    #[derive(Default)]
    pub struct MockDelay {
        /// Total requested delay, ns.
        pub total_ns: u64,
    }

    impl DelayNs for MockDelay {
        async fn delay_ns(&mut self, ns: u32) {
            self.total_ns += u64::from(ns);
        }
    }
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

    #[test]
    fn frame_timing_derived_values() {
        let t = FrameTiming {
            pclk_hz: 24_000_000,
            line_ns: 49_583,
            frame_lines: 672,
            active_lines: 600,
        };
        assert_eq!(t.frame_period_us(), 33_319);
        assert_eq!(t.readout_us(), 29_749);
        assert!((t.fps() - 30.013).abs() < 0.01, "{}", t.fps());
        let zero = FrameTiming { line_ns: 0, ..t };
        assert_eq!(zero.fps(), 0.0);
    }
}
