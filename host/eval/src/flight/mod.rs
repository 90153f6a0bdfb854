//! The replay in flight: the board's pipeline and
//! [`Companion`](touchdown_core::companion::Companion) against a simulated autopilot that
//! speaks MAVLink bytes, under an error model, and the target scored as the autopilot
//! reconstructs it.
//!
//! What this module offers: the error sources ([`ErrorModel`], drawn as a [`Realisation`]),
//! the simulated autopilot and link ([`SimAutopilot`], [`Link`]), the autopilots'
//! reconstructions ([`reconstruct`]), the truth the autopilot is simulated from
//! ([`TruthSource`], with [`TruthTable`] for a recording), one method's flight
//! ([`FlightRun`], used by [`crate::Experiment::in_flight`]) and the three errors it gives per
//! frame ([`FlightOutcome`]), collected and summarised in a [`FlightTrace`].
//!
//! # The three errors
//!
//! All are the camera centre in the pad frame (the replay's convention), against the truth:
//!
//! - **(a) sent**: what touchdown sends, the LANDING_TARGET's body FRD vector (decoded from
//!   the bytes for ArduPilot; the estimate's body vector for PX4, whose message carries the
//!   LOCAL_NED point instead), turned with the *true* body attitude at the exposure, against
//!   the truth at the exposure: the vision's own error.
//! - **(b) reconstructed**: what the autopilot makes of that message with its own attitude and
//!   position estimates, against the truth at the time it assigns the measurement to.
//! - **(c) ideal**: the same reconstruction of an ideal sensor's message (the exact body
//!   vector of that exposure, sent at the same time by the same path): the part of (b) that
//!   comes from the autopilot, not from the vision.
//!
//! # Facts the reconstructions rely on (read in the autopilots' code; our words)
//!
//! ArduPilot (libraries/AC_PrecLand):
//! - `AC_PrecLand_MAVLink::handle_msg` (formerly `AC_PrecLand_Companion`): with
//!   `position_valid = 1` only MAV_FRAME_BODY_FRD (4.7 also LOCAL_FRD) is taken; `x, y, z`
//!   divided by `distance` is the line of sight, and a message with `distance <= 0` is
//!   dropped; `distance` is kept as the range. The measurement's time is only used to tell a
//!   new measurement from a repeat and to expire it after 1 s.
//! - `AC_PrecLand::init`: PLND_LAG is constrained to 0.02-0.25 s; the inertial history holds
//!   `max(round(lag * rate), 1)` entries at the precision-landing update rate (Copter: 400 Hz).
//! - `AC_PrecLand::update` pushes the newest attitude (`Tbn`, body to NED) each update;
//!   `run_estimator` / `construct_pos_meas_using_rangefinder` take the *oldest* entry
//!   (`(*_inertial_history)[0]`) and compute `Tbn * unit * distance + Tbn * PLND_CAM_POS`
//!   (minus the IMU offset, 0 here): the target relative to the vehicle in NED at that
//!   entry's time. So the attitude used is the one `size - 1` ticks before the first update
//!   after receipt: 17.5 ms for the default 0.02 s.
//! - Its filter (PLND_EST_TYPE) then runs on that measurement; (b) is the measurement itself
//!   (`_target_pos_rel_meas_NED`, logged as PL.mX/mY/mZ), before that filter.
//!
//! PX4 (src/modules/mavlink/mavlink_receiver.cpp, `handle_message_landing_target`; msg
//! LandingTargetPose):
//! - only `position_valid` with MAV_FRAME_LOCAL_NED is taken (other frames: "coordinate frame
//!   unsupported"); `x, y, z` become `landing_target_pose.x_abs, y_abs, z_abs` (relative to
//!   the local origin), `abs_pos_valid = true`, and its time stamp is `time_usec` converted by
//!   its TIMESYNC estimate of our clock (`sync_stamp`; the arrival time before it has one).
//! - precision landing flies to that absolute point with the vehicle's own local position
//!   estimate, so the target relative to the vehicle is `x_abs - own position`, both in the
//!   local frame: a slow drift of the local position moves both and cancels, except for what
//!   it does between the exposure and the stamp.
//!
//! # Frames and clocks
//!
//! NED is the simulator's: north = pad +y, east = pad +x, down = pad -z ([`NED_FROM_PAD`]).
//! The camera is at the body origin (PLND_CAM_POS = 0). Our clock (the board's) is the frames'
//! clock plus a constant ([`BoardClock`]) so that the link and the autopilot can run
//! [`WARMUP_US`] before the first frame: the companion has heard the HEARTBEAT, asked for the
//! streams and synchronised its clock when the first frame is exposed.

mod autopilot;
mod error_model;
pub mod reconstruct;
mod run;
mod trace;

pub use autopilot::{
    belief, AutopilotBelief, AutopilotKind, BoardClock, Link, ReceivedTarget, SimAutopilot,
};
pub use error_model::{ErrorModel, Realisation, EKF_RATE_HZ};
pub use run::{board_companion, FlightRun, FlightSetup, PAD_NED, SETTLE_US, STEP_US};
pub use trace::{ErrorKind, ErrorStats, FlightTrace};

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// Pad axes (x east, y north, z up) to NED, and back (it is its own inverse).
pub const NED_FROM_PAD: Matrix3<f64> = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0);
/// The autopilot and the link run this long before the first frame, µs.
pub const WARMUP_US: u64 = 3_000_000;

/// The truth at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrueState {
    /// Camera centre (= the body origin) in the pad frame, metres.
    pub position: Vector3<f64>,
    /// The vehicle's attitude, body FRD to NED (without the camera's vibration).
    pub body_to_ned: Matrix3<f64>,
}

/// Where the truth between frames comes from: the simulator for a scenario, the frames'
/// truths interpolated for a recording ([`TruthTable`]).
pub trait TruthSource {
    /// The truth at `t_s` (the frames' clock, seconds; before the first frame the first
    /// frame's truth is fine), `None` when unknown.
    fn at(&self, t_s: f64) -> Option<TrueState>;

    /// Where the pad's origin is at `t_s`, in the frame of [`TrueState::position`] (the pad
    /// frame as the pad lay when it started to move): zero for a pad at rest, the default.
    /// What the autopilot reconstructs is scored against the camera's position from it.
    fn pad_origin(&self, _t_s: f64) -> Vector3<f64> {
        Vector3::zeros()
    }
}

/// A truth known at sample times, interpolated between them (linear position, spherical
/// attitude) and held beyond the ends.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TruthTable {
    samples: Vec<(f64, Vector3<f64>, UnitQuaternion<f64>)>,
}

impl TruthTable {
    /// An empty table.
    pub fn new() -> Self {
        TruthTable::default()
    }

    /// Adds the truth at `t_s` (samples must come in time order; an earlier one is ignored).
    pub fn push(&mut self, t_s: f64, state: TrueState) {
        if self.samples.last().is_some_and(|s| s.0 > t_s) {
            return;
        }
        let q = UnitQuaternion::from_matrix(&state.body_to_ned);
        self.samples.push((t_s, state.position, q));
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether it has no sample.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }
}

impl TruthSource for TruthTable {
    fn at(&self, t_s: f64) -> Option<TrueState> {
        let first = self.samples.first()?;
        let k = self.samples.partition_point(|s| s.0 <= t_s);
        let (p, q) = if k == 0 {
            (first.1, first.2)
        } else {
            let a = &self.samples[k - 1];
            match self.samples.get(k) {
                Some(b) if b.0 > a.0 => {
                    let w = (t_s - a.0) / (b.0 - a.0);
                    (
                        a.1 * (1.0 - w) + b.1 * w,
                        a.2.try_slerp(&b.2, w, 1e-9).unwrap_or(a.2),
                    )
                }
                _ => (a.1, a.2),
            }
        };
        Some(TrueState {
            position: p,
            body_to_ned: q.to_rotation_matrix().into_inner(),
        })
    }
}

/// One of the three errors of a frame: an estimate of the camera centre in the pad frame and
/// the truth it is scored against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scored {
    /// The time the estimate is taken to be at (frames' clock, µs).
    pub t_us: u64,
    /// The true camera centre then, pad frame, metres.
    pub truth: Vector3<f64>,
    /// The estimate, pad frame, metres.
    pub value: Vector3<f64>,
}

impl Scored {
    /// truth - estimate, metres.
    pub fn error(&self) -> Vector3<f64> {
        self.truth - self.value
    }
}

/// The three errors of one method at one frame (see the module docs); `None` where the
/// method sent nothing or the autopilot took nothing.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FlightOutcome {
    /// (a) what touchdown sends, in the true body axes at the exposure.
    pub sent: Option<Scored>,
    /// (b) what the autopilot reconstructs from it.
    pub reconstructed: Option<Scored>,
    /// (c) what it would reconstruct from an ideal sensor.
    pub ideal: Option<Scored>,
    /// The exposure-to-receipt time of the target, µs.
    pub latency_us: Option<u64>,
    /// The board takes the pad as moving after this frame (TD_PAD_MOTION; the paper's method
    /// has no such notion: false).
    pub pad_moving: bool,
}

impl FlightOutcome {
    /// One of the three.
    pub fn get(&self, kind: ErrorKind) -> Option<&Scored> {
        match kind {
            ErrorKind::Sent => self.sent.as_ref(),
            ErrorKind::Reconstructed => self.reconstructed.as_ref(),
            ErrorKind::Ideal => self.ideal.as_ref(),
        }
    }
}

/// The camera centre in the pad frame of the pad seen `relative_ned` from the vehicle.
pub fn camera_in_pad(relative_ned: &Vector3<f64>) -> Vector3<f64> {
    -(NED_FROM_PAD * relative_ned)
}

/// The pad relative to a camera at `camera_in_pad`, in NED.
pub fn relative_ned(camera_in_pad: &Vector3<f64>) -> Vector3<f64> {
    NED_FROM_PAD * (-camera_in_pad)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    #[test]
    fn truth_table_interpolates_and_holds() {
        let mut t = TruthTable::new();
        let yaw = |a: f64| Rotation3::from_euler_angles(0.0, 0.0, a).into_inner();
        t.push(
            1.0,
            TrueState {
                position: Vector3::new(0.0, 0.0, 10.0),
                body_to_ned: yaw(0.0),
            },
        );
        t.push(
            2.0,
            TrueState {
                position: Vector3::new(2.0, 0.0, 8.0),
                body_to_ned: yaw(0.2),
            },
        );
        let mid = t.at(1.5).unwrap();
        assert!((mid.position - Vector3::new(1.0, 0.0, 9.0)).norm() < 1e-12);
        let angle = Rotation3::from_matrix_unchecked(mid.body_to_ned).angle();
        assert!((angle - 0.1).abs() < 1e-9);
        assert_eq!(t.at(0.0).unwrap().position, Vector3::new(0.0, 0.0, 10.0));
        assert_eq!(t.at(5.0).unwrap().position, Vector3::new(2.0, 0.0, 8.0));
        assert!(TruthTable::new().at(1.0).is_none());
    }

    #[test]
    fn pad_and_ned_axes() {
        // A camera 10 m up, 1 m east (pad +x) and 2 m north (pad +y) of the pad sees it
        // 2 m south, 1 m west and 10 m below.
        let c = Vector3::new(1.0, 2.0, 10.0);
        assert_eq!(relative_ned(&c), Vector3::new(-2.0, -1.0, 10.0));
        assert_eq!(camera_in_pad(&relative_ned(&c)), c);
    }
}
