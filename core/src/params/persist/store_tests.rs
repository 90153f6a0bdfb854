//! The store's behaviour beyond single power cuts, against the flash model: foreign data at
//! boot, torn and failed writes, failed erases, the update from a format-1 log, the real
//! sector size and the end of the sequence numbers.

extern crate std;

use std::vec;
use std::vec::Vec;

use embassy_futures::block_on;

use super::slot::encode_v2;
use super::test_fixtures::*;
use super::*;
use crate::params::ParamSet;

#[test]
fn foreign_data_in_both_sectors_is_erased_at_boot_then_saves_work() {
    let mut m = Model::new(TEST_SECTOR);
    m.fill_foreign(0);
    m.fill_foreign(1);
    let (p, mut store, boot) = TwoSectors::open(&m);
    assert_eq!(p, ParamSet::default());
    assert_eq!(boot.restored, None);
    assert_eq!(boot.foreign, [true, true]);
    let done = block_on(store.boot_cleanup(&mut m));
    assert_eq!(done.erased, [true, true]);
    assert!(m.bytes.iter().all(|&b| b == ERASED));
    assert_eq!(
        block_on(store.save(&mut m, &values(1))).map(|s| s.erased),
        Ok(false)
    );
    let (p, _, boot) = TwoSectors::open(&m);
    assert_eq!(p, values(1));
    assert_eq!((boot.bad_slots, boot.foreign), (0, [false, false]));
}

#[test]
fn foreign_data_next_to_a_valid_sector_erases_only_the_foreign_sector() {
    for foreign_sector in [0, 1] {
        let mut m = Model::new(TEST_SECTOR);
        let (_, mut store) = TwoSectors::boot(&mut m);
        // Two saves land in one sector; foreign data in the other.
        assert!(TwoSectors::save(&mut store, &mut m, &values(1)));
        assert!(TwoSectors::save(&mut store, &mut m, &values(2)));
        let valid = (0..SECTORS).find(|&s| {
            m.bytes[s * TEST_SECTOR..(s + 1) * TEST_SECTOR]
                .iter()
                .any(|&b| b != ERASED)
        });
        let valid = valid.unwrap();
        if valid == foreign_sector {
            // Put the log in the other sector instead.
            let (a, b) = m.bytes.split_at_mut(TEST_SECTOR);
            a.swap_with_slice(b);
        }
        m.fill_foreign(foreign_sector);
        let before = m.bytes.clone();
        let (p, mut store, boot) = TwoSectors::open(&m);
        assert_eq!(p, values(2));
        let mut expect = [false; SECTORS];
        expect[foreign_sector] = true;
        assert_eq!(boot.foreign, expect);
        let erases = m.erases;
        block_on(store.boot_cleanup(&mut m));
        assert_eq!(m.erases, erases + 1);
        let other = 1 - foreign_sector;
        assert_eq!(
            m.bytes[other * TEST_SECTOR..(other + 1) * TEST_SECTOR],
            before[other * TEST_SECTOR..(other + 1) * TEST_SECTOR]
        );
        assert!(TwoSectors::save(&mut store, &mut m, &values(3)));
        assert_eq!(TwoSectors::open(&m).0, values(3));
    }
}

#[test]
fn a_torn_last_slot_after_valid_ones_erases_nothing_and_is_skipped() {
    for tear in [Tear::Garbage, Tear::LowHalf, Tear::HighHalf, Tear::SomeBits] {
        // Valid slots in one sector, the other erased; cut in the middle of the third slot.
        let mut m = Model::new(TEST_SECTOR);
        let (_, mut store) = TwoSectors::boot(&mut m);
        assert!(TwoSectors::save(&mut store, &mut m, &values(1)));
        assert!(TwoSectors::save(&mut store, &mut m, &values(2)));
        m.cut = Some((m.steps + 4, tear));
        assert!(!TwoSectors::save(&mut store, &mut m, &values(3)));
        m.reboot();
        let (p, mut store, boot) = TwoSectors::open(&m);
        assert_eq!(p, values(2));
        assert_eq!(boot.foreign, [false, false]);
        assert_eq!(boot.bad_slots, 1, "{tear:?}");
        assert_eq!(store.boot_erase(), None);
        let erases = m.erases;
        assert_eq!(block_on(store.boot_cleanup(&mut m)), Cleanup::default());
        // The next save goes after the torn words (the model panics on reprogramming one).
        let saved = block_on(store.save(&mut m, &values(4))).unwrap();
        assert!(!saved.erased);
        assert_eq!(m.erases, erases);
        assert_eq!(TwoSectors::open(&m).0, values(4));
    }
}

#[test]
fn a_format_1_log_is_restored_kept_and_erased_only_once_superseded() {
    let mut m = with_format_1_log(4);
    // A torn format-1 slot after the valid ones, as the old firmware could leave.
    let mut slot = [0u8; LEGACY_SLOT_LEN];
    encode_slot(&values(999), &mut slot);
    m.program(1, 4 * LEGACY_SLOT_LEN, &slot[..64]).unwrap();
    let format_1 = m.bytes[TEST_SECTOR..].to_vec();
    let (p, mut store, boot) = TwoSectors::open(&m);
    assert_eq!(p, values(103));
    assert_eq!(boot.restored.map(|r| r.key), Some(SlotKey::Legacy(3)));
    assert_eq!((boot.bad_slots, boot.foreign), (1, [false, false]));
    block_on(store.boot_cleanup(&mut m));
    // Saves fill sector 0 first; sector 1 keeps the format-1 log until then.
    let mut v = 0;
    loop {
        let saved = block_on(store.save(&mut m, &values(v))).unwrap();
        if saved.erased {
            assert_eq!(saved.sector, 1);
            break;
        }
        assert_eq!(saved.sector, 0);
        assert_eq!(m.bytes[TEST_SECTOR..], format_1[..]);
        assert_eq!(TwoSectors::open(&m).0, values(v));
        v += 1;
    }
    assert_eq!(v, 4);
    let (p, _, boot) = TwoSectors::open(&m);
    assert_eq!(p, values(v));
    assert_eq!(boot.restored.map(|r| r.sector), Some(1));
}

#[test]
fn a_failed_write_is_stepped_over_and_reported() {
    let mut m = Model::new(TEST_SECTOR);
    let (_, mut store) = TwoSectors::boot(&mut m);
    assert!(TwoSectors::save(&mut store, &mut m, &values(1)));
    m.fail_program_at = Some(m.steps + 3);
    assert_eq!(
        block_on(store.save(&mut m, &values(2))),
        Err(SaveError::WriteFailed)
    );
    // The next save goes after the failed words, not over them.
    assert!(TwoSectors::save(&mut store, &mut m, &values(3)));
    let (p, _, boot) = TwoSectors::open(&m);
    assert_eq!(p, values(3));
    assert_eq!(boot.bad_slots, 1);
    // And going round the sectors after it still works.
    let (_, mut store) = TwoSectors::boot(&mut m);
    for i in 10..30 {
        assert!(TwoSectors::save(&mut store, &mut m, &values(i)));
        assert_eq!(TwoSectors::open(&m).0, values(i));
    }
}

#[test]
fn a_failed_erase_is_retried_by_the_next_save_and_spares_the_newest_slot() {
    let mut m = Model::new(TEST_SECTOR);
    let (_, mut store) = TwoSectors::boot(&mut m);
    let mut i = 0;
    // Fill sector 0 and then sector 1; the next save erases sector 0.
    while store.next_op() != Ok(Op::Erase { sector: 0 }) {
        assert!(TwoSectors::save(&mut store, &mut m, &values(i)));
        i += 1;
        assert!(i < 20, "sector 0 is never erased");
    }
    let newest = values(i - 1);
    m.fail_erase_at = Some(m.steps);
    assert_eq!(
        block_on(store.save(&mut m, &values(i))),
        Err(SaveError::EraseFailed)
    );
    assert_eq!(TwoSectors::open(&m).0, newest);
    assert_eq!(store.next_op(), Ok(Op::Erase { sector: 0 }));
    let saved = block_on(store.save(&mut m, &values(i))).unwrap();
    assert_eq!((saved.sector, saved.offset, saved.erased), (0, 0, true));
    assert_eq!(TwoSectors::open(&m).0, values(i));
}

/// The firmware's geometry: 128 KiB sectors of 141 slots, after the boot's guard word as once
/// erased.
#[test]
fn real_sectors_hold_141_slots_each_and_alternate() {
    const SECTOR: u32 = 128 * 1024;
    const SLOTS: usize = 141;
    assert_eq!((SECTOR as usize - FLASH_WORD) / SLOT_LEN, SLOTS);
    assert_eq!(SECTOR as usize / SLOT_LEN, SLOTS);
    let mut m = Model::new(SECTOR as usize);
    let (_, mut store) = TwoSectors::boot(&mut m);
    let mut erased_at = Vec::new();
    let saves = 3 * SLOTS + 10;
    for i in 0..saves {
        let saved = block_on(store.save(&mut m, &values(i))).unwrap();
        if saved.erased {
            erased_at.push((i, saved.sector));
        }
    }
    // Sector 0 (after the boot's guard word), sector 1, sector 0 again, then sector 1 again.
    // An erased sector has no guard word, but the word it saves does not make room for
    // another 928-byte slot.
    assert_eq!(erased_at, vec![(2 * SLOTS, 0), (3 * SLOTS, 1)]);
    let (p, _, boot) = TwoSectors::open(&m);
    assert_eq!(p, values(saves - 1));
    assert_eq!(
        boot.restored.map(|r| (r.sector, r.key)),
        Some((1, SlotKey::Seq(saves as u32 - 1)))
    );
    assert_eq!(boot.bad_slots, 0);
}

#[test]
fn geometry_needs_whole_words_and_two_slots() {
    assert!(Geometry::new(128 * 1024).is_some());
    assert!(Geometry::new(2 * SLOT_LEN as u32 + 32).is_some());
    assert!(Geometry::new(2 * SLOT_LEN as u32).is_none());
    assert!(Geometry::new(128 * 1024 + 4).is_none());
}

#[test]
fn sequence_exhaustion_is_an_error_not_a_wrap() {
    let mut m = Model::new(TEST_SECTOR);
    let (_, mut store) = TwoSectors::boot(&mut m);
    let mut slot = [0u8; SLOT_LEN];
    encode_v2(&values(1), u32::MAX, &mut slot);
    m.program(0, FLASH_WORD, &slot).unwrap();
    let (p, mut store2, _) = TwoSectors::open(&m);
    assert_eq!(p, values(1));
    assert_eq!(store2.next_op(), Err(SaveError::SequenceExhausted));
    assert_eq!(
        block_on(store2.save(&mut m, &values(2))),
        Err(SaveError::SequenceExhausted)
    );
    let _ = &mut store;
}
