//! Step 3: from a boundary to a four-corner shape.
//!
//! The paper's step: Douglas-Peucker simplification of the closed boundary, keeping shapes
//! with four corners. The closed curve is split at two far-apart points and each half is
//! simplified with an explicit stack (no recursion) and a fixed vertex capacity. A corner
//! rounded by blur can come out as two vertices; the vertex that bends the outline least is
//! then dropped while it stays within the tolerance.
//!
//! A shape is a candidate when it is convex, every edge is at least `min_edge` pixels, no
//! angle is sharper than [`MIN_ANGLE_COS`] allows, and its sides are not wildly unequal.
//! The corners are returned clockwise on screen (y down), the order of the canonical corners
//! top-left, top-right, bottom-right, bottom-left.

use super::contour::Pixel;
use crate::geometry::cyclic;
use crate::geometry::Point;

/// Most Douglas-Peucker vertices kept before a boundary is given up as not a quad.
const MAX_VERTICES: usize = 12;
/// Tolerance as a fraction of the boundary length (OpenCV ArUco uses 0.03 of the perimeter).
const TOLERANCE_PER_PIXEL: f32 = 0.02;
/// Smallest tolerance, pixels.
const MIN_TOLERANCE: f32 = 1.0;
/// |cos| of the sharpest and flattest accepted corner angle (about 14 and 166 degrees).
pub(crate) const MIN_ANGLE_COS: f32 = 0.97;
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

#[inline]
fn at(contour: &[Pixel], t: usize) -> Point {
    let n = contour.len().max(1);
    contour.get(t % n).copied().map(pt).unwrap_or_default()
}

/// Distance from `p` to the line through `a` and `b` (to `a` when they coincide).
fn line_distance(p: Point, a: Point, b: Point) -> f32 {
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    let len = libm::sqrtf(dx * dx + dy * dy);
    if len < 1e-6 {
        return p.distance(a);
    }
    ((p.x - a.x) * dy - (p.y - a.y) * dx).abs() / len
}

fn cross(o: Point, a: Point, b: Point) -> f32 {
    (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
}

/// Twice the signed area of the boundary polygon: positive when it runs clockwise on
/// screen (an outer boundary), negative for a hole.
pub(crate) fn signed_area2(contour: &[Pixel]) -> i64 {
    let n = contour.len();
    let mut acc = 0i64;
    for i in 0..n {
        let a = contour.get(i).copied().unwrap_or_default();
        let b = contour.get((i + 1) % n).copied().unwrap_or_default();
        acc += a.x as i64 * b.y as i64 - b.x as i64 * a.y as i64;
    }
    acc
}

/// Douglas-Peucker vertices of the closed boundary, as positions `t` along it counted from
/// `origin`; `None` when it needs more than [`MAX_VERTICES`].
fn simplify(
    contour: &[Pixel],
    origin: usize,
    split: usize,
    tolerance: f32,
) -> Option<heapless::Vec<usize, MAX_VERTICES>> {
    let n = contour.len();
    let mut vertices: heapless::Vec<usize, MAX_VERTICES> = heapless::Vec::new();
    vertices.push(0).ok()?;
    vertices.push(split).ok()?;
    let mut stack: heapless::Vec<(usize, usize), MAX_VERTICES> = heapless::Vec::new();
    stack.push((0, split)).ok()?;
    stack.push((split, n)).ok()?;
    while let Some((i, j)) = stack.pop() {
        let (a, b) = (at(contour, origin + i), at(contour, origin + j));
        let mut best = (0.0f32, i);
        for t in i + 1..j {
            let d = line_distance(at(contour, origin + t), a, b);
            if d > best.0 {
                best = (d, t);
            }
        }
        if best.0 > tolerance {
            vertices.push(best.1).ok()?;
            stack.push((i, best.1)).ok()?;
            stack.push((best.1, j)).ok()?;
        }
    }
    sort_short(&mut vertices);
    Some(vertices)
}

/// Ascending insertion sort of a short vertex list (at most [`MAX_VERTICES`]). Used instead
/// of `sort_unstable`, whose order-violation panic path the optimiser cannot remove (the
/// no-panic link check, nopanic/, needs every panic path gone).
fn sort_short(v: &mut [usize]) {
    for i in 1..v.len() {
        for j in (1..=i).rev() {
            match v.get_mut(j - 1..=j) {
                Some([a, b]) if *a > *b => core::mem::swap(a, b),
                _ => break,
            }
        }
    }
}

/// Smallest twice-area over squared boundary length of a candidate (see [`fit_quad`]): a
/// square traced along its axes gives 1/8, at 45 degrees 1/4, a 1:8 rectangle 1/20.
const COMPACTNESS: f32 = 0.04;

/// Fits a candidate quad to a closed boundary.
pub(crate) fn fit_quad(contour: &[Pixel], min_edge: f32) -> Option<Quad> {
    let n = contour.len();
    // An edge of `min_edge` pixels at 45 degrees is min_edge / sqrt(2) steps.
    if (n as f32) < 2.8 * min_edge || n < 8 {
        return None;
    }
    let area2 = signed_area2(contour);
    if area2 == 0 {
        return None;
    }
    // Compactness: a quad's area is a good fraction of its squared perimeter (a 1:8
    // rectangle traced pixel by pixel still has area >= n^2 / 40 for n boundary steps),
    // while noise blobs and thin strokes are ragged outlines around little area. Rejecting
    // them here, before the Douglas-Peucker fit, is most of the cost of a noisy frame.
    if (area2.unsigned_abs() as f32) < COMPACTNESS * (n * n) as f32 {
        return None;
    }
    let hole = area2 < 0;
    // Split at two far-apart points: the farthest from the first, and the farthest from that.
    // Squared integer distances: this runs on every traced contour (thousands on a noisy
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
    let split = (split_abs + n - origin) % n;
    if split == 0 {
        return None;
    }
    let tolerance = (TOLERANCE_PER_PIXEL * n as f32).max(MIN_TOLERANCE);
    let mut vertices = simplify(contour, origin, split, tolerance)?;
    // Drop the vertex that bends the outline least while more than four remain.
    while vertices.len() > 4 {
        let m = vertices.len();
        let mut best = (f32::MAX, 0usize);
        for k in 0..m {
            let prev = vertices.get((k + m - 1) % m).copied().unwrap_or(0);
            let cur = vertices.get(k).copied().unwrap_or(0);
            let next = vertices.get((k + 1) % m).copied().unwrap_or(0);
            let d = line_distance(
                at(contour, origin + cur),
                at(contour, origin + prev),
                at(contour, origin + next),
            );
            if d < best.0 {
                best = (d, k);
            }
        }
        if best.0 > 2.0 * tolerance {
            return None;
        }
        if best.1 < vertices.len() {
            vertices.remove(best.1);
        }
    }
    if vertices.len() != 4 {
        return None;
    }
    let mut corners = [Point::default(); 4];
    for (c, &t) in corners.iter_mut().zip(vertices.iter()) {
        *c = at(contour, origin + t);
    }
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

/// Convex, edges long enough and not too unequal, no degenerate angle.
pub(crate) fn check_shape(c: &[Point; 4], min_edge: f32) -> bool {
    let mut shortest = f32::MAX;
    let mut longest = 0.0f32;
    for k in 0..4 {
        let (a, b, d) = (cyclic(c, k), cyclic(c, k + 1), cyclic(c, k + 2));
        if !(cross(a, b, d) > 0.0) {
            return false;
        }
        let e1 = b.distance(a);
        let e2 = d.distance(b);
        shortest = shortest.min(e1);
        longest = longest.max(e1);
        if e1 < 1e-3 || e2 < 1e-3 {
            return false;
        }
        let cos = ((a.x - b.x) * (d.x - b.x) + (a.y - b.y) * (d.y - b.y)) / (e1 * e2);
        if cos.abs() > MIN_ANGLE_COS {
            return false;
        }
    }
    shortest >= min_edge && longest <= MAX_EDGE_RATIO * shortest
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
}
