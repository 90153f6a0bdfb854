//! Parameter persistence: an append-only log of [`ParamSet::export`] blobs in one flash sector.
//!
//! The STM32H743 erases flash only in 128 KiB sectors (seconds, and ~10k cycles per sector)
//! but programs it in 32-byte flash words, each once per erase. So every save appends one
//! [`SLOT_LEN`]-byte slot (the export blob, zero padded to whole flash words) after the last
//! written one, and the sector is erased only when it is full (455 saves of the 13-parameter
//! table's 288-byte slots). At boot [`scan`] walks the slots up to the first erased one and
//! restores the newest slot whose magic, version and CRC check out; a torn last write (power
//! lost mid-save) therefore falls back to the save before it. [`SaveDebounce`] decides when a changed parameter set is
//! written: only after it has been stable for a while, so a ground station writing ten
//! parameters in a row costs one slot, not ten.
//!
//! The firmware owns the flash driver; this module only decides what to read and write, so it
//! runs in host tests against a byte array.

use super::params::{ImportError, ImportReport, ParamSet, EXPORT_LEN};

/// Flash programming unit of the STM32H7 (256 bits).
pub const FLASH_WORD: usize = 32;
/// Bytes of one slot: the export blob rounded up to whole flash words.
pub const SLOT_LEN: usize = EXPORT_LEN.div_ceil(FLASH_WORD) * FLASH_WORD;
/// Erased flash reads as this byte.
pub const ERASED: u8 = 0xFF;
/// A changed parameter set is saved once it has not changed for this long, µs.
pub const SAVE_DEBOUNCE_US: u64 = 2_000_000;

/// What [`scan`] found.
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

/// Reads the log of `slots` slots through `read` (slot index, buffer; `false` on a read
/// error, which counts as a bad slot) and imports the newest valid slot into `params`
/// (unchanged when there is none).
pub fn scan(
    slots: usize,
    mut read: impl FnMut(usize, &mut [u8; SLOT_LEN]) -> bool,
    params: &mut ParamSet,
) -> ScanResult {
    let mut buf = [0u8; SLOT_LEN];
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

/// Fills `out` with the slot for `params` (export blob, zero padding).
pub fn encode_slot(params: &ParamSet, out: &mut [u8; SLOT_LEN]) {
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
mod tests {
    use super::super::params::ParamId;
    use super::*;

    const SLOTS: usize = 6;

    struct Sector([[u8; SLOT_LEN]; SLOTS]);

    impl Sector {
        fn erased() -> Self {
            Sector([[ERASED; SLOT_LEN]; SLOTS])
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

    const _: () = assert!(SLOT_LEN.is_multiple_of(FLASH_WORD) && SLOT_LEN >= EXPORT_LEN);

    /// The slot size the module documentation's save count is worked out from.
    #[test]
    fn slot_size_of_the_current_table() {
        assert_eq!(EXPORT_LEN, 8 + super::super::params::PARAM_COUNT * 20);
        assert_eq!(SLOT_LEN, 288);
        assert_eq!(128 * 1024 / SLOT_LEN, 455);
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
        let mut torn = [0u8; SLOT_LEN];
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
