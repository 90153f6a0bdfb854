//! The slot format: what one save writes (format 2: header word, sequence number, export blob,
//! padding, trailer with CRC-32), how a slot is recognised and checked, and the format-1 slot
//! (a bare export blob) that older firmware wrote.
//!
//! Separate from the store and the scan because it is the on-flash layout alone: bytes in,
//! bytes out, no decision about where a slot goes.

use super::FLASH_WORD;
use crate::params::{ImportReport, ParamSet, EXPORT_LEN};

/// Slot format version written by [`Store`](super::Store) (1 was the bare export blob, see
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
pub(super) const SLOT_LEN_U32: u32 = SLOT_LEN as u32;
pub(super) const WORD_U32: u32 = FLASH_WORD as u32;
const _: () = assert!(SLOT_LEN <= MAX_SLOT_LEN && MAX_SLOT_LEN / FLASH_WORD <= u8::MAX as usize);

/// Bytes per slot of the format-1 log: the 13-parameter export blob (268 bytes) rounded up to
/// flash words, what every firmware before slot format 2 wrote.
pub const LEGACY_SLOT_LEN: usize = 288;
/// First bytes of an export blob ([`ParamSet::export`]'s magic and format version), i.e. of a
/// format-1 slot.
pub(super) const LEGACY_MAGIC: [u8; 5] = [b'T', b'D', b'P', b'R', 1];

/// The slot length in words if `word` starts a format-2 slot.
pub(super) fn slot_header(word: &[u8; FLASH_WORD]) -> Option<u32> {
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
pub(super) fn check_v2(slot: &[u8], base: &ParamSet) -> Option<(u32, ParamSet, ImportReport)> {
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
pub(super) fn encode_v2(params: &ParamSet, seq: u32, out: &mut [u8; SLOT_LEN]) {
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

#[cfg(test)]
mod tests {
    use super::super::test_fixtures::values;
    use super::*;

    // A format-1 slot held the 13-parameter blob.
    const _: () = assert!(
        LEGACY_SLOT_LEN.is_multiple_of(FLASH_WORD)
            && LEGACY_SLOT_LEN >= 8 + super::super::legacy::LEGACY_PARAM_COUNT * 20
    );

    /// The slot size the module documentation's save count is worked out from.
    #[test]
    fn slot_size_of_the_current_table() {
        assert_eq!(EXPORT_LEN, 8 + (crate::params::PARAM_COUNT + 10) * 20);
        assert_eq!(LEGACY_SLOT_LEN, 288);
        assert_eq!(128 * 1024 / LEGACY_SLOT_LEN, 455);
        // Format 2: a header word and the sequence number more; 33 parameters (the lens's
        // nine and TD_PAD appended to the 23 of the signing firmware, whose 736-byte slots
        // still read back, like the 22 parameters' 512-byte, the 21 and 20 parameters'
        // 480-byte, the 19 parameters' 448-byte, the 16 parameters' 384-byte and the 13
        // parameters' 320-byte ones) and the signing secret's 10 records take 29 words: 141
        // slots per sector after the first boot's free word.
        assert_eq!(SLOT_LEN, 928);
        assert_eq!((128 * 1024 - FLASH_WORD) / SLOT_LEN, 141);
    }

    /// A format-2 slot of an older firmware whose table ended after `records` parameters, in
    /// `words` flash words, as it wrote it (the first `words * FLASH_WORD` bytes).
    fn older_slot(params: &ParamSet, seq: u32, records: usize, words: u8) -> [u8; MAX_SLOT_LEN] {
        let len = usize::from(words) * FLASH_WORD;
        let mut out = [0u8; MAX_SLOT_LEN];
        out[..4].copy_from_slice(&SLOT_MAGIC);
        out[4] = SLOT_VERSION;
        out[5] = words;
        out[FLASH_WORD..SLOT_HEADER_LEN].copy_from_slice(&seq.to_le_bytes());
        params.export_records(records, &mut out[SLOT_HEADER_LEN..len - SLOT_TRAILER_LEN]);
        out[len - 8..len - 4].copy_from_slice(&TRAILER_MAGIC);
        let crc = crc32(&out[..len - 4]);
        out[len - 4..len].copy_from_slice(&crc.to_le_bytes());
        out
    }

    /// A format-2 slot of the 13-parameter firmware (10 words).
    fn thirteen_parameter_slot(params: &ParamSet, seq: u32) -> [u8; 320] {
        let mut out = [0u8; 320];
        out.copy_from_slice(&older_slot(params, seq, 13, 10)[..320]);
        out
    }

    #[test]
    fn a_slot_of_the_twenty_parameter_firmware_imports_with_the_pad_bearing_unset() {
        use crate::params::ParamId;
        let mut saved = values(7);
        saved.set(ParamId::Px4OuterLoopAlt, 15.0).unwrap();
        saved.set(ParamId::PadYaw, 90.0).unwrap();
        // 20 records (408 bytes) took 15 words (480 bytes).
        let slot = older_slot(&saved, 12, 20, 15);
        let slot = &slot[..480];
        let (seq, p, report) = check_v2(slot, &ParamSet::default()).unwrap();
        assert_eq!((seq, report.applied), (12, 20));
        let mut want = saved;
        want.set(ParamId::PadYaw, -1.0).unwrap();
        assert_eq!(p, want);
    }

    #[test]
    fn a_slot_of_the_twenty_one_parameter_firmware_imports_with_the_pad_motion_on_auto() {
        use crate::params::ParamId;
        let mut saved = values(8);
        saved.set(ParamId::PadYaw, 90.0).unwrap();
        saved.set(ParamId::PadMotion, 1.0).unwrap();
        // 21 records (428 bytes) took 15 words (480 bytes).
        let slot = older_slot(&saved, 13, 21, 15);
        let slot = &slot[..480];
        let (seq, p, report) = check_v2(slot, &ParamSet::default()).unwrap();
        assert_eq!((seq, report.applied), (13, 21));
        let mut want = saved;
        want.set(ParamId::PadMotion, 2.0).unwrap();
        assert_eq!(p, want);
    }

    #[test]
    fn a_slot_of_the_twenty_two_parameter_firmware_imports_locked_and_without_a_key() {
        use crate::params::{ParamId, SigningSecret};
        let mut saved = values(9);
        saved.set(ParamId::PadMotion, 0.0).unwrap();
        saved.set(ParamId::Lock, 0.0).unwrap();
        saved.set_signing_secret(SigningSecret::new([7; 32], 5));
        // 22 records (448 bytes) took 16 words (512 bytes); no secret records.
        let slot = older_slot(&saved, 14, 22, 16);
        let slot = &slot[..512];
        let (seq, p, report) = check_v2(slot, &ParamSet::default()).unwrap();
        assert_eq!((seq, report.applied, report.unknown), (14, 22, 0));
        let mut want = saved;
        want.set(ParamId::Lock, 1.0).unwrap();
        want.set_signing_secret(SigningSecret::NONE);
        assert_eq!(p, want);
    }

    #[test]
    fn the_signing_secret_is_saved_in_the_slot_and_restored() {
        use crate::params::SigningSecret;
        let mut saved = values(3);
        let key: [u8; 32] = core::array::from_fn(|i| (i * 37 + 1) as u8);
        saved.set_signing_secret(SigningSecret::new(key, 0x0123_4567_89AB));
        let mut slot = [0u8; SLOT_LEN];
        encode_v2(&saved, 21, &mut slot);
        let (seq, p, report) = check_v2(&slot, &ParamSet::default()).unwrap();
        assert_eq!((seq, report.unknown), (21, 0));
        assert_eq!(p.signing_secret().key(), Some(&key));
        assert_eq!(p.signing_secret().timestamp(), 0x0123_4567_89AB);
        assert_eq!(p, saved);
        // A blob with the key cleared clears it: the records are always written.
        saved.set_signing_secret(SigningSecret::NONE);
        encode_v2(&saved, 22, &mut slot);
        let mut base = ParamSet::default();
        base.set_signing_secret(SigningSecret::new(key, 1));
        let (_, p, _) = check_v2(&slot, &base).unwrap();
        assert!(!p.signing_secret().is_set());
    }

    #[test]
    fn a_slot_of_the_sixteen_parameter_firmware_imports_with_the_camera_at_the_origin() {
        use crate::params::ParamId;
        let mut saved = values(6);
        saved.set(ParamId::CamCal, 1.0).unwrap();
        saved.set(ParamId::CamPosZ, 0.2).unwrap();
        // 16 records (328 bytes) took 12 words (384 bytes).
        let slot = older_slot(&saved, 11, 16, 12);
        let slot = &slot[..384];
        assert_eq!(
            slot_header(slot[..FLASH_WORD].try_into().unwrap()),
            Some(12)
        );
        let (seq, p, report) = check_v2(slot, &ParamSet::default()).unwrap();
        assert_eq!((seq, report.applied), (11, 16));
        let mut want = saved;
        want.set(ParamId::CamPosZ, 0.0).unwrap();
        assert_eq!(p, want);
    }

    #[test]
    fn a_slot_of_the_thirteen_parameter_firmware_imports_with_the_mount_defaults() {
        use crate::params::ParamId;
        let mut saved = values(5);
        saved.set(ParamId::CamRoll, 2.0).unwrap();
        let slot = thirteen_parameter_slot(&saved, 9);
        assert_eq!(
            slot_header(slot[..FLASH_WORD].try_into().unwrap()),
            Some(10)
        );
        let (seq, p, report) = check_v2(&slot, &ParamSet::default()).unwrap();
        assert_eq!((seq, report.applied), (9, 13));
        // Everything it knew, and the defaults of what it did not.
        let mut want = saved;
        want.set(ParamId::CamRoll, 0.0).unwrap();
        assert_eq!(p, want);
        assert_eq!(p.get(ParamId::CamCal), 2.0);
    }

    #[test]
    fn a_slot_of_the_nineteen_parameter_firmware_imports_with_the_outer_loop_default() {
        use crate::params::ParamId;
        let mut saved = values(7);
        saved.set(ParamId::CamPosX, 0.15).unwrap();
        saved.set(ParamId::Px4OuterLoopAlt, 3.0).unwrap();
        // 19 records (388 bytes) took 14 words (448 bytes).
        let slot = older_slot(&saved, 12, 19, 14);
        let slot = &slot[..448];
        let (seq, p, report) = check_v2(slot, &ParamSet::default()).unwrap();
        assert_eq!((seq, report.applied), (12, 19));
        let mut want = saved;
        want.set(ParamId::Px4OuterLoopAlt, 0.0).unwrap();
        assert_eq!(p, want);
    }

    #[test]
    fn a_slot_of_the_signing_firmware_imports_with_the_build_lens_and_pad_and_its_key() {
        use crate::params::{ParamId, SigningSecret};
        let mut saved = values(10);
        saved.set(ParamId::Lock, 0.0).unwrap();
        // Set here, but not in the older firmware's table: they come back at their defaults.
        saved.set(ParamId::CamFx, 300.0).unwrap();
        saved.set(ParamId::CamK1, -0.2).unwrap();
        saved.set(ParamId::Pad, 2.0).unwrap();
        saved.set_signing_secret(SigningSecret::new([9; 32], 77));
        // 23 records and the secret's 10 (668 bytes) took 23 words (736 bytes).
        let mut slot = older_slot(&saved, 15, 23, 23);
        let mut blob = [0u8; 736 - SLOT_HEADER_LEN - SLOT_TRAILER_LEN];
        let n = saved.export_records_with_secret(23, &mut blob);
        assert_eq!(n, 668);
        slot[SLOT_HEADER_LEN..SLOT_HEADER_LEN + blob.len()].copy_from_slice(&blob);
        slot[736 - 8..736 - 4].copy_from_slice(&TRAILER_MAGIC);
        let crc = crc32(&slot[..736 - 4]);
        slot[736 - 4..736].copy_from_slice(&crc.to_le_bytes());
        let (seq, p, report) = check_v2(&slot[..736], &ParamSet::default()).unwrap();
        assert_eq!((seq, report.applied, report.unknown), (15, 23, 0));
        assert_eq!(p.signing_secret().key(), Some(&[9; 32]));
        let mut want = saved;
        for id in [
            ParamId::CamFx,
            ParamId::CamFy,
            ParamId::CamCx,
            ParamId::CamCy,
        ] {
            want.set(id, 0.0).unwrap();
        }
        for id in [
            ParamId::CamK1,
            ParamId::CamK2,
            ParamId::CamP1,
            ParamId::CamP2,
            ParamId::CamK3,
        ] {
            want.set(id, 0.0).unwrap();
        }
        want.set(ParamId::Pad, 0.0).unwrap();
        assert_eq!(p, want);
    }

    #[test]
    fn slot_layout() {
        assert_eq!(SLOT_LEN, 928);
        let mut slot = [0u8; SLOT_LEN];
        encode_v2(&values(3), 0x0102_0304, &mut slot);
        let mut other = [0u8; SLOT_LEN];
        encode_v2(&values(4), 7, &mut other);
        // The first word is the same in every slot (see the module documentation).
        assert_eq!(slot[..FLASH_WORD], other[..FLASH_WORD]);
        assert_eq!(&slot[..6], b"TDSL\x02\x1d");
        assert!(slot[6..FLASH_WORD].iter().all(|&b| b == 0));
        assert_eq!(slot[32..36], [4, 3, 2, 1]);
        // The export blob starts mid-word, so it can never pass for a format-1 slot.
        assert_eq!(&slot[36..40], b"TDPR");
        // The trailer fills the end of the last word, written last.
        assert_eq!(&slot[SLOT_LEN - 8..SLOT_LEN - 4], b"TDOK");
        assert_eq!(
            u32::from_le_bytes(slot[SLOT_LEN - 4..].try_into().unwrap()),
            crc32(&slot[..SLOT_LEN - 4])
        );
        assert_eq!(
            check_v2(&slot, &ParamSet::default()).map(|(seq, p, _)| (seq, p)),
            Some((0x0102_0304, values(3)))
        );
        for i in 0..SLOT_LEN {
            let mut bad = slot;
            bad[i] ^= 0x10;
            assert!(check_v2(&bad, &ParamSet::default()).is_none(), "byte {i}");
        }
    }

    #[test]
    fn crc32_reference_vector() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }
}
