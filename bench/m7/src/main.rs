//! Cortex-M7 instruction counts of touchdown's per-frame path, on QEMU's mps2-an500 under
//! m7count (`cargo run --release` in this directory; `scripts/m7_check.sh` compares the
//! counts with `baseline.txt`).
//!
//! Every frame goes through the per-frame stages the firmware runs, each stage in its own
//! counted region (between [`m7bench_start`] and [`m7bench_stop`]), preceded by a label line
//! `<frame>: <stage>` and followed by the stage's stack high-water mark and a summary of its
//! result (detections, [`DetectStats`]), so a count that dropped because the stage stopped
//! finding anything is visible. Frame names start with the resolution (`qvga-`, `vga-`).
//!
//! Stages today:
//! - `pipeline`: [`FramePipeline::process`], called as `firmware/src/vision.rs` does: the
//!   default families, a static [`QvgaWorkspace`] / [`VgaWorkspace`], the pipeline in static
//!   storage, the default configuration with the default parameters applied (TD_MAX_HAMMING,
//!   the pad as built). That is detection, the pad fix
//!   ([`pad_pose_with_prediction`](touchdown_core::pose::pad_pose_with_prediction): IPPE +
//!   Levenberg-Marquardt) with the simulator's camera, on the frame's pad ([`Frame::pad`]),
//!   and the estimator's predict and update (no attitude streamed: its camera-frame track).
//! - `target`: [`Companion::on_estimate`] with the frame's estimate, as the link task calls
//!   it: the ArduPilot profile's LANDING_TARGET.
//! - `encode`: draining [`Companion::poll_transmit`] into a UART buffer (MAVLink 2 framing,
//!   CRC), as the link task does after each frame.
//!
//! On `qvga-landing-1` only, after `encode`, the vision task's part of the frame stream to a
//! host viewer while one is attached (`firmware/src/vision.rs`, `ViewOffer::offer`):
//! `view-head` encodes the record's head (the frame's detections and fix), `view-copy` copies
//! the frame into the record, `view-halve` halves it instead (`--half`); and the view task's
//! `view-checksum`, the Adler-32 over the head and the pixels as it sends them.
//!
//! After the frames, the link's signing ([`signing_regions`]): `signing: param-set-unsigned`
//! and `signing: param-set-signed` receive one PARAM_SET (a frame pymavlink built, unsigned,
//! and signed with a key the companion holds), so their difference is the cost of checking a
//! signature; `signing: encode-unsigned` and `signing: encode-signed` drain a fresh
//! companion's first frames (HEARTBEAT, TIMESYNC, stream requests) without and with a key.
//!
//! Frames without a detection run `target` and `encode` too (the estimate without a fix is
//! what the firmware posts then).
//!
//! Frames ([`FRAMES`]): the typical ones are rendered by the simulator
//! (`cargo run --release -p touchdown-host-tests --example m7_frames` writes `frames/*.pgm`),
//! but for `qvga-field-36`: the recommended pad 0.37 m below, 36 of its markers in view (the
//! camera's work budget reaches 12 of them), the most the firmware's pad shows at once (frame 612 of `touchdown simulate --scenario landing
//! --pad nested-field`, resampled to the firmware's 320x240 pinhole by
//! `python3 -m emu.make_frame RECORDING 612 OUT.pgm qvga` in `firmware/`); the
//! adversarial ones (noise, checkerboard, hundreds of small squares, marker look-alikes) and the flat ones (the
//! floor: thresholding and the scan with nothing to trace) are generated here, outside the
//! counted regions. Every frame is copied into one 32-byte-aligned RAM buffer first, as the
//! camera's DMA would leave it.

#![no_std]
#![no_main]

mod frames;
mod stack;

use core::arch::asm;
use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use panic_semihosting as _;
use touchdown_core::camera::CameraModel;
use touchdown_core::companion::{Companion, CompanionConfig, Profile, MAX_FRAME_LEN};
use touchdown_core::detect::{DetectStats, QvgaWorkspace, VgaWorkspace};
use touchdown_core::family::tables;
use touchdown_core::filter::VehicleState;
use touchdown_core::frame_stream;
use touchdown_core::image::GrayImage;
use touchdown_core::pad::{designs, PadLayout, PadMarker};
use touchdown_core::params::{ParamId, PipelineSettings, SigningSecret};
use touchdown_core::pipeline::{FramePipeline, FrameReport, PipelineConfig};

use frames::{FrameBuffer, Source};

/// Start of a counted region (m7count looks the symbol up). The body differs from
/// [`m7bench_stop`]'s so the linker cannot merge the two.
#[no_mangle]
#[inline(never)]
pub extern "C" fn m7bench_start() {
    // SAFETY: a no-op instruction.
    unsafe { asm!("nop") }
}

/// End of a counted region.
#[no_mangle]
#[inline(never)]
pub extern "C" fn m7bench_stop() {
    // SAFETY: no-op instructions.
    unsafe { asm!("nop", "nop") }
}

/// One benchmark frame.
struct Frame {
    /// Region label prefix; starts with the resolution.
    name: &'static str,
    width: usize,
    height: usize,
    source: Source,
    /// The pad the pipeline searches for: one marker the frame shows (the benchmark frames
    /// are not pad layouts; a multi-marker pad adds four corners per marker to the one
    /// refinement), the firmware's pad for frames without markers, and the whole pad for the
    /// frame of it.
    pad: &'static PadLayout<'static>,
    /// Markers the frame contains (typical frames); `None` for frames without markers, whose
    /// detections are printed but not checked.
    expected: Option<usize>,
    /// The lens's focal length, pixels, when the frame is not the simulator's pinhole
    /// ([`camera_for`]).
    focal_px: Option<f32>,
}

const QVGA: (usize, usize) = (320, 240);
const VGA: (usize, usize) = (640, 480);

/// Frames each benchmark frame is shown to the companion before the counted one.
const WARM_UP_FRAMES: usize = 6;
/// 30 Hz.
const FRAME_PERIOD_US: u64 = 33_333;

/// A pad of one tag36h11 marker, 0.16 m (any positive size: the count does not depend on
/// it), centred on the landing point.
const fn one_tag(name: &'static str, id: u16) -> PadLayout<'static> {
    let marker = PadMarker {
        family: "tag36h11",
        id,
        size: 0.16,
        x: 0.0,
        y: 0.0,
        yaw_deg: 0.0,
    };
    match PadLayout::new(name, &[marker]) {
        Ok(pad) => pad,
        Err(_) => panic!("a one-marker pad is valid"),
    }
}

/// The pads of the typical frames: the marker the detector reports first in each (the one
/// the fix of earlier baselines was computed on, so the pose costs the same).
const PAD_LANDING_1: PadLayout<'static> = one_tag("landing-1", 7);
const PAD_MULTI_6: PadLayout<'static> = one_tag("multi-6", 0);
const PAD_FAR_1: PadLayout<'static> = one_tag("far-1", 11);
const PAD_VGA_LANDING_3: PadLayout<'static> = one_tag("vga-landing-3", 22);

/// The simulator's camera for a frame (`PinholeCamera::for_frame` in touchdown-sim's renderer,
/// host/sim/src/render/):
/// focal length = the larger dimension, principal point at the centre, no distortion.
fn camera_for(width: usize, height: usize, focal_px: Option<f32>) -> CameraModel {
    let focal = focal_px.unwrap_or(width.max(height) as f32);
    CameraModel::pinhole(
        width as u32,
        height as u32,
        focal,
        focal,
        (width as f32 - 1.0) * 0.5,
        (height as f32 - 1.0) * 0.5,
    )
}

/// The frames, in run order. Renaming one or changing its content invalidates its baseline.
const FRAMES: &[Frame] = &[
    Frame {
        name: "qvga-landing-1",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Pgm(include_bytes!("../frames/qvga-landing-1.pgm")),
        pad: &PAD_LANDING_1,
        expected: Some(1),
        focal_px: None,
    },
    Frame {
        name: "qvga-multi-6",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Pgm(include_bytes!("../frames/qvga-multi-6.pgm")),
        pad: &PAD_MULTI_6,
        expected: Some(6),
        focal_px: None,
    },
    Frame {
        name: "qvga-far-1",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Pgm(include_bytes!("../frames/qvga-far-1.pgm")),
        pad: &PAD_FAR_1,
        expected: Some(1),
        focal_px: None,
    },
    Frame {
        name: "qvga-field-36",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Pgm(include_bytes!("../frames/qvga-field-36.pgm")),
        pad: &designs::NESTED_FIELD,
        // Of its 36 markers, the 12 the camera's work budget reaches (core's MIN_WORK_BUDGET):
        // the scan stops there, which bounds the frame's time.
        expected: Some(12),
        focal_px: Some(233.5),
    },
    Frame {
        name: "qvga-flat",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Flat(128),
        pad: &designs::NESTED,
        expected: Some(0),
        focal_px: None,
    },
    Frame {
        name: "qvga-adv-noise",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Noise { seed: 0x2545_f491 },
        pad: &designs::NESTED,
        expected: None,
        focal_px: None,
    },
    Frame {
        name: "qvga-adv-checker2",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Checker { cell: 2 },
        pad: &designs::NESTED,
        expected: None,
        focal_px: None,
    },
    Frame {
        name: "qvga-adv-checker8",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Checker { cell: 8 },
        pad: &designs::NESTED,
        expected: None,
        focal_px: None,
    },
    Frame {
        name: "qvga-adv-squares",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Squares { side: 4, pitch: 7 },
        pad: &designs::NESTED,
        expected: None,
        focal_px: None,
    },
    Frame {
        name: "qvga-adv-quads",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Squares { side: 8, pitch: 12 },
        pad: &designs::NESTED,
        expected: None,
        focal_px: None,
    },
    Frame {
        name: "qvga-adv-tags",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Tags {
            side: 24,
            pitch: 32,
            seed: 0x1234_5678,
        },
        pad: &designs::NESTED,
        expected: None,
        focal_px: None,
    },
    Frame {
        name: "vga-landing-3",
        width: VGA.0,
        height: VGA.1,
        source: Source::Pgm(include_bytes!("../frames/vga-landing-3.pgm")),
        pad: &PAD_VGA_LANDING_3,
        expected: Some(3),
        focal_px: None,
    },
    Frame {
        name: "vga-flat",
        width: VGA.0,
        height: VGA.1,
        source: Source::Flat(128),
        pad: &designs::NESTED,
        expected: Some(0),
        focal_px: None,
    },
    Frame {
        name: "vga-adv-noise",
        width: VGA.0,
        height: VGA.1,
        source: Source::Noise { seed: 0x9e37_79b9 },
        pad: &designs::NESTED,
        expected: None,
        focal_px: None,
    },
];

/// The frame as the camera leaves it (the firmware's is in AXI SRAM, 32-byte aligned).
static mut FRAME: FrameBuffer = FrameBuffer::new();
/// Work memory as the firmware's `main` provides it (QVGA); VGA for the VGA frames.
static mut QVGA_WORKSPACE: QvgaWorkspace = QvgaWorkspace::new();
static mut VGA_WORKSPACE: VgaWorkspace = VgaWorkspace::new();
/// The pipeline lives in static storage in the firmware too (the vision task's future). Each
/// frame is its own scene (camera, pad), so each gets a new pipeline, written here.
static mut PIPELINE: MaybeUninit<FramePipeline<'static>> = MaybeUninit::uninit();
/// The viewer's frame record's pixels (the firmware's `view::ViewFrame`).
static mut VIEW_PIXELS: [u8; 320 * 240] = [0; 320 * 240];

/// Runs `f` as one counted region labelled `<frame>: <stage>`, with the stack below the
/// current stack pointer painted first, and prints the stack depth `f` reached.
///
/// Adding a stage to the benchmark is one call of this in [`run_frame`].
#[inline(always)]
fn region<R>(frame: &str, stage: &str, f: impl FnOnce() -> R) -> R {
    hprintln!("{}: {}", frame, stage);
    let painted = stack::paint();
    m7bench_start();
    let result = f();
    m7bench_stop();
    let depth = painted.depth();
    hprintln!(
        "  stack {} bytes{}",
        depth.bytes,
        if depth.overflowed {
            " (the whole painted area: more than that)"
        } else {
            ""
        }
    );
    result
}

/// What the benchmark keeps across frames.
struct Bench {
    pipeline: &'static mut MaybeUninit<FramePipeline<'static>>,
    qvga: &'static mut QvgaWorkspace,
    vga: &'static mut VgaWorkspace,
    companion: Companion,
    /// The viewer's record's pixels.
    view: &'static mut [u8; 320 * 240],
    /// Frame time, µs (33 ms per frame).
    now_us: u64,
}

/// The per-frame path on one frame: one region per stage. Returns false when the frame's
/// detections differ from what it contains.
fn run_frame(bench: &mut Bench, frame: &Frame, image: &GrayImage<'_>, pixels: &[u8]) -> bool {
    let Bench {
        pipeline: pipeline_slot,
        qvga,
        vga,
        companion,
        view,
        now_us,
    } = bench;
    // Set up outside the regions, as the vision task does before its first frame.
    let Ok(pipeline) = FramePipeline::new(
        tables::DEFAULT,
        frame.pad,
        camera_for(frame.width, frame.height, frame.focal_px),
        PipelineConfig::default(),
        PipelineSettings::default(),
    ) else {
        hprintln!("  bad pipeline configuration");
        return false;
    };
    let pipeline = pipeline_slot.write(pipeline);
    // No autopilot streams its attitude here: the estimator runs its camera-frame track, and
    // the ArduPilot profile needs nothing more.
    let vehicle = VehicleState::new();
    let vga_frame = (frame.width, frame.height) == VGA;
    // The whole per-frame path, as firmware/src/vision.rs runs it.
    let mut process = |pipeline: &mut FramePipeline<'static>, t: u64| {
        if vga_frame {
            pipeline.process(image, t, &vehicle, &mut vga.buffers())
        } else {
            pipeline.process(image, t, &vehicle, &mut qvga.buffers())
        }
    };
    // The tracker confirms a track over a few frames; the benchmark frames are unrelated
    // scenes, so each is first run a few times outside the regions (as a hover would), and
    // the counted frame is the one that sends its LANDING_TARGET.
    for _ in 0..WARM_UP_FRAMES {
        *now_us += FRAME_PERIOD_US;
        let warm_up = process(pipeline, *now_us);
        companion.on_estimate(&warm_up.estimate, *now_us);
        while companion
            .poll_transmit(*now_us, &mut [0u8; MAX_FRAME_LEN])
            .is_some()
        {}
    }
    *now_us += FRAME_PERIOD_US;
    let t = *now_us;
    // Stage 1: detection, the pad fix and the estimator (the vision task's work).
    let FrameReport {
        estimate,
        fix,
        markers,
        detect_error,
        ..
    } = region(frame.name, "pipeline", || process(pipeline, t));
    let ok = report(frame, detect_error.map_or(Ok(markers), Err), pipeline);
    // Stages 2 and 3: the link task's LANDING_TARGET and its MAVLink bytes for this frame.
    let outcome = region(frame.name, "target", || companion.on_estimate(&estimate, t));
    let mut uart = [0u8; MAX_FRAME_LEN];
    let (messages, bytes) = region(frame.name, "encode", || {
        let (mut messages, mut bytes) = (0u32, 0usize);
        while let Some(n) = companion.poll_transmit(t, &mut uart) {
            messages += 1;
            bytes += n;
        }
        (messages, bytes)
    });
    hprintln!(
        "  fix {} target {:?} sent {} messages, {} bytes",
        fix.is_some(),
        outcome,
        messages,
        bytes
    );
    if frame.name == "qvga-landing-1" {
        view_regions(frame, pixels, pipeline, fix.as_ref(), view, t);
    }
    let fix_expected = frame.expected.is_none_or(|n| (n > 0) == fix.is_some());
    if !fix_expected {
        hprintln!("  MISMATCH: pad fix {}", fix.is_some());
    }
    ok && fix_expected
}

/// The frame stream's regions on one QVGA frame (see the module docs).
fn view_regions(
    frame: &Frame,
    pixels: &[u8],
    pipeline: &FramePipeline<'static>,
    fix: Option<&touchdown_core::pose::PadFix>,
    view: &mut [u8; 320 * 240],
    t: u64,
) {
    let mut head = [0u8; frame_stream::MAX_HEAD_LEN];
    let len = region(frame.name, "view-head", || {
        let meta = frame_stream::FrameMeta {
            index: 1,
            t_us: t,
            width: frame.width as u16,
            height: frame.height as u16,
            scale: 1,
            exposure_us: 4000,
            gain_x16: 16,
            process_us: 9000,
            camera: pipeline.camera(),
            families: tables::DEFAULT,
            pad_name: pipeline.pad().name(),
            pad_scale: 1.0,
            detections: pipeline.detector().detections(),
            fix: fix.map(|f| {
                let c = f.camera_position();
                frame_stream::StreamedFix {
                    camera_position: [c.x, c.y, c.z],
                    markers_used: f.markers_used,
                    reprojection_rms_px: f.reprojection_rms_px,
                }
            }),
        };
        frame_stream::encode_head(&meta, &mut head).unwrap_or(0)
    });
    region(frame.name, "view-copy", || {
        if let Some(out) = view.get_mut(..pixels.len()) {
            out.copy_from_slice(pixels);
        }
    });
    region(frame.name, "view-halve", || {
        frame_stream::halve(pixels, frame.width, frame.height, &mut view[..])
    });
    let sum = region(frame.name, "view-checksum", || {
        let mut sum = frame_stream::Adler32::new();
        sum.update(head.get(..len).unwrap_or_default());
        sum.update(pixels);
        sum.value()
    });
    hprintln!("  head {} bytes, checksum {:08x}", len, sum);
}

/// Prints the detections and statistics of a frame (outside every region); false when the
/// number of detections is not the expected one.
fn report(
    frame: &Frame,
    detected: Result<usize, impl core::fmt::Debug>,
    pipeline: &FramePipeline<'_>,
) -> bool {
    let detector = pipeline.detector();
    let DetectStats {
        contours,
        quads,
        refined,
        bordered,
        decoded,
        fitted,
        deblurred,
        trace_steps,
        work,
        truncated,
    } = *detector.stats();
    let count = match detected {
        Ok(count) => count,
        Err(e) => {
            hprintln!("  detect failed: {:?}", e);
            return false;
        }
    };
    hprintln!(
        "  detections {} contours {} quads {} refined {} bordered {} decoded {} fitted {} deblurred {} trace_steps {} work {} truncated {}",
        count,
        contours,
        quads,
        refined,
        bordered,
        decoded,
        fitted,
        deblurred,
        trace_steps,
        work,
        truncated
    );
    for d in detector.detections() {
        let family = tables::DEFAULT
            .get(usize::from(d.family))
            .map_or("?", |f| f.name);
        hprintln!(
            "    {} id {} hamming {} margin {:.2} centre ({:.1}, {:.1})",
            family,
            d.id,
            d.hamming,
            d.decision_margin,
            d.center.x,
            d.center.y
        );
    }
    match frame.expected {
        Some(expected) if expected != count => {
            hprintln!(
                "  MISMATCH: {} detection(s), the frame has {} marker(s)",
                count,
                expected
            );
            false
        }
        _ => true,
    }
}

/// The key of [`SIGNED_PARAM_SET`]: bytes 1, 2, ..., 32 as two-digit decimal in hex digits.
const SIGNING_KEY: [u8; 32] = [
    0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0x09, 0x10, 0x11, 0x12, 0x13, 0x14, 0x15, 0x16,
    0x17, 0x18, 0x19, 0x20, 0x21, 0x22, 0x23, 0x24, 0x25, 0x26, 0x27, 0x28, 0x29, 0x30, 0x31, 0x32,
];
/// PARAM_SET TD_TAG_SIZE 0.5 to (1, 191) from (255, 190), signed by pymavlink with
/// [`SIGNING_KEY`] at timestamp 1000 (`scripts/mavlink_signing.py sign`).
const SIGNED_PARAM_SET: [u8; 48] = [
    0xfd, 0x17, 0x01, 0x00, 0x00, 0xff, 0xbe, 0x17, 0x00, 0x00, 0x00, 0x00, 0x00, 0x3f, 0x01, 0xbf,
    0x54, 0x44, 0x5f, 0x54, 0x41, 0x47, 0x5f, 0x53, 0x49, 0x5a, 0x45, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x09, 0xb7, 0xdd, 0x00, 0xe8, 0x03, 0x00, 0x00, 0x00, 0x00, 0xef, 0xfd, 0x71, 0x0a, 0xa9, 0x2f,
];
/// The same PARAM_SET unsigned.
const UNSIGNED_PARAM_SET: [u8; 35] = [
    0xfd, 0x17, 0x00, 0x00, 0x00, 0xff, 0xbe, 0x17, 0x00, 0x00, 0x00, 0x00, 0x00, 0x3f, 0x01, 0xbf,
    0x54, 0x44, 0x5f, 0x54, 0x41, 0x47, 0x5f, 0x53, 0x49, 0x5a, 0x45, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x09, 0xd5, 0xaa,
];

/// The signing regions (see the module docs); `false` when a PARAM_SET was not applied.
fn signing_regions() -> bool {
    let keyed = || {
        let mut config = CompanionConfig::with_profile(Profile::ArduPilot);
        config
            .params
            .set_signing_secret(SigningSecret::new(SIGNING_KEY, 0));
        Companion::new(config)
    };
    let mut ok = true;
    for (stage, mut companion, frame) in [
        (
            "param-set-unsigned",
            Companion::new(CompanionConfig::with_profile(Profile::ArduPilot)),
            &UNSIGNED_PARAM_SET[..],
        ),
        ("param-set-signed", keyed(), &SIGNED_PARAM_SET[..]),
    ] {
        region("signing", stage, || companion.receive(frame, 1_000));
        let applied = companion.params().get(ParamId::TagSize) == 0.5;
        hprintln!("  applied {}", applied);
        ok &= applied;
    }
    for (stage, mut companion) in [
        (
            "encode-unsigned",
            Companion::new(CompanionConfig::with_profile(Profile::ArduPilot)),
        ),
        ("encode-signed", keyed()),
    ] {
        let mut uart = [0u8; MAX_FRAME_LEN];
        let (messages, bytes) = region("signing", stage, || {
            let (mut messages, mut bytes) = (0u32, 0usize);
            while let Some(n) = companion.poll_transmit(2_000, &mut uart) {
                messages += 1;
                bytes += n;
            }
            (messages, bytes)
        });
        hprintln!("  sent {} messages, {} bytes", messages, bytes);
    }
    ok
}

#[entry]
fn main() -> ! {
    // SAFETY: `main` runs once, without interrupts; each static is borrowed exactly once here
    // and the borrows live in `bench` (and `frame_buffer`) only.
    let (mut bench, frame_buffer) = unsafe {
        (
            Bench {
                pipeline: &mut *addr_of_mut!(PIPELINE),
                qvga: &mut *addr_of_mut!(QVGA_WORKSPACE),
                vga: &mut *addr_of_mut!(VGA_WORKSPACE),
                companion: Companion::new(CompanionConfig::with_profile(Profile::ArduPilot)),
                view: &mut *addr_of_mut!(VIEW_PIXELS),
                now_us: 0,
            },
            &mut *addr_of_mut!(FRAME),
        )
    };
    hprintln!("m7bench: {} frames", FRAMES.len());
    let mut ok = true;
    for frame in FRAMES {
        let pixels = match frame_buffer.fill(frame.width, frame.height, &frame.source) {
            Ok(pixels) => pixels,
            Err(e) => {
                hprintln!("{}: bad frame: {}", frame.name, e);
                ok = false;
                continue;
            }
        };
        let image = match GrayImage::new(pixels, frame.width, frame.height) {
            Ok(image) => image,
            Err(e) => {
                hprintln!("{}: bad image: {:?}", frame.name, e);
                ok = false;
                continue;
            }
        };
        ok &= run_frame(&mut bench, frame, &image, pixels);
    }
    ok &= signing_regions();
    hprintln!("m7bench: {}", if ok { "done" } else { "FAILED" });
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    #[allow(clippy::empty_loop)]
    loop {}
}
