//! What goes into LANDING_TARGET for each flight stack.
//!
//! - **ArduPilot** (`AC_PrecLand`, companion backend): with `position_valid = 1` it reads
//!   `x, y, z` in `MAV_FRAME_BODY_FRD` and divides them by `distance` (which must be > 0) to get
//!   the line of sight; without it, it falls back to `angle_x`/`angle_y`. It keeps
//!   `time_usec` (jitter-corrected) as the measurement's time, to tell new measurements from
//!   repeats and expire them after 1 s; the lag between exposure and use is its PLND_LAG. Its
//!   estimator keeps a target for up to 2 s without measurements. So: the pad relative to the
//!   vehicle, body axes, every frame, and nothing once the pad is gone. Its own vehicle state
//!   does the rest, so no vehicle state is needed here. Up to 4.6 it reads `x, y, z` in no
//!   other frame (4.7 also takes `MAV_FRAME_LOCAL_FRD`).
//! - **PX4** (`mavlink_receiver` to `landing_target_pose`): only `MAV_FRAME_LOCAL_NED` with
//!   `position_valid = 1`, read as the pad's **absolute** position in the local frame: the
//!   vehicle's LOCAL_POSITION_NED at the exposure plus the pad offset in NED axes. It converts
//!   `time_usec` with its own TIMESYNC estimate of *our* clock once it has converged
//!   (`sync_stamp`; before that, and on links where it runs no TIMESYNC, it uses the arrival
//!   time), which is why
//!   [`super::TimeBase::ByProfile`] sends our boot time to PX4 (and we answer PX4's TIMESYNC
//!   requests so its estimate converges). It refuses any other frame ("coordinate frame 12
//!   unsupported"), which is why the profile must match the autopilot: TD_PROFILE's default,
//!   [`ProfileSetting::Auto`], picks it from the autopilot's HEARTBEAT
//!   ([`Profile::from_autopilot`]).
//!
//! Both get:
//!
//! - `angle_x`, `angle_y` from the **body FRD** vector of the pad (the one `x, y, z` carry in
//!   the ArduPilot profile, [`body_angles`]): ArduPilot rebuilds the line of sight from them as
//!   `(-tan(angle_y), tan(angle_x), 1)` normalised in body FRD when `position_valid` is 0, so
//!   `angle_x = atan2(y, z)`, `angle_y = atan2(-x, z)` make that vector equal `x, y, z /
//!   distance` whatever the camera mount (TD_CAM_YAW included);
//! - `distance`, the norm of that vector;
//! - `q`, the pad's orientation in the frame of `x, y, z`
//!   ([`crate::filter::axes::pad_orientation`]): the rotation
//!   from the pad frame (x right, y up, z up out of the pad, docs/interfaces.md) to body FRD
//!   (ArduPilot) or to NED (PX4), `[w, x, y, z]`, from the frame's pad fix and the attitude at
//!   its exposure, for heading-aligned landings;
//! - `type = LANDING_TARGET_TYPE_VISION_FIDUCIAL`.

use crate::filter::{distance, local_ned_position, Attitude};
use mavlink::dialects::common::MavAutopilot;
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
    /// The TD_PROFILE value that forces this profile.
    pub fn to_param(self) -> f32 {
        match self {
            Profile::ArduPilot => 0.0,
            Profile::Px4 => 1.0,
        }
    }

    /// The profile for an autopilot's HEARTBEAT `autopilot` field: ArduPilot for
    /// MAV_AUTOPILOT_ARDUPILOTMEGA (3), PX4 for MAV_AUTOPILOT_PX4 (12), `None` for anything
    /// else (generic, invalid, other stacks: we do not know which frame they accept).
    pub fn from_autopilot(autopilot: MavAutopilot) -> Option<Profile> {
        match autopilot {
            MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA => Some(Profile::ArduPilot),
            MavAutopilot::MAV_AUTOPILOT_PX4 => Some(Profile::Px4),
            _ => None,
        }
    }

    /// A short name for logs and STATUSTEXT.
    pub fn name(self) -> &'static str {
        match self {
            Profile::ArduPilot => "ArduPilot (BODY_FRD)",
            Profile::Px4 => "PX4 (LOCAL_NED)",
        }
    }
}

/// TD_PROFILE: a forced profile, or the autopilot's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ProfileSetting {
    /// 0: always ArduPilot.
    ArduPilot,
    /// 1: always PX4.
    Px4,
    /// 2 (the default): from the latched autopilot's HEARTBEAT; no target until it is known.
    Auto,
}

impl ProfileSetting {
    /// From TD_PROFILE (0 ArduPilot, 1 PX4, 2 auto; the table refuses anything else, and
    /// anything else reads as auto, the safe choice).
    pub fn from_param(v: i32) -> ProfileSetting {
        match v {
            0 => ProfileSetting::ArduPilot,
            1 => ProfileSetting::Px4,
            _ => ProfileSetting::Auto,
        }
    }

    /// The TD_PROFILE value.
    pub fn to_param(self) -> f32 {
        match self {
            ProfileSetting::ArduPilot => 0.0,
            ProfileSetting::Px4 => 1.0,
            ProfileSetting::Auto => 2.0,
        }
    }

    /// The profile in force given what the autopilot's HEARTBEAT said (`detected`).
    pub fn resolve(self, detected: Option<Profile>) -> Option<Profile> {
        match self {
            ProfileSetting::ArduPilot => Some(Profile::ArduPilot),
            ProfileSetting::Px4 => Some(Profile::Px4),
            ProfileSetting::Auto => detected,
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
    /// `q`: the pad's orientation in the frame of `position`, `[w, x, y, z]`
    /// (the orientations of [`crate::filter::PadEstimate`]).
    pub q: [f32; 4],
}

fn finite(v: &Vector3<f32>) -> bool {
    v.iter().all(|c| c.is_finite())
}

/// `angle_x`, `angle_y` of a body FRD vector: `atan2(y, z)`, `atan2(-x, z)`, so ArduPilot's
/// `(-tan(angle_y), tan(angle_x), 1)` points along it. `None` when not finite or not below
/// the vehicle (`z <= 0`: no such angles; only possible with a tilted mount).
pub fn body_angles(body: &Vector3<f32>) -> Option<(f32, f32)> {
    if !finite(body) || !(body.z > 0.0) {
        return None;
    }
    Some((libm::atan2f(body.y, body.z), libm::atan2f(-body.x, body.z)))
}

/// ArduPilot: the pad relative to the vehicle in body FRD, the pad's orientation `q` (pad to
/// body). `None` when not finite, at zero distance, or not below the vehicle (no angles).
pub fn ardupilot_fields(rel_body: &Vector3<f32>, q: [f32; 4]) -> Option<TargetFields> {
    let (angle_x, angle_y) = body_angles(rel_body)?;
    let d = distance(rel_body);
    if !(d > 0.0) || !d.is_finite() {
        return None;
    }
    Some(TargetFields {
        frame: TargetFrame::BodyFrd,
        position: *rel_body,
        angle_x,
        angle_y,
        distance: d,
        q,
    })
}

/// PX4: the pad's absolute LOCAL_NED position, the vehicle's position plus the relative
/// position in NED axes; the angles from that relative position in body FRD at the exposure
/// (as ArduPilot's would be), `q` the pad's orientation (pad to NED).
pub fn px4_fields(
    vehicle_ned: &Vector3<f32>,
    rel_ned: &Vector3<f32>,
    attitude: &Attitude,
    q: [f32; 4],
) -> Option<TargetFields> {
    let (angle_x, angle_y) = body_angles(&attitude.ned_to_body(rel_ned))?;
    let d = distance(rel_ned);
    let abs = local_ned_position(vehicle_ned, rel_ned);
    if !finite(&abs) || !(d > 0.0) || !d.is_finite() {
        return None;
    }
    Some(TargetFields {
        frame: TargetFrame::LocalNed,
        position: abs,
        angle_x,
        angle_y,
        distance: d,
        q,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ArduPilot's reconstruction (AC_PrecLand_MAVLink, position_valid = 0).
    fn ardupilot_line_of_sight(angle_x: f32, angle_y: f32) -> Vector3<f32> {
        Vector3::new(-libm::tanf(angle_y), libm::tanf(angle_x), 1.0).normalize()
    }

    #[test]
    fn angles_rebuild_the_body_vector_whatever_the_mount() {
        for v in [
            Vector3::new(1.0, -2.0, 10.0),
            Vector3::new(-3.0, 0.5, 4.0),
            Vector3::new(0.0, 0.0, 2.0),
        ] {
            let f = ardupilot_fields(&v, [1.0, 0.0, 0.0, 0.0]).unwrap();
            let los = ardupilot_line_of_sight(f.angle_x, f.angle_y);
            assert!((los - v / f.distance).amax() < 1e-5, "{los} {v}");
        }
        assert!(body_angles(&Vector3::new(1.0, 0.0, 0.0)).is_none());
        assert!(body_angles(&Vector3::new(f32::NAN, 0.0, 1.0)).is_none());
    }

    #[test]
    fn profile_from_heartbeat_and_setting() {
        assert_eq!(
            Profile::from_autopilot(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA),
            Some(Profile::ArduPilot)
        );
        assert_eq!(
            Profile::from_autopilot(MavAutopilot::MAV_AUTOPILOT_PX4),
            Some(Profile::Px4)
        );
        assert_eq!(
            Profile::from_autopilot(MavAutopilot::MAV_AUTOPILOT_GENERIC),
            None
        );
        for s in [
            ProfileSetting::ArduPilot,
            ProfileSetting::Px4,
            ProfileSetting::Auto,
        ] {
            assert_eq!(ProfileSetting::from_param(s.to_param() as i32), s);
        }
        assert_eq!(ProfileSetting::Auto.resolve(None), None);
        assert_eq!(
            ProfileSetting::Px4.resolve(Some(Profile::ArduPilot)),
            Some(Profile::Px4)
        );
    }
}
