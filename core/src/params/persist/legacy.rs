//! Format 1 (the single-sector log before slot format 2), for the tests.
//!
//! `Store::open` reads a format-1 log itself (`scan_sector`). What follows is the old design's
//! own reader and writer, kept only so that the tests can build format-1 logs and show what
//! the old design lost on a power cut; it is not part of the firmware (test builds only).

use super::{ERASED, LEGACY_SLOT_LEN};
use crate::params::{ImportError, ImportReport, ParamSet};

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

/// Parameters in the table of the firmware that wrote format 1 (up to TD_EXP_TARGET).
pub const LEGACY_PARAM_COUNT: usize = 13;

/// Fills `out` with a format-1 slot for `params` (the export blob of the first
/// [`LEGACY_PARAM_COUNT`] parameters, zero padding): what the firmware wrote before slot
/// format 2, for tests of the upgrade path.
///
/// `out` is normally [`LEGACY_SLOT_LEN`] bytes; shorter than the blob, it is left all zeros.
pub fn encode_slot(params: &ParamSet, out: &mut [u8]) {
    out.fill(0);
    params.export_records(LEGACY_PARAM_COUNT, out);
}

/// The format-1 reader.
#[cfg(test)]
mod tests {
    use super::super::test_fixtures::with_profile;
    use super::super::FLASH_WORD;
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
}
