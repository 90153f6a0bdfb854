//! Step 1: binarisation into a 1-bit-per-pixel bitmap.
//!
//! [`local_threshold`]: per 4x4 tile the min and max grey level, spread to the 3x3
//! neighbouring tiles (a 12x12 window), and a pixel is dark when it lies below the window's
//! mid-level. The threshold follows shadows and vignetting across the frame. Where the window
//! has less than `min_contrast` there is no edge to find, so nothing there is dark: uniform
//! areas (sky, tarmac, the inside of a big black cell) cost nothing downstream.
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

/// Which of four pixels (packed little-endian in `pixels`, first pixel in the low byte) are
/// below `threshold`, as a nibble (first pixel = bit 0).
///
/// Four comparisons in one 32-bit word (SIMD within a register), because the Cortex-M7 has
/// no byte-vector compare a compiler would use from stable Rust: per byte, the low seven
/// bits are compared by a subtraction that cannot borrow from the next byte, the top bits
/// decide where they differ, and a multiplication gathers the four flags into a nibble.
#[inline(always)]
fn darker_than(pixels: u32, threshold: u8) -> u32 {
    const HIGH: u32 = 0x8080_8080;
    let t = u32::from(threshold) * 0x0101_0101;
    // Per byte, bit 7: low seven bits of the pixel >= those of the threshold.
    let low_ge = ((pixels | HIGH).wrapping_sub(t & !HIGH)) & HIGH;
    // Pixel >= threshold: its top bit set and the threshold's clear, or the top bits equal
    // and the low bits decide.
    let ge = (pixels & !t & HIGH) | (!(pixels ^ t) & low_ge);
    let lt = (!ge & HIGH) >> 7;
    // Bits 0, 8, 16, 24 -> 21, 22, 23, 24: the partial products land on distinct bits, so
    // nothing carries into the window.
    (lt.wrapping_mul(0x0020_4081) >> 21) & 0xF
}

/// Per-byte minimum and maximum of two words of four pixels (SIMD within a register, as
/// [`darker_than`]): one per-byte comparison, spread to a byte mask, selects either way.
#[inline(always)]
fn byte_min_max(a: u32, b: u32) -> (u32, u32) {
    const HIGH: u32 = 0x8080_8080;
    let low_ge = ((a | HIGH).wrapping_sub(b & !HIGH)) & HIGH;
    let ge = (a & !b & HIGH) | (!(a ^ b) & low_ge);
    // 0xFF in every byte where a >= b.
    let mask = (ge >> 7).wrapping_mul(0xFF);
    ((b & mask) | (a & !mask), (a & mask) | (b & !mask))
}

/// Binarises `image` into `bitmap` (dark = 1) with a tile-local threshold. `tiles` holds at
/// least `2 * ceil(w/4) * ceil(h/4)` bytes.
pub(crate) fn local_threshold(
    image: &GrayImage<'_>,
    min_contrast: u8,
    bitmap: &mut [u32],
    tiles: &mut [u8],
) {
    let (w, h) = (image.width(), image.height());
    let (tw, th) = (w.div_ceil(TILE), h.div_ceil(TILE));
    let n = tw * th;
    let Some((tmin, rest)) = tiles.split_at_mut_checked(n) else {
        return;
    };
    let Some(tmax) = rest.get_mut(..n) else {
        return;
    };
    if tw == 0 {
        return;
    }
    // Tile extrema, one tile row at a time: a tile's four rows are four 32-bit words, which
    // are reduced to a per-byte min and max word in registers (SWAR, see `byte_min_max`),
    // then to the tile's min and max byte.
    for (ty, (mins, maxs)) in tmin
        .chunks_exact_mut(tw)
        .zip(tmax.chunks_exact_mut(tw))
        .enumerate()
    {
        // The last tile row may be short: repeating its last row leaves min and max as is.
        let y0 = ty * TILE;
        let last = h.saturating_sub(1);
        let rows = [
            image.row(y0),
            image.row((y0 + 1).min(last)),
            image.row((y0 + 2).min(last)),
            image.row((y0 + 3).min(last)),
        ];
        let [r0, r1, r2, r3] = rows;
        let whole = r0
            .chunks_exact(TILE)
            .zip(r1.chunks_exact(TILE))
            .zip(r2.chunks_exact(TILE).zip(r3.chunks_exact(TILE)));
        for (((a, b), (c, d)), (lo, hi)) in whole.zip(mins.iter_mut().zip(maxs.iter_mut())) {
            let word = |q: &[u8]| match *q {
                [p0, p1, p2, p3] => u32::from_le_bytes([p0, p1, p2, p3]),
                _ => 0,
            };
            let (mn01, mx01) = byte_min_max(word(a), word(b));
            let (mn23, mx23) = byte_min_max(word(c), word(d));
            let (mn, _) = byte_min_max(mn01, mn23);
            let (_, mx) = byte_min_max(mx01, mx23);
            let [m0, m1, m2, m3] = mn.to_le_bytes();
            let [x0, x1, x2, x3] = mx.to_le_bytes();
            *lo = m0.min(m1).min(m2.min(m3));
            *hi = x0.max(x1).max(x2.max(x3));
        }
        // A partial tile at the end of the rows (width not a multiple of the tile).
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
    // Spread over the 3x3 tile neighbourhood, in place: a horizontal then a vertical pass,
    // each carrying the previous original value in a register.
    spread(tmin, tw, th, u8::min);
    spread(tmax, tw, th, u8::max);
    // Threshold per tile: flat tiles get 0, so no pixel there is dark.
    for (lo, &hi) in tmin.iter_mut().zip(tmax.iter()) {
        *lo = if hi.saturating_sub(*lo) < min_contrast {
            0
        } else {
            (*lo as u16 + hi as u16).div_ceil(2) as u8
        };
    }
    let wpr = words_per_row(w);
    for y in 0..h {
        let row = image.row(y);
        let thresholds = tmin
            .get((y / TILE) * tw..(y / TILE) * tw + tw)
            .unwrap_or(&[]);
        let Some(out) = bitmap.get_mut(y * wpr..y * wpr + wpr) else {
            return;
        };
        // Whole words: 32 pixels = 8 tiles. Where all eight tiles are flat (threshold 0) no
        // pixel can be dark and the pixels are not even read; elsewhere each tile's four
        // pixels are compared with its threshold at once, in one 32-bit word.
        let full = w / 32;
        for ((pixels, tile_thresholds), word) in row
            .chunks_exact(32)
            .zip(thresholds.chunks_exact(32 / TILE))
            .zip(out.iter_mut())
        {
            let flat = match *tile_thresholds {
                [t0, t1, t2, t3, t4, t5, t6, t7] => {
                    u32::from_le_bytes([t0, t1, t2, t3]) | u32::from_le_bytes([t4, t5, t6, t7]) == 0
                }
                _ => false,
            };
            if flat {
                *word = 0;
                continue;
            }
            let mut bits = 0u32;
            for (t, (quad, &th)) in pixels.chunks_exact(TILE).zip(tile_thresholds).enumerate() {
                if let [a, b, c, d] = *quad {
                    bits |= darker_than(u32::from_le_bytes([a, b, c, d]), th) << (TILE * t);
                }
            }
            *word = bits;
        }
        // The partial word at the end of the row.
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
}

/// 3x3 min (or max) filter of a `tw` x `th` grid, in place.
fn spread(grid: &mut [u8], tw: usize, th: usize, pick: fn(u8, u8) -> u8) {
    for row in grid.chunks_mut(tw.max(1)).take(th) {
        let mut previous = row.first().copied().unwrap_or(0);
        for x in 0..tw {
            let current = row.get(x).copied().unwrap_or(0);
            let next = row.get(x + 1).copied().unwrap_or(current);
            if let Some(cell) = row.get_mut(x) {
                *cell = pick(pick(previous, current), next);
            }
            previous = current;
        }
    }
    for x in 0..tw {
        let mut previous = grid.get(x).copied().unwrap_or(0);
        for y in 0..th {
            let current = grid.get(y * tw + x).copied().unwrap_or(0);
            let next = grid.get((y + 1) * tw + x).copied().unwrap_or(current);
            let next = if y + 1 < th { next } else { current };
            if let Some(cell) = grid.get_mut(y * tw + x) {
                *cell = pick(pick(previous, current), next);
            }
            previous = current;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn darker_than_agrees_with_byte_comparisons() {
        let levels = [0u8, 1, 2, 63, 64, 127, 128, 129, 191, 200, 254, 255];
        for &t in &levels {
            for &a in &levels {
                for &b in &levels {
                    for (c, d) in [(0u8, 255u8), (t, t.wrapping_sub(1)), (a, b), (255, 0)] {
                        let expected = (a < t) as u32
                            | ((b < t) as u32) << 1
                            | ((c < t) as u32) << 2
                            | ((d < t) as u32) << 3;
                        let got = darker_than(u32::from_le_bytes([a, b, c, d]), t);
                        assert_eq!(got, expected, "{a} {b} {c} {d} < {t}");
                    }
                }
            }
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
        local_threshold(&img, 20, &mut bitmap, &mut tiles);
        let wpr = words_per_row(w);
        assert!(get_bit(&bitmap, wpr, 10, 8, w, h));
        assert!(get_bit(&bitmap, wpr, 29, 15, w, h));
        assert!(!get_bit(&bitmap, wpr, 9, 8, w, h));
        assert!(!get_bit(&bitmap, wpr, 30, 15, w, h));
        // Far from the square the window is flat: nothing is dark.
        assert!(!get_bit(&bitmap, wpr, 0, 0, w, h));
        let flat = [90u8; 40 * 24];
        let img = GrayImage::new(&flat, w, h).unwrap();
        local_threshold(&img, 20, &mut bitmap, &mut tiles);
        assert!(bitmap.iter().all(|&word| word == 0));
    }

    /// The word-at-a-time binarisation equals a pixel-by-pixel reading of the definition, on
    /// sizes that are not multiples of the tile or the word.
    #[test]
    fn matches_the_definition_on_odd_sizes() {
        let mut seed = 12345u32;
        for &(w, h) in &[(37usize, 23usize), (64, 9), (95, 50), (5, 5), (33, 1)] {
            let mut px = [0u8; 95 * 50];
            for p in px.iter_mut().take(w * h) {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                *p = (seed >> 24) as u8;
            }
            let img = GrayImage::new(&px[..w * h], w, h).unwrap();
            let mut bitmap = [0u32; 3 * 50];
            let mut tiles = [0u8; 2 * 24 * 13];
            local_threshold(&img, 20, &mut bitmap, &mut tiles);
            let (tw, th) = (w.div_ceil(TILE) as isize, h.div_ceil(TILE) as isize);
            for y in 0..h {
                for x in 0..w {
                    let (tx, ty) = ((x / TILE) as isize, (y / TILE) as isize);
                    let (mut lo, mut hi) = (255u8, 0u8);
                    for yy in 0..h {
                        for xx in 0..w {
                            let (ux, uy) = ((xx / TILE) as isize, (yy / TILE) as isize);
                            if (ux - tx).abs() <= 1 && (uy - ty).abs() <= 1 && ux < tw && uy < th {
                                lo = lo.min(px[yy * w + xx]);
                                hi = hi.max(px[yy * w + xx]);
                            }
                        }
                    }
                    let dark = hi - lo >= 20
                        && px[y * w + x] < ((lo as u16 + hi as u16).div_ceil(2)) as u8;
                    let got = get_bit(&bitmap, words_per_row(w), x as isize, y as isize, w, h);
                    assert_eq!(got, dark, "{w}x{h} at ({x}, {y})");
                }
            }
        }
    }
}
