//! `touchdown companion --serial` against a pseudo-terminal: the command opens the port with
//! its termios set-up, replays a simulated recording and writes MAVLink 2 to it; the test
//! plays the flight controller on the pty's other end (a HEARTBEAT a second, as ArduPilot
//! sends) and hands everything it read to pymavlink (`scripts/mavlink_decode.py`, strict
//! parsing, as the core's companion tests do).
//!
//! This is the path a user takes with a USB-serial adapter or a flight controller's USB port,
//! short of the wire: open, raw mode, speed, non-blocking reads and writes, and the exit; and
//! a parameter set over that link (TD_TAG_SIZE) changing what the per-frame path reports.

#![cfg(unix)]

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use rustix::pty::{grantpt, openpt, ptsname, unlockpt, OpenptFlags};
use serde_json::Value;
use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavMessage, MavModeFlag, MavParamType, MavState, MavType, HEARTBEAT_DATA,
    PARAM_SET_DATA,
};
use touchdown_core::companion::mavlink::{MAVLinkV2MessageRaw, MavHeader};

fn touchdown() -> Command {
    Command::new(env!("CARGO_BIN_EXE_touchdown"))
}

/// `msg` as the MAVLink 2 bytes of a frame with `header`.
fn mavlink2(header: MavHeader, msg: &MavMessage) -> Vec<u8> {
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message(header, msg);
    raw.raw_bytes().to_vec()
}

/// An ArduPilot copter's HEARTBEAT (system 1, component 1) as MAVLink 2 bytes, with the
/// next sequence number of `seq`.
fn autopilot_heartbeat(seq: &mut u8) -> Vec<u8> {
    let header = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: *seq,
    };
    *seq = seq.wrapping_add(1);
    let heartbeat = HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    };
    mavlink2(header, &MavMessage::HEARTBEAT(heartbeat))
}

/// A simulated descent of `frames` frames, written to a fresh directory named after `name`.
fn descent_recording(name: &str, frames: u32) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("companion_serial")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    // --ideal: these tests are about the serial link and the parameters, and the descent
    // starts with the pad near the edge of the view, where the default 2 degree mount
    // misalignment takes it out of some of these few frames. The warp model, for the same
    // reason: it renders them in a fraction of the ray caster's time.
    let status = touchdown()
        .args(["simulate", "--ideal", "--scenario", "descent", "--frames"])
        .arg(frames.to_string())
        .args(["--renderer", "warp"])
        .arg("--out")
        .arg(&dir)
        .status()
        .expect("run touchdown simulate");
    assert!(status.success(), "simulate failed");
    dir
}

/// A ground station's PARAM_SET of `name` to `value` for touchdown (system 1, component 191).
fn param_set(name: &str, value: f32) -> Vec<u8> {
    let header = MavHeader {
        system_id: 255,
        component_id: 190,
        sequence: 0,
    };
    let set = PARAM_SET_DATA {
        param_value: value,
        target_system: 1,
        target_component: 191,
        param_id: name.into(),
        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
    };
    mavlink2(header, &MavMessage::PARAM_SET(set))
}

/// Runs `touchdown companion --serial` on `recording` against a pty, playing the flight
/// controller (a heartbeat every 250 ms) after writing `first` to the port, and returns
/// everything the command wrote, decoded by pymavlink (strict), or `None` without pymavlink.
/// `run` names the run's bytes beside the recording (runs on the same recording may overlap).
fn run_over_pty(recording: &Path, run: &str, first: &[u8]) -> Option<Vec<Value>> {
    // The flight controller's end (master) and the port the command opens (slave).
    let master = openpt(OpenptFlags::RDWR | OpenptFlags::NOCTTY).expect("openpt");
    grantpt(&master).expect("grantpt");
    unlockpt(&master).expect("unlockpt");
    // Raw from the start: a new pty echoes what the master writes back to it (the heartbeats
    // would come back mixed into the command's output) until the command makes its end raw.
    let mut modes = rustix::termios::tcgetattr(&master).expect("tcgetattr");
    modes.make_raw();
    rustix::termios::tcsetattr(&master, rustix::termios::OptionalActions::Now, &modes)
        .expect("tcsetattr");
    let slave = PathBuf::from(
        ptsname(&master, Vec::new())
            .expect("ptsname")
            .to_string_lossy()
            .into_owned(),
    );
    let mut port = std::fs::File::from(master);

    let mut child = touchdown()
        .args(["companion", "--recording"])
        .arg(recording)
        .arg("--serial")
        .arg(&slave)
        .args(["--baud", "115200", "--lead", "1", "--linger", "0.5"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn touchdown companion");

    // Reader: everything the command writes, until the slave side closes (EIO) or a timeout.
    let mut reader = port.try_clone().expect("clone the pty");
    let collect = std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let mut buf = [0u8; 4096];
        let deadline = Instant::now() + Duration::from_secs(60);
        while Instant::now() < deadline {
            match reader.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => bytes.extend_from_slice(&buf[..n]),
                // EIO once the last holder of the slave closed it: the command exited.
                Err(_) => break,
            }
        }
        bytes
    });
    // The autopilot side: a heartbeat every 250 ms while the command runs, after `first`
    // (written once the command has had time to open the port and make it raw).
    let mut seq = 0u8;
    let mut sent_first = first.is_empty();
    let exit = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        let _ = port.write_all(&autopilot_heartbeat(&mut seq));
        if !sent_first && seq >= 2 {
            let _ = port.write_all(first);
            sent_first = true;
        }
        std::thread::sleep(Duration::from_millis(250));
    };
    let mut stderr = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut stderr);
    }
    assert!(exit.success(), "touchdown companion failed: {stderr}");
    drop(port);
    let bytes = collect.join().expect("reader thread");
    assert!(!bytes.is_empty(), "nothing arrived on the serial port");

    // pymavlink, strict.
    let path = recording.with_extension(format!("{run}.bin"));
    std::fs::write(&path, &bytes).expect("write frames");
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scripts/mavlink_decode.py");
    let output = Command::new("python3").arg(&script).arg(&path).output();
    let _ = std::fs::remove_file(&path);
    let output = match output {
        Ok(o) if o.status.code() != Some(3) => o,
        _ => {
            println!("skipping: pymavlink not installed");
            return None;
        }
    };
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "pymavlink refused the stream: {stdout}"
    );
    let msgs: Vec<Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).expect("json line"))
        .collect();
    let summary = msgs.last().expect("summary line");
    assert_eq!(summary["_summary"], true);
    assert_eq!(summary["leftover"], 0, "undecoded bytes left");
    println!("serial: {} bytes, {} messages", bytes.len(), msgs.len() - 1);
    Some(msgs)
}

fn count(msgs: &[Value], kind: &str) -> usize {
    msgs.iter().filter(|m| m["_type"] == kind).count()
}

/// The `distance` of every LANDING_TARGET, in order.
fn target_distances(msgs: &[Value]) -> Vec<f64> {
    msgs.iter()
        .filter(|m| m["_type"] == "LANDING_TARGET")
        .map(|m| m["distance"].as_f64().expect("distance"))
        .collect()
}

#[test]
fn companion_over_a_pseudo_terminal() {
    let dir = descent_recording("plain", 45);
    let msgs = run_over_pty(&dir, "plain", &[]);
    let _ = std::fs::remove_dir_all(&dir);
    let Some(msgs) = msgs else { return };
    println!(
        "serial: {} HEARTBEAT, {} LANDING_TARGET",
        count(&msgs, "HEARTBEAT"),
        count(&msgs, "LANDING_TARGET")
    );
    assert!(count(&msgs, "HEARTBEAT") >= 2);
    // 45 frames of a descent onto the pad, all in view: a target for most of them.
    assert!(count(&msgs, "LANDING_TARGET") >= 20);
    for m in msgs.iter().filter(|m| m["_type"] == "LANDING_TARGET") {
        assert_eq!(m["frame"], 12, "BODY_FRD for ArduPilot: {m}");
        assert_eq!(m["_version"], 2);
    }
}

/// TD_TAG_SIZE set over MAVLink reaches the host's per-frame path as it reaches the board's:
/// telling touchdown that the nested pad (largest marker 1.25 m) is printed at 0.625 m halves
/// every distance it reports for the same frames.
#[test]
fn tag_size_set_over_mavlink_scales_the_distances() {
    let dir = descent_recording("tag-size", 30);
    // The two runs side by side, each on its own pty: they only read the recording.
    let (as_built, half) = std::thread::scope(|scope| {
        let as_built = scope.spawn(|| run_over_pty(&dir, "as-built", &[]));
        let half = run_over_pty(&dir, "half", &param_set("TD_TAG_SIZE", 0.625));
        (as_built.join().expect("the run as built"), half)
    });
    let _ = std::fs::remove_dir_all(&dir);
    let (Some(as_built), Some(half)) = (as_built, half) else {
        return;
    };
    // The PARAM_SET was taken and echoed.
    assert!(
        half.iter().any(|m| m["_type"] == "PARAM_VALUE"
            && m["param_id"] == "TD_TAG_SIZE"
            && (m["param_value"].as_f64().unwrap() - 0.625).abs() < 1e-6),
        "no PARAM_VALUE echo of TD_TAG_SIZE"
    );
    let (full, scaled) = (target_distances(&as_built), target_distances(&half));
    assert!(
        full.len() >= 10 && scaled.len() >= 10,
        "{} and {} targets",
        full.len(),
        scaled.len()
    );
    // Target k of both runs comes from (nearly) the same frame: compare them pairwise and
    // take the median, which a frame skipped in one run cannot move.
    let mut ratios: Vec<f64> = scaled.iter().zip(&full).map(|(s, f)| s / f).collect();
    ratios.sort_by(f64::total_cmp);
    let ratio = ratios[ratios.len() / 2];
    println!(
        "TD_TAG_SIZE 0.625: median distance ratio {ratio:.4} over {} targets (first {:.3} m against {:.3} m as built)",
        ratios.len(),
        scaled[0],
        full[0]
    );
    assert!((ratio - 0.5).abs() < 0.01, "ratio {ratio}");
}
