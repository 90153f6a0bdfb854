//! Whichever supported sensor is connected, behind one type.
//!
//! The OV7725 and the OV2640 sit at different SCCB addresses (0x21 and 0x30), so the
//! firmware can find out which module is plugged in by asking each address for its ids
//! ([`Camera::detect`]), then drive it with the operations the vision task needs: set up
//! for a [`Config`] (returning the [`FrameTiming`] for time stamps and the exposure loop),
//! switch exposure control, and write manual exposure and gain once per frame.
//!
//! Both drivers are configured for the same camera-interface contract: YUV 4:2:2 with Y
//! first (the interface keeps every first byte of a pair), HREF high while a line's data is
//! valid, VSYNC high between frames, data stable on PCLK's rising edge. So the camera
//! interface can be set up once, before it is known which sensor answers.

use embedded_hal_async::delay::DelayNs;
use embedded_hal_async::i2c::{ErrorType, I2c};

use crate::ov2640::{self, Ov2640};
use crate::ov7725::{self, Ov7725};
use crate::{Config, ConfigError, Exposure, FrameTiming, GainX16};

/// The supported sensors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Model {
    /// OmniVision OV7725 (VGA).
    Ov7725,
    /// OmniVision OV2640 (UXGA, run in its SVGA mode).
    Ov2640,
}

impl Model {
    /// The sensor's 7-bit SCCB address.
    pub const fn i2c_address(self) -> u8 {
        match self {
            Model::Ov7725 => ov7725::I2C_ADDRESS,
            Model::Ov2640 => ov2640::I2C_ADDRESS,
        }
    }

    /// The sensor's name, for logs.
    pub const fn name(self) -> &'static str {
        match self {
            Model::Ov7725 => "OV7725",
            Model::Ov2640 => "OV2640",
        }
    }
}

/// Why no supported sensor was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DetectError<E> {
    /// Nothing answered at either address (no module, no XCLK, a wiring fault). Holds the
    /// bus error of the last probe (the OV2640's address).
    NoAnswer(E),
    /// A device answered, but its ids are neither sensor's. The first such address and the
    /// two id bytes read there (PID/VER at the OV7725's address, PIDH/PIDL at the OV2640's).
    Unknown {
        /// 7-bit address that answered.
        address: u8,
        /// Product id, high byte.
        pid: u8,
        /// Product id, low byte.
        ver: u8,
    },
}

/// A failed [`Camera::detect`]: the error and the bus, handed back for the next attempt.
#[derive(Debug)]
pub struct Undetected<I: ErrorType> {
    /// The bus.
    pub bus: I,
    /// Why no sensor was found.
    pub error: DetectError<I::Error>,
}

/// Why the sensor could not be set up or adjusted (either driver's error).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// The SCCB/I2C transfer failed (no device, NACK, bus fault).
    Bus(E),
    /// A register write failed part-way through the set-up (NACK, bus fault): which one, so
    /// the log says how far it got. (The OV2640 reports these; the OV7725's are [`Error::Bus`].)
    Write {
        /// The sensor written to.
        model: Model,
        /// The register bank (the OV2640's: 0 DSP, 1 sensor).
        bank: u8,
        /// The register (0xFF: the OV2640's bank select).
        register: u8,
        /// The bus error.
        error: E,
    },
    /// The device no longer reads as the sensor it was detected as (module swapped or a
    /// corrupted read).
    WrongChip {
        /// The sensor it was detected as.
        model: Model,
        /// Product id high byte as read.
        pid: u8,
        /// Product id low byte as read.
        ver: u8,
    },
    /// The configuration cannot be realised by this sensor.
    Config(ConfigError),
}

impl<E> From<ov7725::Error<E>> for Error<E> {
    fn from(e: ov7725::Error<E>) -> Self {
        match e {
            ov7725::Error::Bus(e) => Error::Bus(e),
            ov7725::Error::WrongChip { pid, ver } => Error::WrongChip {
                model: Model::Ov7725,
                pid,
                ver,
            },
            ov7725::Error::Config(c) => Error::Config(c),
        }
    }
}

impl<E> From<ov2640::Error<E>> for Error<E> {
    fn from(e: ov2640::Error<E>) -> Self {
        match e {
            ov2640::Error::Bus(e) => Error::Bus(e),
            ov2640::Error::Write {
                bank,
                register,
                error,
            } => Error::Write {
                model: Model::Ov2640,
                bank: bank as u8,
                register,
                error,
            },
            ov2640::Error::WrongChip { pid, ver, .. } => Error::WrongChip {
                model: Model::Ov2640,
                pid,
                ver,
            },
            ov2640::Error::Config(c) => Error::Config(c),
        }
    }
}

/// The detected sensor with its driver.
#[derive(Debug)]
pub enum Camera<I> {
    /// An OV7725 answered at 0x21.
    Ov7725(Ov7725<I>),
    /// An OV2640 answered at 0x30.
    Ov2640(Ov2640<I>),
}

impl<I: I2c> Camera<I> {
    /// Probes for a supported sensor: the OV7725's id at its address (reads only), then the
    /// OV2640's (a bank select, then reads). The sensor must be powered, out of reset and
    /// clocked (SCCB needs XCLK). On failure the bus comes back with the error.
    pub async fn detect(i2c: I) -> Result<Self, Undetected<I>> {
        let mut ov7725 = Ov7725::new(i2c);
        let first_unknown = match ov7725.check_id().await {
            Ok(()) => return Ok(Camera::Ov7725(ov7725)),
            Err(ov7725::Error::WrongChip { pid, ver }) => Some(DetectError::Unknown {
                address: ov7725::I2C_ADDRESS,
                pid,
                ver,
            }),
            // A bus error (nothing there); check_id has no configuration to refuse.
            Err(ov7725::Error::Bus(_) | ov7725::Error::Config(_)) => None,
        };
        let mut ov2640 = Ov2640::new(ov7725.release());
        let error = match ov2640.read_id().await {
            Ok(id) if id.is_ov2640() => return Ok(Camera::Ov2640(ov2640)),
            Ok(id) => first_unknown.unwrap_or(DetectError::Unknown {
                address: ov2640::I2C_ADDRESS,
                pid: id.pid,
                ver: id.ver,
            }),
            Err(e) => first_unknown.unwrap_or(DetectError::NoAnswer(e)),
        };
        Err(Undetected {
            bus: ov2640.release(),
            error,
        })
    }

    /// Which sensor this is.
    pub fn model(&self) -> Model {
        match self {
            Camera::Ov7725(_) => Model::Ov7725,
            Camera::Ov2640(_) => Model::Ov2640,
        }
    }

    /// Checks the id, resets the sensor and configures it; returns the line and frame
    /// timing in force (with the pixel clock). The configuration is validated before
    /// anything is sent.
    pub async fn init<D: DelayNs>(
        &mut self,
        delay: &mut D,
        config: &Config,
    ) -> Result<FrameTiming, Error<I::Error>> {
        match self {
            Camera::Ov7725(sensor) => Ok(sensor.init(delay, config).await?.timing),
            Camera::Ov2640(sensor) => Ok(sensor.init(delay, config).await?.timing),
        }
    }

    /// Switches exposure control (the sensor's AEC/AGC with a gain ceiling, or manual).
    pub async fn set_exposure(&mut self, exposure: Exposure) -> Result<(), Error<I::Error>> {
        match self {
            Camera::Ov7725(sensor) => Ok(sensor.set_exposure(exposure).await?),
            Camera::Ov2640(sensor) => Ok(sensor.set_exposure(exposure).await?),
        }
    }

    /// Writes exposure (sensor line periods) and gain while in manual mode: what a
    /// software exposure loop calls per adjustment.
    pub async fn set_manual(&mut self, lines: u16, gain: GainX16) -> Result<(), Error<I::Error>> {
        match self {
            Camera::Ov7725(sensor) => Ok(sensor.set_manual(lines, gain).await?),
            Camera::Ov2640(sensor) => Ok(sensor.set_manual(lines, gain).await?),
        }
    }

    /// Reads the exposure (sensor line periods) and gain in force.
    pub async fn read_exposure(&mut self) -> Result<(u16, GainX16), Error<I::Error>> {
        match self {
            Camera::Ov7725(sensor) => Ok(sensor.read_exposure().await?),
            Camera::Ov2640(sensor) => Ok(sensor.read_exposure().await?),
        }
    }

    /// Gives the bus back.
    pub fn release(self) -> I {
        match self {
            Camera::Ov7725(sensor) => sensor.release(),
            Camera::Ov2640(sensor) => sensor.release(),
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec;

    use super::*;
    use crate::mock::{Access, Device, MockBus, MockDelay, Nack};
    use crate::Resolution;
    use embassy_futures::block_on;

    fn ov7725() -> Device {
        let mut d = Device::new(ov7725::I2C_ADDRESS);
        d.regs[0][usize::from(ov7725::reg::PID)] = ov7725::PRODUCT_ID;
        d.regs[0][usize::from(ov7725::reg::VER)] = ov7725::PRODUCT_VERSION;
        d.regs[0][usize::from(ov7725::reg::COM9)] = 0x4A; // datasheet reset value
        d
    }

    fn ov2640() -> Device {
        use ov2640::reg::sensor;
        let mut d = Device::banked(ov2640::I2C_ADDRESS);
        d.regs[1][usize::from(sensor::PIDH)] = 0x26;
        d.regs[1][usize::from(sensor::PIDL)] = 0x42;
        d.regs[1][usize::from(sensor::MIDH)] = 0x7F;
        d.regs[1][usize::from(sensor::MIDL)] = 0xA2;
        d
    }

    #[test]
    fn detects_an_ov7725_without_writing() {
        let camera = block_on(Camera::detect(MockBus::with(vec![ov7725()]))).unwrap();
        assert_eq!(camera.model(), Model::Ov7725);
        let bus = camera.release();
        assert_eq!(
            bus.log,
            [
                Access::Read(0x21, ov7725::reg::PID),
                Access::Read(0x21, ov7725::reg::VER)
            ]
        );
    }

    #[test]
    fn detects_an_ov2640_after_the_ov7725_address_stays_silent() {
        let camera = block_on(Camera::detect(MockBus::with(vec![ov2640()]))).unwrap();
        assert_eq!(camera.model(), Model::Ov2640);
        let bus = camera.release();
        // Only the OV2640's address saw traffic, and only the bank select was written.
        assert!(bus
            .log
            .iter()
            .all(|a| matches!(a, Access::Read(0x30, _) | Access::Write(0x30, 0xFF, 1))));
        assert_eq!(bus.writes(), [(0xFF, 1)]);
    }

    #[test]
    fn no_sensor_is_an_error_and_the_bus_comes_back() {
        let undetected = block_on(Camera::detect(MockBus::default())).unwrap_err();
        assert_eq!(undetected.error, DetectError::NoAnswer(Nack));
        // The bus is usable again: a sensor that appears later is found.
        let mut bus = undetected.bus;
        bus.devices.push(ov2640());
        let camera = block_on(Camera::detect(bus)).unwrap();
        assert_eq!(camera.model(), Model::Ov2640);
    }

    #[test]
    fn an_unknown_device_is_reported_with_its_ids() {
        // Something at the OV7725's address with another id (an OV7670 reads 0x76/0x73).
        let mut d = Device::new(0x21);
        d.regs[0][0x0A] = 0x76;
        d.regs[0][0x0B] = 0x73;
        let undetected = block_on(Camera::detect(MockBus::with(vec![d]))).unwrap_err();
        assert_eq!(
            undetected.error,
            DetectError::Unknown {
                address: 0x21,
                pid: 0x76,
                ver: 0x73
            }
        );
        // An OV2640 of an unknown revision at its address.
        let mut d = ov2640();
        d.regs[1][usize::from(ov2640::reg::sensor::PIDL)] = 0x50;
        let undetected = block_on(Camera::detect(MockBus::with(vec![d]))).unwrap_err();
        assert_eq!(
            undetected.error,
            DetectError::Unknown {
                address: 0x30,
                pid: 0x26,
                ver: 0x50
            }
        );
    }

    #[test]
    fn init_and_exposure_go_to_the_detected_sensor() {
        let config = Config {
            exposure: Exposure::Manual {
                lines: 16,
                gain: GainX16::ONE,
            },
            ..Config::default()
        };
        // OV7725: its own timing (QVGA, 278 lines of 120 µs).
        let bus = MockBus::with(vec![ov7725(), ov2640()]);
        let mut camera = block_on(Camera::detect(bus)).unwrap();
        assert_eq!(camera.model(), Model::Ov7725);
        let timing = block_on(camera.init(&mut MockDelay::default(), &config)).unwrap();
        assert_eq!((timing.frame_lines, timing.line_ns), (278, 120_000));
        block_on(camera.set_manual(20, GainX16(32))).unwrap();
        let bus = camera.release();
        assert!(bus
            .log
            .iter()
            .all(|a| !matches!(a, Access::Write(0x30, ..))));
        assert_eq!(
            bus.log.last(),
            Some(&Access::Write(0x21, ov7725::reg::GAIN, 0x10))
        );

        // OV2640: the SVGA mode's timing (672 lines of 1190 sensor clocks).
        let mut camera = block_on(Camera::detect(MockBus::with(vec![ov2640()]))).unwrap();
        let timing = block_on(camera.init(&mut MockDelay::default(), &config)).unwrap();
        assert_eq!((timing.frame_lines, timing.active_lines), (672, 600));
        block_on(camera.set_manual(20, GainX16(32))).unwrap();
        assert_eq!(block_on(camera.read_exposure()).unwrap(), (20, GainX16(32)));
    }

    #[test]
    fn auto_exposure_maps_to_each_sensors_gain_ceiling() {
        let auto = Exposure::Auto {
            max_gain: GainX16(16 * 8),
        };
        // OV7725: COM9[6:4] = 010 (8x), other bits as read (0x4A).
        let mut camera = block_on(Camera::detect(MockBus::with(vec![ov7725()]))).unwrap();
        block_on(camera.set_exposure(auto)).unwrap();
        let w = camera.release().writes();
        assert_eq!(w, [(ov7725::reg::COM9, 0x2A), (ov7725::reg::COM8, 0xCF)]);
        // OV2640: COM9[7:5] = 010 (8x).
        let mut camera = block_on(Camera::detect(MockBus::with(vec![ov2640()]))).unwrap();
        block_on(camera.set_exposure(auto)).unwrap();
        let w = camera.release().writes();
        assert_eq!(
            w[w.len() - 2..],
            [
                (ov2640::reg::sensor::COM9, 0x40),
                (ov2640::reg::sensor::COM8, 0xC5)
            ]
        );
        // Below 2x and above 32x are limited to the sensors' range (COM9[6:4] = 0 and 4).
        assert_eq!(crate::gain_ceiling_log2(GainX16::ONE), 1);
        assert_eq!(crate::gain_ceiling_log2(GainX16(u16::MAX)), 5);
    }

    #[test]
    fn errors_name_the_sensor_and_the_cause() {
        let mut camera = block_on(Camera::detect(MockBus::with(vec![ov2640()]))).unwrap();
        let too_fast = Config {
            fps: 60,
            resolution: Resolution::Vga,
            ..Config::default()
        };
        assert_eq!(
            block_on(camera.init(&mut MockDelay::default(), &too_fast)),
            Err(Error::Config(ConfigError::FrameRateUnreachable))
        );
        // The module is swapped for an OV7725-less bus between detection and init.
        let mut bus = camera.release();
        bus.device(0x30).regs[1][usize::from(ov2640::reg::sensor::PIDH)] = 0x77;
        let mut camera = Camera::Ov2640(Ov2640::new(bus));
        assert_eq!(
            block_on(camera.init(&mut MockDelay::default(), &Config::default())),
            Err(Error::WrongChip {
                model: Model::Ov2640,
                pid: 0x77,
                ver: 0x42
            })
        );
        let mut camera = Camera::Ov7725(Ov7725::new(MockBus::default()));
        assert_eq!(
            block_on(camera.set_manual(10, GainX16::ONE)),
            Err(Error::Bus(Nack))
        );
        // An OV2640 write that fails names its register (here the bank select before it).
        let mut camera = Camera::Ov2640(Ov2640::new(MockBus::default()));
        assert_eq!(
            block_on(camera.set_manual(10, GainX16::ONE)),
            Err(Error::Write {
                model: Model::Ov2640,
                bank: 1,
                register: 0xFF,
                error: Nack
            })
        );
    }
}
