//! The simulated autopilot (system 1, component 1) and the flight loop's common steps.
//!
//! The autopilot streams what a real one does: HEARTBEAT (and, when asked, a gimbal's just
//! before each), SYSTEM_TIME and its own TIMESYNC requests once a second (PX4 style); the
//! vehicle's ATTITUDE_QUATERNION and LOCAL_POSITION_NED only once asked with
//! SET_MESSAGE_INTERVAL (answered with COMMAND_ACK); it answers our TIMESYNC requests. All of
//! it is stamped in its own clock ([`AutopilotClock`]), which may run ahead, fast or slow, jump,
//! or restart at a reboot.

use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult, MavState, MavType,
    ATTITUDE_QUATERNION_DATA, COMMAND_ACK_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA,
    SYSTEM_TIME_DATA, TIMESYNC_DATA,
};
use touchdown_core::companion::{Companion, FrameParser, TargetOutcome, MAX_FRAME_LEN};

use super::{encode, heartbeat, CameraFrames, FixEstimator, Link, LinkDelay, VehiclePath};

/// The autopilot's clock against the true time `t` (= the companion's clock), µs:
/// `start_us + rate * t`, plus `jump.1` from true time `jump.0` on.
#[derive(Debug, Clone, Copy)]
pub struct AutopilotClock {
    /// The autopilot's time at our time 0 (negative: it booted after us).
    pub start_us: f64,
    /// Autopilot seconds per true second (0.98: 2 % slow).
    pub rate: f64,
    /// (true time, added µs): the clock jumps forward once.
    pub jump: Option<(u64, f64)>,
}

impl AutopilotClock {
    /// A clock that keeps true time, `start_us` ahead of ours.
    pub fn steady(start_us: f64) -> Self {
        AutopilotClock {
            start_us,
            rate: 1.0,
            jump: None,
        }
    }

    /// The autopilot's time at true time `t`.
    pub fn at(&self, t: u64) -> u64 {
        let mut a = self.start_us + self.rate * t as f64;
        if let Some((at, by)) = self.jump {
            if t >= at {
                a += by;
            }
        }
        a as u64
    }
}

/// The simulated autopilot.
pub struct Autopilot {
    pub clock: AutopilotClock,
    /// The flight it reports.
    pub path: VehiclePath,
    /// HEARTBEAT.autopilot.
    pub kind: MavAutopilot,
    /// A MAVLink gimbal (component 154, MAV_AUTOPILOT_GENERIC) heartbeats too, just before
    /// each of the autopilot's.
    pub gimbal: bool,
    /// When the next HEARTBEAT, SYSTEM_TIME and TIMESYNC request go out (true time).
    pub next_hb: u64,
    pub next_systime: u64,
    pub next_timesync: u64,
    seq: u8,
    parser: FrameParser,
    att_interval: Option<u64>,
    pos_interval: Option<u64>,
    next_att: u64,
    next_pos: u64,
}

impl Autopilot {
    pub fn new(clock: AutopilotClock, path: VehiclePath, kind: MavAutopilot) -> Self {
        Autopilot {
            clock,
            path,
            kind,
            gimbal: false,
            next_hb: 0,
            next_systime: 500_000,
            next_timesync: 300_000,
            seq: 0,
            parser: FrameParser::new(),
            att_interval: None,
            pos_interval: None,
            next_att: 0,
            next_pos: 0,
        }
    }

    /// Restarted at true time `boot_us`: its clock counts from there, the streams it was
    /// asked for are forgotten.
    pub fn reboot(&mut self, boot_us: u64) {
        self.clock = AutopilotClock::steady(-(boot_us as f64));
        self.att_interval = None;
        self.pos_interval = None;
        self.parser.clear();
    }

    /// `msg` down `link` at `now`, tagged with `tag`.
    fn send(&mut self, link: &mut Link, now: u64, msg: MavMessage, tag: Option<u64>) {
        let bytes = encode(&mut self.seq, 1, 1, &msg);
        link.send(now, bytes, tag);
    }

    /// Bytes from the companion, arriving at `now`; the answers go down `link`.
    pub fn hear(&mut self, bytes: &[u8], now: u64, link: &mut Link) {
        let mut msgs = Vec::new();
        self.parser.push(bytes, |f| {
            if let Ok(m) = f.decode() {
                msgs.push(m);
            }
        });
        for m in msgs {
            match m {
                MavMessage::TIMESYNC(t) if t.tc1 == 0 => {
                    let tc1 = self.clock.at(now) as i64 * 1000;
                    let reply = MavMessage::TIMESYNC(TIMESYNC_DATA {
                        tc1,
                        ts1: t.ts1,
                        target_system: 1,
                        target_component: 191,
                    });
                    self.send(link, now, reply, None);
                }
                MavMessage::COMMAND_LONG(c)
                    if c.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL =>
                {
                    let interval = c.param2.max(1000.0) as u64;
                    match c.param1 as u32 {
                        31 => self.att_interval = Some(interval),
                        32 => self.pos_interval = Some(interval),
                        _ => {}
                    }
                    let ack = MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
                        command: c.command,
                        result: MavResult::MAV_RESULT_ACCEPTED,
                        ..COMMAND_ACK_DATA::DEFAULT
                    });
                    self.send(link, now, ack, None);
                }
                _ => {}
            }
        }
    }

    /// What the autopilot sends at `now`, down `link`. ATTITUDE_QUATERNION and
    /// LOCAL_POSITION_NED are tagged with their time stamp in the autopilot's clock, µs.
    pub fn tick(&mut self, now: u64, link: &mut Link) {
        let t = now as f32 * 1e-6;
        let ap_us = self.clock.at(now);
        let boot_ms = (ap_us / 1000) as u32;
        if now >= self.next_hb {
            self.next_hb = now + 1_000_000;
            if self.gimbal {
                let gimbal = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                    custom_mode: 0,
                    mavtype: MavType::MAV_TYPE_GIMBAL,
                    autopilot: MavAutopilot::MAV_AUTOPILOT_GENERIC,
                    base_mode: MavModeFlag::empty(),
                    system_status: MavState::MAV_STATE_ACTIVE,
                    mavlink_version: 3,
                });
                let bytes = encode(&mut self.seq, 1, 154, &gimbal);
                link.send(now, bytes, None);
            }
            let hb = heartbeat(self.kind);
            self.send(link, now, hb, None);
        }
        if now >= self.next_systime {
            self.next_systime = now + 1_000_000;
            let st = MavMessage::SYSTEM_TIME(SYSTEM_TIME_DATA {
                time_unix_usec: 0,
                time_boot_ms: boot_ms,
            });
            self.send(link, now, st, None);
        }
        if now >= self.next_timesync {
            self.next_timesync = now + 1_000_000;
            let req = MavMessage::TIMESYNC(TIMESYNC_DATA {
                tc1: 0,
                ts1: ap_us as i64 * 1000,
                target_system: 0,
                target_component: 0,
            });
            self.send(link, now, req, None);
        }
        if let Some(iv) = self.att_interval {
            if now >= self.next_att {
                self.next_att = now + iv;
                let [q1, q2, q3, q4] = self.path.attitude(t).quaternion_wxyz();
                let msg = MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
                    time_boot_ms: boot_ms,
                    q1,
                    q2,
                    q3,
                    q4,
                    ..ATTITUDE_QUATERNION_DATA::DEFAULT
                });
                self.send(link, now, msg, Some(ap_us));
            }
        }
        if let Some(iv) = self.pos_interval {
            if now >= self.next_pos {
                self.next_pos = now + iv;
                let (p, v) = (self.path.position(t), self.path.velocity(t));
                let msg = MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                    time_boot_ms: boot_ms,
                    x: p.x,
                    y: p.y,
                    z: p.z,
                    vx: v.x,
                    vy: v.y,
                    vz: v.z,
                });
                self.send(link, now, msg, Some(ap_us));
            }
        }
    }
}

/// One simulated flight: the board (the companion and its estimator stage, fed by the
/// camera's frames), the autopilot, and the link between them. Each test's loop calls these
/// steps once per [`super::STEP_US`] and adds what it judges in between.
pub struct Flight {
    pub companion: Companion,
    pub estimator: FixEstimator,
    pub camera: CameraFrames,
    pub autopilot: Autopilot,
    /// Companion to autopilot.
    pub uplink: Link,
    /// Autopilot to companion.
    pub downlink: Link,
    out: [u8; MAX_FRAME_LEN],
}

impl Flight {
    pub fn new(
        companion: Companion,
        autopilot: Autopilot,
        uplink: LinkDelay,
        downlink: LinkDelay,
    ) -> Self {
        Flight {
            companion,
            estimator: FixEstimator::new(),
            camera: CameraFrames::new(),
            autopilot,
            uplink: Link::new(uplink),
            downlink: Link::new(downlink),
            out: [0; MAX_FRAME_LEN],
        }
    }

    /// The companion's bytes that arrived by `now` reach the autopilot; `heard` false: they
    /// are lost (it is down).
    pub fn uplink_to_autopilot(&mut self, now: u64, heard: bool) {
        while let Some((bytes, _)) = self.uplink.due(now) {
            if heard {
                self.autopilot.hear(&bytes, now, &mut self.downlink);
            }
        }
    }

    /// The autopilot's own life at `now`.
    pub fn autopilot_tick(&mut self, now: u64) {
        self.autopilot.tick(now, &mut self.downlink);
    }

    /// Every frame processed by `now` goes through the estimator stage to the companion;
    /// `outcome` sees what became of each.
    pub fn deliver_frames(&mut self, now: u64, mut outcome: impl FnMut(TargetOutcome)) {
        while let Some((exposure_us, fix)) = self.camera.processed(now) {
            outcome(
                self.estimator
                    .deliver(&mut self.companion, exposure_us, fix, now),
            );
        }
    }

    /// Everything the companion sends at `now` goes up the link; `sent` sees each frame.
    pub fn transmit(&mut self, now: u64, mut sent: impl FnMut(&[u8])) {
        while let Some(n) = self.companion.poll_transmit(now, &mut self.out) {
            let bytes = self.out[..n].to_vec();
            sent(&bytes);
            self.uplink.send(now, bytes, None);
        }
    }
}
