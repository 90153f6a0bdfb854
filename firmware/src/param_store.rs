//! MAVLink parameters in flash: loaded at boot, saved after a change.
//!
//! The last two 128 KiB sectors of flash bank 2 (offsets 0x1C_0000 and 0x1E_0000 of the
//! 2 MiB) hold a log of parameter slots that survives a power cut at any point of a save:
//! slots are appended to one sector, and only when it is full is the other (older) one erased
//! and written. The format, the scan, which sector and slot come next, when to erase and what
//! to do after a failed write are all `touchdown_core::params::Store`
//! (host-tested against a flash model that cuts the power at every program and erase step);
//! this module only gives it the flash driver ([`ParamFlash`]) and reports what happened.
//! `memory.x` ends the FLASH region before these sectors, so code can never land in them.
//!
//! On an OpenMV Cam H7 the last sector held OpenMV's ROMFS (and a board that ran other
//! firmware may hold anything there): a sector with data but no valid slot is erased when
//! [`task`] starts, or saving would never find room.
//!
//! Why bank 2: the STM32H743's two banks are read-while-write capable, so erasing or
//! programming bank 2 does not stall instruction fetches from bank 1, where the code runs.
//! The driver is embassy's *async* flash: an erase (up to a few seconds for 128 KiB) waits on
//! the flash interrupt instead of spinning, so the other tasks keep running and the watchdog
//! keeps being fed. Saves go through [`SAVE`] to [`task`], so a slow erase never holds up the
//! MAVLink loop either.

use defmt::{info, warn};
use embassy_stm32::flash::{Async, Flash, FLASH_SIZE};
use touchdown_core::companion::MavSeverity;
use touchdown_core::params::{
    Boot, FlashFailed, Geometry, ParamSet, SaveError, SlotFlash, SlotKey, Store, SECTORS,
};

use crate::channels::{self, LinkEvent, SAVE};

/// Size of each parameter sector.
pub const SECTOR_SIZE: u32 = 128 * 1024;
/// Offsets of the parameter sectors from the start of flash: the last two sectors of bank 2
/// (0x081C_0000 and 0x081E_0000; the second is where the one-sector log of older firmware
/// lived, which `Store` still reads).
pub const SECTOR_OFFSETS: [u32; SECTORS] = [
    FLASH_SIZE as u32 - 2 * SECTOR_SIZE,
    FLASH_SIZE as u32 - SECTOR_SIZE,
];
/// The sectors, checked at compile time.
const GEOMETRY: Geometry = match Geometry::new(SECTOR_SIZE) {
    Some(g) => g,
    None => panic!("SECTOR_SIZE cannot hold the parameter log"),
};

/// The offset from the start of flash of `offset` in parameter sector `sector`.
fn flash_offset(sector: usize, offset: u32) -> Option<u32> {
    SECTOR_OFFSETS.get(sector)?.checked_add(offset)
}

/// The flash driver as `Store` wants it: per-sector offsets, async erase and write (the
/// H7 driver programs 32-byte flash words in ascending order and stops at the first error,
/// which the power-loss argument relies on).
pub struct ParamFlash<'a>(pub &'a mut Flash<'static, Async>);

impl SlotFlash for ParamFlash<'_> {
    async fn erase(&mut self, sector: usize) -> Result<(), FlashFailed> {
        let from = flash_offset(sector, 0).ok_or(FlashFailed)?;
        info!("params: erasing sector at 0x{:x}", from);
        self.0.erase(from, from + SECTOR_SIZE).await.map_err(|e| {
            warn!("params: erase at 0x{:x} failed: {}", from, e);
            FlashFailed
        })
    }

    async fn write(&mut self, sector: usize, offset: u32, bytes: &[u8]) -> Result<(), FlashFailed> {
        let at = flash_offset(sector, offset).ok_or(FlashFailed)?;
        self.0.write(at, bytes).await.map_err(|e| {
            warn!("params: write at 0x{:x} failed: {}", at, e);
            FlashFailed
        })
    }
}

/// Scans both parameter sectors at boot (256 KiB of reads and CRCs, a few ms; no erase, that
/// is the task's): the restored parameters (defaults if none) and the [`Store`] that [`task`]
/// continues from. Reports damaged or lost parameters as a STATUSTEXT once the link runs.
pub fn load(flash: &mut Flash<'static, Async>) -> (ParamSet, Store) {
    let mut params = ParamSet::default();
    let (store, boot) = Store::open(
        GEOMETRY,
        |sector, offset, buf| match flash_offset(sector, offset) {
            Some(at) => flash.blocking_read(at, buf).is_ok(),
            None => false,
        },
        &mut params,
    );
    let Boot {
        restored,
        bad_slots,
        foreign,
    } = boot;
    if foreign.iter().any(|&f| f) {
        info!(
            "params: sectors holding data but no parameters (erased next): {}",
            foreign
        );
    }
    match restored {
        None if bad_slots == 0 => info!("params: none saved, defaults"),
        Some(r) => {
            info!(
                "params: restored {} from sector {} ({}), {} bad slot(s)",
                r.key, r.sector, r.report, bad_slots
            );
            if let SlotKey::Legacy(_) = r.key {
                // Kept as it is; the next save goes to the other sector in the new format.
                info!("params: read from the format-1 log of an older firmware");
            }
            if bad_slots > 0 {
                channels::post_to_link(LinkEvent::Status(
                    MavSeverity::MAV_SEVERITY_WARNING,
                    "touchdown: params restored, damaged saves skipped",
                ));
            }
        }
        None => {
            warn!("params: {} slot(s), none valid: defaults", bad_slots);
            channels::post_to_link(LinkEvent::Status(
                MavSeverity::MAV_SEVERITY_ERROR,
                "touchdown: saved params bad (CRC), using defaults",
            ));
        }
    }
    (params, store)
}

/// Erases the sectors [`load`] found holding foreign data, then saves each parameter set
/// signalled on [`SAVE`] (the newest wins if saves pile up) with `Store::save`: at most one
/// erase (async: the other tasks run meanwhile) and one slot write per save. A failed save is
/// reported; the next save retries (an erase) or goes after the failed words (a write).
#[embassy_executor::task]
pub async fn task(mut flash: Flash<'static, Async>, mut store: Store) {
    let mut flash = ParamFlash(&mut flash);
    let cleanup = store.boot_cleanup(&mut flash).await;
    if cleanup.failed.iter().any(|&f| f) {
        channels::post_to_link(LinkEvent::Status(
            MavSeverity::MAV_SEVERITY_ERROR,
            "touchdown: param flash erase failed",
        ));
    }
    loop {
        let params = SAVE.wait().await;
        match store.save(&mut flash, &params).await {
            Ok(saved) => info!(
                "params: saved in sector {} at 0x{:x}{}",
                saved.sector,
                saved.offset,
                if saved.erased {
                    " (sector erased first)"
                } else {
                    ""
                }
            ),
            Err(e) => {
                warn!("params: not saved: {}", e);
                channels::post_to_link(LinkEvent::Status(
                    MavSeverity::MAV_SEVERITY_ERROR,
                    match e {
                        SaveError::EraseFailed => "touchdown: flash erase failed, params not saved",
                        SaveError::WriteFailed => "touchdown: flash write failed, params not saved",
                        SaveError::NoRoom | SaveError::SequenceExhausted => {
                            "touchdown: param flash unusable, params not saved"
                        }
                    },
                ));
            }
        }
    }
}
