//! The camera's SCCB bus: embassy's async I2C behind a DMA bounce buffer.
//!
//! embassy-stm32's async I2C moves every byte with DMA1. DMA1 cannot reach DTCM, where this
//! firmware keeps its stack and every task's state (see `memory.x`), so the sensor driver's
//! two-byte register writes, which live in a task future, would make the DMA fault. This
//! adapter implements the same `embedded_hal_async::i2c::I2c` trait and copies each transfer
//! through a small buffer in AXI SRAM, with D-cache maintenance around the DMA (clean before
//! a write, invalidate after a read).
//!
//! SCCB has no repeated start, and no sensor driver asks for one (the OV7725's, the
//! OV2640's, and the probe that tries both addresses, `touchdown_sensors::any`): each
//! sends one operation per transaction, a register read being a one-byte write of the address
//! and then a separate one-byte read; the OV2640's bank select is an ordinary two-byte write.
//! The probe's access to the address of the sensor that is not fitted ends in a NACK
//! ([`SccbError::I2c`]), which it takes as "not this one". A transaction of several operations
//! would need a repeated start between them, which this adapter does not fake; it refuses it
//! ([`SccbError::Unsupported`]), as it refuses a transfer longer than the bounce buffer.

use embassy_stm32::i2c::{self, I2c, Master};
use embassy_stm32::mode::Async;
use embedded_hal_async::i2c::{ErrorKind, ErrorType, Operation};

/// Largest single transfer, bytes (one cache line).
pub const BOUNCE_LEN: usize = 32;

/// The DMA-reachable staging buffer: one cache line, in AXI SRAM (`main` places it).
#[repr(C, align(32))]
pub struct Bounce([u8; BOUNCE_LEN]);

impl Bounce {
    /// A zeroed buffer (const: usable as a static's initialiser).
    pub const fn new() -> Self {
        Bounce([0; BOUNCE_LEN])
    }
}

/// Why an SCCB transfer failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum SccbError {
    /// The I2C peripheral reported an error (NACK: no sensor, or a wiring fault).
    I2c(i2c::Error),
    /// More than one operation, or more than [`BOUNCE_LEN`] bytes.
    Unsupported,
}

impl embedded_hal_async::i2c::Error for SccbError {
    fn kind(&self) -> ErrorKind {
        match self {
            SccbError::I2c(e) => embedded_hal_async::i2c::Error::kind(e),
            SccbError::Unsupported => ErrorKind::Other,
        }
    }
}

/// The I2C bus with its bounce buffer.
pub struct Sccb {
    i2c: I2c<'static, Async, Master>,
    bounce: &'static mut Bounce,
}

impl Sccb {
    /// Wraps `i2c`; `bounce` must be in DMA-reachable RAM (AXI SRAM or SRAM1..3).
    pub fn new(i2c: I2c<'static, Async, Master>, bounce: &'static mut Bounce) -> Self {
        Sccb { i2c, bounce }
    }
}

impl ErrorType for Sccb {
    type Error = SccbError;
}

impl embedded_hal_async::i2c::I2c for Sccb {
    async fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), SccbError> {
        let [operation] = operations else {
            return Err(SccbError::Unsupported);
        };
        // SAFETY: the core peripherals are stolen only for D-cache maintenance by address on
        // the bounce buffer, which this adapter owns exclusively.
        let mut scb = unsafe { cortex_m::Peripherals::steal() }.SCB;
        match operation {
            Operation::Write(bytes) => {
                let staged = self
                    .bounce
                    .0
                    .get_mut(..bytes.len())
                    .ok_or(SccbError::Unsupported)?;
                staged.copy_from_slice(bytes);
                // The DMA reads memory, not the cache: write the line back first.
                scb.clean_dcache_by_slice(&self.bounce.0);
                let staged = self.bounce.0.get(..bytes.len()).unwrap_or(&[]);
                self.i2c
                    .write(address, staged)
                    .await
                    .map_err(SccbError::I2c)
            }
            Operation::Read(buffer) => {
                let n = buffer.len();
                if n > BOUNCE_LEN {
                    return Err(SccbError::Unsupported);
                }
                // No dirty line may be evicted over the DMA's data.
                scb.clean_dcache_by_slice(&self.bounce.0);
                let staged = self.bounce.0.get_mut(..n).unwrap_or(&mut []);
                let result = self.i2c.read(address, staged).await;
                // SAFETY: the line was cleaned above and the CPU has not written it since.
                unsafe { scb.invalidate_dcache_by_slice(&mut self.bounce.0) };
                result.map_err(SccbError::I2c)?;
                if let Some(staged) = self.bounce.0.get(..n) {
                    buffer.copy_from_slice(staged);
                }
                Ok(())
            }
        }
    }
}
