//! `touchdown companion` over the network links and its summary: each test runs the binary
//! on a few simulated frames and plays the other end itself (a minimal autopilot that sends
//! a HEARTBEAT every 100 ms, as ArduPilot's and PX4's are heard by the companion), then
//! decodes what arrived with the core's own frame parser and the common dialect.
//!
//! - `--tcp`: the test is the TCP server (ArduPilot SITL's SERIAL1 port).
//! - `--tcp-listen`: the test is the client (a ground station or bridge).
//! - `--udp-listen`: the test sends from its socket and must be answered there.
//! - `--udp --udp-local-port`: the datagrams come from the port asked for (PX4's link).
//! - SIGINT and SIGTERM mid-run: the summary, then exit status 130 / 143.
//! - `--profile ardupilot-local-frd` (TD_PROFILE 3): LANDING_TARGET in MAV_FRAME_LOCAL_FRD
//!   once the autopilot streams its attitude.
//! - The summary counts a frame of a message id outside the dialect as such, apart from a
//!   frame with a bad CRC, each once although start markers are inside them.

#![cfg(unix)]

mod common;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, UdpSocket};
use std::path::PathBuf;
use std::process::{Child, Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use touchdown_core::companion::mavlink::dialects::common::{
    MavFrame, MavMessage, ATTITUDE_QUATERNION_DATA,
};
use touchdown_core::companion::mavlink::{MAVLinkV2MessageRaw, MavHeader};
use touchdown_core::companion::FrameParser;

fn touchdown() -> Command {
    Command::new(env!("CARGO_BIN_EXE_touchdown"))
}

/// A level ATTITUDE_QUATERNION, nose 30 degrees east of north, from the same autopilot.
fn attitude(seq: u8, time_boot_ms: u32) -> Vec<u8> {
    let header = MavHeader {
        system_id: 1,
        component_id: 1,
        sequence: seq,
    };
    let half_yaw = 15f32.to_radians();
    let msg = MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
        time_boot_ms,
        q1: half_yaw.cos(),
        q4: half_yaw.sin(),
        ..ATTITUDE_QUATERNION_DATA::DEFAULT
    });
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message(header, &msg);
    raw.raw_bytes().to_vec()
}

/// 20 frames of the simulated descent (pad in view, --ideal), rendered once for all tests of
/// a run (they only read it) and replaced by the next run. Rendered by the warp model, which
/// is quicker than the ray caster: these tests are about the link, not the image.
fn recording() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = common::scratch("companion-net-tests", "descent");
        let status = touchdown()
            .args([
                "simulate",
                "--ideal",
                "--scenario",
                "descent",
                "--frames",
                "20",
                "--renderer",
                "warp",
            ])
            .arg("--out")
            .arg(&dir)
            .status()
            .expect("run touchdown simulate");
        assert!(status.success(), "simulate failed");
        dir
    })
}

/// `touchdown companion` on the recording with `link` options, stdout and stderr piped.
fn companion(link: &[&str], lead: &str, linger: &str) -> Child {
    touchdown()
        .args(["companion", "--recording"])
        .arg(recording())
        .args(link)
        .args(["--lead", lead, "--linger", linger])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn touchdown companion")
}

/// A port that was free a moment ago on 127.0.0.1 (for the command's servers).
fn free_tcp_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free TCP port")
        .port()
}

fn free_udp_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free UDP port")
        .port()
}

/// The message ids of every valid frame in `bytes`, in order.
fn message_ids(bytes: &[u8]) -> Vec<u32> {
    let mut parser = FrameParser::new();
    let mut ids = Vec::new();
    parser.push(bytes, |frame| ids.push(frame.message_id));
    assert_eq!(parser.stats().bad_crc, 0, "corrupt frames from touchdown");
    ids
}

/// LANDING_TARGET's id.
const LANDING_TARGET: u32 = 149;
const HEARTBEAT: u32 = 0;

fn count(ids: &[u32], id: u32) -> usize {
    ids.iter().filter(|&&i| i == id).count()
}

/// Waits for the command and returns its output, with its stderr in the message on failure.
fn finish(child: Child) -> Output {
    let output = child
        .wait_with_output()
        .expect("wait for touchdown companion");
    println!("{}", String::from_utf8_lossy(&output.stdout));
    output
}

fn assert_success(output: &Output) {
    assert!(
        output.status.success(),
        "touchdown companion failed ({:?}): {}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
}

/// Plays the autopilot on a stream: a heartbeat every 100 ms (and `extra` once, after the
/// second), collecting what the command writes until it closes the connection.
fn play_autopilot_on_stream(stream: TcpStream, extra: &[u8]) -> Vec<u8> {
    play_autopilot_with_attitude(stream, extra, false)
}

/// [`play_autopilot_on_stream`], with (`attitude`) the attitude stream at 50 Hz besides.
fn play_autopilot_with_attitude(mut stream: TcpStream, extra: &[u8], attitude: bool) -> Vec<u8> {
    stream.set_nonblocking(true).expect("nonblocking");
    let mut bytes = Vec::new();
    let mut buf = [0u8; 4096];
    let mut seq = 0u8;
    let start = Instant::now();
    let mut next_heartbeat = start;
    let mut next_attitude = start;
    let mut attitude_seq = 0u8;
    let deadline = Instant::now() + Duration::from_secs(60);
    while Instant::now() < deadline {
        if attitude && Instant::now() >= next_attitude {
            let boot_ms = start.elapsed().as_millis() as u32;
            let _ = stream.write_all(&self::attitude(attitude_seq, boot_ms));
            attitude_seq = attitude_seq.wrapping_add(1);
            next_attitude += Duration::from_millis(20);
        }
        if Instant::now() >= next_heartbeat {
            let _ = stream.write_all(&common::ardupilot_heartbeat(seq));
            seq = seq.wrapping_add(1);
            if seq == 2 {
                let _ = stream.write_all(extra);
            }
            next_heartbeat += Duration::from_millis(100);
        }
        match stream.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => bytes.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(2))
            }
            Err(_) => break,
        }
    }
    bytes
}

/// The same over UDP: heartbeats to `to` (or, with `None`, to whoever sent the first
/// datagram), until `child` exits; returns the bytes and the senders' addresses.
fn play_autopilot_on_udp(
    socket: &UdpSocket,
    mut to: Option<SocketAddr>,
    child: &mut Child,
) -> (Vec<u8>, Vec<SocketAddr>) {
    socket.set_nonblocking(true).expect("nonblocking");
    let mut bytes = Vec::new();
    let mut senders = Vec::new();
    let mut buf = [0u8; 4096];
    let mut seq = 0u8;
    let mut next_heartbeat = Instant::now();
    let deadline = Instant::now() + Duration::from_secs(60);
    while Instant::now() < deadline && child.try_wait().expect("wait").is_none() {
        if let (Some(addr), true) = (to, Instant::now() >= next_heartbeat) {
            let _ = socket.send_to(&common::ardupilot_heartbeat(seq), addr);
            seq = seq.wrapping_add(1);
            next_heartbeat += Duration::from_millis(100);
        }
        match socket.recv_from(&mut buf) {
            Ok((n, from)) => {
                bytes.extend_from_slice(&buf[..n]);
                if !senders.contains(&from) {
                    senders.push(from);
                }
                to.get_or_insert(from);
            }
            Err(_) => std::thread::sleep(Duration::from_millis(2)),
        }
    }
    (bytes, senders)
}

/// The summary line starting with `label: `.
fn summary_line<'a>(output: &'a Output, label: &str) -> &'a str {
    let stdout = std::str::from_utf8(&output.stdout).expect("utf-8");
    stdout
        .lines()
        .find(|l| l.starts_with(&format!("{label}: ")))
        .unwrap_or_else(|| panic!("no `{label}:` line in the summary:\n{stdout}"))
}

fn assert_targets_arrived(bytes: &[u8]) {
    let ids = message_ids(bytes);
    println!(
        "{} bytes: {} HEARTBEAT, {} LANDING_TARGET",
        bytes.len(),
        count(&ids, HEARTBEAT),
        count(&ids, LANDING_TARGET)
    );
    assert!(count(&ids, HEARTBEAT) >= 1);
    // 20 frames (0.67 s) of a descent with the pad in view: the tracker's confirmation and
    // TD_RATE_HZ keep some from sending a target; a margin for a busy machine besides.
    assert!(count(&ids, LANDING_TARGET) >= 5, "{ids:?}");
}

#[test]
fn tcp_client_talks_to_an_autopilot_server() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = listener.local_addr().unwrap().to_string();
    let child = companion(&["--tcp", &addr], "0.5", "0.3");
    let (stream, _) = listener.accept().expect("touchdown connects");
    let bytes = play_autopilot_on_stream(stream, &[]);
    let output = finish(child);
    assert_success(&output);
    assert_targets_arrived(&bytes);
    assert!(summary_line(&output, "autopilot").contains("system 1, component 1"));
}

/// The autopilot going away ends a --tcp run: the summary, then one error line, status 2.
#[test]
fn tcp_client_reports_a_closed_connection() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = listener.local_addr().unwrap().to_string();
    let child = companion(&["--tcp", &addr], "30", "0");
    let (stream, _) = listener.accept().expect("touchdown connects");
    std::thread::sleep(Duration::from_millis(300));
    drop(stream);
    let output = finish(child);
    assert_eq!(output.status.code(), Some(2));
    assert!(summary_line(&output, "stopped").contains("the peer closed the connection"));
    let stderr = String::from_utf8_lossy(&output.stderr);
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errors.len(), 1, "{stderr}");
    assert!(errors[0].contains(&format!("--tcp {addr}")), "{stderr}");
}

#[test]
fn tcp_server_takes_a_client() {
    let addr = format!("127.0.0.1:{}", free_tcp_port());
    let child = companion(&["--tcp-listen", &addr], "0.5", "0.3");
    // The command binds in a moment: retry until it listens.
    let deadline = Instant::now() + Duration::from_secs(20);
    let stream = loop {
        match TcpStream::connect(&addr) {
            Ok(s) => break s,
            Err(e) if Instant::now() < deadline => {
                let _ = e;
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(e) => panic!("cannot connect to --tcp-listen {addr}: {e}"),
        }
    };
    let bytes = play_autopilot_on_stream(stream, &[]);
    let output = finish(child);
    assert_success(&output);
    assert_targets_arrived(&bytes);
}

#[test]
fn udp_server_answers_the_sender() {
    let port = free_udp_port();
    let mut child = companion(
        &["--udp-listen", &format!("127.0.0.1:{port}")],
        "0.5",
        "0.3",
    );
    let socket = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let server: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    // Heartbeats are sent until the command exits; the first ones may arrive before it has
    // bound its socket and are lost, as they would be with a real autopilot.
    let (bytes, senders) = play_autopilot_on_udp(&socket, Some(server), &mut child);
    let output = finish(child);
    assert_success(&output);
    assert_eq!(senders, vec![server], "answered from its listening address");
    assert_targets_arrived(&bytes);
}

#[test]
fn udp_client_sends_from_the_fixed_local_port() {
    let autopilot = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let remote = autopilot.local_addr().unwrap().to_string();
    let local = free_udp_port();
    let mut child = companion(
        &["--udp", &remote, "--udp-local-port", &local.to_string()],
        "0.5",
        "0.3",
    );
    // PX4's way: answer the address that first reached us.
    let (bytes, senders) = play_autopilot_on_udp(&autopilot, None, &mut child);
    let output = finish(child);
    assert_success(&output);
    assert_eq!(senders.len(), 1, "{senders:?}");
    assert_eq!(senders[0].port(), local);
    assert_targets_arrived(&bytes);
}

/// The frame of every LANDING_TARGET in `bytes`.
fn landing_target_frames(bytes: &[u8]) -> Vec<MavFrame> {
    let mut parser = FrameParser::new();
    let mut frames = Vec::new();
    parser.push(bytes, |frame| {
        if let Ok(MavMessage::LANDING_TARGET(t)) = frame.decode() {
            frames.push(t.frame);
        }
    });
    frames
}

/// TD_PROFILE 3 from the command line: with the attitude streamed, every target is in
/// LOCAL_FRD (a frame exposed before the first attitude sample would be in BODY_FRD; the
/// stream starts with the link, well before the first frame).
#[test]
fn profile_ardupilot_local_frd_sends_local_frd() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = listener.local_addr().unwrap().to_string();
    let child = touchdown()
        .args(["companion", "--recording"])
        .arg(recording())
        .args(["--tcp", &addr, "--profile", "ardupilot-local-frd"])
        .args(["--lead", "0.5", "--linger", "0.3"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn touchdown companion");
    let (stream, _) = listener.accept().expect("touchdown connects");
    let bytes = play_autopilot_with_attitude(stream, &[], true);
    let output = finish(child);
    assert_success(&output);
    assert_targets_arrived(&bytes);
    let frames = landing_target_frames(&bytes);
    assert!(
        frames.iter().all(|&f| f == MavFrame::MAV_FRAME_LOCAL_FRD),
        "{frames:?}"
    );
}

/// Runs a long --udp run, sends `signal` once the command has started talking, and returns
/// its output.
fn signalled_run(signal: &str) -> Output {
    let autopilot = UdpSocket::bind("127.0.0.1:0").expect("bind");
    autopilot
        .set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let remote = autopilot.local_addr().unwrap().to_string();
    let child = companion(&["--udp", &remote], "0.2", "60");
    // Its first datagram (a HEARTBEAT) comes after the handlers are installed.
    let mut buf = [0u8; 512];
    let (_, from) = autopilot.recv_from(&mut buf).expect("touchdown talks");
    autopilot
        .send_to(&common::ardupilot_heartbeat(0), from)
        .expect("send");
    std::thread::sleep(Duration::from_millis(500));
    let status = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .expect("run kill");
    assert!(status.success());
    finish(child)
}

#[test]
fn sigint_and_sigterm_print_the_summary() {
    // Two runs of their own, side by side: each waits for its link and its signal.
    let runs = [("-INT", "SIGINT", 130), ("-TERM", "SIGTERM", 143)].map(|(signal, name, code)| {
        (
            std::thread::spawn(move || signalled_run(signal)),
            name,
            code,
        )
    });
    for (run, name, code) in runs {
        let output = run.join().expect("the signalled run");
        assert_eq!(output.status.code(), Some(code), "{name}");
        assert!(summary_line(&output, "stopped").starts_with(&format!("stopped: by {name} after")));
        summary_line(&output, "frames");
        summary_line(&output, "sent");
        assert!(summary_line(&output, "autopilot").contains("system 1, component 1"));
    }
}

/// X.25, MAVLink's checksum, to build a frame of a dialect the core does not compile.
fn x25(mut crc: u16, bytes: &[u8]) -> u16 {
    for &b in bytes {
        let mut t = b ^ (crc & 0xFF) as u8;
        t ^= t << 4;
        let t = u16::from(t);
        crc = (crc >> 8) ^ (t << 8) ^ (t << 3) ^ (t >> 4);
    }
    crc
}

/// A valid MAVLink 2 frame of ArduPilot's AHRS (id 163, CRC_EXTRA 127: ardupilotmega, not
/// common), with two false frame starts in its payload (a MAVLink 2 one with valid flags, a
/// MAVLink 1 one), as real payloads have: the parser skips it by its declared length and
/// must count it once.
fn ardupilot_ahrs_frame() -> Vec<u8> {
    let mut payload: Vec<u8> = (1..=28).collect();
    payload[4..8].copy_from_slice(&[0xFD, 3, 0, 0]);
    payload[16..18].copy_from_slice(&[0xFE, 2]);
    let mut frame = vec![0xFD, 28, 0, 0, 0, 1, 1, 163, 0, 0];
    frame.extend_from_slice(&payload);
    let crc = x25(x25(0xFFFF, &frame[1..]), &[127]);
    frame.extend_from_slice(&crc.to_le_bytes());
    frame
}

/// A HEARTBEAT whose first payload bytes were changed into a false MAVLink 2 frame start
/// (the checksum no longer matches): one bad CRC, not two.
fn corrupted_heartbeat() -> Vec<u8> {
    let mut frame = common::ardupilot_heartbeat(100);
    frame[10..14].copy_from_slice(&[0xFD, 1, 0, 0]);
    frame
}

#[test]
fn summary_counts_unknown_messages_apart_from_bad_crcs() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = listener.local_addr().unwrap().to_string();
    let child = companion(&["--tcp", &addr], "0.5", "0.3");
    let (stream, _) = listener.accept().expect("touchdown connects");
    let mut extra = ardupilot_ahrs_frame();
    extra.extend_from_slice(&corrupted_heartbeat());
    let bytes = play_autopilot_on_stream(stream, &extra);
    let output = finish(child);
    assert_success(&output);
    assert_targets_arrived(&bytes);
    assert!(
        summary_line(&output, "not in the dialect").starts_with("not in the dialect: 1 "),
        "{}",
        summary_line(&output, "not in the dialect")
    );
    assert!(
        summary_line(&output, "bad CRC").starts_with("bad CRC: 1 "),
        "{}",
        summary_line(&output, "bad CRC")
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        !stdout.contains("Some(") && !stdout.contains("None"),
        "{stdout}"
    );
}

/// The rendered recording lives under the target directory, never in /tmp.
#[test]
fn the_recording_is_in_the_target_directory() {
    let dir = recording();
    assert!(
        dir.starts_with(env!("CARGO_TARGET_TMPDIR")),
        "{}",
        dir.display()
    );
    assert!(dir.join("frames.csv").is_file(), "{}", dir.display());
    let old = std::env::temp_dir().join(format!("touchdown-net-descent-{}", std::process::id()));
    assert!(!old.exists(), "{}", old.display());
}

/// Without a link the command says which options give one, in one line, with status 2.
#[test]
fn a_missing_link_is_one_clear_line() {
    let output = touchdown()
        .args(["companion", "--recording", "no-such-dir"])
        .output()
        .expect("run touchdown companion");
    assert_eq!(output.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with("error: no link to the autopilot: give one of --udp, --udp-listen"),
        "{stderr}"
    );
}

/// `--signing-key`: every frame the command sends is signed, and pymavlink, given the key (a
/// passphrase's SHA-256), accepts every signature; a bad key is one line before any link
/// opens.
#[test]
fn signing_key_signs_every_frame() {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
    let addr = listener.local_addr().unwrap().to_string();
    let child = touchdown()
        .args(["companion", "--recording"])
        .arg(recording())
        .args(["--tcp", &addr, "--lead", "0.5", "--linger", "0.3"])
        .args(["--signing-key", "touchdown test"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn touchdown companion");
    let (stream, _) = listener.accept().expect("touchdown connects");
    let bytes = play_autopilot_on_stream(stream, &[]);
    let output = finish(child);
    assert_success(&output);
    assert_targets_arrived(&bytes);
    let mut parser = FrameParser::new();
    let mut frames = 0;
    parser.push(&bytes, |frame| {
        frames += 1;
        assert!(
            frame.signature.is_some(),
            "unsigned frame {}",
            frame.message_id
        );
    });
    assert!(frames > 5);
    // pymavlink's verdict (scripts/mavlink_signing.py), with the passphrase's key.
    let key: String = touchdown_cli::signing_key::parse("touchdown test")
        .unwrap()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    let path = std::env::temp_dir().join(format!("touchdown-signed-{}.bin", std::process::id()));
    std::fs::write(&path, &bytes).unwrap();
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scripts/mavlink_signing.py");
    let verdict = Command::new("python3")
        .arg(script)
        .args(["verify", &key])
        .arg(&path)
        .output();
    let _ = std::fs::remove_file(&path);
    match verdict {
        Ok(v) if v.status.code() == Some(3) => println!("skipping: pymavlink not installed"),
        Ok(v) => {
            let text = String::from_utf8_lossy(&v.stdout);
            assert!(v.status.success(), "pymavlink refused a frame: {text}");
            assert!(text.contains(&format!("\"good\": {frames}")), "{text}");
        }
        Err(e) => println!("skipping: pymavlink not installed (python3: {e})"),
    }

    let output = touchdown()
        .args(["companion", "--recording"])
        .arg(recording())
        .args([
            "--tcp-listen",
            "127.0.0.1:9",
            "--signing-key",
            &"0".repeat(64),
        ])
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(2));
    let err = String::from_utf8_lossy(&output.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("--signing-key: all zeros"), "{err}");
}
