//! What the tests that play the flight controller share: a deterministic random source,
//! MAVLink 2 encoding, an autopilot's HEARTBEAT, the pad's place and a pad fix as the camera
//! side would report it (with the covariance of a typical fix), the board's estimator stage fed
//! such fixes, and the simulated flight they are flown in:
//!
//! - `vehicle`: the vehicle's path (position, velocity, attitude over time) and what a camera
//!   frame exposed on it sees ([`Exposure`]), with the frames' timing ([`CameraFrames`]);
//! - `link`: one direction of the serial link, delayed and in order ([`Link`]);
//! - `autopilot`: the simulated autopilot ([`Autopilot`]), its clock ([`AutopilotClock`]),
//!   and the flight loop's common steps ([`Flight`]: board, camera, link and autopilot);
//! - `scenario`: the companion tests' scenarios ([`Scenario`], [`simulate`]: faults,
//!   reboots, silence, a lost pad, a ground station's parameter requests);
//! - `decoded`: everything the companion sent, decoded by pymavlink
//!   (`scripts/mavlink_decode.py`) and checked against the truth ([`landing_targets`],
//!   [`accuracy`]).
//!
//! `tests/companion_*.rs` (the companion against a simulated autopilot) and
//! `tests/clock_drift.rs` (the same with a drifting autopilot clock) each use part of it,
//! hence the `dead_code` and `unused_imports` (of the re-exports) allowances: a part one test
//! binary does not call is still used by another.
#![allow(dead_code, unused_imports)]

mod autopilot;
mod decoded;
mod link;
mod scenario;
mod vehicle;

pub use autopilot::{Autopilot, AutopilotClock, Flight};
pub use decoded::{
    accuracy, decode_with_pymavlink, f, heartbeats_ok, landing_targets, report, Target,
};
pub use link::{Link, LinkDelay};
pub use scenario::{gcs_message, simulate, ParamAction, Run, Scenario, AP_AHEAD_US};
pub use vehicle::{CameraFrames, Exposure, VehiclePath};

use nalgebra::{Matrix3, Matrix6, Vector3};
use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavMessage, MavModeFlag, MavState, MavType, HEARTBEAT_DATA,
};
use touchdown_core::companion::mavlink::{MAVLinkV2MessageRaw, MavHeader};
use touchdown_core::companion::{Companion, TargetOutcome};
use touchdown_core::filter::{EstimatorConfig, PadEstimator};
use touchdown_core::params::PipelineSettings;
use touchdown_core::pose::{PadFix, Pose};

/// The simulation's time step, µs.
pub const STEP_US: u64 = 1_000;
/// A camera frame every 33 ms (30 Hz).
pub const FRAME_PERIOD_US: u64 = 33_333;
/// From a frame's exposure to its pad fix reaching the estimator stage.
pub const PROCESS_DELAY_US: u64 = 25_000;
/// Lateral noise of a fix, as a fraction of the distance.
pub const SIGMA_LATERAL: f32 = 0.002;
/// Range noise of a fix, as a fraction of the distance.
pub const SIGMA_RANGE: f32 = 0.006;

/// splitmix64 + Box-Muller: deterministic, no dependency.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal.
    pub fn gauss(&mut self) -> f32 {
        let u1 = self.uniform().max(1e-12);
        let u2 = self.uniform();
        ((-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()) as f32
    }
}

/// `msg` from (`sys`, `comp`) as MAVLink 2 bytes, with the next sequence number of `seq`.
pub fn encode(seq: &mut u8, sys: u8, comp: u8, msg: &MavMessage) -> Vec<u8> {
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message(
        MavHeader {
            system_id: u32::from(sys),
            component_id: comp,
            sequence: *seq,
        },
        msg,
    );
    *seq = seq.wrapping_add(1);
    raw.raw_bytes().to_vec()
}

/// A multicopter autopilot's HEARTBEAT of the given stack, armed: the flights here are in
/// the air.
pub fn heartbeat(autopilot: MavAutopilot) -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot,
        base_mode: MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

/// The pad, LOCAL_NED, metres.
pub fn pad_ned() -> Vector3<f32> {
    Vector3::new(4.0, 1.0, 0.0)
}

/// A one-marker pad fix at `translation` (camera frame, metres) turned by `rotation` (pad to
/// camera), with the covariance of a fix `distance` away: [`SIGMA_LATERAL`] and
/// [`SIGMA_RANGE`] of the distance on the position, a tight rotation.
pub fn pad_fix(rotation: Matrix3<f32>, translation: Vector3<f32>, distance: f32) -> PadFix {
    let (lateral, range) = (SIGMA_LATERAL * distance, SIGMA_RANGE * distance);
    let mut covariance = Matrix6::<f32>::zeros();
    for k in 0..3 {
        covariance[(k, k)] = 1e-6;
    }
    covariance[(3, 3)] = lateral * lateral;
    covariance[(4, 4)] = lateral * lateral;
    covariance[(5, 5)] = range * range;
    PadFix {
        pose: Pose {
            rotation,
            translation,
        },
        covariance,
        markers_used: 1,
        reprojection_rms_px: 0.3,
        alternative_rms_px: f32::INFINITY,
    }
}

/// The board's estimator stage fed pad fixes instead of images: what
/// `FramePipeline::process` runs after its pad fix, with TD_CAM_YAW applied between frames as
/// `FramePipeline::apply` does, and the companion's vehicle state read when the frame is
/// delivered (as the vision task reads the link's copy before each frame).
pub struct FixEstimator(PadEstimator);

impl FixEstimator {
    pub fn new() -> Self {
        FixEstimator(PadEstimator::new(EstimatorConfig::default()).unwrap())
    }

    /// One frame exposed at `exposure_us`, processed and handed to `companion` at `now_us`.
    pub fn deliver(
        &mut self,
        companion: &mut Companion,
        exposure_us: u64,
        fix: Option<PadFix>,
        now_us: u64,
    ) -> TargetOutcome {
        self.0
            .set_mount_yaw(PipelineSettings::from_params(companion.params()).cam_yaw_deg);
        let estimate = self
            .0
            .update(fix.as_ref(), &companion.vehicle().at(exposure_us));
        companion.on_estimate(&estimate, now_us)
    }
}
