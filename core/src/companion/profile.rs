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
//!   other frame. It adds PLND_CAM_POS (turned with its own delayed attitude) itself, so
//!   TD_CAM_POS is not applied here.
//! - **ArduPilot 4.7+, LOCAL_FRD** (TD_PROFILE 3; `AC_PrecLand` since PR #30446): `x, y, z`
//!   in `MAV_FRAME_LOCAL_FRD`, a level frame turned with the heading (forward, right, down;
//!   no roll, no pitch). ArduPilot turns it into NED with the yaw alone of its PLND_LAG-delayed
//!   attitude, where BODY_FRD is turned with the whole delayed attitude: so the roll and pitch
//!   are ours, at the exposure, and a PLND_LAG that does not match the real delay no longer
//!   tilts the target (the yaw's share remains, small while the heading holds). Its first
//!   version turned by minus the yaw (ArduPilot issue #31651, fixed by PR #31659), which
//!   diverges whenever the nose is not north: use it only on builds with the fix. Never
//!   chosen by auto: HEARTBEAT does not tell the version. Needs the attitude at the exposure;
//!   a frame without one is sent in BODY_FRD, which the same autopilot also takes.
//!   PLND_CAM_POS as above.
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
//!   ([`Profile::from_autopilot`]). It adds no camera offset on this path (`x_abs` is taken
//!   as is, and precision land flies to it), so the pad is the vehicle's position plus the
//!   attitude times (TD_CAM_POS + the camera-to-pad vector): [`px4_fields`].
//!
//! All get:
//!
//! - `angle_x`, `angle_y` from the **body FRD** vector of the pad (the one `x, y, z` carry in
//!   the ArduPilot profile, [`body_angles`]; in LOCAL_FRD from the level vector, as ArduPilot
//!   reads the angles in the message's frame): ArduPilot rebuilds the line of sight from them as
//!   `(-tan(angle_y), tan(angle_x), 1)` normalised in body FRD when `position_valid` is 0, so
//!   `angle_x = atan2(y, z)`, `angle_y = atan2(-x, z)` make that vector equal `x, y, z /
//!   distance` whatever the camera mount (TD_CAM_YAW included);
//! - `distance`, the norm of that vector;
//! - `q`, the pad's orientation in the frame of `x, y, z`
//!   ([`crate::filter::axes::pad_orientation`]): the rotation
//!   from the pad frame (x right, y up, z up out of the pad, docs/interfaces.md) to body FRD
//!   (ArduPilot), to LOCAL_FRD, or to NED (PX4), `[w, x, y, z]`, from the frame's pad fix and the attitude at
//!   its exposure, for heading-aligned landings;
//! - `type = LANDING_TARGET_TYPE_VISION_FIDUCIAL`.

use crate::filter::{distance, local_ned_position, Attitude};
use mavlink::dialects::common::MavAutopilot;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

/// The flight stack LANDING_TARGET is formatted for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Profile {
    /// `MAV_FRAME_BODY_FRD`, pad relative to the vehicle (no vehicle state needed).
    ArduPilot,
    /// `MAV_FRAME_LOCAL_NED`, absolute pad position (needs LOCAL_POSITION_NED and attitude).
    Px4,
    /// `MAV_FRAME_LOCAL_FRD`, pad relative to the vehicle in the heading-turned level frame
    /// (ArduPilot 4.7+; needs the attitude, else BODY_FRD).
    ArduPilotLocalFrd,
}

impl Profile {
    /// The TD_PROFILE value that forces this profile.
    pub fn to_param(self) -> f32 {
        match self {
            Profile::ArduPilot => 0.0,
            Profile::Px4 => 1.0,
            Profile::ArduPilotLocalFrd => 3.0,
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
            Profile::ArduPilotLocalFrd => "ArduPilot 4.7+ (LOCAL_FRD)",
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
    /// 3: always ArduPilot 4.7+ in LOCAL_FRD.
    ArduPilotLocalFrd,
}

impl ProfileSetting {
    /// From TD_PROFILE (0 ArduPilot, 1 PX4, 2 auto, 3 ArduPilot LOCAL_FRD; the table refuses
    /// anything else, and anything else reads as auto, the safe choice).
    pub fn from_param(v: i32) -> ProfileSetting {
        match v {
            0 => ProfileSetting::ArduPilot,
            1 => ProfileSetting::Px4,
            3 => ProfileSetting::ArduPilotLocalFrd,
            _ => ProfileSetting::Auto,
        }
    }

    /// The TD_PROFILE value.
    pub fn to_param(self) -> f32 {
        match self {
            ProfileSetting::ArduPilot => 0.0,
            ProfileSetting::Px4 => 1.0,
            ProfileSetting::Auto => 2.0,
            ProfileSetting::ArduPilotLocalFrd => 3.0,
        }
    }

    /// The profile in force given what the autopilot's HEARTBEAT said (`detected`).
    pub fn resolve(self, detected: Option<Profile>) -> Option<Profile> {
        match self {
            ProfileSetting::ArduPilot => Some(Profile::ArduPilot),
            ProfileSetting::Px4 => Some(Profile::Px4),
            ProfileSetting::ArduPilotLocalFrd => Some(Profile::ArduPilotLocalFrd),
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
    /// MAV_FRAME_LOCAL_FRD (20).
    LocalFrd,
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

/// ArduPilot 4.7+, LOCAL_FRD: the pad relative to the vehicle (`rel_ned`, NED axes) in the
/// level frame turned with the heading of `attitude` (the one at the exposure), the angles
/// from that vector, `q` the pad's orientation (pad to NED, `q_ned`) turned into the same
/// frame. `None` as [`ardupilot_fields`].
pub fn local_frd_fields(
    rel_ned: &Vector3<f32>,
    attitude: &Attitude,
    q_ned: [f32; 4],
) -> Option<TargetFields> {
    let level = attitude.ned_to_local_frd(rel_ned);
    let (angle_x, angle_y) = body_angles(&level)?;
    let d = distance(&level);
    if !(d > 0.0) || !d.is_finite() {
        return None;
    }
    Some(TargetFields {
        frame: TargetFrame::LocalFrd,
        position: level,
        angle_x,
        angle_y,
        distance: d,
        q: ned_to_local_frd_q(q_ned, attitude),
    })
}

/// An orientation `[w, x, y, z]` into NED, re-expressed into LOCAL_FRD (turned back by the
/// heading); an unusable one (the NaN "unknown", zero) stays as it is.
fn ned_to_local_frd_q(q_ned: [f32; 4], attitude: &Attitude) -> [f32; 4] {
    let [w, x, y, z] = q_ned;
    let q = Quaternion::new(w, x, y, z);
    let n = q.norm();
    if !(n > 0.0) || !n.is_finite() {
        return q_ned;
    }
    let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), -attitude.yaw());
    let r = turn * UnitQuaternion::from_quaternion(q);
    [r.w, r.i, r.j, r.k]
}

/// PX4: the pad's absolute LOCAL_NED position, the vehicle's position plus the camera's
/// position (`cam_pos_body`, TD_CAM_POS, body FRD) and the camera-to-pad vector (`rel_ned`,
/// NED axes), both turned with the attitude at the exposure; the angles from that relative
/// position in body FRD at the exposure (as ArduPilot's would be), `q` the pad's orientation
/// (pad to NED). `distance` stays the camera's.
pub fn px4_fields(
    vehicle_ned: &Vector3<f32>,
    rel_ned: &Vector3<f32>,
    attitude: &Attitude,
    cam_pos_body: &Vector3<f32>,
    q: [f32; 4],
) -> Option<TargetFields> {
    let (angle_x, angle_y) = body_angles(&attitude.ned_to_body(rel_ned))?;
    let d = distance(rel_ned);
    let from_origin = attitude.body_to_ned(cam_pos_body) + rel_ned;
    let abs = local_ned_position(vehicle_ned, &from_origin);
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
            ProfileSetting::ArduPilotLocalFrd,
        ] {
            assert_eq!(ProfileSetting::from_param(s.to_param() as i32), s);
        }
        assert_eq!(ProfileSetting::Auto.resolve(None), None);
        assert_eq!(
            ProfileSetting::Px4.resolve(Some(Profile::ArduPilot)),
            Some(Profile::Px4)
        );
        // LOCAL_FRD only when asked for: auto keeps ArduPilot in BODY_FRD.
        assert_eq!(
            ProfileSetting::ArduPilotLocalFrd.resolve(Some(Profile::ArduPilot)),
            Some(Profile::ArduPilotLocalFrd)
        );
        assert_eq!(
            ProfileSetting::Auto.resolve(Profile::from_autopilot(
                MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA
            )),
            Some(Profile::ArduPilot)
        );
        assert_eq!(Profile::ArduPilotLocalFrd.to_param(), 3.0);
    }

    /// ArduPilot 4.7's reconstruction of a LOCAL_FRD vector (AC_PrecLand with the sign fix of
    /// PR #31659): turned about down by its yaw alone.
    fn ardupilot_local_frd_to_ned(v: &Vector3<f32>, yaw: f32) -> Vector3<f32> {
        let (s, c) = libm::sincosf(yaw);
        Vector3::new(c * v.x - s * v.y, s * v.x + c * v.y, v.z)
    }

    #[test]
    fn local_frd_is_level_and_heading_turned() {
        // Rolled 10 deg, pitched -5 deg, nose at 60 deg; the pad 2 m north, 1 m east, 8 m down.
        let att = Attitude::from_euler(0.17, -0.09, 1.05).unwrap();
        let rel_ned = Vector3::new(2.0, 1.0, 8.0);
        let f = local_frd_fields(&rel_ned, &att, [1.0, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!(f.frame, TargetFrame::LocalFrd);
        // Down is down (no tilt), and the yaw alone brings it back to NED.
        assert!((f.position.z - 8.0).abs() < 1e-5, "{}", f.position);
        let back = ardupilot_local_frd_to_ned(&f.position, att.yaw());
        assert!((back - rel_ned).amax() < 1e-5, "{back}");
        assert!((f.distance - distance(&rel_ned)).abs() < 1e-5);
        // The angles rebuild the LOCAL_FRD vector, not the body one.
        let los = Vector3::new(-libm::tanf(f.angle_y), libm::tanf(f.angle_x), 1.0).normalize();
        assert!((los - f.position / f.distance).amax() < 1e-5);
        // q: a pad aligned with NED appears turned back by the heading.
        let q = UnitQuaternion::from_quaternion(Quaternion::new(f.q[0], f.q[1], f.q[2], f.q[3]));
        let (_, _, yaw) = q.euler_angles();
        assert!((yaw + att.yaw()).abs() < 1e-4, "{yaw}");
        // The NaN "unknown" orientation passes through.
        let unknown = local_frd_fields(&rel_ned, &att, [f32::NAN, 0.0, 0.0, 0.0]).unwrap();
        assert!(unknown.q[0].is_nan());
    }

    #[test]
    fn px4_adds_the_camera_position_turned_with_the_attitude() {
        let att = Attitude::from_euler(0.0, 0.0, core::f32::consts::FRAC_PI_2).unwrap();
        let vehicle = Vector3::new(10.0, 20.0, -5.0);
        let rel = Vector3::new(0.0, 0.0, 5.0);
        let q = [1.0, 0.0, 0.0, 0.0];
        let at_origin = px4_fields(&vehicle, &rel, &att, &Vector3::zeros(), q).unwrap();
        assert!((at_origin.position - Vector3::new(10.0, 20.0, 0.0)).amax() < 1e-5);
        // 0.2 m forward, nose east: the pad is 0.2 m further east; distance and angles are the
        // camera's and do not change.
        let cam = Vector3::new(0.2, 0.0, 0.0);
        let f = px4_fields(&vehicle, &rel, &att, &cam, q).unwrap();
        assert!(
            (f.position - at_origin.position - Vector3::new(0.0, 0.2, 0.0)).amax() < 1e-5,
            "{}",
            f.position
        );
        assert_eq!(
            (f.distance, f.angle_x, f.angle_y),
            (at_origin.distance, at_origin.angle_x, at_origin.angle_y)
        );
    }
}
