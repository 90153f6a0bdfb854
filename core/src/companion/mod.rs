//! The companion: the MAVLink side of the landing aid, as a sans-IO state machine.
//!
//! What this module offers: [`Companion`] (configured by [`CompanionConfig`]), which takes each
//! frame's estimate from [`crate::filter`] and the bytes the autopilot sends, and hands out the
//! MAVLink frames to transmit; what it counts and decides, [`CompanionStats`] and
//! [`TargetOutcome`]; the message format per autopilot, [`Profile`]; the clock relation,
//! [`TimeSync`]; and the byte-stream parser, [`FrameParser`], for tools that read MAVLink
//! themselves. [`mavlink`] is the MAVLink crate itself, re-exported as a namespace of message
//! types (not a stage) so that callers build and match messages with the very version and
//! dialect the companion speaks.
//!
//! The board sits on a UART to the flight controller (ArduPilot or PX4). [`Companion`] owns
//! everything between "a frame was estimated" and "these bytes go on the wire", and nothing
//! that touches hardware, the detector or the sensor: the caller feeds it
//!
//! - received bytes, [`Companion::receive`] (any chunking; garbage and broken frames are
//!   survived, see [`FrameParser`]),
//! - each frame's estimate, [`Companion::on_estimate`] (what
//!   [`crate::pipeline::FramePipeline::process`] returns, read with this companion's
//!   [`Companion::vehicle`] state),
//! - the time, as a `now_us` argument on every call (our boot clock, µs, monotonic),
//!
//! and drains [`Companion::poll_transmit`], one serialised MAVLink 2 frame per call, whenever
//! the UART can take more. The firmware's UART task and the host's `touchdown companion`
//! (UDP, serial) run the very same code; the host tests drive it with a simulated autopilot and
//! check every byte with pymavlink.
//!
//! The module is split by concern, in private submodules: `framing` (the byte stream),
//! `receive` (what each incoming message does), `mount` (adopting a mount correction),
//! `target` (an estimate to a LANDING_TARGET,
//! `profile` for the two formats), `transmit` (scheduling and serialising), `timesync` (the
//! autopilot's clock); the parameter table is [`crate::params`], the estimator
//! [`crate::filter::PadEstimator`].
//!
//! # What it sends
//!
//! - HEARTBEAT at 1 Hz (`MAV_TYPE_ONBOARD_CONTROLLER`, `MAV_AUTOPILOT_INVALID`).
//! - LANDING_TARGET for every frame that has a pad fix and a fresh estimate, in the
//!   ArduPilot or PX4 format ([`Profile`]), MAVLink 2 with the extension fields. Never a stale
//!   one: only frames *with* a fix produce a target (a frame without one produces nothing, so
//!   the flight controller's own timeout sees the pad disappear), the estimator must have a
//!   confirmed estimate at that frame's exposure time whose last measurement is fresh
//!   ([`crate::filter::TrackerConfig::max_coast_us`]), and a target not transmitted within
//!   [`CompanionConfig::max_target_latency_us`] of its frame is dropped, not sent late. A newer
//!   target replaces an unsent older one. The format follows TD_PROFILE; with TD_PROFILE auto
//!   (the default) the autopilot's HEARTBEAT chooses it and, until one has been heard, no
//!   target is sent ([`TargetOutcome::NoProfile`]); the choice is announced by STATUSTEXT.
//!
//! The autopilot is the sender of HEARTBEATs from our system id (TD_SYSID) and component 1
//! whose `autopilot` is not MAV_AUTOPILOT_INVALID; the vehicle state, TIMESYNC answers and
//! the profile come from it alone.
//! - VISION_POSITION_ESTIMATE (optional, TD_VPE_EN bit 0): the vehicle in a pad-centred NED
//!   frame, with covariance.
//! - The vehicle's velocity over the ground (optional, TD_VPE_EN bit 1), from the pad's
//!   velocity against the vehicle (a pad that does not move): ODOMETRY with the velocity alone
//!   under the PX4 profile (EKF2 fuses it beside GPS, so that its velocity, and with it the
//!   position controller's hold, no longer wander with GPS noise near the pad),
//!   VISION_SPEED_ESTIMATE under the ArduPilot profiles.
//! - TIMESYNC requests (1 Hz) and answers to the autopilot's requests ([`TimeSync`]), the
//!   answers ahead of everything else waiting (PX4 discards round trips of 10 ms or more).
//! - COMMAND_LONG `MAV_CMD_SET_MESSAGE_INTERVAL` for the vehicle state it needs
//!   (ATTITUDE_QUATERNION; LOCAL_POSITION_NED too for PX4), and for any stream a host tool
//!   adds with [`Companion::request_stream`] (`touchdown sitl` asks a SITL for its ground
//!   truth this way), repeated every second while that stream is not arriving, so a
//!   rebooted autopilot gets asked again. Every frame goes out in the companion's one
//!   sequence: a second sender with the same ids would look like lost frames to the
//!   autopilot's link statistics.
//! - PARAM_VALUE for the parameter protocol ([`crate::params`]); a full list is paced at one
//!   PARAM_VALUE per [`CompanionConfig::param_stream_interval_us`].
//! - STATUSTEXT when the firmware reports a fault ([`Companion::queue_status_text`]: camera
//!   lost, parameters reset), which ground stations show to the pilot, and when the
//!   estimator's mount calibration reports a correction.
//!
//! # Mount calibration
//!
//! A frame's estimate may carry a [`crate::filter::MountCorrection`] (the estimator's in-flight
//! calibration of the camera mount's roll and pitch became confident, or moved
//! significantly). [`Companion::on_estimate`] adopts it itself: with TD_CAM_CAL = 2 it sets
//! TD_CAM_ROLL and TD_CAM_PITCH through the normal parameter path (announced by PARAM_VALUE,
//! saved to flash by the firmware like a ground station's PARAM_SET) and says so by
//! STATUSTEXT; with TD_CAM_CAL = 1 it only says so. The new mount reaches the per-frame path
//! the way every parameter does: the caller converts [`Companion::params`] with
//! [`crate::params::PipelineSettings::from_params`] and, when that changed, applies it
//! ([`crate::pipeline::FramePipeline::apply`]).
//!
//! # Vehicle state
//!
//! ATTITUDE_QUATERNION (or ATTITUDE) and LOCAL_POSITION_NED from the autopilot are stamped
//! into our clock and kept in [`Companion::vehicle`], a short history the estimator reads at
//! each frame's exposure. ArduPilot profile: body FRD from the level estimate, or with no
//! attitude (autopilot silent, or not streaming it) from the camera-frame estimate through
//! the mount; ArduPilot does not need our vehicle state, so targets keep flowing when the
//! autopilot's messages stop (decided: a silent *telemetry* direction does not mean the
//! autopilot cannot hear us). PX4 profile: only with attitude and LOCAL_POSITION_NED at the
//! exposure, so when the autopilot goes silent targets stop within the vehicle state's
//! extrapolation limit ([`crate::filter::VehicleState`]) and resume with its first samples.
//!
//! # Time
//!
//! `time_usec` ([`TimeBase`]): ArduPilot gets the exposure time in the autopilot's clock
//! (TIMESYNC, else SYSTEM_TIME, else our boot time). PX4 gets our boot time, because PX4
//! itself converts `time_usec` with its TIMESYNC estimate of our clock (we answer its
//! requests). An autopilot reboot (its clock going back by more than a second) resets the
//! offset and the vehicle state (whose reboot count restarts the estimator's level track), and
//! triggers a new TIMESYNC and new message-interval requests at once.

mod bearing;
mod framing;
mod guard;
mod mount;
mod pad_motion;
mod profile;
mod receive;
mod shift;
mod signing;
mod state;
mod stats;
mod target;
mod timesync;
mod transmit;
mod velocity;
mod vision;

pub use mavlink;

pub use framing::{FrameParser, ParserStats, RawFrame, Signature, MAX_FRAME_LEN};
pub use guard::REFUSAL_TEXT_PERIOD_US;
pub use mavlink::dialects::common::MavSeverity;
pub use pad_motion::PadMotionSetting;
pub use profile::{Profile, ProfileSetting};
pub use shift::{px4_mode_lands_on_target, PadShift, ShiftConfig, ShiftMeasurement};
pub use signing::{Authenticity, MAX_SIGNING_STREAMS, NEW_STREAM_WINDOW};
pub use stats::{CompanionStats, TargetLatency, TargetOutcome};
pub use timesync::{TimeSource, TimeSync};
pub use vision::{mount_known_for_take_off, TAKE_OFF_MOUNT_SIGMA_DEG};

use crate::filter::{FrameEstimate, VehicleState};
use crate::params::{ParamError, ParamId, ParamSet, SigningSecret};
use heapless::Deque;
use mavlink::dialects::common::{
    MavCmd, MavResult, LANDING_TARGET_DATA, ODOMETRY_DATA, VISION_POSITION_ESTIMATE_DATA,
    VISION_SPEED_ESTIMATE_DATA,
};
use mavlink::MessageData;

/// LANDING_TARGET's payload with every MAVLink 2 extension field. If the mavlink crate is ever
/// generated without extensions (see core/Cargo.toml), this stops compiling.
pub const LANDING_TARGET_FULL_LEN: usize = 60;
const _: () = assert!(
    <LANDING_TARGET_DATA as MessageData>::ENCODED_LEN == LANDING_TARGET_FULL_LEN,
    "mavlink was generated without MAVLink 2 extension fields"
);

/// Capacity of the transmit queue (heartbeat, TIMESYNC, commands, PARAM_VALUE).
pub const TX_QUEUE_CAPACITY: usize = 16;
/// How many message streams the companion keeps asking for: its own two (attitude, local
/// position) and room for a host tool's ([`Companion::request_stream`]).
pub const MAX_STREAMS: usize = 6;
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
    pub(crate) fn from_param(v: i32) -> TimeBase {
        match v {
            1 => TimeBase::Autopilot,
            2 => TimeBase::Companion,
            _ => TimeBase::ByProfile,
        }
    }
}

/// Everything that is fixed at start-up (the tunable part is [`ParamSet`]; the camera mount
/// and the trackers are the estimator's, [`crate::filter::EstimatorConfig`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompanionConfig {
    /// Initial parameter values: defaults, or imported from flash.
    pub params: ParamSet,
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
    /// The PX4 profile's outer loop (TD_PX4_OL_ALT; [`ShiftConfig`]).
    pub px4_shift: ShiftConfig,
}

impl Default for CompanionConfig {
    fn default() -> Self {
        CompanionConfig {
            params: ParamSet::default(),
            heartbeat_period_us: 1_000_000,
            timesync_period_us: 1_000_000,
            interval_request_period_us: 1_000_000,
            stream_timeout_us: 1_000_000,
            attitude_interval_us: 20_000,
            position_interval_us: 33_333,
            param_stream_interval_us: 20_000,
            max_target_latency_us: 100_000,
            autopilot_timeout_us: 3_000_000,
            px4_shift: ShiftConfig::default(),
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
        result: MavResult,
        target: (u8, u8),
    },
    ParamValue(ParamId),
    /// SYS_STATUS, with the vision position's health (TD_VPE_EN bit 0, `vision`).
    SysStatus,
    /// NAMED_VALUE_FLOAT: `TD_VIEW`, the view margin, metres (`vision`); `TD_PAD_BRG`, the
    /// pad's bearing, degrees (`bearing`).
    NamedValue {
        name: &'static str,
        time_boot_ms: u32,
        value: f32,
    },
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
    /// The frame's exposure (our clock), for the exposure-to-send delay.
    exposure_us: u64,
    data: LANDING_TARGET_DATA,
}

#[derive(Debug, Clone, PartialEq)]
struct PendingVpe {
    created_us: u64,
    data: VISION_POSITION_ESTIMATE_DATA,
}

/// The vehicle's velocity, in the message the profile's autopilot fuses.
#[derive(Debug, Clone, PartialEq)]
enum VelocityMessage {
    /// PX4: ODOMETRY with the velocity alone (position and attitude NaN).
    Odometry(ODOMETRY_DATA),
    /// ArduPilot: VISION_SPEED_ESTIMATE.
    Speed(VISION_SPEED_ESTIMATE_DATA),
}

#[derive(Debug, Clone, PartialEq)]
struct PendingVelocity {
    created_us: u64,
    message: VelocityMessage,
}

/// A message stream we ask the autopilot for, and ask again while it is not arriving.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Stream {
    message_id: u32,
    /// The interval asked for, µs.
    interval_us: u32,
    /// Asked for under the PX4 profile, or under any with TD_PAD_MOTION auto
    /// (LOCAL_POSITION_NED: ArduPilot's targets need none of our vehicle position, the
    /// pad's velocity over the ground does).
    position: bool,
    last_rx_us: Option<u64>,
    next_request_us: u64,
}

impl Stream {
    fn new(message_id: u32, interval_us: u32, position: bool) -> Stream {
        Stream {
            message_id,
            interval_us,
            position,
            last_rx_us: None,
            next_request_us: 0,
        }
    }
}

/// Why [`Companion::request_stream`] refused a stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StreamError {
    /// [`MAX_STREAMS`] streams are asked for already.
    Full,
    /// An interval of 0 asks the autopilot for its default rate and -1 stops the stream:
    /// neither is a rate to keep asking for.
    ZeroInterval,
}

/// Everything but the receive parser (so the parser can call into it).
#[derive(Debug, Clone)]
struct State {
    config: CompanionConfig,
    params: ParamSet,
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
    /// The vision estimate's reset counter and fit state (TD_VPE_EN bit 0).
    vision: vision::VisionState,
    /// The turn that holds the vision estimate's frame to the pad (TD_PAD_YAW).
    pad_bearing: bearing::PadBearing,
    velocity: Option<PendingVelocity>,
    /// The slope of the level positions, for the velocity (TD_VPE_EN bit 1).
    velocity_fit: velocity::VelocityFit,
    sequence: u8,
    autopilot: Option<(u8, u8)>,
    autopilot_rx_us: Option<u64>,
    /// The profile the latched autopilot's HEARTBEAT asks for (TD_PROFILE auto).
    detected: Option<Profile>,
    /// The latched autopilot's mode from its HEARTBEAT: custom mode enabled, `custom_mode`.
    autopilot_mode: Option<(bool, u32)>,
    /// The latched autopilot's last HEARTBEAT said it is armed (false until one has).
    autopilot_armed: bool,
    /// The PX4 profile's outer loop.
    shift: PadShift,
    /// Whether the pad moves, as TD_PAD_MOTION auto decides it.
    pad_motion: pad_motion::PadMotionWatch,
    /// The auto profile last announced by STATUSTEXT.
    announced: Option<Profile>,
    /// MAVLink signing: our timestamp and the senders' (the key is in `params`).
    signing: signing::Signing,
    /// The next refused write may be said by STATUSTEXT from then on (`guard`).
    next_refusal_text_us: u64,
    next_heartbeat_us: u64,
    next_timesync_us: u64,
    streams: heapless::Vec<Stream, MAX_STREAMS>,
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

/// The vehicle-state streams every companion asks for.
fn own_streams(config: &CompanionConfig) -> heapless::Vec<Stream, MAX_STREAMS> {
    let mut streams = heapless::Vec::new();
    // Two of MAX_STREAMS: neither push can fail (and a failed one would only leave a stream
    // unrequested, not panic).
    let _ = streams.push(Stream::new(
        MSG_ATTITUDE_QUATERNION,
        config.attitude_interval_us,
        false,
    ));
    let _ = streams.push(Stream::new(
        MSG_LOCAL_POSITION_NED,
        config.position_interval_us,
        true,
    ));
    streams
}

impl Companion {
    /// A companion that has heard nothing yet.
    pub fn new(config: CompanionConfig) -> Self {
        let params = config.params;
        Companion {
            parser: FrameParser::new(),
            state: State {
                config,
                params,
                vehicle: VehicleState::new(),
                timesync: TimeSync::new(),
                queue: Deque::new(),
                timesync_reply: None,
                status: Deque::new(),
                target: None,
                vpe: None,
                vision: vision::VisionState::default(),
                pad_bearing: bearing::PadBearing::default(),
                velocity: None,
                velocity_fit: velocity::VelocityFit::new(),
                sequence: 0,
                autopilot: None,
                autopilot_rx_us: None,
                detected: None,
                autopilot_mode: None,
                autopilot_armed: false,
                shift: PadShift::new(),
                pad_motion: pad_motion::PadMotionWatch::default(),
                announced: None,
                signing: signing::Signing::new(params.signing_secret().timestamp(), 0),
                next_refusal_text_us: 0,
                next_heartbeat_us: 0,
                next_timesync_us: 0,
                streams: own_streams(&config),
                param_cursor: None,
                next_param_us: 0,
                last_target_exposure_us: None,
                stats: CompanionStats::default(),
            },
        }
    }

    /// Feeds bytes received from the flight controller at `now_us`.
    pub fn receive(&mut self, bytes: &[u8], now_us: u64) {
        let state = &mut self.state;
        self.parser
            .push(bytes, |frame| state.handle_frame(frame, now_us));
    }

    /// Feeds one frame's estimate at `now_us` (after its exposure): queues its LANDING_TARGET
    /// when there is one to send (see the module docs).
    pub fn on_estimate(&mut self, frame: &FrameEstimate, now_us: u64) -> TargetOutcome {
        self.state.on_estimate(frame, now_us)
    }

    /// The next frame to send, serialised into `out` (at least [`MAX_FRAME_LEN`] bytes):
    /// its length, or `None` when there is nothing to send (or `out` is too small). Also runs
    /// the periodic work (heartbeat, TIMESYNC, stream requests, parameter list pacing), so call
    /// it regularly, e.g. every few milliseconds and after every `on_estimate`/`receive`.
    pub fn poll_transmit(&mut self, now_us: u64, out: &mut [u8]) -> Option<usize> {
        self.state.poll_transmit(now_us, out)
    }

    /// Asks the autopilot for message `message_id` every `interval_us` (µs) from now on, the
    /// way the companion asks for its own vehicle state: a SET_MESSAGE_INTERVAL to the
    /// latched autopilot, sent again every [`CompanionConfig::interval_request_period_us`]
    /// while no such message has come from it within [`CompanionConfig::stream_timeout_us`]
    /// (also when the autopilot reboots). Any frame with that id from the autopilot counts,
    /// decoded or not (a dialect message the common set does not know still proves the
    /// stream). A message asked for already at another interval is asked for again at once
    /// with the new one; at the same interval, nothing changes.
    pub fn request_stream(&mut self, message_id: u32, interval_us: u32) -> Result<(), StreamError> {
        self.state.request_stream(message_id, interval_us)
    }

    /// Queues a STATUSTEXT with `text` (cut to [`STATUS_TEXT_LEN`] bytes at a character
    /// boundary). Returns `false`, and counts an overflow, when the queue is full.
    pub fn queue_status_text(&mut self, severity: MavSeverity, text: &str) -> bool {
        self.state.queue_status_text(severity, text)
    }

    /// Bytes the receive parser holds: the start of a frame still arriving (or of a false
    /// start whose announced length has not arrived). 0 once everything received so far has
    /// been handled.
    pub fn receive_buffered(&self) -> usize {
        self.parser.buffered()
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
        s.vision_fit = self.state.vision_fit();
        s
    }

    /// The current parameter values (the firmware reads the ones the companion does not use,
    /// e.g. TD_BAUD and, through [`crate::params::PipelineSettings::from_params`], the
    /// pipeline's, and exports them for flash).
    pub fn params(&self) -> &ParamSet {
        &self.state.params
    }

    /// Sets a parameter locally (as a PARAM_SET would, without a reply, and without the
    /// signing check or the flight lock: this is the caller's own process, not the link).
    pub fn set_param(&mut self, id: ParamId, value: f32) -> Result<(), ParamError> {
        self.state.set_param(id, value)
    }

    /// Sets the signing key locally (as an accepted SETUP_SIGNING would, without its
    /// checks): a host tool that holds the owner's key signs with it and checks by it.
    /// [`SigningSecret::NONE`] turns signing off.
    pub fn set_signing_secret(&mut self, secret: SigningSecret, now_us: u64) {
        self.state.set_signing_secret(secret, now_us);
    }

    /// Whether the flight lock holds: TD_LOCK 1 and the latched autopilot's last HEARTBEAT
    /// said armed (parameters but TD_LOCK, and the key, refuse writes from the link).
    pub fn flight_locked(&self) -> bool {
        self.state.flight_locked()
    }

    /// Whether a signing key is set: writes then need signed frames, and every frame sent is
    /// signed.
    pub fn signing(&self) -> bool {
        self.state.params.signing_secret().is_set()
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

    /// The vehicle state the autopilot has streamed (attitude and local position histories, in
    /// our clock): what the estimator reads each frame at its exposure.
    pub fn vehicle(&self) -> &VehicleState {
        &self.state.vehicle
    }

    /// The PX4 profile's outer loop: the shift (north, east, metres) added to the LOCAL_NED
    /// point now (zero when off, inactive or under another profile).
    pub fn px4_shift(&self) -> nalgebra::Vector2<f32> {
        self.state.shift.shift()
    }

    /// Whether the board takes the pad as moving: TD_PAD_MOTION 1, or 2 (auto) once it has
    /// decided so ([`PadMotionSetting`]).
    pub fn pad_moving(&self) -> bool {
        self.state.pad_moving()
    }

    /// The pad's velocity over the ground (north, east, m/s), low-passed, as TD_PAD_MOTION
    /// auto judges it; `None` before a frame had both the level estimate and the vehicle's
    /// velocity.
    pub fn pad_velocity_ne(&self) -> Option<nalgebra::Vector2<f32>> {
        self.state.pad_motion.velocity_ne()
    }

    /// True while the autopilot has been heard within the autopilot timeout.
    pub fn autopilot_alive(&self, now_us: u64) -> bool {
        self.state.autopilot_alive(now_us)
    }
}

#[cfg(test)]
mod tests;
