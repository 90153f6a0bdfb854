//! `touchdown companion` stopped by SIGINT, run in this process: `run` must return
//! `Outcome::Stopped` with 130 after writing its summary, not exit the process itself (a
//! `std::process::exit` there would skip every destructor, the endpoint's and the output
//! buffers', and would end this test binary with status 130, failing it).
//!
//! Its own test binary: the signal handlers are process-wide, and a second signal would end
//! the process at once, so there is exactly one signalled run here. The exit statuses as the
//! shell sees them (130 and 143) are checked on the binary in `companion_net.rs`.

#![cfg(unix)]

mod common;

use std::net::UdpSocket;
use std::process::Command;
use std::time::Duration;

use signal_hook::consts::SIGINT;
use touchdown_cli::companion::{self, CompanionArgs, ProfileArg};
use touchdown_cli::Outcome;

#[test]
fn sigint_returns_the_outcome_after_the_summary() {
    let dir = common::scratch("companion-signal-tests", "descent");
    let status = Command::new(env!("CARGO_BIN_EXE_touchdown"))
        .args([
            "simulate",
            "--ideal",
            "--scenario",
            "descent",
            "--frames",
            "5",
            "--renderer",
            "warp",
        ])
        .arg("--out")
        .arg(&dir)
        .status()
        .expect("run touchdown simulate");
    assert!(status.success(), "simulate failed");

    let autopilot = UdpSocket::bind("127.0.0.1:0").expect("bind");
    autopilot
        .set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let args = CompanionArgs {
        udp: Some(autopilot.local_addr().unwrap().to_string()),
        udp_local_port: None,
        udp_listen: None,
        tcp: None,
        tcp_listen: None,
        serial: None,
        baud: 921_600,
        recording: dir.clone(),
        profile: ProfileArg::Auto,
        lead: 0.2,
        // Far longer than the test: only the signal ends the run.
        linger: 120.0,
        signing_key: None,
    };
    // The autopilot: its first datagram (a HEARTBEAT) comes after the handlers are
    // installed; answer it, let the run go on a moment, then Ctrl-C.
    let signaller = std::thread::spawn(move || {
        let mut buf = [0u8; 512];
        let (_, from) = autopilot.recv_from(&mut buf).expect("touchdown talks");
        autopilot
            .send_to(&common::ardupilot_heartbeat(0), from)
            .expect("send");
        std::thread::sleep(Duration::from_millis(500));
        signal_hook::low_level::raise(SIGINT).expect("raise SIGINT");
    });
    let mut out = Vec::new();
    let mut err = Vec::new();
    let outcome = companion::run(&args, &mut out, &mut err);
    signaller.join().expect("the autopilot thread");
    let stdout = String::from_utf8_lossy(&out);
    println!("{stdout}");
    assert_eq!(outcome, Ok(Outcome::Stopped { status: 130 }), "{stdout}");
    assert!(
        stdout
            .lines()
            .next()
            .unwrap_or("")
            .starts_with("stopped: by SIGINT after"),
        "{stdout}"
    );
    assert!(
        stdout.contains("autopilot: system 1, component 1"),
        "{stdout}"
    );
    std::fs::remove_dir_all(&dir).expect("remove the scratch recording");
}
