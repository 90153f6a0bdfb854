//! Generated code tables of the shipped marker families (`tools/gen_families.py`, do not edit).
//!
//! Each submodule holds one family as static data: its layout (grid, quiet rings,
//! border ring), the codes indexed by id (packed data bits, see [`Family`]), the ids sorted
//! by code for exact look-ups, the true minimum Hamming distance (all rotations, each code
//! against its own rotations too) and the correction bound of
//! [`max_correction_for`](super::max_correction_for).
//!
//! The codes come from the family files in `../shared/data/families` (AprilTag's and OpenCV's
//! dictionaries, same ids as the markers users print); `aruco_original` is OpenCV's
//! `DICT_ARUCO_ORIGINAL`, taken from opencv-contrib-python's `generateImageMarker` with a
//! white quiet ring added. Regenerate everything with
//!
//! ```text
//! python3 tools/gen_families.py
//! ```
//!
//! | family | grid | bits | codes | min distance | max correction | multi-index |
//! |---|---:|---:|---:|---:|---:|---:|
//! | `tag16h5` | 8 | 16 | 30 | 5 | 0 | none |
//! | `tag25h9` | 9 | 25 | 35 | 9 | 0 | none |
//! | `tag36h10` | 10 | 36 | 2320 | 10 | 2 | 4 x 9 bits, 22,664 B |
//! | `tag36h11` | 10 | 36 | 587 | 11 | 2 | 4 x 9 bits, 8,800 B |
//! | `aruco_4x4_50` | 8 | 16 | 50 | 4 | 0 | none |
//! | `aruco_4x4_100` | 8 | 16 | 100 | 3 | 0 | none |
//! | `aruco_4x4_250` | 8 | 16 | 250 | 3 | 0 | none |
//! | `aruco_4x4_1000` | 8 | 16 | 1000 | 2 | 0 | none |
//! | `aruco_5x5_50` | 9 | 25 | 50 | 8 | 0 | none |
//! | `aruco_5x5_100` | 9 | 25 | 100 | 7 | 0 | none |
//! | `aruco_5x5_250` | 9 | 25 | 250 | 6 | 0 | none |
//! | `aruco_5x5_1000` | 9 | 25 | 1000 | 5 | 0 | none |
//! | `aruco_6x6_50` | 10 | 36 | 50 | 13 | 3 | 8+7+7+7+7 bits, 2,046 B |
//! | `aruco_6x6_100` | 10 | 36 | 100 | 12 | 3 | 8+7+7+7+7 bits, 2,546 B |
//! | `aruco_6x6_250` | 10 | 36 | 250 | 11 | 2 | 4 x 9 bits, 6,104 B |
//! | `aruco_6x6_1000` | 10 | 36 | 1000 | 9 | 2 | 4 x 9 bits, 12,104 B |
//! | `aruco_7x7_50` | 11 | 49 | 50 | 19 | 7 | 7+6+6+6+6+6+6+6 bits, 1,968 B |
//! | `aruco_7x7_100` | 11 | 49 | 100 | 18 | 7 | 7+6+6+6+6+6+6+6 bits, 2,768 B |
//! | `aruco_7x7_250` | 11 | 49 | 250 | 17 | 6 | 7 x 7 bits, 5,306 B |
//! | `aruco_7x7_1000` | 11 | 49 | 1000 | 14 | 5 | 9+8+8+8+8+8 bits, 15,596 B |
//! | `aruco_mip_36h12` | 10 | 36 | 250 | 12 | 2 | 4 x 9 bits, 6,104 B |
//! | `aruco_original` | 9 | 25 | 1024 | 0 | 0 | none |
//! | `tagStandard41h12` | 9 | 41 | 2115 | 12 | 3 | 11+10+10+10 bits, 27,168 B |
//!
//! The correction bound is the largest `k` below half the minimum distance for which a random
//! pattern inside a valid border is accepted with probability at most 0.0001
//! ([`MAX_FALSE_ACCEPT`](super::MAX_FALSE_ACCEPT)).
//!
//! Families that correct bits carry a [`MultiIndex`](super::MultiIndex) (chunk widths and
//! flash bytes in the last column) chosen by the generator to balance flash against look-up
//! cost; a family with so few codes that scanning them is as fast has none.
//!
//! Notes from the generator:
//! - aruco_5x5_50 (../shared/data/families/tagAruco5x5_50.txt): header says min_hamming 7, computed 8 (id 25 vs itself turned 1 quarter(s)); using 8
//! - aruco_original (OpenCV 4.14.0 cv2.aruco.DICT_ARUCO_ORIGINAL (opencv-contrib-python)): code(s) `[1023]` equal their own rotation, so their orientation is ambiguous; minimum distance 0 (without that: 1, id 255 turned 2 quarter(s) vs id 1022), no error correction

use super::Family;

pub mod aruco_4x4_100;
pub mod aruco_4x4_1000;
pub mod aruco_4x4_250;
pub mod aruco_4x4_50;
pub mod aruco_5x5_100;
pub mod aruco_5x5_1000;
pub mod aruco_5x5_250;
pub mod aruco_5x5_50;
pub mod aruco_6x6_100;
pub mod aruco_6x6_1000;
pub mod aruco_6x6_250;
pub mod aruco_6x6_50;
pub mod aruco_7x7_100;
pub mod aruco_7x7_1000;
pub mod aruco_7x7_250;
pub mod aruco_7x7_50;
pub mod aruco_mip_36h12;
pub mod aruco_original;
pub mod tag16h5;
pub mod tag25h9;
pub mod tag36h10;
pub mod tag36h11;
pub mod tag_standard41h12;

pub use aruco_4x4_100::ARUCO_4X4_100;
pub use aruco_4x4_1000::ARUCO_4X4_1000;
pub use aruco_4x4_250::ARUCO_4X4_250;
pub use aruco_4x4_50::ARUCO_4X4_50;
pub use aruco_5x5_100::ARUCO_5X5_100;
pub use aruco_5x5_1000::ARUCO_5X5_1000;
pub use aruco_5x5_250::ARUCO_5X5_250;
pub use aruco_5x5_50::ARUCO_5X5_50;
pub use aruco_6x6_100::ARUCO_6X6_100;
pub use aruco_6x6_1000::ARUCO_6X6_1000;
pub use aruco_6x6_250::ARUCO_6X6_250;
pub use aruco_6x6_50::ARUCO_6X6_50;
pub use aruco_7x7_100::ARUCO_7X7_100;
pub use aruco_7x7_1000::ARUCO_7X7_1000;
pub use aruco_7x7_250::ARUCO_7X7_250;
pub use aruco_7x7_50::ARUCO_7X7_50;
pub use aruco_mip_36h12::ARUCO_MIP_36H12;
pub use aruco_original::ARUCO_ORIGINAL;
pub use tag16h5::TAG16H5;
pub use tag25h9::TAG25H9;
pub use tag36h10::TAG36H10;
pub use tag36h11::TAG36H11;
pub use tag_standard41h12::TAG_STANDARD41H12;

/// Every shipped family: the contract's names in contract order, then `tagStandard41h12`.
pub static ALL: &[&Family<'static>] = &[
    &TAG16H5,
    &TAG25H9,
    &TAG36H10,
    &TAG36H11,
    &ARUCO_4X4_50,
    &ARUCO_4X4_100,
    &ARUCO_4X4_250,
    &ARUCO_4X4_1000,
    &ARUCO_5X5_50,
    &ARUCO_5X5_100,
    &ARUCO_5X5_250,
    &ARUCO_5X5_1000,
    &ARUCO_6X6_50,
    &ARUCO_6X6_100,
    &ARUCO_6X6_250,
    &ARUCO_6X6_1000,
    &ARUCO_7X7_50,
    &ARUCO_7X7_100,
    &ARUCO_7X7_250,
    &ARUCO_7X7_1000,
    &ARUCO_MIP_36H12,
    &ARUCO_ORIGINAL,
    &TAG_STANDARD41H12,
];

/// The families the CLI searches when no `--family` is given.
pub static DEFAULT: &[&Family<'static>] = &[&TAG36H11, &ARUCO_6X6_250];

/// A shipped family by its contract name (`tag36h11`, `aruco_6x6_250`, ...), ignoring ASCII case.
pub fn by_name(name: &str) -> Option<&'static Family<'static>> {
    ALL.iter()
        .copied()
        .find(|f| f.name.eq_ignore_ascii_case(name))
}

/// The names of the shipped families, in the order of [`ALL`].
pub fn names() -> impl Iterator<Item = &'static str> {
    ALL.iter().map(|f| f.name)
}

/// The contract's family names (`docs/interfaces.md`), in contract order.
#[cfg(test)]
const CONTRACT: &[&str] = &[
    "tag16h5",
    "tag25h9",
    "tag36h10",
    "tag36h11",
    "aruco_4x4_50",
    "aruco_4x4_100",
    "aruco_4x4_250",
    "aruco_4x4_1000",
    "aruco_5x5_50",
    "aruco_5x5_100",
    "aruco_5x5_250",
    "aruco_5x5_1000",
    "aruco_6x6_50",
    "aruco_6x6_100",
    "aruco_6x6_250",
    "aruco_6x6_1000",
    "aruco_7x7_50",
    "aruco_7x7_100",
    "aruco_7x7_250",
    "aruco_7x7_1000",
    "aruco_mip_36h12",
    "aruco_original",
];

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use crate::family::{max_correction_for, min_hamming_of};
    use std::{string::String, vec, vec::Vec};

    /// Code counts of the shipped families (public facts about the dictionaries).
    fn expected_count(name: &str) -> usize {
        match name {
            "tag16h5" => 30,
            "tag25h9" => 35,
            "tag36h10" => 2320,
            "tag36h11" => 587,
            "aruco_mip_36h12" => 250,
            "aruco_original" => 1024,
            "tagStandard41h12" => 2115,
            other => other.rsplit('_').next().unwrap().parse().unwrap(),
        }
    }

    /// Deterministic pseudo-random bit positions (xorshift), `count` distinct ones below `bits`.
    fn error_pattern(seed: u64, bits: u8, count: u32) -> u64 {
        let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        let mut mask = 0u64;
        while mask.count_ones() < count {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            mask |= 1u64 << (state % bits as u64);
        }
        mask
    }

    fn readings(f: &Family<'_>, code: u64) -> [u64; 4] {
        [0u8, 1, 2, 3].map(|k| f.rotate_code(code, k))
    }

    #[test]
    fn every_family_validates() {
        assert_eq!(ALL.len(), CONTRACT.len() + 1);
        for f in ALL {
            assert_eq!(f.validate(), Ok(()), "{}", f.name);
        }
    }

    #[test]
    fn contract_names_in_order() {
        let names: Vec<&str> = names().collect();
        assert_eq!(&names[..CONTRACT.len()], CONTRACT);
        assert_eq!(names[CONTRACT.len()], "tagStandard41h12");
        assert_eq!(
            DEFAULT.iter().map(|f| f.name).collect::<Vec<_>>(),
            ["tag36h11", "aruco_6x6_250"]
        );
    }

    #[test]
    fn code_counts() {
        for f in ALL {
            assert_eq!(f.codes.len(), expected_count(f.name), "{}", f.name);
            assert_eq!(f.sorted_ids.len(), f.codes.len(), "{}", f.name);
        }
    }

    #[test]
    fn correction_bound_follows_the_formula() {
        for f in ALL {
            assert_eq!(
                f.max_correction,
                max_correction_for(f.bits, f.codes.len(), f.min_hamming),
                "{}",
                f.name
            );
            let (t, d) = (f.max_correction as u32, f.min_hamming as u32);
            assert!(t == 0 || 2 * t < d, "{}", f.name);
        }
    }

    #[test]
    fn min_hamming_is_the_true_distance() {
        for f in ALL {
            assert_eq!(f.min_hamming, min_hamming_of(f), "{}", f.name);
        }
    }

    #[test]
    fn by_name_round_trip() {
        for f in ALL {
            assert!(core::ptr::eq(by_name(f.name).unwrap(), *f));
            let upper: String = f.name.to_ascii_uppercase();
            let lower: String = f.name.to_ascii_lowercase();
            assert!(core::ptr::eq(by_name(&upper).unwrap(), *f), "{upper}");
            assert!(core::ptr::eq(by_name(&lower).unwrap(), *f), "{lower}");
        }
        assert!(by_name("Tag36H11").is_some());
        assert!(by_name("tag36h12").is_none());
        assert!(by_name("").is_none());
    }

    #[test]
    fn every_code_decodes_in_every_rotation() {
        for f in ALL {
            for (id, &code) in f.codes.iter().enumerate() {
                for turn in 0..4u8 {
                    let seen = readings(f, f.rotate_code(code, turn));
                    let d = f
                        .decode(&seen, f.max_correction)
                        .unwrap_or_else(|| panic!("{} id {id} turn {turn}", f.name));
                    assert_eq!(
                        (d.id, d.hamming),
                        (id as u16, 0),
                        "{} id {id} turn {turn}",
                        f.name
                    );
                    assert_eq!(
                        seen[d.rotation as usize], code,
                        "{} id {id} turn {turn}",
                        f.name
                    );
                }
            }
        }
    }

    /// With min distance d >= 2t + 1 between any code and any rotation of any code (itself
    /// included), a reading with t <= max_correction flipped bits is within t of the true code
    /// in the true rotation and at least d - t > t from every other (id, rotation): the decode
    /// is that id, unique.
    #[test]
    fn max_correction_flips_decode_to_the_same_id() {
        for f in ALL {
            let t = f.max_correction as u32;
            for (id, &code) in f.codes.iter().enumerate() {
                for turn in 0..4u8 {
                    let bad = code ^ error_pattern((id as u64) << 2 | turn as u64, f.bits, t);
                    let seen = readings(f, f.rotate_code(bad, turn));
                    let d = f
                        .decode(&seen, f.max_correction)
                        .unwrap_or_else(|| panic!("{} id {id}", f.name));
                    assert_eq!(
                        (d.id, d.hamming as u32),
                        (id as u16, t),
                        "{} id {id} turn {turn}",
                        f.name
                    );
                    assert_eq!(seen[d.rotation as usize], bad, "{} id {id}", f.name);
                }
            }
        }
    }

    /// With e flipped bits, t < e, every (id, rotation) is at least d - e away from the reading.
    /// When d - e > t (i.e. e <= d - t - 1) nothing is within the correction bound: the decode
    /// must fail. When d = 2t + 1 a reading with t + 1 errors can lie within t of another
    /// code, so all that holds there is that a reported decode is genuine (its hamming is the
    /// true distance, at most t).
    #[test]
    fn more_flips_never_decode_wrongly() {
        for f in ALL {
            let t = f.max_correction as u32;
            let d = f.min_hamming as u32;
            let mut counts = vec![t + 1];
            if d > 2 * t + 2 {
                counts.push(d - t - 1);
            }
            for e in counts {
                if e > f.bits as u32 {
                    continue;
                }
                for (id, &code) in f.codes.iter().enumerate() {
                    let bad = code ^ error_pattern(((id as u64) << 8) | e as u64, f.bits, e);
                    let seen = readings(f, bad);
                    let got = f.decode(&seen, f.max_correction);
                    if d > e + t {
                        assert_eq!(got, None, "{} id {id} with {e} errors", f.name);
                    } else if let Some(got) = got {
                        let code = f.codes[got.id as usize];
                        let actual = (code ^ seen[got.rotation as usize]).count_ones();
                        assert_eq!(actual, got.hamming as u32, "{} id {id}", f.name);
                        assert!(actual <= t, "{} id {id}", f.name);
                    }
                }
            }
        }
    }
}
