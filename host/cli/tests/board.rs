//! `touchdown board` against a stand-in board: the board's own MAVLink logic
//! (`touchdown_core::companion::Companion`, what the firmware's link task runs) on a UDP
//! socket. The lens and pad it ends up holding are what the firmware would save to flash and
//! apply (the emulated board's side: firmware/emu/lens.py).

use std::net::UdpSocket;
use std::path::PathBuf;
use std::process::{Command, Output};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use touchdown_core::companion::{Companion, CompanionConfig, MAX_FRAME_LEN};
use touchdown_core::params::{ParamId, ParamSet, SigningSecret};

const KEY: &str = "touchdown board test";

fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("board")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A board on a UDP port until `stop`; its parameters at the end.
struct Board {
    port: u16,
    stop: Arc<AtomicBool>,
    thread: JoinHandle<ParamSet>,
}

impl Board {
    fn start(key: Option<[u8; 32]>) -> Board {
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        socket
            .set_read_timeout(Some(Duration::from_millis(2)))
            .unwrap();
        let port = socket.local_addr().unwrap().port();
        let stop = Arc::new(AtomicBool::new(false));
        let stopping = stop.clone();
        let thread = std::thread::spawn(move || {
            let start = Instant::now();
            let mut companion = Companion::new(CompanionConfig::default());
            if let Some(key) = key {
                companion.set_signing_secret(SigningSecret::new(key, 1), 0);
            }
            let mut peer = None;
            let mut buf = [0u8; 2048];
            let mut out = [0u8; MAX_FRAME_LEN];
            while !stopping.load(Ordering::Relaxed) {
                let now = start.elapsed().as_micros() as u64;
                if let Ok((n, from)) = socket.recv_from(&mut buf) {
                    peer = Some(from);
                    companion.receive(&buf[..n], now);
                }
                while let Some(n) = companion.poll_transmit(now, &mut out) {
                    if let Some(to) = peer {
                        let _ = socket.send_to(&out[..n], to);
                    }
                }
            }
            *companion.params()
        });
        Board { port, stop, thread }
    }

    fn params(self) -> ParamSet {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.join().unwrap()
    }
}

fn board_tool(port: u16, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_touchdown"))
        .args([
            "board",
            "--udp",
            &format!("127.0.0.1:{port}"),
            "--timeout",
            "0.5",
        ])
        .args(args)
        .output()
        .unwrap()
}

fn one_line_error(out: &Output, want: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    assert!(stderr.contains(want), "{stderr}");
}

fn camera_file(dir: &std::path::Path, name: &str, w: u32, h: u32) -> String {
    let path = dir.join(name);
    std::fs::write(
        &path,
        format!(
            "width = {w}\nheight = {h}\nfx = 251.5\nfy = 252.0\ncx = 161.0\ncy = {}\n\
             distortion = [-0.21, 0.05, 0.001, -0.002, 0.0]\n",
            f64::from(h) / 2.0 - 1.0
        ),
    )
    .unwrap();
    path.to_str().unwrap().to_string()
}

#[test]
fn sets_the_lens_and_reads_it_back() {
    let dir = scratch("lens");
    let board = Board::start(None);
    let qvga = camera_file(&dir, "qvga.toml", 320, 240);
    let out = board_tool(board.port, &["set-camera", &qvga]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("TD_CAM_FX = 251.5 (set)"), "{stdout}");
    assert!(stdout.contains("TD_CAM_K1 = -0.21\n"), "{stdout}");
    // A VGA board's halved frames: the lens in the board's own pixels.
    let halved = camera_file(&dir, "halved.toml", 320, 200);
    let out = board_tool(board.port, &["set-camera", &halved]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // A camera of no board's frame size: nothing sent, the board keeps the halved one's.
    let vga = camera_file(&dir, "vga480.toml", 640, 480);
    one_line_error(
        &board_tool(board.port, &["set-camera", &vga]),
        "the board's frames are",
    );
    let p = board.params();
    assert_eq!(p.get(ParamId::CamFx), 503.0);
    assert_eq!(p.get(ParamId::CamCx), (161.0 + 0.5) * 2.0 - 0.5);
    assert_eq!(p.get(ParamId::CamCy), (99.0 + 0.5) * 2.0 - 0.5);
    assert_eq!(p.get(ParamId::CamP2), -0.002);
}

#[test]
fn sets_a_shipped_pad_by_name_or_file_and_refuses_its_own_layout() {
    let dir = scratch("pad");
    let board = Board::start(None);
    let out = board_tool(board.port, &["set-pad", "nested"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("TD_PAD = 3"));
    // nested-field printed at half size, as `touchdown pad` writes it and scaled.
    let half = dir.join("half.toml");
    let full = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../pads/nested-field.toml"
    ))
    .unwrap();
    let mut text = String::new();
    for line in full.lines() {
        let scaled = ["size", "x", "y"].iter().find_map(|k| {
            let (key, value) = line.split_once('=')?;
            let value: f64 = value.trim().parse().ok()?;
            (key.trim() == *k).then(|| format!("{k} = {}", value * 0.5))
        });
        text.push_str(&scaled.unwrap_or_else(|| line.to_string()));
        text.push('\n');
    }
    std::fs::write(&half, text).unwrap();
    let out = board_tool(board.port, &["set-pad", half.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // A layout of its own: refused before anything is sent.
    let own = dir.join("own.toml");
    std::fs::write(
        &own,
        "name = \"own\"\n[[marker]]\nfamily = \"tag36h11\"\nid = 3\nsize = 0.5\nx = 0.0\ny = 0.0\n",
    )
    .unwrap();
    one_line_error(
        &board_tool(board.port, &["set-pad", own.to_str().unwrap()]),
        "a layout of its own",
    );
    one_line_error(
        &board_tool(board.port, &["set-pad", "hexagon"]),
        "neither a shipped design",
    );
    let p = board.params();
    assert_eq!(p.get(ParamId::Pad), 1.0);
    assert_eq!(p.get(ParamId::TagSize), 0.625);
}

#[test]
fn a_board_with_a_key_takes_only_signed_writes() {
    let dir = scratch("signed");
    let key = touchdown_cli::signing_key::parse(KEY).unwrap();
    let board = Board::start(Some(key));
    let qvga = camera_file(&dir, "qvga.toml", 320, 240);
    one_line_error(
        &board_tool(board.port, &["set-camera", &qvga]),
        "refused: not signed",
    );
    let out = board_tool(board.port, &["--signing-key", KEY, "set-camera", &qvga]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(board.params().get(ParamId::CamFx), 251.5);
}

#[test]
fn no_board_is_a_one_line_error() {
    // A port nobody answers on.
    let silent = UdpSocket::bind("127.0.0.1:0").unwrap();
    let port = silent.local_addr().unwrap().port();
    one_line_error(
        &board_tool(port, &["show"]),
        "no answer to PARAM_REQUEST_READ TD_CAM_FX",
    );
    one_line_error(
        &board_tool(port, &["set-camera", "/nonexistent/camera.toml"]),
        "camera.toml",
    );
}
