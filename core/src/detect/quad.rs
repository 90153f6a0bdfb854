//! Step 3: from a boundary to a four-corner shape.
//!
//! The paper's step: Douglas-Peucker simplification of the closed boundary, keeping shapes
//! with four corners. The closed curve is split at two far-apart points and each half is
//! simplified chord by chord along it, each vertex found inserted into a sorted list of
//! fixed capacity (no recursion, no stack). A corner
//! rounded by blur can come out as two vertices; the vertex that bends the outline least is
//! then dropped while it stays within the tolerance.
//!
//! A shape is a candidate when it is convex, every edge is at least `min_edge` pixels, no
//! angle is sharper than [`MIN_ANGLE_COS`] allows, and its sides are not wildly unequal.
//! The corners are returned clockwise on screen (y down), the order of the canonical corners
//! top-left, top-right, bottom-right, bottom-left.
//!
//! No square roots: every length here is only compared (screening and the chord test on
//! squared integer distances, the vertex drop on squared bends, the shape check on squared
//! lengths). libm's `sqrtf` is software on the Cortex-M7 and micromath's is an approximation
//! that would move the limits and drop other vertices; the squared forms are exact and
//! cheaper than either (the costs and errors: `docs/design/floating-point.md`).

use super::contour::Pixel;
use crate::geometry::Point;
use crate::geometry::{cyclic, quad_area};

/// Most Douglas-Peucker vertices kept before a boundary is given up as not a quad.
const MAX_VERTICES: usize = 12;
/// Tolerance as a fraction of the boundary length (OpenCV ArUco uses 0.03 of the perimeter).
const TOLERANCE_PER_PIXEL: f32 = 0.02;
/// Smallest tolerance, pixels.
const MIN_TOLERANCE: f32 = 1.0;
/// |cos| of the sharpest and flattest accepted corner angle (about 10 and 170 degrees): a
/// marker seen 80 degrees off its normal along its diagonal has corners of 13-16 degrees.
pub(crate) const MIN_ANGLE_COS: f32 = 0.985;
/// Longest over shortest edge.
const MAX_EDGE_RATIO: f32 = 12.0;

/// A convex four-corner candidate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Quad {
    /// Clockwise on screen.
    pub corners: [Point; 4],
    /// The boundary encloses a light region (a hole of a dark one).
    pub hole: bool,
}

fn pt(p: Pixel) -> Point {
    Point::new(p.x as f32, p.y as f32)
}

/// The square of the distance from `p` to the line through `a` and `b` (of the distance to
/// `a` when they coincide). Squared: the fit only compares these (with each other and with a
/// limit), and a square root is software on the Cortex-M7 (libm's; micromath's is too far
/// off, and would pick a different vertex to drop).
fn line_distance_squared(p: Point, a: Point, b: Point) -> f32 {
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    let len2 = dx * dx + dy * dy;
    if len2 < 1e-12 {
        return p.distance_squared(a);
    }
    let cross = (p.x - a.x) * dy - (p.y - a.y) * dx;
    cross * cross / len2
}

fn cross(o: Point, a: Point, b: Point) -> f32 {
    (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
}

/// [`signed_area2_i32`] widened, for the tests' exact 64-bit sums.
#[cfg(test)]
pub(crate) fn signed_area2(contour: &[Pixel]) -> i64 {
    i64::from(signed_area2_i32(contour))
}

/// Twice the signed area of the boundary polygon: positive when it runs clockwise on
/// screen (an outer boundary), negative for a hole. An `i32`, which it fits (below): the
/// screening converts it to `f32` in one instruction, where an `i64` needs a software
/// conversion on the Cortex-M7.
fn signed_area2_i32(contour: &[Pixel]) -> i32 {
    // The shoelace sum in wrapping 32-bit arithmetic: its partial sums may wrap, but the
    // total, twice the area of a polygon inside a frame of at most `image::MAX_DIMENSION`
    // pixels a side (2 * 8192^2 < 2^31), fits an i32, so modulo 2^32 it comes out exact.
    // Absolute coordinates, a multiply and a multiply-subtract a pixel: this runs on every
    // boundary long enough to be screened, most of a noisy frame's screening (32-bit
    // products are half the instructions of 64-bit ones on the Cortex-M7).
    let (Some(first), Some(last)) = (contour.first(), contour.last()) else {
        return 0;
    };
    let xy = |p: &Pixel| (i32::from(p.x), i32::from(p.y));
    // The closing term, from the last pixel back to the first.
    let ((fx, fy), (lx, ly)) = (xy(first), xy(last));
    let mut acc = lx.wrapping_mul(fy).wrapping_sub(fx.wrapping_mul(ly));
    let (mut px, mut py) = (fx, fy);
    for p in contour.get(1..).unwrap_or(&[]) {
        let (x, y) = xy(p);
        acc = acc
            .wrapping_add(px.wrapping_mul(y))
            .wrapping_sub(x.wrapping_mul(py));
        (px, py) = (x, y);
    }
    acc
}

/// The boundary at positions `from..to` counted from index 0 of `contour` and wrapping
/// around its end once, as up to two slices in order.
fn wrapped_span(contour: &[Pixel], from: usize, to: usize) -> (&[Pixel], &[Pixel]) {
    let n = contour.len();
    if to <= n {
        (contour.get(from..to).unwrap_or(&[]), &[])
    } else if from >= n {
        (contour.get(from - n..to - n).unwrap_or(&[]), &[])
    } else {
        (
            contour.get(from..).unwrap_or(&[]),
            contour.get(..to - n).unwrap_or(&[]),
        )
    }
}

/// The boundary point strictly between positions `i` and `j` (counted from `origin`) that
/// lies farthest from the chord between them, if it is farther than `tolerance`.
///
/// Integer arithmetic on the pixel coordinates (this loop is most of the fit's time on a
/// noisy frame): the distance is compared as the cross product against the tolerance times
/// the chord length, so there is no division per point. The products fit in `i32` because
/// the boundary lies in a frame of at most [`crate::image::MAX_DIMENSION`] pixels a side:
/// each is below 8192^2 and their difference below 2^31.
fn farthest_from_chord(
    contour: &[Pixel],
    origin: usize,
    i: usize,
    j: usize,
    tolerance: f32,
) -> Option<usize> {
    let n = contour.len();
    // Positions are below 2n (origin < n, i < j <= n): one subtraction wraps them.
    let pixel = |t: usize| {
        let t = if t >= n { t - n } else { t };
        contour.get(t).copied().unwrap_or_default()
    };
    let (a, b) = (pixel(origin + i), pixel(origin + j));
    let (ax, ay) = (i32::from(a.x), i32::from(a.y));
    let (dx, dy) = (i32::from(b.x) - ax, i32::from(b.y) - ay);
    let (first, second) = wrapped_span(contour, origin + i + 1, origin + j);
    let (best, k, limit2) = if dx == 0 && dy == 0 {
        // The chord is a single point (a thin boundary coming back to the same pixel): the
        // distance to it, squared.
        let measure = |p: &Pixel| {
            let (ex, ey) = (i32::from(p.x) - ax, i32::from(p.y) - ay);
            ex.wrapping_mul(ex).wrapping_add(ey.wrapping_mul(ey))
        };
        let (best, k) = farthest_of(first, second, measure);
        (best, k, tolerance * tolerance * tolerance * tolerance)
    } else {
        // The distance to the chord's line scaled by its length, as x dy - y dx less the
        // chord's own value: a multiply and a multiply-subtract a point.
        let c = ax.wrapping_mul(dy).wrapping_sub(ay.wrapping_mul(dx));
        let measure = |p: &Pixel| {
            i32::from(p.x)
                .wrapping_mul(dy)
                .wrapping_sub(i32::from(p.y).wrapping_mul(dx))
                .wrapping_sub(c)
                .wrapping_abs()
        };
        let (best, k) = farthest_of(first, second, measure);
        let (fx, fy) = (dx as f32, dy as f32);
        (best, k, tolerance * tolerance * (fx * fx + fy * fy))
    };
    // Squared on both sides: no square root per chord.
    let best2 = (best as f32) * (best as f32);
    (best2 > limit2).then_some(i + 1 + k)
}

/// The largest `measure` over the points of `first` then `second` (above 0) and the first
/// position at which it is reached, counted from the start of `first`; (0, 0) when none is
/// above 0.
#[inline(always)]
fn farthest_of(first: &[Pixel], second: &[Pixel], measure: impl Fn(&Pixel) -> i32) -> (i32, usize) {
    let mut best = (0i32, 0usize);
    for (k, p) in first.iter().enumerate() {
        let m = measure(p);
        if m > best.0 {
            best = (m, k);
        }
    }
    for (k, p) in second.iter().enumerate() {
        let m = measure(p);
        if m > best.0 {
            best = (m, first.len() + k);
        }
    }
    best
}

/// Douglas-Peucker vertices of the closed boundary, as positions `t` along it counted from
/// `origin`, ascending (the first `count` of the array); `None` when it needs more than
/// [`MAX_VERTICES`] ([`simplify_streaming`], the whole held). Positions are kept as `u16` (a
/// boundary holds at most [`super::MAX_CONTOUR_POINTS`] points): the array is then zeroed in
/// three stores, where one of `usize` took a memset call per fit.
fn simplify(
    contour: &[Pixel],
    origin: usize,
    split: usize,
    tolerance: f32,
) -> Option<([u16; MAX_VERTICES], usize)> {
    let mut vertices = [0u16; MAX_VERTICES];
    let mut count = 0usize;
    // Held whole: a boundary that needs more vertices is no quad, and is given up as soon as
    // it does (most boundaries of a noisy frame end here).
    let whole = simplify_streaming::<MAX_VERTICES>(contour, origin, split, tolerance, false, |t| {
        let Some(slot) = vertices.get_mut(count) else {
            return false;
        };
        *slot = t;
        count += 1;
        true
    });
    whole.then_some((vertices, count))
}

/// Most points [`roughly_convex`] samples along a boundary.
const CONVEXITY_SAMPLES: usize = 16;
/// Fewest boundary steps between two samples of [`roughly_convex`]: a chord of four or more
/// pixels along a digital straight edge is off its direction by at most atan(1/4), 14
/// degrees, so two such chords turn the wrong way by at most 28 degrees on a straight edge.
const CONVEXITY_MIN_SPACING: usize = 4;
/// sin^2 of the sharpest concave turn [`roughly_convex`] accepts between two chords: 60
/// degrees, twice the digitisation's worst case, so thresholding jitter and a dent of a
/// pixel or two in a marker's outline pass while the ragged outline of a noise blob does not.
const CONVEXITY_MAX_CONCAVE_SIN2: f32 = 0.75;

/// Whether the boundary, sampled at up to [`CONVEXITY_SAMPLES`] evenly spaced points, turns
/// one way only (up to digitisation): a quad's outline does, the outline of a noise blob or
/// of texture almost never. `clockwise` is the orientation of a convex outline (the sign of
/// [`signed_area2_i32`]).
///
/// This is the cheap test in front of Douglas-Peucker: it costs a few hundred instructions
/// whatever the boundary's length, while the fit scans the boundary five to eight times. On a
/// frame of noise most boundaries long enough to be a marker fail it.
fn roughly_convex(contour: &[Pixel], clockwise: bool) -> bool {
    let n = contour.len();
    let k = (n / CONVEXITY_MIN_SPACING).min(CONVEXITY_SAMPLES);
    if k < 4 {
        return true;
    }
    let sample = |j: usize| {
        let p = contour.get(j * n / k).copied().unwrap_or_default();
        (i32::from(p.x), i32::from(p.y))
    };
    let (mut a, mut b) = (sample(k - 2), sample(k - 1));
    for j in 0..k {
        let c = sample(j);
        let (ux, uy) = (b.0 - a.0, b.1 - a.1);
        let (vx, vy) = (c.0 - b.0, c.1 - b.1);
        // Screen coordinates (y down): a clockwise outline turns with cross > 0.
        let cross = (ux * vy - uy * vx) as f32;
        let concave = if clockwise { cross < 0.0 } else { cross > 0.0 };
        if concave {
            let (u2, v2) = ((ux * ux + uy * uy) as f32, (vx * vx + vy * vy) as f32);
            if cross * cross > CONVEXITY_MAX_CONCAVE_SIN2 * u2 * v2 {
                return false;
            }
        }
        (a, b) = (b, c);
    }
    true
}

/// Squared ratio of the smallest boundary diameter to `min_edge` that can hold a quad with
/// every side at least `min_edge`: 2 exactly (a square), 1.9 to stay clear of rounding.
const MIN_DIAMETER_PER_EDGE2: f32 = 1.9;

/// Smallest twice-area over squared boundary length of a candidate (see [`screen`]): a
/// square traced along its axes gives 1/8, at 45 degrees 1/4, a 1:8 rectangle 1/20, a marker
/// seen 80 degrees off its normal along its diagonal (a rhombus, diagonals about 1:6) about
/// 1/33 at its ideal outline; the traced one, widened by blur, a little less.
const COMPACTNESS: f32 = 0.025;

/// A boundary that passed [`screen`]: worth the Douglas-Peucker fit ([`fit`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Screened {
    /// The boundary encloses a light region.
    hole: bool,
    /// The boundary's length, pixels (steps): its points may be a thinned-out sample.
    length: usize,
    /// Index of one end of the boundary's diameter, where the fit starts.
    origin: usize,
    /// Position of the other end, counted from `origin`.
    split: usize,
    /// Twice the signed area the boundary encloses ([`signed_area2_i32`]).
    pub area2: i32,
}

/// A boundary that failed [`screen`], with what the screening measured of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Unscreened {
    /// Twice the signed area the boundary encloses ([`signed_area2_i32`]); 0 when it was
    /// too short to be measured.
    pub area2: i32,
}

/// Fits a candidate quad to a closed boundary ([`screen`], then [`fit`]).
#[cfg(test)]
pub(crate) fn fit_quad(contour: &[Pixel], min_edge: f32) -> Option<Quad> {
    fit(
        contour,
        &screen(contour, contour.len(), min_edge, true).ok()?,
        min_edge,
    )
}

/// The cheap tests a boundary must pass before the fit, a few instructions per boundary
/// pixel (priced by [`super::WORK_SCREEN_PIXELS`]): long enough, compact, roughly convex
/// (when `convex`: markers with a quiet margin have a straight outline; tagStandard41h12's
/// data cells outside its border make a bumpy one), wide enough for four sides of
/// `min_edge`. Most boundaries of a
/// cluttered or noisy frame stop here.
///
/// `contour` is the boundary's pixels in order, every one of them or (a boundary longer
/// than the detector's buffer) evenly spaced ones; `length` is its length in steps.
pub(crate) fn screen(
    contour: &[Pixel],
    length: usize,
    min_edge: f32,
    convex: bool,
) -> Result<Screened, Unscreened> {
    let n = length.max(contour.len());
    // An edge of `min_edge` pixels at 45 degrees is min_edge / sqrt(2) steps.
    if (n as f32) < 2.8 * min_edge || contour.len() < 8 {
        return Err(Unscreened { area2: 0 });
    }
    let area2 = signed_area2_i32(contour);
    let unscreened = Unscreened { area2 };
    if area2 == 0 {
        return Err(unscreened);
    }
    // Compactness: a quad's area is a good fraction of its squared perimeter (a 1:8
    // rectangle traced pixel by pixel still has area >= n^2 / 40 for n boundary steps),
    // while noise blobs and thin strokes are ragged outlines around little area. Rejecting
    // them here, before the Douglas-Peucker fit, is most of the cost of a noisy frame.
    if (area2.unsigned_abs() as f32) < COMPACTNESS * (n * n) as f32 {
        return Err(unscreened);
    }
    if convex && !roughly_convex(contour, area2 > 0) {
        return Err(unscreened);
    }
    let hole = area2 < 0;
    let Some((origin, split_abs, split)) = far_apart(contour) else {
        return Err(unscreened);
    };
    // The quad's corners will be boundary pixels, so its diagonals are at most the
    // boundary's diameter; and a convex quad whose sides are all at least `min_edge` has a
    // diagonal of at least sqrt(2) * min_edge (the square is the tightest). A boundary
    // narrower than that cannot pass `check_shape`: stop before the fit (a frame of noise
    // has hundreds of compact blobs just too small to be markers).
    let diameter2 = match (contour.get(origin), contour.get(split_abs)) {
        (Some(a), Some(b)) => {
            let (dx, dy) = (
                f32::from(a.x) - f32::from(b.x),
                f32::from(a.y) - f32::from(b.y),
            );
            dx * dx + dy * dy
        }
        _ => 0.0,
    };
    if diameter2 < MIN_DIAMETER_PER_EDGE2 * min_edge * min_edge {
        return Err(unscreened);
    }
    Ok(Screened {
        hole,
        length: n,
        origin,
        split,
        area2: unscreened.area2,
    })
}

/// Two far-apart boundary points, where the fit splits the boundary: the farthest from the
/// first point (`origin`) and the farthest from that (at index `split_abs`, or `split`
/// counted from `origin`); `None` when they coincide.
#[inline(always)]
fn far_apart(contour: &[Pixel]) -> Option<(usize, usize, usize)> {
    // Squared integer distances: this runs on every screened boundary (thousands on a noisy
    // frame), and a square root per pixel was most of its cost on the Cortex-M7.
    let farthest = |from: usize| -> usize {
        let Some(f) = contour.get(from) else {
            return 0;
        };
        let (fx, fy) = (i32::from(f.x), i32::from(f.y));
        let mut best = (0i32, 0usize);
        for (t, p) in contour.iter().enumerate() {
            let (dx, dy) = (i32::from(p.x) - fx, i32::from(p.y) - fy);
            let d = dx * dx + dy * dy;
            if d > best.0 {
                best = (d, t);
            }
        }
        best.1
    };
    let origin = farthest(0);
    let split_abs = farthest(origin);
    let points = contour.len();
    let split = (split_abs + points - origin) % points.max(1);
    (split != 0).then_some((origin, split_abs, split))
}

/// Drops the vertex that bends the outline least while more than four remain; false when
/// one that must go bends it by more than twice `tolerance`. Each vertex's bend (the square
/// of its distance from the line through its neighbours) is kept, and only the two
/// neighbours of a dropped vertex are measured again. Not inlined: [`fit`] calls it only
/// when Douglas-Peucker left more than four vertices, and inlined it costs every fit.
#[inline(never)]
fn drop_least_bent(corners: &mut heapless::Vec<Point, MAX_VERTICES>, tolerance: f32) -> bool {
    let bend = |points: &[Point], k: usize| {
        let m = points.len().max(1);
        let point = |i: usize| points.get(i % m).copied().unwrap_or_default();
        line_distance_squared(point(k), point(k + m - 1), point(k + 1))
    };
    let mut bends: heapless::Vec<f32, MAX_VERTICES> = heapless::Vec::new();
    for k in 0..corners.len() {
        let _ = bends.push(bend(corners, k));
    }
    while corners.len() > 4 {
        let (least, bent) = bends
            .iter()
            .enumerate()
            .fold(
                (0usize, f32::MAX),
                |best, (k, &b)| {
                    if b < best.1 {
                        (k, b)
                    } else {
                        best
                    }
                },
            );
        if bent > 4.0 * tolerance * tolerance || least >= corners.len() || least >= bends.len() {
            return false;
        }
        remove(corners, least);
        remove(&mut bends, least);
        let m = corners.len();
        for k in [(least + m - 1) % m, least % m] {
            let b = bend(corners, k);
            if let Some(slot) = bends.get_mut(k) {
                *slot = b;
            }
        }
    }
    true
}

/// Removes item `at` (there must be one), moving the later ones down by one: a loop over
/// the few vertices, where `Vec::remove` called `memmove` (the calls were over a quarter of
/// [`drop_least_bent`]'s cost on a frame of noise, where most fits drop vertices).
fn remove<T: Copy, const N: usize>(items: &mut heapless::Vec<T, N>, at: usize) {
    let slice = items.as_mut_slice();
    for k in at + 1..slice.len() {
        if let Some(&item) = slice.get(k) {
            if let Some(slot) = slice.get_mut(k - 1) {
                *slot = item;
            }
        }
    }
    items.pop();
}

/// The Douglas-Peucker fit of a screened boundary: a convex quad with sides of at least
/// `min_edge`, or nothing.
pub(crate) fn fit(contour: &[Pixel], screened: &Screened, min_edge: f32) -> Option<Quad> {
    let Screened {
        hole,
        length,
        origin,
        split,
        ..
    } = *screened;
    let tolerance = (TOLERANCE_PER_PIXEL * length as f32).max(MIN_TOLERANCE);
    let (vertices, count) = simplify(contour, origin, split, tolerance)?;
    let n = contour.len();
    let corner = |t: u16| {
        // Positions are below n, `origin` too: one subtraction wraps them.
        let t = origin + usize::from(t);
        let t = if t >= n { t - n } else { t };
        contour.get(t).copied().map(pt).unwrap_or_default()
    };
    let mut corners = match (count, vertices) {
        // Most boundaries come out of Douglas-Peucker with four vertices.
        (4, [t0, t1, t2, t3, ..]) => [corner(t0), corner(t1), corner(t2), corner(t3)],
        (5.., _) => {
            // (Filled by pushes and emptied by checked removals: `collect` and `remove` into
            // a heapless vector have panic paths the no-panic check would find.)
            let mut corners: heapless::Vec<Point, MAX_VERTICES> = heapless::Vec::new();
            for &t in vertices.iter().take(count) {
                let _ = corners.push(corner(t));
            }
            if !drop_least_bent(&mut corners, tolerance) {
                return None;
            }
            let [c0, c1, c2, c3] = corners.as_slice() else {
                return None;
            };
            [*c0, *c1, *c2, *c3]
        }
        _ => return None,
    };
    // Clockwise on screen.
    let orientation: f32 = (0..4)
        .map(|k| {
            cross(
                cyclic(&corners, k),
                cyclic(&corners, k + 1),
                cyclic(&corners, k + 2),
            )
        })
        .sum();
    if orientation < 0.0 {
        corners.reverse();
    }
    check_shape(&corners, min_edge).then_some(Quad { corners, hole })
}

/// Most quads [`complete`] finds on one boundary.
pub(crate) const MAX_COMPLETIONS: usize = 2;
/// [`complete`]'s simplification tolerance, pixels: fixed, not a share of the boundary's
/// length, since most of the boundary is not the marker's.
const COMPLETION_TOLERANCE: f32 = 3.0;
/// Shortest whole side of a completed quad, in units of `min_edge`: a marker must be large
/// beside what joins it for three of its corners to place the fourth.
const COMPLETION_SIDE_PER_EDGE: f32 = 6.0;
/// Shortest boundary, in steps per `min_edge`, that [`might_complete`] passes: two whole
/// sides and two thirds of a side, 2.67 sides, at up to sqrt(2) pixels a step (1.9 sides'
/// steps, less a little for rounding).
pub(crate) const MIN_COMPLETION_LENGTH_PER_EDGE: f32 = 1.8 * COMPLETION_SIDE_PER_EDGE;
/// Longest boundary [`complete`] follows, in multiples of the way around its bounding box:
/// a marker's outline with a band or a stroke running off it goes round its box about once,
/// twice with the band's two sides; the ragged blobs of noise and texture many times.
const COMPLETION_MAX_LENGTH_PER_BOX: usize = 2;
/// Smallest twice-area of a completed quad, and of the region whose outline [`complete`]
/// follows, over the squared shortest whole side ([`COMPLETION_SIDE_PER_EDGE`]): half a
/// square of that side, so a square marker at least that large, or a larger one seen
/// obliquely. The region holds the marker (or, for a hole, its margin), so it is at least
/// as large; the rim of a pad or a paper, an L or a strip a few pixels wide, is not.
const COMPLETION_MIN_AREA2_PER_SIDE2: f32 = 1.0;
/// How far the hidden corner may lie from where the outline left each of its sides, as a
/// multiple of the side's visible part (which is then at least a third of the side).
const COMPLETION_MAX_EXTENSION: f32 = 3.0;
/// How far short of where the outline left a side the hidden corner may lie, as a share of
/// the visible part: the simplification places that vertex a pixel or two past the turn.
const COMPLETION_MIN_EXTENSION: f32 = 0.9;

/// Quads whose outline ran into something dark at one corner: a shadow's edge along which
/// the binarisation turned the shadowed paper dark up to the marker's border, a stroke or a
/// skid touching it. The boundary then follows three corners of the marker and leaves the
/// two sides beside the fourth part of the way along them; the fourth corner is where
/// those two sides' lines meet. The refinement then puts every edge on the image's own edge
/// and the decoder decides, as for any candidate.
///
/// For a boundary that did not fit a quad whole and passed [`might_complete`] and
/// [`worth_completing`]: an outer one, or a hole's where holes are followed (a convex dark
/// region's corners turn the same way on either, the walk keeping the dark on one side). It
/// is simplified at a fixed tolerance ([`COMPLETION_TOLERANCE`]) and searched for three consecutive convex
/// corners with two whole sides of at least [`COMPLETION_SIDE_PER_EDGE`] `min_edge` between
/// them, whose outer sides, extended, meet within [`COMPLETION_MAX_EXTENSION`] times their
/// visible length. At most [`MAX_COMPLETIONS`] are returned, in the order found.
pub(crate) fn complete(contour: &[Pixel], min_edge: f32) -> heapless::Vec<Quad, MAX_COMPLETIONS> {
    let mut found = heapless::Vec::new();
    // Both ends of the diameter are extreme points of the boundary, so neither lies inside a
    // straight side: the simplification's forced vertices are true turns.
    let Some((origin, _, split)) = far_apart(contour) else {
        return found;
    };
    let n = contour.len();
    let side = COMPLETION_SIDE_PER_EDGE * min_edge;
    let mut window = Window {
        side2: side * side,
        min_edge,
        last: [Point::default(); 5],
        kept: 0,
        first: [Point::default(); WINDOW_FIRST],
        handed: 0,
        first_window: None,
    };
    let closed = simplify_streaming::<STREAM_DEPTH>(
        contour,
        origin,
        split,
        COMPLETION_TOLERANCE,
        true,
        |t| {
            let t = origin + usize::from(t);
            let t = if t >= n { t - n } else { t };
            let p = contour.get(t).copied().map(pt).unwrap_or_default();
            window.push(p, &mut found);
            true
        },
    );
    if closed {
        // Around the start once more: the windows across position 0, those that end before
        // the vertex that closed the first window tested (all, when none was).
        let first = window.first;
        let again = window
            .first_window
            .map_or(window.handed, |handed| handed.saturating_sub(1));
        for p in first.into_iter().take(again) {
            window.push(p, &mut found);
        }
    }
    found
}

/// The first of [`complete`]'s tests, on what the screening measured: long enough for two
/// whole sides of the smallest completed quad and parts of the other two, and enclosing at
/// least its area ([`COMPLETION_MIN_AREA2_PER_SIDE2`]).
pub(crate) fn might_complete(length: usize, area2: i32, min_edge: f32) -> bool {
    let side = COMPLETION_SIDE_PER_EDGE * min_edge;
    (length as f32) >= MIN_COMPLETION_LENGTH_PER_EDGE * min_edge
        && (area2.unsigned_abs() as f32) >= COMPLETION_MIN_AREA2_PER_SIDE2 * side * side
}

/// The second of [`complete`]'s tests, one pass over the boundary: as wide and as high as a
/// whole side and half of one, and not ragged: a marker's outline, with a band or a stroke
/// running off it, goes round its box about once, twice with the band's two sides
/// ([`COMPLETION_MAX_LENGTH_PER_BOX`]); the blobs of noise and texture many times.
pub(crate) fn worth_completing(contour: &[Pixel], length: usize, min_edge: f32) -> bool {
    let side = COMPLETION_SIDE_PER_EDGE * min_edge;
    let (mut x0, mut y0, mut x1, mut y1) = (u16::MAX, u16::MAX, 0u16, 0u16);
    for p in contour {
        (x0, x1, y0, y1) = (x0.min(p.x), x1.max(p.x), y0.min(p.y), y1.max(p.y));
    }
    let (w, h) = (x1.saturating_sub(x0), y1.saturating_sub(y0));
    let around = 2 * (usize::from(w) + usize::from(h));
    let wide = f32::from(w.max(h)) >= side && f32::from(w.min(h)) >= 0.5 * side;
    wide && length <= COMPLETION_MAX_LENGTH_PER_BOX * around
}

/// Pending vertices of [`simplify_streaming`]: the depth of the chord splitting, not the
/// number of vertices.
const STREAM_DEPTH: usize = 24;

/// Most of a boundary's first vertices [`Window`] keeps to close the loop: the five of the
/// first window and a few the window dropped ([`Window::push`]).
const WINDOW_FIRST: usize = 8;

/// The last five vertices of a boundary's simplification as they come, tested each time
/// for a quad with a hidden corner ([`complete`]).
struct Window {
    /// The shortest whole side, squared.
    side2: f32,
    /// The quad's shortest edge ([`check_shape`]).
    min_edge: f32,
    last: [Point; 5],
    /// Vertices kept so far (the last five of them are `last`).
    kept: usize,
    /// The first vertices handed in, handed in again at the end to close the loop.
    first: [Point; WINDOW_FIRST],
    /// Vertices handed in so far.
    handed: usize,
    /// How many had been handed in when the first window was tested.
    first_window: Option<usize>,
}

impl Window {
    /// Takes the next vertex and adds to `found`, while it has room, the quad that the last
    /// five kept complete.
    ///
    /// Douglas-Peucker keeps the farthest point of each chord, so where blur rounds a corner
    /// it can keep two points on the curve, one a pixel or two off the line through its
    /// neighbours: the corner is then two vertices, and no five consecutive ones hold three
    /// corners. So the last vertex kept is dropped when the next one puts it within the
    /// simplification's own tolerance of the line between its neighbours (`fit` drops such
    /// vertices too, [`drop_least_bent`]).
    fn push(&mut self, p: Point, found: &mut heapless::Vec<Quad, MAX_COMPLETIONS>) {
        if let Some(slot) = self.first.get_mut(self.handed) {
            *slot = p;
        }
        self.handed += 1;
        let [_, _, _, before, last] = self.last;
        let straight = self.kept >= 2
            && line_distance_squared(last, before, p)
                <= COMPLETION_TOLERANCE * COMPLETION_TOLERANCE;
        if straight {
            self.last[4] = p;
        } else {
            self.kept += 1;
            self.last = [self.last[1], self.last[2], self.last[3], self.last[4], p];
        }
        if self.kept < 5 || found.is_full() {
            return;
        }
        if self.first_window.is_none() {
            self.first_window = Some(self.handed);
        }
        let [j1, a, b, c, j2] = self.last;
        // Three convex corners (clockwise on screen, as an outer boundary runs) and two
        // whole sides between them.
        if !(cross(j1, a, b) > 0.0 && cross(a, b, c) > 0.0 && cross(b, c, j2) > 0.0) {
            return;
        }
        if a.distance_squared(b) < self.side2 || b.distance_squared(c) < self.side2 {
            return;
        }
        let Some(x) = hidden_corner(a, j1, c, j2) else {
            return;
        };
        let corners = [a, b, c, x];
        if 2.0 * quad_area(&corners) >= COMPLETION_MIN_AREA2_PER_SIDE2 * self.side2
            && check_shape(&corners, self.min_edge)
        {
            let _ = found.push(Quad {
                corners,
                hole: false,
            });
        }
    }
}

/// Douglas-Peucker vertices of the closed boundary, each handed to `emit` (as its position
/// counted from `origin`, ascending) once no later vertex can come before it; `emit`
/// returns false to stop. With `stream`, only the vertices not yet handed on are held, at
/// most `N`, so a boundary of any number of vertices can be simplified; without it all are
/// held and handed on at the end. False when stopped, or when more than `N` had to be held
/// (the vertices handed on so far are still the boundary's, in order).
///
/// The chords are taken in order along the boundary, each vertex found inserted after the
/// start of its chord and the chord up to it taken next: the vertices stay sorted (no sort,
/// no stack), and each chord is measured once, as with a stack. The vertices before the
/// current chord's start are then final. The vertex set does not depend on the order (a
/// chord's vertex depends on its ends only), nor on `N`.
fn simplify_streaming<const N: usize>(
    contour: &[Pixel],
    origin: usize,
    split: usize,
    tolerance: f32,
    stream: bool,
    mut emit: impl FnMut(u16) -> bool,
) -> bool {
    let n = contour.len();
    let (Ok(split16), true) = (u16::try_from(split), N >= 2) else {
        return false;
    };
    let mut vertices = [0u16; N];
    if let Some(slot) = vertices.get_mut(1) {
        *slot = split16;
    }
    let mut count = 2usize;
    let mut k = 0;
    while k < count {
        let i = usize::from(vertices.get(k).copied().unwrap_or_default());
        let j = vertices
            .get(k + 1)
            .filter(|_| k + 1 < count)
            .map_or(n, |&t| usize::from(t));
        let Some(t) = farthest_from_chord(contour, origin, i, j, tolerance) else {
            k += 1;
            continue;
        };
        if count == N {
            if k == 0 || !stream {
                return false;
            }
            // Hand on the final ones, those before the current chord's start.
            for &v in vertices.iter().take(k) {
                if !emit(v) {
                    return false;
                }
            }
            vertices.copy_within(k..count, 0);
            count -= k;
            k = 0;
        }
        // Insert after vertex k, moving the later ones up by one.
        let Ok(mut carry) = u16::try_from(t) else {
            return false;
        };
        for slot in vertices.iter_mut().take(count + 1).skip(k + 1) {
            carry = core::mem::replace(slot, carry);
        }
        count += 1;
    }
    vertices.iter().take(count).all(|&v| emit(v))
}

/// Where the line from `a` through `j1` meets the line from `c` through `j2`, when that
/// lies beyond both `j1` and `j2` by the visible parts' bounds of [`complete`].
fn hidden_corner(a: Point, j1: Point, c: Point, j2: Point) -> Option<Point> {
    let (ux, uy) = (j1.x - a.x, j1.y - a.y);
    let (vx, vy) = (j2.x - c.x, j2.y - c.y);
    let den = ux * vy - uy * vx;
    if den.abs() < 1e-6 {
        return None;
    }
    let (wx, wy) = (c.x - a.x, c.y - a.y);
    // a + s u = c + t v: s and t in units of the visible parts.
    let s = (wx * vy - wy * vx) / den;
    let t = (wx * uy - wy * ux) / den;
    let bounds = COMPLETION_MIN_EXTENSION..=COMPLETION_MAX_EXTENSION;
    (bounds.contains(&s) && bounds.contains(&t)).then(|| Point::new(a.x + s * ux, a.y + s * uy))
}

/// Convex, edges long enough and not too unequal, no degenerate angle.
///
/// On squared lengths: no square root (software on the Cortex-M7, and four per candidate
/// would be a large share of the fit on a frame of small quads). Every test
/// is the square of the one on lengths (`|cos| > c` as `dot^2 > c^2 e1^2 e2^2`), the same
/// up to rounding.
pub(crate) fn check_shape(c: &[Point; 4], min_edge: f32) -> bool {
    for k in 0..4 {
        if !(cross(cyclic(c, k), cyclic(c, k + 1), cyclic(c, k + 2)) > 0.0) {
            return false;
        }
    }
    // Edge k runs from corner k to corner k + 1.
    let edges2: [f32; 4] = core::array::from_fn(|k| {
        let (a, b) = (cyclic(c, k), cyclic(c, k + 1));
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        dx * dx + dy * dy
    });
    let mut shortest2 = f32::MAX;
    let mut longest2 = 0.0f32;
    for k in 0..4 {
        let (a, b, d) = (cyclic(c, k), cyclic(c, k + 1), cyclic(c, k + 2));
        let e1 = cyclic(&edges2, k);
        let e2 = cyclic(&edges2, k + 1);
        shortest2 = shortest2.min(e1);
        longest2 = longest2.max(e1);
        if e1 < 1e-6 || e2 < 1e-6 {
            return false;
        }
        let dot = (a.x - b.x) * (d.x - b.x) + (a.y - b.y) * (d.y - b.y);
        if dot * dot > MIN_ANGLE_COS * MIN_ANGLE_COS * (e1 * e2) {
            return false;
        }
    }
    // A negative `min_edge` passes any edge, not a number none (as on lengths).
    let long_enough = min_edge <= 0.0 || shortest2 >= min_edge * min_edge;
    long_enough && longest2 <= MAX_EDGE_RATIO * MAX_EDGE_RATIO * shortest2
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Moore boundary of an axis-aligned filled rectangle, clockwise.
    fn rectangle(x0: u16, y0: u16, w: u16, h: u16) -> heapless::Vec<Pixel, 512> {
        let mut v = heapless::Vec::new();
        for x in x0..x0 + w {
            v.push(Pixel { x, y: y0 }).unwrap();
        }
        for y in y0 + 1..y0 + h {
            v.push(Pixel { x: x0 + w - 1, y }).unwrap();
        }
        for x in (x0..x0 + w - 1).rev() {
            v.push(Pixel { x, y: y0 + h - 1 }).unwrap();
        }
        for y in (y0 + 1..y0 + h - 1).rev() {
            v.push(Pixel { x: x0, y }).unwrap();
        }
        v
    }

    /// The 32-bit wrapping shoelace equals the exact 64-bit one, for rectangles at the far
    /// corner of the largest frame (where its partial sums wrap) and for ragged polygons.
    #[test]
    fn signed_area_is_exact_where_partial_sums_wrap() {
        let exact = |c: &[Pixel]| -> i64 {
            let n = c.len();
            (0..n)
                .map(|i| {
                    let (a, b) = (c[i], c[(i + 1) % n]);
                    i64::from(a.x) * i64::from(b.y) - i64::from(b.x) * i64::from(a.y)
                })
                .sum()
        };
        for (x0, y0, w, h) in [
            (10, 20, 30, 25),
            (8000, 8000, 120, 100),
            (0, 8050, 100, 140),
        ] {
            let c = rectangle(x0, y0, w, h);
            let area = signed_area2(&c);
            assert_eq!(area, exact(&c), "rectangle at ({x0}, {y0})");
            // Pixel centres: (w - 1) x (h - 1), twice, clockwise on screen.
            assert_eq!(area, 2 * i64::from(w - 1) * i64::from(h - 1));
            let reversed: heapless::Vec<Pixel, 512> = c.iter().rev().copied().collect();
            assert_eq!(signed_area2(&reversed), -area);
        }
        // Ragged walks of unit steps far from the origin (closed by the last-to-first edge).
        let mut state = 12345u32;
        for _ in 0..50 {
            let mut c: heapless::Vec<Pixel, 512> = heapless::Vec::new();
            let (mut x, mut y) = (8100u16, 8100u16);
            for _ in 0..300 {
                state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                x = (x + (state >> 28) as u16 % 3).saturating_sub(1).min(8191);
                y = (y + (state >> 24) as u16 % 3).saturating_sub(1).min(8191);
                c.push(Pixel { x, y }).unwrap();
            }
            assert_eq!(signed_area2(&c), exact(&c));
        }
        assert_eq!(signed_area2(&[]), 0);
    }

    #[test]
    fn rectangle_gives_its_corners_clockwise() {
        let c = rectangle(10, 20, 30, 25);
        let q = fit_quad(&c, 8.0).unwrap();
        assert!(!q.hole);
        let mut xs: [(f32, f32); 4] = core::array::from_fn(|k| (q.corners[k].x, q.corners[k].y));
        xs.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert_eq!(xs, [(10.0, 20.0), (10.0, 44.0), (39.0, 20.0), (39.0, 44.0)]);
        for k in 0..4 {
            assert!(
                cross(
                    q.corners[k],
                    cyclic(&q.corners, k + 1),
                    cyclic(&q.corners, k + 2)
                ) > 0.0
            );
        }
    }

    #[test]
    fn reversed_boundary_is_a_hole() {
        let mut c = rectangle(10, 20, 30, 25);
        c.reverse();
        assert!(fit_quad(&c, 8.0).unwrap().hole);
    }

    #[test]
    fn rejects_small_and_thin_shapes() {
        assert!(fit_quad(&rectangle(0, 0, 5, 5), 8.0).is_none());
        assert!(fit_quad(&rectangle(0, 0, 200, 9), 8.0).is_none());
    }

    #[test]
    fn triangle_is_not_a_quad() {
        let mut v: heapless::Vec<Pixel, 512> = heapless::Vec::new();
        for i in 0..40u16 {
            v.push(Pixel {
                x: 10 + i,
                y: 10 + i,
            })
            .unwrap();
        }
        for i in 0..40u16 {
            v.push(Pixel { x: 50 - i, y: 50 }).unwrap();
        }
        for i in 0..40u16 {
            v.push(Pixel { x: 10, y: 50 - i }).unwrap();
        }
        assert!(fit_quad(&v, 8.0).is_none());
    }

    /// The shape check on squared lengths decides as the one on lengths would, on each of
    /// its limits: edge length, edge ratio, corner angle, orientation.
    #[test]
    fn shape_check_limits() {
        let quad = |p: [(f32, f32); 4]| p.map(|(x, y)| Point::new(x, y));
        let square = quad([(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0)]);
        assert!(check_shape(&square, 10.0));
        assert!(!check_shape(&square, 10.01));
        assert!(check_shape(&square, -1.0));
        assert!(!check_shape(&square, f32::NAN));
        // Counter-clockwise on screen: not convex in the expected turn.
        let mut reversed = square;
        reversed.reverse();
        assert!(!check_shape(&reversed, 1.0));
        // Sides 1 : 12 pass, 1 : 12.5 do not.
        let ratio = |r: f32| quad([(0.0, 0.0), (r, 0.0), (r, 1.0), (0.0, 1.0)]);
        assert!(check_shape(&ratio(12.0), 1.0));
        assert!(!check_shape(&ratio(12.5), 1.0));
        // A parallelogram whose sharp corners are 11 degrees passes, 9 degrees does not
        // (the limit, acos 0.985, is 9.93 degrees).
        let lean = |deg: f32| {
            let (dx, dy) = (
                10.0 * libm::cosf(deg.to_radians()),
                10.0 * libm::sinf(deg.to_radians()),
            );
            quad([(0.0, 0.0), (10.0, 0.0), (10.0 + dx, dy), (dx, dy)])
        };
        assert!(check_shape(&lean(11.0), 1.0));
        assert!(!check_shape(&lean(9.0), 1.0));
    }

    /// An 8-connected boundary through `vertices` in order, closed.
    fn outline(vertices: &[(i32, i32)]) -> heapless::Vec<Pixel, 4096> {
        let mut out = heapless::Vec::new();
        for (k, &(x0, y0)) in vertices.iter().enumerate() {
            let (x1, y1) = vertices[(k + 1) % vertices.len()];
            let steps = (x1 - x0).abs().max((y1 - y0).abs());
            for t in 0..steps {
                let x = x0 as f32 + (x1 - x0) as f32 * t as f32 / steps as f32;
                let y = y0 as f32 + (y1 - y0) as f32 * t as f32 / steps as f32;
                out.push(Pixel {
                    x: x.round() as u16,
                    y: y.round() as u16,
                })
                .unwrap();
            }
        }
        out
    }

    /// A 100-pixel square (clockwise on screen) whose bottom-right corner a 30-pixel band
    /// covers on its way off to the right: the band leaves the right side 25 pixels above
    /// the corner and comes back on the bottom side 17 pixels left of it.
    fn square_with_band() -> heapless::Vec<Pixel, 4096> {
        outline(&[
            (50, 50),
            (150, 50),
            (150, 125),
            (300, 170),
            (300, 200),
            (133, 150),
            (50, 150),
        ])
    }

    fn near_square(q: &Quad) -> bool {
        let truth = [(50.0, 50.0), (150.0, 50.0), (150.0, 150.0), (50.0, 150.0)];
        truth
            .iter()
            .all(|&(x, y)| q.corners.iter().any(|c| c.distance(Point::new(x, y)) < 2.0))
    }

    /// The square's fourth corner is where its two sides beside the band meet; the region
    /// tests pass it (wide, not ragged, a square's area).
    #[test]
    fn a_marker_joined_at_a_corner_is_completed() {
        let boundary = square_with_band();
        assert!(
            fit_quad(&boundary, 7.0).is_none(),
            "the band spoils the fit"
        );
        let area2 = signed_area2_i32(&boundary);
        assert!(area2 > 0);
        assert!(might_complete(boundary.len(), area2, 7.0));
        assert!(worth_completing(&boundary, boundary.len(), 7.0));
        let found = complete(&boundary, 7.0);
        assert!(found.iter().any(near_square), "{found:?}");
        assert!(found.iter().all(|q| !q.hole));
    }

    /// No completion where the band hides most of a side (its visible part under a third of
    /// it), where the sides are shorter than the completion's shortest, or on a ragged blob.
    #[test]
    fn completion_needs_three_corners_and_most_of_two_sides() {
        let hidden_most = outline(&[
            (50, 50),
            (150, 50),
            (150, 70),
            (300, 170),
            (300, 230),
            (60, 150),
            (50, 150),
        ]);
        assert!(!complete(&hidden_most, 7.0).iter().any(near_square));
        // The same shape at a third of the size: sides of 33 pixels, below 6 x 7.
        let small = outline(&[
            (50, 50),
            (83, 50),
            (83, 75),
            (133, 90),
            (133, 100),
            (77, 83),
            (50, 83),
        ]);
        assert!(
            complete(&small, 7.0).is_empty(),
            "{:?}",
            complete(&small, 7.0)
        );
        // A random walk closed on itself: ragged, no three corners with long sides.
        let mut seed = 7u32;
        let mut walk: heapless::Vec<(i32, i32), 600> = heapless::Vec::new();
        let (mut x, mut y) = (200i32, 200i32);
        for _ in 0..600 {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            x += (seed >> 28) as i32 % 3 - 1;
            y += (seed >> 24) as i32 % 3 - 1;
            walk.push((x, y)).unwrap();
        }
        let ragged = outline(&walk);
        assert!(!worth_completing(&ragged, ragged.len(), 7.0) || complete(&ragged, 7.0).is_empty());
    }

    /// A corner the simplification left as two vertices, one on the side a few pixels short
    /// of the corner and the corner itself (where blur rounds it, the farthest point from a
    /// long chord): the window drops the first, within the tolerance of the side, and still
    /// sees three corners between the band's two ends.
    #[test]
    fn a_corner_split_in_two_still_completes() {
        let side = COMPLETION_SIDE_PER_EDGE * 7.0;
        let completes = |walk: &[(f32, f32)]| {
            let mut window = Window {
                side2: side * side,
                min_edge: 7.0,
                last: [Point::default(); 5],
                kept: 0,
                first: [Point::default(); WINDOW_FIRST],
                handed: 0,
                first_window: None,
            };
            let mut found = heapless::Vec::new();
            for &(x, y) in walk {
                window.push(Point::new(x, y), &mut found);
            }
            found.iter().any(near_square)
        };
        // The square of `square_with_band` walked from the band's end on the bottom side round
        // to where the band leaves the right side, its top-left corner whole and split in two.
        let walk = |split: Option<(f32, f32)>| {
            let mut walk: heapless::Vec<(f32, f32), 8> = heapless::Vec::new();
            for p in [(300.0, 200.0), (133.0, 150.0), (50.0, 150.0)] {
                walk.push(p).unwrap();
            }
            if let Some(p) = split {
                walk.push(p).unwrap();
            }
            for p in [(50.0, 50.0), (150.0, 50.0), (150.0, 125.0), (300.0, 170.0)] {
                walk.push(p).unwrap();
            }
            walk
        };
        assert!(completes(&walk(None)));
        assert!(completes(&walk(Some((51.0, 58.0)))));
        // A vertex farther off the side than the tolerance is a corner of its own: no three
        // corners are then consecutive.
        assert!(!completes(&walk(Some((54.0, 58.0)))));
    }

    /// The streaming simplification hands on the same vertices, in order, as the whole one,
    /// however few it may hold pending.
    #[test]
    fn streaming_simplification_matches_the_whole() {
        let boundary = square_with_band();
        let (origin, _, split) = far_apart(&boundary).unwrap();
        for tolerance in [1.0, 2.0, 3.0] {
            let (whole, count) = simplify(&boundary, origin, split, tolerance).unwrap();
            let mut streamed: heapless::Vec<u16, 64> = heapless::Vec::new();
            assert!(simplify_streaming::<6>(
                &boundary,
                origin,
                split,
                tolerance,
                true,
                |t| streamed.push(t).is_ok()
            ));
            // More vertices than it may hold: it handed some on before the end.
            assert!(count > 6, "tolerance {tolerance}: {count}");
            assert_eq!(&whole[..count], &streamed[..], "tolerance {tolerance}");
        }
    }
}
