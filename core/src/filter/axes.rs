//! Vehicle attitude, the camera mount, and the axes MAVLink wants the pad in.
//!
//! The pose gives the pad in the **camera frame** (x right, y down, z forward along the
//! optical axis). The flight controllers want it elsewhere:
//!
//! - ArduPilot: LANDING_TARGET in `MAV_FRAME_BODY_FRD`, the pad relative to the vehicle in the
//!   **body frame** (x forward, y right, z down, fixed to the airframe), plus the image angles
//!   `angle_x`, `angle_y` and the `distance`.
//! - PX4: LANDING_TARGET in `MAV_FRAME_LOCAL_NED`, the pad's absolute position in the flight
//!   controller's local frame (x north, y east, z down, origin fixed to the earth), which needs
//!   the vehicle's attitude and its LOCAL_POSITION_NED.
//!
//! And the tracker ([`crate::filter::tracker`]) wants it where the pad does not move when the
//! vehicle rotates: relative to the vehicle in **NED axes** ("level NED", MAVLink's
//! LOCAL_OFFSET_NED). The yaw-aligned level frame **LOCAL_FRD** (x forward along the vehicle's
//! heading projected on the horizontal plane, y right and horizontal, z down) is also provided,
//! for controllers and logs that think in "ahead/right of me" without the tilt.
//!
//! Conventions, all right-handed, all rotations active (`v_to = R * v_from`):
//!
//! - [`Attitude`]: the unit quaternion rotating **body FRD into local NED**, Hamilton
//!   convention, scalar first `[w, x, y, z]`: exactly MAVLink's ATTITUDE_QUATERNION `q1..q4`
//!   (and PX4's `vehicle_attitude.q`); identity = level, nose north. From MAVLink's ATTITUDE
//!   (roll, pitch, yaw in radians) it is `Rz(yaw) * Ry(pitch) * Rx(roll)`.
//! - [`CameraMount`]: the rotation **camera frame into body FRD**. The default,
//!   [`CameraMount::downward`], is a camera looking straight down with the top of the image
//!   toward the nose: camera x (image right) = body +y (right), camera y (image down) = body
//!   -x (toward the tail), camera z (optical axis) = body +z (down).
//!
//! `angle_x`/`angle_y` ([`landing_angles`]): MAVLink defines them as the "X-axis / Y-axis
//! angular offset of the target from the center of the image", in radians; its landing-target
//! protocol page reads them as the angles of the ray to the target along the image's x and y
//! axes. So `angle_x = atan2(x_cam, z_cam)` (positive: target right of centre) and
//! `angle_y = atan2(y_cam, z_cam)` (positive: target below centre), computed from the
//! undistorted camera-frame position so the lens is already accounted for. This is also how
//! ArduPilot reads them: for the default mount its line of sight in the body frame is
//! `(-tan(angle_y), tan(angle_x), 1)`, i.e. image down = toward the tail.

use crate::filter::Measurement;
use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};

/// A bad attitude or mount input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RotationError {
    /// A component is NaN or infinite.
    NotFinite,
    /// The quaternion's norm is far from 1 (not a rotation, or a zero "not supported" value).
    NotUnit,
    /// The matrix is not a rotation (not orthonormal, or a reflection).
    NotRotation,
}

/// How far from 1 a quaternion's norm may be before it is refused rather than normalised.
const UNIT_TOLERANCE: f32 = 0.1;
/// How far from orthonormal a mount matrix may be (per element of `R^T R - I`).
const ROTATION_TOLERANCE: f32 = 1.0e-3;

fn unit_from_wxyz(q: [f32; 4]) -> Result<UnitQuaternion<f32>, RotationError> {
    if !q.iter().all(|v| v.is_finite()) {
        return Err(RotationError::NotFinite);
    }
    let [w, x, y, z] = q;
    let quat = Quaternion::new(w, x, y, z);
    let norm = quat.norm();
    if !((norm - 1.0).abs() <= UNIT_TOLERANCE) {
        return Err(RotationError::NotUnit);
    }
    Ok(UnitQuaternion::from_quaternion(quat))
}

fn wxyz(q: &UnitQuaternion<f32>) -> [f32; 4] {
    [q.w, q.i, q.j, q.k]
}

/// The vehicle's attitude: the rotation from body FRD to local NED (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Attitude {
    q: UnitQuaternion<f32>,
}

impl Default for Attitude {
    fn default() -> Self {
        Attitude::level_north()
    }
}

impl Attitude {
    /// Level, nose north (the identity).
    pub fn level_north() -> Self {
        Attitude {
            q: UnitQuaternion::identity(),
        }
    }

    /// From MAVLink ATTITUDE_QUATERNION's `[q1, q2, q3, q4]` = `[w, x, y, z]` (body FRD to
    /// NED). Normalised; refused when not finite or its norm is not within 10 % of 1 (an
    /// all-zero "not available" quaternion, for instance).
    pub fn from_quaternion_wxyz(q: [f32; 4]) -> Result<Self, RotationError> {
        Ok(Attitude {
            q: unit_from_wxyz(q)?,
        })
    }

    /// From MAVLink ATTITUDE's roll, pitch and yaw, radians (Tait-Bryan Z-Y-X:
    /// `Rz(yaw) Ry(pitch) Rx(roll)`).
    pub fn from_euler(roll: f32, pitch: f32, yaw: f32) -> Result<Self, RotationError> {
        if !(roll.is_finite() && pitch.is_finite() && yaw.is_finite()) {
            return Err(RotationError::NotFinite);
        }
        Ok(Attitude {
            q: UnitQuaternion::from_euler_angles(roll, pitch, yaw),
        })
    }

    /// The quaternion `[w, x, y, z]`, body FRD to NED.
    pub fn quaternion_wxyz(&self) -> [f32; 4] {
        wxyz(&self.q)
    }

    /// The rotation matrix, body FRD to NED.
    pub fn matrix(&self) -> Matrix3<f32> {
        self.q.to_rotation_matrix().into_inner()
    }

    /// Heading, radians from north toward east: the direction of the nose projected on the
    /// horizontal plane (0 when the nose points straight up or down).
    pub fn yaw(&self) -> f32 {
        let nose = self.q * Vector3::x();
        libm::atan2f(nose.y, nose.x)
    }

    /// A body FRD vector in NED axes.
    pub fn body_to_ned(&self, v: &Vector3<f32>) -> Vector3<f32> {
        self.q * v
    }

    /// A NED vector in body FRD axes.
    pub fn ned_to_body(&self, v: &Vector3<f32>) -> Vector3<f32> {
        self.q.inverse_transform_vector(v)
    }

    /// The rotation from LOCAL_FRD (yaw-aligned level) to NED: a rotation by the yaw about down.
    fn local_frd_to_ned_rotation(&self) -> Rotation3<f32> {
        Rotation3::from_axis_angle(&Vector3::z_axis(), self.yaw())
    }

    /// A NED vector in LOCAL_FRD axes (forward = heading, right, down; no tilt).
    pub fn ned_to_local_frd(&self, v: &Vector3<f32>) -> Vector3<f32> {
        self.local_frd_to_ned_rotation().inverse_transform_vector(v)
    }

    /// A LOCAL_FRD vector in NED axes.
    pub fn local_frd_to_ned(&self, v: &Vector3<f32>) -> Vector3<f32> {
        self.local_frd_to_ned_rotation() * v
    }

    /// A body FRD vector in LOCAL_FRD axes (the tilt removed, the heading kept).
    pub fn body_to_local_frd(&self, v: &Vector3<f32>) -> Vector3<f32> {
        self.ned_to_local_frd(&self.body_to_ned(v))
    }
}

/// How the camera is mounted: the rotation from the camera frame to body FRD.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraMount {
    q: UnitQuaternion<f32>,
}

impl Default for CameraMount {
    fn default() -> Self {
        CameraMount::downward()
    }
}

impl CameraMount {
    /// Looking straight down, image top toward the nose: camera x → body +y (right),
    /// camera y → body -x (tail), camera z → body +z (down).
    pub fn downward() -> Self {
        // Columns: the body-frame images of camera x, y, z.
        let m = Matrix3::new(
            0.0, -1.0, 0.0, //
            1.0, 0.0, 0.0, //
            0.0, 0.0, 1.0,
        );
        CameraMount {
            q: UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m)),
        }
    }

    /// Looking straight down, image top toward the nose, then turned by `yaw` radians about the
    /// optical axis (positive: the image top turns toward the right wing).
    pub fn downward_rotated(yaw: f32) -> Result<Self, RotationError> {
        if !yaw.is_finite() {
            return Err(RotationError::NotFinite);
        }
        let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
        Ok(CameraMount {
            q: turn * CameraMount::downward().q,
        })
    }

    /// From a quaternion `[w, x, y, z]`, camera to body FRD.
    pub fn from_quaternion_wxyz(q: [f32; 4]) -> Result<Self, RotationError> {
        Ok(CameraMount {
            q: unit_from_wxyz(q)?,
        })
    }

    /// From a rotation matrix, camera to body FRD (its columns are the camera axes in the body
    /// frame). Refused unless orthonormal with determinant +1 (to 1e-3).
    pub fn from_matrix(m: &Matrix3<f32>) -> Result<Self, RotationError> {
        if !m.iter().all(|v| v.is_finite()) {
            return Err(RotationError::NotFinite);
        }
        let err = m.transpose() * m - Matrix3::identity();
        if !err.iter().all(|v| v.abs() <= ROTATION_TOLERANCE)
            || !((m.determinant() - 1.0).abs() <= ROTATION_TOLERANCE * 3.0)
        {
            return Err(RotationError::NotRotation);
        }
        Ok(CameraMount {
            q: UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*m)),
        })
    }

    /// The quaternion `[w, x, y, z]`, camera to body FRD.
    pub fn quaternion_wxyz(&self) -> [f32; 4] {
        wxyz(&self.q)
    }

    /// The rotation matrix, camera to body FRD.
    pub fn matrix(&self) -> Matrix3<f32> {
        self.q.to_rotation_matrix().into_inner()
    }

    /// A camera-frame vector in body FRD.
    pub fn camera_to_body(&self, v: &Vector3<f32>) -> Vector3<f32> {
        self.q * v
    }

    /// A body FRD vector in the camera frame.
    pub fn body_to_camera(&self, v: &Vector3<f32>) -> Vector3<f32> {
        self.q.inverse_transform_vector(v)
    }

    /// This mount with the camera turned by `yaw_deg` degrees about its own optical axis
    /// (TD_CAM_YAW: a board mounted rotated in its plane); unchanged when `yaw_deg` is not
    /// finite.
    pub fn turned_about_optical_axis(&self, yaw_deg: f32) -> CameraMount {
        if !yaw_deg.is_finite() {
            return *self;
        }
        let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_deg.to_radians());
        CameraMount {
            q: UnitQuaternion::new_normalize((self.q * turn).into_inner()),
        }
    }

    /// This mount tilted in the body frame: turned by `roll_deg` about body x (forward), then
    /// by `pitch_deg` about body y (right), degrees: camera-to-body = `R_y(pitch) R_x(roll)
    /// self` (TD_CAM_ROLL, TD_CAM_PITCH; the simulator's mount misalignment is the same
    /// product). Unchanged when an angle is not finite.
    pub fn tilted(&self, roll_deg: f32, pitch_deg: f32) -> CameraMount {
        if !(roll_deg.is_finite() && pitch_deg.is_finite()) {
            return *self;
        }
        let roll = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), roll_deg.to_radians());
        let pitch = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), pitch_deg.to_radians());
        CameraMount {
            q: UnitQuaternion::new_normalize((pitch * roll * self.q).into_inner()),
        }
    }
}

/// The pad's orientation: the rotation from the pad frame to body FRD (`attitude` `None`) or
/// to NED (`Some`: the attitude at the exposure, body FRD to NED), `[w, x, y, z]`, from a fix's
/// rotation (pad frame to camera frame) and the mount (camera to body). `None` when the
/// rotation is not finite or not a rotation (far from orthonormal).
pub fn pad_orientation(
    pad_to_camera: &Matrix3<f32>,
    mount: &CameraMount,
    attitude: Option<&Attitude>,
) -> Option<[f32; 4]> {
    if !pad_to_camera.iter().all(|v| v.is_finite()) {
        return None;
    }
    let err = pad_to_camera.transpose() * pad_to_camera - Matrix3::identity();
    if !err.iter().all(|v| v.abs() <= 1.0e-2) || !(pad_to_camera.determinant() > 0.0) {
        return None;
    }
    let cam_pad =
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*pad_to_camera));
    // Shepperd's method on a nearly orthonormal matrix: renormalise.
    let cam_pad = UnitQuaternion::new_normalize(cam_pad.into_inner());
    let body_pad = mount.q * cam_pad;
    let q = match attitude {
        Some(att) => att.q * body_pad,
        None => body_pad,
    };
    let wxyz = [q.w, q.i, q.j, q.k];
    wxyz.iter().all(|v| v.is_finite()).then_some(wxyz)
}

/// The rotation matrix from the camera frame to NED axes: `R_ned_body * R_body_camera`.
pub fn camera_to_ned_matrix(attitude: &Attitude, mount: &CameraMount) -> Matrix3<f32> {
    (attitude.q * mount.q).to_rotation_matrix().into_inner()
}

/// A camera-frame pose measurement in the tracker's level frame: relative to the vehicle,
/// NED axes (position and covariance rotated; the time stamp kept). Use the attitude at the
/// frame's exposure time.
pub fn level_measurement(m: &Measurement, attitude: &Attitude, mount: &CameraMount) -> Measurement {
    m.rotated(&camera_to_ned_matrix(attitude, mount))
}

/// A pad position relative to the vehicle in NED axes, in the camera frame (the inverse of
/// [`level_measurement`]'s rotation), e.g. to compute [`landing_angles`] from a level estimate.
pub fn ned_to_camera(v: &Vector3<f32>, attitude: &Attitude, mount: &CameraMount) -> Vector3<f32> {
    mount.body_to_camera(&attitude.ned_to_body(v))
}

/// The pad's absolute position in LOCAL_NED (PX4's LANDING_TARGET): the vehicle's
/// LOCAL_POSITION_NED plus the relative position in NED axes.
pub fn local_ned_position(
    vehicle_position_ned: &Vector3<f32>,
    relative_ned: &Vector3<f32>,
) -> Vector3<f32> {
    vehicle_position_ned + relative_ned
}

/// LANDING_TARGET's `angle_x`, `angle_y`, radians (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LandingAngles {
    /// Angle of the ray to the target along the image x axis: `atan2(x_cam, z_cam)`,
    /// positive to the right of the image centre.
    pub angle_x: f32,
    /// Angle along the image y axis: `atan2(y_cam, z_cam)`, positive below the image centre.
    pub angle_y: f32,
}

/// `angle_x`, `angle_y` of a target at camera-frame position `p`; `None` when it is not in
/// front of the camera (`z_cam <= 0`) or not finite.
pub fn landing_angles(p: &Vector3<f32>) -> Option<LandingAngles> {
    if !(p.z > 0.0) || !p.iter().all(|v| v.is_finite()) {
        return None;
    }
    Some(LandingAngles {
        angle_x: libm::atan2f(p.x, p.z),
        angle_y: libm::atan2f(p.y, p.z),
    })
}

/// LANDING_TARGET's `distance`: the distance from the camera to the target, metres.
pub fn distance(p: &Vector3<f32>) -> f32 {
    p.norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(q: [f32; 4]) -> UnitQuaternion<f32> {
        let [w, x, y, z] = q;
        UnitQuaternion::new_normalize(Quaternion::new(w, x, y, z))
    }

    #[test]
    fn orientation_of_a_yawed_pad() {
        // Camera straight down, image top to the nose; pad x along camera x, pad y along
        // camera -y, pad z toward the camera (-z): the pad "upright" in the image.
        let mount = CameraMount::downward();
        let upright = Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0);
        let yaw = 0.4f32;
        let turned = upright * Rotation3::from_axis_angle(&Vector3::z_axis(), yaw).into_inner();
        let q0 = unit(pad_orientation(&upright, &mount, None).unwrap());
        let q1 = unit(pad_orientation(&turned, &mount, None).unwrap());
        // Pad y (the top of the print) in body FRD: forward, then turned.
        let y0 = q0 * Vector3::y();
        assert!((y0 - Vector3::x()).amax() < 1e-5, "{y0}");
        let a = q0.angle_to(&q1);
        assert!((a - yaw).abs() < 1e-4, "{a}");
        let att = Attitude::from_euler(0.0, 0.0, 1.0).unwrap();
        let qn = unit(pad_orientation(&upright, &mount, Some(&att)).unwrap());
        let yn = qn * Vector3::y();
        assert!((libm::atan2f(yn.y, yn.x) - 1.0).abs() < 1e-5);
        let mut bad = upright;
        bad[(0, 0)] = f32::NAN;
        assert!(pad_orientation(&bad, &mount, None).is_none());
        assert!(pad_orientation(&(upright * 2.0), &mount, None).is_none());
    }

    #[test]
    fn a_tilted_mount_is_pitch_times_roll_times_the_mount() {
        // The simulator's misaligned mount, written out: camera-to-body = R_y(p) R_x(r) N.
        let (r, p) = (1.5f32.to_radians(), (-1.0f32).to_radians());
        let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, r.cos(), -r.sin(), 0.0, r.sin(), r.cos());
        let ry = Matrix3::new(p.cos(), 0.0, p.sin(), 0.0, 1.0, 0.0, -p.sin(), 0.0, p.cos());
        for yaw_deg in [0.0f32, 30.0, -90.0] {
            let nominal = CameraMount::downward().turned_about_optical_axis(yaw_deg);
            let want = ry * rx * nominal.matrix();
            let got = nominal.tilted(1.5, -1.0).matrix();
            assert!((got - want).amax() < 1e-6, "{got} vs {want}");
        }
        // Roll turns the optical axis (body down) toward body -y: the right wing up sees left.
        let rolled = CameraMount::downward().tilted(10.0, 0.0);
        let axis = rolled.camera_to_body(&Vector3::z());
        assert!(axis.y < -0.17 && axis.x.abs() < 1e-6, "{axis}");
        assert_eq!(
            CameraMount::downward().tilted(f32::NAN, 0.0),
            CameraMount::downward()
        );
    }
}
