//! The estimator stage: filters that smooth the pad position over time, the vehicle state
//! they read it with, and the coordinate axes they work in.
//!
//! A single pose is noisy (its depth error grows with the square of the distance), it is
//! sometimes wrong (a mis-decoded or mirrored pose), and frames get dropped. The flight
//! controller wants one steady, current position of the pad, and nothing at all once the pad
//! is gone. Two filters live here:
//!
//! - [`paper::PaperKalman`]: the per-axis scalar Kalman filter of the reference paper
//!   (section 2.3, equations 8-14, Table 1), implemented literally so its behaviour, including
//!   its lag on a descending vehicle, can be reproduced and compared.
//! - [`tracker::Tracker`]: ours. A 3-D constant-velocity Kalman filter driven by time stamps
//!   (variable time step, dropped frames), fed with the pose's own covariance, with
//!   Mahalanobis gating, recovery from a real jump, a track lifecycle and no stale output.
//!
//! Both consume a [`Measurement`]: a position in metres with its 3x3 covariance and the
//! exposure time stamp. Which axes the position is expressed in is the caller's choice and
//! matters (see [`tracker`]): with the vehicle's attitude, rotate the camera-frame pose into
//! level NED axes with [`axes::level_measurement`] first.
//!
//! What flies is [`estimator::PadEstimator`]: two trackers (level NED axes with the attitude
//! at each frame's exposure from [`vehicle::VehicleState`], and the camera frame as the
//! fallback), run by [`crate::pipeline::FramePipeline`] after each pad fix. [`axes`] holds the
//! attitude, the camera mount and the rotations between camera, body FRD and NED.

pub mod axes;
pub mod estimator;
pub mod paper;
pub mod tracker;
pub mod vehicle;

pub use estimator::{EstimatorConfig, FrameEstimate, LevelEstimate, PadEstimate, PadEstimator};
pub use paper::{PaperConfig, PaperKalman};
pub use tracker::{
    ConfigError, Estimate, RejectReason, TrackState, Tracker, TrackerConfig, UpdateOutcome,
};
pub use vehicle::{PositionSample, VehicleAtExposure, VehicleState};

use nalgebra::{Matrix3, Vector3};

/// One measured position of the pad with its uncertainty.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Exposure time of the frame, microseconds (any monotonic clock; see [`tracker`] for
    /// what happens when it goes backwards).
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
