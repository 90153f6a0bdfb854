//! The reference paper's method (section 2.2, [`Method::Paper`](super::Method::Paper)),
//! kept to reproduce its tables (`cargo replay --scenario paper`, the host tests
//! `paper_geometry` and `rendered`), as one [`Strategy`] of the detector: the steps it shares
//! with ours (contour following, the quad fit, the code look-up) are the detector's, and
//! everything the paper does differently is here, so the production path carries no
//! branches for it.
//!
//! - Binarisation ([`edges`]): normalise the frame to the full 0..255 range, blur it with a
//!   5x5 Gaussian, take 3x3 Sobel gradients and mark pixels whose gradient magnitude exceeds
//!   a fixed level. Every contour of that edge map is traced (holes and both sides of the
//!   edge bands, as OpenCV's `findContours` does), not only the outer boundaries of dark
//!   regions.
//! - Candidates: every quad, whatever its polarity, is a candidate for the normal
//!   (dark-on-light) families; there is no quick look before reading.
//! - Corners: the Douglas-Peucker corners stepped back from the outside of the gradient band
//!   onto the edge itself ([`EDGE_BAND_HALF_WIDTH`]), without sub-pixel refinement.
//! - Cells ([`read_cells`]): each cell the mean over its whole area ("resized to 8x8"),
//!   thresholded at the mean of all cells; only an exact match of border and code counts.

use super::decode::{grid_homography, GridRead};
use super::threshold::{set_bit, words_per_row};
use super::{contour, quad, refine, Candidates, DetectorConfig, Look, Strategy};
use crate::family::{CellRole, Family, MAX_GRID};
use crate::geometry::{Homography, Point};
use crate::image::GrayImage;

/// The paper's method as the detector's [`Strategy`].
pub(super) struct Paper;

impl Strategy for Paper {
    fn binarise(
        &self,
        image: &GrayImage<'_>,
        _config: &DetectorConfig,
        bitmap: &mut [u32],
        tiles: &mut [u8],
    ) -> u32 {
        // The edge map's passes cost the same on every frame of a size.
        edges(image, bitmap, tiles);
        0
    }

    /// Every contour of the edge map: the edge band around a marker's outline leaves a hole
    /// just inside it.
    fn start_rule(&self, _families: &[&Family<'_>]) -> contour::StartRule {
        contour::StartRule::AllBoundaries
    }

    /// The edge map has no polarity: outer boundaries and holes alike are candidates, for
    /// the normal families (the paper has no white-on-black markers).
    fn wanted(&self, family: &Family<'_>, _hole: bool) -> bool {
        !family.reversed()
    }

    fn quick_look(
        &self,
        _candidates: &Candidates<'_, '_, '_>,
        _quad: &quad::Quad,
        _tracer: &mut contour::Tracer<'_>,
    ) -> Look {
        Look::Candidate
    }

    /// The edge map's outline runs along the outside of the gradient band around the
    /// marker's edge (its holes along the inside): step back onto the edge itself.
    fn corners(
        &self,
        _candidates: &Candidates<'_, '_, '_>,
        quad: &quad::Quad,
        _samples: &mut u32,
    ) -> [Point; 4] {
        refine::offset_quad(quad, -EDGE_BAND_HALF_WIDTH)
    }

    /// The paper reads each cell once, as its area's mean: no second, deblurred read.
    fn read(
        &self,
        candidates: &Candidates<'_, '_, '_>,
        family: &Family<'_>,
        corners: &[Point; 4],
        deblurred: bool,
        _samples: &mut u32,
    ) -> Option<GridRead> {
        if deblurred {
            return None;
        }
        read_cells(candidates.image, family, corners)
    }

    /// Exact template comparison.
    fn max_hamming(&self, _config: &DetectorConfig) -> u8 {
        0
    }

    /// The paper's corners are its own step-back from the edge band, nothing else.
    /// The paper keeps four-corner shapes only.
    fn completes_corners(&self) -> bool {
        false
    }

    // The paper's tables reproduce from its own order: every row in turn.
    fn scans_middle_first(&self) -> bool {
        false
    }

    fn fits_patterns(&self, _config: &DetectorConfig) -> bool {
        false
    }
}

/// Gradient magnitude (|gx| + |gy| of the 3x3 Sobel on the normalised, blurred frame) above
/// which a pixel is an edge.
const EDGE_LEVEL: i32 = 160;

/// How far, in pixels, the outermost edge pixels of a sharp step lie from the step after the
/// 5x5 blur and the 3x3 gradient at [`EDGE_LEVEL`] (measured on rendered markers).
const EDGE_BAND_HALF_WIDTH: f32 = 1.5;

/// The paper's binarisation: normalise, 5x5 Gaussian blur, 3x3 Sobel, fixed edge level.
/// `scratch` holds at least `3 * width` bytes (three blurred rows).
fn edges(image: &GrayImage<'_>, bitmap: &mut [u32], scratch: &mut [u8]) {
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
    // `checked_div`: range >= 1, but the optimiser loses that inside the closure and would
    // keep a division-by-zero panic path (see nopanic/).
    let norm = |p: u8| -> i32 {
        (p.saturating_sub(lo) as i32 * 255)
            .checked_div(range)
            .unwrap_or(0)
    };
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
            if gx.abs() + gy.abs() >= EDGE_LEVEL {
                set_bit(bitmap, wpr, x, y);
            }
        }
    }
}

/// Reads a cell as the mean over its area (4x4 points), the paper's "resize".
fn read_cell_area(image: &GrayImage<'_>, h: &Homography, u0: f32, v0: f32) -> Option<f32> {
    let mut acc = 0.0;
    for i in 0..4 {
        for j in 0..4 {
            let p = h.map(u0 + (i as f32 + 0.5) / 4.0, v0 + (j as f32 + 0.5) / 4.0)?;
            acc += image.sample(p.x, p.y);
        }
    }
    Some(acc / 16.0)
}

/// Reads a candidate's cells with the paper's method (normal families only): each cell the
/// mean over its area, thresholded at the mean of all cells; a border cell that reads white
/// rejects the candidate. The look-up must then be exact ([`Strategy::max_hamming`] 0).
fn read_cells(image: &GrayImage<'_>, family: &Family<'_>, quad: &[Point; 4]) -> Option<GridRead> {
    if family.reversed() {
        return None;
    }
    let h = grid_homography(family, quad)?;
    let n = family.grid as usize;
    let b = family.border_ring as usize;
    let mut values = [0.0f32; MAX_GRID * MAX_GRID];
    let mut sum = 0.0f32;
    let mut count = 0usize;
    for r in b..n - b {
        for c in b..n - b {
            let z = read_cell_area(image, &h, c as f32, r as f32)?;
            if let Some(slot) = values.get_mut(r * n + c) {
                *slot = z;
            }
            sum += z;
            count += 1;
        }
    }
    let level = sum / count.max(1) as f32;
    let mut cells = [false; MAX_GRID * MAX_GRID];
    let (mut dark_sum, mut dark_n, mut light_sum, mut light_n) = (0.0f32, 0usize, 0.0f32, 0usize);
    for r in b..n - b {
        for c in b..n - b {
            let z = values.get(r * n + c).copied().unwrap_or(0.0);
            let white = z > level;
            if family.role(r, c) == CellRole::Border && white {
                return None; // the template's border must match exactly
            }
            if let Some(cell) = cells.get_mut(r * n + c) {
                *cell = white;
            }
            if white {
                light_sum += z;
                light_n += 1;
            } else {
                dark_sum += z;
                dark_n += 1;
            }
        }
    }
    let contrast = light_sum / light_n.max(1) as f32 - dark_sum / dark_n.max(1) as f32;
    // The paper's method accepts exact matches only and has no notion of certainty.
    Some(GridRead::certain(
        h,
        family.codes_of_grid(cells.get(..n * n)?),
        contrast,
    ))
}
