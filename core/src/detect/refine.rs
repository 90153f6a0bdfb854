//! Step 4: sub-pixel edges and corners.
//!
//! The quad from the boundary sits on pixel centres and its corners are where the pixel
//! outline happened to bend, which can be a pixel or two off on a blurred corner. The image
//! itself knows better: along each edge, at evenly spaced points away from the corners, the
//! grey-level profile across the edge is read (bilinear, half-pixel steps) and the centroid
//! of its rising gradient lobe is the edge point. A weighted total least squares line through
//! those points is the edge, and neighbouring edges intersect at the corners. Corners that
//! move implausibly far are rejected and the coarse quad is kept, moved half a pixel outwards
//! onto the pixel boundary.
//!
//! ## Through the lens
//! A wide-angle lens bows a marker's edges (a 250-pixel marker's by several pixels), and a
//! straight line through points on the bow meets its neighbour pixels away from the corner.
//! With the camera known (and the marker at least [`MIN_LENS_PERIMETER_PX`] around) the
//! same edge search runs on the edges as an ideal lens would draw them: the rough corners are
//! undistorted, the sample points spread along the straight ideal edges and taken into the
//! frame for the profiles, the edge points found taken back, and the lines fitted and
//! intersected where they are straight; the corners are distorted back into the frame's
//! pixels. On the distortion set the border markers of 60 pixels and more went from 1.08 px
//! mean corner error (max 3.70) to 0.07 px (max 0.12).
//!
//! ## Square roots
//! The edge normals and line fits that place the reported corners take libm's exact `sqrtf`
//! (software on the Cortex-M7, 52 instructions; 12 to 16 per refined candidate). Only the
//! rough quad the precheck screens with ([`rough_half_pixel_adjusted`]) takes micromath's
//! (7 instructions, up to 6.1 % off: its corners within 0.03 px at right angles), where
//! every candidate of a frame pays for it; the half-pixel fallback is computed only when a
//! refinement fails.
//!
//! ## Why the gradient centroid, not the mid-level crossing
//! For an area-sampled step, the centroid of the bilinear profile's gradient is exactly the
//! edge whatever its sub-pixel phase, and a symmetric blur does not move it. The mid-level
//! crossing needs the ink and paper plateaus, and a short profile on a small marker often
//! misses one of them (the edge half a pixel off the profile's centre leaves a mixed pixel at
//! one end): the level moves towards that side. With the crossing, 20-pixel markers came out
//! 0.4 % too small (every edge about 0.05 px inwards), which is a 0.4 % altitude error at the
//! top of a descent; with the centroid the same markers are within 0.01 % unblurred and
//! 0.12 % with a 0.5 px blur (a thin border's inner edge trims the inner tail of the blurred
//! lobe; below 20 px that grows to 0.7 %).

use super::lens;
use super::quad::Quad;
use crate::camera::CameraModel;
use crate::geometry::cyclic;
use crate::geometry::Point;
use crate::image::{GrayImage, WalkStep, WALK_SAMPLE_SCALE};

/// Most edge points per edge. Each is a profile of up to 17 bilinear samples (about 1,200
/// Cortex-M7 instructions; 830 for 11); sixteen along an edge put the fitted line within a few
/// hundredths of a pixel (each point is good to about a tenth), and more only cost time:
/// with 32, refining a large marker's corners was most of a frame's detection time.
const MAX_SAMPLES: usize = 16;
/// Longest profile half-length, pixels.
const MAX_REACH: f32 = 4.0;
/// Profile samples (half-pixel steps over `±MAX_REACH`) the buffer holds.
const MAX_PROFILE: usize = 2 * 2 * MAX_REACH as usize + 2;
/// Smallest dark-to-light difference (grey levels) for a profile to count.
const MIN_STEP: f32 = 6.0;
/// Shortest perimeter (pixels, of the rough quad) whose edges are refined, and cells read,
/// through the lens when the camera is known: markers of about 30 pixels and more. On the
/// distortion set (host-tests/tests/distortion.rs) the border markers of 30-60 pixels came
/// to 0.08 px mean corner error this way against 0.14 px with straight edges; below 30 pixels
/// the lens made no difference (0.30 px either way: blur and noise dominate).
pub(crate) const MIN_LENS_PERIMETER_PX: f32 = 120.0;

/// A fitted line: a point on it and its unit direction.
#[derive(Debug, Clone, Copy, Default)]
struct Line {
    p: Point,
    d: Point,
}

fn intersect(a: &Line, b: &Line) -> Option<Point> {
    let den = a.d.x * b.d.y - a.d.y * b.d.x;
    if den.abs() < 1e-4 {
        return None;
    }
    let s = ((b.p.x - a.p.x) * b.d.y - (b.p.y - a.p.y) * b.d.x) / den;
    let q = Point::new(a.p.x + s * a.d.x, a.p.y + s * a.d.y);
    (q.x.is_finite() && q.y.is_finite()).then_some(q)
}

/// Unit outward normal of the edge a -> b of a clockwise (on screen) polygon.
fn outward_normal(a: Point, b: Point) -> Option<Point> {
    outward_normal_by(a, b, libm::sqrtf)
}

/// [`outward_normal`] with the edge's length from `root` (a square root).
#[inline(always)]
fn outward_normal_by(a: Point, b: Point, root: impl Fn(f32) -> f32) -> Option<Point> {
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    let len = root(dx * dx + dy * dy);
    (len > 1e-3).then(|| Point::new(dy / len, -dx / len))
}

/// How the profiles across one edge are read: along the unit normal `n`, dark to light
/// (`sign` 1: light outside, as for an outer boundary; -1: light inside, a hole), `steps`
/// half pixels each way, with the half-pixel step in [`GrayImage::bilinear_walk`]'s fixed
/// point (converted once for the edge's points).
struct Across {
    n: Point,
    sign: f32,
    steps: usize,
    step: Option<WalkStep>,
}

impl Across {
    fn new(n: Point, sign: f32, radius: f32) -> Self {
        Across {
            n,
            sign,
            steps: profile_steps(radius),
            step: WalkStep::new(0.5 * n.x, 0.5 * n.y),
        }
    }
}

/// The edge point across `across` from `p` (the centroid of the profile's rising gradient
/// lobe, dark to light) and the profile's contrast.
#[inline(always)]
fn edge_point(image: &GrayImage<'_>, p: Point, across: &Across) -> Option<(Point, f32)> {
    // The profile reaches a whole cell (2 * radius) each way, so that the blurred lobe is
    // whole wherever the edge lies within the boundary pixel. It cannot meet another rising
    // edge: inwards lies the rest of the dark border cell, outwards the light margin.
    let Across { n, sign, steps, .. } = *across;
    let count = 2 * steps + 1;
    let centre = 0.5 * sign; // the pixel-centre boundary lies half a pixel off the edge

    // Offsets along `n` from `p`: multiples of a half pixel, exact in f32 (so stepping them
    // by 0.5 gives the same values as computing each).
    let first_offset = centre + (0.0 - steps as f32) * 0.5;
    let start = (p.x + first_offset * n.x, p.y + first_offset * n.y);
    // The samples as integers, WALK_SAMPLE_SCALE per grey level.
    let mut profile = Profile::new();
    let walk = across
        .step
        .as_ref()
        .and_then(|step| image.bilinear_walk(start, step, count));
    match walk {
        // Inside the image (all but profiles at the frame's border): in fixed point.
        Some(mut walk) => read_profile(count, &mut profile, || walk.next_sample()),
        None => {
            let mut o = first_offset;
            read_profile(count, &mut profile, || {
                let s = image.sample(p.x + o * n.x, p.y + o * n.y);
                o += 0.5;
                Some((s * WALK_SAMPLE_SCALE) as i32)
            })
        }
    }
    if profile.len() < count {
        return None;
    }
    // Dark to light: the differences are taken the other way round for a hole.
    let mut rise = Rises::new();
    let (lo, hi, peak) = if sign < 0.0 {
        profile_extremes::<true>(&profile, &mut rise)
    } else {
        profile_extremes::<false>(&profile, &mut rise)
    };
    let contrast = (hi - lo) as f32 * (1.0 / WALK_SAMPLE_SCALE);
    if contrast < MIN_STEP {
        return None;
    }
    // The lobe: the differences around the steepest rise that stay above a tenth of it.
    // The floor keeps sensor noise on the plateaus out of the centroid, and subtracting it
    // from every weight keeps the lobe's own tails symmetric.
    let floor = 0.1 * peak.0 as f32;
    let weight = |j: usize| rise.get(j).map_or(0.0, |&g| g as f32 - floor);
    let mut first = peak.1;
    while first > 0 && weight(first - 1) > 0.0 {
        first -= 1;
    }
    let mut last = peak.1;
    while last + 2 < count && weight(last + 1) > 0.0 {
        last += 1;
    }
    let (mut wsum, mut msum) = (0.0f32, 0.0f32);
    for j in first..=last {
        let w = weight(j).max(0.0);
        wsum += w;
        msum += w * j as f32;
    }
    if !(wsum > 0.0) {
        return None;
    }
    let o = centre + (msum / wsum + 0.5 - steps as f32) * 0.5;
    Some((Point::new(p.x + o * n.x, p.y + o * n.y), contrast))
}

/// The samples of an edge profile (a vector, so nothing is zeroed first: a profile is read
/// for every edge point of every candidate).
type Profile = heapless::Vec<i32, MAX_PROFILE>;

/// Reads an edge profile of `count` samples (at most `MAX_PROFILE`), one per call of
/// `next` until it has none, into `profile`. A loop of its own: with the extremes'
/// bookkeeping in it, the walk's registers were spilled on every sample.
#[inline(always)]
fn read_profile(count: usize, profile: &mut Profile, mut next: impl FnMut() -> Option<i32>) {
    let count = count.min(MAX_PROFILE);
    while profile.len() < count {
        let Some(s) = next() else {
            break;
        };
        if profile.push(s).is_err() {
            break;
        }
    }
}

/// Differences between neighbouring samples of an edge profile, dark to light: `rise[j]`
/// lies between samples j and j + 1.
type Rises = heapless::Vec<i32, { MAX_PROFILE - 1 }>;

/// The lowest and the highest of a profile's samples (grey levels times
/// [`WALK_SAMPLE_SCALE`], at most 255 apart: no difference overflows), its differences into
/// `rise` (each sample minus the one before, or the other way round when `FLIP`: a loop for
/// each, as a multiplication by the sign cost a test per sample), and the steepest of them
/// with its index (the first of equals).
#[inline(always)]
fn profile_extremes<const FLIP: bool>(
    profile: &[i32],
    rise: &mut Rises,
) -> (i32, i32, (i32, usize)) {
    let Some((&first, rest)) = profile.split_first() else {
        return (0, 0, (i32::MIN, 0));
    };
    let (mut lo, mut hi, mut last) = (first, first, first);
    let mut peak = (i32::MIN, 0usize);
    for &s in rest.iter().take(MAX_PROFILE - 1) {
        let g = if FLIP { last - s } else { s - last };
        if g > peak.0 {
            peak = (g, rise.len());
        }
        if rise.push(g).is_err() {
            break;
        }
        lo = lo.min(s);
        hi = hi.max(s);
        last = s;
    }
    (lo, hi, peak)
}

/// Half-pixel steps each way of an edge profile for `radius`.
fn profile_steps(radius: f32) -> usize {
    let reach = (2.0 * radius).min(MAX_REACH);
    ((reach * 2.0) as usize).clamp(2, (MAX_PROFILE - 2) / 2)
}

/// Image samples of one edge profile for `radius`.
fn profile_samples(radius: f32) -> usize {
    2 * profile_steps(radius) + 1
}

/// Weighted total least squares line through points.
fn fit_line(points: &[(Point, f32)]) -> Option<Line> {
    // One pass for the three sums (each still added up in the points' order).
    let (mut wsum, mut wx, mut wy) = (0.0f32, 0.0f32, 0.0f32);
    for (p, w) in points {
        wsum += w;
        wx += p.x * w;
        wy += p.y * w;
    }
    if points.len() < 3 || !(wsum > 0.0) {
        return None;
    }
    let (mx, my) = (wx / wsum, wy / wsum);
    let (mut sxx, mut sxy, mut syy) = (0.0f32, 0.0f32, 0.0f32);
    for (p, w) in points {
        let (dx, dy) = (p.x - mx, p.y - my);
        sxx += w * dx * dx;
        sxy += w * dx * dy;
        syy += w * dy * dy;
    }
    // Principal eigenvector of [[sxx, sxy], [sxy, syy]].
    let half = 0.5 * (sxx - syy);
    let l1 = 0.5 * (sxx + syy) + libm::sqrtf(half * half + sxy * sxy);
    let (ax, ay) = (sxy, l1 - sxx);
    let (bx, by) = (l1 - syy, sxy);
    let (dx, dy) = if ax * ax + ay * ay > bx * bx + by * by {
        (ax, ay)
    } else {
        (bx, by)
    };
    let len = libm::sqrtf(dx * dx + dy * dy);
    (len > 1e-9).then(|| Line {
        p: Point::new(mx, my),
        d: Point::new(dx / len, dy / len),
    })
}

/// The quad with every edge moved `distance` pixels outwards (inwards for a hole, whose
/// boundary pixels lie outside the light region); corners move to keep the edges' directions.
pub(crate) fn offset_quad(quad: &Quad, distance: f32) -> [Point; 4] {
    offset_quad_by(quad, distance, libm::sqrtf)
}

/// [`offset_quad`] with the edges' lengths from `root` (a square root).
#[inline(always)]
fn offset_quad_by(quad: &Quad, distance: f32, root: impl Fn(f32) -> f32) -> [Point; 4] {
    let sign = if quad.hole { -distance } else { distance };
    let c = &quad.corners;
    // Each edge's normal once (both of its corners use it): four square roots, not eight.
    // Edge k runs from corner k to corner k + 1.
    let normals: [Point; 4] = core::array::from_fn(|k| {
        outward_normal_by(cyclic(c, k), cyclic(c, k + 1), &root).unwrap_or_default()
    });
    let mut out = *c;
    for (k, slot) in out.iter_mut().enumerate() {
        let prev = cyclic(&normals, k + 3);
        let next = cyclic(&normals, k);
        // The corner moves along the bisector so that both edges move by `distance`.
        let (bx, by) = (prev.x + next.x, prev.y + next.y);
        let cos_half_sq = 0.25 * (bx * bx + by * by);
        let scale = if cos_half_sq > 0.05 {
            sign / (2.0 * cos_half_sq)
        } else {
            sign
        };
        *slot = Point::new(cyclic(c, k).x + scale * bx, cyclic(c, k).y + scale * by);
    }
    out
}

/// The quad moved half a pixel outwards (inwards for a hole) from the boundary pixel
/// centres onto the pixel boundary.
pub(crate) fn half_pixel_adjusted(quad: &Quad) -> [Point; 4] {
    offset_quad(quad, 0.5)
}

/// [`half_pixel_adjusted`] for screening ([`super::decode::precheck`], which samples the
/// nearest pixels of a rough quad): the edges' normals from micromath's square root (one
/// shift of the float's bits, 7 Cortex-M7 instructions against libm's 52, at most 6.1 %
/// off), so each edge moves 0.5 px give or take 0.03 px and a right-angled corner by at
/// most 0.03 px from the exact one (0.053 px at 60 degrees; the precheck reads the nearest
/// pixels in the middle of the sides). On a frame of small quads, where every candidate is
/// screened, libm's four roots per candidate were 1.6 % of the frame. Corners that are
/// reported or refined use [`half_pixel_adjusted`].
pub(crate) fn rough_half_pixel_adjusted(quad: &Quad) -> [Point; 4] {
    offset_quad_by(quad, 0.5, micromath::F32Ext::sqrt)
}

/// Where an edge's profiles are taken: one point per pixel of the edge from `a` to `b` (on
/// small, steep markers every point counts), keeping clear of the corners by the profile's
/// reach (at least 4 %, at most 30 % of the edge at each end).
fn edge_sample_points(a: Point, b: Point, radius: f32) -> impl Iterator<Item = Point> {
    let len = a.distance(b);
    let count = (len as usize).clamp(3, MAX_SAMPLES);
    let skip = ((radius + 1.0) / len).clamp(0.04, 0.3);
    (0..count).map(move |i| {
        let s = skip + (1.0 - 2.0 * skip) * (i as f32 + 0.5) / count as f32;
        Point::new(a.x + s * (b.x - a.x), a.y + s * (b.y - a.y))
    })
}

/// Corner `k` where fitted edges `k - 1` and `k` meet, if it lies near the rough corner
/// (within 15 % of the edge from it, at least 2.5 px): a corner further off means a line fit
/// went wrong.
fn corner_near(lines: &[Line; 4], rough: &[Point; 4], k: usize) -> Option<Point> {
    let q = intersect(&cyclic(lines, k + 3), &cyclic(lines, k))?;
    let limit = (0.15 * cyclic(rough, k).distance(cyclic(rough, k + 1))).max(2.5);
    (q.distance(cyclic(rough, k)) <= limit).then_some(q)
}

/// Sub-pixel corners of `quad`. `radius` (pixels) bounds how far an edge may move, and must
/// stay below a cell so the search never reaches the next edge inside the marker. With a
/// `lens`, the edges are found and fitted through it ([`refine_corners_through_lens`]). Adds
/// the image samples it read to `samples` (the detector's work accounting).
pub(crate) fn refine_corners(
    image: &GrayImage<'_>,
    quad: &Quad,
    radius: f32,
    lens: Option<&CameraModel>,
    samples: &mut u32,
) -> [Point; 4] {
    if let Some(camera) = lens {
        if let Some(corners) = refine_corners_through_lens(image, quad, radius, camera, samples) {
            return corners;
        }
    }
    refine_straight(image, quad, radius, samples)
}

/// [`refine_corners`] in the frame's own pixels: straight edges.
fn refine_straight(
    image: &GrayImage<'_>,
    quad: &Quad,
    radius: f32,
    samples: &mut u32,
) -> [Point; 4] {
    // Computed only when the refinement fails (its four square roots were spent on every
    // refined candidate).
    let fallback = || half_pixel_adjusted(quad);
    let c = &quad.corners;
    let sign = if quad.hole { -1.0 } else { 1.0 };
    let mut lines = [Line::default(); 4];
    for (k, slot) in lines.iter_mut().enumerate() {
        let (a, b) = (cyclic(c, k), cyclic(c, k + 1));
        let Some(n) = outward_normal(a, b) else {
            return fallback();
        };
        let across = Across::new(n, sign, radius);
        let mut points: heapless::Vec<(Point, f32), MAX_SAMPLES> = heapless::Vec::new();
        for p in edge_sample_points(a, b, radius) {
            *samples = samples.saturating_add(profile_samples(radius) as u32);
            if let Some(found) = edge_point(image, p, &across) {
                let _ = points.push(found);
            }
        }
        match fit_line(&points) {
            Some(line) => *slot = line,
            None => return fallback(),
        }
    }
    let mut out = [Point::default(); 4];
    for (k, slot) in out.iter_mut().enumerate() {
        let Some(q) = corner_near(&lines, c, k) else {
            return fallback();
        };
        *slot = q;
    }
    out
}

/// Image samples' worth of work of undistorting one corner through the lens (a Newton
/// inversion of the lens model, three to six iterations: about as much as four bilinear
/// samples).
const LENS_CORNER_SAMPLES: u32 = 4;
/// Image samples' worth of work of mapping one edge point through the lens (the model and
/// its Jacobian at a point: about one bilinear sample).
const LENS_POINT_SAMPLES: u32 = 1;

/// The frame pixel of an ideal-lens pixel, and the direction in the frame of the ideal-lens
/// unit vector `along` at it, with the length the lens gives that vector (pixels per ideal
/// pixel).
fn through_lens(camera: &CameraModel, ideal: Point, along: Point) -> Option<(Point, Point, f32)> {
    let normalized = lens::normalized(camera, ideal);
    let pixel = camera.pixel_from_normalized(normalized)?;
    let j = camera.distortion_jacobian(normalized);
    // In pixels: diag(fx, fy) * J * diag(1 / fx, 1 / fy).
    let (ax, ay) = (along.x / camera.fx, along.y / camera.fy);
    let dx = camera.fx * (j.m11 * ax + j.m12 * ay);
    let dy = camera.fy * (j.m21 * ax + j.m22 * ay);
    let len = libm::sqrtf(dx * dx + dy * dy);
    (len > 1e-3 && len.is_finite()).then(|| (pixel, Point::new(dx / len, dy / len), len))
}

/// Sub-pixel corners of `quad` (in the frame's pixels) with the edges fitted where they are
/// straight: at the ideal-lens pixels of `camera` ([`lens::ideal_pixel`]). A wide-angle lens bows a
/// large marker's edges by pixels; a straight line through edge points on the bow sits
/// between its middle and its ends, and the corners where two such lines meet are off by
/// about the bow. Here the points are placed evenly along the ideal edge between the ideal
/// corners, taken into the frame for the profile (across the edge as the lens turns it),
/// and the edge point found is taken back by the profile's offset scaled by the lens's local
/// stretch (first order: the offset is a few pixels, over which the lens's stretch barely
/// changes), so no point but the corners needs the model's inversion. The lines are fitted
/// and intersected there, and the corners distorted back. `None` when a corner cannot be
/// undistorted or a line not fitted: the caller refines in the frame's pixels.
fn refine_corners_through_lens(
    image: &GrayImage<'_>,
    quad: &Quad,
    radius: f32,
    camera: &CameraModel,
    samples: &mut u32,
) -> Option<[Point; 4]> {
    *samples = samples.saturating_add(4 * LENS_CORNER_SAMPLES);
    let mut ideal = [Point::default(); 4];
    for (slot, &corner) in ideal.iter_mut().zip(&quad.corners) {
        *slot = lens::ideal_pixel(camera, corner)?;
    }
    let sign = if quad.hole { -1.0 } else { 1.0 };
    let mut lines = [Line::default(); 4];
    for (k, slot) in lines.iter_mut().enumerate() {
        let (a, b) = (cyclic(&ideal, k), cyclic(&ideal, k + 1));
        let n = outward_normal(a, b)?;
        let mut points: heapless::Vec<(Point, f32), MAX_SAMPLES> = heapless::Vec::new();
        for q in edge_sample_points(a, b, radius) {
            *samples = samples.saturating_add(profile_samples(radius) as u32 + LENS_POINT_SAMPLES);
            let Some((p, n_frame, stretch)) = through_lens(camera, q, n) else {
                continue;
            };
            if let Some((found, w)) = edge_point(image, p, &Across::new(n_frame, sign, radius)) {
                let offset = ((found.x - p.x) * n_frame.x + (found.y - p.y) * n_frame.y) / stretch;
                let _ = points.push((Point::new(q.x + offset * n.x, q.y + offset * n.y), w));
            }
        }
        *slot = fit_line(&points)?;
    }
    let mut out = [Point::default(); 4];
    for (k, slot) in out.iter_mut().enumerate() {
        *slot = lens::frame_pixel(camera, corner_near(&lines, &ideal, k)?)?;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The screening's rough quad (micromath's square root) against the exact one, over
    /// squares and rectangles of every orientation, 6 to 300 pixels a side (measured: within
    /// 0.029 pixels), and parallelograms down to 60-degree corners (0.053).
    #[test]
    fn rough_half_pixel_quad_is_within_six_hundredths_of_a_pixel() {
        let (mut worst_square, mut worst) = (0.0f32, 0.0f32);
        for step in 0..90 {
            let angle = (step as f32 * 4.0).to_radians();
            let (s, c) = (libm::sinf(angle), libm::cosf(angle));
            for side in [6.0f32, 9.5, 17.0, 40.0, 111.0, 300.0] {
                for (aspect, shear) in [(1.0f32, 0.0f32), (0.5, 0.0), (1.0, 0.5), (0.7, -0.577)] {
                    // Clockwise on screen (y down): top-left, top-right, bottom-right,
                    // bottom-left, turned by `angle` about (100, 80).
                    let local = [(0.0, 0.0), (side, 0.0), (side, side), (0.0, side)];
                    let corners = local.map(|(x, y): (f32, f32)| {
                        let (x, y) = (x + shear * y, aspect * y);
                        Point::new(100.0 + c * x - s * y, 80.0 + s * x + c * y)
                    });
                    for hole in [false, true] {
                        let quad = Quad { corners, hole };
                        let exact = half_pixel_adjusted(&quad);
                        let rough = rough_half_pixel_adjusted(&quad);
                        for (e, r) in exact.iter().zip(&rough) {
                            worst = worst.max(e.distance(*r));
                            if shear == 0.0 {
                                worst_square = worst_square.max(e.distance(*r));
                            }
                        }
                    }
                }
            }
        }
        assert!(worst_square < 0.03, "{worst_square}");
        assert!(worst < 0.06, "{worst}");
        assert!(worst > 0.0, "micromath's root is not exact");
    }
}
