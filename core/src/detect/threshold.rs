//! Step 1: binarisation into a 1-bit-per-pixel bitmap.
//!
//! [`local_threshold`] (ours): per 4x4 tile the min and max grey level, spread to the 3x3
//! neighbouring tiles (a 12x12 window), and a pixel is dark when it lies below the window's
//! mid-level. The threshold follows shadows and vignetting across the frame. Where the window
//! has less than `min_contrast` there is no edge to find, so nothing there is dark: uniform
//! areas (sky, tarmac, the inside of a big black cell) cost nothing downstream.
//!
//! [`paper_edges`] (the paper's variant): normalise the frame to the full 0..255 range, blur
//! it with a 5x5 Gaussian, take 3x3 Sobel gradients and mark pixels whose gradient magnitude
//! exceeds a fixed level. Contours of that edge map are what the paper's method traces.
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
#[inline]
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
    tmin.fill(255);
    tmax.fill(0);
    // Tile extrema, one pass over the frame in row order; four pixels of a tile at a time,
    // reduced in registers before touching the tile's stored extrema.
    for y in 0..h {
        let row = image.row(y);
        let base = (y / TILE) * tw;
        let (Some(mins), Some(maxs)) =
            (tmin.get_mut(base..base + tw), tmax.get_mut(base..base + tw))
        else {
            return;
        };
        for ((chunk, lo), hi) in row.chunks(TILE).zip(mins.iter_mut()).zip(maxs.iter_mut()) {
            let (mn, mx) = if let [a, b, c, d] = *chunk {
                (a.min(b).min(c.min(d)), a.max(b).max(c.max(d)))
            } else {
                chunk
                    .iter()
                    .fold((255u8, 0u8), |(mn, mx), &p| (mn.min(p), mx.max(p)))
            };
            *lo = (*lo).min(mn);
            *hi = (*hi).max(mx);
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
        // Whole words: 32 pixels = 8 tiles, one threshold load per tile.
        let full = w / 32;
        for ((pixels, tile_thresholds), word) in row
            .chunks_exact(32)
            .zip(thresholds.chunks_exact(32 / TILE))
            .zip(out.iter_mut())
        {
            let mut bits = 0u32;
            for (t, (quad, &th)) in pixels.chunks_exact(TILE).zip(tile_thresholds).enumerate() {
                if let [a, b, c, d] = *quad {
                    let nibble = (a < th) as u32
                        | ((b < th) as u32) << 1
                        | ((c < th) as u32) << 2
                        | ((d < th) as u32) << 3;
                    bits |= nibble << (TILE * t);
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
    for row in grid.chunks_mut(tw).take(th) {
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

/// Gradient magnitude (|gx| + |gy| of the 3x3 Sobel on the normalised, blurred frame) above
/// which a pixel is an edge in the paper's variant.
pub(crate) const PAPER_EDGE_LEVEL: i32 = 160;

/// How far, in pixels, the outermost edge pixels of a sharp step lie from the step after the
/// 5x5 blur and the 3x3 gradient at [`PAPER_EDGE_LEVEL`] (measured on rendered markers).
pub(crate) const PAPER_EDGE_BAND_HALF_WIDTH: f32 = 1.5;

/// The paper's binarisation: normalise, 5x5 Gaussian blur, 3x3 Sobel, fixed edge level.
/// `scratch` holds at least `3 * width` bytes (three blurred rows).
pub(crate) fn paper_edges(image: &GrayImage<'_>, bitmap: &mut [u32], scratch: &mut [u8]) {
    let (w, h) = (image.width(), image.height());
    let wpr = words_per_row(w);
    bitmap.iter_mut().take(wpr * h).for_each(|word| *word = 0);
    let Some(rows) = scratch.get_mut(..3 * w) else {
        return;
    };
    // Normalisation: stretch [min, max] to [0, 255].
    let (mut lo, mut hi) = (255u8, 0u8);
    for y in 0..h {
        for &p in image.row(y) {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    let range = (hi.saturating_sub(lo)).max(1) as i32;
    let norm = |p: u8| -> i32 { (p.saturating_sub(lo) as i32 * 255) / range };
    // Blurred row y into ring slot y % 3.
    const KERNEL: [i32; 5] = [1, 4, 6, 4, 1];
    let blur_row = |y: usize, out: &mut [u8]| {
        for (x, o) in out.iter_mut().enumerate() {
            let mut acc = 0i32;
            for (ky, wy) in KERNEL.iter().enumerate() {
                let yy = y as isize + ky as isize - 2;
                for (kx, wx) in KERNEL.iter().enumerate() {
                    let xx = x as isize + kx as isize - 2;
                    acc += wy * wx * norm(image.pixel_clamped(xx, yy));
                }
            }
            *o = (acc / 256).clamp(0, 255) as u8;
        }
    };
    if h < 3 || w < 3 {
        return;
    }
    for y in 0..2usize {
        if let Some(slot) = rows.get_mut(y * w..y * w + w) {
            blur_row(y, slot);
        }
    }
    for y in 1..h - 1 {
        let next = (y + 1) % 3;
        if let Some(slot) = rows.get_mut(next * w..next * w + w) {
            blur_row(y + 1, slot);
        }
        let at = |yy: usize, x: usize| -> i32 {
            rows.get((yy % 3) * w + x).copied().unwrap_or(0) as i32
        };
        for x in 1..w - 1 {
            let gx = (at(y - 1, x + 1) + 2 * at(y, x + 1) + at(y + 1, x + 1))
                - (at(y - 1, x - 1) + 2 * at(y, x - 1) + at(y + 1, x - 1));
            let gy = (at(y + 1, x - 1) + 2 * at(y + 1, x) + at(y + 1, x + 1))
                - (at(y - 1, x - 1) + 2 * at(y - 1, x) + at(y - 1, x + 1));
            if gx.abs() + gy.abs() >= PAPER_EDGE_LEVEL {
                set_bit(bitmap, wpr, x, y);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
