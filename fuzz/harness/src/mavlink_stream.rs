//! The `mavlink_stream` target: the companion state machine under a script of link bytes,
//! camera frames, parameter changes and time steps, every frame it sends parsed back with
//! the mavlink crate.

use nalgebra::{Matrix6, UnitQuaternion, Vector3};
use touchdown_core::companion::mavlink::dialects::common::{
    MavMessage, MavParamType, PARAM_REQUEST_READ_DATA, PARAM_SET_DATA,
};
use touchdown_core::companion::mavlink::{
    MAVLinkV1MessageRaw, MAVLinkV2MessageRaw, MavFrame, MavHeader, MavlinkVersion, Message,
};
use touchdown_core::companion::{
    Companion, CompanionConfig, CompanionStats, Profile, MAX_FRAME_LEN,
};
use touchdown_core::filter::{EstimatorConfig, PadEstimator};
use touchdown_core::params::{ParamId, ParamSet, PipelineSettings, PARAMS, PARAM_COUNT};
use touchdown_core::pose::{PadFix, Pose};

use crate::input::Input;

/// Message ids the companion reacts to (and LANDING_TARGET, which it must ignore).
const HANDLED_IDS: [u32; 12] = [0, 2, 111, 31, 30, 32, 77, 76, 21, 20, 23, 149];
/// Most frames drained after one operation: far above what one instant can queue (16 queued
/// items, a target, a VPE, the periodic messages).
const MAX_DRAIN: usize = 64;

/// Operations of a [`mavlink_stream`] script (the byte is taken modulo the count).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Op {
    /// Length byte pair (u16, modulo 301), then that many raw bytes.
    RawBytes = 0,
    /// A MAVLink frame of a handled message (see [`mavlink_frame`]).
    Frame = 1,
    /// A PARAM_SET of a real parameter to us: index byte, f32 value.
    ParamSet = 2,
    /// A processed camera frame (see [`mavlink_stream`]).
    CameraFrame = 3,
    /// A local parameter change: index byte, f32 value.
    SetParam = 4,
    /// Time step: kind byte and a u32/u64 amount.
    Time = 5,
    /// Read the statistics.
    Stats = 6,
}

const OPS: usize = 7;

/// A MAVLink frame of a message the companion handles, with fuzzed fields: message id
/// choice, payload length and bytes, version, parameter name, header, then damage (none,
/// truncation, one flipped bit).
pub fn mavlink_frame(input: &mut Input<'_>) -> Vec<u8> {
    let choice = input.u8();
    let id = if choice >= 0xF0 {
        input.u32() & 0xFF_FFFF
    } else {
        HANDLED_IDS[usize::from(choice) % HANDLED_IDS.len()]
    };
    let len = input.below(256);
    let payload = input.bytes(len);
    // MAVLink 1 carries 8-bit message ids only (the mavlink crate panics serialising a larger
    // one as MAVLink 1: the first crash this target found, a harness bug).
    let version = if input.u8() % 6 == 5 && id <= 0xFF {
        MavlinkVersion::V1
    } else {
        MavlinkVersion::V2
    };
    let name = PARAMS[input.below(PARAM_COUNT)].name;
    let rename = !input.u8().is_multiple_of(4);
    let header = MavHeader {
        system_id: u32::from(input.u8()),
        component_id: input.u8(),
        sequence: input.u8(),
    };
    let damage = input.u8();
    let at = usize::from(input.u16());
    let Ok(mut msg) = MavMessage::parse(version, id, payload) else {
        return Vec::new();
    };
    // Real parameter names, so PARAM_SET / PARAM_REQUEST_READ reach the parameter logic.
    match &mut msg {
        MavMessage::PARAM_SET(PARAM_SET_DATA { param_id, .. })
        | MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA { param_id, .. })
            if rename =>
        {
            *param_id = name.into();
        }
        _ => {}
    }
    let mut bytes = match version {
        MavlinkVersion::V1 => {
            let mut raw = MAVLinkV1MessageRaw::new();
            raw.serialize_message(header, &msg);
            raw.raw_bytes().to_vec()
        }
        MavlinkVersion::V2 => {
            let mut raw = MAVLinkV2MessageRaw::new();
            raw.serialize_message(header, &msg);
            raw.raw_bytes().to_vec()
        }
    };
    match damage % 8 {
        0 => bytes.truncate(at % (bytes.len() + 1)),
        1 if !bytes.is_empty() => {
            let bit = at % (bytes.len() * 8);
            bytes[bit / 8] ^= 1 << (bit % 8);
        }
        _ => {}
    }
    bytes
}

/// A PARAM_SET of a real parameter, addressed to us, with any value.
fn param_set(input: &mut Input<'_>, params: &ParamSet) -> Vec<u8> {
    let def = &PARAMS[input.below(PARAM_COUNT)];
    let msg = MavMessage::PARAM_SET(PARAM_SET_DATA {
        param_value: input.f32(),
        target_system: params.get_int(ParamId::SysId) as u8,
        target_component: params.get_int(ParamId::CompId) as u8,
        param_id: def.name.into(),
        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
    });
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message(
        MavHeader {
            system_id: 255,
            component_id: 190,
            sequence: input.u8(),
        },
        &msg,
    );
    raw.raw_bytes().to_vec()
}

fn small(input: &mut Input<'_>, scale: f32) -> f32 {
    f32::from(input.u8() as i8) * scale
}

/// A pad fix: plausible (even selector) or any floats at all (NaN, infinities, a
/// non-orthogonal "rotation").
fn pad_fix(input: &mut Input<'_>) -> PadFix {
    if input.u8().is_multiple_of(2) {
        let rotation = UnitQuaternion::from_euler_angles(
            small(input, 0.02),
            small(input, 0.02),
            small(input, 0.05),
        );
        let translation = Vector3::new(
            small(input, 0.05),
            small(input, 0.05),
            f32::from(input.u8()) * 0.2,
        );
        let sigma = 1e-4 + f32::from(input.u8()) * 1e-3;
        PadFix {
            pose: Pose {
                rotation: *rotation.to_rotation_matrix().matrix(),
                translation,
            },
            covariance: Matrix6::identity() * sigma,
            markers_used: input.u8(),
            reprojection_rms_px: f32::from(input.u8()) * 0.05,
            alternative_rms_px: input.f32(),
        }
    } else {
        let mut pose = Pose::identity();
        for v in pose.rotation.iter_mut().chain(pose.translation.iter_mut()) {
            *v = input.f32();
        }
        let mut covariance = Matrix6::zeros();
        for v in covariance.iter_mut() {
            *v = input.f32();
        }
        PadFix {
            pose,
            covariance,
            markers_used: input.u8(),
            reprojection_rms_px: input.f32(),
            alternative_rms_px: input.f32(),
        }
    }
}

/// Parses one emitted frame back with the mavlink crate; panics unless it is a complete
/// MAVLink 2 frame, unsigned or signed (a script may set a key; the signature itself is
/// `signed_stream`'s to check), with a valid checksum whose payload parses, and unless a
/// LANDING_TARGET / VISION_POSITION_ESTIMATE carries finite numbers.
pub fn check_emitted(bytes: &[u8]) -> MavMessage {
    assert!(bytes.len() >= 12, "frame of {} bytes", bytes.len());
    assert_eq!(bytes[0], 0xFD, "not a MAVLink 2 frame: {bytes:02x?}");
    let incompat = bytes[2];
    assert!(incompat <= 1, "unexpected incompatibility flags {incompat}");
    let signature = if incompat == 1 { 13 } else { 0 };
    assert_eq!(
        bytes.len(),
        10 + usize::from(bytes[1]) + 2 + signature,
        "length field vs frame size"
    );
    let bytes = &bytes[..bytes.len() - signature];
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.as_mut_slice()[..bytes.len()].copy_from_slice(bytes);
    assert!(
        raw.has_valid_crc::<MavMessage>(),
        "bad checksum: {bytes:02x?}"
    );
    let frame = match MavFrame::<MavMessage>::deser_with_flags(
        MavlinkVersion::V2,
        incompat,
        &bytes[4..bytes.len() - 2],
    ) {
        Ok(frame) => frame,
        Err(e) => panic!("mavlink cannot parse {bytes:02x?}: {e:?}"),
    };
    assert_eq!(frame.msg.message_id(), raw.message_id());
    match &frame.msg {
        MavMessage::LANDING_TARGET(t) => {
            let values = [
                t.angle_x, t.angle_y, t.distance, t.size_x, t.size_y, t.x, t.y, t.z,
            ];
            // `q` is a rotation, or MAVLink's "unknown" (NaN first, the rest zero) when the
            // fix's rotation is unusable (core/src/companion/mod.rs, UNKNOWN_Q).
            let q_unknown = t.q[0].is_nan() && t.q[1..].iter().all(|&v| v == 0.0);
            assert!(
                values.iter().all(|v| v.is_finite())
                    && (q_unknown || t.q.iter().all(|v| v.is_finite())),
                "non-finite LANDING_TARGET: {t:?}"
            );
        }
        MavMessage::VISION_POSITION_ESTIMATE(v) => {
            let values = [v.x, v.y, v.z, v.roll, v.pitch, v.yaw];
            assert!(
                values.iter().all(|v| v.is_finite()),
                "non-finite VISION_POSITION_ESTIMATE: {v:?}"
            );
        }
        _ => {}
    }
    frame.msg
}

/// Drains the transmit side at `now_us`, checking every frame; returns how many there were.
pub fn drain(companion: &mut Companion, now_us: u64) -> usize {
    let mut out = [0u8; MAX_FRAME_LEN];
    let mut last = None;
    for sent in 0..MAX_DRAIN {
        match companion.poll_transmit(now_us, &mut out) {
            Some(n) => {
                last = Some(check_emitted(&out[..n]).message_id());
            }
            None => return sent,
        }
    }
    panic!(
        "poll_transmit still had frames after {MAX_DRAIN} calls at {now_us} us (last message id {last:?})"
    );
}

/// The companion state machine under a script of link bytes, frames and time steps.
///
/// Script: byte 0 profile (odd: PX4), byte 1 VPE on (odd), u32 start time, then operations
/// ([`Op`], one byte each, with their arguments) until the input ends; after every operation
/// the transmit side is drained ([`drain`], [`check_emitted`]). Time steps go forwards a
/// little or a lot, backwards (an autopilot reboot is the autopilot's clock, but ours may be
/// fed inconsistently too), or jump anywhere; camera frames have a fix (plausible or any
/// floats) or none, and an exposure usually just before now, sometimes anywhere.
///
/// Returns the companion's counters at the end (the seed tests check how deep a script got).
pub fn mavlink_stream(data: &[u8]) -> CompanionStats {
    let mut input = Input::new(data);
    let profile = if input.u8() % 2 == 1 {
        Profile::Px4
    } else {
        Profile::ArduPilot
    };
    let mut config = CompanionConfig::with_profile(profile);
    if input.u8() % 2 == 1 {
        let _ = config.params.set(ParamId::VpeEnable, 1.0);
    }
    let mut companion = Companion::new(config);
    // The estimator stage of the pipeline, fed the script's pad fixes (there is no image here),
    // with the vehicle state the companion decodes from the script's bytes.
    let mut estimator =
        PadEstimator::new(EstimatorConfig::default()).expect("the default trackers are valid");
    let mut now_us = u64::from(input.u32());
    while !input.is_empty() {
        match input.below(OPS) as u8 {
            x if x == Op::RawBytes as u8 => {
                let len = input.below(301);
                let bytes = input.bytes(len);
                companion.receive(bytes, now_us);
            }
            x if x == Op::Frame as u8 => {
                let bytes = mavlink_frame(&mut input);
                // Any chunking.
                let split = input.below(bytes.len() + 1);
                companion.receive(&bytes[..split], now_us);
                companion.receive(&bytes[split..], now_us);
            }
            x if x == Op::ParamSet as u8 => {
                let bytes = param_set(&mut input, companion.params());
                companion.receive(&bytes, now_us);
            }
            x if x == Op::CameraFrame as u8 => {
                let kind = input.u8();
                let age = u64::from(input.u32() % 200_001);
                let fix = (!kind.is_multiple_of(4)).then(|| pad_fix(&mut input));
                let exposure_us = if kind >= 0xF0 {
                    input.u64() // stamped anywhere, the future included
                } else {
                    now_us.saturating_sub(age)
                };
                let estimate = estimator.update(fix.as_ref(), &companion.vehicle().at(exposure_us));
                let _ = companion.on_estimate(&estimate, now_us);
            }
            x if x == Op::SetParam as u8 => {
                if let Some(id) = ParamId::from_index(input.below(PARAM_COUNT)) {
                    let _ = companion.set_param(id, input.f32());
                }
            }
            x if x == Op::Time as u8 => {
                now_us = match input.u8() % 16 {
                    0 => now_us.saturating_sub(u64::from(input.u32() % 5_000_001)),
                    1 => input.u64(),
                    2 => now_us.saturating_add(u64::from(input.u32() % 20_000_001)),
                    _ => now_us.saturating_add(u64::from(input.u16()) % 50_001),
                };
            }
            _ => {
                let _ = companion.stats();
                let _ = companion.autopilot_alive(now_us);
            }
        }
        // As the pipeline applies TD_CAM_YAW between frames (PARAM_SET bytes included).
        estimator.set_mount_yaw(PipelineSettings::from_params(companion.params()).cam_yaw_deg);
        drain(&mut companion, now_us);
    }
    companion.stats()
}
