//! One method's flight: the board's companion, the simulated autopilot and the two links,
//! run on our clock in steps of [`STEP_US`], and the reconstructions of what arrives.
//!
//! Per frame (see [`crate::Experiment::in_flight`]): the flight runs up to the frame's
//! delivery (its exposure plus the board's processing time), the pipeline runs on the frame
//! with the companion's vehicle state, the companion gets the estimate (and may adopt a mount
//! correction: the pipeline then takes the new settings, as the firmware does), and the flight
//! runs on [`SETTLE_US`] so that the target reaches the autopilot before the next frame.

use nalgebra::Vector3;
use touchdown_core::companion::{Companion, CompanionConfig, MAX_FRAME_LEN};
use touchdown_core::filter::VehicleAtExposure;
use touchdown_core::params::ParamId;

use super::autopilot::{belief, AutopilotKind, BoardClock, Link, ReceivedTarget, SimAutopilot};
use super::error_model::{ErrorModel, Realisation};
use super::reconstruct::{
    ardupilot_attitude_time_us, ardupilot_local_frd_relative_ned, ardupilot_relative_ned,
    px4_relative_ned,
};
use super::{camera_in_pad, relative_ned, Scored, TruthSource, WARMUP_US};
use touchdown_core::companion::mavlink::dialects::common::MavFrame;
use touchdown_core::companion::Profile;

/// The simulation's time step, µs.
pub const STEP_US: u64 = 250;
/// How long the flight runs on after a frame's estimate, µs: the target's bytes take about
/// 2 ms at the default baud and link delay.
pub const SETTLE_US: u64 = 15_000;
/// Board µs at frame time 0: room for the warm-up before a first frame at time 0.
pub const BOARD_OFFSET_US: u64 = WARMUP_US + 1_000_000;
/// A LANDING_TARGET's bytes on the wire (MAVLink 2: 12 bytes of header and checksum around
/// the 60-byte payload), for the paper's method, which is not sent through the companion.
pub const LANDING_TARGET_FRAME_BYTES: usize = 72;
/// The pad's origin in the autopilot's local NED frame, metres (PX4's origin is where it
/// armed: anywhere but the pad, so that a mix-up of absolute and relative shows).
pub const PAD_NED: Vector3<f64> = Vector3::new(6.0, -4.0, 0.5);

/// What every method's flight shares.
#[derive(Debug, Clone, PartialEq)]
pub struct FlightSetup {
    /// Which autopilot, and so which reconstruction.
    pub autopilot: AutopilotKind,
    /// The error sources.
    pub model: ErrorModel,
    /// Their seed (the same for every method).
    pub seed: u64,
    /// Board parameters set before the flight, by name, in order (e.g. `TD_CAM_CAL`).
    pub params: Vec<(String, f32)>,
    /// The camera mount the paper's method believes (the board's is its pipeline's).
    pub paper_mount: touchdown_core::filter::CameraMount,
    /// The `custom_mode` the autopilot's HEARTBEAT reports (with MAV_MODE_FLAG_CUSTOM_MODE_ENABLED);
    /// `None`: none (a scripted flight does not fly to our targets). The closed loop's PX4
    /// reports AUTO.PRECLAND.
    pub autopilot_mode: Option<u32>,
}

impl FlightSetup {
    /// ArduPilot under `model`, seed 1, default parameters and the nominal mount.
    pub fn new(autopilot: AutopilotKind, model: ErrorModel) -> Self {
        FlightSetup {
            autopilot,
            model,
            seed: 1,
            params: Vec::new(),
            paper_mount: touchdown_core::filter::CameraMount::downward(),
            autopilot_mode: None,
        }
    }
}

/// One method's flight (see the module docs).
#[derive(Debug, Clone)]
pub struct FlightRun {
    /// The board's companion, as the firmware runs it.
    pub companion: Companion,
    /// The simulated autopilot.
    pub autopilot: SimAutopilot,
    errors: Realisation,
    clock: BoardClock,
    uplink: Link,
    downlink: Link,
    now_us: Option<u64>,
    frames: u64,
    paper_mount: touchdown_core::filter::CameraMount,
    out: [u8; MAX_FRAME_LEN],
}

/// The board's companion with `params` (TD_* names and values) set, in order, as a user
/// sets them over MAVLink; an unknown or refused parameter is an error naming it.
pub fn board_companion(params: &[(String, f32)]) -> Result<Companion, String> {
    let mut companion = Companion::new(CompanionConfig::default());
    for (name, value) in params {
        let id = ParamId::from_name(name).ok_or_else(|| format!("no parameter {name}"))?;
        companion
            .set_param(id, *value)
            .map_err(|e| format!("{name} = {value}: {e:?}"))?;
    }
    Ok(companion)
}

impl FlightRun {
    /// A flight of `setup`; an unknown or refused parameter is an error naming it.
    pub fn new(setup: &FlightSetup) -> Result<Self, String> {
        Ok(FlightRun {
            companion: board_companion(&setup.params)?,
            autopilot: SimAutopilot::new(setup.autopilot, PAD_NED).with_mode(setup.autopilot_mode),
            errors: Realisation::new(setup.model, setup.seed),
            clock: BoardClock {
                offset_us: BOARD_OFFSET_US,
            },
            uplink: Link::new(),
            downlink: Link::new(),
            now_us: None,
            frames: 0,
            paper_mount: setup.paper_mount,
            out: [0; MAX_FRAME_LEN],
        })
    }

    /// Our clock against the frames'.
    pub fn clock(&self) -> &BoardClock {
        &self.clock
    }

    /// The camera mount the paper's method believes.
    pub fn paper_mount(&self) -> touchdown_core::filter::CameraMount {
        self.paper_mount
    }

    /// The error realisation.
    pub fn errors(&self) -> &Realisation {
        &self.errors
    }

    /// The flight's time (our clock, µs); 0 before it started.
    pub fn now_us(&self) -> u64 {
        self.now_us.unwrap_or(0)
    }

    /// When the next frame, exposed at `exposure_us` (our clock), is processed: its exposure
    /// plus the board's processing time, and not before now.
    pub fn delivery_us(&mut self, exposure_us: u64) -> u64 {
        let d = exposure_us + self.errors.processing_us(self.frames);
        self.frames += 1;
        match self.now_us {
            Some(now) => d.max(now),
            None => d,
        }
    }

    /// Runs everything up to `until_us` (our clock). The first call starts the flight
    /// [`WARMUP_US`] earlier.
    pub fn advance_to(&mut self, until_us: u64, truth: &dyn TruthSource) {
        let mut now = match self.now_us {
            Some(now) => now,
            None => until_us.saturating_sub(WARMUP_US),
        };
        loop {
            self.step(now, truth);
            if now >= until_us {
                break;
            }
            now = (now + STEP_US).min(until_us);
        }
        self.now_us = Some(now);
    }

    fn step(&mut self, now: u64, truth: &dyn TruthSource) {
        self.autopilot
            .tick(now, truth, &self.clock, &self.errors, &mut self.downlink);
        while let Some(bytes) = self.downlink.due(now) {
            self.companion.receive(&bytes, now);
        }
        while let Some(n) = self.companion.poll_transmit(now, &mut self.out) {
            let bytes = self.out[..n].to_vec();
            self.uplink.send(&self.errors, now, bytes);
        }
        while let Some(bytes) = self.uplink.due(now) {
            self.autopilot
                .hear(&bytes, now, &self.errors, &mut self.downlink);
        }
    }

    /// The LANDING_TARGETs the autopilot heard since the last call.
    pub fn take_targets(&mut self) -> Vec<ReceivedTarget> {
        std::mem::take(&mut self.autopilot.received)
    }

    /// When a message sent at `sent_us` on an idle link arrives (the paper's method's target,
    /// which does not go through the companion).
    pub fn arrival_us(&self, sent_us: u64) -> u64 {
        sent_us
            + self.errors.transmission_us(LANDING_TARGET_FRAME_BYTES)
            + self.errors.link_delay_us()
    }

    /// The true state at our clock's `board_us`.
    fn truth_at(&self, truth: &dyn TruthSource, board_us: u64) -> Option<super::TrueState> {
        truth.at(self.clock.frame_s(board_us))
    }

    /// The camera's true position against the pad where it is at `board_us` (pad frame axes).
    fn camera_from_pad(&self, truth: &dyn TruthSource, board_us: u64) -> Option<Vector3<f64>> {
        let t_s = self.clock.frame_s(board_us);
        Some(truth.at(t_s)?.position - truth.pad_origin(t_s))
    }

    /// (a): a body FRD vector sent for the exposure at `exposure_us` (our clock), turned with
    /// the true attitude then, against `truth_position` (the frame's truth).
    pub fn sent(
        &self,
        body: &Vector3<f64>,
        exposure_us: u64,
        truth_position: &Vector3<f64>,
        truth: &dyn TruthSource,
    ) -> Option<Scored> {
        let state = self.truth_at(truth, exposure_us)?;
        Some(Scored {
            t_us: self.clock.frame_us(exposure_us),
            truth: *truth_position,
            value: camera_in_pad(&(state.body_to_ned * body)),
        })
    }

    /// The exact body FRD vector of the pad at the exposure (an ideal sensor's).
    pub fn ideal_body(
        &self,
        exposure_us: u64,
        truth_position: &Vector3<f64>,
        truth: &dyn TruthSource,
    ) -> Option<Vector3<f64>> {
        let state = self.truth_at(truth, exposure_us)?;
        Some(state.body_to_ned.transpose() * relative_ned(truth_position))
    }

    /// ArduPilot's reconstruction of a body FRD target received at `receipt_us`, scored
    /// against the truth at the time of the attitude it uses. With PLND_LAG 0 (the ideal
    /// autopilot of [`ErrorModel::none`]) that is the exposure, `exposure_us`.
    pub fn reconstruct_body(
        &self,
        body: &Vector3<f64>,
        distance: f64,
        exposure_us: u64,
        receipt_us: u64,
        truth: &dyn TruthSource,
    ) -> Option<Scored> {
        self.reconstruct_ardupilot(body, distance, exposure_us, receipt_us, truth, false)
    }

    /// ArduPilot 4.7+'s reconstruction of a LOCAL_FRD target (`level`: the level,
    /// heading-turned vector) received at `receipt_us`: as [`FlightRun::reconstruct_body`],
    /// with the yaw alone of the delayed attitude.
    pub fn reconstruct_local_frd(
        &self,
        level: &Vector3<f64>,
        distance: f64,
        exposure_us: u64,
        receipt_us: u64,
        truth: &dyn TruthSource,
    ) -> Option<Scored> {
        self.reconstruct_ardupilot(level, distance, exposure_us, receipt_us, truth, true)
    }

    /// ArduPilot's reconstruction, BODY_FRD or (`local_frd`) LOCAL_FRD: the attitude at
    /// receipt minus PLND_LAG (the exposure with PLND_LAG 0), scored against the truth then.
    fn reconstruct_ardupilot(
        &self,
        xyz: &Vector3<f64>,
        distance: f64,
        exposure_us: u64,
        receipt_us: u64,
        truth: &dyn TruthSource,
        local_frd: bool,
    ) -> Option<Scored> {
        let lag = self.errors.model.plnd_lag_s;
        let at = if lag > 0.0 {
            ardupilot_attitude_time_us(receipt_us, lag)
        } else {
            exposure_us
        };
        let camera = self.camera_from_pad(truth, at)?;
        let b = belief(truth, &self.clock, &self.errors, &PAD_NED, at)?;
        let reconstruct = if local_frd {
            ardupilot_local_frd_relative_ned
        } else {
            ardupilot_relative_ned
        };
        let rel = reconstruct(xyz, distance, &b.body_to_ned, &Vector3::zeros())?;
        Some(Scored {
            t_us: self.clock.frame_us(at),
            truth: camera,
            value: camera_in_pad(&rel),
        })
    }

    /// The time PX4 stamps a LANDING_TARGET with `time_usec` (our clock) received at
    /// `receipt_us`: converted with its TIMESYNC estimate, else the arrival time; our clock.
    pub fn px4_stamp_us(&self, time_usec: u64, receipt_us: u64) -> u64 {
        match self.autopilot.px4_offset_us() {
            Some(offset) => {
                let ap = time_usec as f64 - offset;
                self.errors.board_clock_us(ap.max(0.0) as u64)
            }
            None => receipt_us,
        }
    }

    /// PX4's reconstruction of an absolute LOCAL_NED target stamped `time_usec` (our clock),
    /// received at `receipt_us`: minus its own position at the converted stamp, scored against
    /// the truth then.
    pub fn reconstruct_local_ned(
        &self,
        absolute: &Vector3<f64>,
        time_usec: u64,
        receipt_us: u64,
        truth: &dyn TruthSource,
    ) -> Option<Scored> {
        let at = self.px4_stamp_us(time_usec, receipt_us);
        let camera = self.camera_from_pad(truth, at)?;
        let b = belief(truth, &self.clock, &self.errors, &PAD_NED, at)?;
        let rel = px4_relative_ned(absolute, &b.position_ned);
        Some(Scored {
            t_us: self.clock.frame_us(at),
            truth: camera,
            value: camera_in_pad(&rel),
        })
    }

    /// The absolute LOCAL_NED point the companion would send for a body FRD vector with the
    /// vehicle state it holds at the exposure (`None` without attitude and position), as the
    /// PX4 profile computes it.
    pub fn local_ned_of(vehicle: &VehicleAtExposure, body: &Vector3<f64>) -> Option<Vector3<f64>> {
        let att = vehicle.attitude?;
        let pos = vehicle.position?;
        let r = att.matrix().cast::<f64>();
        Some(pos.position.cast::<f64>() + r * body)
    }

    /// A body FRD vector in LOCAL_FRD (the tilt of `body_to_ned` removed, its heading kept).
    fn level_of(body_to_ned: &nalgebra::Matrix3<f64>, body: &Vector3<f64>) -> Vector3<f64> {
        let ned = body_to_ned * body;
        let yaw = body_to_ned[(1, 0)].atan2(body_to_ned[(0, 0)]);
        let (s, c) = yaw.sin_cos();
        Vector3::new(c * ned.x + s * ned.y, -s * ned.x + c * ned.y, ned.z)
    }

    /// (b): what this flight's autopilot reconstructs from the LANDING_TARGET it received,
    /// for the exposure at `exposure_us`: ArduPilot from its BODY_FRD or LOCAL_FRD vector
    /// and distance (the simulated ArduPilot is 4.7+, which takes both; any other frame it
    /// refuses), PX4 from its LOCAL_NED point and time stamp (any other frame it drops).
    pub fn reconstruct_received(
        &self,
        target: &ReceivedTarget,
        exposure_us: u64,
        truth: &dyn TruthSource,
    ) -> Option<Scored> {
        let d = &target.data;
        let xyz = Vector3::new(d.x, d.y, d.z).cast::<f64>();
        match self.autopilot.kind {
            AutopilotKind::ArduPilot => {
                let local_frd = match d.frame {
                    MavFrame::MAV_FRAME_BODY_FRD => false,
                    MavFrame::MAV_FRAME_LOCAL_FRD => true,
                    _ => return None,
                };
                let distance = f64::from(d.distance);
                let receipt = target.receipt_us;
                self.reconstruct_ardupilot(&xyz, distance, exposure_us, receipt, truth, local_frd)
            }
            // PX4's mavlink_receiver takes a LANDING_TARGET only in MAV_FRAME_LOCAL_NED
            // and drops any other frame.
            AutopilotKind::Px4 if d.frame == MavFrame::MAV_FRAME_LOCAL_NED => {
                self.reconstruct_local_ned(&xyz, d.time_usec, target.receipt_us, truth)
            }
            AutopilotKind::Px4 => None,
        }
    }

    /// (c): what this flight's autopilot reconstructs from an ideal sensor's message for the
    /// exposure at `exposure_us` (the exact body vector, [`FlightRun::ideal_body`]), received at
    /// `receipt_us`.
    pub fn reconstruct_ideal(
        &self,
        exposure_us: u64,
        receipt_us: u64,
        vehicle: &VehicleAtExposure,
        truth_position: &Vector3<f64>,
        truth: &dyn TruthSource,
    ) -> Option<Scored> {
        let ideal = self.ideal_body(exposure_us, truth_position, truth)?;
        self.reconstruct(&ideal, exposure_us, receipt_us, vehicle, truth)
    }

    /// The reconstruction of `body` for this flight's autopilot, received at `receipt_us`,
    /// exposed at `exposure_us`, with the companion's vehicle state at the exposure for PX4
    /// and for ArduPilot in LOCAL_FRD (TD_PROFILE 3: the body vector levelled with that
    /// attitude, as the companion sends it; BODY_FRD without one, as the companion does).
    pub fn reconstruct(
        &self,
        body: &Vector3<f64>,
        exposure_us: u64,
        receipt_us: u64,
        vehicle: &VehicleAtExposure,
        truth: &dyn TruthSource,
    ) -> Option<Scored> {
        match self.autopilot.kind {
            AutopilotKind::ArduPilot => {
                let local_frd = self.companion.profile() == Some(Profile::ArduPilotLocalFrd);
                match vehicle.attitude.filter(|_| local_frd) {
                    Some(att) => {
                        let r = att.matrix().cast::<f64>();
                        let level = Self::level_of(&r, body);
                        self.reconstruct_local_frd(
                            &level,
                            body.norm(),
                            exposure_us,
                            receipt_us,
                            truth,
                        )
                    }
                    None => {
                        self.reconstruct_body(body, body.norm(), exposure_us, receipt_us, truth)
                    }
                }
            }
            AutopilotKind::Px4 => {
                let abs = Self::local_ned_of(vehicle, body)?;
                self.reconstruct_local_ned(&abs, exposure_us, receipt_us, truth)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flight::TrueState;
    use nalgebra::{Matrix3, Rotation3};

    /// A hover 10 m above the pad, 1 m east, nose north, level, or turning.
    #[derive(Debug)]
    struct Hover {
        yaw_rate: f64,
    }

    impl TruthSource for Hover {
        fn at(&self, t_s: f64) -> Option<TrueState> {
            Some(TrueState {
                position: Vector3::new(1.0, 0.0, 10.0),
                body_to_ned: Rotation3::from_euler_angles(0.0, 0.0, self.yaw_rate * t_s)
                    .into_inner(),
            })
        }
    }

    #[test]
    fn the_companion_gets_the_streams_and_the_autopilot_answers() {
        for kind in [AutopilotKind::ArduPilot, AutopilotKind::Px4] {
            let mut run = FlightRun::new(&FlightSetup::new(kind, ErrorModel::typical())).unwrap();
            let truth = Hover { yaw_rate: 0.0 };
            let t = run.clock().board_us(0);
            run.advance_to(t, &truth);
            let at = run.companion.vehicle().at(t);
            let att = at.attitude.expect("attitude streamed");
            // The autopilot's attitude: level and north within its errors (heading 0.5 deg).
            let angle = Rotation3::from_matrix_unchecked(att.matrix().cast::<f64>()).angle();
            assert!(angle.to_degrees() < 1.5, "{kind:?}: {}", angle.to_degrees());
            // LOCAL_POSITION_NED is asked for by the PX4 profile, and by any with TD_PAD_MOTION
            // auto (the default: the pad's velocity over the ground needs the vehicle's).
            assert!(at.position.is_some(), "{kind:?}");
            let at_rest = FlightSetup {
                params: vec![("TD_PAD_MOTION".into(), 0.0)],
                ..FlightSetup::new(kind, ErrorModel::typical())
            };
            let mut still = FlightRun::new(&at_rest).unwrap();
            still.advance_to(t, &truth);
            assert_eq!(
                still.companion.vehicle().at(t).position.is_some(),
                kind == AutopilotKind::Px4,
                "{kind:?} with TD_PAD_MOTION 0"
            );
            let stats = run.companion.stats();
            assert!(stats.timesync_samples >= 2, "{kind:?}: {stats:?}");
            assert!(stats.interval_acks_accepted >= 1, "{kind:?}");
            // Its clock offset as the companion estimated it: 12.3 s plus the drift.
            let offset = stats.clock_offset_us.expect("synchronised");
            assert!(
                (offset as f64 - 12.3e6).abs() < 2_000.0,
                "{kind:?}: {offset}"
            );
            if kind == AutopilotKind::Px4 {
                let o = run.autopilot.px4_offset_us().expect("PX4 synchronised");
                assert!((o + 12.3e6).abs() < 2_000.0, "{o}");
            }
        }
    }

    #[test]
    fn an_ideal_autopilot_reconstructs_the_truth() {
        let truth = Hover { yaw_rate: 0.3 };
        for kind in [AutopilotKind::ArduPilot, AutopilotKind::Px4] {
            let mut run = FlightRun::new(&FlightSetup::new(kind, ErrorModel::none())).unwrap();
            let exposure = run.clock().board_us(2_000_000);
            // Processed 20 ms later: the attitude samples either side of the exposure are in.
            run.advance_to(exposure + 20_000, &truth);
            let c = Vector3::new(1.0, 0.0, 10.0);
            let body = run.ideal_body(exposure, &c, &truth).unwrap();
            let vehicle = run.companion.vehicle().at(exposure);
            let b = run
                .reconstruct(&body, exposure, exposure, &vehicle, &truth)
                .expect("reconstructed");
            assert!((b.value - c).norm() < 2e-3, "{kind:?}: {b:?}");
            let a = run.sent(&body, exposure, &c, &truth).unwrap();
            assert!((a.value - c).norm() < 1e-9);
        }
    }

    #[test]
    fn an_ideal_autopilot_reconstructs_local_frd_too() {
        // TD_PROFILE 3: the companion sends LOCAL_FRD; ArduPilot 4.7 turns it by its yaw.
        let truth = Hover { yaw_rate: 0.3 };
        let mut setup = FlightSetup::new(AutopilotKind::ArduPilot, ErrorModel::none());
        setup.params.push(("TD_PROFILE".into(), 3.0));
        let mut run = FlightRun::new(&setup).unwrap();
        let exposure = run.clock().board_us(2_000_000);
        run.advance_to(exposure + 20_000, &truth);
        assert_eq!(run.companion.profile(), Some(Profile::ArduPilotLocalFrd));
        let c = Vector3::new(1.0, 0.0, 10.0);
        let body = run.ideal_body(exposure, &c, &truth).unwrap();
        let vehicle = run.companion.vehicle().at(exposure);
        assert!(vehicle.attitude.is_some());
        let b = run
            .reconstruct(&body, exposure, exposure, &vehicle, &truth)
            .expect("reconstructed");
        assert!((b.value - c).norm() < 2e-3, "{b:?}");
    }

    #[test]
    fn the_heading_bias_alone_turns_the_reconstruction() {
        let truth = Hover { yaw_rate: 0.0 };
        let model = ErrorModel {
            heading_bias_deg: 1.0,
            ..ErrorModel::none()
        };
        let run = FlightRun::new(&FlightSetup::new(AutopilotKind::ArduPilot, model)).unwrap();
        let exposure = run.clock().board_us(1_000_000);
        let c = Vector3::new(1.0, 0.0, 10.0);
        let body = run.ideal_body(exposure, &c, &truth).unwrap();
        let b = run
            .reconstruct_body(&body, body.norm(), exposure, exposure, &truth)
            .unwrap();
        // 1 m east turned by 1 deg about down: 1.75 cm sideways, the altitude unchanged.
        let e = b.error();
        assert!((e.xy().norm() - 1.0f64.to_radians()).abs() < 1e-4, "{e}");
        assert!(e.z.abs() < 1e-9);
        let _ = Matrix3::<f64>::identity();
    }
}
