//! The [`Store`]: the state of the two-sector log, which decides where the next slot goes and
//! which sector may be erased, and runs a save or the boot clean-up through [`SlotFlash`].
//!
//! Separate from the slot format and the scan: this is the part that reasons about power
//! cuts (see the parent module), on top of slots it neither lays out nor reads itself.

use core::future::Future;

use super::scan::scan_sector;
use super::slot::{encode_v2, MAX_SLOT_LEN, SLOT_LEN, SLOT_LEN_U32, WORD_U32};
use super::{FLASH_WORD, SECTORS};
use crate::params::{ImportReport, ParamSet};

/// The size of the two sectors, checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Geometry {
    pub(super) sector_len: u32,
}

impl Geometry {
    /// Sectors of `sector_len` bytes: whole flash words, room for two slots and a free word.
    pub const fn new(sector_len: u32) -> Option<Geometry> {
        let len = sector_len as usize;
        if !len.is_multiple_of(FLASH_WORD) || len < 2 * SLOT_LEN + FLASH_WORD {
            return None;
        }
        Some(Geometry { sector_len })
    }

    /// Bytes per sector.
    pub const fn sector_len(self) -> u32 {
        self.sector_len
    }
}

/// Which of two valid slots is newer: a format-2 slot by its sequence number, a format-1 slot by
/// its position in its log; every format-2 slot is newer than every format-1 slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SlotKey {
    /// A format-1 slot (index in its sector's log).
    Legacy(u32),
    /// A format-2 slot (sequence number).
    Seq(u32),
}

/// The flash driver failed (or the power is going).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FlashFailed;

/// The two sectors, as the firmware's flash driver sees them. Offsets are from the start of
/// the sector; `write` gets whole flash words at a word-aligned offset and must program them in
/// ascending order (the H7 driver does), stopping at the first error.
pub trait SlotFlash {
    /// Erases sector `sector` (0 or 1).
    fn erase(&mut self, sector: usize) -> impl Future<Output = Result<(), FlashFailed>>;
    /// Programs `bytes` at `offset` of sector `sector`.
    fn write(
        &mut self,
        sector: usize,
        offset: u32,
        bytes: &[u8],
    ) -> impl Future<Output = Result<(), FlashFailed>>;
}

/// What to do next for a save ([`Store::next_op`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Op {
    /// Erase this sector, then ask again.
    Erase {
        /// The sector.
        sector: usize,
    },
    /// Write the slot ([`Store::encode`]) here.
    Write {
        /// The sector.
        sector: usize,
        /// Offset in the sector.
        offset: u32,
    },
}

/// Why a save did not happen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SaveError {
    /// Erasing the sector failed (retried by the next save).
    EraseFailed,
    /// Programming the slot failed (the next save goes after it).
    WriteFailed,
    /// A freshly erased sector had no room: cannot happen with a [`Geometry`].
    NoRoom,
    /// The sequence numbers are used up (2^32 saves: beyond the flash's endurance).
    SequenceExhausted,
}

/// Where a save went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Saved {
    /// The sector.
    pub sector: usize,
    /// Offset in the sector.
    pub offset: u32,
    /// The sector was erased first.
    pub erased: bool,
}

/// The slot restored at boot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Restored {
    /// Its sector.
    pub sector: usize,
    /// Its sequence number (or format-1 index).
    pub key: SlotKey,
    /// What the import did.
    pub report: ImportReport,
}

/// What [`Store::open`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Boot {
    /// The newest valid slot, imported into the parameters; `None`: defaults.
    pub restored: Option<Restored>,
    /// Slots that started like one but failed their check (torn saves, damage).
    pub bad_slots: u16,
    /// Sectors holding data but no valid slot: [`Store::boot_cleanup`] erases them.
    pub foreign: [bool; SECTORS],
}

/// What [`Store::boot_cleanup`] did, per sector.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Cleanup {
    /// Erased.
    pub erased: [bool; SECTORS],
    /// The erase failed (the next save erases it again if it needs the sector).
    pub failed: [bool; SECTORS],
}

/// What the store knows about one sector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct SectorState {
    /// Its newest valid slot. After a failed erase an upper bound (an erase only removes).
    newest: Option<SlotKey>,
    /// From this offset to the end the sector is erased; `None`: unknown or not to be appended
    /// to (a failed erase, a format-1 log): erase it before writing.
    free: Option<u32>,
    /// `free` was found by the boot scan, not left by our own write or erase: leave a word.
    guard: bool,
    /// Holds data but no valid slot: erase at boot.
    boot_erase: bool,
}

/// The parameter log's state: where the next slot goes and what may be erased. `Copy` and
/// small (the firmware moves it into its task).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Store {
    geometry: Geometry,
    sectors: [SectorState; SECTORS],
    /// The sector saves append to: the one with the newest slot, or the one last written.
    current: Option<usize>,
    /// Sequence number of the next slot (`None`: exhausted).
    next_seq: Option<u32>,
}

impl Store {
    /// Scans both sectors through `read` (sector, offset in it, buffer; `false` on a read
    /// error, which makes that word count as written and that slot as bad) and imports the
    /// newest valid slot into `params` (unchanged when there is none). Reads each word of the
    /// two sectors about once (a slot header failing its CRC makes its words read again).
    pub fn open(
        geometry: Geometry,
        mut read: impl FnMut(usize, u32, &mut [u8]) -> bool,
        params: &mut ParamSet,
    ) -> (Store, Boot) {
        let base = *params;
        let mut buf = [0u8; MAX_SLOT_LEN];
        let mut best: Option<(SlotKey, usize, ParamSet, ImportReport)> = None;
        let mut newest_seq: Option<u32> = None;
        let mut bad_slots = 0u16;
        let mut foreign = [false; SECTORS];
        let empty = SectorState {
            newest: None,
            free: None,
            guard: true,
            boot_erase: false,
        };
        let mut sectors = [empty; SECTORS];
        for (index, (state, foreign)) in sectors.iter_mut().zip(foreign.iter_mut()).enumerate() {
            let scan = scan_sector(geometry, index, &mut read, &base, &mut buf);
            bad_slots = bad_slots.saturating_add(scan.bad_slots);
            let newest = scan.best.map(|(key, _, _)| key);
            if let Some((key, p, report)) = scan.best {
                if best.is_none_or(|(k, ..)| key > k) {
                    best = Some((key, index, p, report));
                }
            }
            if let Some(SlotKey::Seq(s)) = newest {
                newest_seq = Some(newest_seq.map_or(s, |n| n.max(s)));
            }
            *foreign = scan.used_end > 0 && newest.is_none();
            *state = SectorState {
                newest,
                free: (!scan.legacy).then_some(scan.used_end),
                guard: true,
                boot_erase: *foreign,
            };
        }
        let restored = best.map(|(key, sector, p, report)| {
            *params = p;
            Restored {
                sector,
                key,
                report,
            }
        });
        let store = Store {
            geometry,
            sectors,
            current: restored.map(|r| r.sector),
            next_seq: match newest_seq {
                Some(s) => s.checked_add(1),
                None => Some(0),
            },
        };
        let boot = Boot {
            restored,
            bad_slots,
            foreign,
        };
        (store, boot)
    }

    /// The next sector to erase at boot (holds data but no valid slot), if any.
    pub fn boot_erase(&self) -> Option<usize> {
        self.sectors.iter().position(|s| s.boot_erase)
    }

    /// What a save does next: write the slot where there is room (the current sector first),
    /// else erase the sector whose newest valid slot is the older (or that has none), which
    /// loses nothing the other sector does not hold in a newer version. After that erase has
    /// succeeded, the next call returns a write into it; so a save is at most two operations.
    pub fn next_op(&self) -> Result<Op, SaveError> {
        if self.next_seq.is_none() {
            return Err(SaveError::SequenceExhausted);
        }
        let order = match self.current {
            Some(1) => [1, 0],
            _ => [0, 1],
        };
        for sector in order {
            if let Some(offset) = self.room(sector) {
                return Ok(Op::Write { sector, offset });
            }
        }
        let newest = |s: usize| self.sectors.get(s).and_then(|st| st.newest);
        let sector = if newest(0) <= newest(1) { 0 } else { 1 };
        Ok(Op::Erase { sector })
    }

    /// Where a slot fits in `sector`: after everything written (and a guard word when that
    /// position was found at boot).
    fn room(&self, sector: usize) -> Option<u32> {
        let st = self.sectors.get(sector)?;
        let free = st.free?;
        let start = if st.guard {
            free.checked_add(WORD_U32)?
        } else {
            free
        };
        let end = start.checked_add(SLOT_LEN_U32)?;
        (end <= self.geometry.sector_len).then_some(start)
    }

    /// Fills `out` with the slot the next [`Op::Write`] writes: `params` with the next sequence
    /// number.
    pub fn encode(&self, params: &ParamSet, out: &mut [u8; SLOT_LEN]) -> Result<(), SaveError> {
        let seq = self.next_seq.ok_or(SaveError::SequenceExhausted)?;
        encode_v2(params, seq, out);
        Ok(())
    }

    /// Records the outcome of an [`Op::Erase`] of `sector` (also of a boot clean-up erase).
    pub fn erase_done(&mut self, sector: usize, result: Result<(), FlashFailed>) {
        let Some(st) = self.sectors.get_mut(sector) else {
            return;
        };
        // Tried once at boot; a failed one is retried by the save that needs the sector.
        st.boot_erase = false;
        match result {
            Ok(()) => {
                st.newest = None;
                st.free = Some(0);
                st.guard = false;
            }
            // Partly erased, perhaps: unknown content. `newest` stays as an upper bound.
            Err(FlashFailed) => st.free = None,
        }
    }

    /// Records the outcome of the [`Op::Write`] of the slot from [`Store::encode`] at `offset`
    /// of `sector`. Failed or not, those words are used: the next slot goes after them (a
    /// flash word is never programmed twice), and the sequence number is used too (a write
    /// reported failed may still have produced a valid slot, which must not tie with the next).
    pub fn write_done(&mut self, sector: usize, offset: u32, result: Result<(), FlashFailed>) {
        let seq = self.next_seq;
        self.next_seq = seq.and_then(|s| s.checked_add(1));
        let Some(st) = self.sectors.get_mut(sector) else {
            return;
        };
        st.free = Some(offset.saturating_add(SLOT_LEN_U32));
        st.guard = false;
        if let (Ok(()), Some(seq)) = (result, seq) {
            st.newest = Some(SlotKey::Seq(seq));
        }
        self.current = Some(sector);
    }

    /// Erases, through `flash`, the sectors [`Boot::foreign`] named (data, no valid slot). Run
    /// it before the first save; an erase takes long, so the firmware runs it in its task, not
    /// before the other tasks start.
    pub async fn boot_cleanup<F: SlotFlash>(&mut self, flash: &mut F) -> Cleanup {
        let mut done = Cleanup::default();
        // Each erase clears its sector's flag, failed or not: at most SECTORS rounds.
        for _ in 0..SECTORS {
            let Some(sector) = self.boot_erase() else {
                break;
            };
            let result = flash.erase(sector).await;
            self.erase_done(sector, result);
            if let Some(d) = done.erased.get_mut(sector) {
                *d = result.is_ok();
            }
            if let Some(f) = done.failed.get_mut(sector) {
                *f = result.is_err();
            }
        }
        done
    }

    /// Saves `params` through `flash`: [`Store::next_op`], the flash operation,
    /// [`Store::erase_done`] / [`Store::write_done`], at most an erase and a write.
    pub async fn save<F: SlotFlash>(
        &mut self,
        flash: &mut F,
        params: &ParamSet,
    ) -> Result<Saved, SaveError> {
        let mut erased = false;
        let mut slot = [0u8; SLOT_LEN];
        for _ in 0..2 {
            match self.next_op()? {
                // A second erase would mean the fresh sector had no room.
                Op::Erase { .. } if erased => return Err(SaveError::NoRoom),
                Op::Erase { sector } => {
                    let result = flash.erase(sector).await;
                    self.erase_done(sector, result);
                    result.map_err(|FlashFailed| SaveError::EraseFailed)?;
                    erased = true;
                }
                Op::Write { sector, offset } => {
                    self.encode(params, &mut slot)?;
                    let result = flash.write(sector, offset, &slot).await;
                    self.write_done(sector, offset, result);
                    result.map_err(|FlashFailed| SaveError::WriteFailed)?;
                    return Ok(Saved {
                        sector,
                        offset,
                        erased,
                    });
                }
            }
        }
        Err(SaveError::NoRoom)
    }
}
