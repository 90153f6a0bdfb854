//! What the exposure loop is told about a frame ([`Metering`]): the scene's mean and its
//! highlights, the white and black of the decoded markers, and the longest exposure the
//! vehicle's rotation allows.
//!
//! Why more than the mean: a white pad on dark grass in sun is a few percent of the frame, so
//! a loop that brings the frame's mean to mid-grey drives the paper far past the sensor's full
//! well; the white clips and blooms into the black cells and the markers shrink or vanish.
//! Once markers are decoded their own cells say how bright the paper is: [`pad_levels`]
//! samples the centres of the cells the decoded code says are white, and of the black ones
//! (the border ring and the black data cells), through the homography of the detected
//! corners. Before any marker is decoded, [`scene_levels`] gives the mean and the level that
//! the brightest [`HIGHLIGHT_SHARE`]th of the frame reaches, so that the loop can keep a
//! small bright object (the pad before it is decoded) out of clipping.
//!
//! Motion blur: a body rate `w` (rad/s) moves the image by about `w f` pixels per second
//! (`f` the focal length in pixels), so an exposure of `t` smears it by `w f t`.
//! [`motion_cap_us`] is the exposure that keeps this at [`MAX_MOTION_BLUR_PX`]; the loop then
//! makes up the light with gain.
//!
//! Bounded work: the scene is read on a sparse grid (every [`SCENE_STEP`]th pixel of every
//! [`SCENE_STEP`]th row), at most [`MAX_METERED_MARKERS`] markers of at most
//! [`MAX_METERED_GRID`] cells a side are sampled, one bilinear read per cell.

use crate::detect::Detection;
use crate::family::{CellRole, Family};
use crate::geometry::{Homography, Point};
use crate::image::GrayImage;

/// The scene is sampled every this many pixels and rows (1/64 of a frame: 1,200 reads at QVGA).
pub const SCENE_STEP: usize = 8;
/// The highlight is the level the brightest `1 / HIGHLIGHT_SHARE` of the scene's samples reach
/// or exceed: 1/256 is about a 1.6 m x 2.8 m pad at 20 m through a 60 degree lens, at any
/// resolution.
pub const HIGHLIGHT_SHARE: u32 = 256;
/// Markers sampled per frame (the first ones the detector reports).
pub const MAX_METERED_MARKERS: usize = 4;
/// Families with more cells a side than this are not sampled (bounded work).
pub const MAX_METERED_GRID: usize = 12;
/// Markers whose cells are narrower than this (pixels) are not sampled: a cell's centre then
/// reads its neighbours through the lens blur.
pub const MIN_CELL_PX: f32 = 2.5;
/// Least white-minus-black difference (grey levels) for a marker's levels to be believed: a
/// decoded marker always has it; below it the samples missed the marker.
pub const MIN_PAD_CONTRAST: u8 = 16;
/// Image motion allowed during one exposure, pixels, at the vehicle's body rate.
pub const MAX_MOTION_BLUR_PX: f32 = 0.5;
/// Body rates below this (rad/s, 0.6 deg/s) leave the exposure uncapped.
const MIN_CAPPED_RATE: f32 = 0.01;

/// The white and black of the brightest decoded marker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PadLevels {
    /// Mean grey level at the centres of its white cells.
    pub white: u8,
    /// Mean grey level at the centres of its black cells (border and data).
    pub black: u8,
}

/// What the exposure loop ([`super::AutoExposure::update_metered`]) is fed for one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Metering {
    /// Mean grey level of the scene ([`scene_levels`]).
    pub mean: u8,
    /// Level the brightest 1/[`HIGHLIGHT_SHARE`] of the scene reaches; 0 = not measured (no
    /// highlight guard).
    pub highlight: u8,
    /// The decoded markers' levels, when some marker could be sampled.
    pub pad: Option<PadLevels>,
    /// Longest exposure the body rate allows ([`motion_cap_us`]), µs; `None`: no cap (rate
    /// unknown or negligible).
    pub max_exposure_us: Option<u32>,
}

impl Metering {
    /// The mean alone: the loop's behaviour before markers and highlights were metered.
    pub const fn mean_only(mean: u8) -> Self {
        Metering {
            mean,
            highlight: 0,
            pad: None,
            max_exposure_us: None,
        }
    }
}

/// The scene's mean and highlight over every `step`-th pixel of every `step`-th row:
/// `(mean, highlight)`, `(0, 0)` for an empty image.
pub fn scene_levels(image: &GrayImage<'_>, step: usize) -> (u8, u8) {
    let step = step.max(1);
    // u16 counts (512 B of stack, not 1 KB: the vision task's frame path runs on the boot
    // stack). A bin saturates past 65,535 samples, which cannot change the highlight while
    // the image gives fewer than 256 x 65,535 (16.7 million) samples: the downward scan has
    // reached `wanted` (count / 256 <= 65,535) by the time it adds a saturated bin. The mean
    // is summed apart from the histogram, exactly.
    let mut histogram = [0u16; 256];
    let mut sum = 0u64;
    let mut count = 0u32;
    for y in (0..image.height()).step_by(step) {
        for &p in image.row(y).iter().step_by(step) {
            if let Some(bin) = histogram.get_mut(usize::from(p)) {
                *bin = bin.saturating_add(1);
            }
            sum += u64::from(p);
            count = count.saturating_add(1);
        }
    }
    if count == 0 {
        return (0, 0);
    }
    let mean = (sum / u64::from(count)) as u8;
    // The highest level with at least count / HIGHLIGHT_SHARE samples at or above it (at
    // least one sample: a single bright pixel is the highlight of a tiny image).
    let wanted = (count / HIGHLIGHT_SHARE).max(1);
    let mut above = 0u32;
    let mut highlight = 0u8;
    for (level, &n) in histogram.iter().enumerate().rev() {
        above = above.saturating_add(u32::from(n));
        if above >= wanted {
            highlight = level as u8;
            break;
        }
    }
    (mean, highlight)
}

/// The white and black of the brightest of the first [`MAX_METERED_MARKERS`] `detections`
/// (family indices into `families`), sampled at its cells' centres; `None` when no marker
/// could be sampled (unknown family, grid too large, cells too small, too little contrast).
pub fn pad_levels(
    image: &GrayImage<'_>,
    detections: &[Detection],
    families: &[&Family<'_>],
) -> Option<PadLevels> {
    let mut best: Option<PadLevels> = None;
    for detection in detections.iter().take(MAX_METERED_MARKERS) {
        let Some(family) = families.get(usize::from(detection.family)) else {
            continue;
        };
        let Some(levels) = marker_levels(image, detection, family) else {
            continue;
        };
        if best.is_none_or(|b| levels.white > b.white) {
            best = Some(levels);
        }
    }
    best
}

/// One marker's levels (see [`pad_levels`]).
fn marker_levels(
    image: &GrayImage<'_>,
    detection: &Detection,
    family: &Family<'_>,
) -> Option<PadLevels> {
    let grid = usize::from(family.grid);
    let code = *family.codes.get(usize::from(detection.id))?;
    let (offset, cells) = (family.quad_offset(), family.quad_cells());
    if grid > MAX_METERED_GRID || cells == 0 {
        return None;
    }
    // The corners are the detected square's, in the canonical order: grid coordinates
    // (column, row) of its corners map onto them.
    let (a, b) = (offset as f32, (offset + cells) as f32);
    let square = [
        Point::new(a, a),
        Point::new(b, a),
        Point::new(b, b),
        Point::new(a, b),
    ];
    let c = &detection.corners;
    let shortest_side = c[0]
        .distance(c[1])
        .min(c[1].distance(c[2]))
        .min(c[2].distance(c[3]))
        .min(c[3].distance(c[0]));
    if !(shortest_side >= MIN_CELL_PX * cells as f32) {
        return None;
    }
    let h = Homography::from_4_points(&square, c)?;
    let (mut white_sum, mut white_n, mut black_sum, mut black_n) = (0f32, 0u32, 0f32, 0u32);
    let bits = u32::from(family.bits);
    let mut data_index = 0u32;
    for row in 0..grid {
        for col in 0..grid {
            let white = match family.role(row, col) {
                // The margin may be the ground, not paper (the nested pad's large marker).
                CellRole::Quiet => continue,
                CellRole::Border => false,
                CellRole::InnerWhite => true,
                CellRole::Data => {
                    let shift = bits.checked_sub(data_index + 1);
                    data_index += 1;
                    match shift {
                        Some(s) => code.checked_shr(s).is_some_and(|v| v & 1 == 1),
                        None => continue,
                    }
                }
            };
            let Some(p) = h.map(col as f32 + 0.5, row as f32 + 0.5) else {
                continue;
            };
            let level = image.sample(p.x, p.y);
            if white {
                white_sum += level;
                white_n += 1;
            } else {
                black_sum += level;
                black_n += 1;
            }
        }
    }
    if white_n == 0 || black_n == 0 {
        return None;
    }
    let to_level = |sum: f32, n: u32| (sum / n as f32 + 0.5).clamp(0.0, 255.0) as u8;
    let levels = PadLevels {
        white: to_level(white_sum, white_n),
        black: to_level(black_sum, black_n),
    };
    (levels.white >= levels.black.saturating_add(MIN_PAD_CONTRAST)).then_some(levels)
}

/// The longest exposure (µs) that keeps the image motion of a body rate of `rate_rad_s`
/// (the rate vector's length) under [`MAX_MOTION_BLUR_PX`] through a lens of `focal_px`;
/// `None` for a negligible or invalid rate or focal length.
pub fn motion_cap_us(rate_rad_s: f32, focal_px: f32) -> Option<u32> {
    let speed_px_s = rate_rad_s * focal_px;
    if !(rate_rad_s >= MIN_CAPPED_RATE && speed_px_s.is_finite() && focal_px > 0.0) {
        return None;
    }
    let us = MAX_MOTION_BLUR_PX / speed_px_s * 1.0e6;
    // A float-to-int cast saturates; at least 1 µs.
    Some((us as u32).max(1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::family::tables;

    #[test]
    fn the_highlight_is_the_brightest_share_of_the_scene() {
        // 64 x 64 grey 60 with a 6 x 6 square at 250: 36 of 4096 pixels (0.9 %).
        let mut data = [60u8; 64 * 64];
        for y in 10..16 {
            for x in 20..26 {
                data[y * 64 + x] = 250;
            }
        }
        let image = GrayImage::new(&data, 64, 64).unwrap();
        let (mean, highlight) = scene_levels(&image, 1);
        assert_eq!(mean, 61);
        assert_eq!(highlight, 250);
        // A uniform frame: the highlight is its level.
        let flat = [90u8; 32 * 32];
        let image = GrayImage::new(&flat, 32, 32).unwrap();
        assert_eq!(scene_levels(&image, 8), (90, 90));
        assert_eq!(scene_levels(&image, 0), (90, 90));
    }

    #[test]
    fn a_saturated_bin_leaves_the_highlight_exact() {
        // 512 x 256 = 131,072 samples, twice a u16 bin: 130,000 at 240 (that bin saturates),
        // 1,072 at 20. The highlight is 240 and the mean is summed exactly.
        let mut data = [240u8; 512 * 256];
        for p in data.iter_mut().take(1_072) {
            *p = 20;
        }
        let image = GrayImage::new(&data, 512, 256).unwrap();
        let expected_mean = ((130_000u64 * 240 + 1_072 * 20) / 131_072) as u8;
        assert_eq!(scene_levels(&image, 1), (expected_mean, 240));
        // 600 bright samples (more than 131,072 / 256 = 512) above a saturated dark bin.
        let mut data = [30u8; 512 * 256];
        for p in data.iter_mut().skip(1_000).take(600) {
            *p = 250;
        }
        let image = GrayImage::new(&data, 512, 256).unwrap();
        assert_eq!(scene_levels(&image, 1).1, 250);
    }

    #[test]
    fn motion_caps_the_exposure() {
        // 30 deg/s through f = 233.5 px: 122 px/s, 0.5 px in 4.09 ms.
        let cap = motion_cap_us(30f32.to_radians(), 233.5).unwrap();
        assert!((4_000..4_200).contains(&cap), "{cap}");
        // Twice the rate, half the exposure.
        let fast = motion_cap_us(60f32.to_radians(), 233.5).unwrap();
        assert!(fast.abs_diff(cap / 2) <= 1, "{fast} vs {cap}");
        assert_eq!(motion_cap_us(0.0, 233.5), None);
        assert_eq!(motion_cap_us(f32::NAN, 233.5), None);
        assert_eq!(motion_cap_us(1.0, 0.0), None);
        assert_eq!(motion_cap_us(f32::INFINITY, 233.5), None);
    }

    /// A marker of `family`'s code `id` drawn axis-aligned with `cell` pixels per cell at
    /// (`x0`, `y0`), white `white` and black `black`, on a background `ground`.
    fn draw(
        family: &Family<'_>,
        id: usize,
        cell: usize,
        (x0, y0): (usize, usize),
        (white, black, ground): (u8, u8, u8),
        data: &mut [u8],
        width: usize,
    ) -> Detection {
        data.iter_mut().for_each(|p| *p = ground);
        let n = usize::from(family.grid);
        for row in 0..n {
            for col in 0..n {
                let level = if family.cell_is_white(id, row, col).unwrap() {
                    white
                } else {
                    black
                };
                for y in 0..cell {
                    for x in 0..cell {
                        data[(y0 + row * cell + y) * width + x0 + col * cell + x] = level;
                    }
                }
            }
        }
        let off = family.quad_offset() as f32 * cell as f32;
        let size = family.quad_cells() as f32 * cell as f32;
        let (x, y) = (x0 as f32 + off - 0.5, y0 as f32 + off - 0.5);
        Detection {
            family: 0,
            id: id as u16,
            hamming: 0,
            corners: [
                Point::new(x, y),
                Point::new(x + size, y),
                Point::new(x + size, y + size),
                Point::new(x, y + size),
            ],
            center: Point::new(x + 0.5 * size, y + 0.5 * size),
            decision_margin: 1.0,
            contrast: 100.0,
        }
    }

    #[test]
    fn a_marker_reads_its_own_white_and_black() {
        let family = tables::DEFAULT[0];
        let mut data = [0u8; 128 * 128];
        // The ground is darker than the paper and the margin is ground: it is not sampled.
        let d = draw(family, 3, 8, (10, 10), (200, 30, 90), &mut data, 128);
        let image = GrayImage::new(&data, 128, 128).unwrap();
        let levels = pad_levels(&image, &[d], &[family]).unwrap();
        assert_eq!(
            levels,
            PadLevels {
                white: 200,
                black: 30
            }
        );
        // A clipped marker: white 255, black lifted by blooming.
        draw(family, 3, 8, (10, 10), (255, 190, 90), &mut data, 128);
        let image = GrayImage::new(&data, 128, 128).unwrap();
        let levels = pad_levels(&image, &[d], &[family]).unwrap();
        assert_eq!(
            levels,
            PadLevels {
                white: 255,
                black: 190
            }
        );
        // Cells of 2 px are too small; an unknown family index or id gives nothing.
        let small = draw(family, 3, 2, (10, 10), (200, 30, 90), &mut data, 128);
        let image = GrayImage::new(&data, 128, 128).unwrap();
        assert_eq!(pad_levels(&image, &[small], &[family]), None);
        let mut wrong = d;
        wrong.family = 5;
        assert_eq!(pad_levels(&image, &[wrong], &[family]), None);
        wrong.family = 0;
        wrong.id = u16::MAX;
        assert_eq!(pad_levels(&image, &[wrong], &[family]), None);
        // No contrast: the samples missed the marker.
        let flat = [120u8; 128 * 128];
        let image = GrayImage::new(&flat, 128, 128).unwrap();
        assert_eq!(pad_levels(&image, &[d], &[family]), None);
        // Degenerate corners.
        let mut collapsed = d;
        collapsed.corners = [Point::new(f32::NAN, 0.0); 4];
        assert_eq!(pad_levels(&image, &[collapsed], &[family]), None);
    }
}
