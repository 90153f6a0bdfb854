//! The simulated autopilot that speaks MAVLink bytes to the board's companion, and the serial
//! link between them.
//!
//! The autopilot (system 1, component 1) sends HEARTBEAT (ArduPilot's or PX4's) and
//! SYSTEM_TIME once a second; PX4's also sends its own TIMESYNC requests once a second and
//! keeps an estimate of our clock from our answers. It answers our TIMESYNC requests with its
//! clock, and SET_MESSAGE_INTERVAL (COMMAND_LONG) with COMMAND_ACK, after which it streams
//! ATTITUDE_QUATERNION and LOCAL_POSITION_NED at the asked intervals. Each sample is its
//! estimate at the sample's time (the truth with the [`Realisation`]'s errors), stamped in its
//! own drifting clock, and sent the sample latency after that time. LANDING_TARGETs it hears
//! are kept with their receipt time for the reconstruction.
//!
//! The link delays every message by its bytes at the baud rate (one after another: a UART
//! sends one byte at a time) plus a fixed delay, and keeps their order.

use std::collections::VecDeque;

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult, MavState, MavType,
    ATTITUDE_QUATERNION_DATA, COMMAND_ACK_DATA, HEARTBEAT_DATA, LANDING_TARGET_DATA,
    LOCAL_POSITION_NED_DATA, SYSTEM_TIME_DATA, TIMESYNC_DATA,
};
use touchdown_core::companion::mavlink::{MAVLinkV2MessageRaw, MavHeader};
use touchdown_core::companion::FrameParser;

use super::error_model::Realisation;
use super::{TruthSource, NED_FROM_PAD};

/// Which flight stack the simulated autopilot is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AutopilotKind {
    /// ArduPilot: HEARTBEAT MAV_AUTOPILOT_ARDUPILOTMEGA, the body-vector reconstruction.
    ArduPilot,
    /// PX4: HEARTBEAT MAV_AUTOPILOT_PX4, its TIMESYNC requests, the LOCAL_NED reconstruction.
    Px4,
}

impl AutopilotKind {
    /// `ardupilot` or `px4`.
    pub fn name(self) -> &'static str {
        match self {
            AutopilotKind::ArduPilot => "ardupilot",
            AutopilotKind::Px4 => "px4",
        }
    }
}

/// The MAVLink message ids of the streams.
const MSG_ATTITUDE_QUATERNION: u32 = 31;
const MSG_LOCAL_POSITION_NED: u32 = 32;
/// Stream kinds for the sample latency draws.
const KIND_ATTITUDE: u64 = 0;
const KIND_POSITION: u64 = 1;
/// Weight of a new TIMESYNC sample in PX4's offset estimate (an exponential average; PX4's
/// own filter is a double exponential one that converges over hundreds of samples: the
/// replay's autopilot has converged after a few).
const PX4_TIMESYNC_WEIGHT: f64 = 0.2;
/// Half the span of the finite difference that gives LOCAL_POSITION_NED's velocity, s.
const VELOCITY_SPAN_S: f64 = 0.01;

/// One direction of the serial link (see the module docs).
#[derive(Debug, Clone)]
pub struct Link {
    /// (arrival time, bytes), in order.
    queue: VecDeque<(u64, Vec<u8>)>,
    /// When the line has sent everything queued so far, µs.
    line_free_us: u64,
    /// Bytes sent.
    pub bytes: u64,
}

impl Link {
    /// An idle link.
    pub fn new() -> Self {
        Link {
            queue: VecDeque::new(),
            line_free_us: 0,
            bytes: 0,
        }
    }

    /// Sends `bytes` at `now_us`: they arrive once the line has sent them (after what it was
    /// sending) and the fixed delay has passed.
    pub fn send(&mut self, errors: &Realisation, now_us: u64, bytes: Vec<u8>) {
        let start = now_us.max(self.line_free_us);
        let end = start + errors.transmission_us(bytes.len());
        self.line_free_us = end;
        self.bytes += bytes.len() as u64;
        self.queue.push_back((end + errors.link_delay_us(), bytes));
    }

    /// The next message that has arrived by `now_us`.
    pub fn due(&mut self, now_us: u64) -> Option<Vec<u8>> {
        if self.queue.front().is_some_and(|(t, _)| *t <= now_us) {
            self.queue.pop_front().map(|(_, b)| b)
        } else {
            None
        }
    }
}

impl Default for Link {
    fn default() -> Self {
        Link::new()
    }
}

/// A LANDING_TARGET the autopilot heard.
#[derive(Debug, Clone, PartialEq)]
pub struct ReceivedTarget {
    /// When its last byte arrived, our clock (µs).
    pub receipt_us: u64,
    /// What it says.
    pub data: LANDING_TARGET_DATA,
}

/// Our clock (the board's, µs) against the frames' clock (seconds): `board = frame + offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardClock {
    /// Board µs at frame time 0.
    pub offset_us: u64,
}

impl BoardClock {
    /// Board µs of frame-clock µs.
    pub fn board_us(&self, frame_us: u64) -> u64 {
        frame_us + self.offset_us
    }

    /// Frame-clock seconds of board µs (negative before the frames' time 0).
    pub fn frame_s(&self, board_us: u64) -> f64 {
        (board_us as f64 - self.offset_us as f64) * 1e-6
    }

    /// Frame-clock µs of board µs (0 before the frames' time 0).
    pub fn frame_us(&self, board_us: u64) -> u64 {
        board_us.saturating_sub(self.offset_us)
    }
}

/// What the autopilot believes at a time: its attitude and local position estimates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AutopilotBelief {
    /// Body FRD to NED.
    pub body_to_ned: Matrix3<f64>,
    /// Its local position, NED, metres (the truth plus its drift).
    pub position_ned: Vector3<f64>,
}

/// The autopilot's estimates at board time `board_us`, from the truth and the errors;
/// `None` without a truth at that time.
pub fn belief(
    truth: &dyn TruthSource,
    clock: &BoardClock,
    errors: &Realisation,
    pad_ned: &Vector3<f64>,
    board_us: u64,
) -> Option<AutopilotBelief> {
    let t = clock.frame_s(board_us);
    let state = truth.at(t)?;
    Some(AutopilotBelief {
        body_to_ned: errors.estimated_attitude(&state.body_to_ned, t),
        position_ned: pad_ned + NED_FROM_PAD * state.position + errors.position_error(t),
    })
}

/// The simulated autopilot (see the module docs).
#[derive(Debug, Clone)]
pub struct SimAutopilot {
    /// Which stack.
    pub kind: AutopilotKind,
    /// The pad's origin in the autopilot's local NED frame, metres.
    pub pad_ned: Vector3<f64>,
    /// LANDING_TARGETs heard and not yet taken.
    pub received: Vec<ReceivedTarget>,
    /// The HEARTBEAT's `custom_mode`, with MAV_MODE_FLAG_CUSTOM_MODE_ENABLED (`None`: 0,
    /// no flag).
    pub mode: Option<u32>,
    seq: u8,
    parser: FrameParser,
    intervals_us: [Option<u64>; 2],
    next_sample_us: [u64; 2],
    samples: [u64; 2],
    next_heartbeat_us: u64,
    next_system_time_us: u64,
    next_timesync_us: u64,
    /// PX4's estimate of (our clock - its clock), µs, and its sample count.
    px4_offset_us: Option<f64>,
}

impl SimAutopilot {
    /// The same, reporting `mode` in its HEARTBEAT ([`SimAutopilot::mode`]).
    pub fn with_mode(self, mode: Option<u32>) -> Self {
        SimAutopilot { mode, ..self }
    }

    /// An autopilot that has asked and been asked nothing yet.
    pub fn new(kind: AutopilotKind, pad_ned: Vector3<f64>) -> Self {
        SimAutopilot {
            kind,
            pad_ned,
            received: Vec::new(),
            mode: None,
            seq: 0,
            parser: FrameParser::new(),
            intervals_us: [None; 2],
            next_sample_us: [0; 2],
            samples: [0; 2],
            next_heartbeat_us: 0,
            next_system_time_us: 300_000,
            next_timesync_us: 500_000,
            px4_offset_us: None,
        }
    }

    /// PX4's estimate of our clock minus its own, µs (`None` before its first TIMESYNC
    /// answer, or for ArduPilot).
    pub fn px4_offset_us(&self) -> Option<f64> {
        self.px4_offset_us
    }

    fn send(&mut self, link: &mut Link, errors: &Realisation, now_us: u64, msg: &MavMessage) {
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message(
            MavHeader {
                system_id: 1,
                component_id: 1,
                sequence: self.seq,
            },
            msg,
        );
        self.seq = self.seq.wrapping_add(1);
        link.send(errors, now_us, raw.raw_bytes().to_vec());
    }

    /// What the autopilot sends at `now_us` (our clock), down `link`.
    pub fn tick(
        &mut self,
        now_us: u64,
        truth: &dyn TruthSource,
        clock: &BoardClock,
        errors: &Realisation,
        link: &mut Link,
    ) {
        let ap_us = errors.autopilot_clock_us(now_us);
        let boot_ms = (ap_us / 1000) as u32;
        if now_us >= self.next_heartbeat_us {
            self.next_heartbeat_us = now_us + 1_000_000;
            let autopilot = match self.kind {
                AutopilotKind::ArduPilot => MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                AutopilotKind::Px4 => MavAutopilot::MAV_AUTOPILOT_PX4,
            };
            let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: self.mode.unwrap_or(0),
                mavtype: MavType::MAV_TYPE_QUADROTOR,
                autopilot,
                base_mode: match self.mode {
                    Some(_) => MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                    None => MavModeFlag::empty(),
                },
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            });
            self.send(link, errors, now_us, &hb);
        }
        if now_us >= self.next_system_time_us {
            self.next_system_time_us = now_us + 1_000_000;
            let st = MavMessage::SYSTEM_TIME(SYSTEM_TIME_DATA {
                time_unix_usec: 0,
                time_boot_ms: boot_ms,
            });
            self.send(link, errors, now_us, &st);
        }
        if self.kind == AutopilotKind::Px4 && now_us >= self.next_timesync_us {
            self.next_timesync_us = now_us + 1_000_000;
            let req = MavMessage::TIMESYNC(TIMESYNC_DATA {
                tc1: 0,
                ts1: ap_us as i64 * 1000,
                target_system: 0,
                target_component: 0,
            });
            self.send(link, errors, now_us, &req);
        }
        for stream in 0..2 {
            let Some(interval) = self.intervals_us[stream] else {
                continue;
            };
            if now_us < self.next_sample_us[stream] {
                continue;
            }
            self.next_sample_us[stream] = now_us + interval;
            let index = self.samples[stream];
            self.samples[stream] += 1;
            let kind = if stream == 0 {
                KIND_ATTITUDE
            } else {
                KIND_POSITION
            };
            // The sample is the estimate at its own time, sent the latency later.
            let sample_us = now_us.saturating_sub(errors.sample_latency_us(kind, index));
            let Some(b) = belief(truth, clock, errors, &self.pad_ned, sample_us) else {
                continue;
            };
            let time_boot_ms = (errors.autopilot_clock_us(sample_us) / 1000) as u32;
            let msg = if stream == 0 {
                let q = UnitQuaternion::from_matrix(&b.body_to_ned);
                let q = if q.w < 0.0 {
                    -q.into_inner()
                } else {
                    q.into_inner()
                };
                MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
                    time_boot_ms,
                    q1: q.w as f32,
                    q2: q.i as f32,
                    q3: q.j as f32,
                    q4: q.k as f32,
                    ..ATTITUDE_QUATERNION_DATA::DEFAULT
                })
            } else {
                let span_us = (VELOCITY_SPAN_S * 1e6) as u64;
                let velocity = match (
                    belief(truth, clock, errors, &self.pad_ned, sample_us + span_us),
                    belief(
                        truth,
                        clock,
                        errors,
                        &self.pad_ned,
                        sample_us.saturating_sub(span_us),
                    ),
                ) {
                    (Some(a), Some(c)) => {
                        (a.position_ned - c.position_ned) / (2.0 * VELOCITY_SPAN_S)
                    }
                    _ => Vector3::zeros(),
                };
                let p = b.position_ned;
                MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                    time_boot_ms,
                    x: p.x as f32,
                    y: p.y as f32,
                    z: p.z as f32,
                    vx: velocity.x as f32,
                    vy: velocity.y as f32,
                    vz: velocity.z as f32,
                })
            };
            self.send(link, errors, now_us, &msg);
        }
    }

    /// Bytes from the companion, arriving at `now_us`; the answers go down `link`.
    pub fn hear(&mut self, bytes: &[u8], now_us: u64, errors: &Realisation, link: &mut Link) {
        let mut msgs = Vec::new();
        self.parser.push(bytes, |f| {
            if let Ok(m) = f.decode() {
                msgs.push((m, f.system_id, f.component_id));
            }
        });
        let ap_us = errors.autopilot_clock_us(now_us);
        for (m, sys, comp) in msgs {
            match m {
                MavMessage::TIMESYNC(t) if t.tc1 == 0 => {
                    let reply = MavMessage::TIMESYNC(TIMESYNC_DATA {
                        tc1: ap_us as i64 * 1000,
                        ts1: t.ts1,
                        target_system: sys,
                        target_component: comp,
                    });
                    self.send(link, errors, now_us, &reply);
                }
                MavMessage::TIMESYNC(t) if self.kind == AutopilotKind::Px4 => {
                    // Our own request answered: its time at the midpoint of the round trip.
                    let sent_us = t.ts1 as f64 * 1e-3;
                    let midpoint = 0.5 * (sent_us + ap_us as f64);
                    let sample = t.tc1 as f64 * 1e-3 - midpoint;
                    self.px4_offset_us = Some(match self.px4_offset_us {
                        Some(o) => o + PX4_TIMESYNC_WEIGHT * (sample - o),
                        None => sample,
                    });
                }
                MavMessage::COMMAND_LONG(c)
                    if c.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL =>
                {
                    let interval = c.param2.max(1000.0) as u64;
                    match c.param1 as u32 {
                        MSG_ATTITUDE_QUATERNION => self.intervals_us[0] = Some(interval),
                        MSG_LOCAL_POSITION_NED => self.intervals_us[1] = Some(interval),
                        _ => {}
                    }
                    let ack = MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
                        command: c.command,
                        result: MavResult::MAV_RESULT_ACCEPTED,
                        target_system: sys,
                        target_component: comp,
                        ..COMMAND_ACK_DATA::DEFAULT
                    });
                    self.send(link, errors, now_us, &ack);
                }
                MavMessage::LANDING_TARGET(data) => self.received.push(ReceivedTarget {
                    receipt_us: now_us,
                    data,
                }),
                _ => {}
            }
        }
    }
}
