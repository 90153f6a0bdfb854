//! MAVLink parameters in flash: loaded at boot, saved after a change.
//!
//! The last 128 KiB sector of flash bank 2 (offset 0x1E_0000 of the 2 MiB) holds an
//! append-only log of parameter slots (`touchdown_core::companion::persist`: format, scan
//! and debounce logic, host-tested). `memory.x` ends the FLASH region before this sector, so
//! code can never land in it.
//!
//! Why bank 2: the STM32H743's two banks are read-while-write capable, so erasing or
//! programming bank 2 does not stall instruction fetches from bank 1, where the code runs.
//! The driver is embassy's *async* flash: an erase (up to a few seconds for 128 KiB) waits on
//! the flash interrupt instead of spinning, so the other tasks keep running and the watchdog
//! keeps being fed. Saves go through [`SAVE`] to [`task`], so a slow erase never holds up the
//! MAVLink loop either.

use defmt::{info, warn};
use embassy_stm32::flash::{Async, Flash, FLASH_SIZE};
use touchdown_core::companion::params::ParamSet;
use touchdown_core::companion::persist::{self, Restore, ScanResult, SLOT_LEN};
use touchdown_core::companion::MavSeverity;

use crate::channels::{self, LinkEvent, SAVE};

/// Size of the parameter sector.
pub const SECTOR_SIZE: u32 = 128 * 1024;
/// Offset of the parameter sector from the start of flash: the last sector of bank 2.
pub const SECTOR_OFFSET: u32 = FLASH_SIZE as u32 - SECTOR_SIZE;
/// Slots in the sector.
pub const SLOTS: usize = SECTOR_SIZE as usize / SLOT_LEN;

/// Reads the log at boot: the restored parameters (defaults if none) and where the next save
/// goes. Reports a corrupt log as a STATUSTEXT once the link runs.
pub fn load(flash: &mut Flash<'static, Async>) -> (ParamSet, Option<usize>) {
    let mut params = ParamSet::default();
    let ScanResult { restore, next_free } = persist::scan(
        SLOTS,
        |slot, buf| {
            let offset = SECTOR_OFFSET + (slot * SLOT_LEN) as u32;
            flash.blocking_read(offset, buf).is_ok()
        },
        &mut params,
    );
    match restore {
        Restore::Empty => info!("params: none saved, defaults"),
        Restore::Restored {
            slot,
            report,
            bad_slots,
        } => {
            info!(
                "params: restored slot {} ({}), {} bad slot(s)",
                slot, report, bad_slots
            );
            if bad_slots > 0 {
                channels::post_to_link(LinkEvent::Status(
                    MavSeverity::MAV_SEVERITY_WARNING,
                    "touchdown: params restored, damaged saves skipped",
                ));
            }
        }
        Restore::Corrupt { error, bad_slots } => {
            warn!(
                "params: {} slot(s), none valid ({}): defaults",
                bad_slots, error
            );
            channels::post_to_link(LinkEvent::Status(
                MavSeverity::MAV_SEVERITY_ERROR,
                "touchdown: saved params bad (CRC), using defaults",
            ));
        }
    }
    (params, next_free)
}

/// Writes each parameter set signalled on [`SAVE`] into the next free slot, erasing the
/// sector when it is full.
#[embassy_executor::task]
pub async fn task(mut flash: Flash<'static, Async>, mut next_free: Option<usize>) {
    let mut slot = [0u8; SLOT_LEN];
    loop {
        let params = SAVE.wait().await;
        let index = match next_free {
            Some(i) if i < SLOTS => i,
            _ => {
                info!("params: sector full, erasing");
                if let Err(e) = flash
                    .erase(SECTOR_OFFSET, SECTOR_OFFSET + SECTOR_SIZE)
                    .await
                {
                    warn!("params: erase failed: {}", e);
                    channels::post_to_link(LinkEvent::Status(
                        MavSeverity::MAV_SEVERITY_ERROR,
                        "touchdown: flash erase failed, params not saved",
                    ));
                    continue;
                }
                0
            }
        };
        persist::encode_slot(&params, &mut slot);
        let offset = SECTOR_OFFSET + (index * SLOT_LEN) as u32;
        match flash.write(offset, &slot).await {
            Ok(()) => {
                info!("params: saved to slot {}", index);
                next_free = Some(index + 1);
            }
            Err(e) => {
                warn!("params: write failed: {}", e);
                // Never write a flash word twice: move on, the next save erases if needed.
                next_free = Some(index + 1);
                channels::post_to_link(LinkEvent::Status(
                    MavSeverity::MAV_SEVERITY_ERROR,
                    "touchdown: flash write failed, params not saved",
                ));
            }
        }
    }
}
