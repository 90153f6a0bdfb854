//! Rolling-shutter correction of the detected corners: each corner moved to where a global
//! shutter would have seen it at the frame's time.
//!
//! The OV7725 and OV2640 expose their rows one after another over about 30 ms of a 33 ms
//! frame. Row `v` is seen `dt = (v - (h - 1) / 2) * line_time` after the frame's time (the
//! middle row's, [`CameraModel::line_time_us`]), so a vehicle rolling at 30 °/s has turned
//! 0.23° between the top row and the middle one (a few pixels at VGA), and one flying at
//! 5 m/s has moved 7.5 cm. The pose solvers assume one camera pose for all corners; fed the
//! raw corners they fit a skewed pad, and the skew comes out as a tilt and an offset.
//!
//! The correction needs no new solver: a corner at row `v` is a ray of the camera as it was
//! at `t0 + dt`, and that ray, turned and shifted by the camera's motion over `dt`, is the
//! ray the camera had at `t0`. With `w` the camera's angular rate and `c` its velocity, both
//! in the camera's axes at `t0`, and `X(t)` a fixed point in the camera frame at time `t`:
//!
//! ```text
//! X(t0) = exp([w dt]x) X(t0 + dt) + c dt
//! ```
//!
//! (the body rates of [`crate::filter::VehicleState::body_rate_at`] turned through the mount;
//! the NED velocity through the attitude at exposure and the mount). The rotation needs no
//! depth. The shift does: `X(t0 + dt)` is the ray scaled to where it meets the pad's plane,
//! which comes from the estimator's prediction of the pad at `t0` (its position; the
//! plane's normal is up as the attitude gives it when the level fix runs, else the last
//! fix's), or, while the estimator's tracks are not yet confirmed, from the last fix's
//! translation. The first frame of a sequence, with neither, is corrected for the rotation
//! only: a depth from a first fix of this frame would cost a second pad fit (tens of
//! thousands of instructions) to correct a shift of a few pixels once; the next frame has the
//! last fix. Distortion is handled by
//! correcting the ray, not the pixel: undistort, correct, distort ([`CameraModel::undistort`],
//! [`CameraModel::project`]).
//!
//! The cost is a few dozen floating-point operations per corner, five points per pad marker
//! (four corners and the centre) and only the pad's markers: no trigonometry (the rotation
//! by its series to the fourth order, exact to `|w dt|^5 / 120`, 1e-7 rad at 300 °/s over
//! 15 ms), no allocation, no iteration on a pinhole camera.

use crate::camera::CameraModel;
use crate::detect::Detection;
use crate::family::Family;
use crate::geometry::Point;
use crate::pad::PadLayout;
use crate::pose::{layout_marker, MAX_FIX_MARKERS};
use nalgebra::Vector3;

/// The pad's plane in the camera frame at the frame's time: the points `X` with
/// `normal · X = distance`, `distance > 0` (the camera is off the plane, on its normal's
/// negative side).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PadPlane {
    /// Unit normal, camera frame.
    pub normal: Vector3<f32>,
    /// The camera's distance from the plane, metres.
    pub distance: f32,
}

/// Closest the camera may be to the pad's plane for a depth to be taken from it, metres.
const MIN_PLANE_DISTANCE_M: f32 = 0.05;
/// Smallest cosine between a corner's ray and the plane's normal for the ray's depth to be
/// taken from the plane: 0.05 is 87°, a ray grazing the plane.
const MIN_RAY_COSINE: f32 = 0.05;

impl PadPlane {
    /// The plane through `point` (camera frame) with normal `normal`, oriented so that the
    /// distance is positive; `None` when the normal is degenerate or the camera is within
    /// [`MIN_PLANE_DISTANCE_M`] of the plane.
    pub fn through(point: &Vector3<f32>, normal: &Vector3<f32>) -> Option<Self> {
        let length = normal.norm();
        if !(length > 1e-6) {
            return None;
        }
        let normal = normal / length;
        let distance = normal.dot(point);
        let (normal, distance) = if distance < 0.0 {
            (-normal, -distance)
        } else {
            (normal, distance)
        };
        (distance.is_finite() && distance > MIN_PLANE_DISTANCE_M)
            .then_some(PadPlane { normal, distance })
    }
}

/// How the camera moves during one frame's readout, in the camera's axes at the frame time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ReadoutMotion {
    /// Angular rate, rad/s, camera frame.
    rate: Vector3<f32>,
    /// Velocity (m/s, camera frame) and the pad's plane, when both are known.
    translation: Option<(Vector3<f32>, PadPlane)>,
    /// Row-to-row time, seconds.
    line_time_s: f32,
    /// The row exposed at the frame's time, `(height - 1) / 2`.
    middle_row: f32,
}

impl ReadoutMotion {
    /// The motion of `camera` turning at `rate` (rad/s, camera frame) and, when known,
    /// moving at `velocity` (m/s, camera frame) over the pad's `plane`. `None` for a global
    /// shutter (`line_time_us` 0) or a rate that is not finite.
    pub fn new(
        camera: &CameraModel,
        rate: Vector3<f32>,
        velocity: Option<Vector3<f32>>,
        plane: Option<PadPlane>,
    ) -> Option<Self> {
        if !(camera.line_time_us > 0.0 && camera.line_time_us.is_finite()) {
            return None;
        }
        if !rate.iter().all(|c| c.is_finite()) {
            return None;
        }
        let translation = velocity
            .filter(|v| v.iter().all(|c| c.is_finite()))
            .zip(plane);
        Some(ReadoutMotion {
            rate,
            translation,
            line_time_s: camera.line_time_us * 1.0e-6,
            middle_row: (camera.height as f32 - 1.0) * 0.5,
        })
    }

    /// Whether the camera's translation is corrected too (not only its rotation).
    #[cfg(test)]
    pub fn corrects_translation(&self) -> bool {
        self.translation.is_some()
    }

    /// Where a global shutter at the frame's time would have seen what `pixel` shows; `None`
    /// when the pixel cannot be undistorted, its ray does not meet the pad's plane in front of
    /// the camera, or the corrected point is behind the camera.
    pub fn correct(&self, camera: &CameraModel, pixel: Point) -> Option<Point> {
        let dt = (pixel.y - self.middle_row) * self.line_time_s;
        let n = camera.undistort(pixel)?;
        let ray = Vector3::new(n.x, n.y, 1.0);
        let turned = rotate(&(self.rate * dt), &ray);
        let at_frame_time = match &self.translation {
            None => turned,
            Some((velocity, plane)) => {
                // The point is on the plane at t0: normal · (depth R ray + shift) = distance.
                let shift = velocity * dt;
                let cosine = plane.normal.dot(&turned);
                if !(cosine > MIN_RAY_COSINE * turned.norm()) {
                    return None;
                }
                let depth = (plane.distance - plane.normal.dot(&shift)) / cosine;
                if !(depth > 0.0) {
                    return None;
                }
                turned * depth + shift
            }
        };
        camera.project(&at_frame_time)
    }
}

/// `v` rotated by the rotation vector `theta` (Rodrigues' formula with its coefficients
/// `sin a / a` and `(1 - cos a) / a^2` by their series to `a^4`).
fn rotate(theta: &Vector3<f32>, v: &Vector3<f32>) -> Vector3<f32> {
    let a2 = theta.norm_squared();
    let sin_term = 1.0 - a2 * (1.0 / 6.0) * (1.0 - a2 * (1.0 / 20.0));
    let cos_term = 0.5 * (1.0 - a2 * (1.0 / 12.0) * (1.0 - a2 * (1.0 / 30.0)));
    let cross = theta.cross(v);
    v + cross * sin_term + theta.cross(&cross) * cos_term
}

/// Whether `detection` shows a marker of `pad` (matched as the pad fix matches it).
fn on_pad(detection: &Detection, families: &[&Family<'_>], pad: &PadLayout<'_>) -> bool {
    layout_marker(pad, families, detection).is_some()
}

/// The detections of `pad`'s markers (each layout marker once, the first seen, as the pad fix
/// takes them), corners and centre corrected by `motion`, into `out` (cleared first). A
/// detection one of whose points cannot be corrected is kept as detected: its five points
/// stay consistent with each other.
pub(crate) fn correct_pad_detections(
    detections: &[Detection],
    families: &[&Family<'_>],
    pad: &PadLayout<'_>,
    camera: &CameraModel,
    motion: &ReadoutMotion,
    out: &mut heapless::Vec<Detection, MAX_FIX_MARKERS>,
) {
    out.clear();
    for detection in detections {
        if !on_pad(detection, families, pad)
            || out
                .iter()
                .any(|d| d.family == detection.family && d.id == detection.id)
        {
            continue;
        }
        let mut corrected = *detection;
        let points = corrected
            .corners
            .iter_mut()
            .chain(core::iter::once(&mut corrected.center));
        let mut all = true;
        for point in points {
            match motion.correct(camera, *point) {
                Some(p) => *point = p,
                None => all = false,
            }
        }
        // Full: as many markers as one fit takes (the pad fit's own limit).
        if out.push(if all { corrected } else { *detection }).is_err() {
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::{camera_to_ned_matrix, Attitude, CameraMount};
    use crate::pad::PadMarker;
    use crate::pose::{pad_pose, Pose};
    use nalgebra::{Matrix3, UnitQuaternion};

    /// A 640x480 camera with a 60° lens, mild barrel distortion and a 30 ms readout.
    fn camera() -> CameraModel {
        CameraModel {
            distortion: [-0.05, 0.01, 0.0, 0.0, 0.0],
            line_time_us: 30_000.0 / 480.0,
            ..CameraModel::pinhole(640, 480, 554.3, 554.3, 319.5, 239.5)
        }
    }

    /// The ground truth of one frame: the camera's pose in NED and its motion.
    struct Flight {
        /// Camera centre at the frame's time, NED, metres.
        position: Vector3<f32>,
        /// Body attitude at the frame's time.
        attitude: UnitQuaternion<f32>,
        /// Body rate, rad/s, body FRD.
        body_rate: Vector3<f32>,
        /// Velocity, m/s, NED.
        velocity: Vector3<f32>,
        mount: CameraMount,
    }

    impl Flight {
        /// A camera 10 m above the origin, tilted 10° and 5°, rolling, pitching and yawing
        /// at 30 °/s and flying at 5 m/s north-east and 1 m/s down.
        fn fast() -> Self {
            let att = Attitude::from_euler(0.17, -0.09, 0.6).unwrap();
            let [w, x, y, z] = att.quaternion_wxyz();
            Flight {
                position: Vector3::new(0.3, -0.4, -10.0),
                attitude: UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(w, x, y, z)),
                body_rate: Vector3::new(1.0, 1.0, 1.0) * 30.0f32.to_radians(),
                velocity: Vector3::new(3.54, 3.54, 1.0),
                mount: CameraMount::downward(),
            }
        }

        fn attitude_at(&self, dt: f32) -> Attitude {
            let q = self.attitude * UnitQuaternion::from_scaled_axis(self.body_rate * dt);
            Attitude::from_quaternion_wxyz([q.w, q.i, q.j, q.k]).unwrap()
        }

        /// Camera-frame coordinates of an NED point at `t0 + dt`.
        fn camera_point(&self, ned: &Vector3<f32>, dt: f32) -> Vector3<f32> {
            let r = camera_to_ned_matrix(&self.attitude_at(dt), &self.mount);
            r.transpose() * (ned - (self.position + self.velocity * dt))
        }

        /// Where a global shutter at the frame's time sees `ned`.
        fn global_pixel(&self, camera: &CameraModel, ned: &Vector3<f32>) -> Point {
            camera.project(&self.camera_point(ned, 0.0)).unwrap()
        }

        /// Where the rolling shutter sees `ned`: at the time of the row it lands on (a fixed
        /// point: the row depends on the time, the time on the row).
        fn rolling_pixel(&self, camera: &CameraModel, ned: &Vector3<f32>) -> Point {
            let middle = (camera.height as f32 - 1.0) * 0.5;
            let mut pixel = self.global_pixel(camera, ned);
            for _ in 0..20 {
                let dt = (pixel.y - middle) * camera.line_time_us * 1e-6;
                pixel = camera.project(&self.camera_point(ned, dt)).unwrap();
            }
            pixel
        }

        /// The motion the pipeline builds from the vehicle state, with an exact plane.
        fn motion(&self, camera: &CameraModel, translation: bool) -> ReadoutMotion {
            let r = camera_to_ned_matrix(&self.attitude_at(0.0), &self.mount);
            let rate = self.mount.body_to_camera(&self.body_rate);
            let velocity = r.transpose() * self.velocity;
            // The pad: the NED plane z = 0, normal down (+z).
            let origin = self.camera_point(&Vector3::zeros(), 0.0);
            let plane = PadPlane::through(&origin, &(r.transpose() * Vector3::z()));
            ReadoutMotion::new(camera, rate, Some(velocity), plane.filter(|_| translation)).unwrap()
        }

        /// The pad-to-camera pose at the frame time, the pad frame being x north, y west,
        /// z up with its origin at the NED origin.
        fn pad_pose(&self) -> Pose {
            let ned_from_pad = Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0);
            let r = camera_to_ned_matrix(&self.attitude_at(0.0), &self.mount).transpose();
            Pose {
                rotation: r * ned_from_pad,
                translation: -(r * self.position),
            }
        }
    }

    /// NED points of a grid over the field of view, on the ground.
    fn ground_points() -> impl Iterator<Item = Vector3<f32>> {
        (0..7).flat_map(|i| {
            (0..7).map(move |j| Vector3::new(i as f32 * 1.6 - 4.5, j as f32 * 1.6 - 5.2, 0.0))
        })
    }

    #[test]
    fn corrected_points_are_the_global_shutters_within_a_twentieth_of_a_pixel() {
        let camera = camera();
        let flight = Flight::fast();
        let motion = flight.motion(&camera, true);
        assert!(motion.corrects_translation());
        let (mut worst_raw, mut worst, mut points) = (0.0f32, 0.0f32, 0);
        for ned in ground_points() {
            let global = flight.global_pixel(&camera, &ned);
            if !(0.0..640.0).contains(&global.x) || !(0.0..480.0).contains(&global.y) {
                continue;
            }
            let rolling = flight.rolling_pixel(&camera, &ned);
            let corrected = motion.correct(&camera, rolling).unwrap();
            worst_raw = worst_raw.max(rolling.distance(global));
            worst = worst.max(corrected.distance(global));
            points += 1;
        }
        assert!(points > 20, "{points} points in view");
        // The skew is several pixels; what is left is float rounding.
        assert!(
            worst_raw > 3.0,
            "rolling shutter moved points by {worst_raw} px"
        );
        assert!(
            worst < 0.05,
            "corrected points {worst} px off (raw {worst_raw} px)"
        );
    }

    #[test]
    fn the_rotation_alone_needs_no_depth_and_leaves_the_translation() {
        let camera = camera();
        // Turning only: the rotation-only correction is exact.
        let turning = Flight {
            velocity: Vector3::zeros(),
            ..Flight::fast()
        };
        let motion = turning.motion(&camera, false);
        assert!(!motion.corrects_translation());
        for ned in ground_points() {
            let global = turning.global_pixel(&camera, &ned);
            if (0.0..640.0).contains(&global.x) && (0.0..480.0).contains(&global.y) {
                let rolling = turning.rolling_pixel(&camera, &ned);
                let corrected = motion.correct(&camera, rolling).unwrap();
                assert!(corrected.distance(global) < 0.05, "{ned:?}");
            }
        }
        // Flying without turning: without a plane nothing is corrected. 5 m/s at 10 m over
        // 15 ms is 4 px at f = 554 px at the top and bottom rows.
        let flying = Flight {
            body_rate: Vector3::zeros(),
            ..Flight::fast()
        };
        let (rotation_only, full) = (flying.motion(&camera, false), flying.motion(&camera, true));
        let mut worst_raw = 0.0f32;
        for ned in ground_points() {
            let global = flying.global_pixel(&camera, &ned);
            if (0.0..640.0).contains(&global.x) && (0.0..480.0).contains(&global.y) {
                let rolling = flying.rolling_pixel(&camera, &ned);
                let unmoved = rotation_only.correct(&camera, rolling).unwrap();
                assert!(unmoved.distance(rolling) < 1e-3, "{ned:?}");
                assert!(full.correct(&camera, rolling).unwrap().distance(global) < 0.05);
                worst_raw = worst_raw.max(rolling.distance(global));
            }
        }
        assert!(worst_raw > 2.0, "the travel moved points by {worst_raw} px");
    }

    #[test]
    fn a_global_shutter_or_an_unknown_rate_is_no_correction() {
        let global = CameraModel {
            line_time_us: 0.0,
            ..camera()
        };
        let rate = Vector3::new(0.5, 0.0, 0.0);
        assert_eq!(ReadoutMotion::new(&global, rate, None, None), None);
        let nan = Vector3::new(f32::NAN, 0.0, 0.0);
        assert_eq!(ReadoutMotion::new(&camera(), nan, None, None), None);
        // The middle row is exposed at the frame's time: unchanged whatever the motion.
        let motion = Flight::fast().motion(&camera(), true);
        let middle = Point::new(100.0, 239.5);
        assert!(motion.correct(&camera(), middle).unwrap().distance(middle) < 1e-3);
        // Degenerate planes are refused, a ray away from the plane gives no point.
        assert_eq!(
            PadPlane::through(&Vector3::new(0.0, 0.0, 0.01), &Vector3::z()),
            None
        );
        assert_eq!(PadPlane::through(&Vector3::z(), &Vector3::zeros()), None);
        let plane = PadPlane::through(&Vector3::new(0.0, 0.0, -5.0), &Vector3::z()).unwrap();
        assert_eq!((plane.normal, plane.distance), (-Vector3::z(), 5.0));
        let behind = ReadoutMotion::new(&camera(), rate, Some(Vector3::zeros()), Some(plane));
        assert_eq!(
            behind.unwrap().correct(&camera(), Point::new(10.0, 10.0)),
            None
        );
    }

    /// The pad of the pose test: four 1 m markers of the first default family in a square.
    const MARKERS: [PadMarker<'static>; 4] = [
        square_marker(0, -1.2, 1.2),
        square_marker(1, 1.2, 1.2),
        square_marker(2, 1.2, -1.2),
        square_marker(3, -1.2, -1.2),
    ];

    const fn square_marker(id: u16, x: f32, y: f32) -> PadMarker<'static> {
        PadMarker {
            family: "tag36h11",
            id,
            size: 1.0,
            x,
            y,
            yaw_deg: 0.0,
        }
    }

    #[test]
    fn the_pad_pose_from_corrected_corners_is_the_frame_times() {
        let camera = camera();
        let families = crate::family::tables::DEFAULT;
        let family = families
            .iter()
            .position(|f| f.name.eq_ignore_ascii_case("tag36h11"))
            .unwrap() as u8;
        let pad = PadLayout::new("square", &MARKERS).unwrap();
        let flight = Flight::fast();
        let truth = flight.pad_pose();
        let pad_to_ned = |p: &Vector3<f32>| Vector3::new(p.x, -p.y, -p.z);
        // The detections a rolling shutter gives (an extra marker off the pad, one twice).
        let mut detections = heapless::Vec::<Detection, 8>::new();
        for (k, marker) in MARKERS.iter().enumerate() {
            let half = marker.size * 0.5;
            // Top-left, top-right, bottom-right, bottom-left as the marker is printed.
            let corners_pad = [(-half, half), (half, half), (half, -half), (-half, -half)]
                .map(|(x, y)| Vector3::new(marker.x + x, marker.y + y, 0.0));
            let centre = Vector3::new(marker.x, marker.y, 0.0);
            let detection = Detection {
                family,
                id: k as u16,
                hamming: 0,
                corners: corners_pad.map(|c| flight.rolling_pixel(&camera, &pad_to_ned(&c))),
                center: flight.rolling_pixel(&camera, &pad_to_ned(&centre)),
                decision_margin: 1.0,
                contrast: 100.0,
            };
            detections.push(detection).unwrap();
        }
        let mut stranger = detections[0];
        stranger.id = 99;
        detections.push(stranger).unwrap();
        detections.push(detections[1]).unwrap();

        let motion = flight.motion(&camera, true);
        let mut corrected = heapless::Vec::new();
        correct_pad_detections(
            &detections,
            families,
            &pad,
            &camera,
            &motion,
            &mut corrected,
        );
        assert_eq!(corrected.len(), 4, "the pad's four markers, once each");

        let error = |dets: &[Detection]| {
            let fix = pad_pose(dets, families, &pad, &camera).unwrap();
            let position = (fix.camera_position() - truth.camera_position()).norm();
            let rotation = fix.pose.rotation.transpose() * truth.rotation;
            let angle = libm::acosf(((rotation.trace() - 1.0) * 0.5).clamp(-1.0, 1.0));
            (position, angle.to_degrees())
        };
        let (raw_m, raw_deg) = error(&detections);
        let (fixed_m, fixed_deg) = error(&corrected);
        // Without the correction: decimetres and tenths of a degree at 10 m.
        assert!(raw_m > 0.05 && raw_deg > 0.1, "raw {raw_m} m {raw_deg}°");
        assert!(
            fixed_m < 0.01 && fixed_deg < 0.02,
            "corrected {fixed_m} m {fixed_deg}°"
        );
    }
}
