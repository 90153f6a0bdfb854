//! `touchdown companion --serial` against a pseudo-terminal: the command opens the port with
//! its termios set-up, replays a simulated recording and writes MAVLink 2 to it; the test
//! plays the flight controller on the pty's other end (a HEARTBEAT a second, as ArduPilot
//! sends) and hands everything it read to pymavlink (strict parsing, as in
//! tests/companion.rs).
//!
//! This is the path a user takes with a USB-serial adapter or a flight controller's USB port,
//! short of the wire: open, raw mode, speed, non-blocking reads and writes, and the exit.

#![cfg(unix)]

use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use rustix::pty::{grantpt, openpt, ptsname, unlockpt, OpenptFlags};
use serde_json::Value;
use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavMessage, MavModeFlag, MavState, MavType, HEARTBEAT_DATA,
};
use touchdown_core::companion::mavlink::{MAVLinkV2MessageRaw, MavHeader};

fn touchdown() -> Command {
    Command::new(env!("CARGO_BIN_EXE_touchdown"))
}

/// An autopilot HEARTBEAT (system 1, component 1) as MAVLink 2 bytes.
fn autopilot_heartbeat(seq: u8) -> Vec<u8> {
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message(
        MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: seq,
        },
        &MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: MavModeFlag::empty(),
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        }),
    );
    raw.raw_bytes().to_vec()
}

#[test]
fn companion_over_a_pseudo_terminal() {
    let dir = std::env::temp_dir().join(format!("touchdown-serial-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let status = touchdown()
        .args([
            "simulate",
            "--scenario",
            "descent",
            "--frames",
            "45",
            "--out",
        ])
        .arg(&dir)
        .status()
        .expect("run touchdown simulate");
    assert!(status.success(), "simulate failed");

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
        .arg(&dir)
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
    // The autopilot side: a heartbeat a second while the command runs.
    let mut seq = 0u8;
    let exit = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        let _ = port.write_all(&autopilot_heartbeat(seq));
        seq = seq.wrapping_add(1);
        std::thread::sleep(Duration::from_millis(250));
    };
    let mut stderr = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut stderr);
    }
    assert!(exit.success(), "touchdown companion failed: {stderr}");
    drop(port);
    let bytes = collect.join().expect("reader thread");
    let _ = std::fs::remove_dir_all(&dir);
    assert!(!bytes.is_empty(), "nothing arrived on the serial port");

    // pymavlink, strict.
    let path = std::env::temp_dir().join(format!("touchdown-serial-{}.bin", std::process::id()));
    std::fs::write(&path, &bytes).expect("write frames");
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/companion_decode.py");
    let output = Command::new("python3").arg(&script).arg(&path).output();
    let _ = std::fs::remove_file(&path);
    let output = match output {
        Ok(o) if o.status.code() != Some(3) => o,
        _ => {
            println!("skipping: pymavlink not installed");
            return;
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
    let count = |kind: &str| msgs.iter().filter(|m| m["_type"] == kind).count();
    println!(
        "serial: {} bytes, {} messages: {} HEARTBEAT, {} LANDING_TARGET",
        bytes.len(),
        msgs.len() - 1,
        count("HEARTBEAT"),
        count("LANDING_TARGET")
    );
    assert!(count("HEARTBEAT") >= 2, "{stdout}");
    // 45 frames of a descent onto the pad, all in view: a target for most of them.
    assert!(count("LANDING_TARGET") >= 20, "{stdout}");
    for m in msgs.iter().filter(|m| m["_type"] == "LANDING_TARGET") {
        assert_eq!(m["frame"], 12, "BODY_FRD for ArduPilot: {m}");
        assert_eq!(m["_version"], 2);
    }
}
