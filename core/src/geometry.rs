//! Small fixed-size geometry: points, lines and the plane-to-image homography.
//!
//! A homography maps marker-plane coordinates to pixels. With only four correspondences the
//! direct linear transform is an exact 8x8 solve; it is done on coordinates normalised to
//! zero mean and unit scale (Hartley) so f32 keeps its precision on a 1920-pixel image.
//!
//! Indexing here is into fixed-size arrays by loop counters bounded by those sizes; no index
//! comes from input data, so the checked-indexing lint is relaxed for this module only.
#![allow(clippy::indexing_slicing, clippy::needless_range_loop)]

/// A point in pixels (or any plane), f32.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Point {
    /// x (right)
    pub x: f32,
    /// y (down, in pixels)
    pub y: f32,
}

/// Element `k mod 4` of a four-element array (corners, edges): in range by construction.
#[inline]
pub fn cyclic<T: Copy + Default>(items: &[T; 4], k: usize) -> T {
    items.get(k % 4).copied().unwrap_or_default()
}

/// Area of a quadrilateral (shoelace), in squared units of its points.
pub fn quad_area(corners: &[Point; 4]) -> f32 {
    let mut twice = 0.0;
    for (k, a) in corners.iter().enumerate() {
        let b = cyclic(corners, k + 1);
        twice += a.x * b.y - b.x * a.y;
    }
    0.5 * twice.abs()
}

impl Point {
    /// A point from its coordinates.
    pub const fn new(x: f32, y: f32) -> Self {
        Point { x, y }
    }

    /// Euclidean distance.
    pub fn distance(self, other: Point) -> f32 {
        libm::sqrtf(self.distance_squared(other))
    }

    /// The square of [`Point::distance`], without its square root (libm's `sqrtf` is
    /// software on the Cortex-M7, about 52 instructions): for comparing a distance with a
    /// limit, square the limit.
    pub fn distance_squared(self, other: Point) -> f32 {
        let dx = self.x - other.x;
        let dy = self.y - other.y;
        dx * dx + dy * dy
    }
}

/// A 3x3 homography `H`, row-major: `[x', y', w']^T = H [u, v, 1]^T`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Homography {
    /// Row-major coefficients.
    pub m: [f32; 9],
}

impl Homography {
    /// Maps a plane point to the image; `None` when it lands at infinity.
    #[inline]
    pub fn map(&self, u: f32, v: f32) -> Option<Point> {
        let m = &self.m;
        let w = m[6] * u + m[7] * v + m[8];
        if !(w.abs() > 1e-12) {
            return None;
        }
        let x = (m[0] * u + m[1] * v + m[2]) / w;
        let y = (m[3] * u + m[4] * v + m[5]) / w;
        if x.is_finite() && y.is_finite() {
            Some(Point { x, y })
        } else {
            None
        }
    }

    /// The homography that maps each `plane[i]` onto `image[i]`, or `None` when the four points
    /// are degenerate (three collinear, or coincident).
    pub fn from_4_points(plane: &[Point; 4], image: &[Point; 4]) -> Option<Homography> {
        let (tp, plane_n) = normalise(plane)?;
        let (ti, image_n) = normalise(image)?;
        if !in_general_position(&plane_n) || !in_general_position(&image_n) {
            return None;
        }
        // Solve for h (h33 = 1) in the normalised frames: 8 equations, 8 unknowns.
        let mut a = [[0.0f32; 9]; 8];
        for k in 0..4 {
            let (u, v) = (plane_n[k].x, plane_n[k].y);
            let (x, y) = (image_n[k].x, image_n[k].y);
            a[2 * k] = [u, v, 1.0, 0.0, 0.0, 0.0, -x * u, -x * v, x];
            a[2 * k + 1] = [0.0, 0.0, 0.0, u, v, 1.0, -y * u, -y * v, y];
        }
        let h = solve8(&mut a)?;
        let hn = [h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], 1.0];
        // Denormalise: H = Ti^-1 * Hn * Tp.
        let m = mul3(&mul3(&inverse_similarity(&ti), &hn), &tp);
        if m.iter().all(|c| c.is_finite()) {
            Some(Homography { m })
        } else {
            None
        }
    }
}

/// Similarity that moves the points' centroid to 0 and their mean distance to sqrt(2).
fn normalise(p: &[Point; 4]) -> Option<([f32; 9], [Point; 4])> {
    let cx = (p[0].x + p[1].x + p[2].x + p[3].x) * 0.25;
    let cy = (p[0].y + p[1].y + p[2].y + p[3].y) * 0.25;
    let mut mean = 0.0;
    for q in p {
        mean += Point::new(q.x - cx, q.y - cy).distance(Point::default());
    }
    mean *= 0.25;
    if !(mean > 1e-9) || !mean.is_finite() {
        return None;
    }
    let s = core::f32::consts::SQRT_2 / mean;
    let t = [s, 0.0, -s * cx, 0.0, s, -s * cy, 0.0, 0.0, 1.0];
    let mut out = [Point::default(); 4];
    for (o, q) in out.iter_mut().zip(p) {
        *o = Point::new(s * (q.x - cx), s * (q.y - cy));
    }
    Some((t, out))
}

/// No three of the (normalised, so scale-free) points are collinear.
fn in_general_position(p: &[Point; 4]) -> bool {
    const MIN_TWICE_AREA: f32 = 1e-3;
    for skip in 0..4 {
        let mut q = [Point::default(); 3];
        let mut n = 0;
        for (k, &point) in p.iter().enumerate() {
            if k != skip && n < 3 {
                q[n] = point;
                n += 1;
            }
        }
        let cross = (q[1].x - q[0].x) * (q[2].y - q[0].y) - (q[1].y - q[0].y) * (q[2].x - q[0].x);
        if !(cross.abs() > MIN_TWICE_AREA) {
            return false;
        }
    }
    true
}

fn inverse_similarity(t: &[f32; 9]) -> [f32; 9] {
    let s = t[0];
    let inv = 1.0 / s;
    [inv, 0.0, -t[2] * inv, 0.0, inv, -t[5] * inv, 0.0, 0.0, 1.0]
}

fn mul3(a: &[f32; 9], b: &[f32; 9]) -> [f32; 9] {
    let mut c = [0.0f32; 9];
    for r in 0..3 {
        for k in 0..3 {
            c[r * 3 + k] = a[r * 3] * b[k] + a[r * 3 + 1] * b[3 + k] + a[r * 3 + 2] * b[6 + k];
        }
    }
    c
}

/// Gaussian elimination with partial pivoting on an 8x9 augmented matrix.
fn solve8(a: &mut [[f32; 9]; 8]) -> Option<[f32; 8]> {
    for col in 0..8 {
        let mut pivot = col;
        for row in col + 1..8 {
            if a[row][col].abs() > a[pivot][col].abs() {
                pivot = row;
            }
        }
        if !(a[pivot][col].abs() > 1e-9) {
            return None;
        }
        a.swap(col, pivot);
        let inv = 1.0 / a[col][col];
        for row in col + 1..8 {
            let f = a[row][col] * inv;
            if f != 0.0 {
                for k in col..9 {
                    a[row][k] -= f * a[col][k];
                }
            }
        }
    }
    let mut x = [0.0f32; 8];
    for row in (0..8).rev() {
        let mut s = a[row][8];
        for k in row + 1..8 {
            s -= a[row][k] * x[k];
        }
        x[row] = s / a[row][row];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn homography_maps_the_four_points() {
        let plane = [
            Point::new(0.0, 0.0),
            Point::new(8.0, 0.0),
            Point::new(8.0, 8.0),
            Point::new(0.0, 8.0),
        ];
        let image = [
            Point::new(1510.3, 880.2),
            Point::new(1700.9, 900.1),
            Point::new(1690.0, 1070.7),
            Point::new(1500.2, 1040.4),
        ];
        let h = Homography::from_4_points(&plane, &image).unwrap();
        for k in 0..4 {
            let p = h.map(plane[k].x, plane[k].y).unwrap();
            assert!(p.distance(image[k]) < 2e-3, "{k}: {p:?}");
        }
    }

    #[test]
    fn degenerate_points_give_none() {
        let plane = [
            Point::new(0.0, 0.0),
            Point::new(1.0, 0.0),
            Point::new(1.0, 1.0),
            Point::new(0.0, 1.0),
        ];
        let line = [
            Point::new(0.0, 0.0),
            Point::new(1.0, 1.0),
            Point::new(2.0, 2.0),
            Point::new(3.0, 3.0),
        ];
        assert!(Homography::from_4_points(&plane, &line).is_none());
        let same = [Point::new(5.0, 5.0); 4];
        assert!(Homography::from_4_points(&plane, &same).is_none());
    }
}
