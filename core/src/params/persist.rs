//! Parameter persistence: a power-loss-safe log of [`ParamSet::export`] blobs in two flash
//! sectors.
//!
//! The STM32H743 erases flash only in 128 KiB sectors (a second or more, and ~10k cycles per
//! sector) and programs it in 32-byte flash words, each once per erase. So a save appends one
//! [`SLOT_LEN`]-byte slot to a log and never rewrites anything; [`SaveDebounce`] makes a ground
//! station writing ten parameters in a row cost one slot, not ten.
//!
//! A slot (format version [`SLOT_VERSION`]) is whole flash words: a header word that is the
//! same for every slot (magic, version, length in words), the sequence number, the export
//! blob, zero padding, and a trailer (magic, CRC-32 of everything before it) in its **last**
//! word. The flash driver programs words in ascending order, so the trailer is the last word
//! to be programmed: a slot that checks out was written completely.
//!
//! Two sectors ([`SECTORS`]) take turns. Saves append to the sector that holds the newest slot;
//! when it is full, the *other* sector (holding only older slots) is erased and the new slot
//! goes to its start. At boot
//! ([`Store::open`]) both sectors are scanned word by word and the valid slot with the highest
//! sequence number, in either sector, is restored. Why a power cut cannot lose the parameters
//! or mix two sets:
//!
//! - **During a write** the new slot is incomplete, fails its CRC, and the previous newest slot
//!   (untouched: programming only ever touches erased words) wins: the old values. If its last
//!   word got programmed, the new slot is complete and wins: the new values. Never a mix, as
//!   one slot holds the whole set.
//! - **During an erase** only the sector being erased is damaged, and a sector is erased only
//!   when it holds nothing newer than the other sector's newest valid slot ([`Store::next_op`]
//!   erases the sector whose newest slot is the older). The new slot is written to it only
//!   after the erase has completed, so until then the other sector still holds the newest
//!   values: a cut restores the old values. (The one-sector design this replaces erased its
//!   only sector and then wrote slot 0: a cut in between restored the defaults.)
//! - **After a cut** the scan continues the log after the last word that is not erased (a torn
//!   slot is never programmed over). A word whose programming was cut just as it started can
//!   read as erased although its cells (and ECC bits) are partly programmed; it must not get
//!   different data. So the first slot after a boot starts one word further on (the cut word
//!   is the one after the last visible word), and, because that start is the same at the next
//!   boot if the cut hit the new slot's very first word, that first word has the same content
//!   in every slot: programming it again writes the identical bits.
//!
//! A sector that holds data but no valid slot (another firmware's data: an OpenMV Cam's ROMFS
//! at 0x081E_0000, or a partly erased sector) is erased at boot ([`Store::boot_cleanup`]), as
//! otherwise it could never be written. A sector holding a valid slot is never erased at boot.
//!
//! **Older logs.** The firmware before this design (slot format 1) kept a log of bare export
//! blobs, one per [`LEGACY_SLOT_LEN`] bytes, in the last sector. A sector with no version-2
//! slot is also read that way ([`SlotKey::Legacy`], older than any version-2 slot); it is never
//! appended to, so the first save after the update goes to the other sector and the old sector
//! keeps the user's values until that one has filled up and it is erased in turn.
//!
//! This module does no I/O: [`Store`] decides what to read, erase and write, and the firmware
//! runs its [`Store::save`] and [`Store::boot_cleanup`] with its flash driver behind
//! [`SlotFlash`]. Host tests run the same code against a model of the H7's flash that cuts the
//! power at every program and erase step.

use core::future::Future;

#[cfg(test)]
use super::ImportError;
use super::{ImportReport, ParamSet, EXPORT_LEN};

/// Flash programming unit of the STM32H7 (256 bits).
pub const FLASH_WORD: usize = 32;
/// Erased flash reads as this byte.
pub const ERASED: u8 = 0xFF;
/// A changed parameter set is saved once it has not changed for this long, µs.
pub const SAVE_DEBOUNCE_US: u64 = 2_000_000;
/// Flash sectors the log takes turns on.
pub const SECTORS: usize = 2;

/// Slot format version written by [`Store`] (1 was the bare export blob, see
/// [`LEGACY_SLOT_LEN`]).
pub const SLOT_VERSION: u8 = 2;
/// First bytes of a version-2 slot.
const SLOT_MAGIC: [u8; 4] = *b"TDSL";
/// Header: a whole word, identical in every slot of this length: magic (4), version (1),
/// length in flash words (1), zeros; then the sequence number (4, LE). The export blob starts
/// right after, mid-word, so it can never pass for a format-1 slot.
const SLOT_HEADER_LEN: usize = FLASH_WORD + 4;
/// Trailer, at the end of the slot's last word: magic (4), CRC-32 (4, LE) of all bytes before
/// the CRC.
const SLOT_TRAILER_LEN: usize = 8;
const TRAILER_MAGIC: [u8; 4] = *b"TDOK";
/// Bytes of one slot this firmware writes: header, export blob and trailer, rounded up to
/// whole flash words.
pub const SLOT_LEN: usize =
    (SLOT_HEADER_LEN + EXPORT_LEN + SLOT_TRAILER_LEN).div_ceil(FLASH_WORD) * FLASH_WORD;
/// Longest slot read back (a later firmware with a larger table writes longer slots; the
/// length is in the header, so the scan can step over them).
pub const MAX_SLOT_LEN: usize = 32 * FLASH_WORD;
const SLOT_LEN_U32: u32 = SLOT_LEN as u32;
const WORD_U32: u32 = FLASH_WORD as u32;
const _: () = assert!(SLOT_LEN <= MAX_SLOT_LEN && MAX_SLOT_LEN / FLASH_WORD <= u8::MAX as usize);

/// Bytes per slot of the format-1 log: the 13-parameter export blob (268 bytes) rounded up to
/// flash words, what every firmware before slot format 2 wrote.
pub const LEGACY_SLOT_LEN: usize = 288;
/// First bytes of an export blob ([`ParamSet::export`]'s magic and format version), i.e. of a
/// format-1 slot.
const LEGACY_MAGIC: [u8; 5] = [b'T', b'D', b'P', b'R', 1];

/// The size of the two sectors, checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Geometry {
    sector_len: u32,
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

/// One sector's scan.
struct SectorScan {
    best: Option<(SlotKey, ParamSet, ImportReport)>,
    bad_slots: u16,
    /// End of the last word that is not erased (0: the sector is erased).
    used_end: u32,
    /// Holds a format-1 log (and no format-2 slot).
    legacy: bool,
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

/// Scans one sector word by word: a format-2 slot header starts a slot (stepped over whole
/// when valid, else the scan goes on at the next word, so a torn or foreign header cannot
/// hide what follows); in a sector without format-2 slots, format-1 slots at multiples of
/// [`LEGACY_SLOT_LEN`].
fn scan_sector(
    geometry: Geometry,
    sector: usize,
    read: &mut impl FnMut(usize, u32, &mut [u8]) -> bool,
    base: &ParamSet,
    buf: &mut [u8; MAX_SLOT_LEN],
) -> SectorScan {
    let len = geometry.sector_len;
    let mut headers = 0u32;
    let mut best_v2: Option<(u32, ParamSet, ImportReport)> = None;
    let mut best_v1: Option<(u32, ParamSet, ImportReport)> = None;
    let (mut bad_v2, mut bad_v1) = (0u16, 0u16);
    let mut used_end = 0u32;
    let mut pos = 0u32;
    // Every round advances `pos` by at least a word: at most sector_len / 32 rounds.
    while pos < len {
        let next_word = pos.saturating_add(WORD_U32);
        let mut word = [0u8; FLASH_WORD];
        if !read(sector, pos, &mut word) {
            used_end = next_word;
            pos = next_word;
            continue;
        }
        if word.iter().all(|&b| b == ERASED) {
            pos = next_word;
            continue;
        }
        used_end = next_word;
        if let Some(words) = slot_header(&word) {
            headers = headers.saturating_add(1);
            let slot_len = words.saturating_mul(WORD_U32);
            let end = pos.saturating_add(slot_len);
            let slot = buf.get_mut(..slot_len as usize);
            let valid = match slot {
                Some(slot) if end <= len => {
                    if read(sector, pos, slot) {
                        check_v2(slot, base)
                    } else {
                        None
                    }
                }
                _ => None,
            };
            match valid {
                Some((seq, p, report)) => {
                    if best_v2.is_none_or(|(s, ..)| seq >= s) {
                        best_v2 = Some((seq, p, report));
                    }
                    used_end = end;
                    pos = end;
                    continue;
                }
                None => bad_v2 = bad_v2.saturating_add(1),
            }
        } else if pos.is_multiple_of(LEGACY_SLOT_LEN as u32) && word.starts_with(&LEGACY_MAGIC) {
            let end = pos.saturating_add(LEGACY_SLOT_LEN as u32);
            let valid = match buf.get_mut(..LEGACY_SLOT_LEN) {
                Some(slot) if end <= len => {
                    let mut p = *base;
                    if read(sector, pos, slot) {
                        p.import(slot).ok().map(|report| (p, report))
                    } else {
                        None
                    }
                }
                _ => None,
            };
            match valid {
                Some((p, report)) => {
                    best_v1 = Some((pos / LEGACY_SLOT_LEN as u32, p, report));
                    used_end = end;
                    pos = end;
                    continue;
                }
                None => bad_v1 = bad_v1.saturating_add(1),
            }
        }
        pos = next_word;
    }
    // A format-1 log is only believed in a sector without format-2 slots: the firmware never
    // writes format 1 next to format 2.
    let legacy = headers == 0 && best_v1.is_some();
    let best = if headers == 0 {
        best_v1.map(|(i, p, r)| (SlotKey::Legacy(i), p, r))
    } else {
        best_v2.map(|(s, p, r)| (SlotKey::Seq(s), p, r))
    };
    SectorScan {
        best,
        bad_slots: if headers == 0 { bad_v1 } else { bad_v2 },
        used_end,
        legacy,
    }
}

/// The slot length in words if `word` starts a format-2 slot.
fn slot_header(word: &[u8; FLASH_WORD]) -> Option<u32> {
    let (magic, rest) = word.split_first_chunk::<4>()?;
    let (&[version, words], _) = rest.split_first_chunk::<2>()?;
    let min_words = (SLOT_HEADER_LEN + SLOT_TRAILER_LEN).div_ceil(FLASH_WORD);
    let ok = *magic == SLOT_MAGIC
        && version == SLOT_VERSION
        && usize::from(words) >= min_words
        && usize::from(words) * FLASH_WORD <= MAX_SLOT_LEN
        && word.iter().skip(6).all(|&b| b == 0);
    ok.then_some(u32::from(words))
}

/// Checks a whole format-2 slot (trailer magic, CRC, blob) and imports it on top of `base`.
fn check_v2(slot: &[u8], base: &ParamSet) -> Option<(u32, ParamSet, ImportReport)> {
    let (body, crc) = slot.split_last_chunk::<4>()?;
    if crc32(body) != u32::from_le_bytes(*crc) {
        return None;
    }
    let (inner, magic) = body.split_last_chunk::<4>()?;
    if *magic != TRAILER_MAGIC {
        return None;
    }
    let (_, after_header_word) = inner.split_first_chunk::<FLASH_WORD>()?;
    let (seq, _) = after_header_word.split_first_chunk::<4>()?;
    let blob = inner.get(SLOT_HEADER_LEN..)?;
    let mut p = *base;
    let report = p.import(blob).ok()?;
    Some((u32::from_le_bytes(*seq), p, report))
}

/// Writes a format-2 slot for `params` with sequence number `seq`.
fn encode_v2(params: &ParamSet, seq: u32, out: &mut [u8; SLOT_LEN]) {
    out.fill(0);
    let mut header = [0u8; SLOT_HEADER_LEN];
    header[..4].copy_from_slice(&SLOT_MAGIC);
    header[4] = SLOT_VERSION;
    header[5] = (SLOT_LEN / FLASH_WORD) as u8;
    header[FLASH_WORD..].copy_from_slice(&seq.to_le_bytes());
    let (head, rest) = out.split_at_mut(SLOT_HEADER_LEN);
    head.copy_from_slice(&header);
    let (blob_and_pad, trailer) = rest.split_at_mut(SLOT_LEN - SLOT_HEADER_LEN - SLOT_TRAILER_LEN);
    params.export(blob_and_pad);
    let (magic, _) = trailer.split_at_mut(4);
    magic.copy_from_slice(&TRAILER_MAGIC);
    let (body, crc) = out.split_at_mut(SLOT_LEN - 4);
    let c = crc32(body);
    crc.copy_from_slice(&c.to_le_bytes());
}

/// CRC-32 (IEEE 802.3: reflected polynomial 0xEDB88320, initial and final XOR 0xFFFFFFFF),
/// half a byte per table look-up: fast enough to check both sectors at boot in a few ms, with a
/// 64-byte table.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        for nibble in [b & 0x0F, b >> 4] {
            let i = ((crc ^ u32::from(nibble)) & 0x0F) as usize;
            crc = CRC32_NIBBLES.get(i).copied().unwrap_or(0) ^ (crc >> 4);
        }
    }
    !crc
}

// Evaluated at compile time: an index out of bounds would fail the build, not panic.
#[allow(clippy::indexing_slicing)]
const CRC32_NIBBLES: [u32; 16] = {
    let mut t = [0u32; 16];
    let mut i = 0;
    while i < 16 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 4 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
            k += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
};

// ---- Format 1 (the single-sector log before slot format 2), for the tests ----
//
// `Store::open` reads a format-1 log itself (`scan_sector`). What follows is the old design's
// own reader and writer, kept only so that the tests can build format-1 logs and show what
// the old design lost on a power cut; it is not part of the firmware.

#[cfg(test)]
/// What [`scan`] found in a format-1 log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Restore {
    /// Nothing was ever saved (or the sector was just erased): defaults.
    Empty,
    /// The newest valid slot was imported.
    Restored {
        /// Its index.
        slot: usize,
        /// What the import did.
        report: ImportReport,
        /// Written slots that failed their check (skipped).
        bad_slots: usize,
    },
    /// Slots were written but none is valid: defaults (report it: the user's tuning is lost).
    Corrupt {
        /// Why the newest written slot was refused.
        error: ImportError,
        /// Written slots, all bad.
        bad_slots: usize,
    },
}

#[cfg(test)]
/// The result of [`scan`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ScanResult {
    /// What was restored into the parameter set.
    pub restore: Restore,
    /// The slot the next save goes to; `None` when the sector is full (erase it, then save to
    /// slot 0).
    pub next_free: Option<usize>,
}

#[cfg(test)]
/// Reads a format-1 log (one sector of bare export blobs, appended up to the first erased
/// slot) of `slots` slots through `read` (slot index, buffer; `false` on a read error, which
/// counts as a bad slot) and imports the newest valid slot into `params` (unchanged when there
/// is none). The buffer is `N` bytes ([`LEGACY_SLOT_LEN`] for a real format-1 log).
pub fn scan<const N: usize>(
    slots: usize,
    mut read: impl FnMut(usize, &mut [u8; N]) -> bool,
    params: &mut ParamSet,
) -> ScanResult {
    let mut buf = [0u8; N];
    let mut newest: Option<(usize, ParamSet, ImportReport)> = None;
    let mut last_error = None;
    let mut bad_slots = 0;
    let mut next_free = None;
    for slot in 0..slots {
        if !read(slot, &mut buf) {
            bad_slots += 1;
            continue;
        }
        if buf.iter().all(|&b| b == ERASED) {
            next_free = Some(slot);
            break;
        }
        let mut candidate = *params;
        match candidate.import(&buf) {
            Ok(report) => newest = Some((slot, candidate, report)),
            Err(e) => {
                bad_slots += 1;
                last_error = Some(e);
            }
        }
    }
    let restore = match (newest, last_error) {
        (Some((slot, p, report)), _) => {
            *params = p;
            Restore::Restored {
                slot,
                report,
                bad_slots,
            }
        }
        (None, Some(error)) => Restore::Corrupt { error, bad_slots },
        (None, None) => Restore::Empty,
    };
    ScanResult { restore, next_free }
}

#[cfg(test)]
/// Fills `out` with a format-1 slot for `params` (export blob, zero padding): what the
/// firmware wrote before slot format 2, for tests of the upgrade path.
///
/// `out` is normally [`LEGACY_SLOT_LEN`] bytes; shorter than the blob, it is left all zeros.
pub fn encode_slot(params: &ParamSet, out: &mut [u8]) {
    out.fill(0);
    params.export(out);
}

/// Decides when to save: a parameter set different from the saved one, unchanged for
/// [`SAVE_DEBOUNCE_US`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SaveDebounce {
    saved: ParamSet,
    seen: ParamSet,
    since_us: u64,
}

impl SaveDebounce {
    /// Starts from the set that is in flash (or the defaults).
    pub fn new(saved: ParamSet) -> Self {
        SaveDebounce {
            saved,
            seen: saved,
            since_us: 0,
        }
    }

    /// Looks at the current set at `now_us`; returns it when it is due for saving.
    pub fn poll(&mut self, current: &ParamSet, now_us: u64) -> Option<ParamSet> {
        if *current != self.seen {
            self.seen = *current;
            self.since_us = now_us;
        }
        let due =
            self.seen != self.saved && now_us.saturating_sub(self.since_us) >= SAVE_DEBOUNCE_US;
        due.then_some(self.seen)
    }

    /// Records a successful save of `params`.
    pub fn saved(&mut self, params: &ParamSet) {
        self.saved = *params;
    }
}

#[cfg(test)]
#[path = "persist_tests.rs"]
mod power_loss_tests;

/// The format-1 reader ([`scan`]) and [`SaveDebounce`]; the format-2 log is tested in
/// `persist_tests.rs`.
#[cfg(test)]
mod tests {
    use super::super::ParamId;
    use super::*;

    const SLOTS: usize = 6;

    struct Sector([[u8; LEGACY_SLOT_LEN]; SLOTS]);

    impl Sector {
        fn erased() -> Self {
            Sector([[ERASED; LEGACY_SLOT_LEN]; SLOTS])
        }
        fn scan(&self, params: &mut ParamSet) -> ScanResult {
            scan(
                SLOTS,
                |i, buf| {
                    *buf = self.0[i];
                    true
                },
                params,
            )
        }
    }

    fn with_profile(v: f32) -> ParamSet {
        let mut p = ParamSet::default();
        p.set(ParamId::Profile, v).unwrap();
        p
    }

    const _: () =
        assert!(LEGACY_SLOT_LEN.is_multiple_of(FLASH_WORD) && LEGACY_SLOT_LEN >= EXPORT_LEN);

    /// The slot size the module documentation's save count is worked out from.
    #[test]
    fn slot_size_of_the_current_table() {
        assert_eq!(EXPORT_LEN, 8 + super::super::PARAM_COUNT * 20);
        assert_eq!(LEGACY_SLOT_LEN, 288);
        assert_eq!(128 * 1024 / LEGACY_SLOT_LEN, 455);
        // Format 2: a header word and the sequence number more; 409 slots per sector after
        // the first boot's free word.
        assert_eq!(SLOT_LEN, 320);
        assert_eq!((128 * 1024 - FLASH_WORD) / SLOT_LEN, 409);
    }

    #[test]
    fn empty_sector_gives_defaults_and_slot_zero() {
        let mut p = ParamSet::default();
        let r = Sector::erased().scan(&mut p);
        assert_eq!(r.restore, Restore::Empty);
        assert_eq!(r.next_free, Some(0));
        assert_eq!(p, ParamSet::default());
    }

    #[test]
    fn newest_valid_slot_wins_and_a_torn_one_is_skipped() {
        let mut sector = Sector::erased();
        encode_slot(&with_profile(1.0), &mut sector.0[0]);
        encode_slot(&ParamSet::default(), &mut sector.0[1]);
        encode_slot(&with_profile(1.0), &mut sector.0[2]);
        // Slot 3: a save torn by a power loss (half written).
        let mut torn = [0u8; LEGACY_SLOT_LEN];
        encode_slot(&ParamSet::default(), &mut torn);
        sector.0[3][..FLASH_WORD * 2].copy_from_slice(&torn[..FLASH_WORD * 2]);
        let mut p = ParamSet::default();
        let r = sector.scan(&mut p);
        assert_eq!(r.next_free, Some(4));
        match r.restore {
            Restore::Restored {
                slot, bad_slots, ..
            } => assert_eq!((slot, bad_slots), (2, 1)),
            other => panic!("{other:?}"),
        }
        assert_eq!(p, with_profile(1.0));
    }

    #[test]
    fn only_bad_slots_is_corrupt_and_keeps_defaults() {
        let mut sector = Sector::erased();
        encode_slot(&with_profile(1.0), &mut sector.0[0]);
        sector.0[0][20] ^= 0x01; // a flipped bit in a record: CRC fails
        let mut p = ParamSet::default();
        let r = sector.scan(&mut p);
        assert_eq!(
            r.restore,
            Restore::Corrupt {
                error: ImportError::BadCrc,
                bad_slots: 1
            }
        );
        assert_eq!(p, ParamSet::default());
    }

    #[test]
    fn full_sector_has_no_free_slot() {
        let mut sector = Sector::erased();
        for s in sector.0.iter_mut() {
            encode_slot(&with_profile(1.0), s);
        }
        let mut p = ParamSet::default();
        let r = sector.scan(&mut p);
        assert_eq!(r.next_free, None);
        assert!(matches!(r.restore, Restore::Restored { slot: 5, .. }));
    }

    #[test]
    fn debounce_waits_for_a_stable_change() {
        let mut d = SaveDebounce::new(ParamSet::default());
        assert_eq!(d.poll(&ParamSet::default(), 10_000_000), None);
        let a = with_profile(1.0);
        assert_eq!(d.poll(&a, 20_000_000), None);
        assert_eq!(d.poll(&a, 21_000_000), None);
        // Another change restarts the wait.
        let mut b = a;
        b.set(ParamId::RateHz, 10.0).unwrap();
        assert_eq!(d.poll(&b, 21_500_000), None);
        assert_eq!(d.poll(&b, 23_000_000), None);
        assert_eq!(d.poll(&b, 23_500_000), Some(b));
        d.saved(&b);
        assert_eq!(d.poll(&b, 30_000_000), None);
        // Changed back to what is saved: nothing to do.
        d.poll(&a, 31_000_000);
        assert_eq!(d.poll(&b, 31_100_000), None);
        assert_eq!(d.poll(&b, 40_000_000), None);
    }
}
