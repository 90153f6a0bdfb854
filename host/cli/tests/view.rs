//! `touchdown view`: records from a captured stream and from a TCP RTT server (a stand-in
//! that answers the viewer's request as the firmware does), the recording it writes, and its
//! one-line errors. The firmware's side of the same stream is tested end to end on the
//! emulated board (firmware/emu/view.py).

use std::io::{Read, Write};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use touchdown_core::camera::CameraModel;
use touchdown_core::detect::Detection;
use touchdown_core::frame_stream::{FrameMeta, RequestParser, StreamedFix};
use touchdown_core::geometry::Point;
use touchdown_formats::frame_stream::encode_record;

/// A fresh, empty scratch directory under the target directory.
fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("view")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch directory");
    dir
}

fn touchdown(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_touchdown"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run touchdown")
}

/// A record as the firmware writes it: a `width x height` gradient with one marker.
fn record(index: u32, width: u16, height: u16, scale: u8, pad: &str) -> Vec<u8> {
    let camera = CameraModel::pinhole(320, 240, 233.5, 233.5, 159.5, 119.5);
    let pixels: Vec<u8> = (0..usize::from(width) * usize::from(height))
        .map(|i| (i % 251) as u8)
        .collect();
    let detections = [Detection {
        family: 0,
        id: 35,
        hamming: 0,
        corners: [
            Point::new(100.0, 50.0),
            Point::new(140.0, 50.0),
            Point::new(140.0, 90.0),
            Point::new(100.0, 90.0),
        ],
        center: Point::new(120.0, 70.0),
        decision_margin: 1.0,
        contrast: 80.0,
    }];
    let meta = FrameMeta {
        index,
        t_us: 1_000_000 + 33_333 * u64::from(index),
        width,
        height,
        scale,
        exposure_us: 5000,
        gain_x16: 24,
        process_us: 8000,
        camera: &camera,
        families: &[&touchdown_core::family::tables::TAG36H11],
        pad_name: pad,
        pad_scale: 0.5,
        detections: &detections,
        fix: Some(StreamedFix {
            camera_position: [0.5, -0.25, 4.0],
            markers_used: 3,
            reprojection_rms_px: 0.2,
        }),
    };
    encode_record(&meta, &pixels).expect("encodes")
}

fn lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(str::to_string)
        .collect()
}

#[test]
fn records_a_captured_stream_with_the_boards_results() {
    let dir = &scratch("records");
    // Half a record (a viewer joining late), garbage, then two whole halved records.
    let first = record(7, 160, 120, 2, "nested-field");
    let mut stream = first[first.len() / 3..].to_vec();
    stream.extend_from_slice(b"\0\0TDVF\x09garbage");
    stream.extend_from_slice(&first);
    stream.extend_from_slice(&record(8, 160, 120, 2, "nested-field"));
    std::fs::write(dir.join("capture.bin"), &stream).unwrap();

    let out = touchdown(
        &[
            "view",
            "capture.bin",
            "--record",
            "rec",
            "--image",
            "view.png",
        ],
        dir,
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("2 frames"), "{stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("frame      8  160x120"), "{stdout}");
    assert!(stdout.contains("fix x 0.50 y -0.25 z 4.00 m"), "{stdout}");
    assert!(dir.join("view.png").is_file());

    let rec = dir.join("rec");
    assert_eq!(lines(&rec.join("frames.csv")).len(), 3);
    let camera = std::fs::read_to_string(rec.join("camera.toml")).unwrap();
    // The board's 320x240 camera, halved with its frames.
    assert!(
        camera.contains("width = 160") && camera.contains("fx = 116.75"),
        "{camera}"
    );
    assert!(camera.contains("cx = 79.5"), "{camera}");
    let pad = std::fs::read_to_string(rec.join("pad.toml")).unwrap();
    assert!(pad.contains("nested-field"), "{pad}");
    // The largest marker of nested-field (1.25 m) at the board's scale, 0.5.
    assert!(pad.contains("size = 0.625"), "{pad}");
    let board = lines(&rec.join("board.csv"));
    assert_eq!(board.len(), 3);
    assert!(
        board[1].starts_with("0,7,1233331,2,5000,1.5,8000,1,0.5,-0.25,4,3,0.2"),
        "{}",
        board[1]
    );
    let markers = lines(&rec.join("board_markers.csv"));
    // Corners in the halved frame's pixels: (100 + 0.5) / 2 - 0.5.
    assert_eq!(
        markers[1],
        "0,tag36h11,35,0,49.75,24.75,69.75,24.75,69.75,44.75,49.75,44.75"
    );
    let frame = std::fs::read(rec.join("frames/000001.pgm")).unwrap();
    assert!(frame.starts_with(b"P5\n160 120\n255\n"));

    // The same directory again: refused, nothing changed.
    let again = touchdown(&["view", "capture.bin", "--record", "rec"], dir);
    assert_eq!(again.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&again.stderr).contains("not empty"));
    assert_eq!(lines(&rec.join("frames.csv")).len(), 3);
}

#[test]
fn asks_a_tcp_rtt_server_and_stops_after_the_frames_asked_for() {
    let dir = &scratch("tcp");
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let board = std::thread::spawn(move || {
        let (mut conn, _) = listener.accept().unwrap();
        // The firmware sends nothing until asked.
        let mut parser = RequestParser::new();
        let mut buf = [0u8; 64];
        let request = loop {
            let n = conn.read(&mut buf).unwrap();
            assert!(n > 0, "the viewer hung up without asking");
            if let Some(r) = parser.push(&buf[..n]) {
                break r;
            }
        };
        for index in 0..3 {
            let _ = conn.write_all(&record(index, 320, 240, request.scale, "nested-field"));
        }
        request
    });
    let source = format!("tcp:127.0.0.1:{port}");
    let out = touchdown(
        &[
            "view", &source, "--frames", "2", "--every", "3", "--quiet", "--record", "rec",
        ],
        dir,
    );
    let request = board.join().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!((request.every, request.scale), (3, 1));
    assert_eq!(lines(&dir.join("rec/frames.csv")).len(), 3);
    assert!(out.stdout.is_empty());
}

#[test]
fn bad_sources_and_pads_are_one_line_errors() {
    let dir = &scratch("errors");
    let check = |args: &[&str], want: &str| {
        let out = touchdown(args, dir);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
        assert!(stderr.contains(want), "{args:?}: {stderr}");
    };
    check(&["view", "missing.bin"], "cannot open");
    std::fs::write(dir.join("noise.bin"), vec![0x5Au8; 5000]).unwrap();
    check(&["view", "noise.bin"], "no frame in the stream");
    // Nothing listens on a port we just closed.
    let port = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    check(
        &["view", &format!("tcp:127.0.0.1:{port}")],
        "cannot connect",
    );
    std::fs::write(
        dir.join("own-pad.bin"),
        record(1, 320, 240, 1, "my-own-pad"),
    )
    .unwrap();
    check(
        &["view", "own-pad.bin", "--record", "rec"],
        "not a shipped design: give its pad.toml with --pad",
    );
    check(&["view", "noise.bin", "--timeout", "0"], "--timeout");
}
