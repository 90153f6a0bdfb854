//! The simulated camera: the core's [`CameraModel`] (intrinsics and Brown-Conrady
//! distortion) in `f64`, its mount on the vehicle, and the per-pixel rays the renderer uses.
//!
//! Frames (all right-handed, rotations active):
//! - **pad frame** (contract): x right, y up, z up out of the pad. The simulator's world is
//!   the pad frame with x = east and y = north, so NED = (y, x, -z).
//! - **body** FRD and the vehicle attitude body-to-NED, as MAVLink and `core::frames` use them.
//! - **camera** (contract): x right, y down, z forward. [`CameraMount::downward`] is
//!   `core::frames::CameraMount::downward`: looking straight down, image top toward the nose.
//!
//! So a level vehicle with its nose north sees the pad upright: image right = pad +x,
//! image up = pad +y.
//!
//! Rendering runs the lens backwards: every pixel corner is undistorted once per camera into
//! a normalised ray ([`RayMap`]); sub-pixel samples interpolate the rays of their pixel's
//! four corners bilinearly. The distortion is smooth at the pixel scale, so the interpolation
//! error is far below the 1/32-pixel sampling step (and zero without distortion, where the
//! map is linear).

use touchdown_core::camera::CameraModel;
use touchdown_core::geometry::Point;

use super::math::{from_columns, from_euler, mul, mul_vec, transpose, Mat3, Vec3};

/// Newton iterations in `f64` after the core's `f32` undistortion.
const POLISH_ITERATIONS: usize = 3;

/// A calibrated camera in `f64`, with the `f32` model that goes into `camera.toml`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimCamera {
    /// The model as the firmware and `camera.toml` hold it.
    pub model: CameraModel,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    k: [f64; 5],
}

impl SimCamera {
    /// The simulator's view of a core camera model (its `f32` numbers taken exactly).
    pub fn new(model: CameraModel) -> Self {
        let d = model.distortion.map(f64::from);
        SimCamera {
            model,
            fx: f64::from(model.fx),
            fy: f64::from(model.fy),
            cx: f64::from(model.cx),
            cy: f64::from(model.cy),
            k: d,
        }
    }

    /// A `width` x `height` camera with square pixels, the principal point at the frame
    /// centre and a horizontal field of view of `hfov_deg` (of the undistorted image).
    pub fn with_fov(width: u32, height: u32, hfov_deg: f64, distortion: [f32; 5]) -> Self {
        let f = (0.5 * f64::from(width) / (0.5 * hfov_deg.to_radians()).tan()) as f32;
        let model = CameraModel {
            distortion,
            ..CameraModel::pinhole(
                width,
                height,
                f,
                f,
                (f64::from(width) - 1.0) as f32 * 0.5,
                (f64::from(height) - 1.0) as f32 * 0.5,
            )
        };
        Self::new(model)
    }

    /// Frame width, pixels.
    pub fn width(&self) -> usize {
        self.model.width as usize
    }

    /// Frame height, pixels.
    pub fn height(&self) -> usize {
        self.model.height as usize
    }

    /// Focal length along x, pixels.
    pub fn fx(&self) -> f64 {
        self.fx
    }

    /// The lens distortion of normalised coordinates (OpenCV's model).
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3] = self.k;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        (
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// The pixel of normalised (undistorted) coordinates.
    pub fn pixel_of_normalized(&self, x: f64, y: f64) -> [f64; 2] {
        let (xd, yd) = self.distort(x, y);
        [self.fx * xd + self.cx, self.fy * yd + self.cy]
    }

    /// The pixel a camera-frame point is seen at; `None` behind the camera.
    pub fn project(&self, p: Vec3) -> Option<[f64; 2]> {
        (p[2] > 1e-9).then(|| self.pixel_of_normalized(p[0] / p[2], p[1] / p[2]))
    }

    /// Normalised coordinates of a pixel: the core's `f32` Newton inversion, polished in
    /// `f64`. `None` where the lens model folds over (no unique inverse).
    pub fn undistort(&self, u: f64, v: f64) -> Option<(f64, f64)> {
        let tx = (u - self.cx) / self.fx;
        let ty = (v - self.cy) / self.fy;
        if self.k.iter().all(|&k| k == 0.0) {
            return Some((tx, ty));
        }
        let start = self.model.undistort(Point::new(u as f32, v as f32))?;
        let (mut x, mut y) = (f64::from(start.x), f64::from(start.y));
        for _ in 0..POLISH_ITERATIONS {
            let (dx, dy) = self.distort(x, y);
            let (rx, ry) = (dx - tx, dy - ty);
            let [[a, b], [c, d]] = self.distortion_jacobian(x, y);
            let det = a * d - b * c;
            if det.is_nan() || det <= 0.0 {
                return None;
            }
            x -= (d * rx - b * ry) / det;
            y -= (-c * rx + a * ry) / det;
        }
        (x.is_finite() && y.is_finite()).then_some((x, y))
    }

    fn distortion_jacobian(&self, x: f64, y: f64) -> [[f64; 2]; 2] {
        let [k1, k2, p1, p2, k3] = self.k;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let d_radial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
        let off = 2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y;
        [
            [
                radial + 2.0 * x * x * d_radial + 2.0 * p1 * y + 6.0 * p2 * x,
                off,
            ],
            [
                off,
                radial + 2.0 * y * y * d_radial + 6.0 * p1 * y + 2.0 * p2 * x,
            ],
        ]
    }
}

/// Normalised rays of every pixel corner, `(width + 1) x (height + 1)`, row-major; corner
/// `(i, j)` is the point `(i - 0.5, j - 0.5)` in pixel coordinates. NaN where the lens model
/// has no inverse. Also holds the vignetting factor of every pixel centre.
#[derive(Debug, Clone)]
pub struct RayMap {
    /// Corners per row (`width + 1`).
    pub stride: usize,
    /// The rays.
    pub rays: Vec<[f64; 2]>,
    /// `cos(angle off the optical axis)` of every pixel centre, row-major `width x height`.
    pub cos_off_axis: Vec<f32>,
}

impl RayMap {
    /// Undistorts every pixel corner of `camera` (once per recording).
    pub fn new(camera: &SimCamera) -> Self {
        let (w, h) = (camera.width(), camera.height());
        let stride = w + 1;
        let mut rays = Vec::with_capacity(stride * (h + 1));
        for j in 0..=h {
            for i in 0..=w {
                let ray = camera
                    .undistort(i as f64 - 0.5, j as f64 - 0.5)
                    .map_or([f64::NAN; 2], |(x, y)| [x, y]);
                rays.push(ray);
            }
        }
        let mut cos_off_axis = Vec::with_capacity(w * h);
        for j in 0..h {
            for i in 0..w {
                let c = [
                    rays[j * stride + i],
                    rays[j * stride + i + 1],
                    rays[(j + 1) * stride + i],
                    rays[(j + 1) * stride + i + 1],
                ];
                let x = 0.25 * (c[0][0] + c[1][0] + c[2][0] + c[3][0]);
                let y = 0.25 * (c[0][1] + c[1][1] + c[2][1] + c[3][1]);
                let cos = 1.0 / (1.0 + x * x + y * y).sqrt();
                cos_off_axis.push(if cos.is_finite() { cos as f32 } else { 0.0 });
            }
        }
        RayMap {
            stride,
            rays,
            cos_off_axis,
        }
    }

    /// The ray of pixel corner `(i, j)`.
    #[inline]
    pub fn corner(&self, i: usize, j: usize) -> [f64; 2] {
        self.rays
            .get(j * self.stride + i)
            .copied()
            .unwrap_or([f64::NAN; 2])
    }
}

/// How the camera is fixed to the vehicle: the rotation camera frame to body FRD.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraMount {
    /// Camera-to-body rotation.
    pub rotation: Mat3,
}

impl CameraMount {
    /// Looking straight down, image top toward the nose (as `core::frames`).
    pub fn downward() -> Self {
        CameraMount {
            rotation: from_columns([0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        }
    }
}

impl CameraMount {
    /// The downward mount turned by `roll_deg` about body x and `pitch_deg` about body y:
    /// camera-to-body = `R_y(pitch) R_x(roll) downward` (a misaligned mount; the flight
    /// effects of [`crate::effects`]). Zero angles give [`CameraMount::downward`] exactly.
    pub fn misaligned(roll_deg: f64, pitch_deg: f64) -> Self {
        let nominal = Self::downward();
        if roll_deg == 0.0 && pitch_deg == 0.0 {
            return nominal;
        }
        let roll = from_euler(roll_deg.to_radians(), 0.0, 0.0);
        let pitch = from_euler(0.0, pitch_deg.to_radians(), 0.0);
        CameraMount {
            rotation: mul(&pitch, &mul(&roll, &nominal.rotation)),
        }
    }
}

impl Default for CameraMount {
    fn default() -> Self {
        Self::downward()
    }
}

/// NED axes to pad axes (pad x = east, y = north, z = up).
pub const NED_TO_PAD: Mat3 = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]];

/// Where the camera is: its centre and orientation in the pad frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPose {
    /// Camera-to-pad rotation.
    pub rotation: Mat3,
    /// Camera centre in the pad frame, metres.
    pub position: Vec3,
}

impl CameraPose {
    /// The camera of a vehicle at `position` (pad frame) with attitude `body_to_ned`.
    pub fn of_vehicle(position: Vec3, body_to_ned: &Mat3, mount: &CameraMount) -> Self {
        CameraPose {
            rotation: mul(&NED_TO_PAD, &mul(body_to_ned, &mount.rotation)),
            position,
        }
    }

    /// A pad-frame point in the camera frame.
    pub fn to_camera(&self, p: Vec3) -> Vec3 {
        let d = [
            p[0] - self.position[0],
            p[1] - self.position[1],
            p[2] - self.position[2],
        ];
        mul_vec(&transpose(&self.rotation), d)
    }

    /// The map from normalised image coordinates `(x, y, 1)` to pad-plane points, as a
    /// homography whose third output is positive exactly when the ray meets the ground in
    /// front of the camera (so [`crate::math::apply_homography`] refuses the sky).
    pub fn ground_homography(&self) -> Mat3 {
        // The ray d = R n meets z = 0 at c + t d with t = -c_z / d_z, i.e.
        // (c_x d_z - c_z d_x, c_y d_z - c_z d_y) / d_z; negate so the weight is -d_z > 0.
        let r = &self.rotation;
        let c = self.position;
        let mut h = [[0.0; 3]; 3];
        for k in 0..3 {
            h[0][k] = -(c[0] * r[2][k] - c[2] * r[0][k]);
            h[1][k] = -(c[1] * r[2][k] - c[2] * r[1][k]);
            h[2][k] = -r[2][k];
        }
        h
    }

    /// Distance from the camera to the ground along the optical axis (infinite when it
    /// points at or above the horizon).
    pub fn axis_distance_to_ground(&self) -> f64 {
        let dz = self.rotation[2][2];
        if dz < -1e-9 {
            self.position[2] / -dz
        } else {
            f64::INFINITY
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level_vehicle_sees_the_pad_upright() {
        let pose = CameraPose::of_vehicle(
            [0.0, 0.0, 10.0],
            &super::super::math::IDENTITY,
            &CameraMount::downward(),
        );
        // Pad +x (east) is image right, pad +y (north) image up.
        let east = pose.to_camera([1.0, 0.0, 0.0]);
        let north = pose.to_camera([0.0, 1.0, 0.0]);
        assert!(east[0] > 0.0 && east[1].abs() < 1e-12 && (east[2] - 10.0).abs() < 1e-12);
        assert!(north[1] < 0.0 && north[0].abs() < 1e-12);
    }

    #[test]
    fn undistort_inverts_the_lens() {
        let camera = SimCamera::with_fov(640, 480, 60.0, [-0.12, 0.03, 0.0005, -0.0003, 0.0]);
        for (u, v) in [(0.0, 0.0), (639.0, 479.0), (320.3, 12.7), (-0.5, 479.5)] {
            let (x, y) = camera.undistort(u, v).unwrap();
            let p = camera.pixel_of_normalized(x, y);
            assert!((p[0] - u).abs() < 1e-9 && (p[1] - v).abs() < 1e-9, "{p:?}");
        }
    }
}
