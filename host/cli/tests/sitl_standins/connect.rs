//! `touchdown sitl --tcp` against a stand-in for ArduPilot SITL: a TCP server that speaks
//! what ArduCopter SITL sends on a serial port (HEARTBEAT, SYSTEM_TIME, ATTITUDE_QUATERNION,
//! SIM_STATE with the position in 1e-7 degrees in both its float and its integer fields,
//! TIMESYNC answers) for a vehicle it flies on a script: a hover at 4 m, 30 cm north and 20 cm
//! west of the pad, heading 30 degrees, then straight down at 1 m/s onto the ground.
//!
//! Like ArduPilot on a port that streams nothing unasked, the stand-in sends SIM_STATE only once
//! it has been asked for it with SET_MESSAGE_INTERVAL.
//!
//! Asserted: the run asks for SIM_STATE, and every frame it sends is in one unbroken sequence
//! (one sender, as the autopilot's link statistics expect of the board); every LANDING_TARGET
//! the run sends is in BODY_FRD and points at the pad as the
//! script has it (the horizontal components, which the script holds constant, within a few
//! centimetres); enough of them arrive; and the run reports the touchdown where the script
//! put the vehicle down; with TD_VPE_EN 1, every VISION_POSITION_ESTIMATE the board sends is
//! matched to its frame and right to centimetres in the run's own check. That is the whole
//! connected path: ground truth decoded from the
//! SITL's messages, the frames rendered from it, the per-frame path and the companion on
//! them, and the bytes both ways over TCP in wall-clock time.

use crate::common;

use std::io::{Read, Write};
use std::net::TcpListener;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use touchdown_core::companion::mavlink::dialects::common::{
    MavBool, MavCmd, MavFrame, MavMessage, MavModeFlag, ATTITUDE_QUATERNION_DATA, SIM_STATE_DATA,
    SYSTEM_TIME_DATA, TIMESYNC_DATA,
};
use touchdown_core::companion::FrameParser;

/// The pad's origin (ArduPilot SITL's default home, CMAC).
const PAD: [f64; 3] = [-35.363_261, 149.165_230, 584.0];
const NORTH_M: f64 = 0.30;
const EAST_M: f64 = -0.20;
const YAW_DEG: f64 = 30.0;
/// The hover before the descent, seconds.
const HOVER_S: f64 = 1.0;
/// Above `touchdown sitl`'s airborne height (2 m), from which a landing counts.
const START_HEIGHT_M: f64 = 4.0;
const GEAR_M: f64 = 0.1;

/// The scripted vehicle's height over the pad at `t` seconds.
fn height(t: f64) -> f64 {
    (START_HEIGHT_M - (t - HOVER_S).max(0.0)).max(GEAR_M)
}

#[test]
fn a_landing_against_a_sitl_over_tcp_is_rendered_from_its_ground_truth() {
    let json = land_on_the_standin(&[]);
    // No VISION_POSITION_ESTIMATE sent (TD_VPE_EN 0): no figure for it.
    assert!(json.get("vision_accuracy").is_none(), "{json}");
}

/// With TD_VPE_EN bit 0 the run sets each VISION_POSITION_ESTIMATE the board sends against
/// the stand-in's truth at its frame's time (the stand-in answers TIMESYNC, so the stamps
/// are in its clock): every one finds its frame, the hover and the descent above the
/// airborne height give a figure, and with an ideal camera over a still vehicle the
/// position is right to centimetres. Only watching: no figure while holding.
#[test]
fn the_boards_vision_position_is_checked_against_the_truth() {
    let json = land_on_the_standin(&["--board-params", "TD_VPE_EN=1"]);
    let v = &json["vision_accuracy"];
    let messages = v["messages"].as_u64().expect("messages");
    assert!(messages >= 10, "{v}");
    assert_eq!(v["without_truth"], 0, "{v}");
    assert!(v.get("holding").is_none(), "{v}");
    let airborne = &v["airborne"];
    assert!(airborne["messages"].as_u64().expect("airborne") >= 5, "{v}");
    let max = airborne["horizontal_max_m"].as_f64().expect("max");
    assert!(max < 0.05, "{v}");
    let pct = airborne["within_2sigma_pct"].as_f64().expect("pct");
    assert!((0.0..=100.0).contains(&pct), "{v}");
}

/// Flies `touchdown sitl --json` (with `extra` arguments) against the stand-in, asserts what
/// every such landing must show, and returns its JSON line.
fn land_on_the_standin(extra: &[&str]) -> serde_json::Value {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = listener.local_addr().expect("addr").port();
    let pad_at = format!("{},{},{}", PAD[0], PAD[1], PAD[2]);
    let child = Command::new(env!("CARGO_BIN_EXE_touchdown"))
        .args([
            "sitl",
            "--tcp",
            &format!("127.0.0.1:{port}"),
            "--pad-at",
            &pad_at,
            "--ideal",
            "--qvga",
            "--fps",
            "10",
            "--max-time",
            "40",
            "--json",
        ])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("touchdown sitl");
    // Accept without blocking, so that a run that fails before it connects fails the test
    // with its message instead of hanging it.
    let mut child = child;
    listener
        .set_nonblocking(true)
        .expect("non-blocking listener");
    let waited = Instant::now();
    let mut stream = loop {
        match listener.accept() {
            Ok((stream, _)) => break stream,
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
            Err(e) => panic!("accept: {e}"),
        }
        if child.try_wait().expect("the run").is_some() || waited.elapsed().as_secs() > 30 {
            let _ = child.kill();
            let output = child.wait_with_output().expect("the run");
            panic!(
                "the run never connected: {}",
                String::from_utf8_lossy(&output.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    stream.set_nonblocking(true).expect("non-blocking");

    let yaw = YAW_DEG.to_radians();
    let (half_cos, half_sin) = ((yaw / 2.0).cos() as f32, (yaw / 2.0).sin() as f32);
    let lat_e7 = ((PAD[0] + (NORTH_M / 6_378_137.0).to_degrees()) * 1e7).round();
    let lon_e7 = ((PAD[1] + (EAST_M / (6_378_137.0 * PAD[0].to_radians().cos())).to_degrees())
        * 1e7)
        .round();
    // The pad seen from the body: NED (-north, -east, +height) turned by -yaw.
    let (c, s) = (yaw.cos(), yaw.sin());
    let body_x = c * -NORTH_M + s * -EAST_M;
    let body_y = -s * -NORTH_M + c * -EAST_M;

    let start = Instant::now();
    let mut seq = 0u8;
    let mut parser = FrameParser::new();
    let mut next_sample = 0.0;
    let mut next_second = 0.0;
    let mut targets = 0usize;
    let mut worst_cm = 0.0f64;
    let mut wrong_frames = 0usize;
    // SIM_STATE is streamed once asked for (MAV_CMD_SET_MESSAGE_INTERVAL, message 108).
    let mut truth_asked = false;
    // The run's frames: the sequence number expected next, and how many broke the sequence.
    let mut next_seq: Option<u8> = None;
    let mut sequence_breaks = 0usize;
    let mut frames_in = 0usize;
    let mut buf = [0u8; 4096];
    while start.elapsed() < Duration::from_secs(40) {
        let t = start.elapsed().as_secs_f64();
        let boot_ms = (t * 1e3) as u32;
        let mut out = Vec::new();
        if t >= next_second {
            next_second += 1.0;
            // In the air from the start: armed.
            out.extend(common::ardupilot_heartbeat_with(
                seq,
                MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
            ));
            seq = seq.wrapping_add(1);
            out.extend(common::autopilot_frame(
                &mut seq,
                &MavMessage::SYSTEM_TIME(SYSTEM_TIME_DATA {
                    time_unix_usec: 0,
                    time_boot_ms: boot_ms,
                }),
            ));
        }
        let sample_due = t >= next_sample;
        if sample_due {
            next_sample += 0.02;
            out.extend(common::autopilot_frame(
                &mut seq,
                &MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
                    time_boot_ms: boot_ms,
                    q1: half_cos,
                    q4: half_sin,
                    ..ATTITUDE_QUATERNION_DATA::DEFAULT
                }),
            ));
        }
        if sample_due && truth_asked {
            out.extend(common::autopilot_frame(
                &mut seq,
                &MavMessage::SIM_STATE(SIM_STATE_DATA {
                    q1: half_cos,
                    q4: half_sin,
                    yaw: yaw as f32,
                    lat: lat_e7 as f32,
                    lon: lon_e7 as f32,
                    lat_int: lat_e7 as i32,
                    lon_int: lon_e7 as i32,
                    alt: (PAD[2] + height(t)) as f32,
                    vd: if height(t) > GEAR_M && t > HOVER_S {
                        1.0
                    } else {
                        0.0
                    },
                    ..SIM_STATE_DATA::DEFAULT
                }),
            ));
        }
        match stream.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                let mut answers = Vec::new();
                parser.push(&buf[..n], |f| {
                    frames_in += 1;
                    if next_seq.is_some_and(|s| s != f.sequence) {
                        sequence_breaks += 1;
                    }
                    next_seq = Some(f.sequence.wrapping_add(1));
                    match f.decode() {
                        Ok(MavMessage::COMMAND_LONG(c))
                            if c.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL
                                && c.param1 == 108.0
                                && (c.target_system, c.target_component) == (1, 1) =>
                        {
                            truth_asked = true;
                        }
                        Ok(MavMessage::TIMESYNC(ts)) if ts.tc1 == 0 => {
                            answers.push(MavMessage::TIMESYNC(TIMESYNC_DATA {
                                tc1: (t * 1e9) as i64,
                                ts1: ts.ts1,
                                target_system: 0,
                                target_component: 0,
                            }))
                        }
                        Ok(MavMessage::LANDING_TARGET(lt)) => {
                            targets += 1;
                            if lt.frame != MavFrame::MAV_FRAME_BODY_FRD
                                || lt.position_valid != MavBool::MAV_BOOL_TRUE
                            {
                                wrong_frames += 1;
                            }
                            let miss = (f64::from(lt.x) - body_x).hypot(f64::from(lt.y) - body_y);
                            worst_cm = worst_cm.max(100.0 * miss);
                        }
                        _ => {}
                    }
                });
                for answer in answers {
                    out.extend(common::autopilot_frame(&mut seq, &answer));
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
            Err(_) => break,
        }
        if !out.is_empty() && stream.write_all(&out).is_err() {
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let output = child.wait_with_output().expect("the run ends");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(0), "{stdout}\n{stderr}");
    let json: serde_json::Value = serde_json::from_str(stdout.trim()).expect("one JSON line");
    println!("{json}\ntargets {targets}, worst horizontal miss {worst_cm:.1} cm");
    assert!(truth_asked, "the run never asked for SIM_STATE: {stderr}");
    assert_eq!(
        sequence_breaks, 0,
        "{sequence_breaks} of {frames_in} frames broke the run's sequence"
    );
    assert_eq!(json["autopilot"], "sitl");
    assert_eq!(json["touched_down"], true, "{json}");
    let north = json["north_cm"].as_f64().expect("north");
    let east = json["east_cm"].as_f64().expect("east");
    assert!((north - 100.0 * NORTH_M).abs() < 1.0, "{json}");
    assert!((east - 100.0 * EAST_M).abs() < 1.0, "{json}");
    assert_eq!(wrong_frames, 0, "targets not BODY_FRD with a position");
    assert!(
        targets >= 20,
        "only {targets} LANDING_TARGETs arrived: {json}"
    );
    assert!(worst_cm < 5.0, "a target {worst_cm:.1} cm off the pad");
    json
}
