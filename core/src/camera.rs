//! Camera model: pinhole intrinsics with Brown-Conrady lens distortion.
//!
//! Only the marker corners are undistorted, never the whole frame: four points per marker
//! cost nothing, while remapping a frame would cost a frame-sized buffer and a pass over
//! every pixel on a microcontroller. The pose solvers therefore work in *normalised image
//! coordinates* (undistorted, `x = X/Z`, `y = Y/Z` in the camera frame) for their closed-form
//! starts and in *pixels* (with distortion) for the reprojection error they minimise.
//!
//! The distortion is OpenCV's five-coefficient model `[k1, k2, p1, p2, k3]`: for normalised
//! `(x, y)` with `r^2 = x^2 + y^2`,
//!
//! ```text
//! radial = 1 + k1 r^2 + k2 r^4 + k3 r^6
//! x_d = x radial + 2 p1 x y + p2 (r^2 + 2 x^2)
//! y_d = y radial + p1 (r^2 + 2 y^2) + 2 p2 x y
//! u = fx x_d + cx,   v = fy y_d + cy
//! ```
//!
//! Pixel convention (the contract): (0, 0) is the centre of the top-left pixel, x right,
//! y down; the camera frame is x right, y down, z forward along the optical axis.
//!
//! The inverse of the distortion has no closed form. [`CameraModel::undistort`] runs Newton's
//! method on the 2x2 distortion Jacobian with a fixed iteration cap and a convergence test,
//! and refuses points where the model folds over (Jacobian determinant not positive): strong
//! wide-angle models are not invertible far outside the calibrated field, and a silently
//! wrong corner is worse than a dropped one.

use crate::geometry::Point;
use nalgebra::{Matrix2, Matrix2x3, Vector2, Vector3};

/// Newton iterations allowed when inverting the distortion.
pub const UNDISTORT_MAX_ITERATIONS: usize = 20;
/// Convergence threshold of [`CameraModel::undistort`], pixels (distorted-image distance).
pub const UNDISTORT_TOLERANCE_PX: f32 = 1e-3;
/// Points closer to the camera plane than this (metres along z) are not projected.
pub const MIN_DEPTH: f32 = 1e-6;

/// Why a camera model is unusable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CameraError {
    /// Width or height is zero.
    EmptyImage,
    /// `fx` or `fy` is not a finite positive number.
    BadFocalLength,
    /// `fx / fy` is outside [`MAX_ASPECT`]'s range: almost certainly a typo.
    BadAspect,
    /// `cx` or `cy` is not finite, or further than one image size from the image centre.
    BadPrincipalPoint,
    /// A distortion coefficient is not finite.
    BadDistortion,
    /// The line time is negative, not finite, or the frame's readout exceeds
    /// [`MAX_READOUT_US`].
    BadLineTime,
}

/// Longest accepted frame readout (`line_time_us * height`), microseconds.
pub const MAX_READOUT_US: f32 = 1.0e6;

/// Largest accepted ratio between `fx` and `fy` (either way round).
pub const MAX_ASPECT: f32 = 4.0;

/// A pixel coordinate in a frame resampled `factor` new pixels per old pixel: pixel centres
/// are at whole coordinates, so a block's centre maps to the new pixel's (the contract's
/// convention: (0, 0) is the centre of the top-left pixel).
pub fn resampled_coordinate(x: f32, factor: f32) -> f32 {
    (x + 0.5) * factor - 0.5
}

/// A calibrated camera. Lengths in pixels; see the module documentation for the model.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CameraModel {
    /// Image width the calibration is for, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f32,
    /// Focal length along y, pixels.
    pub fy: f32,
    /// Principal point x, pixels.
    pub cx: f32,
    /// Principal point y, pixels.
    pub cy: f32,
    /// `[k1, k2, p1, p2, k3]`, OpenCV's order; all zero for an ideal pinhole.
    pub distortion: [f32; 5],
    /// Rolling shutter: the time from one row's exposure to the next row's, microseconds
    /// (row `v` is exposed `(v - (height - 1) / 2) * line_time_us` after the frame's time,
    /// which is the middle row's); 0 for a global shutter. A property of the sensor as
    /// clocked (pixel clock and line length), not of the lens, but it travels with the
    /// calibration because both describe how a pixel came to be.
    pub line_time_us: f32,
}

impl CameraModel {
    /// A distortion-free camera (not validated; see [`CameraModel::validate`]). `const`, so a
    /// firmware can hold its calibration in a `static`.
    pub const fn pinhole(width: u32, height: u32, fx: f32, fy: f32, cx: f32, cy: f32) -> Self {
        CameraModel {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            distortion: [0.0; 5],
            line_time_us: 0.0,
        }
    }

    /// The same lens for the same scene resampled `factor` new pixels per old pixel along
    /// each axis (0.5: a frame halved by averaging 2x2 blocks; 2: the other way), into a
    /// `width x height` frame: focal lengths scale, the principal point moves with the pixel
    /// centres ([`resampled_coordinate`]), the distortion (on normalised coordinates) stays,
    /// and a row takes `1 / factor` times as long to read out.
    pub fn resampled(&self, factor: f32, width: u32, height: u32) -> CameraModel {
        CameraModel {
            width,
            height,
            fx: self.fx * factor,
            fy: self.fy * factor,
            cx: resampled_coordinate(self.cx, factor),
            cy: resampled_coordinate(self.cy, factor),
            distortion: self.distortion,
            line_time_us: self.line_time_us / factor,
        }
    }

    /// A checked camera model.
    pub fn new(
        width: u32,
        height: u32,
        focal: (f32, f32),
        principal_point: (f32, f32),
        distortion: [f32; 5],
    ) -> Result<Self, CameraError> {
        let camera = CameraModel {
            width,
            height,
            fx: focal.0,
            fy: focal.1,
            cx: principal_point.0,
            cy: principal_point.1,
            distortion,
            line_time_us: 0.0,
        };
        camera.validate()?;
        Ok(camera)
    }

    /// Checks that the numbers describe a usable camera.
    pub fn validate(&self) -> Result<(), CameraError> {
        if self.width == 0 || self.height == 0 {
            return Err(CameraError::EmptyImage);
        }
        if !(self.fx.is_finite() && self.fx > 0.0 && self.fy.is_finite() && self.fy > 0.0) {
            return Err(CameraError::BadFocalLength);
        }
        let aspect = self.fx / self.fy;
        if !(1.0 / MAX_ASPECT..=MAX_ASPECT).contains(&aspect) {
            return Err(CameraError::BadAspect);
        }
        let (w, h) = (self.width as f32, self.height as f32);
        if !((self.cx - 0.5 * w).abs() <= w && (self.cy - 0.5 * h).abs() <= h) {
            return Err(CameraError::BadPrincipalPoint);
        }
        if self.distortion.iter().any(|k| !k.is_finite()) {
            return Err(CameraError::BadDistortion);
        }
        // A frame's rows cannot take longer to read than a second: anything beyond is a typo
        // (milliseconds for microseconds) that would skew every corner.
        if !(self.line_time_us.is_finite()
            && self.line_time_us >= 0.0
            && self.line_time_us * self.height as f32 <= MAX_READOUT_US)
        {
            return Err(CameraError::BadLineTime);
        }
        Ok(())
    }

    /// True when any distortion coefficient is non-zero.
    pub fn has_distortion(&self) -> bool {
        self.distortion.iter().any(|&k| k != 0.0)
    }

    /// Applies the lens distortion to normalised coordinates.
    pub fn distort(&self, normalized: Point) -> Point {
        let [k1, k2, p1, p2, k3] = self.distortion;
        let (x, y) = (normalized.x, normalized.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        Point::new(
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// Jacobian of [`CameraModel::distort`] with respect to the undistorted `(x, y)`.
    pub fn distortion_jacobian(&self, normalized: Point) -> Matrix2<f32> {
        let [k1, k2, p1, p2, k3] = self.distortion;
        let (x, y) = (normalized.x, normalized.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        // d(radial)/d(r^2)
        let d_radial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
        Matrix2::new(
            radial + 2.0 * x * x * d_radial + 2.0 * p1 * y + 6.0 * p2 * x,
            2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y,
            2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y,
            radial + 2.0 * y * y * d_radial + 6.0 * p1 * y + 2.0 * p2 * x,
        )
    }

    /// The pixel of normalised (undistorted) image coordinates, distortion applied; `None`
    /// when the result is not finite.
    pub fn pixel_from_normalized(&self, normalized: Point) -> Option<Point> {
        let d = self.distort(normalized);
        let p = Point::new(self.fx * d.x + self.cx, self.fy * d.y + self.cy);
        (p.x.is_finite() && p.y.is_finite()).then_some(p)
    }

    /// The pixel a camera-frame point is seen at; `None` behind (or on) the camera plane.
    pub fn project(&self, point_cam: &Vector3<f32>) -> Option<Point> {
        if !(point_cam.z > MIN_DEPTH) {
            return None;
        }
        self.pixel_from_normalized(Point::new(
            point_cam.x / point_cam.z,
            point_cam.y / point_cam.z,
        ))
    }

    /// The pixel of a camera-frame point and the 2x3 Jacobian of that pixel with respect to
    /// the point (for Gauss-Newton); `None` behind the camera.
    pub fn project_with_jacobian(
        &self,
        point_cam: &Vector3<f32>,
    ) -> Option<(Point, Matrix2x3<f32>)> {
        if !(point_cam.z > MIN_DEPTH) {
            return None;
        }
        let inv_z = 1.0 / point_cam.z;
        let n = Point::new(point_cam.x * inv_z, point_cam.y * inv_z);
        let pixel = self.pixel_from_normalized(n)?;
        // d(normalised)/d(point)
        let dn = Matrix2x3::new(inv_z, 0.0, -n.x * inv_z, 0.0, inv_z, -n.y * inv_z);
        let focal = Matrix2::new(self.fx, 0.0, 0.0, self.fy);
        Some((pixel, focal * self.distortion_jacobian(n) * dn))
    }

    /// Normalised (undistorted) image coordinates of a pixel: the inverse of
    /// [`CameraModel::pixel_from_normalized`]. `None` when Newton's method does not converge
    /// within [`UNDISTORT_MAX_ITERATIONS`], or the point lies where the distortion model
    /// folds over and has no unique inverse.
    pub fn undistort(&self, pixel: Point) -> Option<Point> {
        let target = Vector2::new((pixel.x - self.cx) / self.fx, (pixel.y - self.cy) / self.fy);
        if !(target.x.is_finite() && target.y.is_finite()) {
            return None;
        }
        if !self.has_distortion() {
            return Some(Point::new(target.x, target.y));
        }
        // Tolerance in normalised units from the pixel tolerance.
        let tolerance = UNDISTORT_TOLERANCE_PX / self.fx.max(self.fy);
        let mut x = target;
        for _ in 0..UNDISTORT_MAX_ITERATIONS {
            let p = Point::new(x.x, x.y);
            let d = self.distort(p);
            let residual = Vector2::new(d.x - target.x, d.y - target.y);
            let jacobian = self.distortion_jacobian(p);
            if !(jacobian.determinant() > 0.0) {
                return None;
            }
            if residual.norm() < tolerance {
                return Some(p);
            }
            let step = jacobian.try_inverse()? * residual;
            x -= step;
            if !(x.x.is_finite() && x.y.is_finite()) {
                return None;
            }
        }
        // Last chance: converged on the final step.
        let p = Point::new(x.x, x.y);
        let d = self.distort(p);
        let residual = Vector2::new(d.x - target.x, d.y - target.y);
        (residual.norm() < tolerance && self.distortion_jacobian(p).determinant() > 0.0)
            .then_some(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resampling_moves_the_principal_point_with_the_pixel_centres() {
        let camera = CameraModel {
            line_time_us: 60.0,
            ..CameraModel::pinhole(640, 480, 500.0, 502.0, 319.5, 239.5)
        };
        let half = camera.resampled(0.5, 320, 240);
        assert_eq!(
            (half.fx, half.fy, half.cx, half.cy),
            (250.0, 251.0, 159.5, 119.5)
        );
        assert_eq!(half.line_time_us, 120.0);
        assert_eq!(half.resampled(2.0, 640, 480), camera);
        assert_eq!(resampled_coordinate(0.0, 0.5), -0.25);
    }

    fn strong() -> CameraModel {
        CameraModel {
            distortion: [-0.3, 0.1, 0.001, -0.0015, -0.005],
            ..CameraModel::pinhole(640, 480, 457.0, 457.0, 318.2, 241.7)
        }
    }

    #[test]
    fn validation() {
        let good = CameraModel::pinhole(640, 480, 700.0, 700.0, 320.0, 240.0);
        assert_eq!(good.validate(), Ok(()));
        let bad = |f: fn(&mut CameraModel)| {
            let mut c = good;
            f(&mut c);
            c.validate().unwrap_err()
        };
        assert_eq!(bad(|c| c.width = 0), CameraError::EmptyImage);
        assert_eq!(bad(|c| c.fx = -1.0), CameraError::BadFocalLength);
        assert_eq!(bad(|c| c.fy = f32::NAN), CameraError::BadFocalLength);
        assert_eq!(bad(|c| c.fy = 70.0), CameraError::BadAspect);
        assert_eq!(
            bad(|c| c.cx = f32::INFINITY),
            CameraError::BadPrincipalPoint
        );
        assert_eq!(bad(|c| c.cy = 5000.0), CameraError::BadPrincipalPoint);
        assert_eq!(
            bad(|c| c.distortion[4] = f32::NAN),
            CameraError::BadDistortion
        );
    }

    #[test]
    fn undistort_inverts_strong_distortion_over_the_frame() {
        let camera = strong();
        let mut worst = 0.0f32;
        for row in 0..=24 {
            for col in 0..=32 {
                let pixel = Point::new(col as f32 * 20.0 - 0.5, row as f32 * 20.0 - 0.5);
                let n = camera
                    .undistort(pixel)
                    .expect("inside the calibrated field");
                let back = camera.pixel_from_normalized(n).unwrap();
                worst = worst.max(back.distance(pixel));
            }
        }
        assert!(worst < 2e-3, "worst round trip {worst} px");
    }

    #[test]
    fn project_then_undistort_recovers_the_ray() {
        let camera = strong();
        for k in 0..50 {
            let a = k as f32 * 0.37;
            let p = Vector3::new(0.6 * libm::cosf(a), 0.45 * libm::sinf(1.3 * a), 1.0);
            let pixel = camera.project(&p).unwrap();
            let n = camera.undistort(pixel).unwrap();
            assert!(
                (n.x - p.x).abs() < 1e-5 && (n.y - p.y).abs() < 1e-5,
                "{p:?} {n:?}"
            );
        }
        assert!(camera.project(&Vector3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let camera = strong();
        let p = Vector3::new(0.31, -0.22, 1.7);
        let (_, j) = camera.project_with_jacobian(&p).unwrap();
        for axis in 0..3 {
            let mut d = Vector3::zeros();
            d[axis] = 1e-3;
            let a = camera.project(&(p + d)).unwrap();
            let b = camera.project(&(p - d)).unwrap();
            let (gx, gy) = ((a.x - b.x) / 2e-3, (a.y - b.y) / 2e-3);
            assert!((gx - j[(0, axis)]).abs() < 0.5 && (gy - j[(1, axis)]).abs() < 0.5);
        }
    }

    #[test]
    fn folded_region_is_refused() {
        // k1 strongly negative: the model turns back on itself beyond r ~ 1.
        let camera = CameraModel {
            distortion: [-0.5, 0.0, 0.0, 0.0, 0.0],
            ..CameraModel::pinhole(640, 480, 100.0, 100.0, 320.0, 240.0)
        };
        // Beyond the fold's maximum radius (0.544 normalised, 54 px) there is no inverse.
        assert!(camera.undistort(Point::new(320.0 + 60.0, 240.0)).is_none());
        assert!(camera.undistort(Point::new(320.0 + 40.0, 240.0)).is_some());
    }
}
