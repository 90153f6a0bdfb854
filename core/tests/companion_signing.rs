//! MAVLink 2 signing and the flight lock on the companion, byte for byte against pymavlink
//! (`scripts/mavlink_signing.py`): frames signed by pymavlink are taken, unsigned, wrongly
//! signed and replayed writes refused, the board's own frames verified by pymavlink with the
//! key; while the autopilot is armed the parameters hold until TD_LOCK is 0. Without
//! pymavlink the tests print `skipping: pymavlink not installed` (CI installs it).

use std::io::Write as _;
use std::path::PathBuf;
use std::process::{Command, Stdio};

use serde_json::{json, Value};
use touchdown_core::companion::mavlink::dialects::common::MavMessage;
use touchdown_core::companion::{Companion, CompanionConfig, FrameParser, MAX_FRAME_LEN};
use touchdown_core::params::{name_str, ParamId};

const KEY: [u8; 32] = [
    0x3a, 0x91, 0x07, 0xc4, 0x5e, 0x22, 0xf0, 0x18, 0x6b, 0xd3, 0x4c, 0x99, 0x01, 0xe7, 0x2f, 0x80,
    0x55, 0x6d, 0xa2, 0x3b, 0xc8, 0x14, 0x7e, 0xf9, 0x0d, 0x66, 0xb1, 0x2a, 0x93, 0x4f, 0xe5, 0x70,
];
const OTHER_KEY: [u8; 32] = [0x42; 32];
/// The key's initial timestamp: 2026 in 10 µs units since 2015.
const T0: u64 = 11 * 365 * 24 * 3600 * 100_000;

fn script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scripts/mavlink_signing.py")
}

fn hex(key: &[u8]) -> String {
    key.iter().map(|b| format!("{b:02x}")).collect()
}

/// pymavlink's frames for `specs` (see the script), signed with `key`; `None` without
/// pymavlink.
fn pymavlink_frames(key: Option<&[u8; 32]>, specs: &[Value]) -> Option<Vec<Vec<u8>>> {
    let key = key.map(|k| hex(k)).unwrap_or_else(|| "-".into());
    let child = Command::new("python3")
        .arg(script())
        .args(["sign", &key])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn();
    let Ok(mut child) = child else {
        println!("skipping: pymavlink not installed (no python3)");
        return None;
    };
    {
        let mut stdin = child.stdin.take().unwrap();
        for s in specs {
            writeln!(stdin, "{s}").unwrap();
        }
    }
    let out = child.wait_with_output().unwrap();
    if out.status.code() == Some(3) {
        println!("skipping: pymavlink not installed");
        return None;
    }
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    Some(
        text.lines()
            .map(|l| {
                (0..l.len())
                    .step_by(2)
                    .map(|i| u8::from_str_radix(&l[i..i + 2], 16).unwrap())
                    .collect()
            })
            .collect(),
    )
}

/// pymavlink's verdict on the board's frames with `key`: (messages, good signatures).
fn pymavlink_verify(key: &[u8; 32], bytes: &[u8]) -> (u64, u64) {
    let mut path = std::env::temp_dir();
    path.push(format!("touchdown-signing-{}.bin", std::process::id()));
    std::fs::write(&path, bytes).unwrap();
    let out = Command::new("python3")
        .arg(script())
        .args(["verify", &hex(key)])
        .arg(&path)
        .output()
        .unwrap();
    let _ = std::fs::remove_file(&path);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "pymavlink refused the board's frames: {text}"
    );
    let v: Value = serde_json::from_str(text.trim()).unwrap();
    assert_eq!(v["leftover"], 0, "{v}");
    assert_eq!(v["bad"], 0, "{v}");
    (v["messages"].as_u64().unwrap(), v["good"].as_u64().unwrap())
}

fn param_set(name: &str, value: f32, ts: u64) -> Value {
    json!({"type": "PARAM_SET", "timestamp": ts, "fields": {
        "target_system": 1, "target_component": 191, "param_id": name,
        "param_value": value, "param_type": 9}})
}

fn setup_signing(key: &[u8; 32], initial: u64, ts: u64) -> Value {
    json!({"type": "SETUP_SIGNING", "timestamp": ts, "fields": {
        "target_system": 1, "target_component": 191, "secret_key": key.to_vec(),
        "initial_timestamp": initial}})
}

fn unsigned(mut v: Value) -> Value {
    v["unsigned"] = json!(true);
    v
}

fn heartbeat(armed: bool) -> Value {
    // ArduPilot (3), quadrotor (2), custom mode enabled (1), armed (128).
    let base_mode = if armed { 129 } else { 1 };
    json!({"type": "HEARTBEAT", "unsigned": true, "src": [1, 1], "fields": {
        "type": 2, "autopilot": 3, "base_mode": base_mode, "custom_mode": 9,
        "system_status": 4, "mavlink_version": 3}})
}

/// What the board said back: every frame's bytes, PARAM_VALUEs, STATUSTEXTs, COMMAND_ACK
/// results.
#[derive(Default)]
struct Replies {
    bytes: Vec<u8>,
    values: Vec<(String, f32)>,
    texts: Vec<String>,
    acks: Vec<u32>,
}

fn feed(companion: &mut Companion, frame: &[u8], now: u64) -> Replies {
    companion.receive(frame, now);
    drain(companion, now)
}

fn drain(companion: &mut Companion, now: u64) -> Replies {
    let mut out = [0u8; MAX_FRAME_LEN];
    let mut r = Replies::default();
    let mut parser = FrameParser::new();
    while let Some(n) = companion.poll_transmit(now, &mut out) {
        r.bytes.extend_from_slice(&out[..n]);
        parser.push(&out[..n], |raw| match raw.decode() {
            Ok(MavMessage::PARAM_VALUE(v)) => r
                .values
                .push((name_str(&v.param_id[..]).to_string(), v.param_value)),
            Ok(MavMessage::STATUSTEXT(t)) => r.texts.push(name_str(&t.text[..]).to_string()),
            Ok(MavMessage::COMMAND_ACK(a)) => r.acks.push(a.result as u32),
            _ => {}
        });
    }
    r
}

#[test]
fn only_writes_signed_with_the_key_change_the_board_and_its_frames_are_signed() {
    let specs = [
        unsigned(setup_signing(&KEY, T0, 0)), // 0: the first key: taken unsigned
        unsigned(param_set("TD_TAG_SIZE", 0.5, 0)), // 1: refused
        param_set("TD_TAG_SIZE", 0.5, T0 + 100), // 2: applied
        param_set("TD_TAG_SIZE", 0.6, T0 + 200), // 3: applied
        param_set("TD_TAG_SIZE", 0.7, T0 + 150), // 4: older than 3: a replay
        json!({"type": "COMMAND_LONG", "unsigned": true, "fields": {
            "target_system": 1, "target_component": 191, "command": 246, "confirmation": 0,
            "param1": 1.0, "param2": 0.0, "param3": 0.0, "param4": 0.0, "param5": 0.0,
            "param6": 0.0, "param7": 0.0}}), // 5: denied
        json!({"type": "PARAM_REQUEST_READ", "unsigned": true, "fields": {
            "target_system": 1, "target_component": 191, "param_id": "TD_TAG_SIZE",
            "param_index": -1}}), // 6: reading stays open
        unsigned(setup_signing(&OTHER_KEY, T0, 0)), // 7: refused
        param_set("TD_TAG_SIZE", 0.8, T0 + 250), // 8: another stream's first, older than 3
    ];
    let Some(mut frames) = pymavlink_frames(Some(&KEY), &specs) else {
        return;
    };
    // 9: signed with another key; 10: from a new stream, older than the last write applied.
    let Some(more) = pymavlink_frames(Some(&OTHER_KEY), &[param_set("TD_TAG_SIZE", 0.9, T0 + 300)])
    else {
        return;
    };
    frames.extend(more);
    let mut old = param_set("TD_TAG_SIZE", 1.0, T0 - 7_000_000);
    old["src"] = json!([255, 191]);
    frames.extend(pymavlink_frames(Some(&KEY), &[old]).unwrap());
    // 8 came from another stream (link 1), so that it is judged as a new one.
    let mut s8 = specs[8].clone();
    s8["link_id"] = json!(1);
    frames[8] = pymavlink_frames(Some(&KEY), &[s8]).unwrap().remove(0);

    let mut c = Companion::new(CompanionConfig::default());
    let mut now = 1_000_000;
    let mut step = |c: &mut Companion, i: usize| {
        now += 10_000;
        feed(c, &frames[i], now)
    };
    let tag = |c: &Companion| c.params().get(ParamId::TagSize);

    let r = step(&mut c, 0);
    assert!(c.signing());
    assert!(
        r.texts.iter().any(|t| t == "touchdown: signing on"),
        "{:?}",
        r.texts
    );
    let mut signed_out = r.bytes;

    let r = step(&mut c, 1);
    assert_eq!(tag(&c), 0.0);
    assert_eq!(r.values, vec![("TD_TAG_SIZE".to_string(), 0.0)]);
    assert!(r
        .texts
        .contains(&"touchdown: TD_TAG_SIZE refused: not signed".to_string()));
    signed_out.extend(r.bytes);

    for (i, want) in [(2, 0.5), (3, 0.6), (4, 0.6)] {
        let r = step(&mut c, i);
        assert_eq!(tag(&c), want, "frame {i}");
        assert_eq!(
            r.values,
            vec![("TD_TAG_SIZE".to_string(), want)],
            "frame {i}"
        );
        signed_out.extend(r.bytes);
    }
    let r = step(&mut c, 5);
    assert_eq!(r.acks, vec![2], "MAV_RESULT_DENIED");
    signed_out.extend(r.bytes);
    let r = step(&mut c, 6);
    assert_eq!(r.values, vec![("TD_TAG_SIZE".to_string(), 0.6)]);
    signed_out.extend(r.bytes);
    let r = step(&mut c, 7);
    assert!(c.signing());
    signed_out.extend(r.bytes);
    let r = step(&mut c, 8);
    assert_eq!(tag(&c), 0.8);
    signed_out.extend(r.bytes);
    let r = step(&mut c, 9);
    assert_eq!(tag(&c), 0.8, "another key");
    signed_out.extend(r.bytes);
    let r = step(&mut c, 10);
    assert_eq!(tag(&c), 0.8, "a new stream older than the last write");
    signed_out.extend(r.bytes);
    // The periodic frames (heartbeat, TIMESYNC, stream requests) are signed too.
    signed_out.extend(drain(&mut c, now + 2_000_000).bytes);

    let s = c.stats();
    assert_eq!(s.signing_setups, 1);
    assert_eq!(s.bad_signatures, 1);
    assert_eq!(s.replayed_frames, 2);
    assert_eq!(s.signed_frames, 3);
    assert_eq!(s.writes_refused_unsigned, 6);
    let (messages, good) = pymavlink_verify(&KEY, &signed_out);
    assert!(messages >= 12, "{messages}");
    assert_eq!(
        good, messages,
        "every frame after the key signed and accepted"
    );
}

#[test]
fn a_signed_setup_signing_changes_or_clears_the_key() {
    let Some(first) = pymavlink_frames(None, &[unsigned(setup_signing(&KEY, T0, 0))]) else {
        return;
    };
    let change =
        pymavlink_frames(Some(&KEY), &[setup_signing(&OTHER_KEY, T0 + 10, T0 + 5)]).unwrap();
    let under_new = pymavlink_frames(
        Some(&OTHER_KEY),
        &[
            param_set("TD_RATE_HZ", 10.0, T0 + 20),
            setup_signing(&[0; 32], 0, T0 + 30),
        ],
    )
    .unwrap();
    let mut c = Companion::new(CompanionConfig::default());
    feed(&mut c, &first[0], 1_000);
    feed(&mut c, &change[0], 2_000);
    assert!(c.signing());
    assert_eq!(c.params().signing_secret().key(), Some(&OTHER_KEY));
    feed(&mut c, &under_new[0], 3_000);
    assert_eq!(c.params().get(ParamId::RateHz), 10.0);
    let r = feed(&mut c, &under_new[1], 4_000);
    assert!(!c.signing());
    assert!(r.texts.contains(&"touchdown: signing off".to_string()));
    // Unsigned again: frames go out without a signature, writes are taken unsigned.
    assert_eq!(r.bytes[2] & 1, 0);
}

#[test]
fn the_flight_lock_holds_the_parameters_while_the_autopilot_is_armed() {
    let specs = [
        heartbeat(true),
        unsigned(param_set("TD_TAG_SIZE", 0.5, 0)),
        unsigned(setup_signing(&KEY, T0, 0)),
        unsigned(param_set("TD_LOCK", 0.0, 0)),
        unsigned(param_set("TD_TAG_SIZE", 0.5, 0)),
        unsigned(param_set("TD_LOCK", 1.0, 0)),
        heartbeat(false),
        unsigned(param_set("TD_CAM_YAW", 90.0, 0)),
    ];
    let Some(frames) = pymavlink_frames(None, &specs) else {
        return;
    };
    let mut c = Companion::new(CompanionConfig::default());
    let mut now = 0;
    let mut replies = Vec::new();
    for f in &frames {
        now += 500_000;
        replies.push(feed(&mut c, f, now));
    }
    assert_eq!(replies[1].values, vec![("TD_TAG_SIZE".to_string(), 0.0)]);
    assert!(replies[1]
        .texts
        .contains(&"touchdown: TD_TAG_SIZE refused: armed (TD_LOCK)".to_string()));
    assert!(!c.signing(), "no key set in flight");
    assert!(
        replies[2].texts.is_empty(),
        "rate-limited: {:?}",
        replies[2].texts
    );
    assert_eq!(replies[4].values, vec![("TD_TAG_SIZE".to_string(), 0.5)]);
    assert_eq!(c.params().get(ParamId::Lock), 1.0);
    assert_eq!(c.params().get(ParamId::CamYaw), 90.0, "on the ground again");
    let s = c.stats();
    assert_eq!(s.writes_refused_locked, 2);
    assert_eq!(s.writes_refused_unsigned, 0);
}

#[test]
fn a_flood_of_refused_writes_says_so_once_per_period() {
    let specs: Vec<Value> = (0..200)
        .map(|i| unsigned(param_set("TD_TAG_SIZE", 0.1 + i as f32 * 0.001, 0)))
        .collect();
    let Some(frames) = pymavlink_frames(None, &specs) else {
        return;
    };
    let mut c = Companion::new(CompanionConfig::default());
    c.set_signing_secret(touchdown_core::params::SigningSecret::new(KEY, T0), 0);
    let mut texts = 0;
    // 200 writes over 5 s: a text at 0, 2 and 4 s.
    for (i, f) in frames.iter().enumerate() {
        let r = feed(&mut c, f, i as u64 * 25_000);
        texts += r.texts.iter().filter(|t| t.contains("refused")).count();
        assert_eq!(r.values.len(), 1);
    }
    assert_eq!(texts, 3);
    assert_eq!(c.params().get(ParamId::TagSize), 0.0);
    assert_eq!(c.stats().writes_refused_unsigned, 200);
}

#[test]
fn the_key_is_never_listed_among_the_parameters() {
    let Some(frames) = pymavlink_frames(
        None,
        &[
            unsigned(setup_signing(&KEY, T0, 0)),
            json!({"type": "PARAM_REQUEST_LIST", "unsigned": true, "fields": {
                "target_system": 1, "target_component": 191}}),
        ],
    ) else {
        return;
    };
    let mut c = Companion::new(CompanionConfig::default());
    feed(&mut c, &frames[0], 1_000);
    let mut values = Vec::new();
    let mut now = 2_000;
    c.receive(&frames[1], now);
    for _ in 0..200 {
        now += 20_000;
        values.extend(drain(&mut c, now).values);
    }
    assert_eq!(values.len(), touchdown_core::params::PARAM_COUNT);
    assert!(
        values.iter().all(|(n, _)| n.starts_with("TD_")),
        "{values:?}"
    );
    assert!(
        !format!("{:?}", c.params()).contains("58"),
        "the key in a debug print"
    );
}

#[test]
fn a_signed_write_is_not_taken_again_after_a_reboot() {
    let Some(first) = pymavlink_frames(None, &[unsigned(setup_signing(&KEY, T0, 0))]) else {
        return;
    };
    let writes = pymavlink_frames(
        Some(&KEY),
        &[
            param_set("TD_RATE_HZ", 15.0, T0 + 100),
            param_set("TD_RATE_HZ", 20.0, T0 + 200),
            param_set("TD_RATE_HZ", 25.0, T0 + 300),
        ],
    )
    .unwrap();
    let mut c = Companion::new(CompanionConfig::default());
    feed(&mut c, &first[0], 1_000);
    feed(&mut c, &writes[0], 2_000);
    feed(&mut c, &writes[1], 3_000);
    assert_eq!(c.params().get(ParamId::RateHz), 20.0);
    // The saved timestamp moved past the last write: what the flash keeps.
    assert_eq!(c.params().signing_secret().timestamp(), T0 + 201);
    // A reboot: the parameters (and the secret) as saved, the streams forgotten.
    let config = CompanionConfig {
        params: *c.params(),
        ..CompanionConfig::default()
    };
    let mut c = Companion::new(config);
    for (i, w) in writes[..2].iter().enumerate() {
        let r = feed(&mut c, w, 10_000 + i as u64);
        assert_eq!(
            r.values,
            vec![("TD_RATE_HZ".to_string(), 20.0)],
            "write {i} again"
        );
    }
    assert_eq!(c.stats().replayed_frames, 2);
    feed(&mut c, &writes[2], 20_000);
    assert_eq!(c.params().get(ParamId::RateHz), 25.0, "a newer write");
}
