//! The companion: the MAVLink side of the landing aid, as a sans-IO state machine.
//!
//! The board sits on a UART to the flight controller (ArduPilot or PX4). [`Companion`] owns
//! everything between "a frame was processed" and "these bytes go on the wire", and nothing
//! that touches hardware: the caller feeds it
//!
//! - received bytes, [`Companion::receive`] (any chunking; garbage and broken frames are
//!   survived, see [`link`]),
//! - processed frames, [`Companion::on_frame`] (exposure time and the pad fix, if any),
//! - the time, as a `now_us` argument on every call (our boot clock, µs, monotonic),
//!
//! and drains [`Companion::poll_transmit`], one serialised MAVLink 2 frame per call, whenever
//! the UART can take more. The firmware's UART task and the host's `touchdown companion`
//! (UDP) run the very same code; the host tests drive it with a simulated autopilot and check
//! every byte with pymavlink.
//!
//! # What it sends
//!
//! - HEARTBEAT at 1 Hz (`MAV_TYPE_ONBOARD_CONTROLLER`, `MAV_AUTOPILOT_INVALID`).
//! - LANDING_TARGET for every processed frame that has a pad fix and a fresh estimate, in the
//!   ArduPilot or PX4 format ([`profile`]), MAVLink 2 with the extension fields. Never a stale
//!   one: only frames *with* a fix produce a target (a frame without one produces nothing, so
//!   the flight controller's own timeout sees the pad disappear), the tracker must have a
//!   confirmed estimate at that frame's exposure time whose last measurement is at most
//!   [`TrackerConfig::max_coast_us`] old, and a target not transmitted within
//!   [`CompanionConfig::max_target_latency_us`] of its frame is dropped, not sent late. A newer
//!   target replaces an unsent older one. The format follows TD_PROFILE; with TD_PROFILE auto
//!   (the default) the autopilot's HEARTBEAT chooses it and, until one has been heard, no
//!   target is sent ([`FrameOutcome::NoProfile`]); the choice is announced by STATUSTEXT.
//!
//! The autopilot is the sender of HEARTBEATs from our system id (TD_SYSID) and component 1
//! whose `autopilot` is not MAV_AUTOPILOT_INVALID; the vehicle state, TIMESYNC answers and
//! the profile come from it alone.
//! - VISION_POSITION_ESTIMATE (optional, TD_VPE_EN): the vehicle in a pad-centred NED frame,
//!   with covariance.
//! - TIMESYNC requests (1 Hz) and answers to the autopilot's requests ([`timesync`]), the
//!   answers ahead of everything else waiting (PX4 discards round trips of 10 ms or more).
//! - COMMAND_LONG `MAV_CMD_SET_MESSAGE_INTERVAL` for the vehicle state it needs
//!   (ATTITUDE_QUATERNION; LOCAL_POSITION_NED too for PX4), repeated every second while that
//!   stream is not arriving, so a rebooted autopilot gets asked again.
//! - PARAM_VALUE for the parameter protocol ([`params`]); a full list is paced at one
//!   PARAM_VALUE per [`CompanionConfig::param_stream_interval_us`].
//! - STATUSTEXT when the firmware reports a fault ([`Companion::queue_status_text`]: camera
//!   lost, parameters reset), which ground stations show to the pilot.
//!
//! # Frames and filtering
//!
//! Two trackers ([`crate::filter::tracker`]) see every fix:
//!
//! - the **level** tracker filters the pad relative to the vehicle in NED axes, each pose
//!   rotated with the attitude *at the frame's exposure* ([`vehicle`] keeps a short history and
//!   interpolates). This is the good one: the pad is static in that frame.
//! - the **camera-frame** tracker filters the raw camera-frame positions; its larger process
//!   noise absorbs the vehicle's tilting. It is the fallback when there is no attitude.
//!
//! ArduPilot profile: body FRD from the level estimate and the attitude at exposure; with no
//! attitude (autopilot silent, or not streaming it) from the camera-frame estimate through the
//! mount. ArduPilot does not need our vehicle state, so targets keep flowing when the
//! autopilot's messages stop (decided: a silent *telemetry* direction does not mean the
//! autopilot cannot hear us). PX4 profile: only with attitude and LOCAL_POSITION_NED at the
//! exposure, so when the autopilot goes silent targets stop within
//! [`vehicle::MAX_EXTRAPOLATION_US`] and resume with its first samples.
//!
//! # Time
//!
//! `time_usec` ([`TimeBase`]): ArduPilot gets the exposure time in the autopilot's clock
//! (TIMESYNC, else SYSTEM_TIME, else our boot time). PX4 gets our boot time, because PX4
//! itself converts `time_usec` with its TIMESYNC estimate of our clock (we answer its
//! requests). An autopilot reboot (its clock going back by more than a second) resets the
//! offset, the vehicle state and the level tracker, and triggers a new TIMESYNC and new
//! message-interval requests at once.

pub mod link;
pub mod params;
pub mod persist;
pub mod profile;
pub mod timesync;
pub mod vehicle;
pub mod vision;

pub use mavlink;

pub use link::{FrameParser, ParserStats, RawFrame, MAX_FRAME_LEN};
pub use mavlink::dialects::common::MavSeverity;
pub use params::{ParamError, ParamId, ParamSet, PARAMS, PARAM_COUNT};
pub use profile::{Profile, ProfileSetting, TargetFields, TargetFrame};
pub use timesync::{TimeSource, TimeSync};
pub use vehicle::{PositionSample, VehicleState};
pub use vision::VisionSettings;

use crate::filter::{ConfigError, Measurement, Tracker, TrackerConfig};
use crate::frames::{level_measurement, Attitude, CameraMount};
use crate::pose::PadFix;
use heapless::Deque;
use mavlink::dialects::common::{
    LandingTargetType, MavAutopilot, MavBool, MavCmd, MavFrame, MavMessage, MavModeFlag,
    MavParamType, MavResult, MavState, MavType, COMMAND_ACK_DATA, COMMAND_LONG_DATA,
    HEARTBEAT_DATA, LANDING_TARGET_DATA, PARAM_VALUE_DATA, STATUSTEXT_DATA, TIMESYNC_DATA,
    VISION_POSITION_ESTIMATE_DATA,
};
use mavlink::MessageData;
use nalgebra::{UnitQuaternion, Vector3};

/// LANDING_TARGET's payload with every MAVLink 2 extension field. If the mavlink crate is ever
/// generated without extensions (see core/Cargo.toml), this stops compiling.
pub const LANDING_TARGET_FULL_LEN: usize = 60;
const _: () = assert!(
    <LANDING_TARGET_DATA as MessageData>::ENCODED_LEN == LANDING_TARGET_FULL_LEN,
    "mavlink was generated without MAVLink 2 extension fields"
);

/// Capacity of the transmit queue (heartbeat, TIMESYNC, commands, PARAM_VALUE).
pub const TX_QUEUE_CAPACITY: usize = 16;
/// Capacity of the STATUSTEXT queue (faults are rare; more are dropped and counted).
pub const STATUS_QUEUE_CAPACITY: usize = 4;
/// Longest STATUSTEXT text, bytes (MAVLink's field; longer text is cut).
pub const STATUS_TEXT_LEN: usize = 50;
/// LANDING_TARGET `q` when the fix's rotation is unusable (not finite, not a rotation): NaN in
/// the first element, MAVLink's usual "unknown" for a quaternion; identity would claim an
/// orientation. Neither autopilot reads `q` today.
const UNKNOWN_Q: [f32; 4] = [f32::NAN, 0.0, 0.0, 0.0];
/// MAV_COMP_ID_AUTOPILOT1: the flight controller's component id.
const MAV_COMP_ID_AUTOPILOT1: u8 = 1;
/// MAVLink message id of ATTITUDE_QUATERNION.
const MSG_ATTITUDE_QUATERNION: u32 = 31;
/// MAVLink message id of LOCAL_POSITION_NED.
const MSG_LOCAL_POSITION_NED: u32 = 32;
/// A converted autopilot time stamp further than this from our receive time is not trusted
/// (the offset is wrong, e.g. a reboot not yet noticed); the receive time is used instead.
const MAX_STAMP_DISAGREEMENT_US: u64 = 500_000;

/// Which clock `time_usec` is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TimeBase {
    /// ArduPilot: autopilot clock; PX4: companion clock (see the module docs).
    ByProfile,
    /// The autopilot's clock where known (TIMESYNC / SYSTEM_TIME), else our boot time.
    Autopilot,
    /// Our boot time.
    Companion,
}

impl TimeBase {
    fn from_param(v: i32) -> TimeBase {
        match v {
            1 => TimeBase::Autopilot,
            2 => TimeBase::Companion,
            _ => TimeBase::ByProfile,
        }
    }
}

/// Everything that is fixed at start-up (the tunable part is [`ParamSet`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompanionConfig {
    /// Initial parameter values: defaults, or imported from flash.
    pub params: ParamSet,
    /// The camera mount before TD_CAM_YAW's turn about the optical axis.
    pub mount: CameraMount,
    /// The level (NED axes) tracker.
    pub level_tracker: TrackerConfig,
    /// The camera-frame tracker (no attitude).
    pub camera_tracker: TrackerConfig,
    /// HEARTBEAT period, µs.
    pub heartbeat_period_us: u64,
    /// TIMESYNC request period, µs.
    pub timesync_period_us: u64,
    /// How often a missing vehicle-state stream is requested again, µs.
    pub interval_request_period_us: u64,
    /// A stream silent this long counts as missing (and is requested again), µs.
    pub stream_timeout_us: u64,
    /// Requested ATTITUDE_QUATERNION interval, µs.
    pub attitude_interval_us: u32,
    /// Requested LOCAL_POSITION_NED interval, µs (PX4 profile).
    pub position_interval_us: u32,
    /// Pace of a full parameter list, µs per PARAM_VALUE.
    pub param_stream_interval_us: u64,
    /// A LANDING_TARGET not transmitted this long after its frame was processed is dropped.
    pub max_target_latency_us: u64,
    /// The autopilot counts as gone after this long without any message from it, µs.
    pub autopilot_timeout_us: u64,
}

impl Default for CompanionConfig {
    fn default() -> Self {
        CompanionConfig {
            params: ParamSet::default(),
            mount: CameraMount::downward(),
            level_tracker: TrackerConfig::level(),
            camera_tracker: TrackerConfig::camera_frame(),
            heartbeat_period_us: 1_000_000,
            timesync_period_us: 1_000_000,
            interval_request_period_us: 1_000_000,
            stream_timeout_us: 1_000_000,
            attitude_interval_us: 20_000,
            position_interval_us: 33_333,
            param_stream_interval_us: 20_000,
            max_target_latency_us: 100_000,
            autopilot_timeout_us: 3_000_000,
        }
    }
}

impl CompanionConfig {
    /// Defaults with the given profile.
    pub fn with_profile(profile: Profile) -> Self {
        let mut c = CompanionConfig::default();
        // In range by construction.
        let _ = c.params.set(ParamId::Profile, profile.to_param());
        c
    }
}

/// One processed camera frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameResult {
    /// Exposure time, our boot clock, µs.
    pub exposure_us: u64,
    /// The pad pose, when the pad was found.
    pub fix: Option<PadFix>,
}

/// What [`Companion::on_frame`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameOutcome {
    /// A LANDING_TARGET is queued.
    TargetQueued,
    /// No pad in this frame: nothing sent.
    NoFix,
    /// The tracker has no confirmed, fresh estimate (starting, or the fix was rejected).
    NoEstimate,
    /// PX4 profile: no attitude or local position at the exposure time.
    NoVehicleState,
    /// TD_PROFILE auto and no autopilot identified yet (no HEARTBEAT from it, or one whose
    /// `autopilot` is neither ArduPilot nor PX4): a target in the wrong frame would be
    /// refused, so none is sent.
    NoProfile,
    /// Within TD_RATE_HZ's interval of the previous target.
    RateLimited,
    /// The estimate gave no valid target (not finite, behind the camera).
    Invalid,
}

/// Counters (saturating) and link state, for logs and reports.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CompanionStats {
    /// The receive parser's counters.
    pub link: ParserStats,
    /// Valid frames whose payload did not decode (bad enum value...).
    pub decode_errors: u32,
    /// Frames handed to [`Companion::poll_transmit`]'s caller.
    pub tx_frames: u32,
    /// Bytes handed out.
    pub tx_bytes: u64,
    /// LANDING_TARGETs sent.
    pub landing_targets: u32,
    /// VISION_POSITION_ESTIMATEs sent.
    pub vision_estimates: u32,
    /// PARAM_VALUEs sent.
    pub param_values: u32,
    /// Queue items (STATUSTEXTs included) dropped because their queue was full.
    pub queue_overflows: u32,
    /// STATUSTEXTs sent.
    pub status_texts: u32,
    /// Targets dropped because they were not transmitted in time.
    pub targets_expired: u32,
    /// Unsent targets replaced by a newer one.
    pub targets_replaced: u32,
    /// Frames processed.
    pub frames: u32,
    /// Frames with a pad fix.
    pub frames_with_fix: u32,
    /// Frames with a fix but no fresh estimate.
    pub no_estimate: u32,
    /// Frames with a fix but no vehicle state (PX4).
    pub no_vehicle_state: u32,
    /// Frames with a fix but no profile yet (TD_PROFILE auto, autopilot not identified).
    pub no_profile: u32,
    /// Autopilot reboots detected.
    pub autopilot_reboots: u32,
    /// Accepted PARAM_SETs.
    pub param_sets_accepted: u32,
    /// Rejected PARAM_SETs (answered with the old value).
    pub param_sets_rejected: u32,
    /// SET_MESSAGE_INTERVAL commands sent.
    pub interval_requests: u32,
    /// COMMAND_ACKs for them with MAV_RESULT_ACCEPTED.
    pub interval_acks_accepted: u32,
    /// COMMAND_ACKs for them with another result.
    pub interval_acks_other: u32,
    /// TIMESYNC samples used / answers refused / confirmed offset jumps.
    pub timesync_samples: u32,
    /// TIMESYNC answers refused (not ours, or a round trip too long).
    pub timesync_rejected: u32,
    /// Where the clock offset comes from.
    pub time_source: Option<TimeSource>,
    /// Autopilot minus companion clock, µs.
    pub clock_offset_us: Option<i64>,
    /// The autopilot's (system, component) id, once heard.
    pub autopilot: Option<(u8, u8)>,
}

/// Something waiting in the transmit queue.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Pending {
    Heartbeat,
    TimesyncRequest {
        ts1: i64,
        target: (u8, u8),
    },
    TimesyncResponse {
        tc1: i64,
        ts1: i64,
        target: (u8, u8),
    },
    SetInterval {
        message_id: u32,
        interval_us: u32,
        target: (u8, u8),
    },
    CommandAck {
        command: MavCmd,
        target: (u8, u8),
    },
    ParamValue(ParamId),
}

/// A STATUSTEXT waiting to be sent.
#[derive(Debug, Clone, Copy, PartialEq)]
struct StatusText {
    severity: MavSeverity,
    text: [u8; STATUS_TEXT_LEN],
}

#[derive(Debug, Clone, PartialEq)]
struct PendingTarget {
    created_us: u64,
    data: LANDING_TARGET_DATA,
}

#[derive(Debug, Clone, PartialEq)]
struct PendingVpe {
    created_us: u64,
    data: VISION_POSITION_ESTIMATE_DATA,
}

/// A vehicle-state stream we request.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Stream {
    message_id: u32,
    last_rx_us: Option<u64>,
    next_request_us: u64,
}

/// Everything but the receive parser (so the parser can call into it).
#[derive(Debug, Clone)]
struct State {
    config: CompanionConfig,
    params: ParamSet,
    mount: CameraMount,
    level: Tracker,
    camera: Tracker,
    vehicle: VehicleState,
    timesync: TimeSync,
    queue: Deque<Pending, TX_QUEUE_CAPACITY>,
    /// The answer to the latest TIMESYNC request, sent before anything else: PX4 discards
    /// samples whose round trip is 10 ms or more (and wants hundreds of good ones), so it
    /// must not wait behind targets and parameters. One slot: a newer request supersedes an
    /// unanswered older one, whose round trip is already long.
    timesync_reply: Option<Pending>,
    status: Deque<StatusText, STATUS_QUEUE_CAPACITY>,
    target: Option<PendingTarget>,
    vpe: Option<PendingVpe>,
    sequence: u8,
    autopilot: Option<(u8, u8)>,
    autopilot_rx_us: Option<u64>,
    /// The profile the latched autopilot's HEARTBEAT asks for (TD_PROFILE auto).
    detected: Option<Profile>,
    /// The auto profile last announced by STATUSTEXT.
    announced: Option<Profile>,
    next_heartbeat_us: u64,
    next_timesync_us: u64,
    streams: [Stream; 2],
    param_cursor: Option<usize>,
    next_param_us: u64,
    last_target_exposure_us: Option<u64>,
    stats: CompanionStats,
}

/// The companion state machine (see the module documentation).
#[derive(Debug, Clone)]
pub struct Companion {
    parser: FrameParser,
    state: State,
}

fn mount_with_yaw(base: &CameraMount, yaw_deg: f32) -> CameraMount {
    let [w, x, y, z] = base.quaternion_wxyz();
    let q = UnitQuaternion::new_normalize(nalgebra::Quaternion::new(w, x, y, z))
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_deg.to_radians());
    CameraMount::from_quaternion_wxyz([q.w, q.i, q.j, q.k]).unwrap_or(*base)
}

impl Companion {
    /// A companion that has heard nothing yet. Fails when a tracker configuration is invalid.
    pub fn new(config: CompanionConfig) -> Result<Self, ConfigError> {
        let params = config.params;
        Ok(Companion {
            parser: FrameParser::new(),
            state: State {
                config,
                params,
                mount: mount_with_yaw(&config.mount, params.get(ParamId::CamYaw)),
                level: Tracker::new(config.level_tracker)?,
                camera: Tracker::new(config.camera_tracker)?,
                vehicle: VehicleState::new(),
                timesync: TimeSync::new(),
                queue: Deque::new(),
                timesync_reply: None,
                status: Deque::new(),
                target: None,
                vpe: None,
                sequence: 0,
                autopilot: None,
                autopilot_rx_us: None,
                detected: None,
                announced: None,
                next_heartbeat_us: 0,
                next_timesync_us: 0,
                streams: [
                    Stream {
                        message_id: MSG_ATTITUDE_QUATERNION,
                        last_rx_us: None,
                        next_request_us: 0,
                    },
                    Stream {
                        message_id: MSG_LOCAL_POSITION_NED,
                        last_rx_us: None,
                        next_request_us: 0,
                    },
                ],
                param_cursor: None,
                next_param_us: 0,
                last_target_exposure_us: None,
                stats: CompanionStats::default(),
            },
        })
    }

    /// Feeds bytes received from the flight controller at `now_us`.
    pub fn receive(&mut self, bytes: &[u8], now_us: u64) {
        let state = &mut self.state;
        self.parser
            .push(bytes, |frame| state.handle_frame(frame, now_us));
    }

    /// Feeds one processed frame at `now_us` (after its exposure).
    pub fn on_frame(&mut self, frame: FrameResult, now_us: u64) -> FrameOutcome {
        self.state.on_frame(&frame, now_us)
    }

    /// The next frame to send, serialised into `out` (at least [`MAX_FRAME_LEN`] bytes):
    /// its length, or `None` when there is nothing to send (or `out` is too small). Also runs
    /// the periodic work (heartbeat, TIMESYNC, stream requests, parameter list pacing), so call
    /// it regularly, e.g. every few milliseconds and after every `on_frame`/`receive`.
    pub fn poll_transmit(&mut self, now_us: u64, out: &mut [u8]) -> Option<usize> {
        self.state.poll_transmit(now_us, out)
    }

    /// Queues a STATUSTEXT with `text` (cut to [`STATUS_TEXT_LEN`] bytes at a character
    /// boundary). Returns `false`, and counts an overflow, when the queue is full.
    pub fn queue_status_text(&mut self, severity: MavSeverity, text: &str) -> bool {
        self.state.queue_status_text(severity, text)
    }

    /// Counters and link state.
    pub fn stats(&self) -> CompanionStats {
        let mut s = self.state.stats;
        s.link = self.parser.stats();
        s.timesync_samples = self.state.timesync.samples();
        s.timesync_rejected = self.state.timesync.rejected();
        s.time_source = Some(self.state.timesync.source());
        s.clock_offset_us = self.state.timesync.offset_us();
        s.autopilot = self.state.autopilot;
        s
    }

    /// The current parameter values (the firmware reads the ones the companion does not use,
    /// e.g. TD_BAUD and, through [`VisionSettings::from_params`], the camera's, and exports
    /// them for flash).
    pub fn params(&self) -> &ParamSet {
        &self.state.params
    }

    /// Sets a parameter locally (as a PARAM_SET would, without a reply).
    pub fn set_param(&mut self, id: ParamId, value: f32) -> Result<(), ParamError> {
        self.state.set_param(id, value)
    }

    /// The profile in force: TD_PROFILE's forced one, or with TD_PROFILE auto the one the
    /// autopilot's HEARTBEAT asks for; `None` while auto has not identified it (no targets).
    pub fn profile(&self) -> Option<Profile> {
        self.state.profile()
    }

    /// The clock offset estimator.
    pub fn timesync(&self) -> &TimeSync {
        &self.state.timesync
    }

    /// True while the autopilot has been heard within the autopilot timeout.
    pub fn autopilot_alive(&self, now_us: u64) -> bool {
        self.state.autopilot_alive(now_us)
    }
}

impl State {
    fn profile_setting(&self) -> ProfileSetting {
        ProfileSetting::from_param(self.params.get_int(ParamId::Profile))
    }

    fn profile(&self) -> Option<Profile> {
        self.profile_setting().resolve(self.detected)
    }

    /// Announces the auto profile by STATUSTEXT when it is first known or changes, so the
    /// pilot sees which frame the targets are in; a forced profile is the user's own choice
    /// and is not announced. A pending target formatted for the previous profile is dropped
    /// (the other stack would refuse it).
    fn refresh_profile(&mut self) {
        if self.profile_setting() != ProfileSetting::Auto {
            // Back to auto later: announce again.
            self.announced = None;
            return;
        }
        if let Some(p) = self.detected {
            if self.announced != Some(p) {
                if self.announced.is_some() {
                    self.target = None;
                }
                self.announced = Some(p);
                let text = match p {
                    Profile::ArduPilot => "touchdown: profile auto: ArduPilot (BODY_FRD)",
                    Profile::Px4 => "touchdown: profile auto: PX4 (LOCAL_NED)",
                };
                self.queue_status_text(MavSeverity::MAV_SEVERITY_INFO, text);
            }
        }
    }

    fn queue_status_text(&mut self, severity: MavSeverity, text: &str) -> bool {
        let mut end = text.len().min(STATUS_TEXT_LEN);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        let mut bytes = [0u8; STATUS_TEXT_LEN];
        if let (Some(dst), Some(src)) = (bytes.get_mut(..end), text.as_bytes().get(..end)) {
            dst.copy_from_slice(src);
        }
        if self
            .status
            .push_back(StatusText {
                severity,
                text: bytes,
            })
            .is_err()
        {
            self.stats.queue_overflows = self.stats.queue_overflows.saturating_add(1);
            return false;
        }
        true
    }

    fn sysid(&self) -> u8 {
        u8::try_from(self.params.get_int(ParamId::SysId)).unwrap_or(1)
    }

    fn compid(&self) -> u8 {
        u8::try_from(self.params.get_int(ParamId::CompId)).unwrap_or(191)
    }

    fn time_base(&self) -> TimeBase {
        match TimeBase::from_param(self.params.get_int(ParamId::TimeBase)) {
            TimeBase::ByProfile => match self.profile() {
                // No profile: no target either; the autopilot clock is the contract's default.
                Some(Profile::ArduPilot) | None => TimeBase::Autopilot,
                Some(Profile::Px4) => TimeBase::Companion,
            },
            other => other,
        }
    }

    fn autopilot_alive(&self, now_us: u64) -> bool {
        self.autopilot_rx_us
            .is_some_and(|t| now_us.saturating_sub(t) <= self.config.autopilot_timeout_us)
    }

    fn set_param(&mut self, id: ParamId, value: f32) -> Result<(), ParamError> {
        let old = self.params.get(id);
        self.params.set(id, value)?;
        if id == ParamId::CamYaw && old != self.params.get(id) {
            self.mount = mount_with_yaw(&self.config.mount, self.params.get(id));
            // Measurements before and after a mount change are in different frames.
            self.level.reset();
            self.camera.reset();
        }
        if id == ParamId::Profile && old != self.params.get(id) {
            self.refresh_profile();
        }
        Ok(())
    }

    fn enqueue(&mut self, p: Pending) {
        if self.queue.push_back(p).is_err() {
            self.stats.queue_overflows = self.stats.queue_overflows.saturating_add(1);
        }
    }

    fn addressed_to_us(&self, target_system: u8, target_component: u8) -> bool {
        (target_system == 0 || target_system == self.sysid())
            && (target_component == 0 || target_component == self.compid())
    }

    fn is_from_autopilot(&self, frame: &RawFrame<'_>) -> bool {
        self.autopilot == Some((frame.system_id, frame.component_id))
    }

    /// Our-clock time of an autopilot sample stamped `time_boot_ms`, received at `now_us`.
    fn stamp(&self, time_boot_ms: u32, now_us: u64) -> u64 {
        match self.timesync.from_autopilot(u64::from(time_boot_ms) * 1000) {
            Some(t) if t.abs_diff(now_us) <= MAX_STAMP_DISAGREEMENT_US => t,
            _ => now_us,
        }
    }

    /// Checks an autopilot time stamp for a reboot (its clock going back).
    fn check_clock(&mut self, time_boot_ms: u32, now_us: u64) {
        if self
            .vehicle
            .observe_time(u64::from(time_boot_ms) * 1000, now_us)
        {
            self.on_autopilot_reboot(now_us);
        }
    }

    fn on_autopilot_reboot(&mut self, now_us: u64) {
        self.stats.autopilot_reboots = self.stats.autopilot_reboots.saturating_add(1);
        self.timesync.reset();
        self.vehicle.clear_samples();
        self.level.reset();
        self.next_timesync_us = now_us;
        for s in &mut self.streams {
            s.last_rx_us = None;
            s.next_request_us = now_us;
        }
    }

    fn handle_frame(&mut self, frame: &RawFrame<'_>, now_us: u64) {
        if frame.system_id == self.sysid() && frame.component_id == self.compid() {
            return; // our own echo (a UDP router may reflect it)
        }
        let msg = match frame.decode() {
            Ok(m) => m,
            Err(_) => {
                self.stats.decode_errors = self.stats.decode_errors.saturating_add(1);
                return;
            }
        };
        if let MavMessage::HEARTBEAT(h) = &msg {
            // The autopilot is component 1 (MAV_COMP_ID_AUTOPILOT1) of our own system (a
            // companion shares the vehicle's system id, TD_SYSID). Anything else (a MAVLink
            // gimbal or camera the flight controller forwards, often MAV_AUTOPILOT_GENERIC; a
            // ground station; another companion) must not take its place, nor choose the
            // profile.
            let is_autopilot = frame.system_id == self.sysid()
                && frame.component_id == MAV_COMP_ID_AUTOPILOT1
                && h.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID;
            if is_autopilot {
                self.autopilot = Some((frame.system_id, frame.component_id));
                self.detected = Profile::from_autopilot(h.autopilot);
                self.refresh_profile();
            }
        }
        let from_autopilot = self.is_from_autopilot(frame);
        if from_autopilot {
            self.autopilot_rx_us = Some(now_us);
        }
        let offset_before = (self.timesync.offset_us().is_some(), self.timesync.jumps());
        match msg {
            MavMessage::ATTITUDE_QUATERNION(a) if from_autopilot => {
                self.check_clock(a.time_boot_ms, now_us);
                if let Ok(att) = Attitude::from_quaternion_wxyz([a.q1, a.q2, a.q3, a.q4]) {
                    let t = self.stamp(a.time_boot_ms, now_us);
                    self.vehicle.push_attitude(t, &att, now_us);
                    self.mark_stream(MSG_ATTITUDE_QUATERNION, now_us);
                }
            }
            MavMessage::ATTITUDE(a) if from_autopilot => {
                self.check_clock(a.time_boot_ms, now_us);
                if let Ok(att) = Attitude::from_euler(a.roll, a.pitch, a.yaw) {
                    let t = self.stamp(a.time_boot_ms, now_us);
                    self.vehicle.push_attitude(t, &att, now_us);
                    // ATTITUDE serves as well as ATTITUDE_QUATERNION.
                    self.mark_stream(MSG_ATTITUDE_QUATERNION, now_us);
                }
            }
            MavMessage::LOCAL_POSITION_NED(p) if from_autopilot => {
                self.check_clock(p.time_boot_ms, now_us);
                let v = [p.x, p.y, p.z, p.vx, p.vy, p.vz];
                if v.iter().all(|c| c.is_finite()) {
                    let t = self.stamp(p.time_boot_ms, now_us);
                    let sample = PositionSample {
                        position: Vector3::new(p.x, p.y, p.z),
                        velocity: Vector3::new(p.vx, p.vy, p.vz),
                    };
                    self.vehicle.push_position(t, sample, now_us);
                    self.mark_stream(MSG_LOCAL_POSITION_NED, now_us);
                }
            }
            MavMessage::SYSTEM_TIME(s) if from_autopilot => {
                self.check_clock(s.time_boot_ms, now_us);
                self.timesync.on_system_time(s.time_boot_ms, now_us);
            }
            MavMessage::TIMESYNC(t) => {
                if t.tc1 == 0 {
                    // A request (from the autopilot, or anyone): answer with our time, ahead
                    // of everything queued (see `timesync_reply`).
                    let tc1 = i64::try_from(now_us.saturating_mul(1000)).unwrap_or(i64::MAX);
                    self.timesync_reply = Some(Pending::TimesyncResponse {
                        tc1,
                        ts1: t.ts1,
                        target: (frame.system_id, frame.component_id),
                    });
                } else if from_autopilot {
                    let ap_us = u64::try_from(t.tc1 / 1000).unwrap_or(0);
                    if self.vehicle.observe_time(ap_us, now_us) {
                        self.on_autopilot_reboot(now_us);
                    }
                    self.timesync.on_response(t.tc1, t.ts1, now_us);
                }
            }
            MavMessage::COMMAND_ACK(a) if a.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => {
                if a.result == MavResult::MAV_RESULT_ACCEPTED {
                    self.stats.interval_acks_accepted =
                        self.stats.interval_acks_accepted.saturating_add(1);
                } else {
                    self.stats.interval_acks_other =
                        self.stats.interval_acks_other.saturating_add(1);
                }
            }
            MavMessage::COMMAND_LONG(c)
                if c.target_system == self.sysid() && c.target_component == self.compid() =>
            {
                // No command is implemented: say so rather than leave the sender retrying.
                self.enqueue(Pending::CommandAck {
                    command: c.command,
                    target: (frame.system_id, frame.component_id),
                });
            }
            MavMessage::PARAM_REQUEST_LIST(r)
                if self.addressed_to_us(r.target_system, r.target_component) =>
            {
                self.param_cursor = Some(0);
                self.next_param_us = now_us;
            }
            MavMessage::PARAM_REQUEST_READ(r)
                if self.addressed_to_us(r.target_system, r.target_component) =>
            {
                let id = if r.param_index >= 0 {
                    ParamId::from_index(usize::from(r.param_index.unsigned_abs()))
                } else {
                    ParamId::from_name(params::name_str(&r.param_id[..]))
                };
                if let Some(id) = id {
                    self.enqueue(Pending::ParamValue(id));
                }
            }
            MavMessage::PARAM_SET(s)
                if self.addressed_to_us(s.target_system, s.target_component) =>
            {
                if let Some(id) = ParamId::from_name(params::name_str(&s.param_id[..])) {
                    match self.set_param(id, s.param_value) {
                        Ok(()) => {
                            self.stats.param_sets_accepted =
                                self.stats.param_sets_accepted.saturating_add(1)
                        }
                        Err(_) => {
                            self.stats.param_sets_rejected =
                                self.stats.param_sets_rejected.saturating_add(1)
                        }
                    }
                    // The new value, or the unchanged old one: the sender sees what holds.
                    self.enqueue(Pending::ParamValue(id));
                }
            }
            _ => {}
        }
        let offset_after = (self.timesync.offset_us().is_some(), self.timesync.jumps());
        if offset_before != offset_after {
            // Samples stamped with the old (or no) offset are not comparable with new ones.
            self.vehicle.clear_samples();
        }
    }

    fn mark_stream(&mut self, message_id: u32, now_us: u64) {
        if let Some(s) = self.streams.iter_mut().find(|s| s.message_id == message_id) {
            s.last_rx_us = Some(now_us);
        }
    }

    fn on_frame(&mut self, frame: &FrameResult, now_us: u64) -> FrameOutcome {
        self.stats.frames = self.stats.frames.saturating_add(1);
        let t = frame.exposure_us;
        self.level.predict_to(t);
        self.camera.predict_to(t);
        let Some(fix) = frame.fix else {
            return FrameOutcome::NoFix;
        };
        self.stats.frames_with_fix = self.stats.frames_with_fix.saturating_add(1);
        let m = Measurement {
            t_us: t,
            position: fix.pose.translation,
            covariance: fix.pad_position_covariance(),
        };
        self.camera.update(&m);
        let attitude = self.vehicle.attitude_at(t);
        if let Some(att) = &attitude {
            self.level.update(&level_measurement(&m, att, &self.mount));
        }
        let level = attitude.and_then(|att| self.level.estimate(t).map(|e| (e, att)));
        // The pad's orientation from this frame's fix (the position is filtered, the
        // orientation is this frame's: the tracker filters positions only).
        let pad_q = |att: Option<&Attitude>| {
            profile::pad_orientation(&fix.pose.rotation, &self.mount, att).unwrap_or(UNKNOWN_Q)
        };
        let fields = match self.profile() {
            None => {
                self.stats.no_profile = self.stats.no_profile.saturating_add(1);
                return FrameOutcome::NoProfile;
            }
            Some(Profile::ArduPilot) => {
                let rel_body = match &level {
                    Some((e, att)) => Some(att.ned_to_body(&e.position)),
                    None => self
                        .camera
                        .estimate(t)
                        .map(|e| self.mount.camera_to_body(&e.position)),
                };
                let Some(rel_body) = rel_body else {
                    self.stats.no_estimate = self.stats.no_estimate.saturating_add(1);
                    return FrameOutcome::NoEstimate;
                };
                // Body FRD needs no attitude: the camera is fixed to the body.
                profile::ardupilot_fields(&rel_body, pad_q(None))
            }
            Some(Profile::Px4) => {
                let (Some(att), Some(pos)) = (attitude, self.vehicle.position_at(t)) else {
                    self.stats.no_vehicle_state = self.stats.no_vehicle_state.saturating_add(1);
                    return FrameOutcome::NoVehicleState;
                };
                let Some((e, _)) = &level else {
                    self.stats.no_estimate = self.stats.no_estimate.saturating_add(1);
                    return FrameOutcome::NoEstimate;
                };
                profile::px4_fields(&pos.position, &e.position, &att, pad_q(Some(&att)))
            }
        };
        let Some(fields) = fields else {
            return FrameOutcome::Invalid;
        };
        let rate = self.params.get(ParamId::RateHz).max(1.0);
        let min_interval_us = (0.9e6 / rate) as u64;
        if self
            .last_target_exposure_us
            .is_some_and(|last| t > last && t - last < min_interval_us)
        {
            return FrameOutcome::RateLimited;
        }
        self.last_target_exposure_us = Some(t);
        let time_usec = match self.time_base() {
            TimeBase::Companion | TimeBase::ByProfile => t,
            TimeBase::Autopilot => self.timesync.to_autopilot(t).unwrap_or(t),
        };
        let data = LANDING_TARGET_DATA {
            time_usec,
            angle_x: fields.angle_x,
            angle_y: fields.angle_y,
            distance: fields.distance,
            size_x: 0.0,
            size_y: 0.0,
            target_num: 0,
            frame: match fields.frame {
                TargetFrame::BodyFrd => MavFrame::MAV_FRAME_BODY_FRD,
                TargetFrame::LocalNed => MavFrame::MAV_FRAME_LOCAL_NED,
            },
            x: fields.position.x,
            y: fields.position.y,
            z: fields.position.z,
            q: fields.q,
            mavtype: LandingTargetType::LANDING_TARGET_TYPE_VISION_FIDUCIAL,
            position_valid: MavBool::MAV_BOOL_TRUE,
        };
        if self.target.is_some() {
            self.stats.targets_replaced = self.stats.targets_replaced.saturating_add(1);
        }
        self.target = Some(PendingTarget {
            created_us: now_us,
            data,
        });
        if self.params.get_int(ParamId::VpeEnable) == 1 {
            if let Some((e, att)) = &level {
                self.vpe = Some(PendingVpe {
                    created_us: now_us,
                    data: vision_estimate(time_usec, e, att),
                });
            }
        }
        FrameOutcome::TargetQueued
    }

    /// Queues what is due at `now_us`.
    fn tick(&mut self, now_us: u64) {
        // A schedule saturated at u64::MAX is never due: otherwise a clock at the end of its
        // range would queue a frame on every poll, forever, at one instant (found by the
        // mavlink_stream fuzz target; fuzz/regressions/mavlink_stream/).
        if now_us >= self.next_heartbeat_us && self.next_heartbeat_us < u64::MAX {
            self.enqueue(Pending::Heartbeat);
            self.next_heartbeat_us = now_us.saturating_add(self.config.heartbeat_period_us);
        }
        let alive = self.autopilot_alive(now_us);
        if let (Some(target), true) = (self.autopilot, alive) {
            if now_us >= self.next_timesync_us && self.next_timesync_us < u64::MAX {
                let ts1 = self.timesync.request(now_us);
                self.enqueue(Pending::TimesyncRequest { ts1, target });
                self.next_timesync_us = now_us.saturating_add(self.config.timesync_period_us);
            }
            let wants_position = self.profile() == Some(Profile::Px4);
            let (timeout, period) = (
                self.config.stream_timeout_us,
                self.config.interval_request_period_us,
            );
            let mut requests: [Option<Pending>; 2] = [None, None];
            for (s, req) in self.streams.iter_mut().zip(requests.iter_mut()) {
                let wanted = s.message_id == MSG_ATTITUDE_QUATERNION || wants_position;
                let flowing = s
                    .last_rx_us
                    .is_some_and(|t| now_us.saturating_sub(t) <= timeout);
                if wanted && !flowing && now_us >= s.next_request_us && s.next_request_us < u64::MAX
                {
                    s.next_request_us = now_us.saturating_add(period);
                    let interval_us = if s.message_id == MSG_ATTITUDE_QUATERNION {
                        self.config.attitude_interval_us
                    } else {
                        self.config.position_interval_us
                    };
                    *req = Some(Pending::SetInterval {
                        message_id: s.message_id,
                        interval_us,
                        target,
                    });
                }
            }
            for p in requests.into_iter().flatten() {
                self.stats.interval_requests = self.stats.interval_requests.saturating_add(1);
                self.enqueue(p);
            }
        }
        if let Some(i) = self.param_cursor {
            // Leave room in the queue for everything else.
            if now_us >= self.next_param_us && self.queue.len() < TX_QUEUE_CAPACITY / 2 {
                match ParamId::from_index(i) {
                    Some(id) => {
                        self.enqueue(Pending::ParamValue(id));
                        self.param_cursor = Some(i + 1);
                        self.next_param_us =
                            now_us.saturating_add(self.config.param_stream_interval_us);
                    }
                    None => self.param_cursor = None,
                }
            }
        }
    }

    fn poll_transmit(&mut self, now_us: u64, out: &mut [u8]) -> Option<usize> {
        if out.len() < MAX_FRAME_LEN {
            return None;
        }
        self.tick(now_us);
        // TIMESYNC answers first: their round trip is what the autopilot measures.
        if let Some(p) = self.timesync_reply.take() {
            let msg = self.message(p);
            return self.emit(&msg, out);
        }
        let latency = self.config.max_target_latency_us;
        while let Some(p) = self.target.take() {
            if now_us.saturating_sub(p.created_us) > latency {
                self.stats.targets_expired = self.stats.targets_expired.saturating_add(1);
                continue;
            }
            self.stats.landing_targets = self.stats.landing_targets.saturating_add(1);
            return self.emit(&MavMessage::LANDING_TARGET(p.data), out);
        }
        if let Some(p) = self.vpe.take() {
            if now_us.saturating_sub(p.created_us) <= latency {
                self.stats.vision_estimates = self.stats.vision_estimates.saturating_add(1);
                return self.emit(&MavMessage::VISION_POSITION_ESTIMATE(p.data), out);
            }
        }
        if let Some(s) = self.status.pop_front() {
            self.stats.status_texts = self.stats.status_texts.saturating_add(1);
            let msg = MavMessage::STATUSTEXT(STATUSTEXT_DATA {
                severity: s.severity,
                text: s.text.into(),
                ..STATUSTEXT_DATA::DEFAULT
            });
            return self.emit(&msg, out);
        }
        let p = self.queue.pop_front()?;
        let msg = self.message(p);
        if let Pending::ParamValue(_) = p {
            self.stats.param_values = self.stats.param_values.saturating_add(1);
        }
        self.emit(&msg, out)
    }

    fn message(&self, p: Pending) -> MavMessage {
        match p {
            Pending::Heartbeat => MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 0,
                mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
                autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                base_mode: MavModeFlag::empty(),
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            }),
            Pending::TimesyncRequest { ts1, target } => MavMessage::TIMESYNC(TIMESYNC_DATA {
                tc1: 0,
                ts1,
                target_system: target.0,
                target_component: target.1,
            }),
            Pending::TimesyncResponse { tc1, ts1, target } => MavMessage::TIMESYNC(TIMESYNC_DATA {
                tc1,
                ts1,
                target_system: target.0,
                target_component: target.1,
            }),
            Pending::SetInterval {
                message_id,
                interval_us,
                target,
            } => MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                param1: message_id as f32,
                param2: interval_us as f32,
                command: MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                target_system: target.0,
                target_component: target.1,
                ..COMMAND_LONG_DATA::DEFAULT
            }),
            Pending::CommandAck { command, target } => MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
                command,
                result: MavResult::MAV_RESULT_UNSUPPORTED,
                target_system: target.0,
                target_component: target.1,
                ..COMMAND_ACK_DATA::DEFAULT
            }),
            Pending::ParamValue(id) => MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
                param_value: self.params.get(id),
                param_count: PARAM_COUNT as u16,
                param_index: id.index() as u16,
                param_id: id.def().name.into(),
                param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
            }),
        }
    }

    fn emit(&mut self, msg: &MavMessage, out: &mut [u8]) -> Option<usize> {
        let (seq, sys, comp) = (self.sequence, self.sysid(), self.compid());
        // Serialise through the concrete payload type. `serialize_message(&MavMessage)` would
        // link the serialiser of every message of the common dialect (~110 KB of flash in the
        // firmware) although the companion only ever sends these. Framed by
        // `link::write_v2_frame` (same bytes as `MAVLinkV2MessageRaw`, without its panic
        // paths; see nopanic/).
        let written = match msg {
            MavMessage::HEARTBEAT(d) => link::write_v2_frame(out, seq, sys, comp, d),
            MavMessage::TIMESYNC(d) => link::write_v2_frame(out, seq, sys, comp, d),
            MavMessage::COMMAND_LONG(d) => link::write_v2_frame(out, seq, sys, comp, d),
            MavMessage::COMMAND_ACK(d) => link::write_v2_frame(out, seq, sys, comp, d),
            MavMessage::PARAM_VALUE(d) => link::write_v2_frame(out, seq, sys, comp, d),
            MavMessage::LANDING_TARGET(d) => link::write_v2_frame(out, seq, sys, comp, d),
            MavMessage::VISION_POSITION_ESTIMATE(d) => link::write_v2_frame(out, seq, sys, comp, d),
            MavMessage::STATUSTEXT(d) => link::write_v2_frame(out, seq, sys, comp, d),
            _ => return None,
        };
        self.sequence = self.sequence.wrapping_add(1);
        let len = written?;
        self.stats.tx_frames = self.stats.tx_frames.saturating_add(1);
        self.stats.tx_bytes = self.stats.tx_bytes.saturating_add(len as u64);
        Some(len)
    }
}

/// VISION_POSITION_ESTIMATE: the vehicle in a pad-centred NED frame (origin at the pad, NED
/// axes), i.e. minus the pad's level position, with the vehicle's attitude; covariance upper
/// triangle (x, y, z, roll, pitch, yaw), row-major: the estimate's position covariance, the
/// attitude entries set to (0.05 rad)², since the attitude is the autopilot's own.
fn vision_estimate(
    time_usec: u64,
    e: &crate::filter::Estimate,
    att: &Attitude,
) -> VISION_POSITION_ESTIMATE_DATA {
    let [w, x, y, z] = att.quaternion_wxyz();
    let q = UnitQuaternion::new_normalize(nalgebra::Quaternion::new(w, x, y, z));
    let (roll, pitch, yaw) = q.euler_angles();
    let mut full = nalgebra::Matrix6::<f32>::zeros();
    full.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&e.position_covariance);
    for k in 3..6 {
        if let Some(v) = full.get_mut((k, k)) {
            *v = 0.05 * 0.05;
        }
    }
    let mut covariance = [0.0f32; 21];
    let mut slots = covariance.iter_mut();
    for r in 0..6 {
        for c in r..6 {
            if let (Some(slot), Some(v)) = (slots.next(), full.get((r, c))) {
                *slot = *v;
            }
        }
    }
    let p = -e.position;
    VISION_POSITION_ESTIMATE_DATA {
        usec: time_usec,
        x: p.x,
        y: p.y,
        z: p.z,
        roll,
        pitch,
        yaw,
        covariance,
        reset_counter: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn landing_target_has_extension_fields() {
        assert_eq!(
            <LANDING_TARGET_DATA as MessageData>::ENCODED_LEN,
            LANDING_TARGET_FULL_LEN
        );
    }

    #[test]
    fn heartbeat_first_and_at_one_hertz() {
        let mut c = Companion::new(CompanionConfig::default()).unwrap();
        let mut out = [0u8; MAX_FRAME_LEN];
        let mut heartbeats = 0;
        for ms in 0..3000u64 {
            while let Some(n) = c.poll_transmit(ms * 1000, &mut out) {
                // MAVLink 2, message id 0.
                assert_eq!(out[0], 0xFD);
                assert_eq!(&out[7..10], &[0, 0, 0]);
                assert!(n > 12);
                heartbeats += 1;
            }
        }
        assert_eq!(heartbeats, 3);
    }

    #[test]
    fn status_text_is_sent_once_and_cut_to_the_field() {
        let mut c = Companion::new(CompanionConfig::default()).unwrap();
        let mut out = [0u8; MAX_FRAME_LEN];
        // Drain the first heartbeat.
        while c.poll_transmit(0, &mut out).is_some() {}
        let long = "camera: no frame for 2 s, re-initialising the OV7725 sensor now";
        assert!(long.len() > STATUS_TEXT_LEN);
        assert!(c.queue_status_text(MavSeverity::MAV_SEVERITY_ERROR, long));
        let mut texts = 0;
        let mut parser = FrameParser::new();
        while let Some(n) = c.poll_transmit(1000, &mut out) {
            parser.push(&out[..n], |frame| {
                if let Ok(MavMessage::STATUSTEXT(s)) = frame.decode() {
                    assert_eq!(s.severity, MavSeverity::MAV_SEVERITY_ERROR);
                    assert_eq!(s.text.to_str().unwrap(), &long[..STATUS_TEXT_LEN]);
                    texts += 1;
                }
            });
        }
        assert_eq!(texts, 1);
        assert_eq!(c.stats().status_texts, 1);
        // A full queue refuses and counts.
        for _ in 0..STATUS_QUEUE_CAPACITY {
            assert!(c.queue_status_text(MavSeverity::MAV_SEVERITY_INFO, "x"));
        }
        assert!(!c.queue_status_text(MavSeverity::MAV_SEVERITY_INFO, "x"));
        assert_eq!(c.stats().queue_overflows, 1);
        // Multi-byte characters are never split.
        let mut c = Companion::new(CompanionConfig::default()).unwrap();
        let accents = "é".repeat(30); // 60 bytes
        assert!(c.queue_status_text(MavSeverity::MAV_SEVERITY_INFO, &accents));
        assert_eq!(c.state.status.front().unwrap().text[48..], [0xC3, 0xA9]);
    }

    fn heartbeat_from(c: &mut Companion, sys: u8, comp: u8, autopilot: MavAutopilot) {
        let mut out = [0u8; MAX_FRAME_LEN];
        let data = HEARTBEAT_DATA {
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot,
            base_mode: MavModeFlag::empty(),
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        };
        let n = link::write_v2_frame(&mut out, 0, sys, comp, &data).unwrap();
        c.receive(&out[..n], 0);
    }

    #[test]
    fn auto_profile_latches_on_the_autopilot_only() {
        let mut c = Companion::new(CompanionConfig::default()).unwrap();
        assert_eq!(c.profile(), None);
        let fix = FrameResult {
            exposure_us: 0,
            fix: Some(PadFix {
                pose: crate::pose::Pose {
                    rotation: nalgebra::Matrix3::identity(),
                    translation: Vector3::new(0.0, 0.0, 5.0),
                },
                covariance: nalgebra::Matrix6::identity() * 1e-4,
                markers_used: 1,
                reprojection_rms_px: 0.3,
                alternative_rms_px: f32::INFINITY,
            }),
        };
        assert_eq!(c.on_frame(fix, 1000), FrameOutcome::NoProfile);
        assert_eq!(c.stats().no_profile, 1);
        // A gimbal (component 154), another system's autopilot: ignored.
        heartbeat_from(&mut c, 1, 154, MavAutopilot::MAV_AUTOPILOT_GENERIC);
        heartbeat_from(&mut c, 2, 1, MavAutopilot::MAV_AUTOPILOT_PX4);
        assert_eq!((c.profile(), c.stats().autopilot), (None, None));
        heartbeat_from(&mut c, 1, 1, MavAutopilot::MAV_AUTOPILOT_PX4);
        assert_eq!(c.profile(), Some(Profile::Px4));
        assert_eq!(c.stats().autopilot, Some((1, 1)));
        heartbeat_from(&mut c, 1, 154, MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
        assert_eq!(c.profile(), Some(Profile::Px4));
        // Announced once; again when the autopilot changes.
        heartbeat_from(&mut c, 1, 1, MavAutopilot::MAV_AUTOPILOT_PX4);
        assert_eq!(c.state.status.len(), 1);
        heartbeat_from(&mut c, 1, 1, MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
        assert_eq!(c.profile(), Some(Profile::ArduPilot));
        assert_eq!(c.state.status.len(), 2);
        // A forced profile wins.
        c.set_param(ParamId::Profile, 1.0).unwrap();
        assert_eq!(c.profile(), Some(Profile::Px4));
    }

    #[test]
    fn footprint_is_small() {
        // The firmware keeps one in static RAM: stay well under 8 KiB.
        let size = core::mem::size_of::<Companion>();
        assert!(size < 8192, "{size} bytes");
    }
}
