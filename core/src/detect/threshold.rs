//! Step 1: binarisation into a 1-bit-per-pixel bitmap.
//!
//! [`local_threshold`]: per 4x4 tile the min and max grey level, spread to the 3x3
//! neighbouring tiles (a 12x12 window), and a pixel is dark when it lies below the window's
//! mid-level. The threshold follows shadows and vignetting across the frame. Where the window
//! has less than `min_contrast` there is no edge to find, so nothing there is dark: uniform
//! areas (sky, tarmac, the inside of a big black cell) cost nothing downstream. A window whose
//! dark level is a quarter of its light one or less needs only [`DARK_MIN_CONTRAST`]: a
//! marker deep in a shadow, the camera exposed for the sun ([`has_contrast`]).
//!
//! # Across a hard shadow
//!
//! The mid-level fails where a shadow's edge crosses a marker's margin: a window holding the
//! sunlit paper (240) and the shadowed border's black (15) puts its mid-level above the
//! shadowed paper (90), so a band of shadowed white along the shadow's edge turns dark and
//! joins the border, and the marker's outline is no longer a quad. A shadow scales every level
//! under it by the same factor, so what tells paper from ink across it is the *ratio* of the
//! levels: [`ratio_threshold`] puts the threshold at the geometric mean of the same windows'
//! extrema (each raised by [`RATIO_PEDESTAL`], the sensor's black offset and flare), which
//! keeps the shadowed paper light whenever the shadow darkens less than the ink does
//! (sqrt(31 x 256) - 16 = 74 in the example). It is no better everywhere: it sits lower, so a
//! thin, blurred dark line that reaches only part of the way down (a far marker's border) can
//! stay light. The per-frame path therefore binarises the frame at the mid-level and uses the
//! ratio only where it looks again for a pad it just lost ([`super::Detector::detect_region`]),
//! a region a fraction of the frame: one pixel at a time, apart from the frame's word-wide
//! pass (sharing that pass's code, even as a second instance of it, cost the frame's pass 2 %
//! more Cortex-M7 instructions).
//!
//! From VGA up ([`MaxRows::for_frame`]) a tile's maximum comes from two of its four rows
//! (0 and 2); its minimum still from all four. The dark side decides where an outline is
//! traced: a marker's border or a thin dark edge must show its darkest pixel in every window
//! it crosses (taking both extrema from every other row, AprilTag's three test photos, 799 x
//! 533, lost 2 of their 47 markers; this way none). The light level is the white margin and
//! cells, broad areas that six of a window's twelve rows still sample. It saves a fifth of
//! the tile extrema, the largest part of a VGA frame's fixed cost (0.3 M of 1.4 M Cortex-M7
//! instructions).
//!
//! # Two ways to the same bitmap
//!
//! [`local_threshold`] works four pixels a 32-bit word in general-purpose registers (SIMD
//! within a register): the Cortex-M7 has no vector unit a compiler would use from stable
//! Rust, and it is the product. On x86-64 the compiler runs that word arithmetic four words
//! to an SSE2 vector, but a per-byte minimum still costs about eight instructions where
//! SSE2 has one (`pminub`), so 64-bit hosts run [`local_threshold_vectorised`] instead: the
//! same steps as byte loops over small arrays, which compilers turn into vector
//! instructions (the comparison with the thresholds as words again, of eight pixels), with
//! the same bitmap and the same count of compared blocks (charged to the work budget, so
//! host tools reproduce what flies; its speed-up on x86-64 is in `docs/performance.md`).
//! Which one runs is chosen by
//! `target_pointer_width` where the detector calls it; the tests hold both to the
//! pixel-by-pixel definition. The two share the partial tiles, the comparison loop (generic
//! over the kernel of a 32 x 4 block: [`dark_block`] or [`Vectorised::dark_block`]) and the
//! bottom rows; the shared loop costs the M7's frames a little more than a copy of its own
//! would, the price of one comparison loop instead of two.
//!
//! Bitmap layout: row `y` starts at word `y * words_per_row(width)`; pixel `x` is bit `x % 32`
//! of word `x / 32` (least significant bit = leftmost pixel), so "left neighbour" is a shift.

use super::TILE;
use crate::image::GrayImage;

/// Words per bitmap row.
#[inline]
pub(crate) fn words_per_row(width: usize) -> usize {
    width.div_ceil(32)
}

/// Reads bit (x, y) of a bitmap; outside the image reads as 0.
#[cfg(test)]
pub(crate) fn get_bit(
    bitmap: &[u32],
    wpr: usize,
    x: isize,
    y: isize,
    width: usize,
    height: usize,
) -> bool {
    if x < 0 || y < 0 || x as usize >= width || y as usize >= height {
        return false;
    }
    let (x, y) = (x as usize, y as usize);
    bitmap
        .get(y * wpr + x / 32)
        .is_some_and(|w| (w >> (x % 32)) & 1 == 1)
}

/// Sets bit (x, y) (coordinates must be inside the image).
#[inline]
pub(crate) fn set_bit(bitmap: &mut [u32], wpr: usize, x: usize, y: usize) {
    if let Some(w) = bitmap.get_mut(y * wpr + x / 32) {
        *w |= 1 << (x % 32);
    }
}

/// Top bit of every byte.
const HIGH: u32 = 0x8080_8080;
/// Low seven bits of every byte.
const LOW7: u32 = 0x7F7F_7F7F;

/// Per byte of two words of four bytes: bit 7 set where the byte of `a` >= that of `b`,
/// every other bit clear.
///
/// Four comparisons in one 32-bit word (SIMD within a register), because the Cortex-M7 has
/// no byte-vector compare a compiler would use from stable Rust (its DSP instructions need
/// `asm!`). Per byte, `a >= b` exactly when `a + !b >= 255`, that is when the rounded-up
/// mean of `a` and `!b` is at least 128. That mean is `(a | !b) - ((a ^ !b) >> 1)`, a
/// subtraction that cannot borrow (the first term is never the smaller) and a shift whose
/// bits crossing into the next byte are masked off. `a ^ !b` is written `!(a ^ b)` because
/// the callers that select with the result need `a ^ b` anyway: with it, four instructions
/// for four bytes (`orn`, `bic` with a shifted operand, `sub`, `and`).
#[inline(always)]
fn bytes_ge(a: u32, b: u32) -> u32 {
    let differ = a ^ b;
    (a | !b).wrapping_sub(!(differ >> 1) & LOW7) & HIGH
}

/// 0xFF in every byte where the byte of `a` >= that of `b` ([`bytes_ge`]), 0 elsewhere.
#[inline(always)]
fn ge_mask(a: u32, b: u32) -> u32 {
    // Each byte's flag (bit 7) moved to bit 0, times 0xFF: no byte carries into the next.
    (bytes_ge(a, b) >> 7).wrapping_mul(0xFF)
}

/// Per-byte minimum and maximum of two words of four pixels (SIMD within a register, as
/// [`bytes_ge`]): one per-byte comparison, spread to a byte mask, selects either way.
#[inline(always)]
fn byte_min_max(a: u32, b: u32) -> (u32, u32) {
    // Where a >= b, the minimum is b = a ^ (a ^ b) and the maximum a = b ^ (a ^ b).
    let swap = (a ^ b) & ge_mask(a, b);
    (a ^ swap, b ^ swap)
}

/// Per-byte minimum of two words of four bytes ([`byte_min_max`]).
#[inline(always)]
fn byte_min(a: u32, b: u32) -> u32 {
    a ^ ((a ^ b) & ge_mask(a, b))
}

/// Per-byte maximum of two words of four bytes ([`byte_min_max`]).
#[inline(always)]
fn byte_max(a: u32, b: u32) -> u32 {
    b ^ ((a ^ b) & ge_mask(a, b))
}

/// The smallest byte of `mins` and the largest of `maxs`.
///
/// Both in the same two per-byte minima ([`byte_min`]): the maximum of the bytes is the
/// complement of the minimum of their complements, so the low halves of `mins` and of
/// `!maxs` are packed in one word, the high halves in another, and two halvings leave the
/// minimum in byte 0 and the complemented maximum in byte 2. Fewer instructions than six
/// byte extractions and comparisons.
#[inline(always)]
fn word_min_max(mins: u32, maxs: u32) -> (u8, u8) {
    let not_maxs = !maxs;
    let low_halves = (mins & 0xFFFF) | (not_maxs << 16);
    let high_halves = (mins >> 16) | (not_maxs & 0xFFFF_0000);
    let pairs = byte_min(low_halves, high_halves);
    let single = byte_min(pairs, pairs >> 8);
    (single as u8, !(single >> 16) as u8)
}

/// [`word_min_max`] before the extraction: the smallest byte of `mins` in byte 0, the
/// complement of the largest of `maxs` in byte 2.
#[inline(always)]
fn packed_min_max(mins: u32, maxs: u32) -> u32 {
    let not_maxs = !maxs;
    let low_halves = (mins & 0xFFFF) | (not_maxs << 16);
    let high_halves = (mins >> 16) | (not_maxs & 0xFFFF_0000);
    let pairs = byte_min(low_halves, high_halves);
    byte_min(pairs, pairs >> 8)
}

/// The contrast a window needs where its darkest level is at most a quarter of its
/// lightest (see [`has_contrast`]).
const DARK_MIN_CONTRAST: u8 = 12;

/// Whether a window whose extrema are `lo` and `hi` has an edge to find: a contrast of
/// `min_contrast`, or of [`DARK_MIN_CONTRAST`] where `lo` is at most a quarter of `hi`.
///
/// A marker in a deep shadow, the camera exposed for the sunlit ground beside it, is ink of
/// a few grey levels on paper of some twenty: every level scaled down by the shadow, its
/// contrast near `min_contrast`, so that windows along its outline fall below it and the
/// outline breaks. Lowering `min_contrast` itself lets the fainter texture of sunlit ground
/// (grass, gravel) through, and its contours spend the work budget before the markers are
/// reached (docs/accuracy.md, "Hard stills"). What tells the shadowed marker from texture
/// is the ratio: ink against paper is dark against light whatever the light, a texture's
/// levels differ by tens of percent. So a window as dark against its light as ink is, a quarter or
/// less, needs only the lower contrast, which the noise of a dark frame (a few levels)
/// does not reach.
#[inline(always)]
fn has_contrast(lo: u8, hi: u8, min_contrast: u8) -> bool {
    let contrast = hi.saturating_sub(lo);
    contrast >= min_contrast || (contrast >= DARK_MIN_CONTRAST && lo <= hi >> 2)
}

/// The threshold of one window with extrema `lo` and `hi`: the rounded-up mid-level, or 0
/// where it has no contrast ([`has_contrast`]); [`tile_thresholds`] for a byte.
#[inline(always)]
fn mid_threshold(lo: u8, hi: u8, min_contrast: u8) -> u8 {
    // The mid-level first, then a select: the vectorised pass's loops stay branch-free.
    let mid = (u16::from(lo) + u16::from(hi)).div_ceil(2) as u8;
    if has_contrast(lo, hi, min_contrast) {
        mid
    } else {
        0
    }
}

/// Per-byte threshold of four tiles from the minima `lo` and maxima `hi` of their windows
/// (every byte of `hi` >= that of `lo`): the rounded-up mid-level, or 0 where the window
/// has no contrast ([`has_contrast`]; `min_contrast` is its byte repeated in every byte).
#[inline(always)]
fn tile_thresholds(lo: u32, hi: u32, min_contrast: u32) -> u32 {
    const DARK: u32 = DARK_MIN_CONTRAST as u32 * 0x0101_0101;
    const LOW6: u32 = 0x3F3F_3F3F;
    // hi - lo cannot borrow across bytes (no byte of hi is below lo's).
    let contrast = hi.wrapping_sub(lo);
    // The three comparisons' flags (bit 7) combined first, spread to a mask once.
    let dark = bytes_ge(contrast, DARK) & bytes_ge((hi >> 2) & LOW6, lo);
    let enough = ((bytes_ge(contrast, min_contrast) | dark) >> 7).wrapping_mul(0xFF);
    // ceil((lo + hi) / 2) = (lo | hi) - ((lo ^ hi) >> 1), per byte without borrows.
    let mid = (lo | hi).wrapping_sub(((lo ^ hi) >> 1) & LOW7);
    mid & enough
}

/// The tile grid of a `w` x `h` image: its width and height in tiles and the two grids
/// (minima, maxima) cut from `tiles`; `None` when `tiles` is too short or the image empty.
#[inline(always)]
fn tile_grids(
    w: usize,
    h: usize,
    tiles: &mut [u8],
) -> Option<(usize, usize, &mut [u8], &mut [u8])> {
    let (tw, th) = (w.div_ceil(TILE), h.div_ceil(TILE));
    let n = tw * th;
    let (tmin, rest) = tiles.split_at_mut_checked(n)?;
    let tmax = rest.get_mut(..n)?;
    (tw > 0).then_some((tw, th, tmin, tmax))
}

/// Which rows of a tile its maximum is taken over (its minimum: always all four).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum MaxRows {
    /// All four.
    All,
    /// Rows 0 and 2 (see the module docs).
    EveryOther,
}

/// Frames of at least this many pixels (VGA) take their tile maxima from every other row.
const EVERY_OTHER_ROW_FROM_PIXELS: usize = 640 * 480;

impl MaxRows {
    /// The rows for a `width` x `height` frame: [`MaxRows::EveryOther`] from VGA up, where
    /// the tile extrema are a third of a landing frame's cost on the Cortex-M7;
    /// [`MaxRows::All`] below, where they are cheap enough.
    pub(crate) fn for_frame(width: usize, height: usize) -> Self {
        if width.saturating_mul(height) >= EVERY_OTHER_ROW_FROM_PIXELS {
            MaxRows::EveryOther
        } else {
            MaxRows::All
        }
    }
}

/// Binarises `image` into `bitmap` (dark = 1) with a tile-local threshold, the tile maxima
/// taken over `max_rows`. `tiles` holds at least `2 * ceil(w/4) * ceil(h/4)` bytes. Four
/// pixels a 32-bit word: the Cortex-M7's way (64-bit hosts run
/// [`local_threshold_vectorised`], see the module docs).
///
/// Returns the blocks of 32 x 4 pixels that had a tile with contrast: their pixels were
/// compared, where a block of flat tiles is written without being read. That part of the
/// cost depends on the image (all of a frame of noise, a fifth of a landing frame), so the
/// detector charges it to the frame's work budget ([`super::WORK_THRESHOLD_BLOCK`]); the
/// rest (the tile extrema) is the same for every frame of a size.
pub(crate) fn local_threshold(
    image: &GrayImage<'_>,
    min_contrast: u8,
    max_rows: MaxRows,
    bitmap: &mut [u32],
    tiles: &mut [u8],
) -> u32 {
    let (w, h) = (image.width(), image.height());
    let Some((tw, th, tmin, tmax)) = tile_grids(w, h, tiles) else {
        return 0;
    };
    // Tile extrema, one tile row at a time: a tile's four rows are four 32-bit words, which
    // are reduced to a per-byte min and max word in registers (SWAR, see `byte_min_max`),
    // then to the tile's min and max byte.
    for (ty, (mins, maxs)) in tmin
        .chunks_exact_mut(tw)
        .zip(tmax.chunks_exact_mut(tw))
        .enumerate()
    {
        let rows = tile_row_pixels(image, ty);
        let [r0, r1, r2, r3] = rows;
        let word = |q: &[u8]| match *q {
            [p0, p1, p2, p3] => u32::from_le_bytes([p0, p1, p2, p3]),
            _ => 0,
        };
        let per_tile = r0
            .chunks_exact(TILE)
            .zip(r1.chunks_exact(TILE))
            .zip(r2.chunks_exact(TILE).zip(r3.chunks_exact(TILE)))
            .zip(mins.iter_mut().zip(maxs.iter_mut()));
        match max_rows {
            MaxRows::All => {
                for (((a, b), (c, d)), (lo, hi)) in per_tile {
                    let (mn01, mx01) = byte_min_max(word(a), word(b));
                    let (mn23, mx23) = byte_min_max(word(c), word(d));
                    let (lo4, hi4) = (byte_min(mn01, mn23), byte_max(mx01, mx23));
                    (*lo, *hi) = word_min_max(lo4, hi4);
                }
            }
            MaxRows::EveryOther => {
                // The minimum of all four rows, the maximum of rows 0 and 2.
                for (((a, b), (c, d)), (lo, hi)) in per_tile {
                    let (mn02, mx02) = byte_min_max(word(a), word(c));
                    let lo4 = byte_min(byte_min(mn02, word(b)), word(d));
                    (*lo, *hi) = word_min_max(lo4, mx02);
                }
            }
        }
        partial_tile_extrema(rows, w, mins, maxs);
        spread_along(mins, byte_min, u8::min);
        spread_along(maxs, byte_max, u8::max);
    }
    // Spread over the 3x3 tile neighbourhood, in place: the horizontal pass was done per
    // tile row above; the vertical one also turns the window's extrema into thresholds (flat
    // tiles get 0, so no pixel there is dark).
    spread_down_to_thresholds(tmin, tmax, tw, th, min_contrast);
    compare_with_thresholds(image, tmin, tw, bitmap, dark_block)
}

/// The four pixel rows of tile row `ty`. The last tile row may be short: its last row
/// stands in for the missing ones, which leaves its tiles' minima and maxima as they are.
#[inline(always)]
fn tile_row_pixels<'i>(image: &GrayImage<'i>, ty: usize) -> [&'i [u8]; 4] {
    let y0 = ty * TILE;
    let last = image.height().saturating_sub(1);
    [
        image.row(y0),
        image.row((y0 + 1).min(last)),
        image.row((y0 + 2).min(last)),
        image.row((y0 + 3).min(last)),
    ]
}

/// The extrema of the partial tile at the end of a tile row (`rows`, its four pixel rows;
/// width `w` not a multiple of the tile) into the last bytes of `mins` and `maxs`: all its
/// rows for both, whatever [`MaxRows`] (the few pixels cost little).
#[inline(always)]
fn partial_tile_extrema(rows: [&[u8]; 4], w: usize, mins: &mut [u8], maxs: &mut [u8]) {
    let start = (w / TILE) * TILE;
    if start < w {
        let (mut mn, mut mx) = (255u8, 0u8);
        for row in rows {
            for &p in row.get(start..).unwrap_or(&[]) {
                mn = mn.min(p);
                mx = mx.max(p);
            }
        }
        if let (Some(lo), Some(hi)) = (mins.last_mut(), maxs.last_mut()) {
            *lo = mn;
            *hi = mx;
        }
    }
}

/// The bitmap of `image` against the per-tile thresholds `tmin` (`tw` a row): a pixel is
/// dark where it is below its tile's threshold. Returns the blocks of 32 x 4 pixels whose
/// pixels were compared (those with a tile of contrast; a partial tile row at the bottom
/// counts as blocks of 32 x 1).
///
/// A tile row's four pixel rows at once, 32 pixels (a bitmap word, eight tiles) a row at a
/// time: the eight thresholds are read once for the four rows, and where all eight are 0
/// (flat tiles) no pixel can be dark and the pixels are not even read; elsewhere
/// `dark_block` compares the block's four rows with them ([`dark_block`] on the Cortex-M7,
/// [`Vectorised::dark_block`] on 64-bit hosts). Partial words and a partial tile row at the
/// end, one row and one pixel at a time ([`compare_bottom_rows`]).
#[inline(always)]
fn compare_with_thresholds(
    image: &GrayImage<'_>,
    tmin: &[u8],
    tw: usize,
    bitmap: &mut [u32],
    dark_block: impl Fn([&[u8]; 4], u64) -> [u32; 4],
) -> u32 {
    let (w, h) = (image.width(), image.height());
    let mut compared = 0u32;
    let wpr = words_per_row(w).max(1);
    let full = w / 32;
    let whole_tile_rows = h / TILE;
    let groups = bitmap
        .chunks_exact_mut(TILE * wpr)
        .zip(tmin.chunks_exact(tw.max(1)))
        .take(whole_tile_rows)
        .enumerate();
    for (ty, (out, thresholds)) in groups {
        let y0 = ty * TILE;
        let rows = [
            image.row(y0),
            image.row(y0 + 1),
            image.row(y0 + 2),
            image.row(y0 + 3),
        ];
        let Some([o0, o1, o2, o3]) = four_rows(out, wpr) else {
            return compared;
        };
        let [r0, r1, r2, r3] = rows;
        let columns = thresholds
            .chunks_exact(32 / TILE)
            .zip(r0.chunks_exact(32).zip(r1.chunks_exact(32)))
            .zip(r2.chunks_exact(32).zip(r3.chunks_exact(32)))
            .zip(o0.iter_mut().zip(o1.iter_mut()))
            .zip(o2.iter_mut().zip(o3.iter_mut()));
        for ((((eight, (p0, p1)), (p2, p3)), (w0, w1)), (w2, w3)) in columns {
            let eight = <[u8; 8]>::try_from(eight).map_or(0, u64::from_le_bytes);
            if eight == 0 {
                (*w0, *w1, *w2, *w3) = (0, 0, 0, 0);
                continue;
            }
            compared += 1;
            [*w0, *w1, *w2, *w3] = dark_block([p0, p1, p2, p3], eight);
        }
        for (row, out) in rows.into_iter().zip([o0, o1, o2, o3]) {
            partial_word(row, thresholds, full, out);
        }
    }
    compare_bottom_rows(image, tmin, tw, bitmap, compared)
}

/// The first four rows of `wpr` words of `out` (a tile row of the bitmap).
#[inline(always)]
fn four_rows(out: &mut [u32], wpr: usize) -> Option<[&mut [u32]; 4]> {
    let (o0, rest) = out.split_at_mut_checked(wpr)?;
    let (o1, rest) = rest.split_at_mut_checked(wpr)?;
    let (o2, o3) = rest.split_at_mut_checked(wpr)?;
    Some([o0, o1, o2, o3])
}

/// The rows of a partial tile row at the bottom of the bitmap, one row and 32 pixels at a
/// time ([`dark_bits`]), for both ways of comparing; returns `compared` plus the words
/// compared (each a block of its own).
#[inline(always)]
fn compare_bottom_rows(
    image: &GrayImage<'_>,
    tmin: &[u8],
    tw: usize,
    bitmap: &mut [u32],
    mut compared: u32,
) -> u32 {
    let (w, h) = (image.width(), image.height());
    let wpr = words_per_row(w).max(1);
    let full = w / 32;
    for y in h / TILE * TILE..h {
        let row = image.row(y);
        let thresholds = tmin
            .get((y / TILE) * tw..(y / TILE) * tw + tw)
            .unwrap_or(&[]);
        let Some(out) = bitmap.get_mut(y * wpr..y * wpr + wpr) else {
            return compared;
        };
        let words = row
            .chunks_exact(32)
            .zip(thresholds.chunks_exact(32 / TILE))
            .zip(out.iter_mut());
        for ((pixels, eight), word) in words {
            let eight = <[u8; 8]>::try_from(eight).map_or(0, u64::from_le_bytes);
            compared += u32::from(eight != 0);
            *word = dark_bits(pixels, &spread_thresholds(eight));
        }
        partial_word(row, thresholds, full, out);
    }
    compared
}

/// The bitmap words of a block of 32 x 4 pixels (`rows`, 32 pixels each) against the
/// thresholds of its eight tiles (one a byte of `eight`), four pixels a 32-bit word: each
/// threshold spread to a word once for the four rows ([`spread_thresholds`]), each row's
/// tiles compared by [`dark_bits`].
#[inline(always)]
fn dark_block(rows: [&[u8]; 4], eight: u64) -> [u32; 4] {
    let spread = spread_thresholds(eight);
    let [p0, p1, p2, p3] = rows;
    [
        dark_bits(p0, &spread),
        dark_bits(p1, &spread),
        dark_bits(p2, &spread),
        dark_bits(p3, &spread),
    ]
}

/// Eight tiles' thresholds (one a byte of `eight`), each in the four bytes of a word.
#[inline(always)]
fn spread_thresholds(eight: u64) -> [u32; 8] {
    core::array::from_fn(|i| u32::from((eight >> (8 * i)) as u8) * 0x0101_0101)
}

/// Per byte of two words of four bytes: bit 7 set where the byte of `a` < that of `b`,
/// every other bit clear.
///
/// Four comparisons in one 32-bit word (SIMD within a register), because the Cortex-M7 has
/// no byte-vector compare a compiler would use from stable Rust (its DSP instructions need
/// `asm!`). Per byte, `a < b` exactly when `!a + b >= 256`, that is when the rounded-down
/// mean of `!a` and `b` is at least 128. That mean is `(!a & b) + ((!a ^ b) >> 1)`, an
/// addition that cannot carry out of a byte and a shift whose bits crossing into the next
/// byte are masked off: four instructions (`eor`, `bic`, `bic` with a shifted operand,
/// `add`), and the mask of bit 7 goes with the caller's next shift.
#[inline(always)]
fn bytes_lt(a: u32, b: u32) -> u32 {
    (b & !a).wrapping_add(!((a ^ b) >> 1) & LOW7) & HIGH
}

/// The bitmap word of 32 pixels (`pixels`, eight tiles of four) against their tiles'
/// thresholds (`spread`, [`spread_thresholds`]): bit `i` set where pixel `i` is below its
/// tile's threshold (0 for a slice that is not 32 pixels).
///
/// Per tile [`bytes_lt`] on its four pixels as a word; then per two tiles one
/// multiplication gathers the eight flags: the first tile's flags moved to bits 0, 8, 16, 24
/// and the second's to 4, 12, 20, 28, the multiplier `1 + 2^7 + 2^14 + 2^21` moves them to
/// bits 21 to 28 in pixel order, and no two of the partial products (a flag bit plus a
/// multiple of 7 up to 21) share a bit, so nothing carries into that window.
#[inline(always)]
fn dark_bits(pixels: &[u8], spread: &[u32; 8]) -> u32 {
    let Ok(pixels) = <&[u8; 32]>::try_from(pixels) else {
        return 0;
    };
    let (tiles, _) = pixels.as_chunks::<TILE>();
    let mut bits = 0;
    for (pair, (tiles, spread)) in tiles
        .chunks_exact(2)
        .zip(spread.chunks_exact(2))
        .enumerate()
    {
        if let ([first, second], [first_threshold, second_threshold]) = (tiles, spread) {
            let first = bytes_lt(u32::from_le_bytes(*first), *first_threshold);
            let second = bytes_lt(u32::from_le_bytes(*second), *second_threshold);
            let flags = ((first >> 7) & 0x0101_0101) | ((second >> 3) & 0x1010_1010);
            bits |= ((flags.wrapping_mul(0x0020_4081) >> 21) & 0xFF) << (8 * pair);
        }
    }
    bits
}

/// The partial word at the end of a row (`full` whole words before it), if any, one pixel
/// at a time.
#[inline(always)]
fn partial_word(row: &[u8], thresholds: &[u8], full: usize, out: &mut [u32]) {
    if let Some(word) = out.get_mut(full) {
        let start = full * 32;
        let mut bits = 0u32;
        for (i, &p) in row.get(start..).unwrap_or(&[]).iter().enumerate() {
            let t = thresholds.get((start + i) / TILE).copied().unwrap_or(0);
            bits |= ((p < t) as u32) << i;
        }
        *word = bits;
    }
}

/// [`local_threshold`] on arrays of pixels, a byte each, in element-by-element loops that
/// compilers turn into vector instructions: for 64-bit hosts, whose architectures all have
/// a vector unit (SSE2 on x86-64, NEON on aarch64). A byte minimum, maximum or average is
/// one instruction for 16 pixels there (`pminub`, `pmaxub`, `pavgb`), where the word
/// arithmetic of [`local_threshold`] takes about eight for four. The same steps and results (the
/// tests hold both to the definition); the comparison, whose flags need gathering into bits,
/// is SWAR again, eight pixels a 64-bit word ([`Vectorised::dark_block`]). On the Cortex-M7
/// this way would be slower: its arrays go through memory.
pub(crate) fn local_threshold_vectorised(
    image: &GrayImage<'_>,
    min_contrast: u8,
    max_rows: MaxRows,
    bitmap: &mut [u32],
    tiles: &mut [u8],
) -> u32 {
    let (w, h) = (image.width(), image.height());
    let Some((tw, th, tmin, tmax)) = tile_grids(w, h, tiles) else {
        return 0;
    };
    for (ty, (mins, maxs)) in tmin
        .chunks_exact_mut(tw)
        .zip(tmax.chunks_exact_mut(tw))
        .enumerate()
    {
        let rows = tile_row_pixels(image, ty);
        Vectorised::tile_row_extrema(rows, mins, maxs, max_rows);
        partial_tile_extrema(rows, w, mins, maxs);
        spread_along(mins, byte_min, u8::min);
        spread_along(maxs, byte_max, u8::max);
    }
    Vectorised::spread_down_to_thresholds(tmin, tmax, tw, th, min_contrast);
    compare_with_thresholds(image, tmin, tw, bitmap, Vectorised::dark_block)
}

/// The steps of [`local_threshold_vectorised`].
struct Vectorised;

/// Pixels of a row that [`Vectorised`] takes at a time: 16 tiles, four 16-byte vectors.
const VECTOR_CHUNK: usize = 64;

impl Vectorised {
    /// The extrema of a tile row's tiles (`rows`, its four pixel rows) into `mins` and
    /// `maxs`, the maxima over `max_rows` ([`Vectorised::chunk_extrema`], 64 pixels at a
    /// time). The pixels after the last whole chunk are padded to one by repeating each row's
    /// last pixel, which leaves the extrema of the tiles they fill as they are. (A partial
    /// tile's maximum comes out over `max_rows` too; the caller replaces it.)
    #[inline(always)]
    fn tile_row_extrema(rows: [&[u8]; 4], mins: &mut [u8], maxs: &mut [u8], max_rows: MaxRows) {
        const TILES: usize = VECTOR_CHUNK / TILE;
        let [r0, r1, r2, r3] = rows;
        let chunks = r0
            .as_chunks::<VECTOR_CHUNK>()
            .0
            .iter()
            .zip(r1.as_chunks::<VECTOR_CHUNK>().0)
            .zip(
                r2.as_chunks::<VECTOR_CHUNK>()
                    .0
                    .iter()
                    .zip(r3.as_chunks().0),
            )
            .zip(mins.chunks_mut(TILES).zip(maxs.chunks_mut(TILES)));
        for (((a, b), (c, d)), (lows, highs)) in chunks {
            Self::chunk_extrema([a, b, c, d], lows, highs, max_rows);
        }
        let done = r0.len() / VECTOR_CHUNK * VECTOR_CHUNK;
        if done < r0.len() {
            let padded = |row: &[u8]| {
                let rest = row.get(done..).unwrap_or(&[]);
                let mut chunk = [rest.last().copied().unwrap_or(0); VECTOR_CHUNK];
                for (cell, &p) in chunk.iter_mut().zip(rest) {
                    *cell = p;
                }
                chunk
            };
            let [a, b, c, d] = [padded(r0), padded(r1), padded(r2), padded(r3)];
            let first = done / TILE;
            if let (Some(lows), Some(highs)) = (mins.get_mut(first..), maxs.get_mut(first..)) {
                Self::chunk_extrema([&a, &b, &c, &d], lows, highs, max_rows);
            }
        }
    }

    /// The extrema of the 16 tiles of 64 pixels of four rows into the first 16 (or fewer)
    /// bytes of `lows` and `highs`: per pixel column the minimum and maximum of the rows (a
    /// byte loop: `pminub`, `pmaxub`), then per tile the extrema of its four columns, the word
    /// arithmetic of the Cortex-M7's way ([`packed_min_max`]) on 16 words, four to a vector.
    #[inline(always)]
    fn chunk_extrema(
        rows: [&[u8; VECTOR_CHUNK]; 4],
        lows: &mut [u8],
        highs: &mut [u8],
        max_rows: MaxRows,
    ) {
        let [a, b, c, d] = rows;
        let (mut low, mut high) = ([0u8; VECTOR_CHUNK], [0u8; VECTOR_CHUNK]);
        let columns = low
            .iter_mut()
            .zip(high.iter_mut())
            .zip(a.iter().zip(b))
            .zip(c.iter().zip(d));
        match max_rows {
            MaxRows::All => {
                for (((lo, hi), (&a, &b)), (&c, &d)) in columns {
                    *lo = a.min(b).min(c.min(d));
                    *hi = a.max(b).max(c.max(d));
                }
            }
            MaxRows::EveryOther => {
                for (((lo, hi), (&a, &b)), (&c, &d)) in columns {
                    *lo = a.min(b).min(c.min(d));
                    *hi = a.max(c);
                }
            }
        }
        let mut packed = [0u32; VECTOR_CHUNK / TILE];
        let tiles = low.chunks_exact(TILE).zip(high.chunks_exact(TILE));
        for (extrema, (lo4, hi4)) in packed.iter_mut().zip(tiles) {
            *extrema = packed_min_max(word(lo4), word(hi4));
        }
        for ((lo, hi), extrema) in lows.iter_mut().zip(highs.iter_mut()).zip(packed) {
            (*lo, *hi) = (extrema as u8, !(extrema >> 16) as u8);
        }
    }

    /// [`spread_down_to_thresholds`]'s two passes as byte loops along the rows: per tile a
    /// `pminub` or `pmaxub`, and the threshold a `pavgb` (the rounded-up mean) kept where a
    /// saturating difference reaches `min_contrast`.
    fn spread_down_to_thresholds(
        tmin: &mut [u8],
        tmax: &mut [u8],
        tw: usize,
        th: usize,
        min_contrast: u8,
    ) {
        if tw == 0 {
            return;
        }
        for y in 1..th {
            pair_byte_rows(tmin, tw, y, u8::min);
            pair_byte_rows(tmax, tw, y, u8::max);
        }
        let threshold = |lo: u8, hi: u8| mid_threshold(lo, hi, min_contrast);
        for y in (0..th).rev() {
            // Row y (a pair) and the pair above it; the top row's window is its own pair.
            let (Some((above_lo, row_lo)), Some((above_hi, row_hi))) = (
                tmin.split_at_mut_checked(y * tw),
                tmax.split_at_checked(y * tw),
            ) else {
                return;
            };
            let (Some(row_lo), Some(row_hi)) = (row_lo.get_mut(..tw), row_hi.get(..tw)) else {
                return;
            };
            let up_lo = above_lo.get(above_lo.len().saturating_sub(tw)..);
            let up_hi = above_hi.get(above_hi.len().saturating_sub(tw)..);
            match (up_lo, up_hi) {
                (Some(up_lo), Some(up_hi)) if y > 0 => {
                    let ins = row_hi.iter().zip(up_lo.iter().zip(up_hi));
                    for (cell, (&hi, (&up_lo, &up_hi))) in row_lo.iter_mut().zip(ins) {
                        *cell = threshold((*cell).min(up_lo), hi.max(up_hi));
                    }
                }
                _ => {
                    for (cell, &hi) in row_lo.iter_mut().zip(row_hi) {
                        *cell = threshold(*cell, hi);
                    }
                }
            }
        }
    }

    /// The bitmap words of a block of 32 x 4 pixels (`rows`, 32 pixels each) against the
    /// thresholds of its eight tiles (one a byte of `eight`): bit `i` of word `r` set where
    /// pixel `i` of row `r` is below its tile's threshold. Two tiles (eight pixels) a
    /// 64-bit word: [`bytes_lt`]'s arithmetic at twice the width, and one
    /// multiplication gathers a word's eight flags. The multiplier `2^7 + 2^14 + .. + 2^56`
    /// moves flag `k` (bit `8k`, once shifted down from bit 7) to bit `56 + k`, and no two
    /// of the partial products (bit `8j + 56 - 7k`) share a bit, so nothing carries into the
    /// top byte. (As a byte loop the comparisons would be two vector instructions a row, but
    /// gathering their flags into bits needs `pmovmskb`, which compilers do not reliably
    /// emit from plain code: as bytes, they were slower than this.)
    #[inline(always)]
    fn dark_block(rows: [&[u8]; 4], eight: u64) -> [u32; 4] {
        let [t0, t1, t2, t3, t4, t5, t6, t7] = eight.to_le_bytes();
        let spread = [[t0, t1], [t2, t3], [t4, t5], [t6, t7]]
            .map(|[a, b]| u64::from_le_bytes([a, a, a, a, b, b, b, b]));
        let row_bits = |row: &[u8]| {
            let Ok(row) = <&[u8; 32]>::try_from(row) else {
                return 0;
            };
            let (pairs, _) = row.as_chunks::<8>();
            let mut bits = 0;
            for ((pair, threshold), k) in pairs.iter().zip(spread).zip(0..) {
                let flags = bytes_lt64(u64::from_le_bytes(*pair), threshold) >> 7;
                bits |= ((flags.wrapping_mul(0x0102_0408_1020_4080) >> 56) as u32) << (8 * k);
            }
            bits
        };
        // (Not `rows.map`: the compiler leaves that a call.)
        let [r0, r1, r2, r3] = rows;
        [row_bits(r0), row_bits(r1), row_bits(r2), row_bits(r3)]
    }
}

/// [`bytes_lt`] on eight bytes.
#[inline(always)]
fn bytes_lt64(a: u64, b: u64) -> u64 {
    const HIGH64: u64 = 0x8080_8080_8080_8080;
    const LOW7_64: u64 = 0x7F7F_7F7F_7F7F_7F7F;
    (b & !a).wrapping_add(!((a ^ b) >> 1) & LOW7_64) & HIGH64
}

/// Row `y - 1` of a `tw`-wide `grid` becomes the per-byte `pick` of itself and row `y`, a
/// byte at a time ([`pick_bytes`]).
#[inline(always)]
fn pair_byte_rows(grid: &mut [u8], tw: usize, y: usize, pick: impl Fn(u8, u8) -> u8) {
    let Some((head, rest)) = grid.split_at_mut_checked(y * tw) else {
        return;
    };
    let upper = head.get_mut(y.saturating_sub(1) * tw..);
    if let (Some(upper), Some(lower), true) = (upper, rest.get(..tw), y > 0) {
        pick_bytes(upper, lower, pick);
    }
}

/// `into` becomes the per-byte `pick` of itself and `from`. Not inlined: as a function of
/// its own the two slices are known not to overlap, and the loop is vectorised (inlined into
/// the rows' loop, it stayed a byte at a time).
#[inline(never)]
fn pick_bytes(into: &mut [u8], from: &[u8], pick: impl Fn(u8, u8) -> u8) {
    for (cell, &other) in into.iter_mut().zip(from) {
        *cell = pick(*cell, other);
    }
}

/// Grey levels added to a window's extrema before their geometric mean
/// ([`ratio_threshold`]): what a sensor reads for no light at all (its black offset and the
/// lens's flare) is not scaled by a shadow, and without it a window whose darkest pixel reads
/// 0 would put the threshold at 0 and nothing would be dark.
const RATIO_PEDESTAL: u32 = 16;

/// The threshold of one window at the ratio of its extrema: `ceil(sqrt((lo + P)(hi + P))) - P`
/// (`P` = [`RATIO_PEDESTAL`]), between `lo` and `hi` like the mid-level, below it.
fn ratio_level(lo: u8, hi: u8) -> u8 {
    let product = (u32::from(lo) + RATIO_PEDESTAL) * (u32::from(hi) + RATIO_PEDESTAL);
    let root = product.isqrt();
    let root = if root * root < product {
        root + 1
    } else {
        root
    };
    root.saturating_sub(RATIO_PEDESTAL).min(255) as u8
}

/// Binarises `image` into `bitmap` (dark = 1) as [`local_threshold`] does (the same tiles,
/// windows and `min_contrast`, every row of a tile), but with the threshold at the ratio of
/// the window's extrema ([`ratio_level`], see the module docs). `tiles` holds at least
/// `2 * ceil(w/4) * ceil(h/4)` bytes.
pub(crate) fn ratio_threshold(
    image: &GrayImage<'_>,
    min_contrast: u8,
    bitmap: &mut [u32],
    tiles: &mut [u8],
) {
    let (w, h) = (image.width(), image.height());
    let Some((tw, th, tmin, tmax)) = tile_grids(w, h, tiles) else {
        return;
    };
    // Each tile's extrema, then along the tile rows.
    tmin.fill(u8::MAX);
    tmax.fill(0);
    for y in 0..h {
        let tiles = (y / TILE) * tw..(y / TILE + 1) * tw;
        let (Some(lows), Some(highs)) = (tmin.get_mut(tiles.clone()), tmax.get_mut(tiles)) else {
            return;
        };
        for (x, &p) in image.row(y).iter().enumerate() {
            if let (Some(lo), Some(hi)) = (lows.get_mut(x / TILE), highs.get_mut(x / TILE)) {
                *lo = (*lo).min(p);
                *hi = (*hi).max(p);
            }
        }
    }
    for (lows, highs) in tmin.chunks_exact_mut(tw).zip(tmax.chunks_exact_mut(tw)) {
        spread_along(lows, byte_min, u8::min);
        spread_along(highs, byte_max, u8::max);
    }
    // Down the columns: each row becomes the extreme of itself and the row below, then
    // (bottom up, so that the row above is still a pair) of its pair and the pair above,
    // which is the 3x3 window, and turns into its threshold in `tmin`.
    for y in 1..th {
        pair_rows(tmin, tw, y, byte_min, u8::min);
        pair_rows(tmax, tw, y, byte_max, u8::max);
    }
    for y in (0..th).rev() {
        // The top row's window is its own pair.
        let above = y.saturating_sub(1);
        for x in 0..tw {
            let at = |grid: &[u8], row: usize| grid.get(row * tw + x).copied().unwrap_or(0);
            let lo = at(tmin, y).min(at(tmin, above));
            let hi = at(tmax, y).max(at(tmax, above));
            if let Some(cell) = tmin.get_mut(y * tw + x) {
                *cell = if !has_contrast(lo, hi, min_contrast) {
                    0
                } else {
                    ratio_level(lo, hi)
                };
            }
        }
    }
    let wpr = words_per_row(w);
    for y in 0..h {
        let Some(out) = bitmap.get_mut(y * wpr..y * wpr + wpr) else {
            return;
        };
        out.fill(0);
        let thresholds = tmin.get((y / TILE) * tw..).unwrap_or(&[]);
        for (x, &p) in image.row(y).iter().enumerate() {
            let threshold = thresholds.get(x / TILE).copied().unwrap_or(0);
            if let Some(word) = out.get_mut(x / 32) {
                *word |= u32::from(p < threshold) << (x % 32);
            }
        }
    }
}

/// 3-wide min (or max) filter of one row of tiles, in place (the edges repeat): four tiles
/// a word by `pick_word` ([`byte_min`] or [`byte_max`]) against the word shifted by one tile
/// either way (the neighbours across the word's ends come from the words before and after
/// it), the bytes after the last whole word one at a time by `pick`. The write trails the
/// read by one word, so the original neighbours stay in registers.
#[inline(always)]
fn spread_along(row: &mut [u8], pick_word: impl Fn(u32, u32) -> u32, pick: impl Fn(u8, u8) -> u8) {
    let whole = row.len() / 4 * 4;
    let (words, tail) = row.split_at_mut(whole);
    let mut slots = words.chunks_exact_mut(4);
    // The byte before the tail (its left neighbour), or none when the row is shorter than a
    // word; then the first tile is its own left neighbour.
    let mut before_tail = None;
    if let Some(mut slot) = slots.next() {
        let mut current = word(slot);
        // Top byte = the left neighbour of the current word's first tile: itself at the edge.
        let mut previous = current << 24;
        let filter = |previous: u32, current: u32, next_first: u32| {
            let left = (current << 8) | (previous >> 24);
            let right = (current >> 8) | (next_first << 24);
            pick_word(pick_word(left, current), right)
        };
        for next_slot in slots {
            let next = word(next_slot);
            slot.copy_from_slice(&filter(previous, current, next).to_le_bytes());
            (previous, current, slot) = (current, next, next_slot);
        }
        // The last word's right neighbour: the tail's first byte, or itself at the edge.
        let next_first = tail.first().map_or(current >> 24, |&b| u32::from(b));
        slot.copy_from_slice(&filter(previous, current, next_first).to_le_bytes());
        before_tail = Some((current >> 24) as u8);
    }
    let mut cells = tail.iter_mut();
    let Some(mut slot) = cells.next() else {
        return;
    };
    let mut current = *slot;
    let mut previous = before_tail.unwrap_or(current);
    for cell in cells {
        let next = *cell;
        *slot = pick(pick(previous, current), next);
        (previous, current, slot) = (current, next, cell);
    }
    *slot = pick(previous, current);
}

/// The vertical half of the 3x3 min filter of `tmin` and max filter of `tmax` (`tw` x `th`
/// grids, already filtered along their rows; the edges repeat), then each tile's threshold
/// ([`tile_thresholds`]) written into `tmin`.
///
/// In place and row by row, in two passes: top down, each row becomes the extreme of itself
/// and the row below (the row below is still original); bottom up, each row's window is
/// the extreme of its own pair and the pair above (still a pair), which covers the row
/// above, itself and the row below, and becomes its threshold. Four tiles a word (SWAR, see
/// [`byte_min_max`]) along plain rows; the bytes past a row's last whole word one at a time.
fn spread_down_to_thresholds(
    tmin: &mut [u8],
    tmax: &mut [u8],
    tw: usize,
    th: usize,
    min_contrast: u8,
) {
    if tw == 0 {
        return;
    }
    for y in 1..th {
        pair_rows(tmin, tw, y, byte_min, u8::min);
        pair_rows(tmax, tw, y, byte_max, u8::max);
    }
    let contrast = u32::from(min_contrast) * 0x0101_0101;
    let whole = tw / 4 * 4;
    let tail = |row: &[u8]| -> usize { row.len().min(whole) };
    for y in (0..th).rev() {
        // Row y (a pair) and the pair above it; the top row's window is its own pair.
        let (Some((above_lo, row_lo)), Some((above_hi, row_hi))) = (
            tmin.split_at_mut_checked(y * tw),
            tmax.split_at_checked(y * tw),
        ) else {
            return;
        };
        let (Some(row_lo), Some(row_hi)) = (row_lo.get_mut(..tw), row_hi.get(..tw)) else {
            return;
        };
        let up_lo = above_lo
            .get(above_lo.len().saturating_sub(tw)..)
            .unwrap_or(&[]);
        let up_hi = above_hi
            .get(above_hi.len().saturating_sub(tw)..)
            .unwrap_or(&[]);
        let mut out = row_lo.chunks_exact_mut(4);
        if y > 0 {
            let ins = up_lo
                .chunks_exact(4)
                .zip(row_hi.chunks_exact(4).zip(up_hi.chunks_exact(4)));
            for (slot, (up_lo, (hi, up_hi))) in (&mut out).zip(ins) {
                let lo = byte_min(word(slot), word(up_lo));
                let hi = byte_max(word(hi), word(up_hi));
                slot.copy_from_slice(&tile_thresholds(lo, hi, contrast).to_le_bytes());
            }
        } else {
            for (slot, hi) in (&mut out).zip(row_hi.chunks_exact(4)) {
                let threshold = tile_thresholds(word(slot), word(hi), contrast);
                slot.copy_from_slice(&threshold.to_le_bytes());
            }
        }
        // The tiles past the last whole word.
        let cells = out.into_remainder().iter_mut().enumerate();
        for (i, cell) in cells {
            let at = |row: &[u8]| row.get(tail(row) + i).copied();
            let (lo, hi) = match (at(row_hi), at(up_lo), at(up_hi)) {
                (Some(hi), Some(up_lo), Some(up_hi)) => ((*cell).min(up_lo), hi.max(up_hi)),
                (Some(hi), ..) => (*cell, hi),
                _ => (*cell, *cell),
            };
            *cell = mid_threshold(lo, hi, min_contrast);
        }
    }
}

/// Four bytes as a little-endian word (0 for a slice of another length).
#[inline(always)]
fn word(bytes: &[u8]) -> u32 {
    <[u8; 4]>::try_from(bytes).map_or(0, u32::from_le_bytes)
}

/// Row `y - 1` of a `tw`-wide `grid` becomes the per-byte `pick` of itself and row `y`:
/// four bytes a word by `pick_word`, the bytes past the last whole word by `pick`.
#[inline(always)]
fn pair_rows(
    grid: &mut [u8],
    tw: usize,
    y: usize,
    pick_word: impl Fn(u32, u32) -> u32,
    pick: impl Fn(u8, u8) -> u8,
) {
    let Some((head, rest)) = grid.split_at_mut_checked(y * tw) else {
        return;
    };
    let upper = head.get_mut(y.saturating_sub(1) * tw..);
    let (Some(upper), Some(lower), true) = (upper, rest.get(..tw), y > 0) else {
        return;
    };
    let mut out = upper.chunks_exact_mut(4);
    for (slot, below) in (&mut out).zip(lower.chunks_exact(4)) {
        slot.copy_from_slice(&pick_word(word(slot), word(below)).to_le_bytes());
    }
    let below = lower.get(tw / 4 * 4..).unwrap_or(&[]);
    for (cell, &b) in out.into_remainder().iter_mut().zip(below) {
        *cell = pick(*cell, b);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The frame's binarisation both ways, named for the failure messages.
    type Binarise = fn(&GrayImage<'_>, u8, MaxRows, &mut [u32], &mut [u8]) -> u32;
    const BOTH_WAYS: [(&str, Binarise); 2] = [
        ("swar", local_threshold),
        ("vectorised", local_threshold_vectorised),
    ];

    /// Two words with `a` and `b` in byte `lane` and different bytes around them.
    fn lane_pair(a: u8, b: u8, lane: u32) -> (u32, u32) {
        let others = 0x5AFF_00A5 & !(0xFF << (8 * lane));
        (
            u32::from(a) << (8 * lane) | others,
            u32::from(b) << (8 * lane) | (others.rotate_left(8) & !(0xFF << (8 * lane))),
        )
    }

    /// Every pair of bytes, in every lane, with different bytes around it.
    #[test]
    fn bytes_ge_agrees_with_bytes() {
        for a in 0..=255u8 {
            for b in 0..=255u8 {
                for lane in 0..4 {
                    let (x, y) = lane_pair(a, b, lane);
                    let ge = bytes_ge(x, y);
                    assert_eq!(
                        ge >> (8 * lane + 7) & 1 == 1,
                        a >= b,
                        "{a} >= {b} lane {lane}"
                    );
                }
                let threshold = tile_thresholds(u32::from(a.min(b)), u32::from(a.max(b)), 20);
                let (lo, hi) = (a.min(b), a.max(b));
                let contrast = hi - lo;
                let expected =
                    if contrast < 20 && !(contrast >= 12 && 4 * u16::from(lo) <= u16::from(hi)) {
                        0
                    } else {
                        (u16::from(lo) + u16::from(hi)).div_ceil(2) as u8
                    };
                assert_eq!(threshold as u8, expected, "{lo} {hi}");
            }
        }
    }

    #[test]
    fn word_min_max_agrees_with_bytes() {
        let mut seed = 99u32;
        for _ in 0..20_000 {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let mins = seed;
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let maxs = seed;
            let expected_min = mins.to_le_bytes().into_iter().min().unwrap();
            let expected_max = maxs.to_le_bytes().into_iter().max().unwrap();
            assert_eq!(word_min_max(mins, maxs), (expected_min, expected_max));
        }
        for level in 0..=255u8 {
            let word = u32::from_le_bytes([level, 255, level, 0]);
            assert_eq!(word_min_max(word, word), (0, 255));
            let word = u32::from(level) * 0x0101_0101;
            assert_eq!(word_min_max(word, word), (level, level));
        }
    }

    #[test]
    fn byte_min_max_agrees_with_bytes() {
        let levels = [0u8, 1, 2, 63, 64, 127, 128, 129, 191, 200, 254, 255];
        for &a in &levels {
            for &b in &levels {
                for (c, d) in [(0u8, 255u8), (a, a), (b, a), (255, 0)] {
                    let x = u32::from_le_bytes([a, b, c, d]);
                    let y = u32::from_le_bytes([b, d, a, c]);
                    let (mn, mx) = byte_min_max(x, y);
                    let expect_min = [a.min(b), b.min(d), c.min(a), d.min(c)];
                    let expect_max = [a.max(b), b.max(d), c.max(a), d.max(c)];
                    assert_eq!(mn.to_le_bytes(), expect_min, "{x:#x} {y:#x}");
                    assert_eq!(mx.to_le_bytes(), expect_max, "{x:#x} {y:#x}");
                }
            }
        }
    }

    /// Every pair of bytes, in every lane, with different bytes around it.
    #[test]
    fn bytes_lt_agrees_with_bytes() {
        for a in 0..=255u8 {
            for b in 0..=255u8 {
                for lane in 0..4 {
                    let (x, y) = lane_pair(a, b, lane);
                    let lt = bytes_lt(x, y);
                    assert_eq!(
                        lt >> (8 * lane + 7) & 1 == 1,
                        a < b,
                        "{a} < {b} lane {lane}"
                    );
                    assert_eq!(lt & !HIGH, 0);
                }
            }
        }
    }

    #[test]
    fn dark_bits_agree_with_byte_comparisons() {
        let mut seed = 5u32;
        let levels = [0u8, 1, 2, 63, 64, 127, 128, 129, 191, 200, 254, 255];
        for round in 0..4000 {
            let mut pixels = [0u8; 32];
            for p in pixels.iter_mut() {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                *p = if round % 2 == 0 {
                    levels[(seed >> 24) as usize % levels.len()]
                } else {
                    (seed >> 24) as u8
                };
            }
            let mut eight = [0u8; 8];
            for t in eight.iter_mut() {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                *t = levels[(seed >> 24) as usize % levels.len()];
            }
            let got = dark_bits(&pixels, &spread_thresholds(u64::from_le_bytes(eight)));
            for (i, &p) in pixels.iter().enumerate() {
                let dark = p < eight[i / TILE];
                assert_eq!(
                    got >> i & 1 == 1,
                    dark,
                    "pixel {i}: {p} < {}",
                    eight[i / TILE]
                );
            }
        }
        assert_eq!(dark_bits(&[0u8; 31], &[u32::MAX; 8]), 0);
    }

    /// Every pair of bytes, in every lane of the 64-bit word, with different bytes around it.
    #[test]
    fn bytes_lt64_agrees_with_bytes() {
        for a in 0..=255u8 {
            for b in 0..=255u8 {
                for lane in 0..8 {
                    let others = 0x5AFF_00A5_C33C_0FF0u64 & !(0xFF << (8 * lane));
                    let x = u64::from(a) << (8 * lane) | others;
                    let y = u64::from(b) << (8 * lane)
                        | (others.rotate_left(8) & !(0xFF << (8 * lane)));
                    let lt = bytes_lt64(x, y);
                    for (i, (p, q)) in x.to_le_bytes().into_iter().zip(y.to_le_bytes()).enumerate()
                    {
                        assert_eq!(lt >> (8 * i + 7) & 1 == 1, p < q, "{p} < {q} lane {i}");
                    }
                    assert_eq!(lt & !0x8080_8080_8080_8080, 0);
                }
            }
        }
    }

    /// The vectorised blocks of 32 x 4 pixels against eight thresholds, on random pixels and
    /// on the levels around the byte boundaries, agree with byte comparisons (and with the
    /// Cortex-M7's words).
    #[test]
    fn vectorised_dark_blocks_agree_with_byte_comparisons() {
        let mut seed = 17u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 24) as u8
        };
        let levels = [0u8, 1, 2, 63, 64, 127, 128, 129, 191, 200, 254, 255];
        for round in 0..4000 {
            let mut pixels = [[0u8; 32]; 4];
            for p in pixels.iter_mut().flatten() {
                let r = next();
                *p = if round % 2 == 0 {
                    levels[r as usize % 12]
                } else {
                    r
                };
            }
            let thresholds: [u8; 8] = core::array::from_fn(|_| levels[next() as usize % 12]);
            let eight = u64::from_le_bytes(thresholds);
            let [r0, r1, r2, r3] = &pixels;
            let words = Vectorised::dark_block([r0, r1, r2, r3], eight);
            let spread = spread_thresholds(eight);
            for (r, (row, word)) in pixels.iter().zip(words).enumerate() {
                assert_eq!(word, dark_bits(row, &spread), "row {r}");
                for (i, &p) in row.iter().enumerate() {
                    let dark = p < thresholds[i / TILE];
                    assert_eq!(word >> i & 1 == 1, dark, "row {r} pixel {i}");
                }
            }
        }
        let short = [&[0u8; 31][..], &[0u8; 32], &[0u8; 32], &[0u8; 32]];
        assert_eq!(Vectorised::dark_block(short, u64::MAX)[0], 0);
    }

    /// The vectorised vertical spread and thresholds equal the word-at-a-time ones on random
    /// grids (each tile's maximum at least its minimum) of every width up to five words.
    #[test]
    fn vectorised_spread_down_matches_the_words() {
        let mut seed = 23u32;
        for tw in 1..=21usize {
            for th in 1..=5usize {
                let mut lows = [0u8; 21 * 5];
                let mut highs = [0u8; 21 * 5];
                for (lo, hi) in lows.iter_mut().zip(highs.iter_mut()).take(tw * th) {
                    seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    let (a, b) = ((seed >> 24) as u8, (seed >> 16) as u8);
                    (*lo, *hi) = (a.min(b), a.max(b));
                }
                let n = tw * th;
                let (mut words_lo, mut words_hi) = (lows, highs);
                spread_down_to_thresholds(&mut words_lo[..n], &mut words_hi[..n], tw, th, 30);
                let (mut bytes_lo, mut bytes_hi) = (lows, highs);
                Vectorised::spread_down_to_thresholds(
                    &mut bytes_lo[..n],
                    &mut bytes_hi[..n],
                    tw,
                    th,
                    30,
                );
                assert_eq!(bytes_lo, words_lo, "{tw} x {th}");
            }
        }
    }

    /// The word-at-a-time 3-wide filter equals the definition (edges repeat) on every row
    /// length up to three words and a tail, both ways.
    #[test]
    fn spread_along_matches_the_definition() {
        let mut seed = 7u32;
        for len in 1..=15usize {
            for _ in 0..50 {
                let mut row = [0u8; 15];
                for cell in row.iter_mut().take(len) {
                    seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    *cell = (seed >> 24) as u8;
                }
                let original = row;
                let at = |i: usize| original[i.min(len - 1)];
                let (mut lows, mut highs) = (row, row);
                spread_along(&mut lows[..len], byte_min, u8::min);
                spread_along(&mut highs[..len], byte_max, u8::max);
                for i in 0..len {
                    let window = [at(i.saturating_sub(1)), at(i), at(i + 1)];
                    let (lo, hi) = (window.iter().min(), window.iter().max());
                    assert_eq!(Some(&lows[i]), lo, "min, length {len} at {i}: {original:?}");
                    assert_eq!(
                        Some(&highs[i]),
                        hi,
                        "max, length {len} at {i}: {original:?}"
                    );
                }
                assert_eq!(lows[len..], original[len..], "beyond the row");
            }
        }
    }

    /// Sunlit paper (240) left of x = 16, shadowed paper (90) right of it, and a shadowed ink
    /// bar (15) at x = 20..24: the mid-level turns the shadowed paper between the shadow's
    /// edge and the ink dark (one blob from the edge to the bar), the ratio keeps it light
    /// and the ink dark.
    #[test]
    fn the_ratio_keeps_shadowed_paper_light_beside_sunlit_paper() {
        let (w, h) = (40usize, 16usize);
        let mut px = [0u8; 40 * 16];
        for (i, p) in px.iter_mut().enumerate() {
            *p = match i % w {
                0..16 => 240,
                20..24 => 15,
                _ => 90,
            };
        }
        let img = GrayImage::new(&px, w, h).unwrap();
        let wpr = words_per_row(w);
        let (mut mid, mut ratio) = ([0u32; 2 * 16], [0u32; 2 * 16]);
        let mut tiles = [0u8; 2 * 10 * 4];
        local_threshold(&img, 20, MaxRows::All, &mut mid, &mut tiles);
        ratio_threshold(&img, 20, &mut ratio, &mut tiles);
        for x in 16..20 {
            assert!(get_bit(&mid, wpr, x, 8, w, h), "mid-level at {x}");
            assert!(!get_bit(&ratio, wpr, x, 8, w, h), "ratio at {x}");
        }
        for x in 20..24 {
            assert!(get_bit(&ratio, wpr, x, 8, w, h), "ink at {x}");
        }
        assert!(!get_bit(&ratio, wpr, 10, 8, w, h), "sunlit paper");
        // The level itself: between the extrema, below the mid-level, above 0 for a black 0.
        assert_eq!(ratio_level(15, 240), 74);
        assert_eq!(ratio_level(100, 100), 100);
        assert_eq!(ratio_level(0, 255), 50);
        assert_eq!(ratio_level(255, 255), 255);
    }

    /// On random images of every size up to 3 x 3 tiles and a partial tile, the ratio's
    /// bitmap is the definition: a pixel is dark when it is below the ratio level of the
    /// extrema over its tile and the eight around it (edges repeat), with `min_contrast`.
    #[test]
    fn the_ratio_threshold_matches_the_definition() {
        let mut seed = 11u32;
        for w in 1..=14usize {
            for h in 1..=14usize {
                let mut px = [0u8; 14 * 14];
                for p in px.iter_mut().take(w * h) {
                    seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    *p = (seed >> 24) as u8;
                }
                let img = GrayImage::new(&px[..w * h], w, h).unwrap();
                let mut bitmap = [u32::MAX; 14];
                let mut tiles = [0u8; 2 * 4 * 4];
                ratio_threshold(&img, 40, &mut bitmap, &mut tiles);
                for y in 0..h {
                    for x in 0..w {
                        let (tx, ty) = ((x / TILE) as isize, (y / TILE) as isize);
                        let (mut lo, mut hi) = (255u8, 0u8);
                        for (qx, qy) in (0..w).flat_map(|qx| (0..h).map(move |qy| (qx, qy))) {
                            let (ux, uy) = ((qx / TILE) as isize, (qy / TILE) as isize);
                            if (ux - tx).abs() <= 1 && (uy - ty).abs() <= 1 {
                                lo = lo.min(px[qy * w + qx]);
                                hi = hi.max(px[qy * w + qx]);
                            }
                        }
                        let t = if hi - lo < 40 { 0 } else { ratio_level(lo, hi) };
                        let dark = get_bit(&bitmap, 1, x as isize, y as isize, w, h);
                        assert_eq!(dark, px[y * w + x] < t, "{w}x{h} at ({x}, {y})");
                    }
                }
            }
        }
    }

    /// The binarisation counts the 32 x 4 blocks it compared, which the detector charges: a
    /// flat frame none, one dark speck the blocks its tiles' 3 x 3 windows reach (the tile's
    /// own block and the one below; the next word's tiles are all flat), and each partial
    /// row of a partial tile row at the bottom as a block of its own.
    #[test]
    fn compared_blocks_are_counted() {
        for (way, local_threshold) in BOTH_WAYS {
            let (w, h) = (64usize, 8usize);
            let mut px = [200u8; 64 * 8];
            let img = GrayImage::new(&px, w, h).unwrap();
            let mut bitmap = [0u32; 2 * 8];
            let mut tiles = [0u8; 2 * 16 * 2];
            assert_eq!(
                local_threshold(&img, 20, MaxRows::All, &mut bitmap, &mut tiles),
                0,
                "{way}"
            );
            px[2 * w + 1] = 20;
            let img = GrayImage::new(&px, w, h).unwrap();
            assert_eq!(
                local_threshold(&img, 20, MaxRows::All, &mut bitmap, &mut tiles),
                2,
                "{way}"
            );
            assert_eq!(bitmap[2 * 2], 1 << 1, "{way}: the speck is dark");
            // Two more rows: a third tile row of two rows, compared row by row.
            let (w, h) = (64usize, 10usize);
            let mut px = [200u8; 64 * 10];
            px[2 * w + 1] = 20;
            px[9 * w + 40] = 20;
            let img = GrayImage::new(&px, w, h).unwrap();
            let mut bitmap = [0u32; 2 * 10];
            let mut tiles = [0u8; 2 * 16 * 3];
            // Tile rows 0 and 1 of word 0 (the first speck), tile rows 1 and 2 of word 1 (the
            // second: tile row 1 a block, tile row 2 two rows of one word each).
            // (The second speck's tile is column 10: its window, 9 to 11, stays in word 1.)
            assert_eq!(
                local_threshold(&img, 20, MaxRows::All, &mut bitmap, &mut tiles),
                2 + 1 + 2,
                "{way}"
            );
        }
    }

    #[test]
    fn dark_square_on_white_and_flat_areas() {
        let (w, h) = (40usize, 24usize);
        let mut px = [200u8; 40 * 24];
        for y in 8..16 {
            for x in 10..30 {
                px[y * w + x] = 30;
            }
        }
        let img = GrayImage::new(&px, w, h).unwrap();
        let mut bitmap = [0u32; 2 * 24];
        let mut tiles = [0u8; 2 * 10 * 6];
        local_threshold(&img, 20, MaxRows::All, &mut bitmap, &mut tiles);
        let wpr = words_per_row(w);
        assert!(get_bit(&bitmap, wpr, 10, 8, w, h));
        assert!(get_bit(&bitmap, wpr, 29, 15, w, h));
        assert!(!get_bit(&bitmap, wpr, 9, 8, w, h));
        assert!(!get_bit(&bitmap, wpr, 30, 15, w, h));
        // Far from the square the window is flat: nothing is dark.
        assert!(!get_bit(&bitmap, wpr, 0, 0, w, h));
        let flat = [90u8; 40 * 24];
        let img = GrayImage::new(&flat, w, h).unwrap();
        local_threshold(&img, 20, MaxRows::All, &mut bitmap, &mut tiles);
        assert!(bitmap.iter().all(|&word| word == 0));
    }

    /// The binarisation, either way, equals a pixel-by-pixel reading of the definition, on
    /// sizes that are not multiples of the tile, the word or the vectorised way's 64 pixels,
    /// with either choice of rows for the maxima.
    #[test]
    fn matches_the_definition_on_odd_sizes() {
        let mut seed = 12345u32;
        for &(w, h) in &[
            (37usize, 23usize),
            (64, 9),
            (95, 50),
            (5, 5),
            (33, 1),
            (40, 6),
            (128, 8),
            (130, 9),
            (68, 5),
            (71, 7),
        ] {
            let mut px = [0u8; 95 * 50];
            for p in px.iter_mut().take(w * h) {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                *p = (seed >> 24) as u8;
            }
            let img = GrayImage::new(&px[..w * h], w, h).unwrap();
            let runs = [MaxRows::All, MaxRows::EveryOther]
                .into_iter()
                .flat_map(|max_rows| BOTH_WAYS.map(|way| (max_rows, way)));
            for (max_rows, (way, local_threshold)) in runs {
                let mut bitmap = [0u32; 5 * 50];
                let mut tiles = [0u8; 2 * 33 * 13];
                local_threshold(&img, 20, max_rows, &mut bitmap, &mut tiles);
                // Whether pixel (xx, yy) counts in its tile's maximum: every row, or rows 0
                // and 2 of the tile (the last row standing in for missing ones), and every
                // row of a partial tile at the end of the rows.
                let in_max = |xx: usize, yy: usize| {
                    let y0 = yy / TILE * TILE;
                    max_rows == MaxRows::All
                        || xx >= w / TILE * TILE
                        || yy == y0
                        || yy == (y0 + 2).min(h - 1)
                };
                let (tw, th) = (w.div_ceil(TILE) as isize, h.div_ceil(TILE) as isize);
                for y in 0..h {
                    for x in 0..w {
                        let (tx, ty) = ((x / TILE) as isize, (y / TILE) as isize);
                        let (mut lo, mut hi) = (255u8, 0u8);
                        for yy in 0..h {
                            for xx in 0..w {
                                let (ux, uy) = ((xx / TILE) as isize, (yy / TILE) as isize);
                                let near = (ux - tx).abs() <= 1 && (uy - ty).abs() <= 1;
                                if near && ux < tw && uy < th {
                                    lo = lo.min(px[yy * w + xx]);
                                    if in_max(xx, yy) {
                                        hi = hi.max(px[yy * w + xx]);
                                    }
                                }
                            }
                        }
                        let contrast = hi.saturating_sub(lo);
                        let dark = (contrast >= 20
                            || (contrast >= 12 && 4 * u16::from(lo) <= u16::from(hi)))
                            && px[y * w + x] < ((lo as u16 + hi as u16).div_ceil(2)) as u8;
                        let got = get_bit(&bitmap, words_per_row(w), x as isize, y as isize, w, h);
                        assert_eq!(got, dark, "{w}x{h} {max_rows:?} {way} at ({x}, {y})");
                    }
                }
            }
        }
    }

    /// The word-wide thresholds equal the byte rule for every pair of extrema: the dark
    /// window's lower contrast included, in every byte position.
    #[test]
    fn tile_thresholds_follow_the_contrast_rule_in_every_byte() {
        let min_contrast = 20u8;
        let repeated = u32::from(min_contrast) * 0x0101_0101;
        for lo in 0..=255u8 {
            for hi in lo..=255u8 {
                let expected = if has_contrast(lo, hi, min_contrast) {
                    (u16::from(lo) + u16::from(hi)).div_ceil(2) as u8
                } else {
                    0
                };
                for byte in 0..4 {
                    // The other bytes a window with contrast, so a carry would show.
                    let (mut los, mut his) = ([10u8; 4], [200u8; 4]);
                    los[byte] = lo;
                    his[byte] = hi;
                    let got =
                        tile_thresholds(u32::from_le_bytes(los), u32::from_le_bytes(his), repeated)
                            .to_le_bytes();
                    assert_eq!(got[byte], expected, "lo {lo} hi {hi} byte {byte}");
                    assert_eq!(got[(byte + 1) % 4], 105, "lo {lo} hi {hi} byte {byte}");
                }
            }
        }
        // The rule itself: ink on shadowed paper passes, sunlit texture and dark noise do not.
        assert!(has_contrast(3, 18, 20));
        assert!(!has_contrast(60, 78, 20));
        assert!(!has_contrast(3, 14, 20));
        assert!(!has_contrast(5, 16, 20));
        assert!(has_contrast(60, 80, 20));
    }
}
