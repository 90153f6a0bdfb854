//! Step 2: following the boundaries of the binary image.
//!
//! A boundary starts at every dark pixel whose left neighbour is not dark and which no
//! earlier boundary passed through ([`start_bits`]). From there, Moore neighbour tracing
//! walks clockwise around the dark region keeping the light pixel on its left, which gives
//! the outer boundary of a dark blob (a marker's black border seen from outside) or the
//! boundary of a hole in it (the inner edge of a border ring), depending on which light
//! region the start pixel faced. The walk stops when it is about to leave the start pixel in
//! the direction it first left it (Jacob's criterion), so thin structures are walked fully.
//!
//! Every step marks the pixel in the `visited` bitmap, so no boundary is followed twice, and
//! draws from a per-frame step budget, so the time per frame is bounded on any image: a
//! frame of noise ends with [`Trace::OutOfBudget`] rather than a long stall.

use super::threshold::get_bit;

/// A boundary pixel.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Pixel {
    pub x: u16,
    pub y: u16,
}

/// Neighbour offsets, clockwise on screen (y down) starting east.
const DX: [isize; 8] = [1, 1, 0, -1, -1, -1, 0, 1];
const DY: [isize; 8] = [0, 1, 1, 1, 0, -1, -1, -1];
/// Direction of the light start neighbour (west).
const WEST: usize = 4;

/// How a trace ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Trace {
    /// The boundary closed; this many pixels were stored.
    Closed(usize),
    /// The boundary closed but was longer than the output buffer (not a candidate).
    TooLong,
    /// The frame's step budget ran out in the middle of the boundary.
    OutOfBudget,
}

/// Boundary follower over one frame's bitmaps.
pub(crate) struct Tracer<'b> {
    pub bitmap: &'b [u32],
    pub visited: &'b mut [u32],
    pub width: usize,
    pub height: usize,
    pub words_per_row: usize,
    /// Steps left for this frame.
    pub budget: u32,
    /// Steps taken so far.
    pub steps: u32,
}

impl Tracer<'_> {
    #[inline]
    fn dark(&self, x: isize, y: isize) -> bool {
        get_bit(
            self.bitmap,
            self.words_per_row,
            x,
            y,
            self.width,
            self.height,
        )
    }

    #[inline]
    fn mark(&mut self, x: usize, y: usize) {
        super::threshold::set_bit(self.visited, self.words_per_row, x, y);
    }

    /// First dark neighbour of (x, y), searching clockwise from direction `from`.
    #[inline]
    fn next(&self, x: isize, y: isize, from: usize) -> Option<usize> {
        (0..8).map(|i| (from + i) & 7).find(|&d| {
            self.dark(
                x + DX.get(d).copied().unwrap_or(0),
                y + DY.get(d).copied().unwrap_or(0),
            )
        })
    }

    /// Follows the boundary through the dark pixel (x0, y0) whose west neighbour is light,
    /// storing its pixels in `out`.
    pub fn trace(&mut self, x0: usize, y0: usize, out: &mut [Pixel]) -> Trace {
        let (sx, sy) = (x0 as isize, y0 as isize);
        let (mut x, mut y) = (sx, sy);
        let mut from = WEST;
        let mut first: Option<usize> = None;
        let mut len = 0usize;
        let mut overflow = false;
        loop {
            let step = self.next(x, y, from);
            if x == sx && y == sy {
                match (first, step) {
                    (Some(f), Some(d)) if f == d => break,
                    (None, _) => first = step,
                    _ => {}
                }
            }
            self.mark(x as usize, y as usize);
            match out.get_mut(len) {
                Some(slot) => {
                    *slot = Pixel {
                        x: x as u16,
                        y: y as u16,
                    };
                    len += 1;
                }
                None => overflow = true,
            }
            let Some(d) = step else {
                break; // an isolated pixel
            };
            if self.budget == 0 {
                return Trace::OutOfBudget;
            }
            self.budget -= 1;
            self.steps += 1;
            x += DX.get(d).copied().unwrap_or(0);
            y += DY.get(d).copied().unwrap_or(0);
            // The light pixel we passed last, seen from the new pixel.
            from = if d % 2 == 0 { (d + 6) & 7 } else { (d + 5) & 7 };
        }
        if overflow {
            Trace::TooLong
        } else {
            Trace::Closed(len)
        }
    }
}

/// Start pixels of row word `k`: dark, left neighbour light, not yet on a followed boundary.
/// `left_word` is the previous word of the same row (0 at the row start).
#[inline]
pub(crate) fn start_bits(dark: u32, left_word: u32, visited: u32) -> u32 {
    let left = (dark << 1) | (left_word >> 31);
    dark & !left & !visited
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::threshold::{set_bit, words_per_row};

    fn bitmap_of(rows: &[&str]) -> (usize, usize, [u32; 64]) {
        let (w, h) = (rows[0].len(), rows.len());
        let mut bm = [0u32; 64];
        for (y, row) in rows.iter().enumerate() {
            for (x, ch) in row.bytes().enumerate() {
                if ch == b'#' {
                    set_bit(&mut bm, words_per_row(w), x, y);
                }
            }
        }
        (w, h, bm)
    }

    fn trace_at(rows: &[&str], x: usize, y: usize) -> (Trace, [Pixel; 64]) {
        let (w, h, bm) = bitmap_of(rows);
        let mut visited = [0u32; 64];
        let mut t = Tracer {
            bitmap: &bm,
            visited: &mut visited,
            width: w,
            height: h,
            words_per_row: words_per_row(w),
            budget: 1000,
            steps: 0,
        };
        let mut out = [Pixel::default(); 64];
        (t.trace(x, y, &mut out), out)
    }

    #[test]
    fn square_outer_boundary() {
        let rows = ["......", ".####.", ".####.", ".####.", "......"];
        let (r, out) = trace_at(&rows, 1, 1);
        assert_eq!(r, Trace::Closed(10));
        // Clockwise on screen: along the top row first.
        assert_eq!((out[1].x, out[1].y), (2, 1));
        assert_eq!((out[3].x, out[3].y), (4, 1));
        assert_eq!((out[4].x, out[4].y), (4, 2));
    }

    #[test]
    fn ring_hole_is_followed_from_its_own_start() {
        let rows = [
            ".......", ".#####.", ".#...#.", ".#...#.", ".#####.", ".......",
        ];
        // (5, 2) is dark with a hole pixel to its west: the hole boundary.
        let (r, _) = trace_at(&rows, 5, 2);
        assert!(matches!(r, Trace::Closed(n) if n >= 8));
    }

    #[test]
    fn single_pixel_and_thin_line() {
        let (r, _) = trace_at(&["...", ".#.", "..."], 1, 1);
        assert_eq!(r, Trace::Closed(1));
        let (r, _) = trace_at(&[".....", ".###.", "....."], 1, 1);
        assert_eq!(r, Trace::Closed(4)); // there and back
    }

    #[test]
    fn budget_stops_the_walk() {
        let rows = ["......", ".####.", ".####.", ".####.", "......"];
        let (w, h, bm) = bitmap_of(&rows);
        let mut visited = [0u32; 64];
        let mut t = Tracer {
            bitmap: &bm,
            visited: &mut visited,
            width: w,
            height: h,
            words_per_row: 1,
            budget: 3,
            steps: 0,
        };
        let mut out = [Pixel::default(); 64];
        assert_eq!(t.trace(1, 1, &mut out), Trace::OutOfBudget);
    }

    #[test]
    fn start_bits_skip_runs_and_visited() {
        assert_eq!(start_bits(0b0111_0110, 0, 0), 0b0001_0010);
        assert_eq!(start_bits(0b1, 1 << 31, 0), 0);
        assert_eq!(start_bits(0b0110, 0, 0b0010), 0);
    }
}
