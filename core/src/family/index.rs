//! Multi-index hashing: the approximate code look-up of [`Family::decode`](super::Family::decode).
//!
//! A family that corrects up to `k` bit errors must find every code within `k` bits of one of
//! the four readings of a candidate. Comparing the readings with every code costs four popcounts
//! per code (tag36h11: 2,348, in software on the Cortex-M7), and it is paid for every bordered
//! quad that is not a marker. The index avoids that with the pigeonhole principle: the data
//! bits are split into `m > k` disjoint chunks, so `k` differing bits leave at least one chunk
//! where the reading and the code agree exactly. Per chunk, a bucket table lists the ids of the
//! codes with each chunk value; a look-up verifies only the codes that share a bucket with a
//! reading (a few per bucket) and picks the nearest.
//!
//! ## Layout
//! - `chunk_bits[c]` is the width of chunk `c`; chunk 0 holds the least significant bits of
//!   the code, chunk 1 the next ones, and so on, up to `bits` in all;
//! - `starts` holds, chunk after chunk, `2^chunk_bits[c] + 1` offsets: bucket `v` of chunk
//!   `c` is `ids[c * n + starts[v]..c * n + starts[v + 1]]` (offsets relative to the chunk's
//!   part of `ids`, so they fit a `u16` for any family size);
//! - `ids` holds, chunk after chunk, the `n` ids of the family sorted by that chunk's value
//!   (ascending ids within a bucket).
//!
//! The tables are generated with the code tables (`tools/gen_families.py`), which picks the
//! chunk widths per family to balance flash against look-up cost; families parsed at run time
//! have no index and use the linear scan.

use super::{Decoded, FamilyErrorKind};

/// Widest chunk: its bucket offsets take `2^16 + 1` entries.
pub const MAX_CHUNK_BITS: u8 = 16;

/// Bucket tables that find every code within a few bits of a reading (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MultiIndex<'a> {
    /// Width of each chunk in bits, least significant chunk first; they add up to the
    /// family's `bits`, and there are more chunks than the family's `max_correction`.
    pub chunk_bits: &'a [u8],
    /// Per chunk, `2^width + 1` bucket offsets into that chunk's part of `ids`.
    pub starts: &'a [u16],
    /// Per chunk, every id once, grouped by the chunk's value.
    pub ids: &'a [u16],
}

impl MultiIndex<'_> {
    /// Whether a look-up that accepts up to `limit` differing bits finds every code within
    /// that distance: at least `limit + 1` chunks.
    pub fn covers(&self, limit: u8) -> bool {
        self.chunk_bits.len() > usize::from(limit)
    }

    /// The nearest `(id, rotation)` within `limit` bits of the readings: the smallest distance,
    /// ties broken by the smallest id, then the smallest rotation (the order in which a scan
    /// over ids, then rotations, meets them first). Needs [`MultiIndex::covers`]`(limit)`; an
    /// index that does not match `codes` (see [`MultiIndex::check`]) can miss codes but never
    /// panics.
    pub(super) fn nearest(&self, codes: &[u64], readings: &[u64; 4], limit: u8) -> Option<Decoded> {
        const ID_SHIFT: u32 = 2;
        const DISTANCE_SHIFT: u32 = 18;
        let n = codes.len();
        let limit = u32::from(limit);
        // (distance, id, rotation) packed so that the integer order is the tie-break order.
        let mut best = u32::MAX;
        let mut shift = 0u32;
        let mut starts_base = 0usize;
        let mut ids_base = 0usize;
        for &width in self.chunk_bits {
            let buckets = 1usize.checked_shl(u32::from(width))?;
            let starts = self.starts.get(starts_base..starts_base + buckets + 1)?;
            let ids = self.ids.get(ids_base..ids_base + n)?;
            let mask = (buckets - 1) as u64;
            for (rotation, &reading) in readings.iter().enumerate() {
                let value = (reading.checked_shr(shift).unwrap_or(0) & mask) as usize;
                let (Some(&lo), Some(&hi)) = (starts.get(value), starts.get(value + 1)) else {
                    continue;
                };
                let bucket = ids.get(usize::from(lo)..usize::from(hi)).unwrap_or(&[]);
                for &id in bucket {
                    let Some(&code) = codes.get(usize::from(id)) else {
                        continue;
                    };
                    let distance = (code ^ reading).count_ones();
                    if distance <= limit {
                        let key = distance << DISTANCE_SHIFT
                            | u32::from(id) << ID_SHIFT
                            | rotation as u32;
                        best = best.min(key);
                    }
                }
            }
            shift += u32::from(width);
            starts_base += buckets + 1;
            ids_base += n;
        }
        (best != u32::MAX).then_some(Decoded {
            id: (best >> ID_SHIFT) as u16,
            rotation: (best & 3) as u8,
            hamming: (best >> DISTANCE_SHIFT) as u8,
        })
    }

    /// Checks that the index serves a family of `codes` with `bits` data bits correcting
    /// `max_correction` bits: enough chunks, widths that add up to `bits`, tables of the right
    /// sizes, and in every chunk each bucket lists strictly ascending ids whose code has that
    /// bucket's chunk value. With exactly `n` entries per chunk that means every code appears
    /// once per chunk, in its own bucket, which is what makes look-ups find every near code.
    pub fn check(
        &self,
        codes: &[u64],
        bits: u8,
        max_correction: u8,
    ) -> Result<(), FamilyErrorKind> {
        const BAD: FamilyErrorKind = FamilyErrorKind::BadMultiIndex;
        let n = codes.len();
        if !self.covers(max_correction) {
            return Err(BAD);
        }
        let mut total_bits = 0u32;
        let mut total_starts = 0usize;
        for &width in self.chunk_bits {
            if !(1..=MAX_CHUNK_BITS).contains(&width) {
                return Err(BAD);
            }
            total_bits += u32::from(width);
            total_starts += (1usize << width) + 1;
        }
        let total_ids = self.chunk_bits.len().checked_mul(n).ok_or(BAD)?;
        if total_bits != u32::from(bits)
            || self.starts.len() != total_starts
            || self.ids.len() != total_ids
        {
            return Err(BAD);
        }
        let mut shift = 0u32;
        let mut starts_base = 0usize;
        let mut ids_base = 0usize;
        for &width in self.chunk_bits {
            let buckets = 1usize << width;
            let starts = self
                .starts
                .get(starts_base..starts_base + buckets + 1)
                .ok_or(BAD)?;
            let ids = self.ids.get(ids_base..ids_base + n).ok_or(BAD)?;
            if starts.first() != Some(&0) || starts.last().map(|&s| usize::from(s)) != Some(n) {
                return Err(BAD);
            }
            let mask = (buckets - 1) as u64;
            for (value, pair) in starts.windows(2).enumerate() {
                let &[lo, hi] = pair else {
                    return Err(BAD);
                };
                let bucket = ids.get(usize::from(lo)..usize::from(hi)).ok_or(BAD)?;
                let mut previous: Option<u16> = None;
                for &id in bucket {
                    let code = *codes.get(usize::from(id)).ok_or(BAD)?;
                    let in_bucket = (code.checked_shr(shift).unwrap_or(0) & mask) as usize;
                    if in_bucket != value || previous.is_some_and(|p| p >= id) {
                        return Err(BAD);
                    }
                    previous = Some(id);
                }
            }
            shift += u32::from(width);
            starts_base += buckets + 1;
            ids_base += n;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use crate::family::{tables, Family};
    use std::{vec, vec::Vec};

    /// xorshift64: deterministic test readings.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }

        /// `count` distinct bits below `bits`.
        fn flips(&mut self, bits: u8, count: u32) -> u64 {
            let mut mask = 0u64;
            while mask.count_ones() < count.min(u32::from(bits)) {
                mask |= 1u64 << (self.next() % u64::from(bits));
            }
            mask
        }
    }

    /// The same family without its multi-index: decodes with the linear scan.
    fn scanning<'a>(f: &Family<'a>) -> Family<'a> {
        Family { index: None, ..*f }
    }

    /// An index built the straightforward way (test only), for hand-made families.
    fn build(codes: &[u64], widths: &[u8]) -> (Vec<u16>, Vec<u16>) {
        let (mut starts, mut ids) = (Vec::new(), Vec::new());
        let mut shift = 0u32;
        for &w in widths {
            let value = |c: u64| ((c >> shift) & ((1u64 << w) - 1)) as usize;
            let mut order: Vec<u16> = (0..codes.len() as u16).collect();
            order.sort_by_key(|&id| (value(codes[id as usize]), id));
            let mut offset = 0u16;
            for v in 0..=(1usize << w) {
                starts.push(offset);
                offset += codes.iter().filter(|&&c| value(c) == v).count() as u16;
            }
            ids.extend(order);
            shift += u32::from(w);
        }
        (starts, ids)
    }

    /// Readings near a code (0 to max_correction + 2 flipped bits, any rotation, the other
    /// three readings the matching rotations) and readings far from every code (random).
    fn readings_for(f: &Family<'_>, rng: &mut Rng, count: usize) -> Vec<[u64; 4]> {
        let mask = if f.bits >= 64 {
            u64::MAX
        } else {
            (1u64 << f.bits) - 1
        };
        let mut out = vec![[0u64; 4], [mask; 4]];
        for i in 0..count {
            let seen = if i % 3 == 2 {
                rng.next() & mask
            } else {
                let code = f.codes[(rng.next() % f.codes.len() as u64) as usize];
                let errors = (rng.next() % (u64::from(f.max_correction) + 3)) as u32;
                f.rotate_code(code ^ rng.flips(f.bits, errors), (rng.next() & 3) as u8)
            };
            out.push([0u8, 1, 2, 3].map(|k| f.rotate_code(seen, k)));
        }
        out
    }

    /// The decode through the index returns exactly what the linear scan returns: same id,
    /// rotation and distance, for every correction limit up to the family's bound, with and
    /// without the exact-match path.
    #[test]
    fn indexed_decode_equals_the_linear_scan() {
        let names = [
            "tag36h11",
            "aruco_6x6_250",
            "tagStandard41h12",
            "aruco_7x7_250",
            "aruco_7x7_50",
            "aruco_6x6_1000",
            "tag36h10",
        ];
        let mut rng = Rng(0x2545_f491_4f6c_dd1d);
        for name in names {
            let f = tables::by_name(name).unwrap();
            assert!(f.index.is_some(), "{name} has no multi-index");
            let scan = scanning(f);
            let no_exact = Family {
                sorted_ids: &[],
                ..*f
            };
            let (mut near, mut found) = (0, 0);
            for seen in readings_for(f, &mut rng, 3000) {
                for limit in [0, 1, f.max_correction, u8::MAX] {
                    let got = f.decode(&seen, limit);
                    assert_eq!(got, scan.decode(&seen, limit), "{name} {seen:x?} {limit}");
                    assert_eq!(
                        no_exact.decode(&seen, limit),
                        scanning(&no_exact).decode(&seen, limit),
                        "{name} {seen:x?} {limit} (no exact path)"
                    );
                    if limit == f.max_correction {
                        found += usize::from(got.is_some());
                        near += usize::from(got.is_some_and(|d| d.hamming > 0));
                    }
                }
            }
            // The readings exercised both outcomes and real corrections.
            assert!(
                near > 500 && found < 3000,
                "{name}: {near} corrected, {found} found"
            );
        }
    }

    /// Ties: a hand-made family whose codes are equally far from many readings (distance
    /// guarantees ignored on purpose) still resolves them like the scan: smallest distance,
    /// then smallest id, then smallest rotation.
    #[test]
    fn ties_resolve_like_the_scan() {
        let base = tables::by_name("tag36h11").unwrap();
        // Codes two or three bits apart from each other, and rotations of one another.
        let first = base.codes[7];
        let mut codes = vec![first, first ^ 0b11, first ^ 0b101, first ^ (0b111 << 20)];
        codes.push(base.rotate_code(first, 1));
        codes.push(base.rotate_code(first ^ 0b11, 2));
        let widths = [6u8, 6, 6, 6, 6, 6];
        let (starts, ids) = build(&codes, &widths);
        let index = MultiIndex {
            chunk_bits: &widths,
            starts: &starts,
            ids: &ids,
        };
        let f = Family {
            codes: &codes,
            sorted_ids: &[],
            max_correction: 5,
            index: Some(&index),
            ..*base
        };
        assert_eq!(index.check(&codes, f.bits, f.max_correction), Ok(()));
        let mut rng = Rng(7);
        let mut ties = 0;
        for _ in 0..4000 {
            let code = codes[(rng.next() % codes.len() as u64) as usize];
            let errors = (rng.next() % 6) as u32;
            let seen = f.rotate_code(code ^ rng.flips(f.bits, errors), (rng.next() & 3) as u8);
            let readings = [0u8, 1, 2, 3].map(|k| f.rotate_code(seen, k));
            let got = f.decode(&readings, 5);
            assert_eq!(got, scanning(&f).decode(&readings, 5), "{readings:x?}");
            if let Some(d) = got {
                let at_best = codes
                    .iter()
                    .flat_map(|&c| readings.map(|r| (c ^ r).count_ones()))
                    .filter(|&x| x == u32::from(d.hamming))
                    .count();
                ties += usize::from(at_best > 1);
            }
        }
        assert!(ties > 100, "only {ties} ties");
    }

    /// The generator's tables are what a straightforward build gives for the same widths.
    #[test]
    fn generated_tables_match_a_direct_build() {
        for f in tables::ALL {
            let Some(index) = f.index else {
                continue;
            };
            let (starts, ids) = build(f.codes, index.chunk_bits);
            assert_eq!(index.starts, &starts[..], "{}", f.name);
            assert_eq!(index.ids, &ids[..], "{}", f.name);
        }
    }

    /// Families that correct bits have an index unless they are tiny, the others none.
    #[test]
    fn correcting_families_have_an_index() {
        for f in tables::ALL {
            if f.max_correction == 0 {
                assert!(f.index.is_none(), "{}", f.name);
            } else {
                let index = f.index.unwrap();
                assert!(index.covers(f.max_correction), "{}", f.name);
            }
        }
    }

    fn expect_rejected(f: &Family<'_>, starts: &[u16], ids: &[u16], widths: &[u8], what: &str) {
        let index = MultiIndex {
            chunk_bits: widths,
            starts,
            ids,
        };
        let corrupt = Family {
            index: Some(&index),
            ..*f
        };
        assert_eq!(
            corrupt.validate(),
            Err(FamilyErrorKind::BadMultiIndex),
            "{what}"
        );
    }

    #[test]
    fn a_corrupt_index_is_rejected() {
        let f = tables::by_name("tag36h11").unwrap();
        let index = f.index.unwrap();
        let widths = index.chunk_bits.to_vec();
        let n = f.codes.len();
        assert_eq!(f.validate(), Ok(()));

        // Two ids of different buckets swapped: each is now listed under the wrong value
        // (a code with its errors outside that chunk would be missed).
        let mut ids = index.ids.to_vec();
        let (a, b) = (0, n - 1);
        ids.swap(a, b);
        expect_rejected(f, index.starts, &ids, &widths, "swapped ids");

        // An id listed twice (so another is missing) in the same bucket.
        let mut ids = index.ids.to_vec();
        let bucket = index.starts[..=1 << widths[0]]
            .windows(2)
            .position(|w| w[1] - w[0] >= 2)
            .unwrap();
        let first = usize::from(index.starts[bucket]);
        ids[first + 1] = ids[first];
        expect_rejected(f, index.starts, &ids, &widths, "duplicate id");

        // An id out of range.
        let mut ids = index.ids.to_vec();
        ids[3 * n + 5] = n as u16;
        expect_rejected(f, index.starts, &ids, &widths, "id out of range");

        // Offsets that lose the last code of a chunk, and decreasing offsets.
        let mut starts = index.starts.to_vec();
        starts[1 << widths[0]] -= 1;
        expect_rejected(f, &starts, index.ids, &widths, "short chunk");
        let mut starts = index.starts.to_vec();
        let (lo, hi) = (starts[bucket], starts[bucket + 1]);
        starts[bucket] = hi;
        starts[bucket + 1] = lo;
        expect_rejected(f, &starts, index.ids, &widths, "decreasing offsets");

        // Too few chunks for the correction bound (36 bits in 2 chunks of 18 > 16 bits, and
        // in 2 chunks it could not cover 2 errors anyway), widths not adding up to the bits,
        // tables of the wrong size.
        expect_rejected(f, index.starts, index.ids, &[9, 9, 18], "too few chunks");
        expect_rejected(f, index.starts, index.ids, &[9, 9, 9, 8], "widths");
        expect_rejected(f, &index.starts[1..], index.ids, &widths, "starts size");
        expect_rejected(f, index.starts, &index.ids[1..], &widths, "ids size");
    }
}
