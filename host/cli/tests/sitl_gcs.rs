//! `touchdown sitl --gcs`'s ground-station half against stand-ins for an autopilot's
//! ground-station port: what a user meets before the flight starts. The flight itself is
//! flown against the real ArduCopter and PX4 SITLs by `scripts/sitl_rehearsal.sh` in CI.
//!
//! The stand-in speaks ArduCopter's parameter protocol over TCP: HEARTBEATs (armed or not),
//! PARAM_VALUE for every PARAM_REQUEST_READ of a name it has, and for a PARAM_SET the value
//! it then holds (unchanged for a parameter it refuses); nothing for a name it lacks.
//!
//! Asserted: a port with nothing behind it, an armed vehicle, a refused parameter and a
//! missing one each end the run with exit status 2 and one line saying which, before the
//! board's link is opened.

#[allow(dead_code)] // The shared helpers this file does not need.
mod common;

use std::collections::HashMap;
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavMessage, MavModeFlag, MavParamType, MavState, MavType, HEARTBEAT_DATA,
    PARAM_VALUE_DATA,
};
use touchdown_core::companion::FrameParser;

/// How the stand-in behaves.
#[derive(Clone)]
struct StandIn {
    armed: bool,
    /// Parameters it has, with their values.
    params: HashMap<&'static str, f32>,
    /// A parameter whose writes it ignores.
    refuses: Option<&'static str>,
}

impl StandIn {
    fn ardupilot() -> Self {
        StandIn {
            armed: false,
            params: [
                ("PLND_ENABLED", 0.0),
                ("PLND_TYPE", 0.0),
                ("PLND_EST_TYPE", 1.0),
                ("PLND_ORIENT", 25.0),
                ("PLND_YAW_ALIGN", 0.0),
                ("SIM_WIND_SPD", 0.0),
                ("SIM_WIND_DIR", 180.0),
                ("SIM_WIND_T", 0.0),
                ("SIM_WIND_TURB", 0.0),
            ]
            .into_iter()
            .collect(),
            refuses: None,
        }
    }
}

fn param_value(seq: &mut u8, name: &str, value: f32) -> Vec<u8> {
    common::autopilot_frame(
        seq,
        &MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
            param_value: value,
            param_count: 9,
            param_index: 0,
            param_id: name.into(),
            param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
        }),
    )
}

/// Serves one client until it leaves or 30 s pass.
fn serve(mut stream: TcpStream, mut standin: StandIn) {
    let _ = stream.set_nonblocking(true);
    let mut parser = FrameParser::new();
    let mut seq = 0u8;
    let mut rx = [0u8; 2048];
    let mut next_heartbeat = Instant::now();
    let until = Instant::now() + Duration::from_secs(30);
    while Instant::now() < until {
        if Instant::now() >= next_heartbeat {
            next_heartbeat = Instant::now() + Duration::from_millis(200);
            let base_mode = if standin.armed {
                MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
            } else {
                MavModeFlag::empty()
            };
            let hb = common::autopilot_frame(
                &mut seq,
                &MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                    custom_mode: 0,
                    mavtype: MavType::MAV_TYPE_QUADROTOR,
                    autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                    base_mode,
                    system_status: MavState::MAV_STATE_STANDBY,
                    mavlink_version: 3,
                }),
            );
            if stream.write_all(&hb).is_err() {
                return;
            }
        }
        let n = match stream.read(&mut rx) {
            Ok(0) => return,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => 0,
            Err(_) => return,
        };
        let mut replies = Vec::new();
        parser.push(&rx[..n], |f| match f.decode() {
            Ok(MavMessage::PARAM_REQUEST_READ(r)) => {
                let name = touchdown_core::params::name_str(&r.param_id[..]).to_string();
                if let Some((k, v)) = standin.params.get_key_value(name.as_str()) {
                    replies.push((*k, *v));
                }
            }
            Ok(MavMessage::PARAM_SET(s)) => {
                let name = touchdown_core::params::name_str(&s.param_id[..]).to_string();
                let refused = standin.refuses == Some(name.as_str());
                if let Some((k, v)) = standin.params.get_key_value(name.as_str()) {
                    let (k, held) = (*k, if refused { *v } else { s.param_value });
                    standin.params.insert(k, held);
                    replies.push((k, held));
                }
            }
            _ => {}
        });
        for (name, value) in replies {
            if stream
                .write_all(&param_value(&mut seq, name, value))
                .is_err()
            {
                return;
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Runs `touchdown sitl --gcs` against the stand-in (or against nothing when `standin` is
/// `None`, on a port that was just freed).
fn rehearse(standin: Option<StandIn>) -> Output {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = listener.local_addr().expect("addr").port();
    let server = match standin {
        Some(s) => Some(std::thread::spawn(move || {
            if let Ok((stream, _)) = listener.accept() {
                serve(stream, s);
            }
        })),
        None => {
            drop(listener);
            None
        }
    };
    let output = Command::new(env!("CARGO_BIN_EXE_touchdown"))
        .args([
            "sitl",
            // The board's link: never opened, since every case here fails before it.
            "--tcp",
            "127.0.0.1:9",
            "--gcs",
            &format!("tcp:127.0.0.1:{port}"),
        ])
        .output()
        .expect("run touchdown");
    if let Some(server) = server {
        let _ = server.join();
    }
    output
}

fn assert_one_line_error(output: &Output, needles: &[&str]) {
    assert_eq!(output.status.code(), Some(2), "{output:?}");
    let stderr = String::from_utf8_lossy(&output.stderr);
    let last = stderr.lines().last().unwrap_or_default();
    assert!(last.starts_with("error: "), "{stderr}");
    for needle in needles {
        assert!(last.contains(needle), "`{needle}` not in {last:?}");
    }
}

#[test]
fn no_sitl_on_the_port_is_one_line() {
    assert_one_line_error(
        &rehearse(None),
        &["--gcs tcp:127.0.0.1:", "is the SITL running?"],
    );
}

#[test]
fn an_armed_vehicle_is_refused() {
    let standin = StandIn {
        armed: true,
        ..StandIn::ardupilot()
    };
    assert_one_line_error(&rehearse(Some(standin)), &["armed", "on the ground"]);
}

#[test]
fn a_refused_parameter_is_named_with_what_the_autopilot_keeps() {
    let standin = StandIn {
        refuses: Some("PLND_TYPE"),
        ..StandIn::ardupilot()
    };
    assert_one_line_error(
        &rehearse(Some(standin)),
        &["refused PLND_TYPE = 1", "keeps 0"],
    );
}

#[test]
fn a_missing_parameter_is_named() {
    let mut standin = StandIn::ardupilot();
    standin.params.remove("PLND_EST_TYPE");
    assert_one_line_error(&rehearse(Some(standin)), &["no parameter PLND_EST_TYPE"]);
}

#[test]
fn gcs_without_the_boards_link_is_a_usage_error() {
    let output = Command::new(env!("CARGO_BIN_EXE_touchdown"))
        .args(["sitl", "--gcs", "tcp:127.0.0.1:5760"])
        .output()
        .expect("run touchdown");
    assert_one_line_error(&output, &["--gcs", "board's link"]);
    let output = Command::new(env!("CARGO_BIN_EXE_touchdown"))
        .args(["sitl", "--tcp", "127.0.0.1:5762", "--gcs", "5760"])
        .output()
        .expect("run touchdown");
    assert_eq!(output.status.code(), Some(2), "{output:?}");
}
