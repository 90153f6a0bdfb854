//! The fuzz harnesses: one function per cargo-fuzz target, each taking the raw input bytes
//! and panicking when an invariant breaks.
//!
//! They live here, not in `fuzz_targets/`, so that the host tests replay the seed corpora and
//! every regression input (`host-tests/tests/fuzz_regressions.rs` includes this file as a
//! module) without libFuzzer. Hence no dependency beyond the project's crates and nalgebra:
//! structured inputs are read with [`Input`], a byte reader that yields zeros once the data
//! runs out.
//!
//! | target | input | checked |
//! |---|---|---|
//! | [`detect`] | frame size, family set, pixels | detections name real ids, finite corners, step budget |
//! | [`family_file`] | buffer size, family text | ids decode back to themselves; detector runs with the family |
//! | [`config_toml`] | text | an accepted camera validates, an accepted pad builds its layout |
//! | [`recording`] | selector, `frames.csv` text or PGM bytes | accepted rows and frames are consistent |
//! | [`mavlink_stream`] | a script of link bytes, frames, params, time steps | every emitted frame is valid MAVLink, targets finite, draining ends |

use nalgebra::{Matrix6, UnitQuaternion, Vector3};
use touchdown_core::camera::CameraModel;
use touchdown_core::companion::mavlink::dialects::common::{
    MavMessage, MavParamType, PARAM_REQUEST_READ_DATA, PARAM_SET_DATA,
};
use touchdown_core::companion::mavlink::{
    MAVLinkV1MessageRaw, MAVLinkV2MessageRaw, MavFrame, MavHeader, MavlinkVersion, Message,
};
use touchdown_core::companion::{
    Companion, CompanionConfig, CompanionStats, Profile, MAX_FRAME_LEN,
};
use touchdown_core::detect::{Detection, DetectorConfig, QvgaWorkspace, VgaWorkspace};
use touchdown_core::family::{parse_family, tables, Family};
use touchdown_core::filter::{EstimatorConfig, PadEstimator, VehicleState};
use touchdown_core::image::GrayImage;
use touchdown_core::pad::{designs, PadLayout, PadMarker};
use touchdown_core::params::{ParamId, ParamSet, PipelineSettings, PARAMS, PARAM_COUNT};
use touchdown_core::pipeline::{FramePipeline, PipelineConfig};
use touchdown_core::pose::{marker_pose, PadFix, Pose, PoseMethod};
use touchdown_host::formats::camera::parse_camera;
use touchdown_host::formats::pad::parse_pad;
use touchdown_host::formats::pgm::parse_pgm;
use touchdown_host::formats::recording::parse_frames_csv;

/// Reads structured values from fuzz input; past the end every value is zero.
#[derive(Debug)]
pub struct Input<'a> {
    data: &'a [u8],
}

impl<'a> Input<'a> {
    /// A reader over `data`.
    pub fn new(data: &'a [u8]) -> Self {
        Input { data }
    }

    /// True when every byte has been read.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// The next byte (0 past the end).
    pub fn u8(&mut self) -> u8 {
        match self.data.split_first() {
            Some((&b, rest)) => {
                self.data = rest;
                b
            }
            None => 0,
        }
    }

    /// The next `N` bytes, zero-padded.
    fn array<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        for b in &mut out {
            *b = self.u8();
        }
        out
    }

    /// A little-endian u16.
    pub fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.array())
    }

    /// A little-endian u32.
    pub fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.array())
    }

    /// A little-endian u64.
    pub fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.array())
    }

    /// Any f32 bit pattern (NaN, infinities and subnormals included).
    pub fn f32(&mut self) -> f32 {
        f32::from_bits(self.u32())
    }

    /// A value in `0..n` (`n` at most 65,536; one byte when `n` <= 256).
    pub fn below(&mut self, n: usize) -> usize {
        if n <= 1 {
            0
        } else if n <= 256 {
            usize::from(self.u8()) % n
        } else {
            usize::from(self.u16()) % n
        }
    }

    /// Up to `n` bytes (fewer at the end of the input).
    pub fn bytes(&mut self, n: usize) -> &'a [u8] {
        let (head, tail) = self.data.split_at(n.min(self.data.len()));
        self.data = tail;
        head
    }
}

// ---------------------------------------------------------------------------------------
// detect

/// Largest frame the `detect` target makes (the firmware's largest, VGA).
pub const DETECT_MAX_WIDTH: usize = 640;
/// See [`DETECT_MAX_WIDTH`].
pub const DETECT_MAX_HEIGHT: usize = 480;

/// Family sets the `detect` target chooses from: the default pair, reversed and small
/// families, the paper's, one with ambiguous codes, and eight different layouts at once.
pub static FAMILY_SETS: &[&[&Family<'static>]] = &[
    tables::DEFAULT,
    &[&tables::TAG_STANDARD41H12, &tables::TAG16H5],
    &[&tables::ARUCO_6X6_250],
    &[&tables::ARUCO_ORIGINAL, &tables::ARUCO_4X4_1000],
    &[
        &tables::TAG25H9,
        &tables::TAG36H10,
        &tables::ARUCO_5X5_1000,
        &tables::ARUCO_7X7_1000,
        &tables::ARUCO_MIP_36H12,
        &tables::TAG_STANDARD41H12,
        &tables::TAG36H11,
        &tables::ARUCO_4X4_50,
    ],
];

/// Work memory and the frame of the `detect` target (allocated once per process, as the
/// firmware keeps them static). The pipelines are made per input: their camera follows the
/// frame size.
#[derive(Debug)]
pub struct DetectState {
    workspace: Box<VgaWorkspace>,
    frame: Vec<u8>,
}

impl Default for DetectState {
    fn default() -> Self {
        DetectState {
            workspace: Box::new(VgaWorkspace::new()),
            frame: Vec::with_capacity(DETECT_MAX_WIDTH * DETECT_MAX_HEIGHT),
        }
    }
}

/// Panics unless every detection names a family of the slice, an id below that family's
/// size, and finite corners, centre, margin and contrast.
pub fn check_detections(detections: &[Detection], families: &[&Family<'_>]) {
    for d in detections {
        let Some(family) = families.get(usize::from(d.family)) else {
            panic!("detection names family {} of {}", d.family, families.len());
        };
        assert!(
            usize::from(d.id) < family.codes.len(),
            "{} id {} but the family has {} codes",
            family.name,
            d.id,
            family.codes.len()
        );
        assert!(
            d.corners
                .iter()
                .chain([&d.center])
                .all(|p| p.x.is_finite() && p.y.is_finite()),
            "non-finite corner or centre: {d:?}"
        );
        assert!(
            d.decision_margin.is_finite() && d.contrast.is_finite(),
            "{d:?}"
        );
    }
}

/// Marker pose of every detection with both methods (the host tools' single-marker pose; the
/// pipeline runs only the pad fix).
fn run_marker_pose(detections: &[Detection], camera: &CameraModel) {
    for d in detections {
        for method in [PoseMethod::Ippe, PoseMethod::PaperHomography] {
            if let Ok(pose) = marker_pose(&d.corners, 0.16, camera, method) {
                let best = &pose.best;
                assert!(
                    best.pose
                        .rotation
                        .iter()
                        .chain(best.pose.translation.iter())
                        .all(|v| v.is_finite())
                        && !best.reprojection_rms_px.is_nan(),
                    "pose of {d:?} is not finite: {best:?}"
                );
            }
        }
    }
}

/// The per-frame path ([`FramePipeline`]) on an arbitrary frame, then marker pose on
/// whatever it found.
///
/// Input: bytes 0-1 width-1 (little endian, modulo 640), bytes 2-3 height-1 (modulo 480),
/// byte 4 the family set ([`FAMILY_SETS`]), the rest pixels, row-major. A frame needs up
/// to 307,200 pixel bytes, far more than a fuzzer writes, so the pixel bytes are repeated to
/// fill it: short inputs still make full-size frames with periodic content (stripes,
/// checkerboards, grids of blobs: the structures that stress contour tracing).
///
/// Both detection pipelines (the default and the paper's) each search for both shipped pad
/// designs, then marker pose (IPPE and the paper's homography decomposition) of every
/// detection.
pub fn detect(state: &mut DetectState, data: &[u8]) {
    let Some((header, pixels)) = data.split_first_chunk::<5>() else {
        return;
    };
    let width = usize::from(u16::from_le_bytes([header[0], header[1]])) % DETECT_MAX_WIDTH + 1;
    let height = usize::from(u16::from_le_bytes([header[2], header[3]])) % DETECT_MAX_HEIGHT + 1;
    let families = FAMILY_SETS[usize::from(header[4]) % FAMILY_SETS.len()];
    state.frame.clear();
    if pixels.is_empty() {
        state.frame.resize(width * height, 0);
    } else {
        state
            .frame
            .extend(pixels.iter().copied().cycle().take(width * height));
    }
    let image = GrayImage::new(&state.frame, width, height).expect("frame size is valid");
    let focal = width.max(height) as f32;
    let camera = CameraModel::pinhole(
        width as u32,
        height as u32,
        focal,
        focal,
        (width as f32 - 1.0) * 0.5,
        (height as f32 - 1.0) * 0.5,
    );
    for config in [DetectorConfig::default(), DetectorConfig::paper()] {
        for (k, layout) in designs::ALL.into_iter().enumerate() {
            // Boxed: the detector inside holds a contour buffer of tens of KiB.
            // The configuration's correction cap as it is (not TD_MAX_HAMMING's default), so
            // every bound a family allows is fuzzed.
            let settings = PipelineSettings {
                max_hamming: config.max_hamming,
                ..PipelineSettings::default()
            };
            let pipeline_config = PipelineConfig {
                detector: config,
                ..PipelineConfig::default()
            };
            let mut pipeline = Box::new(
                FramePipeline::new(families, layout, camera, pipeline_config, settings)
                    .expect("the default trackers are valid"),
            );
            let exposure_us = 1_000_000;
            let report = pipeline.process(
                &image,
                exposure_us,
                &VehicleState::new(),
                &mut state.workspace.buffers(),
            );
            assert_eq!(report.detect_error, None, "valid families and VGA buffers");
            assert_eq!(report.estimate.exposure_us, exposure_us);
            assert_eq!(report.estimate.fix_found, report.fix.is_some());
            let detector = pipeline.detector();
            let detections = detector.detections();
            assert_eq!(report.markers, detections.len());
            check_detections(detections, families);
            let stats = *detector.stats();
            let budget = ((detector.config().work_budget_per_pixel * (width * height) as f32)
                as u32)
                .max(touchdown_core::detect::MIN_WORK_BUDGET);
            assert!(
                stats.work <= budget && stats.trace_steps <= stats.work,
                "{} work units ({} trace steps) over a budget of {budget}",
                stats.work,
                stats.trace_steps
            );
            if let Some(fix) = report.fix {
                assert!(fix.pose.is_valid(), "pad fix {fix:?}");
            }
            // The detections do not depend on the pad: their marker pose once per
            // configuration.
            if k == 0 {
                run_marker_pose(detections, &camera);
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// family_file

/// Pixels per cell of the marker drawn by [`family_file`].
const FAMILY_CELL_PX: usize = 4;
/// Ids [`family_file`] checks for the decode round trip (the first ones).
const FAMILY_CHECKED_IDS: usize = 32;

/// The family-file parser on arbitrary text, and the family it builds.
///
/// Byte 0 sizes the caller's code buffer (1 to 1021 codes, so "too many codes" is reached),
/// the rest is the file. When the file parses into a family: each of the first ids decodes
/// back to itself from its own code in every rotation, and the per-frame path
/// ([`FramePipeline`]), given the family alone and a pad of its marker 0, runs on an image of
/// that marker drawn axis-aligned and reports only ids of the family (and a valid fix, if
/// any).
pub fn family_file(data: &[u8]) {
    let Some((&size, text)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(text) else {
        return;
    };
    let mut codes = vec![0u64; 1 + 4 * usize::from(size)];
    let Ok(header) = parse_family(text, "fuzz", &mut codes) else {
        return;
    };
    assert!(header.count >= 1 && header.count <= codes.len());
    let mut sorted_ids = vec![0u16; header.count];
    let Ok(family) = header.into_family(&codes, &mut sorted_ids) else {
        return;
    };
    assert_eq!(family.validate(), Ok(()));
    assert_eq!(family.check_layout(), Ok(()));
    for (id, &code) in family.codes.iter().enumerate().take(FAMILY_CHECKED_IDS) {
        for start in 0..4u8 {
            let readings = [0u8, 1, 2, 3].map(|k| family.rotate_code(code, start + k));
            let Some(decoded) = family.decode(&readings, 0) else {
                panic!("id {id} (code {code:#x}) does not decode");
            };
            assert_eq!(usize::from(decoded.id), id, "code {code:#x} turned {start}");
            assert_eq!(decoded.hamming, 0);
        }
    }

    let grid = usize::from(family.grid);
    let side = (grid + 2) * FAMILY_CELL_PX;
    let mut pixels = vec![255u8; side * side];
    for row in 0..grid {
        for col in 0..grid {
            if family.cell_is_white(0, row, col) == Some(false) {
                for y in 0..FAMILY_CELL_PX {
                    let start =
                        ((row + 1) * FAMILY_CELL_PX + y) * side + (col + 1) * FAMILY_CELL_PX;
                    pixels[start..start + FAMILY_CELL_PX].fill(0);
                }
            }
        }
    }
    let image = GrayImage::new(&pixels, side, side).expect("a valid size");
    let families = [&family];
    let marker = PadMarker {
        family: family.name,
        id: 0,
        size: 0.16,
        x: 0.0,
        y: 0.0,
        yaw_deg: 0.0,
    };
    let pad = PadLayout::new("fuzz", &[marker]).expect("a one-marker pad of a named family");
    let focal = side as f32;
    let centre = (side as f32 - 1.0) * 0.5;
    let camera = CameraModel::pinhole(side as u32, side as u32, focal, focal, centre, centre);
    let mut workspace = Box::new(QvgaWorkspace::new());
    let mut pipeline = Box::new(
        FramePipeline::new(
            &families,
            &pad,
            camera,
            PipelineConfig::default(),
            PipelineSettings::default(),
        )
        .expect("the default trackers are valid"),
    );
    let report = pipeline.process(&image, 0, &VehicleState::new(), &mut workspace.buffers());
    assert_eq!(
        report.detect_error, None,
        "a validated family and QVGA buffers"
    );
    check_detections(pipeline.detector().detections(), &families);
    if let Some(fix) = report.fix {
        assert!(fix.pose.is_valid(), "pad fix {fix:?}");
    }
}

// ---------------------------------------------------------------------------------------
// config_toml

/// `camera.toml` and `pad.toml` parsers on arbitrary text: an accepted camera validates in
/// the core (so pose will not reject it later); an accepted pad builds its core layout.
pub fn config_toml(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match parse_camera(text) {
        Ok(camera) => assert_eq!(camera.validate(), Ok(()), "accepted camera {camera:?}"),
        Err(e) => assert!(!e.reason.is_empty()),
    }
    match parse_pad(text) {
        Ok(pad) => {
            let layout = pad.layout().expect("an accepted pad builds its layout");
            assert!(!layout.markers().is_empty());
        }
        Err(e) => assert!(!e.reason.is_empty()),
    }
}

// ---------------------------------------------------------------------------------------
// recording

/// The recording readers: `frames.csv` (even byte 0) or an 8-bit binary PGM (odd byte 0,
/// with an expected size from byte 0's upper bits when bit 1 is set). Accepted rows count up
/// from 0 with increasing times and finite truth; an accepted PGM holds exactly
/// width x height pixels of the expected size.
pub fn recording(data: &[u8]) {
    let Some((&selector, rest)) = data.split_first() else {
        return;
    };
    if selector & 1 == 0 {
        let Ok(text) = std::str::from_utf8(rest) else {
            return;
        };
        if let Ok((has_truth, entries)) = parse_frames_csv(text) {
            for (k, e) in entries.iter().enumerate() {
                assert_eq!(e.index, k);
                if let Some(previous) = k.checked_sub(1).and_then(|p| entries.get(p)) {
                    assert!(e.t_us > previous.t_us);
                }
                if let Some(truth) = &e.truth {
                    assert!(has_truth);
                    assert!(truth
                        .position
                        .iter()
                        .chain(truth.orientation.iter())
                        .all(|v| v.is_finite()));
                }
            }
        }
    } else {
        let expected = (selector & 2 != 0).then(|| {
            (
                usize::from((selector >> 2) & 7) + 1,
                usize::from(selector >> 5) + 1,
            )
        });
        if let Ok(frame) = parse_pgm(rest, expected) {
            assert_eq!(frame.pixels.len(), frame.width * frame.height);
            if let Some(size) = expected {
                assert_eq!((frame.width, frame.height), size);
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// mavlink_stream

/// Message ids the companion reacts to (and LANDING_TARGET, which it must ignore).
const HANDLED_IDS: [u32; 12] = [0, 2, 111, 31, 30, 32, 77, 76, 21, 20, 23, 149];
/// Most frames drained after one operation: far above what one instant can queue (16 queued
/// items, a target, a VPE, the periodic messages).
const MAX_DRAIN: usize = 64;

/// Operations of a [`mavlink_stream`] script (the byte is taken modulo the count).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Op {
    /// Length byte pair (u16, modulo 301), then that many raw bytes.
    RawBytes = 0,
    /// A MAVLink frame of a handled message (see [`mavlink_frame`]).
    Frame = 1,
    /// A PARAM_SET of a real parameter to us: index byte, f32 value.
    ParamSet = 2,
    /// A processed camera frame (see [`mavlink_stream`]).
    CameraFrame = 3,
    /// A local parameter change: index byte, f32 value.
    SetParam = 4,
    /// Time step: kind byte and a u32/u64 amount.
    Time = 5,
    /// Read the statistics.
    Stats = 6,
}

const OPS: usize = 7;

/// A MAVLink frame of a message the companion handles, with fuzzed fields: message id
/// choice, payload length and bytes, version, parameter name, header, then damage (none,
/// truncation, one flipped bit).
pub fn mavlink_frame(input: &mut Input<'_>) -> Vec<u8> {
    let choice = input.u8();
    let id = if choice >= 0xF0 {
        input.u32() & 0xFF_FFFF
    } else {
        HANDLED_IDS[usize::from(choice) % HANDLED_IDS.len()]
    };
    let len = input.below(256);
    let payload = input.bytes(len);
    // MAVLink 1 carries 8-bit message ids only (the mavlink crate panics serialising a larger
    // one as MAVLink 1: the first crash this target found, a harness bug).
    let version = if input.u8() % 6 == 5 && id <= 0xFF {
        MavlinkVersion::V1
    } else {
        MavlinkVersion::V2
    };
    let name = PARAMS[input.below(PARAM_COUNT)].name;
    let rename = !input.u8().is_multiple_of(4);
    let header = MavHeader {
        system_id: u32::from(input.u8()),
        component_id: input.u8(),
        sequence: input.u8(),
    };
    let damage = input.u8();
    let at = usize::from(input.u16());
    let Ok(mut msg) = MavMessage::parse(version, id, payload) else {
        return Vec::new();
    };
    // Real parameter names, so PARAM_SET / PARAM_REQUEST_READ reach the parameter logic.
    match &mut msg {
        MavMessage::PARAM_SET(PARAM_SET_DATA { param_id, .. })
        | MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA { param_id, .. })
            if rename =>
        {
            *param_id = name.into();
        }
        _ => {}
    }
    let mut bytes = match version {
        MavlinkVersion::V1 => {
            let mut raw = MAVLinkV1MessageRaw::new();
            raw.serialize_message(header, &msg);
            raw.raw_bytes().to_vec()
        }
        MavlinkVersion::V2 => {
            let mut raw = MAVLinkV2MessageRaw::new();
            raw.serialize_message(header, &msg);
            raw.raw_bytes().to_vec()
        }
    };
    match damage % 8 {
        0 => bytes.truncate(at % (bytes.len() + 1)),
        1 if !bytes.is_empty() => {
            let bit = at % (bytes.len() * 8);
            bytes[bit / 8] ^= 1 << (bit % 8);
        }
        _ => {}
    }
    bytes
}

/// A PARAM_SET of a real parameter, addressed to us, with any value.
fn param_set(input: &mut Input<'_>, params: &ParamSet) -> Vec<u8> {
    let def = &PARAMS[input.below(PARAM_COUNT)];
    let msg = MavMessage::PARAM_SET(PARAM_SET_DATA {
        param_value: input.f32(),
        target_system: params.get_int(ParamId::SysId) as u8,
        target_component: params.get_int(ParamId::CompId) as u8,
        param_id: def.name.into(),
        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
    });
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message(
        MavHeader {
            system_id: 255,
            component_id: 190,
            sequence: input.u8(),
        },
        &msg,
    );
    raw.raw_bytes().to_vec()
}

fn small(input: &mut Input<'_>, scale: f32) -> f32 {
    f32::from(input.u8() as i8) * scale
}

/// A pad fix: plausible (even selector) or any floats at all (NaN, infinities, a
/// non-orthogonal "rotation").
fn pad_fix(input: &mut Input<'_>) -> PadFix {
    if input.u8().is_multiple_of(2) {
        let rotation = UnitQuaternion::from_euler_angles(
            small(input, 0.02),
            small(input, 0.02),
            small(input, 0.05),
        );
        let translation = Vector3::new(
            small(input, 0.05),
            small(input, 0.05),
            f32::from(input.u8()) * 0.2,
        );
        let sigma = 1e-4 + f32::from(input.u8()) * 1e-3;
        PadFix {
            pose: Pose {
                rotation: *rotation.to_rotation_matrix().matrix(),
                translation,
            },
            covariance: Matrix6::identity() * sigma,
            markers_used: input.u8(),
            reprojection_rms_px: f32::from(input.u8()) * 0.05,
            alternative_rms_px: input.f32(),
        }
    } else {
        let mut pose = Pose::identity();
        for v in pose.rotation.iter_mut().chain(pose.translation.iter_mut()) {
            *v = input.f32();
        }
        let mut covariance = Matrix6::zeros();
        for v in covariance.iter_mut() {
            *v = input.f32();
        }
        PadFix {
            pose,
            covariance,
            markers_used: input.u8(),
            reprojection_rms_px: input.f32(),
            alternative_rms_px: input.f32(),
        }
    }
}

/// Parses one emitted frame back with the mavlink crate; panics unless it is a complete,
/// unsigned MAVLink 2 frame with a valid checksum whose payload parses, and unless a
/// LANDING_TARGET / VISION_POSITION_ESTIMATE carries finite numbers.
pub fn check_emitted(bytes: &[u8]) -> MavMessage {
    assert!(bytes.len() >= 12, "frame of {} bytes", bytes.len());
    assert_eq!(bytes[0], 0xFD, "not a MAVLink 2 frame: {bytes:02x?}");
    let incompat = bytes[2];
    assert_eq!(incompat, 0, "unexpected incompatibility flags (signing?)");
    assert_eq!(
        bytes.len(),
        10 + usize::from(bytes[1]) + 2,
        "length field vs frame size"
    );
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.as_mut_slice()[..bytes.len()].copy_from_slice(bytes);
    assert!(
        raw.has_valid_crc::<MavMessage>(),
        "bad checksum: {bytes:02x?}"
    );
    let frame = match MavFrame::<MavMessage>::deser_with_flags(
        MavlinkVersion::V2,
        incompat,
        &bytes[4..bytes.len() - 2],
    ) {
        Ok(frame) => frame,
        Err(e) => panic!("mavlink cannot parse {bytes:02x?}: {e:?}"),
    };
    assert_eq!(frame.msg.message_id(), raw.message_id());
    match &frame.msg {
        MavMessage::LANDING_TARGET(t) => {
            let values = [
                t.angle_x, t.angle_y, t.distance, t.size_x, t.size_y, t.x, t.y, t.z,
            ];
            assert!(
                values.iter().chain(t.q.iter()).all(|v| v.is_finite()),
                "non-finite LANDING_TARGET: {t:?}"
            );
        }
        MavMessage::VISION_POSITION_ESTIMATE(v) => {
            let values = [v.x, v.y, v.z, v.roll, v.pitch, v.yaw];
            assert!(
                values.iter().all(|v| v.is_finite()),
                "non-finite VISION_POSITION_ESTIMATE: {v:?}"
            );
        }
        _ => {}
    }
    frame.msg
}

/// Drains the transmit side at `now_us`, checking every frame; returns how many there were.
pub fn drain(companion: &mut Companion, now_us: u64) -> usize {
    let mut out = [0u8; MAX_FRAME_LEN];
    let mut last = None;
    for sent in 0..MAX_DRAIN {
        match companion.poll_transmit(now_us, &mut out) {
            Some(n) => {
                last = Some(check_emitted(&out[..n]).message_id());
            }
            None => return sent,
        }
    }
    panic!(
        "poll_transmit still had frames after {MAX_DRAIN} calls at {now_us} us (last message id {last:?})"
    );
}

/// The companion state machine under a script of link bytes, frames and time steps.
///
/// Script: byte 0 profile (odd: PX4), byte 1 VPE on (odd), u32 start time, then operations
/// ([`Op`], one byte each, with their arguments) until the input ends; after every operation
/// the transmit side is drained ([`drain`], [`check_emitted`]). Time steps go forwards a
/// little or a lot, backwards (an autopilot reboot is the autopilot's clock, but ours may be
/// fed inconsistently too), or jump anywhere; camera frames have a fix (plausible or any
/// floats) or none, and an exposure usually just before now, sometimes anywhere.
///
/// Returns the companion's counters at the end (the seed tests check how deep a script got).
pub fn mavlink_stream(data: &[u8]) -> CompanionStats {
    let mut input = Input::new(data);
    let profile = if input.u8() % 2 == 1 {
        Profile::Px4
    } else {
        Profile::ArduPilot
    };
    let mut config = CompanionConfig::with_profile(profile);
    if input.u8() % 2 == 1 {
        let _ = config.params.set(ParamId::VpeEnable, 1.0);
    }
    let mut companion = Companion::new(config);
    // The estimator stage of the pipeline, fed the script's pad fixes (there is no image here),
    // with the vehicle state the companion decodes from the script's bytes.
    let mut estimator =
        PadEstimator::new(EstimatorConfig::default()).expect("the default trackers are valid");
    let mut now_us = u64::from(input.u32());
    while !input.is_empty() {
        match input.below(OPS) as u8 {
            x if x == Op::RawBytes as u8 => {
                let len = input.below(301);
                let bytes = input.bytes(len);
                companion.receive(bytes, now_us);
            }
            x if x == Op::Frame as u8 => {
                let bytes = mavlink_frame(&mut input);
                // Any chunking.
                let split = input.below(bytes.len() + 1);
                companion.receive(&bytes[..split], now_us);
                companion.receive(&bytes[split..], now_us);
            }
            x if x == Op::ParamSet as u8 => {
                let bytes = param_set(&mut input, companion.params());
                companion.receive(&bytes, now_us);
            }
            x if x == Op::CameraFrame as u8 => {
                let kind = input.u8();
                let age = u64::from(input.u32() % 200_001);
                let fix = (!kind.is_multiple_of(4)).then(|| pad_fix(&mut input));
                let exposure_us = if kind >= 0xF0 {
                    input.u64() // stamped anywhere, the future included
                } else {
                    now_us.saturating_sub(age)
                };
                let estimate = estimator.update(fix.as_ref(), &companion.vehicle().at(exposure_us));
                let _ = companion.on_estimate(&estimate, now_us);
            }
            x if x == Op::SetParam as u8 => {
                if let Some(id) = ParamId::from_index(input.below(PARAM_COUNT)) {
                    let _ = companion.set_param(id, input.f32());
                }
            }
            x if x == Op::Time as u8 => {
                now_us = match input.u8() % 16 {
                    0 => now_us.saturating_sub(u64::from(input.u32() % 5_000_001)),
                    1 => input.u64(),
                    2 => now_us.saturating_add(u64::from(input.u32() % 20_000_001)),
                    _ => now_us.saturating_add(u64::from(input.u16()) % 50_001),
                };
            }
            _ => {
                let _ = companion.stats();
                let _ = companion.autopilot_alive(now_us);
            }
        }
        // As the pipeline applies TD_CAM_YAW between frames (PARAM_SET bytes included).
        estimator.set_mount_yaw(PipelineSettings::from_params(companion.params()).cam_yaw_deg);
        drain(&mut companion, now_us);
    }
    companion.stats()
}
