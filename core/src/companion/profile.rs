//! What goes into LANDING_TARGET for each flight stack.
//!
//! - **ArduPilot** (`AC_PrecLand`, companion backend): with `position_valid = 1` it reads
//!   `x, y, z` in `MAV_FRAME_BODY_FRD` and divides them by `distance` (which must be > 0) to get
//!   the line of sight; without it, it falls back to `angle_x`/`angle_y`. It time-stamps the
//!   message on receipt and drops the target after 1 s without messages; so the pad relative
//!   to the vehicle, body axes, every frame, and nothing once the pad is gone. Its own vehicle
//!   state does the rest, so no vehicle state is needed here.
//! - **PX4** (`mavlink_receiver` to `landing_target_pose`): only `MAV_FRAME_LOCAL_NED` with
//!   `position_valid = 1`, read as the pad's **absolute** position in the local frame: the
//!   vehicle's LOCAL_POSITION_NED at the exposure plus the pad offset in NED axes. It converts
//!   `time_usec` with its own TIMESYNC estimate of *our* clock (`sync_stamp`), which is why
//!   [`super::TimeBase::ByProfile`] sends our boot time to PX4 (and we answer PX4's TIMESYNC
//!   requests so its estimate converges).
//!
//! Both get `angle_x`, `angle_y` and `distance` from the camera-frame vector (see
//! [`crate::frames::landing_angles`]), `q` identity (the pad's orientation is not reported),
//! `type = LANDING_TARGET_TYPE_VISION_FIDUCIAL`.

use crate::frames::{distance, landing_angles, Attitude, CameraMount};
use nalgebra::Vector3;

/// The flight stack LANDING_TARGET is formatted for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Profile {
    /// `MAV_FRAME_BODY_FRD`, pad relative to the vehicle (no vehicle state needed).
    ArduPilot,
    /// `MAV_FRAME_LOCAL_NED`, absolute pad position (needs LOCAL_POSITION_NED and attitude).
    Px4,
}

impl Profile {
    /// From TD_PROFILE (0 ArduPilot, 1 PX4).
    pub fn from_param(v: i32) -> Profile {
        if v == 1 {
            Profile::Px4
        } else {
            Profile::ArduPilot
        }
    }

    /// The TD_PROFILE value.
    pub fn to_param(self) -> f32 {
        match self {
            Profile::ArduPilot => 0.0,
            Profile::Px4 => 1.0,
        }
    }
}

/// The frame of [`TargetFields::position`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TargetFrame {
    /// MAV_FRAME_BODY_FRD (12).
    BodyFrd,
    /// MAV_FRAME_LOCAL_NED (1).
    LocalNed,
}

/// The geometric fields of one LANDING_TARGET.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetFields {
    /// Frame of `position`.
    pub frame: TargetFrame,
    /// `x, y, z`, metres.
    pub position: Vector3<f32>,
    /// `angle_x`, radians.
    pub angle_x: f32,
    /// `angle_y`, radians.
    pub angle_y: f32,
    /// `distance` from the camera, metres (> 0).
    pub distance: f32,
}

fn finite(v: &Vector3<f32>) -> bool {
    v.iter().all(|c| c.is_finite())
}

/// ArduPilot: the pad relative to the vehicle in body FRD. `None` when not finite, at zero
/// distance, or not in front of the camera (no valid angles).
pub fn ardupilot_fields(rel_body: &Vector3<f32>, mount: &CameraMount) -> Option<TargetFields> {
    let cam = mount.body_to_camera(rel_body);
    let angles = landing_angles(&cam)?;
    let d = distance(rel_body);
    if !finite(rel_body) || !(d > 0.0) || !d.is_finite() {
        return None;
    }
    Some(TargetFields {
        frame: TargetFrame::BodyFrd,
        position: *rel_body,
        angle_x: angles.angle_x,
        angle_y: angles.angle_y,
        distance: d,
    })
}

/// PX4: the pad's absolute LOCAL_NED position, the vehicle's position plus the relative
/// position in NED axes; angles from the attitude and mount at the exposure.
pub fn px4_fields(
    vehicle_ned: &Vector3<f32>,
    rel_ned: &Vector3<f32>,
    attitude: &Attitude,
    mount: &CameraMount,
) -> Option<TargetFields> {
    let cam = crate::frames::ned_to_camera(rel_ned, attitude, mount);
    let angles = landing_angles(&cam)?;
    let d = distance(rel_ned);
    let abs = crate::frames::local_ned_position(vehicle_ned, rel_ned);
    if !finite(&abs) || !(d > 0.0) || !d.is_finite() {
        return None;
    }
    Some(TargetFields {
        frame: TargetFrame::LocalNed,
        position: abs,
        angle_x: angles.angle_x,
        angle_y: angles.angle_y,
        distance: d,
    })
}
