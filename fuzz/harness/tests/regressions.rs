//! Replays the fuzz seed corpora (`fuzz/corpus/<target>/`) and every input a fuzzer found
//! (`fuzz/regressions/<target>/`) through the fuzz harnesses, without libFuzzer.
//!
//! The harnesses are this crate's library (`touchdown-fuzz-harness`), the one the cargo-fuzz
//! targets call, so a crash found by `cargo fuzz` and saved under `fuzz/regressions/` fails
//! `cargo test` until it is fixed, and the checks the fuzzers make (valid ids, finite corners, valid MAVLink out, budgets) run in
//! CI on the seeds. The seeds are also checked for reaching what they are meant to reach (the
//! marker seed decodes, the MAVLink capture makes the companion send targets).
//!
//! The MAVLink seeds are scripts for the `mavlink_stream` harness built from a simulated
//! autopilot's byte stream; `write_mavlink_seeds` (ignored) regenerates them:
//! `cargo test -p touchdown-fuzz-harness --test regressions -- --ignored write_mavlink_seeds`.

use std::path::{Path, PathBuf};

use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavMessage, MavModeFlag, MavParamType, MavState, MavType,
    ATTITUDE_QUATERNION_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, PARAM_REQUEST_LIST_DATA,
    PARAM_SET_DATA, SYSTEM_TIME_DATA, TIMESYNC_DATA,
};
use touchdown_core::companion::mavlink::{MAVLinkV2MessageRaw, MavHeader};
use touchdown_fuzz_harness as harness;

const TARGETS: [&str; 7] = [
    "detect",
    "family_file",
    "config_toml",
    "recording",
    "mavlink_stream",
    "signed_stream",
    "frame_stream",
];

/// `fuzz/`, this crate's parent directory.
fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Files of `fuzz/<kind>/<target>/`, sorted (none if the directory does not exist).
fn inputs(kind: &str, target: &str) -> Vec<PathBuf> {
    let dir = fuzz_dir().join(kind).join(target);
    let mut files: Vec<PathBuf> = match std::fs::read_dir(&dir) {
        Ok(entries) => entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file())
            .collect(),
        Err(_) => Vec::new(),
    };
    files.sort();
    files
}

fn run(target: &str, data: &[u8], state: &mut harness::DetectState) {
    match target {
        "detect" => harness::detect(state, data),
        "family_file" => harness::family_file(data),
        "config_toml" => harness::config_toml(data),
        "recording" => harness::recording(data),
        "mavlink_stream" => {
            harness::mavlink_stream(data);
        }
        "signed_stream" => {
            harness::signed_stream(data);
        }
        "frame_stream" => harness::frame_stream(data),
        _ => unreachable!("unknown target {target}"),
    }
}

/// Every seed and every saved regression input passes its harness.
#[test]
fn seeds_and_regressions_pass_their_harness() {
    let mut state = harness::DetectState::default();
    let mut seeds = 0;
    for target in TARGETS {
        let corpus = inputs("corpus", target);
        assert!(!corpus.is_empty(), "fuzz/corpus/{target}/ has no seeds");
        seeds += corpus.len();
        for path in corpus.iter().chain(inputs("regressions", target).iter()) {
            let data = std::fs::read(path).unwrap();
            println!("{target}: {}", path.display());
            run(target, &data, &mut state);
        }
    }
    assert!(seeds >= 10);
}

/// The marker seed of the detect target holds a readable tag36h11 id 0 (so the fuzzer starts
/// inside the decoder, not only in the threshold and contour code).
#[test]
fn detect_seed_holds_a_marker() {
    let data = std::fs::read(fuzz_dir().join("corpus/detect/tag36h11-id0-48x48")).unwrap();
    let (header, pixels) = data.split_at(5);
    let width = usize::from(u16::from_le_bytes([header[0], header[1]])) + 1;
    let height = usize::from(u16::from_le_bytes([header[2], header[3]])) + 1;
    assert_eq!(pixels.len(), width * height);
    let image = touchdown_core::image::GrayImage::new(pixels, width, height).unwrap();
    let mut workspace = Box::new(touchdown_core::detect::QvgaWorkspace::new());
    // Through the per-frame path the board runs, on a one-marker pad of that tag.
    let families = touchdown_core::family::tables::DEFAULT;
    let marker = touchdown_core::pad::PadMarker {
        family: "tag36h11",
        id: 0,
        size: 0.16,
        x: 0.0,
        y: 0.0,
        yaw_deg: 0.0,
    };
    let pad = touchdown_core::pad::PadLayout::new("seed", &[marker]).unwrap();
    let (w, h) = (width as f32, height as f32);
    let camera = touchdown_core::camera::CameraModel::pinhole(
        width as u32,
        height as u32,
        w,
        w,
        0.5 * (w - 1.0),
        0.5 * (h - 1.0),
    );
    let mut pipeline = Box::new(
        touchdown_core::pipeline::FramePipeline::new(
            families,
            &pad,
            camera,
            touchdown_core::pipeline::PipelineConfig::default(),
            touchdown_core::params::PipelineSettings::default(),
        )
        .unwrap(),
    );
    let vehicle = touchdown_core::filter::VehicleState::new();
    let report = pipeline.process(&image, 0, &vehicle, &mut workspace.buffers());
    assert_eq!(report.detect_error, None);
    assert!(report.fix.is_some(), "the pad's one marker gives a fix");
    let found = pipeline.detector().detections();
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!((found[0].family, found[0].id), (0, 0));
}

/// The MAVLink capture seeds drive the companion all the way to LANDING_TARGETs.
#[test]
fn mavlink_seeds_reach_landing_targets() {
    for (name, _) in mavlink_seeds() {
        let data = std::fs::read(fuzz_dir().join("corpus/mavlink_stream").join(name)).unwrap();
        let stats = harness::mavlink_stream(&data);
        println!("{name}: {stats:?}");
        if name.starts_with("capture") {
            assert!(stats.landing_targets > 0, "{name}: {stats:?}");
            assert!(stats.autopilot.is_some(), "{name}: {stats:?}");
        } else {
            assert!(stats.param_sets_rejected > 0, "{name}: {stats:?}");
        }
        assert_eq!(stats.decode_errors, 0, "{name}: {stats:?}");
    }
}

/// The `signed_stream` seeds: a key and writes signed with it, unsigned, replayed, locked
/// in flight, TD_LOCK off, the key cleared; no key and a first key set unsigned.
fn signed_seeds() -> Vec<(&'static str, Vec<u8>)> {
    // A PARAM_SET: op 0, signing choice (0 key, 1 other key, 2 unsigned, 3 old timestamp),
    // timestamp step, parameter index, value.
    fn param_set(s: &mut Vec<u8>, choice: u8, index: u8, value: f32) {
        s.extend_from_slice(&[0, choice]);
        s.extend_from_slice(&10u16.to_le_bytes());
        s.push(index);
        s.extend_from_slice(&value.to_le_bytes());
    }
    // A SETUP_SIGNING: op 1, signing choice, step, fill byte, first byte, zero flag, initial.
    fn setup(s: &mut Vec<u8>, choice: u8, fill: u8, zero: bool) {
        s.extend_from_slice(&[1, choice]);
        s.extend_from_slice(&10u16.to_le_bytes());
        s.extend_from_slice(&[fill, fill, if zero { 0 } else { 1 }]);
        s.extend_from_slice(&500u32.to_le_bytes());
    }
    let lock = touchdown_core::params::ParamId::Lock as u8;
    let tag = touchdown_core::params::ParamId::TagSize as u8;
    let mut keyed = vec![7u8; 32];
    keyed.extend_from_slice(&1000u32.to_le_bytes());
    keyed.extend_from_slice(&2000u32.to_le_bytes());
    param_set(&mut keyed, 0, tag, 0.5); // applied
    param_set(&mut keyed, 2, tag, 0.7); // unsigned: refused
    keyed.push(5); // the same bytes again: refused
    keyed.extend_from_slice(&[2, 0]); // armed
    param_set(&mut keyed, 0, tag, 0.6); // locked: refused
    param_set(&mut keyed, 0, lock, 0.0); // applied
    keyed.extend_from_slice(&[4, 0x40, 0x42, 0x0F, 0]); // a second
    setup(&mut keyed, 0, 0, true); // key cleared
    param_set(&mut keyed, 2, tag, 0.8); // unsigned, no key: applied
    let mut first = vec![0u8; 32];
    first.extend_from_slice(&0u32.to_le_bytes());
    first.extend_from_slice(&0u32.to_le_bytes());
    setup(&mut first, 2, 9, false); // the first key, unsigned: applied
    param_set(&mut first, 2, tag, 0.5); // unsigned: refused
    param_set(&mut first, 1, tag, 0.5); // another key: refused
    vec![("keyed-writes", keyed), ("first-key", first)]
}

/// The signing seeds apply the writes signed with the key in force and refuse the rest.
#[test]
fn signed_seeds_apply_signed_writes_and_refuse_the_rest() {
    for (name, want) in [("keyed-writes", (4, 3)), ("first-key", (1, 2))] {
        let data = std::fs::read(fuzz_dir().join("corpus/signed_stream").join(name)).unwrap();
        assert_eq!(
            signed_seeds().iter().find(|(n, _)| *n == name).unwrap().1,
            data,
            "{name}: regenerate with write_signed_seeds"
        );
        assert_eq!(
            harness::signed_stream(&data),
            want,
            "{name}: (applied, refused)"
        );
    }
}

/// Regenerates `fuzz/corpus/signed_stream/` (run on demand).
#[test]
#[ignore]
fn write_signed_seeds() {
    let dir = fuzz_dir().join("corpus/signed_stream");
    std::fs::create_dir_all(&dir).unwrap();
    for (name, bytes) in signed_seeds() {
        std::fs::write(dir.join(name), bytes).unwrap();
    }
}

/// Regenerates `fuzz/corpus/mavlink_stream/` (run on demand, see the module docs).
#[test]
#[ignore]
fn write_mavlink_seeds() {
    let dir = fuzz_dir().join("corpus/mavlink_stream");
    std::fs::create_dir_all(&dir).unwrap();
    for (name, bytes) in mavlink_seeds() {
        std::fs::write(dir.join(name), bytes).unwrap();
    }
}

/// A `mavlink_stream` script (see `harness::mavlink_stream` for the format).
struct Script(Vec<u8>);

impl Script {
    fn new(px4: bool, vpe: bool, start_us: u32) -> Self {
        let mut s = vec![u8::from(px4), u8::from(vpe)];
        s.extend_from_slice(&start_us.to_le_bytes());
        Script(s)
    }

    /// Received bytes, as the UART delivered them (chunks of at most 300 bytes).
    fn receive(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(300) {
            self.0.push(harness::Op::RawBytes as u8);
            self.0
                .extend_from_slice(&(chunk.len() as u16).to_le_bytes());
            self.0.extend_from_slice(chunk);
        }
    }

    /// Time passes by `dt_us` (at most 50 ms).
    fn wait(&mut self, dt_us: u16) {
        self.0.extend_from_slice(&[harness::Op::Time as u8, 3]);
        self.0.extend_from_slice(&dt_us.to_le_bytes());
    }

    /// A processed frame exposed `age_us` ago with a level pad `height_dm` decimetres below.
    fn frame_with_fix(&mut self, age_us: u32, offset: (i8, i8), height_dm: u8) {
        self.0
            .extend_from_slice(&[harness::Op::CameraFrame as u8, 1]);
        self.0.extend_from_slice(&age_us.to_le_bytes());
        // Plausible fix: level, offset in 5 cm steps, height in 0.2 m steps, sigma 0.0101.
        self.0
            .extend_from_slice(&[0, 0, 0, 0, offset.0 as u8, offset.1 as u8, height_dm / 2]);
        self.0.extend_from_slice(&[10, 6, 4]);
        self.0.extend_from_slice(&f32::INFINITY.to_le_bytes());
    }

    fn param_set(&mut self, index: u8, value: f32) {
        self.0
            .extend_from_slice(&[harness::Op::ParamSet as u8, index]);
        self.0.extend_from_slice(&value.to_le_bytes());
        self.0.push(0);
    }
}

/// Autopilot (system 1, component 1) frames, MAVLink 2.
struct Autopilot {
    seq: u8,
}

impl Autopilot {
    fn frame(&mut self, msg: &MavMessage) -> Vec<u8> {
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message(
            MavHeader {
                system_id: 1,
                component_id: 1,
                sequence: self.seq,
            },
            msg,
        );
        self.seq = self.seq.wrapping_add(1);
        raw.raw_bytes().to_vec()
    }

    fn heartbeat(&mut self) -> Vec<u8> {
        self.frame(&MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 9,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        }))
    }
}

/// (file name, script) of every MAVLink seed.
fn mavlink_seeds() -> Vec<(&'static str, Vec<u8>)> {
    let mut seeds = Vec::new();
    for (name, px4) in [("capture-ardupilot", false), ("capture-px4", true)] {
        let mut ap = Autopilot { seq: 0 };
        let mut s = Script::new(px4, px4, 1_000_000);
        // The autopilot's clock is 5 s ahead of ours; 2 s of flight at 30 frames per second.
        let ap_ahead_ms = 5_000u32;
        for k in 0..60u32 {
            let t_ms = 1_000 + k * 33;
            let mut rx = Vec::new();
            if k % 30 == 0 {
                rx.extend(ap.heartbeat());
                rx.extend(ap.frame(&MavMessage::SYSTEM_TIME(SYSTEM_TIME_DATA {
                    time_unix_usec: 0,
                    time_boot_ms: t_ms + ap_ahead_ms,
                })));
                rx.extend(ap.frame(&MavMessage::TIMESYNC(TIMESYNC_DATA {
                    tc1: 0,
                    ts1: i64::from(t_ms + ap_ahead_ms) * 1_000_000,
                    target_system: 0,
                    target_component: 0,
                })));
            }
            rx.extend(
                ap.frame(&MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
                    time_boot_ms: t_ms + ap_ahead_ms,
                    q1: 1.0,
                    ..ATTITUDE_QUATERNION_DATA::DEFAULT
                })),
            );
            rx.extend(
                ap.frame(&MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                    time_boot_ms: t_ms + ap_ahead_ms,
                    z: -10.0,
                    ..LOCAL_POSITION_NED_DATA::DEFAULT
                })),
            );
            s.receive(&rx);
            s.wait(8_000);
            s.frame_with_fix(25_000, (2, -1), 100);
            s.wait(25_333);
        }
        seeds.push((name, s.0));
    }

    // Parameters: the list, an absurd value (rejected), garbage, a truncated frame.
    let mut ap = Autopilot { seq: 0 };
    let mut s = Script::new(false, false, 0);
    s.receive(&ap.heartbeat());
    let gcs = |msg: &MavMessage| {
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message(
            MavHeader {
                system_id: 255,
                component_id: 190,
                sequence: 0,
            },
            msg,
        );
        raw.raw_bytes().to_vec()
    };
    s.receive(&gcs(&MavMessage::PARAM_REQUEST_LIST(
        PARAM_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 0,
        },
    )));
    s.wait(50_000);
    s.wait(50_000);
    s.param_set(1, 1.0e9); // TD_RATE_HZ
    s.param_set(3, f32::NAN); // TD_CAM_YAW
    let set = gcs(&MavMessage::PARAM_SET(PARAM_SET_DATA {
        param_value: -5.0,
        target_system: 1,
        target_component: 191,
        param_id: "TD_TAG_SIZE".into(),
        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
    }));
    s.receive(&[0xFD, 0x09, 0x00, 0x55, 0xAA]);
    s.receive(&set[..set.len() - 3]);
    s.receive(&set);
    s.wait(10_000);
    seeds.push(("params-absurd", s.0));
    seeds
}

/// The `frame_stream` seeds: records as the board writes them (a small frame with a marker
/// and a fix, then one joined half-way before a whole one) and a viewer's request, each after
/// a chunk-size byte.
fn frame_stream_seeds() -> Vec<(&'static str, Vec<u8>)> {
    use touchdown_core::frame_stream::{FrameMeta, StreamedFix, ViewRequest};
    use touchdown_formats::frame_stream::encode_record;
    let camera = touchdown_core::camera::CameraModel::pinhole(320, 240, 233.5, 233.5, 159.5, 119.5);
    let p = |x, y| touchdown_core::geometry::Point::new(x, y);
    let detections = [touchdown_core::detect::Detection {
        family: 0,
        id: 36,
        hamming: 0,
        corners: [p(4.0, 2.0), p(12.0, 2.0), p(12.0, 10.0), p(4.0, 10.0)],
        center: p(8.0, 6.0),
        decision_margin: 1.0,
        contrast: 90.0,
    }];
    let pixels: Vec<u8> = (0..16 * 12).map(|i| (i * 7 % 256) as u8).collect();
    let record = |index| {
        encode_record(
            &FrameMeta {
                index,
                t_us: 1_000_000,
                width: 16,
                height: 12,
                scale: 2,
                exposure_us: 4000,
                gain_x16: 16,
                process_us: 9000,
                camera: &camera,
                families: &[&touchdown_core::family::tables::TAG36H11],
                pad_name: "nested-field",
                pad_scale: 1.0,
                detections: &detections,
                fix: Some(StreamedFix {
                    camera_position: [0.1, 0.2, 3.0],
                    markers_used: 1,
                    reprojection_rms_px: 0.2,
                }),
            },
            &pixels,
        )
        .unwrap()
    };
    let one = record(1);
    let mut joined = vec![63u8];
    joined.extend_from_slice(&one[one.len() / 2..]);
    joined.extend_from_slice(&record(2));
    let mut whole = vec![255u8];
    whole.extend_from_slice(&one);
    let mut request = vec![0u8, b'T', b'D'];
    request.extend_from_slice(&ViewRequest { every: 2, scale: 1 }.encode());
    vec![
        ("record", whole),
        ("joined-mid-record", joined),
        ("request", request),
    ]
}

/// Regenerates `fuzz/corpus/frame_stream/` (run on demand).
#[test]
#[ignore]
fn write_frame_stream_seeds() {
    let dir = fuzz_dir().join("corpus/frame_stream");
    std::fs::create_dir_all(&dir).unwrap();
    for (name, bytes) in frame_stream_seeds() {
        std::fs::write(dir.join(name), bytes).unwrap();
    }
}

/// The frame-stream seeds hold what they say: the whole record and the one after a cut are
/// read, the request is found.
#[test]
fn frame_stream_seeds_decode() {
    for (name, bytes) in frame_stream_seeds() {
        let mut reader = touchdown_formats::frame_stream::StreamReader::new();
        reader.push(&bytes[1..]);
        let frames = std::iter::from_fn(|| reader.next_frame()).count();
        let requests = touchdown_core::frame_stream::RequestParser::new().push(&bytes[1..]);
        match name {
            "request" => assert!(requests.is_some() && frames == 0, "{name}"),
            _ => assert_eq!(frames, 1, "{name}"),
        }
        harness::frame_stream(&bytes);
    }
}
