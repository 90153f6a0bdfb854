//! The driver's tests against the mock SCCB bus: the bank handling, the id check, errors,
//! manual exposure. The write sequence of the set-up is tested in `sequence`; the tables and
//! the clock plan next to their code.

extern crate std;
use std::vec;
use std::vec::Vec;

use super::reg::{dsp, sensor, BANK_SEL};
use super::*;
use crate::mock::{Access, Device, MockBus, MockDelay, Nack};
use embassy_futures::block_on;
use embedded_hal_async::i2c::{ErrorType, I2c, Operation};

mod sequence;

/// An OV2640 at its address with the datasheet's id registers (and a few reset values
/// the driver reads back).
fn ov2640_bus(pidl: u8) -> MockBus {
    let mut device = Device::banked(I2C_ADDRESS);
    let s = Bank::Sensor as usize;
    device.regs[s][usize::from(sensor::PIDH)] = PRODUCT_ID_HIGH;
    device.regs[s][usize::from(sensor::PIDL)] = pidl;
    device.regs[s][usize::from(sensor::MIDH)] = 0x7F;
    device.regs[s][usize::from(sensor::MIDL)] = 0xA2;
    device.regs[s][usize::from(sensor::COM9)] = 0x50; // 8x ceiling, bit 4 set
    device.regs[Bank::Dsp as usize][usize::from(dsp::CTRL0)] = 0xC0 | CTRL0_V_FIRST;
    MockBus::with(vec![device])
}

fn bank(b: Bank) -> (u8, u8) {
    (BANK_SEL, b as u8)
}

/// The writes after the reset (the id check writes only the bank select before it).
fn after_reset(bus: &MockBus) -> Vec<(u8, u8)> {
    let w = bus.writes();
    let reset = w
        .iter()
        .position(|&x| x == (sensor::COM7, COM7_RESET))
        .unwrap();
    w[reset + 1..].to_vec()
}

/// The writes after the reset with the bank each went to, bank selects taken out. Fails
/// the test if a bank select does not change the bank (the first one after the reset
/// excepted: the reset leaves the bank unknown), or if a register is written before any
/// bank was selected.
fn banked_after_reset(bus: &MockBus) -> Vec<Setting> {
    let mut selected: Option<Bank> = None;
    let mut out = Vec::new();
    for (i, (register, value)) in after_reset(bus).into_iter().enumerate() {
        if register == BANK_SEL {
            let b = if value == 0 { Bank::Dsp } else { Bank::Sensor };
            assert!(
                selected != Some(b),
                "write {i}: bank {b:?} selected again while selected"
            );
            selected = Some(b);
        } else {
            let bank = selected.expect("a register written before any bank select");
            out.push(Setting {
                bank,
                register,
                value,
            });
        }
    }
    out
}

/// A bus that refuses (NACKs) the `nth` write (0-based) to one register of one bank of
/// the OV2640 and passes everything else to the mock.
struct Refusing {
    bus: MockBus,
    bank: Bank,
    register: u8,
    nth: usize,
    seen: usize,
}

impl ErrorType for Refusing {
    type Error = Nack;
}

impl I2c for Refusing {
    async fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Nack> {
        if let [Operation::Write([register, _])] = operations {
            let bank = self.bus.device(I2C_ADDRESS).bank;
            if *register == self.register && bank == self.bank as usize {
                self.seen += 1;
                if self.seen == self.nth + 1 {
                    return Err(Nack);
                }
            }
        }
        self.bus.transaction(address, operations).await
    }
}

#[test]
fn a_refused_write_is_an_error_naming_its_register_and_nothing_follows_it() {
    // The whole set-up on a bus that acknowledges everything.
    let mut camera = Ov2640::new(ov2640_bus(0x42));
    block_on(camera.init(&mut MockDelay::default(), &Config::default())).unwrap();
    let full = camera.release().log;
    // (bank selected when the write is refused, register, which of its writes in that
    // bank is refused, the error's bank).
    for (bank, register, nth, named_bank) in [
        (Bank::Sensor, 0x35, 0, Bank::Sensor),  // mid SVGA_TIMING
        (Bank::Dsp, dsp::BPDATA, 3, Bank::Dsp), // mid DSP_COMMON, a data port
        (Bank::Dsp, 0xE1, 1, Bank::Dsp),        // YUV422 (DSP_COMMON wrote it first)
        (Bank::Sensor, sensor::CLKRC, 0, Bank::Sensor), // a derived value
        // The select of the DSP bank right after the reset (the sensor bank still
        // selected): named as a write of BANK_SEL for the DSP bank.
        (Bank::Sensor, BANK_SEL, 0, Bank::Dsp),
    ] {
        let mut camera = Ov2640::new(Refusing {
            bus: ov2640_bus(0x42),
            bank,
            register,
            nth,
            seen: 0,
        });
        let r = block_on(camera.init(&mut MockDelay::default(), &Config::default()));
        assert_eq!(
            r,
            Err(Error::Write {
                bank: named_bank,
                register,
                error: Nack
            }),
            "{register:#04x}"
        );
        // What went through is the set-up up to the refused write, and nothing after it.
        let log = camera.release().bus.log;
        assert_eq!(log[..], full[..log.len()], "{register:#04x}");
        assert!(
            matches!(full[log.len()], Access::Write(_, r, _) if r == register),
            "{register:#04x}: {:?}",
            full[log.len()]
        );
    }
}

#[test]
fn manual_exposure_and_flips_at_init() {
    let mut camera = Ov2640::new(ov2640_bus(0x42));
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
    let plan = block_on(camera.init(&mut MockDelay::default(), &config)).unwrap();
    // 15 fps: 24 MHz / 2 = 12 MHz, no dummy lines.
    assert_eq!(
        (plan.doubler, plan.divider, plan.dummy_lines),
        (false, 1, 0)
    );
    assert_eq!(camera.max_exposure_lines(), 672);
    let w = after_reset(&camera.release());
    assert!(w.contains(&(sensor::CLKRC, 0x01)));
    // Mirror, flip and the one-row shift that keeps the Bayer phase.
    assert!(w.contains(&(sensor::REG04, 0xF8)));
    let tail = &w[w.len() - 5..];
    assert_eq!(
        tail,
        [
            (sensor::COM8, 0xC0),  // AEC and AGC off first
            (sensor::REG45, 0x00), // 0x0123 >> 10
            (sensor::AEC, 0x48),   // (0x0123 >> 2) & 0xFF
            (sensor::REG04, 0xFB), // flips kept, AEC[1:0] = 3
            (sensor::GAIN, 0x14),  // 2 x (1 + 4/16)
        ]
    );
}

#[test]
fn set_manual_splits_and_clamps() {
    let mut camera = Ov2640::new(ov2640_bus(0x42));
    // Before init the whole 16-bit range is accepted.
    block_on(camera.set_manual(0xFFFF, GainX16(16 * 64))).unwrap();
    block_on(camera.set_manual(0, GainX16(0))).unwrap();
    let bus = camera.release();
    assert_eq!(
        bus.writes(),
        [
            bank(Bank::Sensor),
            (sensor::REG45, 0x3F), // AEC[15:10], AGC[9:8] = 0
            (sensor::AEC, 0xFF),
            (sensor::REG04, 0x2B),
            (sensor::GAIN, 0xFF), // 64x clamped to 31x, the register's top
            // No bank select: the sensor bank is still selected.
            (sensor::REG45, 0x00), // 0 lines clamped to 1
            (sensor::AEC, 0x00),
            (sensor::REG04, 0x29),
            (sensor::GAIN, 0x00), // below 1x clamped to 1x
        ]
    );
    // After init: at most one frame (25 fps: 672 + 135 dummy lines = 807).
    let mut camera = Ov2640::new(bus);
    let config = Config {
        fps: 25,
        exposure: Exposure::Manual {
            lines: 100,
            gain: GainX16::ONE,
        },
        ..Config::default()
    };
    let plan = block_on(camera.init(&mut MockDelay::default(), &config)).unwrap();
    assert_eq!(plan.dummy_lines, 135);
    assert_eq!(camera.max_exposure_lines(), 807);
    block_on(camera.set_manual(5000, GainX16::ONE)).unwrap();
    let w = camera.release().writes();
    assert_eq!(
        w[w.len() - 4..],
        [
            (sensor::REG45, 0x00),
            (sensor::AEC, 0xC9), // 807 = 0b11_0010_0111: 807 >> 2 = 201
            (sensor::REG04, 0x2B),
            (sensor::GAIN, 0x00),
        ]
    );
}

#[test]
fn wrong_id_is_an_error_and_only_the_bank_select_is_written() {
    // An OV7670-like id, and an OV2640 id with another manufacturer.
    for (pid, ver, mid) in [
        (0x76, 0x73, 0x7FA2),
        (0x26, 0x42, 0x0000),
        (0x26, 0x43, 0x7FA2),
    ] {
        let mut bus = ov2640_bus(ver);
        let s = Bank::Sensor as usize;
        let device = bus.device(I2C_ADDRESS);
        device.regs[s][usize::from(sensor::PIDH)] = pid;
        let [midh, midl] = u16::to_be_bytes(mid);
        device.regs[s][usize::from(sensor::MIDH)] = midh;
        device.regs[s][usize::from(sensor::MIDL)] = midl;
        let mut camera = Ov2640::new(bus);
        let r = block_on(camera.init(&mut MockDelay::default(), &Config::default()));
        assert_eq!(
            r,
            Err(Error::WrongChip {
                pid,
                ver,
                manufacturer: mid
            })
        );
        assert_eq!(camera.release().writes(), [bank(Bank::Sensor)]);
    }
}

#[test]
fn missing_sensor_is_a_bus_error_and_the_bank_is_reselected() {
    let mut camera = Ov2640::new(MockBus::default());
    let r = block_on(camera.init(&mut MockDelay::default(), &Config::default()));
    assert_eq!(r, Err(Error::Bus(Nack)));
    // A failed bank select leaves the bank unknown: the next access selects it again.
    let mut camera = Ov2640::new(ov2640_bus(0x42));
    block_on(camera.check_id()).unwrap();
    camera.bank = None;
    block_on(camera.set_manual(10, GainX16::ONE)).unwrap();
    let w = camera.release().writes();
    assert_eq!(w.iter().filter(|&&x| x == bank(Bank::Sensor)).count(), 2);
}

#[test]
fn bad_configuration_is_refused_before_any_bus_traffic() {
    let mut camera = Ov2640::new(ov2640_bus(0x42));
    let slow = Config {
        xclk_hz: 1_000_000,
        ..Config::default()
    };
    let r = block_on(camera.init(&mut MockDelay::default(), &slow));
    assert_eq!(r, Err(Error::Config(ConfigError::XclkOutOfRange)));
    let fast = Config {
        fps: 60,
        ..Config::default()
    };
    let r = block_on(camera.init(&mut MockDelay::default(), &fast));
    assert_eq!(r, Err(Error::Config(ConfigError::FrameRateUnreachable)));
    let zero = Config {
        exposure: Exposure::Manual {
            lines: 0,
            gain: GainX16::ONE,
        },
        ..Config::default()
    };
    let r = block_on(camera.init(&mut MockDelay::default(), &zero));
    assert_eq!(r, Err(Error::Config(ConfigError::ZeroExposure)));
    assert!(camera.release().log.is_empty());
}

#[test]
fn exposure_fields_round_trip() {
    for lines in [0u16, 1, 3, 4, 0x3FF, 0x400, 0x1234, 0xFFFF] {
        let (high, middle, low) = exposure_fields(lines);
        assert!(high <= 0x3F && low <= 0x03);
        // Whatever else the registers hold (flip bits, AGC[9:8]) is ignored.
        assert_eq!(exposure_from_fields(high | 0xC0, middle, low | 0xFC), lines);
    }
}

#[test]
fn read_exposure_uses_the_sensor_bank_and_separate_transactions() {
    let mut bus = ov2640_bus(0x42);
    let device = bus.device(I2C_ADDRESS);
    let s = Bank::Sensor as usize;
    device.regs[s][usize::from(sensor::REG45)] = 0xC1; // AGC[9:8] set, AEC[15:10] = 1
    device.regs[s][usize::from(sensor::AEC)] = 0x02;
    device.regs[s][usize::from(sensor::REG04)] = 0x2A;
    device.regs[s][usize::from(sensor::GAIN)] = 0x30; // 4x

    // Something else at GAIN's address in the DSP bank, to catch a read from the wrong bank.
    device.regs[Bank::Dsp as usize][usize::from(sensor::GAIN)] = 0xFF;
    let mut camera = Ov2640::new(bus);
    let (lines, gain) = block_on(camera.read_exposure()).unwrap();
    assert_eq!((lines, gain), (0x040A, GainX16(64)));
}

#[test]
fn init_after_a_power_cycle_selects_the_bank_again() {
    // Detected (sensor bank selected and remembered), then power-cycled through the
    // pins, which puts the bank select back to the DSP bank.
    let mut camera = Ov2640::new(ov2640_bus(0x42));
    block_on(camera.check_id()).unwrap();
    camera.i2c.device(I2C_ADDRESS).bank = Bank::Dsp as usize;
    block_on(camera.init(&mut MockDelay::default(), &Config::default())).unwrap();
    let w = camera.release().writes();
    assert_eq!(
        w[..3],
        [bank(Bank::Sensor), bank(Bank::Sensor), (sensor::COM7, 0x80)]
    );
}

#[test]
fn explicit_bank_select_write_forgets_the_bank() {
    let mut camera = Ov2640::new(ov2640_bus(0x42));
    block_on(camera.write_register(Bank::Sensor, BANK_SEL, 0)).unwrap();
    block_on(camera.write_register(Bank::Sensor, sensor::GAIN, 0x10)).unwrap();
    let bus = camera.release();
    assert_eq!(
        bus.writes(),
        [
            bank(Bank::Sensor),
            (BANK_SEL, 0),
            bank(Bank::Sensor),
            (sensor::GAIN, 0x10)
        ]
    );
    let mut bus = bus;
    assert_eq!(bus.device(I2C_ADDRESS).regs[1][0], 0x10);
}
