//! What the companion does with each frame the autopilot (or anyone) sends: HEARTBEAT latches
//! the autopilot and its profile, the vehicle state is stamped into our clock and kept,
//! TIMESYNC is answered or used, and the parameter protocol is served.
//!
//! Only the latched autopilot (component 1 of our system, TD_SYSID) feeds the vehicle state
//! and the clock offset; a gimbal or a ground station on the same link never does.

use super::framing::RawFrame;
use super::guard::Write;
use super::profile::Profile;
use super::signing::Authenticity;
use super::{
    Pending, State, MAV_COMP_ID_AUTOPILOT1, MAX_STAMP_DISAGREEMENT_US, MSG_ATTITUDE_QUATERNION,
};
use crate::filter::Attitude;
use crate::filter::PositionSample;
use crate::params::{self, ParamId, SigningSecret};
use mavlink::dialects::common::{
    MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult, MavSeverity,
};
use nalgebra::Vector3;

impl State {
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
        // Counted in the state: the estimator restarts its level track when it sees it.
        self.vehicle.on_reboot();
        // A new local frame: the shift measured in the old one means nothing there.
        self.shift.reset();
        self.next_timesync_us = now_us;
        for s in &mut self.streams {
            s.last_rx_us = None;
            s.next_request_us = now_us;
        }
    }

    pub(super) fn handle_frame(&mut self, frame: &RawFrame<'_>, now_us: u64) {
        if frame.system_id == self.sysid() && frame.component_id == self.compid() {
            return; // our own echo (a UDP router may reflect it)
        }
        let authenticity = self.authenticate(frame, now_us);
        if self.is_from_autopilot(frame) {
            // The stream is arriving, whatever its content: asking again would not mend a
            // malformed sample, and a message outside the common dialect (ArduPilot's
            // SIMSTATE) still proves its stream.
            self.mark_stream(frame.message_id, now_us);
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
                let custom = h
                    .base_mode
                    .contains(MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED);
                self.autopilot_mode = Some((custom, h.custom_mode));
                self.autopilot_armed = h
                    .base_mode
                    .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
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
                }
            }
            MavMessage::SYSTEM_TIME(s) if from_autopilot => {
                self.check_clock(s.time_boot_ms, now_us);
                self.timesync.on_system_time(s.time_boot_ms, now_us);
                self.signing.advance_to_unix(s.time_unix_usec, now_us);
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
                // No command is implemented: say so rather than leave the sender retrying;
                // with a key set, an unsigned one is told it was denied.
                let result = if self.may_write(Write::Command, authenticity, now_us) {
                    MavResult::MAV_RESULT_UNSUPPORTED
                } else {
                    MavResult::MAV_RESULT_DENIED
                };
                self.enqueue(Pending::CommandAck {
                    command: c.command,
                    result,
                    target: (frame.system_id, frame.component_id),
                });
            }
            MavMessage::SETUP_SIGNING(s)
                if self.addressed_to_us(s.target_system, s.target_component) =>
            {
                self.on_setup_signing(s.secret_key, s.initial_timestamp, authenticity, now_us);
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
                    let allowed = self.may_write(Write::Param(id), authenticity, now_us);
                    if allowed {
                        self.note_applied_write(frame);
                    }
                    match allowed.then(|| self.set_param(id, s.param_value)) {
                        None => {}
                        Some(Ok(())) => {
                            self.stats.param_sets_accepted =
                                self.stats.param_sets_accepted.saturating_add(1)
                        }
                        Some(Err(_)) => {
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

    /// Checks `frame`'s signature (with a key set) and counts what it proved.
    fn authenticate(&mut self, frame: &RawFrame<'_>, now_us: u64) -> Authenticity {
        let key = self.params.signing_secret().key().copied();
        let a = self.signing.check(key.as_ref(), frame, now_us);
        let counter = match a {
            Authenticity::Signed => &mut self.stats.signed_frames,
            Authenticity::BadSignature => &mut self.stats.bad_signatures,
            Authenticity::Replayed => &mut self.stats.replayed_frames,
            Authenticity::Unsigned => return a,
        };
        *counter = counter.saturating_add(1);
        a
    }

    /// A SETUP_SIGNING addressed to us: the key (all zeros: none) and its initial timestamp,
    /// applied when the guard allows it, and said by STATUSTEXT.
    fn on_setup_signing(
        &mut self,
        key: [u8; params::KEY_LEN],
        initial_timestamp: u64,
        authenticity: Authenticity,
        now_us: u64,
    ) {
        if !self.may_write(Write::SigningKey, authenticity, now_us) {
            return;
        }
        let secret = SigningSecret::new(key, initial_timestamp);
        self.set_signing_secret(secret, now_us);
        self.stats.signing_setups = self.stats.signing_setups.saturating_add(1);
        let text = if secret.is_set() {
            "touchdown: signing on"
        } else {
            "touchdown: signing off"
        };
        self.queue_status_text(MavSeverity::MAV_SEVERITY_NOTICE, text);
    }

    /// Takes `secret` as the key (a new key's streams start afresh) and runs our timestamp
    /// from its initial one if that is newer.
    pub(super) fn set_signing_secret(&mut self, secret: SigningSecret, now_us: u64) {
        self.params.set_signing_secret(secret);
        self.signing.restart(secret.timestamp());
        self.signing.advance_to(secret.timestamp(), now_us);
    }

    /// A write in `frame` was applied: with a key, the saved timestamp moves past the frame's
    /// (`signing`: it is then never taken again, a reboot included).
    fn note_applied_write(&mut self, frame: &RawFrame<'_>) {
        let secret = *self.params.signing_secret();
        if let (true, Some(signature)) = (secret.is_set(), frame.signature) {
            let next = secret.after_write(signature.timestamp);
            self.params.set_signing_secret(next);
            self.signing.raise_floor(next.timestamp());
        }
    }

    fn mark_stream(&mut self, message_id: u32, now_us: u64) {
        if let Some(s) = self.streams.iter_mut().find(|s| s.message_id == message_id) {
            s.last_rx_us = Some(now_us);
        }
    }
}
