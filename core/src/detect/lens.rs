//! Step 3 through a distorting lens: the quad fit on the boundary as an ideal lens would have
//! drawn it.
//!
//! A wide-angle lens (the board's M12 lenses: k1 of -0.2 to -0.35) bends a marker's straight
//! edges, most near the frame border: the edges of a 120-pixel marker there bow by a pixel or
//! three, of a 300-pixel one by up to ten. Douglas-Peucker then has to trade the bow against
//! its tolerance, and the four vertices it keeps are where the outline bent most, not the
//! corners. With the camera model known ([`super::Detector::set_camera`]) the boundary is
//! undistorted first: each point goes to where a distortion-free camera with the same focal
//! lengths and principal point would have seen it, where the marker's edges are straight
//! again, and the fit runs there. Its four corners are distorted back, so the quad handed on
//! (to the quick look, the edge refinement and the cell reading) is in the frame's own
//! pixels like every other: the detector's output convention does not depend on the camera,
//! and the pose, which undistorts the reported corners itself, does so exactly once. The
//! steps after the fit use the lens the same way (`refine`: the edges fitted where they are
//! straight; `decode`: the cell grid laid on the ideal-lens marker and each cell's point
//! taken into the frame), with [`ideal_pixel`] and [`frame_pixel`] from here.
//!
//! Bounded work: the boundary is first thinned to at most [`MAX_LENS_POINTS`] evenly spaced
//! points (the fit's tolerance is a fiftieth of the length, so the corners lose nothing a
//! refinement does not restore), each undistorted by the camera's Newton inversion, charged
//! at [`WORK_UNDISTORT`] a point. A boundary with a point the lens model cannot invert (where
//! it folds over, far outside a calibrated field) is fitted as it is.
//!
//! The straightened points are [`Pixel`]s again (rounded, relative to an origin:
//! [`Straightened::origin`]) in a buffer of [`MAX_LENS_POINTS`], so the fit needs no change:
//! it sees just another boundary. The boundary itself is left as it was, so that a fit that
//! fails through the lens can still be tried on it as the frame shows it.
//!
//! Only boundaries of at least [`MIN_LENS_LENGTH`] steps go through the lens: on smaller
//! markers the bow stays under a pixel even at k1 = -0.35 at the frame's corner, and rounding
//! the straightened points to whole pixels costs such a marker more than the bow.

use super::contour::Pixel;
use super::quad::Quad;
use crate::camera::CameraModel;
use crate::geometry::Point;

/// Shortest boundary (steps) fitted through the lens: a marker of about 60 pixels, whose
/// edges a k1 = -0.35 lens bows by about a pixel at the frame's border.
pub(crate) const MIN_LENS_LENGTH: usize = 240;
/// Most boundary points undistorted for one fit.
pub(crate) const MAX_LENS_POINTS: usize = 256;
/// Work units per undistorted point: a Newton inversion of the lens model takes three to six
/// iterations of about 100 Cortex-M7 instructions each (not measured on the M7: the
/// benchmark's camera has no distortion).
pub(crate) const WORK_UNDISTORT: u32 = 6;
/// Where the straightened points are placed in the `u16` range: the boundary's first point
/// goes here, so the others (within a frame's size of it) stay positive.
const ORIGIN_OFFSET: f32 = 16384.0;

/// A boundary straightened in place by [`straighten`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Straightened {
    /// Points of the buffer that now hold the straightened boundary.
    pub points: usize,
    /// The ideal-lens pixel that the stored coordinate (0, 0) stands for.
    pub origin: Point,
}

/// The pixel a distortion-free camera with `camera`'s intrinsics sees `pixel` at (its
/// ideal-lens pixel).
pub(super) fn ideal_pixel(camera: &CameraModel, pixel: Point) -> Option<Point> {
    let n = camera.undistort(pixel)?;
    let p = Point::new(camera.fx * n.x + camera.cx, camera.fy * n.y + camera.cy);
    (p.x.is_finite() && p.y.is_finite()).then_some(p)
}

/// The frame pixel of an ideal-lens pixel: the inverse of [`ideal_pixel`].
pub(super) fn frame_pixel(camera: &CameraModel, ideal: Point) -> Option<Point> {
    camera.pixel_from_normalized(normalized(camera, ideal))
}

/// The normalised image coordinates of an ideal-lens pixel.
pub(super) fn normalized(camera: &CameraModel, ideal: Point) -> Point {
    Point::new(
        (ideal.x - camera.cx) / camera.fx,
        (ideal.y - camera.cy) / camera.fy,
    )
}

/// Up to [`MAX_LENS_POINTS`] evenly spaced points of `boundary`, at their ideal-lens
/// positions (rounded, relative to the returned origin), into `out`. `None` when a point
/// cannot be undistorted or lands out of the stored range.
pub(crate) fn straighten(
    camera: &CameraModel,
    boundary: &[Pixel],
    out: &mut [Pixel; MAX_LENS_POINTS],
) -> Option<Straightened> {
    let n = boundary.len();
    let count = n.min(MAX_LENS_POINTS);
    let pixel = |p: Pixel| Point::new(f32::from(p.x), f32::from(p.y));
    let first = ideal_pixel(camera, pixel(*boundary.first()?))?;
    let origin = Point::new(first.x - ORIGIN_OFFSET, first.y - ORIGIN_OFFSET);
    for (i, slot) in out.iter_mut().take(count).enumerate() {
        let p = ideal_pixel(camera, pixel(*boundary.get(i * n / count)?))?;
        let (x, y) = (libm::roundf(p.x - origin.x), libm::roundf(p.y - origin.y));
        let range = 0.0..=f32::from(u16::MAX);
        if !(range.contains(&x) && range.contains(&y)) {
            return None;
        }
        *slot = Pixel {
            x: x as u16,
            y: y as u16,
        };
    }
    Some(Straightened {
        points: count,
        origin,
    })
}

/// The quad fitted to a straightened boundary, its corners taken back through the lens into
/// the frame's pixels; `None` when a corner has no image (outside the model's range).
pub(crate) fn bend_back(
    camera: &CameraModel,
    straight: &Straightened,
    quad: &Quad,
) -> Option<Quad> {
    let mut corners = quad.corners;
    for c in corners.iter_mut() {
        *c = frame_pixel(
            camera,
            Point::new(c.x + straight.origin.x, c.y + straight.origin.y),
        )?;
    }
    Some(Quad {
        corners,
        hole: quad.hole,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::quad;

    fn wide() -> CameraModel {
        CameraModel {
            distortion: [-0.35, 0.117, 0.0, 0.0, 0.0],
            ..CameraModel::pinhole(640, 480, 457.0, 457.0, 319.5, 239.5)
        }
    }

    /// The 8-connected pixel outline, clockwise on screen, of the square with the given
    /// ideal-lens corners as `camera` draws it (every point of the ideal outline distorted,
    /// rounded, repeated pixels dropped).
    fn bent_square(camera: &CameraModel, corners: [Point; 4]) -> heapless::Vec<Pixel, 4096> {
        let mut out: heapless::Vec<Pixel, 4096> = heapless::Vec::new();
        for k in 0..4 {
            let (a, b) = (corners[k], corners[(k + 1) % 4]);
            for j in 0..400 {
                let s = j as f32 / 400.0;
                let ideal = Point::new(a.x + s * (b.x - a.x), a.y + s * (b.y - a.y));
                let n = Point::new(
                    (ideal.x - camera.cx) / camera.fx,
                    (ideal.y - camera.cy) / camera.fy,
                );
                let p = camera.pixel_from_normalized(n).unwrap();
                let px = Pixel {
                    x: libm::roundf(p.x) as u16,
                    y: libm::roundf(p.y) as u16,
                };
                if out.last() != Some(&px) {
                    out.push(px).unwrap();
                }
            }
        }
        out
    }

    #[test]
    fn a_bent_marker_fits_at_its_true_corners() {
        let camera = wide();
        // A 170-pixel square (ideal lens) against the left of the frame: the lens bows its
        // edges by several pixels.
        let ideal = [
            Point::new(-60.0, 150.0),
            Point::new(120.0, 150.0),
            Point::new(120.0, 330.0),
            Point::new(-60.0, 330.0),
        ];
        let truth = ideal.map(|c| {
            let n = Point::new((c.x - camera.cx) / camera.fx, (c.y - camera.cy) / camera.fy);
            camera.pixel_from_normalized(n).unwrap()
        });
        assert!(truth.iter().all(|c| c.x > 0.0 && c.y > 0.0), "{truth:?}");
        let boundary = bent_square(&camera, ideal);
        let length = boundary.len();
        let mut out = [Pixel::default(); MAX_LENS_POINTS];
        let straight = straighten(&camera, &boundary, &mut out).unwrap();
        let points = &out[..straight.points];
        let screened = quad::screen(points, length, 7.0, true).ok().unwrap();
        let fitted = quad::fit(points, &screened, 7.0).unwrap();
        let bent = bend_back(&camera, &straight, &fitted).unwrap();
        for t in truth {
            let nearest = bent
                .corners
                .iter()
                .map(|c| c.distance(t))
                .fold(f32::MAX, f32::min);
            assert!(nearest < 2.5, "corner {t:?} fitted at {:?}", bent.corners);
        }
    }

    #[test]
    fn points_the_lens_cannot_invert_are_refused() {
        // Far beyond the fold of a strong k1 without k2.
        let camera = CameraModel {
            distortion: [-0.5, 0.0, 0.0, 0.0, 0.0],
            ..CameraModel::pinhole(640, 480, 100.0, 100.0, 320.0, 240.0)
        };
        let boundary = [Pixel { x: 600, y: 240 }; 8];
        let mut out = [Pixel::default(); MAX_LENS_POINTS];
        assert_eq!(straighten(&camera, &boundary, &mut out), None);
        assert_eq!(straighten(&camera, &[], &mut out), None);
    }
}
