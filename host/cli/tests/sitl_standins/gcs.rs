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
//! board's link is opened. The same for a GPS-denied rehearsal (`--gps-loss-height`): a
//! build without the SITL's GPS switch, without visual odometry or without ARMING_SKIPCHK, a
//! PX4, and the arming check's bit added to what the autopilot already skips.

use crate::common;

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
    /// What its HEARTBEAT says it is.
    autopilot: MavAutopilot,
    /// Parameters it has, with their values.
    params: HashMap<&'static str, f32>,
    /// A parameter whose writes it ignores.
    refuses: Option<&'static str>,
}

impl StandIn {
    fn ardupilot() -> Self {
        StandIn {
            armed: false,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
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
                // For --gps-loss-height.
                ("SIM_GPS1_ENABLE", 1.0),
                ("VISO_TYPE", 0.0),
                ("VISO_DELAY_MS", 10.0),
                ("EK3_SRC2_POSXY", 0.0),
                ("EK3_SRC2_VELXY", 0.0),
                ("EK3_SRC2_POSZ", 1.0),
                ("EK3_SRC2_VELZ", 0.0),
                ("EK3_SRC2_YAW", 0.0),
                ("ARMING_SKIPCHK", 6.0),
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
                    autopilot: standin.autopilot,
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
    rehearse_with(standin, &[])
}

/// [`rehearse`] with more options for `touchdown sitl`.
fn rehearse_with(standin: Option<StandIn>, extra: &[&str]) -> Output {
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
            // A closed port and a missing parameter are waited out: a second, and three
            // tries of half a second, instead of the defaults' 10 s and 4.5 s.
            "--connect-timeout",
            "1",
            "--param-timeout",
            "0.5",
        ])
        .args(extra)
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

/// The run retries the refused port for its whole `--connect-timeout`, then says why.
#[test]
fn a_closed_port_asks_whether_the_sitl_runs() {
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

/// A GPS-denied rehearsal's option: GPS lost at 12 m of a 12 m climb.
const GPS_LOSS: [&str; 4] = ["--height", "12", "--gps-loss-height", "12"];

#[test]
fn gps_loss_without_the_sitls_gps_switch_is_one_line() {
    let mut standin = StandIn::ardupilot();
    standin.params.remove("SIM_GPS1_ENABLE");
    assert_one_line_error(
        &rehearse_with(Some(standin), &GPS_LOSS),
        &[
            "--gps-loss-height",
            "neither SIM_GPS1_ENABLE nor SIM_GPS_DISABLE",
        ],
    );
}

#[test]
fn gps_loss_without_visual_odometry_or_the_skip_mask_says_what_is_missing() {
    // Two stand-ins side by side: each run waits out the tries of the parameter it lacks.
    let [viso, skip] = ["VISO_TYPE", "ARMING_SKIPCHK"].map(|missing| {
        std::thread::spawn(move || {
            let mut standin = StandIn::ardupilot();
            standin.params.remove(missing);
            rehearse_with(Some(standin), &GPS_LOSS)
        })
    });
    assert_one_line_error(
        &viso.join().expect("the run without VISO_TYPE"),
        &["no parameter VISO_TYPE", "visual odometry"],
    );
    assert_one_line_error(
        &skip.join().expect("the run without ARMING_SKIPCHK"),
        &["no parameter ARMING_SKIPCHK", "ARMING_CHECK"],
    );
}

#[test]
fn gps_loss_adds_the_vision_bit_to_the_checks_already_skipped() {
    // The stand-in skips bits 1 and 2 (6) and refuses the write: the value asked for is
    // both, plus bit 18 (262144).
    let standin = StandIn {
        refuses: Some("ARMING_SKIPCHK"),
        ..StandIn::ardupilot()
    };
    assert_one_line_error(
        &rehearse_with(Some(standin), &GPS_LOSS),
        &["refused ARMING_SKIPCHK = 262150", "keeps 6"],
    );
}

#[test]
fn gps_loss_on_px4_is_not_supported_yet() {
    let standin = StandIn {
        autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
        ..StandIn::ardupilot()
    };
    assert_one_line_error(
        &rehearse_with(Some(standin), &GPS_LOSS),
        &["--gps-loss-height", "not supported on PX4 yet"],
    );
}

#[test]
fn gps_loss_options_out_of_place_are_usage_errors() {
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_touchdown"))
            .args(args)
            .output()
            .expect("run touchdown")
    };
    // Above the climb, or not a height.
    for bad in ["13", "0", "nan"] {
        assert_one_line_error(
            &run(&[
                "sitl",
                "--tcp",
                "127.0.0.1:9",
                "--gcs",
                "tcp:127.0.0.1:9",
                "--height",
                "12",
                "--gps-loss-height",
                bad,
            ]),
            &["--gps-loss-height must be"],
        );
    }
    // Without the ground station, or without a SITL at all.
    assert_one_line_error(
        &run(&[
            "sitl",
            "--tcp",
            "127.0.0.1:9",
            "--height",
            "12",
            "--gps-loss-height",
            "8",
        ]),
        &["--gps-loss-height needs --gcs"],
    );
    assert_one_line_error(
        &run(&["sitl", "--height", "12", "--gps-loss-height", "8"]),
        &["--gps-loss-height", "running SITL"],
    );
    // A board told to send no position.
    assert_one_line_error(
        &run(&[
            "sitl",
            "--tcp",
            "127.0.0.1:9",
            "--gcs",
            "tcp:127.0.0.1:9",
            "--height",
            "12",
            "--gps-loss-height",
            "8",
            "--board-params",
            "TD_VPE_EN=2",
        ]),
        &["TD_VPE_EN = 2", "VISION_POSITION_ESTIMATE"],
    );
}

#[test]
fn no_gps_and_pad_options_out_of_place_are_usage_errors() {
    const LINKS: [&str; 4] = ["--tcp", "127.0.0.1:9", "--gcs", "tcp:127.0.0.1:9"];
    let cases: [(Vec<&str>, &[&str]); 12] = [
        // Signing: the ground station sets the key on the autopilot, so only with it.
        (
            vec!["--tcp", "127.0.0.1:9", "--signing-key", "secret"],
            &["--signing-key needs --gcs"],
        ),
        (
            vec!["--signing-key", "secret"],
            &["--signing-key", "running SITL"],
        ),
        (
            [&LINKS[..], &["--signing-key", ""]].concat(),
            &["--signing-key: empty"],
        ),
        (
            vec!["--tcp", "127.0.0.1:9", "--no-gps"],
            &["--no-gps needs --gcs"],
        ),
        (vec!["--no-gps"], &["--no-gps", "running SITL"]),
        (
            [&LINKS[..], &["--no-gps", "--gps-loss-height", "8"]].concat(),
            &["--no-gps", "--gps-loss-height"],
        ),
        (
            [&LINKS[..], &["--no-gps", "--board-params", "TD_VPE_EN=0"]].concat(),
            &["--no-gps: TD_VPE_EN = 0", "VISION_POSITION_ESTIMATE"],
        ),
        (
            vec!["--pad", "round"],
            &["--pad: no design `round`", "nested-rest"],
        ),
        // A moving pad against a running SITL: only with the ground station, which starts it
        // with the LAND; never heaving or rolling (the SITL's ground is still), never without
        // GPS (the board's position is against the pad).
        (
            vec!["--tcp", "127.0.0.1:9", "--pad-velocity", "1,0"],
            &["moving pad", "needs --gcs"],
        ),
        (
            [
                &LINKS[..],
                &["--pad-velocity", "1,0", "--deck-heave", "0.3@6"],
            ]
            .concat(),
            &["--deck-heave", "for the model"],
        ),
        (
            [&LINKS[..], &["--pad-velocity", "1,0", "--no-gps"]].concat(),
            &["--no-gps", "moving pad"],
        ),
        (
            vec!["--pad-turn-rate", "5"],
            &["--pad-turn-rate", "--pad-velocity too"],
        ),
    ];
    for (args, needles) in cases {
        let output = Command::new(env!("CARGO_BIN_EXE_touchdown"))
            .arg("sitl")
            .args(&args)
            .output()
            .expect("run touchdown");
        assert_one_line_error(&output, needles);
    }
}

#[test]
fn timeouts_that_are_not_seconds_are_usage_errors() {
    for (option, bad) in [
        ("--connect-timeout", "0"),
        ("--connect-timeout", "nan"),
        ("--param-timeout", "0.0"),
        ("--param-timeout", "1e9"),
    ] {
        let output = Command::new(env!("CARGO_BIN_EXE_touchdown"))
            .args([
                "sitl",
                "--tcp",
                "127.0.0.1:9",
                "--gcs",
                "tcp:127.0.0.1:9",
                option,
                bad,
            ])
            .output()
            .expect("run touchdown");
        assert_eq!(output.status.code(), Some(2), "{option} {bad}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(
            stderr.contains(option) && stderr.contains("at most 3600"),
            "{option} {bad}: {stderr}"
        );
    }
}
