//! Step 7: corners of small markers from a fit of the decoded pattern to the pixels.
//!
//! ## Why
//! Far from the pad a marker spans 10-20 pixels, a cell 1-2 pixels, and the blur is about
//! as wide as a cell. The edge search of [`super::refine`] then reads a gradient lobe whose
//! tails run into the neighbouring edges (the white ring's outer edge outside, the first data
//! cells inside): the centroid moves by a few hundredths of a pixel per edge, in a direction
//! set by the blur and by what lies around the marker. That is a scale error: on a 1 m marker
//! at 50 m (11 pixels across) the altitude read 1.4 % high on our renderer and 1.4 % low on
//! another, the largest error of the pose above 25 m once the tilt comes from the attitude.
//!
//! Once the marker is decoded, the whole pattern is known: every cell's colour, the white
//! ring outside the border (the family's quiet ring, or the printed margin every family needs
//! for its outline to be found). So the image of the marker is predicted, not searched:
//! the known cells mapped through the corner homography, blurred by a Gaussian of unknown
//! width, with unknown black and white levels and, on each of its four sides, an unknown
//! level beyond the known area, after a band of white paper of unknown width. A pad on grass
//! has dark ground on some sides of a marker and the white sheet on others, and a marker is
//! printed on a margin of any width: the ground's edge a cell or two beyond the border lies
//! within a far marker's blur, or half a cell beyond it within the pixels read of a larger
//! one, and with the level put right at the known area's end the fit moved the edges towards
//! it (by 3 % on a marker of 22 pixels). A Gauss-Newton fit of the 4 corners, the blur, the two levels, the
//! outside levels and the bands to every pixel over the marker moves the corners to where
//! the whole pattern agrees: each edge is placed with its neighbours modelled instead of
//! trimmed, so the scale is unbiased whatever the blur.
//!
//! ## The model
//! A pixel at image point `x` (pixel centres at integers) reads `a + c * B(u)`, where `u` is
//! `x` in grid coordinates (cells; the detected corners sit at the border's outer corners,
//! see [`Family::quad_offset`]) and `B` is the blurred pattern (1 white, 0 black). The blur
//! is a Gaussian (the optics and the pixel's own area together) with a width in grid cells
//! of its own along each grid axis: a motion line or an astigmatic lens blurs one way more
//! than the other, and one width for both read the motion line's 50 m 0.41 % long. The
//! widths are along the grid, exact for a marker seen square on, as every far marker is, and
//! the corners' moves then leave them alone, which keeps the derivatives simple. A Gaussian
//! over a grid of squares is separable, so `B` and its derivatives are sums of products of
//! normal-distribution differences along the two axes.
//!
//! ## Cost and bounds
//! Only markers whose longest side is at most [`MAX_SIDE_PX`] are fitted; above it the edge
//! search is already within a tenth of a percent. At most [`MAX_PIXELS`] pixels, those near
//! the pattern's edges (a fixed scatter of them on the larger markers), and [`ITERATIONS`]
//! iterations, so the time per marker is bounded whatever the image. A fit is kept only
//! when the model explains the pixels, the blur and contrast are sane and no corner moved
//! more than [`max_corner_shift`]; otherwise the edge corners stand.

// The normal equations are fixed N x N arrays indexed by loop counters below N, and the
// normal tables by an index clamped to their length: never by data.
#![allow(clippy::indexing_slicing)]

mod model;
mod solve;

use super::contour::Tracer;
use super::Detection;
use crate::family::Family;
use crate::geometry::{Homography, Point};
use crate::image::GrayImage;
use model::Pattern;
use solve::{level_systems, linearise, solve_damped, solve_levels, LevelSystem, Pass};

/// Longest marker side (pixels) that is fitted. At 40 pixels a cell of an 8-cell border
/// square is 5 pixels, wider than any blur, and the edge search is unbiased there.
pub const MAX_SIDE_PX: f32 = 40.0;
/// Most pixels one fit reads: those near the pattern's edges (see `window`), a fixed scatter
/// of them when there are more. Measured in the tests, the scale is within 0.15 % at 11
/// pixels across with 128 pixels (96 gave 0.29 %, and a regular lattice of 96 0.35 %: it
/// beats against the cell grid). A fit costs about 2,400 Cortex-M7 instructions per
/// pixel and pass, its window and solves included.
pub const MAX_PIXELS: usize = 128;
/// Levenberg-Marquardt steps. The edge corners start within a few tenths of a pixel and the
/// model is smooth there: three steps converge to about a hundredth of a pixel (the last
/// one's cost is evaluated without derivatives, only to keep or refuse it).
pub const ITERATIONS: usize = 3;
/// Range of the fitted contrast, as a multiple of the decoder's measure of it (a mean over
/// blurred cells: lower than the real contrast on a small marker, never far above it).
const CONTRAST_RANGE: (f32, f32) = (0.5, 4.0);
/// Largest residual RMS a fit may leave, as a fraction of the fitted contrast.
const MAX_RESIDUAL_OF_CONTRAST: f32 = 0.15;
/// Starting Levenberg-Marquardt damping of the normal equations' diagonal: keeps a step
/// finite when a parameter is barely observed (the outside level of a marker in a wide
/// margin).
const DAMPING: f32 = 1e-3;
/// A fit that moves a corner further than [`max_corner_shift`] (pixels) is not the small
/// correction it is for (a wrong decode, an occluded marker, clutter beside the marker that
/// the model has no level for): refused. The bound is this many pixels on a marker of 20
/// pixels and above; on a smaller one, this times 20 over its longest side, up to
/// [`MAX_CORNER_SHIFT_PX`]. The edge search's corners are off by more the smaller the marker
/// and the more its image is formed otherwise than by a plain Gaussian blur: a gamma-encoded
/// camera moves each edge of a 14-pixel marker towards its dark side, its corners 0.2-0.7 px
/// inward, which the fit must be allowed to correct (at 0.6 px it refused most of those
/// fits, and the range read 1.7-2.4 % long; `docs/accuracy.md`, "Through other lenses and
/// cameras"). On markers of 19-21 pixels on a printed margin beside grass, fits that moved a
/// corner 0.7-0.9 px made it worse (`hard_stills --class small`): there the edge corners
/// stand.
pub const MIN_CORNER_SHIFT_PX: f32 = 0.6;
/// The largest [`max_corner_shift`], on markers of 12 pixels and below.
pub const MAX_CORNER_SHIFT_PX: f32 = 1.0;
/// Longest side (pixels) from which the bound is [`MIN_CORNER_SHIFT_PX`].
const FULL_SHIFT_SIDE_PX: f32 = 20.0;

/// How far (pixels) a fit may move a corner of a marker whose longest side is `side` pixels.
pub(crate) fn max_corner_shift(side: f32) -> f32 {
    (MIN_CORNER_SHIFT_PX * FULL_SHIFT_SIDE_PX / side.max(1.0))
        .clamp(MIN_CORNER_SHIFT_PX, MAX_CORNER_SHIFT_PX)
}
/// Work units of one fit (see `DetectorConfig::work_budget_per_pixel`; one unit is 40 to
/// 100 Cortex-M7 instructions). Measured on the Cortex-M7 benchmark (`bench/m7`,
/// qvga-far-1: one tag36h11 of 14 pixels): about 1.15 million instructions for its pixels,
/// the levels' pass and four passes of the model, 12,500 units at the 90 instructions a unit
/// of the first measurement (0.90 million and 10,000 units before the printed bands; a fit
/// never reads more pixels than there). It is charged before it starts and skipped when the
/// frame's budget cannot pay for it.
pub const WORK_PATTERN_FIT: u32 = 12_500;
/// Most cells per side of a family grid the fit models.
const MAX_GRID: usize = 16;
/// Blur range (pixels) a fit may end in: below, the pixel's own area; above, the marker is
/// not resolved.
const BLUR_RANGE_PX: (f32, f32) = (0.25, 3.0);
/// The Gaussian is summed over this many of its widths on either side of a point.
const WINDOW_SIGMAS: f32 = 3.0;
/// Most cells one axis of the window may cover: a blur of up to 1.1 cells (a marker of 8
/// cells blurred by 1.2 pixels is 9 pixels across, the smallest the detector finds).
const MAX_WINDOW: usize = 8;
/// Blur the fit starts from (pixels): typical of a small lens at focus.
const INITIAL_BLUR_PX: f32 = 0.8;
/// Parameters: 4 corners (x, y), the blur along the grid's u and v axes (the logarithm of its
/// width in grid cells: always positive, and a step of a given size means the same at any
/// blur), black level, contrast,
/// the outside level of each side ([`model::SIDES`], from `OUTSIDE` on) and the width (cells)
/// of the white printed band between the known area and that level on each side (from
/// `BAND` on).
const N: usize = 12 + 2 * model::SIDES;
const BLUR: usize = 8;
const BLUR_V: usize = 9;
const BLACK: usize = 10;
const CONTRAST: usize = 11;
const OUTSIDE: usize = 12;
const BAND: usize = OUTSIDE + model::SIDES;
/// Weight of the pull of each side's outside level towards the mean of the four, in pixels
/// that lie wholly beyond that side: it keeps a side no pixel measures (a marker at the
/// image's edge) at the others' level, and is too weak to hold a side that a row of pixels
/// measures (the tests' scale errors moved by under 0.01 % between 0.5 and 8).
const OUTSIDE_PULL: f32 = 0.5;

/// Weight of the pull of each printed band's width towards none, in pixels that lie wholly
/// in it: it keeps a width no pixel measures (a band on a side whose level is as white as
/// the paper, or wider than the window) from wandering, and is far too weak to hold one that
/// a pixel sees (a stronger pull held two-cell bands near one, and the scale of the smallest
/// markers out: `a_printed_margin_of_any_width_leaves_the_scale_unbiased`).
const BAND_PULL: f32 = 1e-4;
/// Widest printed band the fit may end with, cells: the window reaches about two cells
/// beyond the known area on the smallest markers, and nothing further is measured.
const MAX_BAND_CELLS: f32 = 3.0;
/// Largest change of a band's width (cells) in one step: the model is linear in a band's
/// edge only within about the blur's width of it.
const MAX_BAND_STEP_CELLS: f32 = 0.5;
/// Band widths (cells) the fit may start from: the one whose solved levels leave the least
/// residual (see `fit`). The first is none: on a marker whose cells are wider than
/// [`EDGE_REACH_PX`], the only one (see `fit`).
const BAND_STARTS: [f32; 3] = [0.0, 1.0, 2.0];

/// One pixel a fit reads: its position and grey level.
#[derive(Debug, Clone, Copy)]
struct Sample {
    x: u16,
    y: u16,
    value: u8,
}

/// The pixels a fit reads, chosen once from the start corners so that every pass reads the
/// same ones: those of the marker's box within reach of an edge of the pattern (a change of
/// colour, or the end of the known area). Only they tell where the edges are; a uniform
/// sample of a large, sharp marker had so few of them that its corners drifted by half a
/// pixel in a flat cost. When there are more than [`MAX_PIXELS`], a fixed scatter (a hash of
/// the position, which unlike a lattice cannot beat against the cell grid) keeps that many.
struct Window {
    samples: heapless::Vec<Sample, MAX_PIXELS>,
}

/// Distance from a pattern edge (pixels) within which a pixel is read: the blur's reach (2.5
/// of the widest blur the fit starts near) and the pixel's own half width.
const EDGE_REACH_PX: f32 = 2.5;

/// The window of the marker at `corners`, whose cells are `cell_px` pixels across.
fn window(
    image: &GrayImage<'_>,
    pattern: &Pattern,
    corners: &[Point; 4],
    cell_px: f32,
) -> Option<Window> {
    let to_image = Homography::from_4_points(&pattern.corner_points(), corners)?;
    let to_grid = Homography::from_4_points(corners, &pattern.corner_points())?;
    let c = pattern.side as f32;
    let (mut lo_x, mut lo_y, mut hi_x, mut hi_y) = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
    for (u, v) in [(0.0, 0.0), (c, 0.0), (c, c), (0.0, c)] {
        let p = to_image.map(u, v)?;
        lo_x = lo_x.min(p.x);
        lo_y = lo_y.min(p.y);
        hi_x = hi_x.max(p.x);
        hi_y = hi_y.max(p.y);
    }
    // The blur reaches a little beyond the known area: read it, the outside levels and the
    // bands model it.
    let pad = 1.5;
    let x0 = libm::floorf(lo_x - pad).max(0.0);
    let y0 = libm::floorf(lo_y - pad).max(0.0);
    let x1 = libm::ceilf(hi_x + pad).min(image.width() as f32 - 1.0);
    let y1 = libm::ceilf(hi_y + pad).min(image.height() as f32 - 1.0);
    if !(x1 > x0 && y1 > y0) || x1 > f32::from(u16::MAX) || y1 > f32::from(u16::MAX) {
        return None;
    }
    let (x0, y0, x1, y1) = (x0 as usize, y0 as usize, x1 as usize, y1 as usize);
    // The reach in grid cells: pixels times cells per pixel.
    let reach = EDGE_REACH_PX / cell_px;
    // A pixel is near an edge when the colour (None beyond the known area) at its grid point
    // differs from the colour `reach` cells away along either grid axis.
    let near_edge = |x: usize, y: usize| -> bool {
        let Some(g) = to_grid.map(x as f32, y as f32) else {
            return false;
        };
        let here = pattern.colour_at(g.x, g.y);
        [(reach, 0.0), (-reach, 0.0), (0.0, reach), (0.0, -reach)]
            .iter()
            .any(|(du, dv)| pattern.colour_at(g.x + du, g.y + dv) != here)
    };
    let mut edges = 0usize;
    for y in y0..=y1 {
        for x in x0..=x1 {
            edges += usize::from(near_edge(x, y));
        }
    }
    let step = edges.div_ceil(MAX_PIXELS).max(1);
    let mut samples = heapless::Vec::new();
    'rows: for y in y0..=y1 {
        let row = image.row(y);
        for x in x0..=x1 {
            if !scattered(x, y, step) || !near_edge(x, y) {
                continue;
            }
            let value = row.get(x).copied().unwrap_or(0);
            if samples
                .push(Sample {
                    x: x as u16,
                    y: y as u16,
                    value,
                })
                .is_err()
            {
                break 'rows;
            }
        }
    }
    Some(Window { samples })
}

/// Whether pixel (x, y) is in a fixed scatter of one pixel in `step`.
fn scattered(x: usize, y: usize, step: usize) -> bool {
    if step <= 1 {
        return true;
    }
    let h = (x as u32).wrapping_mul(0x9E37_79B1) ^ (y as u32).wrapping_mul(0x85EB_CA77);
    let h = h ^ (h >> 15);
    (h.wrapping_mul(0x2C1B_3C6D) >> 16).is_multiple_of(step as u32)
}

/// The mean side of a quad, pixels.
fn mean_side(c: &[Point; 4]) -> f32 {
    0.25 * (0..4).map(|k| c[k].distance(c[(k + 1) % 4])).sum::<f32>()
}

/// The corners in a parameter vector.
fn fitted_corners(params: &[f32; N]) -> [Point; 4] {
    let mut corners = [Point::default(); 4];
    for (k, c) in corners.iter_mut().enumerate() {
        *c = Point::new(params[2 * k], params[2 * k + 1]);
    }
    corners
}

/// Whether a marker at `corners` is small enough to be fitted.
pub(crate) fn fits(corners: &[Point; 4]) -> bool {
    longest_side(corners) <= MAX_SIDE_PX
}

/// The longest side of a quad, pixels.
pub(crate) fn longest_side(corners: &[Point; 4]) -> f32 {
    (0..4)
        .map(|k| corners[k].distance(corners[(k + 1) % 4]))
        .fold(0.0, f32::max)
}

/// Why a fit was not kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Refusal {
    /// The marker is larger than [`MAX_SIDE_PX`].
    Large,
    /// The family's layout is not modelled, or the id is unknown.
    Layout,
    /// The marker's image is degenerate or outside the image.
    Geometry,
    /// The normal equations were singular.
    Singular,
    /// The model does not explain the pixels.
    Residual,
    /// The blur or the contrast ended outside their ranges.
    Levels,
    /// A corner moved more than [`max_corner_shift`].
    Moved,
}

/// Corners of the decoded marker `id` of `family` at `corners` (detection order), fitted to
/// the pixels as the module docs describe, with the image of the marker's centre; or why
/// the fit was refused (the marker is not small, its family's layout is not modelled, the
/// model does not fit). `contrast` (grey levels, the decoder's) checks the fitted contrast.
pub(crate) fn fit(
    image: &GrayImage<'_>,
    family: &Family<'_>,
    id: u16,
    corners: &[Point; 4],
    contrast: f32,
) -> Result<([Point; 4], Point), Refusal> {
    let side = longest_side(corners);
    if side > MAX_SIDE_PX {
        return Err(Refusal::Large);
    }
    let pattern = Pattern::new(family, id).ok_or(Refusal::Layout)?;
    let cell_px = mean_side(corners) / (pattern.quad_hi - pattern.quad_lo);
    if !(cell_px > 0.0) {
        return Err(Refusal::Geometry);
    }
    let win = window(image, &pattern, corners, cell_px).ok_or(Refusal::Geometry)?;
    let mut params = [0.0f32; N];
    for (k, c) in corners.iter().enumerate() {
        params[2 * k] = c.x;
        params[2 * k + 1] = c.y;
    }
    params[BLUR] = libm::logf(INITIAL_BLUR_PX / cell_px);
    params[BLUR_V] = params[BLUR];
    // The levels enter the model linearly: solved exactly for the start geometry and blur
    // (the outside level stays white, a printed margin, when no pixel lies beyond the known
    // area to measure it).
    for level in params.iter_mut().skip(OUTSIDE).take(model::SIDES) {
        *level = 1.0;
    }
    // A band's outer edge is a step one or two cells beyond the known area, too far from a
    // start of none for the steps to find (from none, a two-cell band ended near one): the
    // start is the width among `BAND_STARTS`, the same on every side, whose solved levels
    // leave the least residual (one pass for all of them). Where a cell is wider than the
    // pixels read reach, a band of a cell or more ends beyond them and its solved levels say
    // nothing of it (started there, the corners of markers of 24-32 pixels moved:
    // `recall_report`); such a marker starts from none, and a narrower band, whose edge the
    // pixels do see, is fitted from there.
    let starts = if cell_px <= EDGE_REACH_PX {
        &BAND_STARTS[..]
    } else {
        &BAND_STARTS[..1]
    };
    let mut systems = [LevelSystem::default(); BAND_STARTS.len()];
    level_systems(&pattern, &win, &params, starts, &mut systems).ok_or(Refusal::Geometry)?;
    let mut best: Option<(f32, [f32; N])> = None;
    for (system, &band) in systems.iter().zip(starts.iter()) {
        let mut trial = params;
        for width in trial.iter_mut().skip(BAND) {
            *width = band;
        }
        if let Ok(residual) = solve_levels(system, &mut trial) {
            if best.as_ref().is_none_or(|(r, _)| residual < *r) {
                best = Some((residual, trial));
            }
        }
    }
    params = best.ok_or(Refusal::Levels)?.1;
    // Levenberg-Marquardt: the start is within a few tenths of a pixel, where the model is
    // nearly linear and the first step usually lands. A step that does not lower the cost
    // is taken back and retried shorter.
    let mut current = linearise(&pattern, &win, &params, Pass::Full).ok_or(Refusal::Geometry)?;
    let mut damping = DAMPING;
    for iteration in 0..ITERATIONS {
        let mut step =
            solve_damped(&current.jtj, &current.jte, damping).ok_or(Refusal::Singular)?;
        for d in step.iter_mut().skip(BAND) {
            *d = d.clamp(-MAX_BAND_STEP_CELLS, MAX_BAND_STEP_CELLS);
        }
        let mut trial = params;
        for (p, d) in trial.iter_mut().zip(step.iter()) {
            *p += d;
        }
        let last = iteration + 1 == ITERATIONS;
        let pass = if last { Pass::Cost } else { Pass::Full };
        match linearise(&pattern, &win, &trial, pass) {
            Some(next) if next.cost < current.cost => {
                params = trial;
                current = next;
                damping = (damping * 0.1).max(DAMPING * 1e-3);
            }
            _ => damping *= 10.0,
        }
    }
    // The model must explain the pixels: a residual of a few grey levels (sensor noise and
    // the blur's shape), far below the contrast. A wrong pattern or clutter does not fit.
    let rms = libm::sqrtf(current.cost / current.count.max(1) as f32);
    if !(rms < MAX_RESIDUAL_OF_CONTRAST * params[CONTRAST]) {
        return Err(Refusal::Residual);
    }
    let fitted = fitted_corners(&params);
    let cells = pattern.quad_hi - pattern.quad_lo;
    let blur = libm::expf(0.5 * (params[BLUR] + params[BLUR_V])) * mean_side(&fitted) / cells;
    // The fitted contrast must be the marker's: a fit that flattened it found something else.
    let contrast_ratio = params[CONTRAST] / contrast.max(1.0);
    let within = |x: f32, (lo, hi): (f32, f32)| x >= lo && x <= hi;
    if !within(blur, BLUR_RANGE_PX) || !within(contrast_ratio, CONTRAST_RANGE) {
        return Err(Refusal::Levels);
    }
    let bound = max_corner_shift(side);
    if fitted
        .iter()
        .zip(corners.iter())
        .any(|(f, c)| !(f.distance(*c) <= bound))
    {
        return Err(Refusal::Moved);
    }
    // The centre as the decoder maps it: the grid's middle through the corner homography.
    let middle = 0.5 * pattern.side as f32;
    let center = Homography::from_4_points(&pattern.corner_points(), &fitted)
        .and_then(|h| h.map(middle, middle))
        .ok_or(Refusal::Geometry)?;
    Ok((fitted, center))
}

/// Step 7 over a frame's `detections`: fits the largest marker when every marker of the
/// frame is small. The largest sets the pad fix's scale (its corners are the farthest
/// apart; a larger marker, or the spread of several, would set it better than any small
/// marker's own size), and one fit a frame keeps a frame of many small look-alikes from
/// paying for many. Charges [`WORK_PATTERN_FIT`] to `tracer`, and fits nothing when the
/// budget cannot pay. Returns whether the largest marker's corners were replaced.
pub(super) fn fit_small_markers(
    image: &GrayImage<'_>,
    families: &[&Family<'_>],
    detections: &mut [Detection],
    tracer: &mut Tracer<'_>,
) -> bool {
    let mut largest: Option<(&mut Detection, f32)> = None;
    for d in detections.iter_mut() {
        let side = longest_side(&d.corners);
        if side > MAX_SIDE_PX {
            return false;
        }
        if largest.as_ref().is_none_or(|(_, s)| side > *s) {
            largest = Some((d, side));
        }
    }
    let Some((detection, _)) = largest else {
        return false;
    };
    let Some(family) = families.get(usize::from(detection.family)) else {
        return false;
    };
    if !tracer.charge(WORK_PATTERN_FIT) {
        return false;
    }
    let Ok((corners, center)) = fit(
        image,
        family,
        detection.id,
        &detection.corners,
        detection.contrast,
    ) else {
        return false;
    };
    detection.corners = corners;
    detection.center = center;
    true
}

#[cfg(test)]
pub(super) mod tests;
