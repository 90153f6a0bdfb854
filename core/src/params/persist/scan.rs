//! The replay of a sector's log at boot: a word-by-word scan for the newest valid slot.
//!
//! Separate from the store because it only reads: it finds the newest slot of either format,
//! counts the bad ones and where the written part ends, and [`super::Store::open`] decides
//! from two such scans what to restore and where the log continues.

use super::slot::{check_v2, slot_header, LEGACY_MAGIC, LEGACY_SLOT_LEN, MAX_SLOT_LEN, WORD_U32};
use super::{Geometry, SlotKey, ERASED, FLASH_WORD};
use crate::params::{ImportReport, ParamSet};

/// One sector's scan.
pub(super) struct SectorScan {
    pub(super) best: Option<(SlotKey, ParamSet, ImportReport)>,
    pub(super) bad_slots: u16,
    /// End of the last word that is not erased (0: the sector is erased).
    pub(super) used_end: u32,
    /// Holds a format-1 log (and no format-2 slot).
    pub(super) legacy: bool,
}

/// Scans one sector word by word: a format-2 slot header starts a slot (stepped over whole
/// when valid, else the scan goes on at the next word, so a torn or foreign header cannot
/// hide what follows); in a sector without format-2 slots, format-1 slots at multiples of
/// [`LEGACY_SLOT_LEN`].
pub(super) fn scan_sector(
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
