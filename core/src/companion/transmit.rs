//! What the companion sends and when: the periodic messages (HEARTBEAT, TIMESYNC requests,
//! stream requests while a stream is missing, its own or a host tool's, a paced parameter
//! list), and the order of the transmit queue: TIMESYNC answers first, then the newest
//! LANDING_TARGET (dropped when older than
//! [`super::CompanionConfig::max_target_latency_us`]), VISION_POSITION_ESTIMATE, the velocity
//! (ODOMETRY or VISION_SPEED_ESTIMATE), STATUSTEXT, and the rest in order.
//!
//! Frames are serialised here, one per call, into the caller's buffer.

use core::fmt::Write;

use super::framing;
use super::pad_motion::PadMotionSetting;
use super::profile::Profile;
use super::{
    Pending, State, Stream, StreamError, VelocityMessage, MAX_FRAME_LEN, STATUS_TEXT_LEN,
    TX_QUEUE_CAPACITY,
};
use crate::params::{ParamId, PARAM_COUNT};
use mavlink::dialects::common::{
    MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavParamType, MavSeverity, MavState,
    MavSysStatusSensor, MavSysStatusSensorExtended, MavType, COMMAND_ACK_DATA, COMMAND_LONG_DATA,
    HEARTBEAT_DATA, NAMED_VALUE_FLOAT_DATA, PARAM_VALUE_DATA, STATUSTEXT_DATA, SYS_STATUS_DATA,
    TIMESYNC_DATA,
};

/// Targets sent before the first report of their exposure-to-send delay; the report repeats
/// each time the count doubles.
const LATENCY_REPORT_FIRST: u32 = 100;

impl State {
    /// Queues what is due at `now_us`.
    fn tick(&mut self, now_us: u64) {
        // A schedule saturated at u64::MAX is never due: otherwise a clock at the end of its
        // range would queue a frame on every poll, forever, at one instant (found by the
        // mavlink_stream fuzz target; fuzz/regressions/mavlink_stream/).
        if now_us >= self.next_heartbeat_us && self.next_heartbeat_us < u64::MAX {
            self.enqueue(Pending::Heartbeat);
            if self.params.get_int(ParamId::VpeEnable) & crate::params::VPE_POSITION != 0 {
                self.enqueue(Pending::SysStatus);
            }
            self.next_heartbeat_us = now_us.saturating_add(self.config.heartbeat_period_us);
        }
        let alive = self.autopilot_alive(now_us);
        if let (Some(target), true) = (self.autopilot, alive) {
            if now_us >= self.next_timesync_us && self.next_timesync_us < u64::MAX {
                let ts1 = self.timesync.request(now_us);
                self.enqueue(Pending::TimesyncRequest { ts1, target });
                self.next_timesync_us = now_us.saturating_add(self.config.timesync_period_us);
            }
            let position = self.profile() == Some(Profile::Px4)
                || self.pad_motion_setting() == PadMotionSetting::Auto;
            let (timeout, period) = (
                self.config.stream_timeout_us,
                self.config.interval_request_period_us,
            );
            for i in 0..self.streams.len() {
                let Some(s) = self.streams.get_mut(i) else {
                    break;
                };
                let flowing = s
                    .last_rx_us
                    .is_some_and(|t| now_us.saturating_sub(t) <= timeout);
                let due = now_us >= s.next_request_us && s.next_request_us < u64::MAX;
                if (s.position && !position) || flowing || !due {
                    continue;
                }
                s.next_request_us = now_us.saturating_add(period);
                let (message_id, interval_us) = (s.message_id, s.interval_us);
                self.stats.interval_requests = self.stats.interval_requests.saturating_add(1);
                self.enqueue(Pending::SetInterval {
                    message_id,
                    interval_us,
                    target,
                });
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

    /// See [`super::Companion::request_stream`].
    pub(super) fn request_stream(
        &mut self,
        message_id: u32,
        interval_us: u32,
    ) -> Result<(), StreamError> {
        if interval_us == 0 {
            return Err(StreamError::ZeroInterval);
        }
        if let Some(s) = self.streams.iter_mut().find(|s| s.message_id == message_id) {
            if s.interval_us != interval_us {
                // A changed rate is asked for at once, flowing or not.
                s.interval_us = interval_us;
                s.last_rx_us = None;
                s.next_request_us = 0;
            }
            return Ok(());
        }
        self.streams
            .push(Stream::new(message_id, interval_us, false))
            .map_err(|_| StreamError::Full)
    }

    pub(super) fn poll_transmit(&mut self, now_us: u64, out: &mut [u8]) -> Option<usize> {
        if out.len() < MAX_FRAME_LEN {
            return None;
        }
        self.tick(now_us);
        // TIMESYNC answers first: their round trip is what the autopilot measures.
        if let Some(p) = self.timesync_reply.take() {
            self.stats.timesync_answers = self.stats.timesync_answers.saturating_add(1);
            let msg = self.message(p);
            return self.emit(now_us, &msg, out);
        }
        let latency = self.config.max_target_latency_us;
        while let Some(p) = self.target.take() {
            if now_us.saturating_sub(p.created_us) > latency {
                self.stats.targets_expired = self.stats.targets_expired.saturating_add(1);
                continue;
            }
            self.stats.landing_targets = self.stats.landing_targets.saturating_add(1);
            self.record_target_latency(now_us.saturating_sub(p.exposure_us));
            return self.emit(now_us, &MavMessage::LANDING_TARGET(p.data), out);
        }
        if let Some(p) = self.vpe.take() {
            if now_us.saturating_sub(p.created_us) <= latency {
                self.stats.vision_estimates = self.stats.vision_estimates.saturating_add(1);
                return self.emit(now_us, &MavMessage::VISION_POSITION_ESTIMATE(p.data), out);
            }
        }
        if let Some(p) = self.velocity.take() {
            if now_us.saturating_sub(p.created_us) <= latency {
                self.stats.vision_velocities = self.stats.vision_velocities.saturating_add(1);
                let msg = match p.message {
                    VelocityMessage::Odometry(d) => MavMessage::ODOMETRY(d),
                    VelocityMessage::Speed(d) => MavMessage::VISION_SPEED_ESTIMATE(d),
                };
                return self.emit(now_us, &msg, out);
            }
        }
        if let Some(s) = self.status.pop_front() {
            self.stats.status_texts = self.stats.status_texts.saturating_add(1);
            let msg = MavMessage::STATUSTEXT(STATUSTEXT_DATA {
                severity: s.severity,
                text: s.text.into(),
                ..STATUSTEXT_DATA::DEFAULT
            });
            return self.emit(now_us, &msg, out);
        }
        let p = self.queue.pop_front()?;
        let msg = self.message(p);
        if let Pending::ParamValue(_) = p {
            self.stats.param_values = self.stats.param_values.saturating_add(1);
        }
        self.emit(now_us, &msg, out)
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
            Pending::SysStatus => {
                let vision = MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_VISION_POSITION;
                MavMessage::SYS_STATUS(SYS_STATUS_DATA {
                    onboard_control_sensors_present: vision,
                    onboard_control_sensors_enabled: vision,
                    onboard_control_sensors_health: if self.vision_fit() {
                        vision
                    } else {
                        MavSysStatusSensor::empty()
                    },
                    // The generated default of a bitflags field is its first flag, not
                    // none.
                    onboard_control_sensors_present_extended: MavSysStatusSensorExtended::empty(),
                    onboard_control_sensors_enabled_extended: MavSysStatusSensorExtended::empty(),
                    onboard_control_sensors_health_extended: MavSysStatusSensorExtended::empty(),
                    // No battery: MAVLink's "unknown" values.
                    voltage_battery: u16::MAX,
                    current_battery: -1,
                    battery_remaining: -1,
                    ..SYS_STATUS_DATA::DEFAULT
                })
            }
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
            Pending::CommandAck {
                command,
                result,
                target,
            } => MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
                command,
                result,
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
            Pending::NamedValue {
                name,
                time_boot_ms,
                value,
            } => MavMessage::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
                time_boot_ms,
                value,
                name: name.into(),
            }),
        }
    }

    /// Counts a sent target's exposure-to-send delay and tells the ground station the
    /// figures after 100 targets and then each time the count doubles (a few times a flight):
    /// the delay to set the autopilot's lag to (ArduPilot's PLND_LAG) is measured, not
    /// guessed.
    fn record_target_latency(&mut self, delay_us: u64) {
        let latency = &mut self.stats.target_latency;
        latency.record(delay_us);
        let count = latency.count;
        let due = count.is_multiple_of(LATENCY_REPORT_FIRST)
            && (count / LATENCY_REPORT_FIRST).is_power_of_two();
        if !due {
            return;
        }
        // Tenths of milliseconds in integers: float formatting would cost the firmware
        // kilobytes of flash for one message.
        let tenths = |us: u32| us.saturating_add(50) / 100;
        let (mean, max) = (
            tenths(latency.mean_us().unwrap_or(0)),
            tenths(latency.max_us),
        );
        let mut text = heapless::String::<STATUS_TEXT_LEN>::new();
        // 50 bytes hold the longest figures (two ten-digit numbers and the words): the write
        // cannot run out of room.
        let _ = write!(
            text,
            "touchdown: lag {}.{} ms mean, {}.{} ms max",
            mean / 10,
            mean % 10,
            max / 10,
            max % 10
        );
        self.queue_status_text(MavSeverity::MAV_SEVERITY_INFO, &text);
    }

    fn emit(&mut self, now_us: u64, msg: &MavMessage, out: &mut [u8]) -> Option<usize> {
        let (seq, sys, comp) = (self.sequence, self.sysid(), self.compid());
        // With a key, every frame goes out signed (`signing`): the flag is in the header, so
        // in the CRC, and the signature is appended after it.
        let key = self.params.signing_secret().key().copied();
        let flags = if key.is_some() {
            framing::IFLAG_SIGNED
        } else {
            0
        };
        // Serialise through the concrete payload type. `serialize_message(&MavMessage)` would
        // link the serialiser of every message of the common dialect (~110 KB of flash in the
        // firmware) although the companion only ever sends these. Framed by
        // `framing::write_v2_frame` (same bytes as `MAVLinkV2MessageRaw`, without its panic
        // paths; see nopanic/).
        let written = match msg {
            MavMessage::HEARTBEAT(d) => {
                framing::write_v2_frame_flagged(out, flags, seq, sys, comp, d)
            }
            MavMessage::SYS_STATUS(d) => {
                framing::write_v2_frame_flagged(out, flags, seq, sys, comp, d)
            }
            MavMessage::TIMESYNC(d) => {
                framing::write_v2_frame_flagged(out, flags, seq, sys, comp, d)
            }
            MavMessage::COMMAND_LONG(d) => {
                framing::write_v2_frame_flagged(out, flags, seq, sys, comp, d)
            }
            MavMessage::COMMAND_ACK(d) => {
                framing::write_v2_frame_flagged(out, flags, seq, sys, comp, d)
            }
            MavMessage::PARAM_VALUE(d) => {
                framing::write_v2_frame_flagged(out, flags, seq, sys, comp, d)
            }
            MavMessage::LANDING_TARGET(d) => {
                framing::write_v2_frame_flagged(out, flags, seq, sys, comp, d)
            }
            MavMessage::VISION_POSITION_ESTIMATE(d) => {
                framing::write_v2_frame_flagged(out, flags, seq, sys, comp, d)
            }
            MavMessage::ODOMETRY(d) => {
                framing::write_v2_frame_flagged(out, flags, seq, sys, comp, d)
            }
            MavMessage::VISION_SPEED_ESTIMATE(d) => {
                framing::write_v2_frame_flagged(out, flags, seq, sys, comp, d)
            }
            MavMessage::STATUSTEXT(d) => {
                framing::write_v2_frame_flagged(out, flags, seq, sys, comp, d)
            }
            MavMessage::NAMED_VALUE_FLOAT(d) => {
                framing::write_v2_frame_flagged(out, flags, seq, sys, comp, d)
            }
            _ => return None,
        };
        self.sequence = self.sequence.wrapping_add(1);
        let mut len = written?;
        if let Some(key) = key {
            len = self.signing.sign(&key, out, len, now_us)?;
        }
        self.stats.tx_frames = self.stats.tx_frames.saturating_add(1);
        self.stats.tx_bytes = self.stats.tx_bytes.saturating_add(len as u64);
        Some(len)
    }
}
