//! The companion state machine (core/src/companion) against a simulated autopilot, with every
//! emitted byte checked by pymavlink.
//!
//! A vehicle flies a known path (descending, rolling, pitching, turning) over a pad at a known
//! NED position. Every 33 ms a camera frame is "exposed"; 25 ms later its pad fix (the true
//! camera-frame pad position plus Gaussian noise with the covariance the fix reports) reaches
//! the board's estimator stage (`FixEstimator`) and then `Companion::on_estimate`. The simulated autopilot streams what a real one does: HEARTBEAT and
//! SYSTEM_TIME always, TIMESYNC requests (PX4 style), ATTITUDE_QUATERNION and
//! LOCAL_POSITION_NED only once asked with SET_MESSAGE_INTERVAL (answered with COMMAND_ACK),
//! answers our TIMESYNC requests, all in its own clock (1000 s ahead of ours), over a link with
//! 2-3 ms latency. Faults: garbage, truncated frames and flipped bits on the autopilot's
//! stream; a reboot (clock restarts, streams forgotten); 10 s of silence; the pad lost.
//!
//! Everything the companion sends is written to a file and decoded by pymavlink with
//! `robust_parsing` off (`tests/companion_decode.py`): each frame must have a valid CRC, and
//! the decoded values are compared with the truth. Without pymavlink the tests print
//! `skipping: pymavlink not installed` (CI installs it). Figures are printed; run with
//! `--nocapture` to see them.
//!
//! The camera parameters (TD_TAG_SIZE, TD_MAX_HAMMING and the auto-exposure limits
//! TD_EXP_MAX_US, TD_GAIN_MAX, TD_EXP_TARGET) are checked without pymavlink: a ground
//! station's PARAM_SETs are range-checked, the resulting vision settings are what the
//! firmware's vision task applies, and the values survive the flash log across a reboot.

mod autopilot_sim;

use std::collections::{BTreeMap, VecDeque};
use std::path::PathBuf;
use std::process::Command;

use nalgebra::{Matrix3, Matrix6, Quaternion, Rotation3, UnitQuaternion, Vector3};
use serde_json::Value;
use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavParamType, MavResult, MavState, MavType,
    ATTITUDE_QUATERNION_DATA, COMMAND_ACK_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA,
    PARAM_REQUEST_LIST_DATA, PARAM_REQUEST_READ_DATA, PARAM_SET_DATA, SYSTEM_TIME_DATA,
    TIMESYNC_DATA,
};
use touchdown_core::companion::{
    Companion, CompanionConfig, CompanionStats, FrameParser, Profile, TargetOutcome, MAX_FRAME_LEN,
};
use touchdown_core::detect::DetectorConfig;
use touchdown_core::filter::axes::{camera_to_ned_matrix, Attitude, CameraMount};
use touchdown_core::pad::designs;
use touchdown_core::params::name_str;
use touchdown_core::params::persist::{self, FlashFailed, SlotFlash, ERASED, SLOT_LEN};
use touchdown_core::params::{ParamId, ParamSet, PipelineSettings, PARAM_COUNT};
use touchdown_core::pose::{PadFix, Pose};
use touchdown_core::sensor::exposure::AutoExposureLimits;
use touchdown_core::sensor::GainX16;

use autopilot_sim::{
    encode, heartbeat, pad_fix, pad_ned, FixEstimator, Rng, SIGMA_LATERAL, SIGMA_RANGE,
};

/// The autopilot booted this long before the companion (its clock = ours + this).
const AP_AHEAD_US: u64 = 1_000_000_000;
const STEP_US: u64 = 1_000;
const FRAME_PERIOD_US: u64 = 33_333;
const PROCESS_DELAY_US: u64 = 25_000;
const UPLINK_DELAY_US: u64 = 2_000; // companion -> autopilot
const DOWNLINK_DELAY_US: u64 = 3_000; // autopilot -> companion
const REBOOT_DOWN_US: u64 = 1_500_000;

fn vehicle_position(t: f32) -> Vector3<f32> {
    Vector3::new(2.0 + 0.2 * t, -1.0 + 0.3 * (0.5 * t).sin(), -12.0 + 0.3 * t)
}
fn vehicle_velocity(t: f32) -> Vector3<f32> {
    Vector3::new(0.2, 0.15 * (0.5 * t).cos(), 0.3)
}
fn vehicle_attitude(t: f32) -> Attitude {
    Attitude::from_euler(
        0.1 * (1.3 * t).sin(),
        0.08 * (0.9 * t).cos(),
        0.5 + 0.05 * t,
    )
    .unwrap()
}

#[derive(Debug, Clone, Copy)]
enum ParamAction {
    RequestList,
    ReadName(&'static str),
    ReadIndex(i16),
    Set(&'static str, f32),
}

#[derive(Debug, Clone)]
struct Scenario {
    name: &'static str,
    profile: Profile,
    duration_us: u64,
    /// The autopilot sends nothing in [start, end).
    silent: Option<(u64, u64)>,
    /// The autopilot reboots at this time (down for REBOOT_DOWN_US, clock restarts).
    reboot_at: Option<u64>,
    /// No pad in frames exposed in [start, end).
    lost: Option<(u64, u64)>,
    corrupt: bool,
    params: Vec<(u64, ParamAction)>,
    vpe: bool,
    /// TD_PROFILE auto (the default) instead of forcing `profile`; the simulated autopilot's
    /// HEARTBEAT then says `profile`'s autopilot.
    auto: bool,
    /// A MAVLink gimbal (component 154, MAV_AUTOPILOT_GENERIC) heartbeats too, just before
    /// each of the autopilot's.
    gimbal: bool,
    /// The autopilot's first HEARTBEAT (and everything else of it) from this time on.
    autopilot_from_us: u64,
    /// The pad turned about its z axis by this, radians (0: pad x east, pad y north).
    pad_yaw: f32,
    /// TD_CAM_YAW, degrees (the simulated camera is turned the same way).
    cam_yaw_deg: f32,
}

impl Scenario {
    fn new(name: &'static str, profile: Profile) -> Self {
        Scenario {
            name,
            profile,
            duration_us: 8_000_000,
            silent: None,
            reboot_at: None,
            lost: None,
            corrupt: false,
            params: Vec::new(),
            vpe: false,
            auto: false,
            gimbal: false,
            autopilot_from_us: 0,
            pad_yaw: 0.0,
            cam_yaw_deg: 0.0,
        }
    }
}

/// The simulated autopilot (system 1, component 1).
struct Autopilot {
    seq: u8,
    /// Its clock = ours + ahead (before a reboot), or ours - reboot time (after).
    epoch: i64,
    att_interval: Option<u64>,
    pos_interval: Option<u64>,
    next_att: u64,
    next_pos: u64,
    next_hb: u64,
    next_systime: u64,
    next_timesync: u64,
    parser: FrameParser,
    outbox: VecDeque<(u64, Vec<u8>)>,
    acks_sent: u32,
    timesync_answers: u32,
    /// HEARTBEAT.autopilot.
    kind: MavAutopilot,
    gimbal: bool,
}

impl Autopilot {
    fn new() -> Self {
        Autopilot {
            seq: 0,
            epoch: AP_AHEAD_US as i64,
            att_interval: None,
            pos_interval: None,
            next_att: 0,
            next_pos: 0,
            next_hb: 0,
            next_systime: 500_000,
            next_timesync: 300_000,
            parser: FrameParser::new(),
            outbox: VecDeque::new(),
            acks_sent: 0,
            timesync_answers: 0,
            kind: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            gimbal: false,
        }
    }

    fn clock_us(&self, now: u64) -> u64 {
        (now as i64 + self.epoch) as u64
    }

    fn send(&mut self, now: u64, msg: MavMessage) {
        let bytes = encode(&mut self.seq, 1, 1, &msg);
        self.outbox.push_back((now + DOWNLINK_DELAY_US, bytes));
    }

    fn reboot(&mut self, now: u64) {
        self.epoch = -(now as i64);
        self.att_interval = None;
        self.pos_interval = None;
        self.parser.clear();
    }

    /// Bytes from the companion, arriving at `now`.
    fn hear(&mut self, bytes: &[u8], now: u64) {
        let mut msgs = Vec::new();
        self.parser.push(bytes, |f| {
            if let Ok(m) = f.decode() {
                msgs.push(m);
            }
        });
        for m in msgs {
            match m {
                MavMessage::TIMESYNC(t) if t.tc1 == 0 => {
                    self.timesync_answers += 1;
                    let tc1 = self.clock_us(now) as i64 * 1000;
                    self.send(
                        now,
                        MavMessage::TIMESYNC(TIMESYNC_DATA {
                            tc1,
                            ts1: t.ts1,
                            target_system: 1,
                            target_component: 191,
                        }),
                    );
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
                    self.acks_sent += 1;
                    self.send(
                        now,
                        MavMessage::COMMAND_ACK(COMMAND_ACK_DATA {
                            command: c.command,
                            result: MavResult::MAV_RESULT_ACCEPTED,
                            ..COMMAND_ACK_DATA::DEFAULT
                        }),
                    );
                }
                _ => {}
            }
        }
    }

    fn tick(&mut self, now: u64) {
        let t = now as f32 * 1e-6;
        let boot_ms = (self.clock_us(now) / 1000) as u32;
        if now >= self.next_hb {
            self.next_hb = now + 1_000_000;
            if self.gimbal {
                let bytes = encode(
                    &mut self.seq,
                    1,
                    154,
                    &MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                        custom_mode: 0,
                        mavtype: MavType::MAV_TYPE_GIMBAL,
                        autopilot: MavAutopilot::MAV_AUTOPILOT_GENERIC,
                        base_mode: MavModeFlag::empty(),
                        system_status: MavState::MAV_STATE_ACTIVE,
                        mavlink_version: 3,
                    }),
                );
                self.outbox.push_back((now + DOWNLINK_DELAY_US, bytes));
            }
            self.send(now, heartbeat(self.kind));
        }
        if now >= self.next_systime {
            self.next_systime = now + 1_000_000;
            self.send(
                now,
                MavMessage::SYSTEM_TIME(SYSTEM_TIME_DATA {
                    time_unix_usec: 0,
                    time_boot_ms: boot_ms,
                }),
            );
        }
        if now >= self.next_timesync {
            self.next_timesync = now + 1_000_000;
            let ts1 = self.clock_us(now) as i64 * 1000;
            self.send(
                now,
                MavMessage::TIMESYNC(TIMESYNC_DATA {
                    tc1: 0,
                    ts1,
                    target_system: 0,
                    target_component: 0,
                }),
            );
        }
        if let Some(iv) = self.att_interval {
            if now >= self.next_att {
                self.next_att = now + iv;
                let [q1, q2, q3, q4] = vehicle_attitude(t).quaternion_wxyz();
                self.send(
                    now,
                    MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
                        time_boot_ms: boot_ms,
                        q1,
                        q2,
                        q3,
                        q4,
                        ..ATTITUDE_QUATERNION_DATA::DEFAULT
                    }),
                );
            }
        }
        if let Some(iv) = self.pos_interval {
            if now >= self.next_pos {
                self.next_pos = now + iv;
                let p = vehicle_position(t);
                let v = vehicle_velocity(t);
                self.send(
                    now,
                    MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                        time_boot_ms: boot_ms,
                        x: p.x,
                        y: p.y,
                        z: p.z,
                        vx: v.x,
                        vy: v.y,
                        vz: v.z,
                    }),
                );
            }
        }
    }
}

/// The ground station: PARAM_* requests (system 255, component 190).
fn gcs_message(seq: &mut u8, action: ParamAction) -> Vec<u8> {
    let msg = match action {
        ParamAction::RequestList => MavMessage::PARAM_REQUEST_LIST(PARAM_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 0,
        }),
        ParamAction::ReadName(name) => MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
            param_index: -1,
            target_system: 1,
            target_component: 191,
            param_id: name.into(),
        }),
        ParamAction::ReadIndex(i) => MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
            param_index: i,
            target_system: 1,
            target_component: 191,
            param_id: "".into(),
        }),
        ParamAction::Set(name, value) => MavMessage::PARAM_SET(PARAM_SET_DATA {
            param_value: value,
            target_system: 1,
            target_component: 191,
            param_id: name.into(),
            param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
        }),
    };
    encode(seq, 255, 190, &msg)
}

/// Truth at one exposure.
#[derive(Debug, Clone, Copy)]
struct Truth {
    rel_body: Vector3<f32>,
    distance: f32,
    /// The pad's orientation in the target's frame: pad to body FRD, and pad to NED.
    pad_body: UnitQuaternion<f32>,
    pad_ned: UnitQuaternion<f32>,
}

/// What the autopilot's stream suffered.
#[derive(Debug, Default, Clone, Copy)]
struct Damage {
    frames: u32,
    intact: u32,
    garbage_bursts: u32,
    truncated: u32,
    flipped: u32,
}

struct Run {
    tx: Vec<(u64, Vec<u8>)>,
    truth: BTreeMap<u64, Truth>,
    stats: CompanionStats,
    damage: Damage,
    first_link_frame_after: Option<u64>,
    reboot_at: Option<u64>,
}

fn in_window(w: Option<(u64, u64)>, t: u64) -> bool {
    w.is_some_and(|(a, b)| t >= a && t < b)
}

fn simulate(s: &Scenario) -> Run {
    let mut config = if s.auto {
        CompanionConfig::default()
    } else {
        CompanionConfig::with_profile(s.profile)
    };
    config.params.set(ParamId::CamYaw, s.cam_yaw_deg).unwrap();
    if s.vpe {
        config.params.set(ParamId::VpeEnable, 1.0).unwrap();
    }
    // What TD_CAM_YAW means: the downward camera turned about its optical axis.
    let mount = CameraMount::downward_rotated(s.cam_yaw_deg.to_radians()).unwrap();
    // The estimator's mount is the downward one; TD_CAM_YAW turns it (as the pipeline does).
    let mut companion = Companion::new(config);
    let mut estimator = FixEstimator::new();
    let mut ap = Autopilot::new();
    ap.kind = match s.profile {
        Profile::ArduPilot => MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        Profile::Px4 => MavAutopilot::MAV_AUTOPILOT_PX4,
    };
    ap.gimbal = s.gimbal;
    ap.next_hb = s.autopilot_from_us;
    ap.next_systime = ap.next_systime.max(s.autopilot_from_us);
    ap.next_timesync = ap.next_timesync.max(s.autopilot_from_us);
    let mut rng = Rng(0x5EED_0000 + s.name.len() as u64);
    let mut uplink: VecDeque<(u64, Vec<u8>)> = VecDeque::new();
    let mut tx = Vec::new();
    let mut truth = BTreeMap::new();
    let mut damage = Damage::default();
    let mut gcs_seq = 0u8;
    let mut params = s.params.clone();
    params.sort_by_key(|p| p.0);
    let mut params: VecDeque<_> = params.into();
    let mut next_exposure = 100_000u64;
    // (delivery time, exposure time, fix)
    let mut pending_frames: VecDeque<(u64, u64, Option<PadFix>)> = VecDeque::new();
    let mut out = [0u8; MAX_FRAME_LEN];
    let reboot_window = s.reboot_at.map(|r| (r, r + REBOOT_DOWN_US));
    let mut rebooted = false;
    let mut first_link_frame_after = None;

    let mut now = 0u64;
    while now < s.duration_us {
        // Companion -> autopilot.
        while uplink.front().is_some_and(|(t, _)| *t <= now) {
            let (_, bytes) = uplink.pop_front().unwrap();
            if !in_window(reboot_window, now) {
                ap.hear(&bytes, now);
            }
        }
        // The autopilot's own life.
        if let Some((r, back)) = reboot_window {
            if now >= r && !rebooted {
                rebooted = true;
                ap.outbox.clear();
            }
            if now == back {
                ap.reboot(r);
                ap.next_hb = now;
                ap.next_systime = now;
            }
        }
        let talking = !in_window(s.silent, now) && !in_window(reboot_window, now);
        if talking {
            ap.tick(now);
        }
        // Autopilot -> companion (damaged when asked).
        while ap.outbox.front().is_some_and(|(t, _)| *t <= now) {
            let (_, mut bytes) = ap.outbox.pop_front().unwrap();
            if !talking {
                continue;
            }
            damage.frames += 1;
            let mut intact = true;
            if s.corrupt {
                let r = rng.uniform();
                if r < 0.05 {
                    // Garbage before the frame (may contain start markers).
                    let n = 1 + (rng.next_u64() % 40) as usize;
                    let junk: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
                    companion.receive(&junk, now);
                    damage.garbage_bursts += 1;
                } else if r < 0.08 {
                    let cut = 1 + (rng.next_u64() as usize % (bytes.len() - 1));
                    bytes.truncate(cut);
                    damage.truncated += 1;
                    intact = false;
                } else if r < 0.11 {
                    let i = rng.next_u64() as usize % bytes.len();
                    bytes[i] ^= 1 << (rng.next_u64() % 8);
                    damage.flipped += 1;
                    intact = false;
                }
            }
            if intact {
                damage.intact += 1;
            }
            if first_link_frame_after.is_none()
                && (s.silent.is_some_and(|(_, b)| now >= b)
                    || reboot_window.is_some_and(|(_, b)| now >= b))
            {
                first_link_frame_after = Some(now);
            }
            // Deliver in two pieces to exercise reassembly.
            let half = bytes.len() / 2;
            companion.receive(&bytes[..half], now);
            companion.receive(&bytes[half..], now);
        }
        // Ground station.
        while params.front().is_some_and(|(t, _)| *t <= now) {
            let (_, action) = params.pop_front().unwrap();
            companion.receive(&gcs_message(&mut gcs_seq, action), now);
        }
        // Camera.
        if now >= next_exposure {
            let te = next_exposure;
            next_exposure += FRAME_PERIOD_US;
            let t = te as f32 * 1e-6;
            let att = vehicle_attitude(t);
            let rel_ned = pad_ned() - vehicle_position(t);
            let r_cam_ned = camera_to_ned_matrix(&att, &mount).transpose();
            let t_cam = r_cam_ned * rel_ned;
            let d = t_cam.norm();
            // Pad x east, pad y north, pad z up; then turned about its z by `pad_yaw`.
            let r_ned_pad = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0)
                * Rotation3::from_axis_angle(&Vector3::z_axis(), s.pad_yaw).into_inner();
            let pad_ned_q =
                UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r_ned_pad));
            let [w, x, y, z] = att.quaternion_wxyz();
            let body_to_ned = UnitQuaternion::new_normalize(Quaternion::new(w, x, y, z));
            truth.insert(
                te,
                Truth {
                    rel_body: att.ned_to_body(&rel_ned),
                    distance: d,
                    pad_body: body_to_ned.inverse() * pad_ned_q,
                    pad_ned: pad_ned_q,
                },
            );
            let fix = if in_window(s.lost, te) {
                None
            } else {
                let (sl, sr) = (SIGMA_LATERAL * d, SIGMA_RANGE * d);
                let noisy =
                    t_cam + Vector3::new(sl * rng.gauss(), sl * rng.gauss(), sr * rng.gauss());
                Some(pad_fix(r_cam_ned * r_ned_pad, noisy, d))
            };
            pending_frames.push_back((te + PROCESS_DELAY_US, te, fix));
        }
        while pending_frames.front().is_some_and(|(t, _, _)| *t <= now) {
            let (_, te, fix) = pending_frames.pop_front().unwrap();
            estimator.deliver(&mut companion, te, fix, now);
        }
        // Drain the companion.
        while let Some(n) = companion.poll_transmit(now, &mut out) {
            let bytes = out[..n].to_vec();
            uplink.push_back((now + UPLINK_DELAY_US, bytes.clone()));
            tx.push((now, bytes));
        }
        now += STEP_US;
    }
    Run {
        tx,
        truth,
        stats: companion.stats(),
        damage,
        first_link_frame_after,
        reboot_at: s.reboot_at,
    }
}

/// pymavlink's decoding of every frame, in order; `None` when pymavlink is not installed.
fn decode_with_pymavlink(name: &str, tx: &[(u64, Vec<u8>)]) -> Option<Vec<Value>> {
    let mut path = std::env::temp_dir();
    path.push(format!(
        "touchdown-companion-{name}-{}.bin",
        std::process::id()
    ));
    let bytes: Vec<u8> = tx.iter().flat_map(|(_, b)| b.iter().copied()).collect();
    std::fs::write(&path, &bytes).unwrap();
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/companion_decode.py");
    let output = Command::new("python3").arg(&script).arg(&path).output();
    let _ = std::fs::remove_file(&path);
    let output = match output {
        Ok(o) => o,
        Err(e) => {
            println!("skipping: pymavlink not installed (python3: {e})");
            return None;
        }
    };
    let stdout = String::from_utf8_lossy(&output.stdout);
    if output.status.code() == Some(3) {
        println!("skipping: pymavlink not installed");
        return None;
    }
    assert!(
        output.status.success(),
        "pymavlink refused the stream: {stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let mut msgs: Vec<Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let summary = msgs.pop().unwrap();
    assert_eq!(summary["_summary"], true);
    assert_eq!(summary["leftover"], 0, "undecoded bytes left");
    assert_eq!(
        msgs.len(),
        tx.len(),
        "pymavlink decoded {} messages from {} frames",
        msgs.len(),
        tx.len()
    );
    for m in &msgs {
        assert_ne!(m["_type"], "BAD_DATA");
        assert_eq!(m["_version"], 2, "{m}");
        assert_eq!(m["_src"], serde_json::json!([1, 191]), "{m}");
    }
    Some(msgs)
}

fn f(v: &Value, key: &str) -> f64 {
    v[key].as_f64().unwrap_or_else(|| panic!("no {key} in {v}"))
}

/// One decoded LANDING_TARGET matched to its frame.
#[derive(Debug, Clone, Copy)]
struct Target {
    tx_us: u64,
    exposure_us: u64,
    /// time_usec minus the exposure (0: our clock; the offset: the autopilot's).
    clock_us: i64,
    xyz: Vector3<f32>,
    angle_x: f32,
    angle_y: f32,
    distance: f32,
    /// The pad's orientation, decoded (normalised).
    q: UnitQuaternion<f32>,
}

/// Checks the LANDING_TARGETs' invariants and matches each to the frame it came from.
fn landing_targets(run: &Run, msgs: &[Value], profile: Profile) -> Vec<Target> {
    let mut out = Vec::new();
    for ((tx_us, _), m) in run.tx.iter().zip(msgs) {
        if m["_type"] != "LANDING_TARGET" {
            continue;
        }
        let frame = match profile {
            Profile::ArduPilot => 12, // MAV_FRAME_BODY_FRD
            Profile::Px4 => 1,        // MAV_FRAME_LOCAL_NED
        };
        assert_eq!(m["frame"], frame, "{m}");
        assert_eq!(m["_mlen"], 60, "extension fields missing: {m}");
        assert_eq!(m["type"], 2, "LANDING_TARGET_TYPE_VISION_FIDUCIAL: {m}");
        assert_eq!(m["position_valid"], 1, "{m}");
        assert!(f(m, "distance") > 0.0, "{m}");
        // The frame: processed at most ~200 ms before transmission, and time_usec is its
        // exposure in one of the clocks it may be in (ours, the autopilot's, the rebooted
        // autopilot's), to within 3 ms.
        let time_usec = m["time_usec"].as_u64().unwrap();
        let mut clocks = vec![0i64, AP_AHEAD_US as i64];
        if let Some(r) = run.reboot_at {
            clocks.push(-(r as i64));
        }
        let Some((exposure_us, clock_us)) = run
            .truth
            .range(tx_us.saturating_sub(200_000)..=*tx_us)
            .map(|(&te, _)| (te, time_usec as i64 - te as i64))
            .find(|&(_, c)| clocks.iter().any(|k| (c - k).abs() < 3_000))
        else {
            panic!("LANDING_TARGET at {tx_us} with time_usec {time_usec} matches no frame");
        };
        out.push(Target {
            tx_us: *tx_us,
            exposure_us,
            clock_us,
            xyz: Vector3::new(f(m, "x") as f32, f(m, "y") as f32, f(m, "z") as f32),
            angle_x: f(m, "angle_x") as f32,
            angle_y: f(m, "angle_y") as f32,
            distance: f(m, "distance") as f32,
            q: {
                let q: Vec<f32> = (0..4).map(|k| m["q"][k].as_f64().unwrap() as f32).collect();
                UnitQuaternion::new_normalize(Quaternion::new(q[0], q[1], q[2], q[3]))
            },
        });
    }
    out
}

/// Compares the targets with the truth: returns (RMS error per axis, worst error / allowed).
fn accuracy(run: &Run, targets: &[Target], profile: Profile) -> (Vector3<f32>, f32) {
    let mut sq = Vector3::zeros();
    let mut worst = 0.0f32;
    for t in targets {
        let truth = run.truth[&t.exposure_us];
        let expected = match profile {
            Profile::ArduPilot => truth.rel_body,
            Profile::Px4 => pad_ned(),
        };
        let err = t.xyz - expected;
        // "Within the pose's accuracy": 4 sigma of one fix's range noise (the filtered value
        // must do better), at least 5 cm.
        let allowed = (4.0 * SIGMA_RANGE * truth.distance).max(0.05);
        worst = worst.max(err.amax() / allowed);
        sq += err.component_mul(&err);
        // angle_x/angle_y/distance consistent with x/y/z (default mount: camera x = body y,
        // camera y = -body x, camera z = body z).
        // ArduPilot's line of sight from the angles (AC_PrecLand_MAVLink, position_valid 0):
        // (-tan(angle_y), tan(angle_x), 1) normalised, body FRD, whatever the mount.
        let los = Vector3::new(-t.angle_y.tan(), t.angle_x.tan(), 1.0).normalize();
        // The pad's orientation: its yaw within a degree (the whole rotation too).
        let want_q = match profile {
            Profile::ArduPilot => truth.pad_body,
            Profile::Px4 => truth.pad_ned,
        };
        let yaw_err = (t.q.euler_angles().2 - want_q.euler_angles().2).to_degrees();
        let yaw_err = (yaw_err + 540.0).rem_euclid(360.0) - 180.0;
        assert!(yaw_err.abs() < 1.0, "q yaw off by {yaw_err} deg: {t:?}");
        assert!(t.q.angle_to(&want_q).to_degrees() < 1.0, "{t:?}");
        if profile == Profile::ArduPilot {
            let b = t.xyz;
            assert!((los - b / t.distance).amax() < 1e-4, "{los} {t:?}");
            assert!((t.distance - b.norm()).abs() < 1e-3, "{t:?}");
        } else {
            // The angles are the body vector at the exposure (the autopilot's attitude).
            assert!(
                (los - truth.rel_body.normalize()).amax() < 0.02,
                "{los} {t:?}"
            );
            assert!(
                (t.distance - truth.distance).abs() < 0.1 * truth.distance,
                "{t:?}"
            );
        }
    }
    let n = targets.len().max(1) as f32;
    ((sq / n).map(f32::sqrt), worst)
}

fn report(name: &str, run: &Run, msgs: &[Value]) {
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    for m in msgs {
        *counts
            .entry(m["_type"].as_str().unwrap().to_string())
            .or_default() += 1;
    }
    let s = &run.stats;
    println!(
        "[{name}] sent {} frames ({} bytes): {counts:?}",
        s.tx_frames, s.tx_bytes
    );
    println!(
        "[{name}] rx: {} bytes, {} frames ok, {} bad CRC, {} garbage bytes, {} unknown; \
         timesync {} samples (offset {:?} us, source {:?}); reboots {}; targets: {} sent, \
         {} expired, {} no estimate, {} no vehicle state",
        s.link.bytes,
        s.link.frames,
        s.link.bad_crc,
        s.link.garbage_bytes,
        s.link.unknown,
        s.timesync_samples,
        s.clock_offset_us,
        s.time_source,
        s.autopilot_reboots,
        s.landing_targets,
        s.targets_expired,
        s.no_estimate,
        s.no_vehicle_state
    );
}

fn heartbeats_ok(run: &Run, msgs: &[Value], duration_us: u64) {
    let hb: Vec<u64> = run
        .tx
        .iter()
        .zip(msgs)
        .filter(|(_, m)| m["_type"] == "HEARTBEAT")
        .map(|((t, _), m)| {
            assert_eq!(m["type"], 18, "MAV_TYPE_ONBOARD_CONTROLLER");
            assert_eq!(m["autopilot"], 8, "MAV_AUTOPILOT_INVALID");
            *t
        })
        .collect();
    assert_eq!(hb.len() as u64, duration_us.div_ceil(1_000_000), "{hb:?}");
    for w in hb.windows(2) {
        assert!((w[1] - w[0]).abs_diff(1_000_000) <= 2_000, "{hb:?}");
    }
}

#[test]
fn ardupilot_profile_pymavlink() {
    let mut s = Scenario::new("ardupilot", Profile::ArduPilot);
    s.vpe = true;
    s.params = vec![
        (2_000_000, ParamAction::RequestList),
        (3_000_000, ParamAction::ReadName("TD_RATE_HZ")),
        (3_100_000, ParamAction::ReadIndex(2)),
        (4_000_000, ParamAction::Set("TD_RATE_HZ", 1.0e9)),
        (4_100_000, ParamAction::Set("TD_TAG_SIZE", f32::NAN)),
        (4_200_000, ParamAction::Set("TD_MAX_HAMMING", 1.5)),
        (4_300_000, ParamAction::Set("TD_TAG_SIZE", 0.5)),
        (4_400_000, ParamAction::Set("TD_NO_SUCH", 1.0)),
    ];
    let run = simulate(&s);
    let Some(msgs) = decode_with_pymavlink(s.name, &run.tx) else {
        return;
    };
    report(s.name, &run, &msgs);
    heartbeats_ok(&run, &msgs, s.duration_us);
    let targets = landing_targets(&run, &msgs, s.profile);
    // 30 Hz for 8 s, less the first frames (track confirmation).
    assert!(targets.len() > 220, "{} targets", targets.len());
    let (rms, worst) = accuracy(&run, &targets, s.profile);
    println!(
        "[{}] {} LANDING_TARGET (BODY_FRD): RMS error x {:.3} y {:.3} z {:.3} m; worst {:.2} of the allowed 4 sigma",
        s.name,
        targets.len(),
        rms.x,
        rms.y,
        rms.z,
        worst
    );
    assert!(worst <= 1.0);
    // time_usec: the autopilot's clock once TIMESYNC has an answer (after ~0.5 s).
    let synced: Vec<_> = targets.iter().filter(|t| t.tx_us > 1_500_000).collect();
    assert!(!synced.is_empty());
    for t in &synced {
        assert!(
            (t.clock_us - AP_AHEAD_US as i64).abs() <= 1_000,
            "time_usec not in the autopilot clock: {t:?}"
        );
    }
    let worst_clock = synced
        .iter()
        .map(|t| (t.clock_us - AP_AHEAD_US as i64).abs())
        .max()
        .unwrap();
    println!(
        "[{}] time_usec vs autopilot clock: worst {worst_clock} us",
        s.name
    );
    // Parameters.
    let pv: Vec<(u64, &Value)> = run
        .tx
        .iter()
        .zip(&msgs)
        .filter(|(_, m)| m["_type"] == "PARAM_VALUE")
        .map(|((t, _), m)| (*t, m))
        .collect();
    let listed: Vec<_> = pv
        .iter()
        .filter(|(t, _)| (2_000_000..3_000_000).contains(t))
        .collect();
    assert_eq!(listed.len(), PARAM_COUNT, "the full list");
    for (k, (_, m)) in listed.iter().enumerate() {
        assert_eq!(m["param_index"], k);
        assert_eq!(m["param_count"], PARAM_COUNT);
        assert_eq!(m["param_type"], 9, "MAV_PARAM_TYPE_REAL32");
    }
    let span = listed.last().unwrap().0 - listed.first().unwrap().0;
    assert!(
        span >= (PARAM_COUNT as u64 - 1) * 19_000,
        "paced: {span} us"
    );
    let by_time = |lo: u64| -> Vec<&Value> {
        pv.iter()
            .filter(|(t, _)| (lo..lo + 50_000).contains(t))
            .map(|(_, m)| *m)
            .collect()
    };
    assert_eq!(by_time(3_000_000)[0]["param_id"], "TD_RATE_HZ");
    assert_eq!(by_time(3_100_000)[0]["param_id"], "TD_TAG_SIZE");
    // Absurd values: answered with the old value.
    let r = by_time(4_000_000);
    assert_eq!(
        (r[0]["param_id"].clone(), f(r[0], "param_value")),
        ("TD_RATE_HZ".into(), 30.0)
    );
    let r = by_time(4_100_000);
    assert_eq!(f(r[0], "param_value"), 0.0, "{}", r[0]);
    let r = by_time(4_200_000);
    assert_eq!(f(r[0], "param_value"), 1.0);
    let r = by_time(4_300_000);
    assert!(
        (f(r[0], "param_value") - 0.5).abs() < 1e-6,
        "accepted: {}",
        r[0]
    );
    assert!(by_time(4_400_000).is_empty(), "unknown names get no answer");
    assert_eq!(run.stats.param_sets_rejected, 3);
    assert_eq!(run.stats.param_sets_accepted, 1);
    // VISION_POSITION_ESTIMATE: the vehicle in the pad-centred NED frame, with covariance.
    let vpe: Vec<&Value> = msgs
        .iter()
        .filter(|m| m["_type"] == "VISION_POSITION_ESTIMATE")
        .collect();
    assert!(vpe.len() > 200);
    let last = vpe.last().unwrap();
    let t_end = *run.truth.keys().last().unwrap() as f32 * 1e-6;
    let truth = vehicle_position(t_end) - pad_ned();
    assert!((f(last, "x") as f32 - truth.x).abs() < 0.3, "{last}");
    assert!((f(last, "z") as f32 - truth.z).abs() < 0.5, "{last}");
    assert_eq!(last["covariance"].as_array().unwrap().len(), 21);
    assert!(last["covariance"][0].as_f64().unwrap() > 0.0, "{last}");
    // TIMESYNC answers to the autopilot's requests, SET_MESSAGE_INTERVAL requests.
    let answers = msgs
        .iter()
        .filter(|m| m["_type"] == "TIMESYNC" && m["tc1"].as_i64() != Some(0))
        .count();
    assert!(answers >= 7, "{answers} TIMESYNC answers");
    let requests = msgs
        .iter()
        .filter(|m| m["_type"] == "COMMAND_LONG" && m["command"] == 511)
        .count();
    assert!(requests >= 1);
    assert!(run.stats.interval_acks_accepted >= 1);
}

#[test]
fn px4_profile_pymavlink() {
    let s = Scenario::new("px4", Profile::Px4);
    let run = simulate(&s);
    let Some(msgs) = decode_with_pymavlink(s.name, &run.tx) else {
        return;
    };
    report(s.name, &run, &msgs);
    heartbeats_ok(&run, &msgs, s.duration_us);
    let targets = landing_targets(&run, &msgs, s.profile);
    assert!(targets.len() > 200, "{} targets", targets.len());
    let (rms, worst) = accuracy(&run, &targets, s.profile);
    println!(
        "[{}] {} LANDING_TARGET (LOCAL_NED): RMS error x {:.3} y {:.3} z {:.3} m; worst {:.2} of the allowed 4 sigma",
        s.name,
        targets.len(),
        rms.x,
        rms.y,
        rms.z,
        worst
    );
    assert!(worst <= 1.0);
    // PX4 converts time_usec itself (its TIMESYNC with us): our exposure time, exactly.
    for t in &targets {
        assert_eq!(t.clock_us, 0, "{t:?}");
    }
    // Both streams requested.
    let requested: Vec<f64> = msgs
        .iter()
        .filter(|m| m["_type"] == "COMMAND_LONG" && m["command"] == 511)
        .map(|m| f(m, "param1"))
        .collect();
    assert!(
        requested.contains(&31.0) && requested.contains(&32.0),
        "{requested:?}"
    );
    // Every answer to PX4's TIMESYNC requests goes out in the millisecond its request
    // arrived (tc1 is our time at receipt, in ns), whatever else was waiting.
    let answers: Vec<(u64, i64)> = run
        .tx
        .iter()
        .zip(&msgs)
        .filter(|(_, m)| m["_type"] == "TIMESYNC" && m["tc1"].as_i64() != Some(0))
        .map(|((t, _), m)| (*t, m["tc1"].as_i64().unwrap()))
        .collect();
    assert!(answers.len() >= 7, "{answers:?}");
    for (tx_us, tc1) in answers {
        assert_eq!(tx_us as i64, tc1 / 1000, "answered late");
    }
}

/// The STATUSTEXTs sent, in order.
fn status_texts(msgs: &[Value]) -> Vec<String> {
    msgs.iter()
        .filter(|m| m["_type"] == "STATUSTEXT")
        .map(|m| {
            m["text"]
                .as_str()
                .unwrap()
                .trim_end_matches('\0')
                .to_string()
        })
        .collect()
}

#[test]
fn auto_profile_follows_the_autopilot_heartbeat_not_a_gimbal() {
    for profile in [Profile::ArduPilot, Profile::Px4] {
        let (name, announcement) = match profile {
            Profile::ArduPilot => (
                "auto-ardupilot",
                "touchdown: profile auto: ArduPilot (BODY_FRD)",
            ),
            Profile::Px4 => ("auto-px4", "touchdown: profile auto: PX4 (LOCAL_NED)"),
        };
        let mut s = Scenario::new(name, profile);
        s.auto = true;
        // A gimbal heartbeats from the start (before the autopilot is heard, and just before
        // each of its heartbeats); the autopilot's first heartbeat comes at 1 s.
        s.gimbal = true;
        s.autopilot_from_us = 1_000_000;
        // A pad turned by 30 degrees under a camera turned by 90 (TD_CAM_YAW).
        s.pad_yaw = 30f32.to_radians();
        s.cam_yaw_deg = 90.0;
        let run = simulate(&s);
        let Some(msgs) = decode_with_pymavlink(s.name, &run.tx) else {
            return;
        };
        report(s.name, &run, &msgs);
        // The frame each stack takes (checked per target by `landing_targets`), and the pad's
        // orientation and the angles (checked per target by `accuracy`).
        let targets = landing_targets(&run, &msgs, profile);
        assert!(targets.len() > 180, "{} targets", targets.len());
        let (_, worst) = accuracy(&run, &targets, profile);
        assert!(worst <= 1.0);
        // Nothing until the autopilot said what it is (its heartbeat arrives at 1.003 s).
        let first = targets.first().unwrap().tx_us;
        assert!(
            first >= 1_003_000,
            "target at {first} us before the autopilot"
        );
        assert!(run.stats.no_profile >= 20, "{}", run.stats.no_profile);
        // The autopilot is 1/1, the gimbal never took over, the choice announced once.
        assert_eq!(run.stats.autopilot, Some((1, 1)));
        assert_eq!(status_texts(&msgs), vec![announcement.to_string()]);
        println!(
            "[{name}] first target at {:.3} s; {} frames with a fix before the autopilot was \
             identified; announced: {announcement}",
            first as f64 * 1e-6,
            run.stats.no_profile
        );
        heartbeats_ok(&run, &msgs, s.duration_us);
    }
}

/// A TIMESYNC request is answered by the very next frame out, ahead of a pending target and a
/// parameter list being streamed.
#[test]
fn timesync_reply_goes_ahead_of_the_queue() {
    let mut companion = Companion::new(CompanionConfig::default());
    let mut ap_seq = 0u8;
    let mut gcs_seq = 0u8;
    let mut out = [0u8; MAX_FRAME_LEN];
    let ardupilot = heartbeat(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
    companion.receive(&encode(&mut ap_seq, 1, 1, &ardupilot), 0);
    assert_eq!(companion.profile(), Some(Profile::ArduPilot));
    let mut tx: Vec<(u64, Vec<u8>)> = Vec::new();
    let drain = |c: &mut Companion, now: u64, tx: &mut Vec<(u64, Vec<u8>)>, out: &mut [u8]| {
        while let Some(n) = c.poll_transmit(now, out) {
            tx.push((now, out[..n].to_vec()));
        }
    };
    drain(&mut companion, 0, &mut tx, &mut out);
    // Frames of a pad straight below until a target is pending (no attitude: camera-frame
    // tracker), a parameter list requested, nothing drained.
    let fix = PadFix {
        pose: Pose {
            rotation: Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0),
            translation: Vector3::new(0.1, 0.2, 5.0),
        },
        covariance: Matrix6::identity() * 1e-4,
        markers_used: 1,
        reprojection_rms_px: 0.3,
        alternative_rms_px: f32::INFINITY,
    };
    let mut now = 10_000;
    let mut queued = false;
    let mut estimator = FixEstimator::new();
    for _ in 0..30 {
        now += FRAME_PERIOD_US;
        let outcome = estimator.deliver(&mut companion, now - PROCESS_DELAY_US, Some(fix), now);
        queued = outcome == TargetOutcome::TargetQueued;
        if queued {
            break;
        }
        drain(&mut companion, now, &mut tx, &mut out);
    }
    assert!(queued);
    companion.receive(&gcs_message(&mut gcs_seq, ParamAction::RequestList), now);
    // Let the list start filling the queue (paced), then the autopilot's TIMESYNC request.
    let ts1 = 123_456_789_000i64;
    let request = MavMessage::TIMESYNC(TIMESYNC_DATA {
        tc1: 0,
        ts1,
        target_system: 0,
        target_component: 0,
    });
    companion.receive(&encode(&mut ap_seq, 1, 1, &request), now);
    let first = tx.len();
    drain(&mut companion, now, &mut tx, &mut out);
    let Some(msgs) = decode_with_pymavlink("timesync-first", &tx) else {
        return;
    };
    let after: Vec<&Value> = msgs[first..].iter().collect();
    assert!(after.len() >= 3, "{after:?}");
    assert_eq!(after[0]["_type"], "TIMESYNC", "{after:?}");
    assert_eq!(after[0]["ts1"].as_i64(), Some(ts1));
    assert_eq!(after[0]["tc1"].as_i64(), Some(now as i64 * 1000));
    // The rest still goes out: the target, then the queue (parameters among it).
    assert_eq!(after[1]["_type"], "LANDING_TARGET", "{after:?}");
    assert!(after.iter().any(|m| m["_type"] == "PARAM_VALUE"));
}

#[test]
fn faults_garbage_truncation_bad_crc() {
    let mut s = Scenario::new("faults", Profile::Px4);
    s.corrupt = true;
    s.duration_us = 10_000_000;
    let run = simulate(&s);
    let d = run.damage;
    let st = run.stats;
    println!(
        "[faults] autopilot sent {} frames: {} intact, {} truncated, {} bit-flipped, {} garbage bursts inserted",
        d.frames, d.intact, d.truncated, d.flipped, d.garbage_bursts
    );
    println!(
        "[faults] companion: {} frames accepted, {} bad CRC, {} garbage bytes skipped, {} unknown; \
         dropped {} = exactly the damaged ones",
        st.link.frames,
        st.link.bad_crc,
        st.link.garbage_bytes,
        st.link.unknown,
        d.frames - st.link.frames
    );
    assert!(d.truncated > 10 && d.flipped > 10 && d.garbage_bursts > 10);
    // Every intact frame is found; no damaged one gets through.
    assert_eq!(st.link.frames, d.intact);
    assert!(st.link.bad_crc >= d.truncated + d.flipped - 5);
    let Some(msgs) = decode_with_pymavlink(s.name, &run.tx) else {
        return;
    };
    report(s.name, &run, &msgs);
    let targets = landing_targets(&run, &msgs, s.profile);
    assert!(targets.len() > 250, "{} targets", targets.len());
    let (_, worst) = accuracy(&run, &targets, s.profile);
    assert!(worst <= 1.0);
}

/// Longest time without a LANDING_TARGET from `from` on, and the first target after `from`.
fn first_target_after(targets: &[Target], from: u64) -> Option<u64> {
    targets.iter().map(|t| t.tx_us).find(|&t| t >= from)
}

#[test]
fn autopilot_silent_for_ten_seconds() {
    for profile in [Profile::ArduPilot, Profile::Px4] {
        let name = match profile {
            Profile::ArduPilot => "silent-ardupilot",
            Profile::Px4 => "silent-px4",
        };
        let mut s = Scenario::new(name, profile);
        s.duration_us = 18_000_000;
        s.silent = Some((4_000_000, 14_000_000));
        let run = simulate(&s);
        let Some(msgs) = decode_with_pymavlink(s.name, &run.tx) else {
            return;
        };
        report(s.name, &run, &msgs);
        let targets = landing_targets(&run, &msgs, profile);
        let during = targets
            .iter()
            .filter(|t| t.exposure_us >= 4_100_000 && t.exposure_us < 14_000_000)
            .count();
        let back = run.first_link_frame_after.unwrap();
        let first = first_target_after(&targets, 14_000_000).unwrap();
        println!(
            "[{name}] {during} targets while the autopilot was silent for 10 s; link back at \
             {:.3} s, first target {:.0} ms later",
            back as f64 * 1e-6,
            (first.saturating_sub(back)) as f64 * 1e-3
        );
        match profile {
            // No vehicle state needed: the camera-frame tracker carries on.
            Profile::ArduPilot => assert!(during > 280, "{during}"),
            // Vehicle state stale: nothing (the last one within 60 ms + latency of the silence).
            Profile::Px4 => {
                assert_eq!(during, 0);
                assert!(first - back <= 1_000_000, "recovery {} us", first - back);
            }
        }
        let (_, worst) = accuracy(&run, &targets, profile);
        assert!(worst <= 1.0);
        heartbeats_ok(&run, &msgs, s.duration_us);
    }
}

#[test]
fn autopilot_reboot_resets_the_clock() {
    for profile in [Profile::ArduPilot, Profile::Px4] {
        let name = match profile {
            Profile::ArduPilot => "reboot-ardupilot",
            Profile::Px4 => "reboot-px4",
        };
        let mut s = Scenario::new(name, profile);
        s.duration_us = 10_000_000;
        s.reboot_at = Some(4_000_000);
        let run = simulate(&s);
        let Some(msgs) = decode_with_pymavlink(s.name, &run.tx) else {
            return;
        };
        report(s.name, &run, &msgs);
        assert_eq!(run.stats.autopilot_reboots, 1);
        let targets = landing_targets(&run, &msgs, profile);
        let back = run.first_link_frame_after.unwrap();
        // After the reboot the autopilot's clock is ours minus 4 s.
        let new_offset = -4_000_000i64;
        let recovered = targets
            .iter()
            .find(|t| {
                t.tx_us >= back
                    && match profile {
                        Profile::ArduPilot => (t.clock_us - new_offset).abs() <= 1_000,
                        Profile::Px4 => true,
                    }
            })
            .map(|t| t.tx_us)
            .unwrap();
        println!(
            "[{name}] reboot: link back at {:.3} s, first correct target {:.0} ms later",
            back as f64 * 1e-6,
            (recovered - back) as f64 * 1e-3
        );
        assert!(recovered - back <= 1_000_000);
        if profile == Profile::ArduPilot {
            // Once re-synchronised, never the old clock again.
            for t in targets.iter().filter(|t| t.tx_us >= recovered) {
                assert!((t.clock_us - new_offset).abs() <= 1_000, "{t:?}");
            }
        }
        let (_, worst) = accuracy(&run, &targets, profile);
        assert!(worst <= 1.0);
    }
}

#[test]
fn target_lost_sends_nothing() {
    let mut s = Scenario::new("lost", Profile::ArduPilot);
    s.lost = Some((3_000_000, 4_500_000));
    let run = simulate(&s);
    let Some(msgs) = decode_with_pymavlink(s.name, &run.tx) else {
        return;
    };
    report(s.name, &run, &msgs);
    let targets = landing_targets(&run, &msgs, s.profile);
    let during = targets
        .iter()
        .filter(|t| t.exposure_us >= 3_000_000 && t.exposure_us < 4_500_000)
        .count();
    let last_before = targets
        .iter()
        .filter(|t| t.exposure_us < 3_000_000)
        .map(|t| t.tx_us)
        .max()
        .unwrap();
    let first_after = first_target_after(&targets, 4_500_000).unwrap();
    println!(
        "[lost] pad lost 3.0-4.5 s: {during} targets for lost frames; last target at {:.3} s, \
         next at {:.3} s ({:.0} ms after the pad is back)",
        last_before as f64 * 1e-6,
        first_after as f64 * 1e-6,
        (first_after - 4_500_000) as f64 * 1e-3
    );
    assert_eq!(during, 0);
    assert!(last_before < 3_000_000 + PROCESS_DELAY_US + 5_000);
    assert!(first_after - 4_500_000 < 1_000_000);
}

/// Sends `action` from the ground station at `now` and returns every PARAM_VALUE the
/// companion answers with (name, value), decoded by our own parser.
fn ground_station(
    companion: &mut Companion,
    seq: &mut u8,
    action: ParamAction,
    now: u64,
) -> Vec<(String, f32)> {
    companion.receive(&gcs_message(seq, action), now);
    let mut out = [0u8; MAX_FRAME_LEN];
    let mut parser = FrameParser::new();
    let mut values = Vec::new();
    while let Some(n) = companion.poll_transmit(now, &mut out) {
        parser.push(&out[..n], |raw| {
            if let Ok(MavMessage::PARAM_VALUE(v)) = raw.decode() {
                values.push((name_str(&v.param_id[..]).to_string(), v.param_value));
            }
        });
    }
    values
}

#[test]
fn camera_params_are_range_checked_applied_and_persisted() {
    let mut companion = Companion::new(CompanionConfig::default());
    let mut seq = 0u8;
    let mut now = 1_000_000u64;
    // (name, value sent, value answered: the new one if accepted, else the old one)
    let sets: [(&str, f32, f32); 17] = [
        ("TD_EXP_MAX_US", 2_000.0, 2_000.0),
        ("TD_EXP_MAX_US", 50.0, 2_000.0),     // below 100 us
        ("TD_EXP_MAX_US", 40_000.0, 2_000.0), // above 33 ms
        ("TD_EXP_MAX_US", 1_500.5, 2_000.0),  // an integer
        ("TD_GAIN_MAX", 2.5, 2.5),
        ("TD_GAIN_MAX", 0.5, 2.5),  // below unity
        ("TD_GAIN_MAX", 40.0, 2.5), // above 32x
        ("TD_GAIN_MAX", f32::NAN, 2.5),
        ("TD_EXP_TARGET", 90.0, 90.0),
        ("TD_EXP_TARGET", 250.0, 90.0), // above 220
        ("TD_EXP_TARGET", 30.0, 90.0),  // below 40
        ("TD_TAG_SIZE", 0.01, 0.0),     // between "unset" and 2 cm
        ("TD_TAG_SIZE", 0.625, 0.625),
        ("TD_TAG_SIZE", -0.625, 0.625),
        ("TD_TAG_SIZE", f32::INFINITY, 0.625),
        ("TD_MAX_HAMMING", 2.0, 2.0),
        ("TD_MAX_HAMMING", 4.0, 2.0), // above 3
    ];
    for (name, sent, answered) in sets {
        now += 10_000;
        let replies = ground_station(&mut companion, &mut seq, ParamAction::Set(name, sent), now);
        assert_eq!(
            replies,
            vec![(name.to_string(), answered)],
            "{name} = {sent}"
        );
    }
    let stats = companion.stats();
    assert_eq!(
        (stats.param_sets_accepted, stats.param_sets_rejected),
        (5, 12)
    );

    // What the firmware's vision task gets.
    let settings = PipelineSettings::from_params(companion.params());
    assert_eq!(
        settings,
        PipelineSettings {
            max_hamming: 2,
            tag_size_m: Some(0.625),
            exposure: AutoExposureLimits {
                target: 90,
                max_exposure_us: 2_000,
                max_gain: GainX16(40),
                ..AutoExposureLimits::default()
            },
            cam_yaw_deg: 0.0,
        }
    );
    assert_eq!(
        settings
            .detector_config(DetectorConfig::default())
            .max_hamming,
        2
    );
    // The nested pad (largest marker 1.25 m) printed at half size.
    let pad = settings.pad(&designs::NESTED).unwrap();
    assert_eq!(settings.pad_scale(&designs::NESTED), 0.5);
    assert_eq!(
        pad.find("tag36h11", 0).map(|m| (m.size, m.y)),
        Some((0.625, 0.7))
    );
    // The defaults are the compile-time ones.
    let defaults = PipelineSettings::from_params(&ParamSet::default());
    assert_eq!(defaults.exposure, AutoExposureLimits::default());
    assert_eq!(defaults.pad(&designs::NESTED), Ok(designs::NESTED));

    // Saved to the flash log the way the firmware saves (core's `Store`, after a first save
    // of the defaults), restored at the next boot.
    let geometry = persist::Geometry::new(8 * SLOT_LEN as u32).unwrap();
    let mut flash = RamSectors::new(geometry);
    let mut fresh = ParamSet::default();
    let (mut store, boot) =
        persist::Store::open(geometry, |s, o, b| flash.read(s, o, b), &mut fresh);
    assert_eq!(boot.restored, None);
    block_on(store.save(&mut flash, &ParamSet::default())).unwrap();
    block_on(store.save(&mut flash, companion.params())).unwrap();
    let mut restored = ParamSet::default();
    let (_, boot) = persist::Store::open(geometry, |s, o, b| flash.read(s, o, b), &mut restored);
    let found = boot.restored.expect("a valid slot");
    assert_eq!(found.key, persist::SlotKey::Seq(1));
    assert_eq!(usize::from(found.report.applied), PARAM_COUNT);
    assert_eq!((found.report.rejected, found.report.unknown), (0, 0));
    assert_eq!(boot.bad_slots, 0);
    assert_eq!(&restored, companion.params());
    assert_eq!(PipelineSettings::from_params(&restored), settings);

    // After the reboot a ground station reads the new parameters back, by name and by index.
    let mut rebooted = Companion::new(CompanionConfig {
        params: restored,
        ..CompanionConfig::default()
    });
    let mut seq = 0u8;
    assert_eq!(
        ground_station(
            &mut rebooted,
            &mut seq,
            ParamAction::ReadName("TD_EXP_MAX_US"),
            100_000
        ),
        vec![("TD_EXP_MAX_US".to_string(), 2_000.0)]
    );
    for (id, want) in [
        (ParamId::ExpMaxUs, 2_000.0),
        (ParamId::GainMax, 2.5),
        (ParamId::ExpTarget, 90.0),
    ] {
        let i = id.index() as i16;
        assert_eq!(
            ground_station(&mut rebooted, &mut seq, ParamAction::ReadIndex(i), 200_000),
            vec![(id.def().name.to_string(), want)]
        );
    }
}

/// Two flash sectors in RAM for [`persist::Store`]: erased is 0xFF, a program may only go to
/// erased bytes (what the H7 requires; the test fails if the store ever programs over data).
struct RamSectors {
    len: usize,
    bytes: Vec<u8>,
}

impl RamSectors {
    fn new(geometry: persist::Geometry) -> Self {
        let len = geometry.sector_len() as usize;
        RamSectors {
            len,
            bytes: vec![ERASED; persist::SECTORS * len],
        }
    }

    fn read(&self, sector: usize, offset: u32, buf: &mut [u8]) -> bool {
        let start = sector * self.len + offset as usize;
        match self.bytes.get(start..start + buf.len()) {
            Some(src) => {
                buf.copy_from_slice(src);
                true
            }
            None => false,
        }
    }
}

impl SlotFlash for RamSectors {
    async fn erase(&mut self, sector: usize) -> Result<(), FlashFailed> {
        let start = sector * self.len;
        self.bytes[start..start + self.len].fill(ERASED);
        Ok(())
    }

    async fn write(&mut self, sector: usize, offset: u32, bytes: &[u8]) -> Result<(), FlashFailed> {
        let start = sector * self.len + offset as usize;
        let dst = &mut self.bytes[start..start + bytes.len()];
        assert!(dst.iter().all(|&b| b == ERASED), "programmed over data");
        dst.copy_from_slice(bytes);
        Ok(())
    }
}

/// Runs a future that never waits (the RAM flash is ready at once) to completion.
fn block_on<F: std::future::Future>(future: F) -> F::Output {
    use std::task::{Context, Poll, Waker};
    let mut future = std::pin::pin!(future);
    let mut cx = Context::from_waker(Waker::noop());
    match future.as_mut().poll(&mut cx) {
        Poll::Ready(output) => output,
        Poll::Pending => panic!("the RAM flash never waits"),
    }
}
