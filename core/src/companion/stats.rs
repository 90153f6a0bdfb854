//! What the companion counts, for logs and reports, and what became of each frame's target.

use super::framing::ParserStats;
use super::timesync::TimeSource;

/// What [`super::Companion::on_estimate`] did with a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TargetOutcome {
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
    /// Frames handed to [`super::Companion::poll_transmit`]'s caller.
    pub tx_frames: u32,
    /// Bytes handed out.
    pub tx_bytes: u64,
    /// LANDING_TARGETs sent.
    pub landing_targets: u32,
    /// VISION_POSITION_ESTIMATEs sent.
    pub vision_estimates: u32,
    /// Times the VISION_POSITION_ESTIMATE's reset counter stepped (the stream resumed after a
    /// gap: a new track).
    pub vision_resets: u32,
    /// The VISION_POSITION_ESTIMATE is fit to navigate on (see `companion::vision`).
    pub vision_fit: bool,
    /// VISION_POSITION_ESTIMATEs held back: the autopilot disarmed and the position not fit
    /// to take off on (see `companion::vision`).
    pub vision_held: u32,
    /// Velocities sent (ODOMETRY or VISION_SPEED_ESTIMATE, TD_VPE_EN bit 1).
    pub vision_velocities: u32,
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
    /// TIMESYNC requests answered (sent): PX4 uses the board's time stamps only after some
    /// hundreds of them (docs/setup-px4.md).
    pub timesync_answers: u32,
    /// Where the clock offset comes from.
    pub time_source: Option<TimeSource>,
    /// Autopilot minus companion clock, µs.
    pub clock_offset_us: Option<i64>,
    /// The autopilot's (system, component) id, once heard.
    pub autopilot: Option<(u8, u8)>,
    /// Delay from each sent target's exposure to its hand-out for sending.
    pub target_latency: TargetLatency,
    /// Mount corrections received with the estimates (reported by STATUSTEXT).
    pub mount_corrections: u32,
    /// Of those, set into TD_CAM_ROLL/TD_CAM_PITCH (TD_CAM_CAL = 2, in range).
    pub mount_corrections_applied: u32,
    /// Times TD_PAD_MOTION auto decided that the pad moves or stands still again (each
    /// announced by STATUSTEXT).
    pub pad_motion_changes: u32,
    /// Frames received with a valid signature under our key.
    pub signed_frames: u32,
    /// Signed frames whose signature did not match our key (treated as unsigned).
    pub bad_signatures: u32,
    /// Frames signed with our key but not newer than their stream's last (replays; treated
    /// as unsigned).
    pub replayed_frames: u32,
    /// Writes (PARAM_SET, SETUP_SIGNING, COMMAND_LONG) refused for want of a valid signature.
    pub writes_refused_unsigned: u32,
    /// Writes refused by the flight lock (TD_LOCK) while armed.
    pub writes_refused_locked: u32,
    /// SETUP_SIGNING messages applied (a key set, changed or cleared).
    pub signing_setups: u32,
}

/// Delay from a frame's exposure to the moment its LANDING_TARGET is handed to the link for
/// sending (our clock), over every target sent. It is what the autopilot's own lag setting
/// must cover (ArduPilot's PLND_LAG: the attitude and position it pairs the target with are
/// its own from that long ago), plus the frame's transfer time on the UART (a LANDING_TARGET
/// frame is 72 bytes: 0.8 ms at 921,600 baud, 12.5 ms at 57,600).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TargetLatency {
    /// Targets measured.
    pub count: u32,
    /// Sum of their delays, µs (saturating).
    pub sum_us: u64,
    /// The longest delay, µs.
    pub max_us: u32,
    /// The last target's delay, µs.
    pub last_us: u32,
}

impl TargetLatency {
    /// Adds one target's delay.
    pub(super) fn record(&mut self, delay_us: u64) {
        let us = u32::try_from(delay_us).unwrap_or(u32::MAX);
        self.count = self.count.saturating_add(1);
        self.sum_us = self.sum_us.saturating_add(u64::from(us));
        self.max_us = self.max_us.max(us);
        self.last_us = us;
    }

    /// The mean delay, µs; `None` before the first target.
    pub fn mean_us(&self) -> Option<u32> {
        let mean = self.sum_us.checked_div(u64::from(self.count))?;
        Some(u32::try_from(mean).unwrap_or(u32::MAX))
    }
}
