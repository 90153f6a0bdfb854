//! The estimator stage: filters that smooth the pad position over time, the vehicle state
//! they read it with, and the coordinate axes they work in.
//!
//! What this module offers: [`PadEstimator`] (configured by [`EstimatorConfig`]), which takes
//! each frame's pad fix from [`crate::pose`] and returns a [`FrameEstimate`] for
//! [`crate::companion`]; the two filters, [`Tracker`] and [`PaperKalman`], both fed a
//! [`Measurement`]; [`VehicleState`], the vehicle's attitude and position history read at each
//! frame's exposure; and the axes: [`Attitude`], [`CameraMount`] and the rotations between
//! camera, body FRD and NED ([`level_measurement`], [`camera_to_ned_matrix`],
//! [`ned_to_camera`], [`local_ned_position`], [`landing_angles`]).
//!
//! A single pose is noisy (its depth error grows with the square of the distance), it is
//! sometimes wrong (a mis-decoded or mirrored pose), and frames get dropped. The flight
//! controller wants one steady, current position of the pad, and nothing at all once the pad
//! is gone. Two filters live here:
//!
//! - [`PaperKalman`]: the per-axis scalar Kalman filter of the reference paper
//!   (section 2.3, equations 8-14, Table 1), implemented literally so its behaviour, including
//!   its lag on a descending vehicle, can be reproduced and compared.
//! - [`Tracker`]: ours. A 3-D constant-velocity Kalman filter driven by time stamps
//!   (variable time step, dropped frames), fed with the pose's own covariance, with
//!   Mahalanobis gating, recovery from a real jump, a track lifecycle and no stale output.
//!
//! Both consume a [`Measurement`]: a position in metres with its 3x3 covariance and the
//! exposure time stamp. Which axes the position is expressed in is the caller's choice and
//! matters (a constant-velocity model only fits in axes that do not turn with the vehicle, see
//! [`TrackerConfig::level`] and [`TrackerConfig::camera_frame`]): with the vehicle's attitude,
//! rotate the camera-frame pose into level NED axes with [`level_measurement`] first, and add
//! the attitude's error to its covariance with [`level_covariance`].
//!
//! What flies is [`PadEstimator`]: two trackers (level NED axes with the attitude at each
//! frame's exposure from [`VehicleState`], and the camera frame as the fallback), run by
//! [`crate::pipeline::FramePipeline`] after each pad fix.
//!
//! The camera mount's roll and pitch are calibrated in flight by [`MountCalibrator`] (in
//! `mount_calibration`), which the estimator feeds: its [`MountCorrection`]s come out in
//! [`FrameEstimate::mount_correction`].
//!
//! The module is split by concern, in private submodules: `estimator` (the [`PadEstimator`]),
//! `tracker` and `paper` (the two filters), `vehicle` (the vehicle state history) and `axes`
//! (the frames and the rotations between them).

mod axes;
mod estimator;
mod mount_calibration;
mod paper;
mod tracker;
mod vehicle;

pub use axes::{
    camera_to_ned_matrix, distance, landing_angles, level_measurement, local_ned_position,
    ned_to_camera, Attitude, CameraMount, LandingAngles, RotationError,
};
pub use estimator::{
    level_covariance, turn_covariance, EstimatorConfig, FrameEstimate, LevelEstimate, PadEstimate,
    PadEstimator, ATTITUDE_NOISE_DEG, MOUNT_PRIOR_SIGMA_DEG,
};
pub use mount_calibration::{
    roll_pitch_aligning, MountCalibrationConfig, MountCalibrationMode, MountCalibrationStats,
    MountCalibrator, MountCorrection, MountEstimate, MountRefusal, ATTITUDE_BIAS_DEG,
    FRAME_DECORRELATION_US, MIN_REREPORT_DEG, REREPORT_SIGMAS, RESTART_AFTER_OUTLIERS,
};
pub use paper::{PaperConfig, PaperKalman};
pub use tracker::{
    ConfigError, Estimate, RejectReason, TrackState, Tracker, TrackerConfig, UpdateOutcome,
};
pub use vehicle::{
    PositionSample, VehicleAtExposure, VehicleState, MAX_EXTRAPOLATION_US, MAX_GAP_US,
    MAX_RATE_GAP_US, POSITION_HISTORY, REBOOT_BACKWARDS_US,
};

use nalgebra::{Matrix3, Vector3};

/// One measured position of the pad with its uncertainty.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Exposure time of the frame, microseconds (any monotonic clock; see
    /// [`TrackerConfig::max_backwards_us`] for what happens when it goes backwards).
    pub t_us: u64,
    /// Position of the pad centre, metres, in the frame the filter runs in.
    pub position: Vector3<f32>,
    /// Covariance of `position`, m². Symmetric positive semi-definite; the tracker adds a
    /// small floor so an over-confident pose cannot freeze the filter.
    pub covariance: Matrix3<f32>,
}

impl Measurement {
    /// The same measurement expressed in another frame: `position' = r * position`,
    /// `covariance' = r * covariance * r^T` (`r` a rotation matrix).
    pub fn rotated(&self, r: &Matrix3<f32>) -> Measurement {
        Measurement {
            t_us: self.t_us,
            position: r * self.position,
            covariance: r * self.covariance * r.transpose(),
        }
    }
}
