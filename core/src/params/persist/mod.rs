//! Parameter persistence: a power-loss-safe log of
//! [`ParamSet::export`](crate::params::ParamSet::export) blobs in two flash sectors.
//!
//! The STM32H743 erases flash only in 128 KiB sectors (a second or more, and ~10k cycles per
//! sector) and programs it in 32-byte flash words, each once per erase. So a save appends one
//! [`SLOT_LEN`]-byte slot to a log and never rewrites anything; [`SaveDebounce`] makes a ground
//! station writing ten parameters in a row cost one slot, not ten.
//!
//! A slot (format version [`SLOT_VERSION`](slot::SLOT_VERSION)) is whole flash words: a header word that is the
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
//! blobs, one per [`LEGACY_SLOT_LEN`](slot::LEGACY_SLOT_LEN) bytes, in the last sector. A sector with no version-2
//! slot is also read that way ([`SlotKey::Legacy`], older than any version-2 slot); it is never
//! appended to, so the first save after the update goes to the other sector and the old sector
//! keeps the user's values until that one has filled up and it is erased in turn.
//!
//! This module does no I/O: [`Store`] decides what to read, erase and write, and the firmware
//! runs its [`Store::save`] and [`Store::boot_cleanup`] with its flash driver behind
//! [`SlotFlash`]. Host tests run the same code against a model of the H7's flash that cuts the
//! power at every program and erase step.
//!
//! The module is split by concern: `slot` is the slot format (layout, header, trailer, CRC-32,
//! and the format-1 blob), `scan` the replay of a sector's log at boot, `store` the [`Store`]
//! that decides where a save goes and what is erased, `debounce` when to save. The tests run
//! against `test_fixtures`, a model of the H7's flash: `power_loss_tests` cut the power at every
//! step, `store_tests` cover the store's other cases.

mod debounce;
#[cfg(test)]
mod legacy;
#[cfg(test)]
mod power_loss_tests;
mod scan;
mod slot;
mod store;
#[cfg(test)]
mod store_tests;
#[cfg(test)]
mod test_fixtures;

pub use debounce::{SaveDebounce, SAVE_DEBOUNCE_US};
#[cfg(test)]
pub use legacy::{encode_slot, scan};
#[cfg(test)]
pub use slot::LEGACY_SLOT_LEN;
pub use slot::SLOT_LEN;
pub use store::{
    Boot, Cleanup, FlashFailed, Geometry, Op, Restored, SaveError, Saved, SlotFlash, SlotKey, Store,
};

/// Flash programming unit of the STM32H7 (256 bits).
pub const FLASH_WORD: usize = 32;
/// Erased flash reads as this byte.
pub const ERASED: u8 = 0xFF;
/// Flash sectors the log takes turns on.
pub const SECTORS: usize = 2;
