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
