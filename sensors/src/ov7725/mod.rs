//! OmniVision OV7725: VGA CMOS sensor, configured over SCCB.
//!
//! What this driver sets up, and nothing else (every other register keeps its reset value,
//! which gives a usable image, as the Linux ov772x driver also relies on):
//!
//! - **Identity**: PID/VER must read `0x77`/`0x21` before anything is written, so a wrong
//!   module (an OV2640, an OV7670 at another address, a floating bus) is an error, not a
//!   device we scribble on.
//! - **Reset**: COM7 bit 7 puts every register back to its default; the sensor needs about a
//!   millisecond before it answers again ([`RESET_SETTLE_US`]).
//! - **Format**: YUV 4:2:2 with Y first (`Y0 U0 Y1 V0 ...`), so the camera interface keeps
//!   every *first* byte of each pixel clock pair and the frame buffer receives 8-bit grey.
//! - **Size**: VGA (640x480) or the sensor's native QVGA mode (320x240, the whole field of
//!   view, subsampled), with the window registers of both modes.
//! - **Frame rate**: the pixel clock is `XCLK x PLL / prescaler`; [`plan_clock`] picks the PLL
//!   multiplier (COM4) and the prescaler (CLKRC) and adds dummy lines (DM_LNL/DM_LNH) to hit
//!   the requested rate.
//! - **Exposure and gain**: the sensor's own AEC/AGC with a gain ceiling (COM9), or manual
//!   exposure (AEC/AECH, in line periods) and gain (GAIN). The sensor's AEC has no exposure
//!   ceiling below the frame period; for a hard exposure limit (motion blur in bright sun) run
//!   [`touchdown_core::sensor::AutoExposure`] and feed its manual settings here.
//!
//! The bus is SCCB, which is I2C-compatible for writes but does not support a repeated
//! start: a register read is a write of the register address, a STOP, then a separate read
//! transaction ([`Ov7725::read_register`]), never `write_read`.
//!
//! Sources for the register semantics: the OV7725 datasheet's register table (COM2..COM9,
//! CLKRC, PLL, window and exposure registers) and the Linux `ov772x` driver's documented
//! window geometry and frame sizes (784x510 pixel periods per VGA frame, 576x278 per QVGA
//! frame). Nothing was copied; the values are derived below.

//!
//! The driver is split by concern: [`reg`] is the register map, `clock` plans the pixel clock
//! and frame length for a frame rate ([`plan_clock`]), `gain` is the GAIN register's encoding
//! (shared with the OV2640, which uses the same one), and this module holds the driver that
//! writes them in order. The register field values below are shared by the driver and the
//! clock plan, so they live here, next to the set-up sequence that documents them.
use embedded_hal_async::delay::DelayNs;
use embedded_hal_async::i2c::I2c;

use crate::{gain_ceiling_log2, GainX16, Resolution};
// The set-up and its errors are the sensor-independent ones (`crate::Config`), so the firmware
// drives either sensor through one type; re-exported so `ov7725::Config` still names them.
pub use crate::{Config, ConfigError, Exposure};

mod clock;
mod gain;
pub mod reg;

pub use clock::{plan_clock, ClockPlan, Pll, Prescaler};
pub use gain::{gain_from_register, gain_register};

/// 7-bit SCCB address (0x42 to write, 0x43 to read in 8-bit notation).
pub const I2C_ADDRESS: u8 = 0x21;
/// Product id, high byte (register PID).
pub const PRODUCT_ID: u8 = 0x77;
/// Product id, low byte (register VER) of the OV7725 (the OV7720 reads 0x20).
pub const PRODUCT_VERSION: u8 = 0x21;
/// Wait after the register reset before the next access, µs (datasheet: 1 ms).
pub const RESET_SETTLE_US: u32 = 2_000;
/// Input clock range of the sensor (datasheet), Hz.
pub const XCLK_RANGE_HZ: core::ops::RangeInclusive<u32> = 10_000_000..=48_000_000;
/// Highest pixel clock [`plan_clock`] uses, Hz: VGA at 30 fps needs exactly this, and it
/// keeps the parallel bus within what hand-wired DCMI modules carry reliably.
pub const MAX_PCLK_HZ: u32 = 24_000_000;
/// A frame rate within this many parts per million of the request counts as exact.
pub const FPS_TOLERANCE_PPM: u64 = 5_000;

/// COM7 bit 7: reset every register to its default.
const COM7_RESET: u8 = 0x80;
/// COM7 bit 6: QVGA.
const COM7_QVGA: u8 = 0x40;
/// COM7 bits `[1:0]` = 00: YUV output.
const COM7_YUV: u8 = 0x00;
/// COM3 bit 7: vertical flip.
const COM3_VFLIP: u8 = 0x80;
/// COM3 bit 6: horizontal mirror.
const COM3_MIRROR: u8 = 0x40;
/// COM3 bit 4: YUV byte order with Y first (Y U Y V), so Y is every even byte.
const COM3_Y_FIRST: u8 = 0x10;
/// COM4 bit 0: reserved, 1 after reset; written back unchanged.
const COM4_RESERVED: u8 = 0x01;
/// CLKRC bit 7: reserved, 1 after reset; written back unchanged.
const CLKRC_RESERVED: u8 = 0x80;
/// CLKRC bit 6: feed the input clock to the PLL directly, no prescaler.
const CLKRC_DIRECT: u8 = 0x40;
/// Largest prescaler field value, `CLKRC[5:0]` (datasheet range 0..=31).
const CLKRC_MAX_N: u8 = 31;
/// COM8 with the sensor's AEC and AGC on: fast AEC/AGC (bit 7), unlimited AEC steps (bit 6),
/// exposures shorter than a line allowed (bit 3: bright sun), AGC (bit 2), AWB (bit 1), AEC
/// (bit 0). The banding filter (bit 5) stays off: it would hold the exposure at multiples of
/// 1/100 s, far too long outdoors.
const COM8_AUTO: u8 = 0xCF;
/// COM8 for manual exposure: as [`COM8_AUTO`] without AGC (bit 2) and AEC (bit 0).
const COM8_MANUAL: u8 = COM8_AUTO & !0x05;
/// COM9 bits `[6:4]`: gain ceiling field.
const COM9_CEILING_MASK: u8 = 0x70;
/// DSP_CTRL4 = 0: the DSP outputs YUV/RGB (not raw Bayer).
const DSP_CTRL4_YUV: u8 = 0x00;

/// Why the sensor could not be set up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// The SCCB/I2C transfer failed (no device, NACK, bus fault).
    Bus(E),
    /// Something answered, but it is not an OV7725 (PID, VER as read).
    WrongChip {
        /// Register PID as read.
        pid: u8,
        /// Register VER as read.
        ver: u8,
    },
    /// The configuration cannot be realised.
    Config(ConfigError),
}

/// Window registers of each mode: (HSTART, HSIZE, VSTART, VSIZE, HREF). The window's LSBs
/// (HREF) are all zero for both modes: VGA starts at pixel 140, line 14; QVGA at 252, 6.
const fn window(resolution: Resolution) -> [u8; 5] {
    match resolution {
        Resolution::Vga => [
            (140u16 >> 2) as u8,
            (640u16 >> 2) as u8,
            14 >> 1,
            (480u16 >> 1) as u8,
            0,
        ],
        Resolution::Qvga => [
            (252u16 >> 2) as u8,
            (320u16 >> 2) as u8,
            6 >> 1,
            (240u16 >> 1) as u8,
            0,
        ],
    }
}

/// The OV7725 on an SCCB (I2C) bus.
#[derive(Debug)]
pub struct Ov7725<I> {
    i2c: I,
}

impl<I: I2c> Ov7725<I> {
    /// A driver for the sensor at [`I2C_ADDRESS`] on `i2c`. Nothing is sent yet.
    pub fn new(i2c: I) -> Self {
        Ov7725 { i2c }
    }

    /// Gives the bus back.
    pub fn release(self) -> I {
        self.i2c
    }

    /// Reads one register: the address in one write transaction, STOP, then a one-byte read
    /// (SCCB has no repeated start).
    pub async fn read_register(&mut self, register: u8) -> Result<u8, Error<I::Error>> {
        self.i2c
            .write(I2C_ADDRESS, &[register])
            .await
            .map_err(Error::Bus)?;
        let mut value = [0u8];
        self.i2c
            .read(I2C_ADDRESS, &mut value)
            .await
            .map_err(Error::Bus)?;
        let [value] = value;
        Ok(value)
    }

    /// Writes one register.
    pub async fn write_register(&mut self, register: u8, value: u8) -> Result<(), Error<I::Error>> {
        self.i2c
            .write(I2C_ADDRESS, &[register, value])
            .await
            .map_err(Error::Bus)
    }

    /// Reads PID and VER and checks that they say OV7725.
    pub async fn check_id(&mut self) -> Result<(), Error<I::Error>> {
        let pid = self.read_register(reg::PID).await?;
        let ver = self.read_register(reg::VER).await?;
        if pid == PRODUCT_ID && ver == PRODUCT_VERSION {
            Ok(())
        } else {
            Err(Error::WrongChip { pid, ver })
        }
    }

    /// Checks the id, resets the sensor and configures it (see the module documentation for
    /// the sequence). Returns the clock plan in force. The configuration is validated before
    /// anything is sent.
    pub async fn init<D: DelayNs>(
        &mut self,
        delay: &mut D,
        config: &Config,
    ) -> Result<ClockPlan, Error<I::Error>> {
        let plan =
            plan_clock(config.xclk_hz, config.resolution, config.fps).map_err(Error::Config)?;
        if let Exposure::Manual { lines: 0, .. } = config.exposure {
            return Err(Error::Config(ConfigError::ZeroExposure));
        }
        self.check_id().await?;

        // Every register back to its default, then give the sensor time to come back.
        self.write_register(reg::COM7, COM7_RESET).await?;
        delay.delay_us(RESET_SETTLE_US).await;

        // Resolution and YUV output.
        let com7 = match config.resolution {
            Resolution::Qvga => COM7_QVGA | COM7_YUV,
            Resolution::Vga => COM7_YUV,
        };
        self.write_register(reg::COM7, com7).await?;
        // Y first in each pixel pair, so the DCMI keeps the even bytes; flips as asked.
        let mut com3 = COM3_Y_FIRST;
        if config.vflip {
            com3 |= COM3_VFLIP;
        }
        if config.mirror {
            com3 |= COM3_MIRROR;
        }
        self.write_register(reg::COM3, com3).await?;

        // Sensor window and output size of the mode (sizes are multiples of 4 and 2, so the
        // LSB fields in HREF and EXHCH are zero).
        let [hstart, hsize, vstart, vsize, href] = window(config.resolution);
        self.write_register(reg::HSTART, hstart).await?;
        self.write_register(reg::HSIZE, hsize).await?;
        self.write_register(reg::VSTART, vstart).await?;
        self.write_register(reg::VSIZE, vsize).await?;
        self.write_register(reg::HREF, href).await?;
        let (w, h) = (config.resolution.width(), config.resolution.height());
        self.write_register(reg::HOUTSIZE, (w >> 2) as u8).await?;
        self.write_register(reg::VOUTSIZE, (h >> 1) as u8).await?;
        self.write_register(reg::EXHCH, 0x00).await?;
        self.write_register(reg::DSP_CTRL4, DSP_CTRL4_YUV).await?;

        // Pixel clock and frame length.
        self.write_register(reg::COM4, plan.pll.com4_bits() | COM4_RESERVED)
            .await?;
        self.write_register(reg::CLKRC, plan.prescaler.clkrc())
            .await?;
        self.write_register(reg::EXHCL, 0x00).await?;
        let [dummy_lo, dummy_hi] = plan.dummy_lines.to_le_bytes();
        self.write_register(reg::DM_LNL, dummy_lo).await?;
        self.write_register(reg::DM_LNH, dummy_hi).await?;

        self.set_exposure(config.exposure).await?;
        Ok(plan)
    }

    /// Switches exposure control (sensor AEC/AGC with a gain ceiling, or manual values).
    pub async fn set_exposure(&mut self, exposure: Exposure) -> Result<(), Error<I::Error>> {
        match exposure {
            Exposure::Auto { max_gain } => {
                // COM9[6:4]: the AGC ceiling, 0 = 2x ... 4 = 32x.
                let ceiling = gain_ceiling_log2(max_gain) - 1;
                let com9 = self.read_register(reg::COM9).await?;
                let com9 = (com9 & !COM9_CEILING_MASK) | (ceiling << 4);
                self.write_register(reg::COM9, com9).await?;
                self.write_register(reg::COM8, COM8_AUTO).await
            }
            Exposure::Manual { lines, gain } => {
                if lines == 0 {
                    return Err(Error::Config(ConfigError::ZeroExposure));
                }
                // AEC/AGC off first, or they overwrite the values below.
                self.write_register(reg::COM8, COM8_MANUAL).await?;
                self.set_manual(lines, gain).await
            }
        }
    }

    /// Writes exposure (line periods) and gain while in manual mode (three register writes;
    /// what a software exposure loop calls per adjustment).
    pub async fn set_manual(&mut self, lines: u16, gain: GainX16) -> Result<(), Error<I::Error>> {
        let [lo, hi] = lines.max(1).to_le_bytes();
        self.write_register(reg::AECH, hi).await?;
        self.write_register(reg::AEC, lo).await?;
        self.write_register(reg::GAIN, gain_register(gain)).await
    }

    /// Reads the exposure (line periods) and gain in force (useful with the sensor's AEC on).
    pub async fn read_exposure(&mut self) -> Result<(u16, GainX16), Error<I::Error>> {
        let hi = self.read_register(reg::AECH).await?;
        let lo = self.read_register(reg::AEC).await?;
        let gain = self.read_register(reg::GAIN).await?;
        Ok((u16::from_le_bytes([lo, hi]), gain_from_register(gain)))
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use embassy_futures::block_on;
    use embedded_hal_async::i2c::{ErrorKind, ErrorType, Operation};

    /// What the mock bus saw.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    enum Access {
        Write(u8, u8),
        Read(u8),
    }

    /// A register file behind a 7-bit address. A one-byte write sets the register pointer,
    /// a two-byte write stores a value, a one-byte read returns the pointed register. Any
    /// transaction with more than one operation (a repeated start, which SCCB lacks) fails.
    struct MockSccb {
        regs: [u8; 256],
        pointer: u8,
        log: Vec<Access>,
        present: bool,
    }

    impl MockSccb {
        fn ov7725() -> Self {
            let mut regs = [0u8; 256];
            regs[reg::PID as usize] = PRODUCT_ID;
            regs[reg::VER as usize] = PRODUCT_VERSION;
            regs[reg::COM9 as usize] = 0x4A; // datasheet reset value
            MockSccb {
                regs,
                pointer: 0,
                log: Vec::new(),
                present: true,
            }
        }

        fn writes(&self) -> Vec<(u8, u8)> {
            self.log
                .iter()
                .filter_map(|a| match a {
                    Access::Write(r, v) => Some((*r, *v)),
                    Access::Read(_) => None,
                })
                .collect()
        }
    }

    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    struct Nack;
    impl embedded_hal_async::i2c::Error for Nack {
        fn kind(&self) -> ErrorKind {
            ErrorKind::NoAcknowledge(embedded_hal_async::i2c::NoAcknowledgeSource::Address)
        }
    }

    impl ErrorType for MockSccb {
        type Error = Nack;
    }

    impl I2c for MockSccb {
        async fn transaction(
            &mut self,
            address: u8,
            operations: &mut [Operation<'_>],
        ) -> Result<(), Nack> {
            if !self.present || address != I2C_ADDRESS || operations.len() != 1 {
                return Err(Nack);
            }
            match &mut operations[0] {
                Operation::Write([r]) => self.pointer = *r,
                Operation::Write([r, v]) => {
                    self.regs[*r as usize] = *v;
                    self.log.push(Access::Write(*r, *v));
                }
                Operation::Read([out]) => {
                    *out = self.regs[self.pointer as usize];
                    self.log.push(Access::Read(self.pointer));
                }
                _ => return Err(Nack),
            }
            Ok(())
        }
    }

    #[derive(Default)]
    struct MockDelay {
        total_ns: u64,
    }

    impl DelayNs for MockDelay {
        async fn delay_ns(&mut self, ns: u32) {
            self.total_ns += u64::from(ns);
        }
    }

    #[test]
    fn init_qvga_auto_writes_the_documented_sequence() {
        let mut sensor = Ov7725::new(MockSccb::ov7725());
        let mut delay = MockDelay::default();
        let plan = block_on(sensor.init(&mut delay, &Config::default())).unwrap();
        let bus = sensor.release();
        // Id first (read, nothing written before it), then the reset.
        assert_eq!(bus.log[0], Access::Read(reg::PID));
        assert_eq!(bus.log[1], Access::Read(reg::VER));
        assert_eq!(
            bus.writes(),
            [
                (reg::COM7, 0x80),     // reset
                (reg::COM7, 0x40),     // QVGA, YUV
                (reg::COM3, 0x10),     // Y first
                (reg::HSTART, 0x3F),   // 252 / 4
                (reg::HSIZE, 0x50),    // 320 / 4
                (reg::VSTART, 0x03),   // 6 / 2
                (reg::VSIZE, 0x78),    // 240 / 2
                (reg::HREF, 0x00),     // window LSBs
                (reg::HOUTSIZE, 0x50), // 320 / 4
                (reg::VOUTSIZE, 0x78), // 240 / 2
                (reg::EXHCH, 0x00),
                (reg::DSP_CTRL4, 0x00),
                (reg::COM4, 0x41),   // PLL x4
                (reg::CLKRC, 0x84),  // / ((4 + 1) x 2)
                (reg::EXHCL, 0x00),  // no dummy pixels
                (reg::DM_LNL, 0x00), // no dummy lines
                (reg::DM_LNH, 0x00),
                (reg::COM9, 0x2A), // 8x ceiling, other COM9 bits as read (0x4A)
                (reg::COM8, 0xCF), // AEC + AGC on, banding filter off
            ]
        );
        // The reset was waited for.
        assert!(delay.total_ns >= u64::from(RESET_SETTLE_US) * 1000);
        // 24 MHz x 4 / 10 = 9.6 MHz: 278 lines of 1152 clocks = 29.98 fps.
        assert_eq!(plan.pclk_hz, 9_600_000);
        assert_eq!(plan.timing.frame_lines, 278);
        assert_eq!(plan.timing.line_ns, 120_000);
        assert_eq!(plan.timing.frame_period_us(), 33_360);
    }

    #[test]
    fn init_vga_manual_writes_exposure_and_gain() {
        let mut sensor = Ov7725::new(MockSccb::ov7725());
        let config = Config {
            resolution: Resolution::Vga,
            fps: 15,
            exposure: Exposure::Manual {
                lines: 0x0123,
                gain: GainX16(40), // 2.5x
            },
            vflip: true,
            mirror: true,
            ..Config::default()
        };
        let plan = block_on(sensor.init(&mut MockDelay::default(), &config)).unwrap();
        let w = sensor.release().writes();
        assert_eq!(w[1], (reg::COM7, 0x00)); // VGA, YUV
        assert_eq!(w[2], (reg::COM3, 0xD0)); // flip + mirror + Y first
        assert_eq!(w[3], (reg::HSTART, 0x23));
        assert_eq!(w[4], (reg::HSIZE, 0xA0));
        assert_eq!(w[5], (reg::VSTART, 0x07));
        assert_eq!(w[6], (reg::VSIZE, 0xF0));
        // VGA at 15 fps: 24 MHz / 2 = 12 MHz, no PLL, 510 lines.
        assert_eq!(w[12], (reg::COM4, 0x01));
        assert_eq!(w[13], (reg::CLKRC, 0x80));
        assert_eq!(plan.pclk_hz, 12_000_000);
        assert_eq!(plan.dummy_lines, 0);
        assert_eq!(
            &w[17..],
            [
                (reg::COM8, 0xCA), // AEC and AGC off first
                (reg::AECH, 0x01),
                (reg::AEC, 0x23),
                (reg::GAIN, 0x14), // 2 x (1 + 4/16)
            ]
        );
    }

    #[test]
    fn wrong_product_id_is_an_error_and_nothing_is_written() {
        let mut bus = MockSccb::ov7725();
        bus.regs[reg::PID as usize] = 0x26; // an OV2640's PID
        bus.regs[reg::VER as usize] = 0x42;
        let mut sensor = Ov7725::new(bus);
        let r = block_on(sensor.init(&mut MockDelay::default(), &Config::default()));
        assert_eq!(
            r,
            Err(Error::WrongChip {
                pid: 0x26,
                ver: 0x42
            })
        );
        assert!(sensor.release().writes().is_empty());
    }

    #[test]
    fn missing_sensor_is_a_bus_error() {
        let mut bus = MockSccb::ov7725();
        bus.present = false;
        let mut sensor = Ov7725::new(bus);
        let r = block_on(sensor.init(&mut MockDelay::default(), &Config::default()));
        assert_eq!(r, Err(Error::Bus(Nack)));
    }

    #[test]
    fn bad_configuration_is_refused_before_any_bus_traffic() {
        let mut sensor = Ov7725::new(MockSccb::ov7725());
        let slow_clock = Config {
            xclk_hz: 1_000_000,
            ..Config::default()
        };
        let r = block_on(sensor.init(&mut MockDelay::default(), &slow_clock));
        assert_eq!(r, Err(Error::Config(ConfigError::XclkOutOfRange)));
        let zero = Config {
            exposure: Exposure::Manual {
                lines: 0,
                gain: GainX16::ONE,
            },
            ..Config::default()
        };
        let r = block_on(sensor.init(&mut MockDelay::default(), &zero));
        assert_eq!(r, Err(Error::Config(ConfigError::ZeroExposure)));
        assert!(sensor.release().log.is_empty());
    }

    #[test]
    fn read_exposure_uses_separate_transactions() {
        let mut bus = MockSccb::ov7725();
        bus.regs[reg::AECH as usize] = 0x02;
        bus.regs[reg::AEC as usize] = 0x10;
        bus.regs[reg::GAIN as usize] = 0x30; // 4x
        let mut sensor = Ov7725::new(bus);
        let (lines, gain) = block_on(sensor.read_exposure()).unwrap();
        assert_eq!((lines, gain), (0x0210, GainX16(64)));
    }
}
