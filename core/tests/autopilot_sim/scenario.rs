//! The companion tests' scenarios: a vehicle flies a known path ([`VehiclePath::APPROACH`]:
//! descending, rolling, pitching, turning) over a pad at a known NED position. Every 33 ms a
//! camera frame is "exposed"; 25 ms later its pad fix (the true camera-frame pad position plus
//! Gaussian noise with the covariance the fix reports) reaches the board's estimator stage
//! ([`super::FixEstimator`]) and then `Companion::on_estimate`. The simulated autopilot
//! ([`Autopilot`]) runs in its own clock, 1000 s ahead of ours, over a link with 2-3 ms
//! latency. Faults: garbage, truncated frames and flipped bits on the autopilot's stream; a
//! reboot (clock restarts, streams forgotten); 10 s of silence; the pad lost. A ground station
//! sends PARAM_* requests at set times.
//!
//! [`simulate`] flies one [`Scenario`] and returns everything the companion sent, with the
//! truth of every frame ([`Run`]), for `decoded` to check.

use std::collections::{BTreeMap, VecDeque};

use nalgebra::{Quaternion, Rotation3, UnitQuaternion, Vector3};
use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavMessage, MavParamType, PARAM_REQUEST_LIST_DATA, PARAM_REQUEST_READ_DATA,
    PARAM_SET_DATA,
};
use touchdown_core::companion::{Companion, CompanionConfig, CompanionStats, Profile};
use touchdown_core::filter::CameraMount;
use touchdown_core::params::ParamId;

use super::{
    encode, Autopilot, AutopilotClock, Exposure, Flight, LinkDelay, Rng, VehiclePath, STEP_US,
};

/// The autopilot booted this long before the companion (its clock = ours + this).
pub const AP_AHEAD_US: u64 = 1_000_000_000;
const UPLINK_DELAY_US: u64 = 2_000; // companion -> autopilot
const DOWNLINK_DELAY_US: u64 = 3_000; // autopilot -> companion
/// How long a rebooting autopilot is down.
pub const REBOOT_DOWN_US: u64 = 1_500_000;

/// A ground station's request.
#[derive(Debug, Clone, Copy)]
pub enum ParamAction {
    RequestList,
    ReadName(&'static str),
    ReadIndex(i16),
    Set(&'static str, f32),
}

/// One flight of the companion tests: the autopilot's stack, how long, and what goes wrong.
#[derive(Debug, Clone)]
pub struct Scenario {
    pub name: &'static str,
    pub profile: Profile,
    pub duration_us: u64,
    /// The autopilot sends nothing in [start, end).
    pub silent: Option<(u64, u64)>,
    /// The autopilot reboots at this time (down for REBOOT_DOWN_US, clock restarts).
    pub reboot_at: Option<u64>,
    /// No pad in frames exposed in [start, end).
    pub lost: Option<(u64, u64)>,
    pub corrupt: bool,
    pub params: Vec<(u64, ParamAction)>,
    /// TD_VPE_EN: bit 0 VISION_POSITION_ESTIMATE, bit 1 the velocity.
    pub vision: f32,
    /// TD_PROFILE auto (the default) instead of forcing `profile`; the simulated autopilot's
    /// HEARTBEAT then says `profile`'s autopilot.
    pub auto: bool,
    /// A MAVLink gimbal (component 154, MAV_AUTOPILOT_GENERIC) heartbeats too, just before
    /// each of the autopilot's.
    pub gimbal: bool,
    /// The autopilot's first HEARTBEAT (and everything else of it) from this time on.
    pub autopilot_from_us: u64,
    /// The pad turned about its z axis by this, radians (0: pad x east, pad y north).
    pub pad_yaw: f32,
    /// TD_CAM_YAW, degrees (the simulated camera is turned the same way).
    pub cam_yaw_deg: f32,
    /// The simulated camera's mount tilted by this roll and pitch, degrees, which the board
    /// is not told (TD_CAM_ROLL and TD_CAM_PITCH stay 0).
    pub mount_error_deg: (f32, f32),
}

impl Scenario {
    /// An 8 s flight of `profile` without faults or ground station.
    pub fn new(name: &'static str, profile: Profile) -> Self {
        Scenario {
            name,
            profile,
            duration_us: 8_000_000,
            silent: None,
            reboot_at: None,
            lost: None,
            corrupt: false,
            params: Vec::new(),
            vision: 0.0,
            auto: false,
            gimbal: false,
            autopilot_from_us: 0,
            pad_yaw: 0.0,
            cam_yaw_deg: 0.0,
            mount_error_deg: (0.0, 0.0),
        }
    }
}

/// The ground station: PARAM_* requests (system 255, component 190).
pub fn gcs_message(seq: &mut u8, action: ParamAction) -> Vec<u8> {
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
pub struct Truth {
    pub rel_body: Vector3<f32>,
    pub distance: f32,
    /// The pad's orientation in the target's frame: pad to body FRD, and pad to NED.
    pub pad_body: UnitQuaternion<f32>,
    pub pad_ned: UnitQuaternion<f32>,
}

/// What the autopilot's stream suffered.
#[derive(Debug, Default, Clone, Copy)]
pub struct Damage {
    pub frames: u32,
    pub intact: u32,
    pub garbage_bursts: u32,
    pub truncated: u32,
    pub flipped: u32,
}

/// What a flight produced: every frame the companion sent (with its time), the truth of every
/// exposure, the companion's counters, and what the autopilot's stream suffered.
pub struct Run {
    pub tx: Vec<(u64, Vec<u8>)>,
    pub truth: BTreeMap<u64, Truth>,
    pub stats: CompanionStats,
    pub damage: Damage,
    pub first_link_frame_after: Option<u64>,
    pub reboot_at: Option<u64>,
}

/// Whether `t` is in the window [start, end).
fn in_window(w: Option<(u64, u64)>, t: u64) -> bool {
    w.is_some_and(|(a, b)| t >= a && t < b)
}

impl Truth {
    /// The truth of the frame `seen`.
    fn of(seen: &Exposure) -> Self {
        let pad_ned_q =
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(seen.r_ned_pad));
        let [w, x, y, z] = seen.attitude.quaternion_wxyz();
        let body_to_ned = UnitQuaternion::new_normalize(Quaternion::new(w, x, y, z));
        Truth {
            rel_body: seen.attitude.ned_to_body(&seen.rel_ned),
            distance: seen.distance,
            pad_body: body_to_ned.inverse() * pad_ned_q,
            pad_ned: pad_ned_q,
        }
    }
}

/// Flies scenario `s`.
pub fn simulate(s: &Scenario) -> Run {
    let mut config = if s.auto {
        CompanionConfig::default()
    } else {
        CompanionConfig::with_profile(s.profile)
    };
    config.params.set(ParamId::CamYaw, s.cam_yaw_deg).unwrap();
    config.params.set(ParamId::VpeEnable, s.vision).unwrap();
    // What TD_CAM_YAW means: the downward camera turned about its optical axis.
    let mount = CameraMount::downward_rotated(s.cam_yaw_deg.to_radians())
        .unwrap()
        .tilted(s.mount_error_deg.0, s.mount_error_deg.1);
    // The estimator's mount is the downward one; TD_CAM_YAW turns it (as the pipeline does).
    let kind = match s.profile {
        Profile::ArduPilot | Profile::ArduPilotLocalFrd => {
            MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA
        }
        Profile::Px4 => MavAutopilot::MAV_AUTOPILOT_PX4,
    };
    let mut ap = Autopilot::new(
        AutopilotClock::steady(AP_AHEAD_US as f64),
        VehiclePath::APPROACH,
        kind,
    );
    ap.gimbal = s.gimbal;
    ap.next_hb = s.autopilot_from_us;
    ap.next_systime = ap.next_systime.max(s.autopilot_from_us);
    ap.next_timesync = ap.next_timesync.max(s.autopilot_from_us);
    let mut flight = Flight::new(
        Companion::new(config),
        ap,
        LinkDelay::Fixed(UPLINK_DELAY_US),
        LinkDelay::Fixed(DOWNLINK_DELAY_US),
    );
    let mut rng = Rng(0x5EED_0000 + s.name.len() as u64);
    let mut tx = Vec::new();
    let mut truth = BTreeMap::new();
    let mut damage = Damage::default();
    let mut gcs_seq = 0u8;
    let mut params = s.params.clone();
    params.sort_by_key(|p| p.0);
    let mut params: VecDeque<_> = params.into();
    let reboot_window = s.reboot_at.map(|r| (r, r + REBOOT_DOWN_US));
    let mut rebooted = false;
    let mut first_link_frame_after = None;

    let mut now = 0u64;
    while now < s.duration_us {
        flight.uplink_to_autopilot(now, !in_window(reboot_window, now));
        // The autopilot's own life.
        if let Some((r, back)) = reboot_window {
            if now >= r && !rebooted {
                rebooted = true;
                flight.downlink.clear();
            }
            if now == back {
                flight.autopilot.reboot(r);
                flight.autopilot.next_hb = now;
                flight.autopilot.next_systime = now;
            }
        }
        let talking = !in_window(s.silent, now) && !in_window(reboot_window, now);
        if talking {
            flight.autopilot_tick(now);
        }
        // Autopilot -> companion (damaged when asked).
        while let Some((mut bytes, _)) = flight.downlink.due(now) {
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
                    flight.companion.receive(&junk, now);
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
            flight.companion.receive(&bytes[..half], now);
            flight.companion.receive(&bytes[half..], now);
        }
        // Ground station.
        while params.front().is_some_and(|(t, _)| *t <= now) {
            let (_, action) = params.pop_front().unwrap();
            flight
                .companion
                .receive(&gcs_message(&mut gcs_seq, action), now);
        }
        // Camera.
        if let Some(te) = flight.camera.exposure_due(now) {
            let seen = Exposure::new(&flight.autopilot.path, te, &mount, s.pad_yaw);
            truth.insert(te, Truth::of(&seen));
            let fix = if in_window(s.lost, te) {
                None
            } else {
                Some(seen.noisy_fix(&mut rng))
            };
            flight.camera.process(te, fix);
        }
        flight.deliver_frames(now, |_| {});
        flight.transmit(now, |bytes| tx.push((now, bytes.to_vec())));
        now += STEP_US;
    }
    Run {
        tx,
        truth,
        stats: flight.companion.stats(),
        damage,
        first_link_frame_after,
        reboot_at: s.reboot_at,
    }
}
