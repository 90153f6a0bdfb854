//! What each autopilot makes of a LANDING_TARGET: the pad relative to the vehicle in NED,
//! and the time it takes the measurement to be at (see the facts in [`super`]).

use nalgebra::{Matrix3, Vector3};

/// ArduPilot's precision-landing update rate (Copter calls `AC_PrecLand::init(400)` and runs
/// its update in the 400 Hz loop), Hz.
pub const ARDUPILOT_LOOP_HZ: f64 = 400.0;
/// ArduPilot constrains PLND_LAG to 0.02-0.25 s; 0 here is the ideal autopilot of
/// [`super::ErrorModel::none`] (no history at all).
pub const ARDUPILOT_MAX_LAG_S: f64 = 0.25;

/// The time (µs, same clock as `receipt_us`) of the inertial history entry ArduPilot turns a
/// LANDING_TARGET received at `receipt_us` with: the measurement is consumed at the next
/// 400 Hz update, whose history holds `max(round(lag * 400), 1)` entries, the newest being
/// that update's, and the oldest (`[0]`) is used: `size - 1` ticks before the update. With
/// `lag_s = 0` the receipt time itself.
pub fn ardupilot_attitude_time_us(receipt_us: u64, lag_s: f64) -> u64 {
    if lag_s <= 0.0 {
        return receipt_us;
    }
    let tick_us = 1e6 / ARDUPILOT_LOOP_HZ;
    let lag = lag_s.min(ARDUPILOT_MAX_LAG_S);
    let size = (lag * ARDUPILOT_LOOP_HZ).round().max(1.0);
    let update = (receipt_us as f64 / tick_us).ceil() * tick_us;
    (update - (size - 1.0) * tick_us).max(0.0).round() as u64
}

/// ArduPilot's measurement (`AC_PrecLand::construct_pos_meas_using_rangefinder`): the
/// LANDING_TARGET's body FRD `x, y, z` divided by `distance` (refused when `distance <= 0`,
/// as `AC_PrecLand_MAVLink::handle_msg` does), turned into NED with the delayed attitude
/// `body_to_ned`, scaled back by `distance`, plus PLND_CAM_POS (`cam_pos_body`) turned the
/// same way. Returns the pad relative to the vehicle, NED, metres.
pub fn ardupilot_relative_ned(
    body: &Vector3<f64>,
    distance: f64,
    body_to_ned: &Matrix3<f64>,
    cam_pos_body: &Vector3<f64>,
) -> Option<Vector3<f64>> {
    // NaN fails `is_finite`, so `distance <= 0.0` sees only numbers.
    if !distance.is_finite() || distance <= 0.0 || !body.iter().all(|v| v.is_finite()) {
        return None;
    }
    let unit = body / distance;
    Some(body_to_ned * unit * distance + body_to_ned * cam_pos_body)
}

/// ArduPilot 4.7+'s measurement from a MAV_FRAME_LOCAL_FRD target (`AC_PrecLand`, PR #30446
/// with the yaw sign of PR #31659): `x, y, z` (`level`, the level frame turned with the
/// heading) divided by `distance`, turned into NED about down by the **yaw alone** of the
/// delayed attitude `body_to_ned` (its roll and pitch are not used), scaled back, plus
/// PLND_CAM_POS turned with the whole delayed attitude, as in BODY_FRD. The pad relative to
/// the vehicle, NED, metres.
pub fn ardupilot_local_frd_relative_ned(
    level: &Vector3<f64>,
    distance: f64,
    body_to_ned: &Matrix3<f64>,
    cam_pos_body: &Vector3<f64>,
) -> Option<Vector3<f64>> {
    if !distance.is_finite() || distance <= 0.0 || !level.iter().all(|v| v.is_finite()) {
        return None;
    }
    // The yaw of the attitude's Euler angles: the nose's heading.
    let yaw = body_to_ned[(1, 0)].atan2(body_to_ned[(0, 0)]);
    let heading = Matrix3::new(
        yaw.cos(),
        -yaw.sin(),
        0.0,
        yaw.sin(),
        yaw.cos(),
        0.0,
        0.0,
        0.0,
        1.0,
    );
    let unit = level / distance;
    Some(heading * unit * distance + body_to_ned * cam_pos_body)
}

/// PX4's measurement: LANDING_TARGET in MAV_FRAME_LOCAL_NED is the pad's absolute position
/// in the local frame (`landing_target_pose.x_abs..z_abs`); relative to the vehicle it is that
/// minus the vehicle's own local position estimate at the message's (converted) time.
pub fn px4_relative_ned(
    absolute_ned: &Vector3<f64>,
    own_position_ned: &Vector3<f64>,
) -> Vector3<f64> {
    absolute_ned - own_position_ned
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    #[test]
    fn body_vector_and_attitude_give_the_ned_vector() {
        // Nose east (yaw 90 deg), level: body forward = east, right = south.
        let att = Rotation3::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2).into_inner();
        let body = Vector3::new(2.0, 1.0, 10.0);
        let d = body.norm();
        let ned = ardupilot_relative_ned(&body, d, &att, &Vector3::zeros()).unwrap();
        assert!(
            (ned - Vector3::new(-1.0, 2.0, 10.0)).norm() < 1e-12,
            "{ned}"
        );
        // x, y, z are divided by the distance and multiplied back: the vector stands whatever
        // the distance field says, as long as it is positive.
        let ned2 = ardupilot_relative_ned(&body, 2.0 * d, &att, &Vector3::zeros()).unwrap();
        assert!((ned2 - ned).norm() < 1e-12);
        // PLND_CAM_POS 0.1 m forward adds 0.1 m east.
        let cam = ardupilot_relative_ned(&body, d, &att, &Vector3::new(0.1, 0.0, 0.0)).unwrap();
        assert!((cam - ned - Vector3::new(0.0, 0.1, 0.0)).norm() < 1e-12);
        assert!(ardupilot_relative_ned(&body, 0.0, &att, &Vector3::zeros()).is_none());
    }

    #[test]
    fn a_local_frd_vector_is_turned_by_the_yaw_alone() {
        // Rolled 20 deg, nose east: the level vector 2 m forward (east), 1 m right (south).
        let att = Rotation3::from_euler_angles(0.35, 0.0, std::f64::consts::FRAC_PI_2).into_inner();
        let level = Vector3::new(2.0, 1.0, 10.0);
        let d = level.norm();
        let ned = ardupilot_local_frd_relative_ned(&level, d, &att, &Vector3::zeros()).unwrap();
        assert!(
            (ned - Vector3::new(-1.0, 2.0, 10.0)).norm() < 1e-12,
            "{ned}"
        );
        // The roll does not enter; the BODY_FRD reconstruction of the same numbers tilts.
        let body = ardupilot_relative_ned(&level, d, &att, &Vector3::zeros()).unwrap();
        assert!((body - ned).norm() > 1.0);
        assert!(ardupilot_local_frd_relative_ned(&level, 0.0, &att, &Vector3::zeros()).is_none());
    }

    #[test]
    fn plnd_lag_picks_the_history_entry() {
        // 0.02 s at 400 Hz: 8 entries, the oldest 7 ticks (17.5 ms) before the update that
        // follows the receipt.
        assert_eq!(
            ardupilot_attitude_time_us(1_000_000, 0.02),
            1_000_000 - 17_500
        );
        assert_eq!(
            ardupilot_attitude_time_us(1_000_001, 0.02),
            1_002_500 - 17_500
        );
        // 0.1 s: 40 entries, 39 ticks.
        assert_eq!(
            ardupilot_attitude_time_us(2_000_000, 0.1),
            2_000_000 - 97_500
        );
        // Above ArduPilot's 0.25 s bound it is held there; 0 is the ideal autopilot.
        assert_eq!(
            ardupilot_attitude_time_us(2_000_000, 0.4),
            ardupilot_attitude_time_us(2_000_000, 0.25)
        );
        assert_eq!(ardupilot_attitude_time_us(2_000_123, 0.0), 2_000_123);
    }

    #[test]
    fn px4_subtracts_its_own_position() {
        let abs = Vector3::new(4.0, 1.0, 0.0);
        let own = Vector3::new(3.0, 3.0, -10.0);
        assert_eq!(px4_relative_ned(&abs, &own), Vector3::new(1.0, -2.0, 10.0));
    }
}
