//! Power-loss tests of the parameter log against a model of the STM32H7's flash.
//!
//! The model ([`Model`]) is the contract the log relies on, and it enforces the H7's rules:
//! erased reads `0xFF`; programming is in whole 32-byte flash words, each only while erased
//! (programming a word that is not erased panics: that is a bug of the log, on silicon it
//! leaves an ECC error); erasing is per sector. Every word program and every sector erase is
//! one *step*, and a test can cut the power at any step: the word being programmed is left
//! torn (garbage, half programmed, or some of its bits), the sector being erased is left
//! partly erased (some words erased, others old or garbage), and nothing happens after.
//!
//!
//! Also the ways of running the log against it ([`Design`], [`TwoSectors`]) and the parameter
//! sets the tests save, shared by the power-loss tests, the store's tests and the slot and
//! format-1 tests.
//!
//! Test code only: the parent module declares this module under `#[cfg(test)]`, so the `std`,
//! the `Vec`s and the `unwrap`s below never reach the firmware.
extern crate std;

use std::vec;
use std::vec::Vec;

use embassy_futures::block_on;

use super::*;
use crate::params::{ParamId, ParamSet};

/// How the step the power is cut at is left.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Tear {
    /// The step never started.
    None,
    /// Program: random bytes. Erase: each word erased, old or random.
    Garbage,
    /// Program: the first 16 bytes programmed, the rest still erased. Erase: the first half
    /// of the words erased, the rest old.
    LowHalf,
    /// Program: the last 16 bytes programmed, the first still erased. Erase: the second half
    /// erased, the first old.
    HighHalf,
    /// Program: some of the word's 0 bits not programmed yet. Erase: everything erased but a
    /// few random words.
    SomeBits,
    /// Program: cut just as it started: the word still reads erased, but its ECC bits are not,
    /// so it must not be programmed again. Erase: as [`Tear::Garbage`].
    Invisible,
}

pub(super) const TEARS: [Tear; 6] = [
    Tear::None,
    Tear::Garbage,
    Tear::LowHalf,
    Tear::HighHalf,
    Tear::SomeBits,
    Tear::Invisible,
];

/// Two sectors of flash words.
#[derive(Clone)]
pub(super) struct Model {
    pub(super) sector_len: usize,
    pub(super) bytes: Vec<u8>,
    /// Per word: touched by a cut program although it reads erased ([`Tear::Invisible`]), and
    /// the data that program was for: only that data may be programmed into it again.
    dirty: Vec<Option<[u8; FLASH_WORD]>>,
    /// Steps (word programs and sector erases) done since the model was made.
    pub(super) steps: u64,
    /// Cut the power at this step.
    pub(super) cut: Option<(u64, Tear)>,
    /// The power is off: every operation fails and changes nothing.
    pub(super) dead: bool,
    /// A program error (the driver returns an error) at this step, the word half programmed.
    pub(super) fail_program_at: Option<u64>,
    /// Erase errors (the driver returns an error, the sector unchanged) at these steps.
    pub(super) fail_erase_at: Option<u64>,
    rng: u64,
    pub(super) erases: u64,
    pub(super) cut_during_erase: bool,
}

impl Model {
    pub(super) fn new(sector_len: usize) -> Self {
        assert!(sector_len.is_multiple_of(FLASH_WORD));
        Model {
            sector_len,
            bytes: vec![ERASED; SECTORS * sector_len],
            dirty: vec![None; SECTORS * sector_len / FLASH_WORD],
            steps: 0,
            cut: None,
            dead: false,
            fail_program_at: None,
            fail_erase_at: None,
            rng: 0x9E37_79B9_7F4A_7C15,
            erases: 0,
            cut_during_erase: false,
        }
    }

    fn random(&mut self) -> u64 {
        // xorshift64*: deterministic, so every run tears the same way.
        self.rng ^= self.rng >> 12;
        self.rng ^= self.rng << 25;
        self.rng ^= self.rng >> 27;
        self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn garbage_word(&mut self) -> [u8; FLASH_WORD] {
        let mut w = [0u8; FLASH_WORD];
        for b in w.iter_mut() {
            *b = self.random() as u8;
        }
        // A torn word never reads as erased (on silicon its ECC bits are programmed too).
        if w.iter().all(|&b| b == ERASED) {
            w[0] = 0;
        }
        w
    }

    fn base(&self, sector: usize, offset: usize, len: usize) -> usize {
        assert!(sector < SECTORS, "sector {sector}");
        assert!(
            offset + len <= self.sector_len,
            "{offset}+{len} outside the sector"
        );
        sector * self.sector_len + offset
    }

    /// Powers up again after a cut.
    pub(super) fn reboot(&mut self) {
        self.dead = false;
        self.cut = None;
    }

    /// Counts a step; `Some(tear)` when the power is cut at it.
    fn step(&mut self) -> Option<Tear> {
        let s = self.steps;
        self.steps += 1;
        match self.cut {
            Some((at, tear)) if at == s => {
                self.dead = true;
                Some(tear)
            }
            _ => None,
        }
    }

    pub(super) fn read(&self, sector: usize, offset: usize, buf: &mut [u8]) -> bool {
        let b = self.base(sector, offset, buf.len());
        buf.copy_from_slice(&self.bytes[b..b + buf.len()]);
        true
    }

    pub(super) fn program(
        &mut self,
        sector: usize,
        offset: usize,
        data: &[u8],
    ) -> Result<(), FlashFailed> {
        if self.dead {
            return Err(FlashFailed);
        }
        assert!(
            offset.is_multiple_of(FLASH_WORD) && data.len().is_multiple_of(FLASH_WORD),
            "unaligned program at {offset}, {} bytes",
            data.len()
        );
        let base = self.base(sector, offset, data.len());
        for (i, word) in data.chunks_exact(FLASH_WORD).enumerate() {
            let at = base + i * FLASH_WORD;
            assert!(
                self.bytes[at..at + FLASH_WORD].iter().all(|&b| b == ERASED),
                "programming the non-erased word at sector {sector} offset {}",
                offset + i * FLASH_WORD
            );
            if let Some(before) = self.dirty[at / FLASH_WORD] {
                assert!(
                    before == word,
                    "programming the word at sector {sector} offset {} with other data after a cut",
                    offset + i * FLASH_WORD
                );
            }
            let step = self.steps;
            if let Some(tear) = self.step() {
                let torn: [u8; FLASH_WORD] = match tear {
                    Tear::None => [ERASED; FLASH_WORD],
                    Tear::Invisible => {
                        self.dirty[at / FLASH_WORD] = word.try_into().ok();
                        [ERASED; FLASH_WORD]
                    }
                    Tear::Garbage => self.garbage_word(),
                    Tear::LowHalf => {
                        let mut w = [ERASED; FLASH_WORD];
                        w[..16].copy_from_slice(&word[..16]);
                        w
                    }
                    Tear::HighHalf => {
                        let mut w = [ERASED; FLASH_WORD];
                        w[16..].copy_from_slice(&word[16..]);
                        w
                    }
                    Tear::SomeBits => {
                        let mut w = [0u8; FLASH_WORD];
                        for (d, s) in w.iter_mut().zip(word) {
                            *d = *s | self.random() as u8;
                        }
                        w
                    }
                };
                self.bytes[at..at + FLASH_WORD].copy_from_slice(&torn);
                return Err(FlashFailed);
            }
            if self.fail_program_at == Some(step) {
                // The controller flags an error half way through the word; the driver stops.
                self.bytes[at..at + 16].copy_from_slice(&word[..16]);
                return Err(FlashFailed);
            }
            self.bytes[at..at + FLASH_WORD].copy_from_slice(word);
            self.dirty[at / FLASH_WORD] = None;
        }
        Ok(())
    }

    pub(super) fn erase_sector(&mut self, sector: usize) -> Result<(), FlashFailed> {
        if self.dead {
            return Err(FlashFailed);
        }
        let base = self.base(sector, 0, self.sector_len);
        let step = self.steps;
        self.erases += 1;
        if let Some(tear) = self.step() {
            self.cut_during_erase = true;
            let words = self.sector_len / FLASH_WORD;
            for w in 0..words {
                let at = base + w * FLASH_WORD;
                let r = self.random();
                let action = match tear {
                    Tear::None => 1,                                     // old
                    Tear::Garbage | Tear::Invisible => r % 3,            // erased, old, garbage
                    Tear::LowHalf => usize::from(w >= words / 2) as u64, // erased, then old
                    Tear::HighHalf => usize::from(w < words / 2) as u64,
                    Tear::SomeBits => {
                        if r.is_multiple_of(5) {
                            2
                        } else {
                            0
                        }
                    }
                };
                match action {
                    0 => {
                        self.bytes[at..at + FLASH_WORD].fill(ERASED);
                        self.dirty[at / FLASH_WORD] = None;
                    }
                    1 => {}
                    _ => {
                        let g = self.garbage_word();
                        self.bytes[at..at + FLASH_WORD].copy_from_slice(&g);
                    }
                }
            }
            return Err(FlashFailed);
        }
        if self.fail_erase_at == Some(step) {
            return Err(FlashFailed);
        }
        self.bytes[base..base + self.sector_len].fill(ERASED);
        self.dirty[base / FLASH_WORD..(base + self.sector_len) / FLASH_WORD].fill(None);
        Ok(())
    }

    /// Fills `sector` with random bytes: what an OpenMV Cam's ROMFS looks like to us.
    pub(super) fn fill_foreign(&mut self, sector: usize) {
        let base = self.base(sector, 0, self.sector_len);
        for i in 0..self.sector_len / FLASH_WORD {
            let g = self.garbage_word();
            self.bytes[base + i * FLASH_WORD..base + (i + 1) * FLASH_WORD].copy_from_slice(&g);
        }
    }
}

/// A way of storing parameters, as the firmware runs it: boot (scan, restore, any clean-up)
/// and save.
pub(super) trait Design {
    type State: Clone;
    fn boot(m: &mut Model) -> (ParamSet, Self::State);
    fn save(s: &mut Self::State, m: &mut Model, p: &ParamSet) -> bool;
}

/// A distinct parameter set per number.
pub(super) fn values(i: usize) -> ParamSet {
    let mut p = ParamSet::default();
    p.set(ParamId::RateHz, (1 + i % 100) as f32).unwrap();
    p.set(ParamId::CamYaw, (i % 360) as f32 * 0.5 - 90.0)
        .unwrap();
    p.set(ParamId::Profile, (i % 2) as f32).unwrap();
    p
}

/// A parameter set whose profile is `v`.
pub(super) fn with_profile(v: f32) -> ParamSet {
    let mut p = ParamSet::default();
    p.set(ParamId::Profile, v).unwrap();
    p
}

impl SlotFlash for Model {
    async fn erase(&mut self, sector: usize) -> Result<(), FlashFailed> {
        self.erase_sector(sector)
    }
    async fn write(&mut self, sector: usize, offset: u32, bytes: &[u8]) -> Result<(), FlashFailed> {
        self.program(sector, offset as usize, bytes)
    }
}

/// The design of this module, driven exactly as `firmware/src/param_store.rs` drives it:
/// [`Store::open`] and [`Store::boot_cleanup`] at boot, [`Store::save`] per save.
pub(super) struct TwoSectors;

impl TwoSectors {
    pub(super) fn open(m: &Model) -> (ParamSet, Store, Boot) {
        let geometry = Geometry::new(m.sector_len as u32).unwrap();
        let mut p = ParamSet::default();
        let (store, boot) = Store::open(
            geometry,
            |sector, offset, buf| m.read(sector, offset as usize, buf),
            &mut p,
        );
        (p, store, boot)
    }
}

impl Design for TwoSectors {
    type State = Store;
    fn boot(m: &mut Model) -> (ParamSet, Store) {
        let (p, mut store, _) = Self::open(m);
        block_on(store.boot_cleanup(m));
        (p, store)
    }
    fn save(s: &mut Store, m: &mut Model, p: &ParamSet) -> bool {
        block_on(s.save(m, p)).is_ok()
    }
}

/// Small sectors (4 slots) so that a few saves go round both sectors several times.
pub(super) const TEST_SECTOR: usize = 4 * SLOT_LEN + 2 * FLASH_WORD;

/// A format-1 log (the firmware before slot format 2) in the last sector: `n` saves of
/// `values(100 + i)`.
pub(super) fn with_format_1_log(n: usize) -> Model {
    let mut m = Model::new(TEST_SECTOR);
    for i in 0..n {
        let mut slot = [0u8; LEGACY_SLOT_LEN];
        encode_slot(&values(100 + i), &mut slot);
        m.program(1, i * LEGACY_SLOT_LEN, &slot).unwrap();
    }
    m
}
