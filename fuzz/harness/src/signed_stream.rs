//! The `signed_stream` target: the companion with a signing key under a script of signed,
//! wrongly signed, unsigned and replayed writes, SETUP_SIGNING, armed and disarmed
//! HEARTBEATs, raw bytes and time steps.
//!
//! Checked besides "no panic": the parameters and the key change only through a write
//! signed with the key in force (or, with no key, any write), never through an unsigned,
//! wrongly signed or replayed one; while armed with TD_LOCK 1 nothing but TD_LOCK changes;
//! every frame the companion sends is signed when a key is set (its signature verified here,
//! with the key, over the bytes it covers) and unsigned otherwise, and its signing timestamps
//! strictly increase.

use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavMessage, MavModeFlag, MavParamType, MavState, MavType, HEARTBEAT_DATA,
    PARAM_SET_DATA, SETUP_SIGNING_DATA,
};
use touchdown_core::companion::mavlink::{MAVLinkV2MessageRaw, MavHeader, Message};
use touchdown_core::companion::{Companion, CompanionConfig, MAX_FRAME_LEN};
use touchdown_core::crc::crc16_x25;
use touchdown_core::params::{ParamId, ParamSet, SigningSecret, PARAMS, PARAM_COUNT};
use touchdown_core::sha256::Sha256;

use crate::input::Input;
use crate::mavlink_stream::check_emitted;

/// Most frames drained after one operation.
const MAX_DRAIN: usize = 64;

/// A MAVLink 2 frame of `msg` from `src`, signed with `key` at `timestamp` on `link_id`
/// (unsigned when `key` is `None`).
pub fn frame(
    msg: &MavMessage,
    src: (u8, u8),
    sequence: u8,
    key: Option<&[u8; 32]>,
    link_id: u8,
    timestamp: u64,
) -> Vec<u8> {
    let mut raw = MAVLinkV2MessageRaw::new();
    let header = MavHeader {
        system_id: u32::from(src.0),
        component_id: src.1,
        sequence,
    };
    raw.serialize_message(header, msg);
    let mut bytes = raw.raw_bytes().to_vec();
    let Some(key) = key else {
        return bytes;
    };
    // Set the signed flag and recompute the checksum over the changed header.
    bytes[2] |= 1;
    let len = bytes.len();
    let mut crc = crc16_x25(0xFFFF, &bytes[1..len - 2]);
    crc = crc16_x25(crc, &[msg_extra_crc(msg)]);
    bytes[len - 2..].copy_from_slice(&crc.to_le_bytes());
    bytes.push(link_id);
    bytes.extend_from_slice(&timestamp.to_le_bytes()[..6]);
    let tag = tag(key, &bytes);
    bytes.extend_from_slice(&tag);
    bytes
}

fn msg_extra_crc(msg: &MavMessage) -> u8 {
    MavMessage::extra_crc(msg.message_id())
}

/// The 6-byte signature of `signed` (a frame up to and including its link id and timestamp).
fn tag(key: &[u8; 32], signed: &[u8]) -> [u8; 6] {
    let mut h = Sha256::new();
    h.update(key);
    h.update(signed);
    let d = h.finish();
    [d[0], d[1], d[2], d[3], d[4], d[5]]
}

/// Checks one emitted frame's signing against `key` (the key in force): signed and valid
/// with a key, unsigned without; returns its timestamp when signed.
fn check_signing(bytes: &[u8], key: Option<&[u8; 32]>) -> Option<u64> {
    let signed = bytes[2] & 1 != 0;
    let Some(key) = key else {
        assert!(!signed, "signed without a key: {bytes:02x?}");
        return None;
    };
    assert!(signed, "unsigned frame with a key set: {bytes:02x?}");
    let n = bytes.len();
    assert_eq!(
        n,
        10 + usize::from(bytes[1]) + 2 + 13,
        "signed frame length"
    );
    assert_eq!(tag(key, &bytes[..n - 6]), bytes[n - 6..], "bad signature");
    let mut ts = [0u8; 8];
    ts[..6].copy_from_slice(&bytes[n - 12..n - 6]);
    Some(u64::from_le_bytes(ts))
}

/// The companion with a key under a script of writes (see the module documentation).
///
/// Script: 32 key bytes (all zero: no key at the start), then operations, one byte each:
/// 0 a PARAM_SET (parameter, value, signing choice, timestamp step), 1 a SETUP_SIGNING
/// (signing choice, new key byte, zero key), 2 the autopilot's HEARTBEAT (armed or not),
/// 3 raw bytes, 4 a time step, 5 the same bytes as an earlier write again (a replay).
pub fn signed_stream(data: &[u8]) -> (u32, u32) {
    let mut input = Input::new(data);
    let mut key = [0u8; 32];
    for k in key.iter_mut() {
        *k = input.u8();
    }
    let mut config = CompanionConfig::default();
    config
        .params
        .set_signing_secret(SigningSecret::new(key, u64::from(input.u32())));
    let mut companion = Companion::new(config);
    let mut now_us = 1_000_000u64;
    let mut their_ts = u64::from(input.u32());
    let mut last_sent_ts = 0u64;
    let mut last_write: Option<Vec<u8>> = None;
    let mut seq = 0u8;
    let mut applied = 0u32;
    // Writes sent but maybe not handled yet: the parser waits for the whole frame a false
    // start in earlier bytes announced, and hands the write out with later bytes. Each with
    // the key it was signed with (`None`: unsigned).
    let mut pending: Vec<Option<[u8; 32]>> = Vec::new();
    while !input.is_empty() {
        let before: ParamSet = *companion.params();
        let in_force = before.signing_secret().key().copied();
        // The lock is judged only where nothing but this operation's own write can reach the
        // companion: raw bytes may hold whole frames (libFuzzer solves the CRC comparison), a
        // disarming HEARTBEAT among them, and bytes held behind a false start come out later.
        let mut locked = companion.flight_locked() && companion.receive_buffered() == 0;
        // Whether this operation's write is one the board may take.
        let mut may_change = false;
        seq = seq.wrapping_add(1);
        let op = input.below(6);
        if matches!(op, 0 | 1 | 5) && companion.receive_buffered() > 0 {
            // Bytes held behind a false start (raw bytes before) are flushed with zeros that
            // cover the longest length it may announce, so that this write reaches a parser
            // at rest and is handled now: its verdict is this operation's. (Left in place, a
            // write may vanish into the false start's span as line noise swallows frames, and
            // its copy sent again is then rightly the first the board sees.)
            companion.receive(&[0u8; MAX_FRAME_LEN + 1], now_us);
        }
        match op {
            op @ (0 | 1) => {
                let choice = input.u8() % 4;
                // 0: signed with the key in force; 1: another key; 2: unsigned; 3: an old
                // timestamp with the key in force (a replay unless it is the stream's first).
                let step = u64::from(input.u16());
                their_ts = match choice {
                    3 => their_ts.saturating_sub(step),
                    _ => their_ts.saturating_add(step + 1),
                };
                let msg = if op == 0 {
                    let def = &PARAMS[input.below(PARAM_COUNT)];
                    MavMessage::PARAM_SET(PARAM_SET_DATA {
                        param_value: input.f32(),
                        target_system: 1,
                        target_component: 191,
                        param_id: def.name.into(),
                        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
                    })
                } else {
                    let fill = input.u8();
                    let mut secret_key = [fill; 32];
                    secret_key[0] = input.u8();
                    let zero = input.u8().is_multiple_of(2);
                    if fill == 0 && zero {
                        secret_key = [0; 32];
                    }
                    MavMessage::SETUP_SIGNING(SETUP_SIGNING_DATA {
                        initial_timestamp: u64::from(input.u32()),
                        target_system: 1,
                        target_component: 191,
                        secret_key,
                    })
                };
                let other = [0xA5u8; 32];
                let sign_with = match (choice, in_force.as_ref()) {
                    (0 | 3, Some(k)) => Some(k),
                    (0 | 3, None) => None,
                    (1, _) => Some(&other),
                    _ => None,
                };
                let bytes = frame(&msg, (255, 190), seq, sign_with, 0, their_ts);
                pending.push(sign_with.copied());
                // Signed with the key in force (an old timestamp may still be its stream's
                // first, within the window: "may" change, not "must").
                may_change =
                    in_force.is_none() || (sign_with.is_some() && sign_with == in_force.as_ref());
                companion.receive(&bytes, now_us);
                last_write = Some(bytes);
            }
            2 => {
                let armed = input.u8().is_multiple_of(2);
                let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
                if armed {
                    base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
                }
                let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                    custom_mode: 0,
                    mavtype: MavType::MAV_TYPE_QUADROTOR,
                    autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                    base_mode,
                    system_status: MavState::MAV_STATE_ACTIVE,
                    mavlink_version: 3,
                });
                let bytes = frame(&hb, (1, 1), seq, None, 0, 0);
                companion.receive(&bytes, now_us);
            }
            3 => {
                let len = input.below(301);
                companion.receive(input.bytes(len), now_us);
                // Unsigned frames in them (a signature cannot be forged) may write when no
                // key is in force.
                may_change = in_force.is_none();
                locked = false;
            }
            4 => {
                now_us = now_us.saturating_add(u64::from(input.u32() % 5_000_001));
            }
            _ => {
                if let Some(bytes) = &last_write {
                    // The same bytes again: never a change where a key is in force.
                    companion.receive(bytes, now_us);
                    may_change = in_force.is_none();
                }
            }
        }
        // A write handled only now counts with the key in force now.
        may_change |= pending
            .iter()
            .any(|k| in_force.is_none() || (k.is_some() && *k == in_force));
        if companion.receive_buffered() == 0 {
            pending.clear();
        }
        let after = *companion.params();
        if after != before {
            applied += 1;
            assert!(
                may_change,
                "changed by a write not signed with the key in force: {before:?} -> {after:?}"
            );
            if locked {
                // TD_LOCK itself may change, and the saved timestamp moves with every signed
                // write applied; nothing else.
                let mut unlocked = after;
                let _ = unlocked.set(ParamId::Lock, before.get(ParamId::Lock));
                unlocked.set_signing_secret(*before.signing_secret());
                assert_eq!(unlocked, before, "changed while armed with TD_LOCK 1");
                assert_eq!(
                    after.signing_secret().key(),
                    before.signing_secret().key(),
                    "the key changed while armed with TD_LOCK 1"
                );
            }
        }
        let key_now = after.signing_secret().key().copied();
        let mut out = [0u8; MAX_FRAME_LEN];
        let mut drained = 0;
        while let Some(n) = companion.poll_transmit(now_us, &mut out) {
            let bytes = &out[..n];
            check_emitted(bytes);
            if let Some(ts) = check_signing(bytes, key_now.as_ref()) {
                assert!(ts > last_sent_ts, "timestamp {ts} after {last_sent_ts}");
                last_sent_ts = ts;
            }
            drained += 1;
            assert!(drained <= MAX_DRAIN, "draining does not end");
        }
    }
    let s = companion.stats();
    (applied, s.writes_refused_unsigned + s.writes_refused_locked)
}
