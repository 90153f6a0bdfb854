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
//! - `detect`: [`Detector::detect`], called as `firmware/src/vision.rs` does: the default
//!   families, a static [`QvgaWorkspace`] / [`VgaWorkspace`], a detector kept across frames,
//!   the default configuration.
//! - `pose`: [`marker_pose`] (IPPE + Levenberg-Marquardt) of every detection, with the
//!   simulator's camera. The firmware does not call pose yet; switch to what it calls (pad
//!   pose on pad-layout frames) when issue 5 lands.
//!
//! The filter and message encoding are added as one [`region`] call each in [`run_frame`].
//!
//! Frames ([`FRAMES`]): the typical ones are rendered by the simulator
//! (`cargo run --release -p touchdown-host --example m7_frames` writes `frames/*.pgm`); the
//! adversarial ones (noise, checkerboard, thousands of small squares) and the flat ones (the
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
use touchdown_core::detect::{DetectStats, Detector, DetectorConfig, QvgaWorkspace, VgaWorkspace};
use touchdown_core::family::tables;
use touchdown_core::image::GrayImage;
use touchdown_core::pose::{marker_pose, PoseMethod};

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
    /// Markers the frame contains (typical frames); `None` for frames without markers, whose
    /// detections are printed but not checked.
    expected: Option<usize>,
}

const QVGA: (usize, usize) = (320, 240);
const VGA: (usize, usize) = (640, 480);

/// Edge of the printed markers for the pose stage, metres (any positive size: the count does
/// not depend on it).
const MARKER_SIZE_M: f32 = 0.16;

/// The simulator's camera for a frame (`PinholeCamera::for_frame` in host-tests' renderer):
/// focal length = the larger dimension, principal point at the centre, no distortion.
fn camera_for(width: usize, height: usize) -> CameraModel {
    let focal = width.max(height) as f32;
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
        expected: Some(1),
    },
    Frame {
        name: "qvga-multi-6",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Pgm(include_bytes!("../frames/qvga-multi-6.pgm")),
        expected: Some(6),
    },
    Frame {
        name: "qvga-far-1",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Pgm(include_bytes!("../frames/qvga-far-1.pgm")),
        expected: Some(1),
    },
    Frame {
        name: "qvga-flat",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Flat(128),
        expected: Some(0),
    },
    Frame {
        name: "qvga-adv-noise",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Noise { seed: 0x2545_f491 },
        expected: None,
    },
    Frame {
        name: "qvga-adv-checker2",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Checker { cell: 2 },
        expected: None,
    },
    Frame {
        name: "qvga-adv-checker8",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Checker { cell: 8 },
        expected: None,
    },
    Frame {
        name: "qvga-adv-squares",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Squares { side: 4, pitch: 7 },
        expected: None,
    },
    Frame {
        name: "qvga-adv-quads",
        width: QVGA.0,
        height: QVGA.1,
        source: Source::Squares { side: 8, pitch: 12 },
        expected: None,
    },
    Frame {
        name: "vga-landing-3",
        width: VGA.0,
        height: VGA.1,
        source: Source::Pgm(include_bytes!("../frames/vga-landing-3.pgm")),
        expected: Some(3),
    },
    Frame {
        name: "vga-flat",
        width: VGA.0,
        height: VGA.1,
        source: Source::Flat(128),
        expected: Some(0),
    },
    Frame {
        name: "vga-adv-noise",
        width: VGA.0,
        height: VGA.1,
        source: Source::Noise { seed: 0x9e37_79b9 },
        expected: None,
    },
];

/// The frame as the camera leaves it (the firmware's is in AXI SRAM, 32-byte aligned).
static mut FRAME: FrameBuffer = FrameBuffer::new();
/// Work memory as the firmware's `main` provides it (QVGA); VGA for the VGA frames.
static mut QVGA_WORKSPACE: QvgaWorkspace = QvgaWorkspace::new();
static mut VGA_WORKSPACE: VgaWorkspace = VgaWorkspace::new();
/// The detector lives in static storage in the firmware too (the vision task's future).
static mut DETECTOR: MaybeUninit<Detector> = MaybeUninit::uninit();

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
struct Pipeline {
    detector: &'static mut Detector,
    qvga: &'static mut QvgaWorkspace,
    vga: &'static mut VgaWorkspace,
}

/// The per-frame path on one frame: one region per stage. Returns false when the frame's
/// detections differ from what it contains.
fn run_frame(pipeline: &mut Pipeline, frame: &Frame, image: &GrayImage<'_>) -> bool {
    let Pipeline {
        detector,
        qvga,
        vga,
    } = pipeline;
    let vga_frame = (frame.width, frame.height) == VGA;
    // Stage 1: detection, as firmware/src/vision.rs calls it.
    let detected = region(frame.name, "detect", || {
        let result = if vga_frame {
            detector.detect(image, tables::DEFAULT, &mut vga.buffers())
        } else {
            detector.detect(image, tables::DEFAULT, &mut qvga.buffers())
        };
        result.map(|detections| detections.len())
    });
    let ok = report(frame, detected, detector);
    // Stage 2: pose of every detected marker (IPPE, both candidates refined by
    // Levenberg-Marquardt). The firmware does not call pose yet (issue 5); until it does,
    // this is the per-marker method on the simulator's camera.
    let camera = camera_for(frame.width, frame.height);
    let detections = detector.detections();
    let (poses, failures) = region(frame.name, "pose", || {
        let (mut poses, mut failures) = (0u32, 0u32);
        for d in detections {
            match marker_pose(&d.corners, MARKER_SIZE_M, &camera, PoseMethod::Ippe) {
                Ok(_) => poses += 1,
                Err(_) => failures += 1,
            }
        }
        (poses, failures)
    });
    hprintln!("  poses {} failed {}", poses, failures);
    // Further stages (filter, message encoding) go here, each as one
    // `let x = region(frame.name, "filter", || ...);` on the previous stage's results.
    ok && failures == 0
}

/// Prints the detections and statistics of a frame (outside every region); false when the
/// number of detections is not the expected one.
fn report(
    frame: &Frame,
    detected: Result<usize, impl core::fmt::Debug>,
    detector: &Detector,
) -> bool {
    let DetectStats {
        contours,
        quads,
        bordered,
        decoded,
        trace_steps,
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
        "  detections {} contours {} quads {} bordered {} decoded {} trace_steps {} truncated {}",
        count,
        contours,
        quads,
        bordered,
        decoded,
        trace_steps,
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

#[entry]
fn main() -> ! {
    // SAFETY: `main` runs once, without interrupts; each static is borrowed exactly once here
    // and the borrows live in `pipeline` (and `frame_buffer`) only.
    let (mut pipeline, frame_buffer) = unsafe {
        (
            Pipeline {
                detector: (*addr_of_mut!(DETECTOR)).write(Detector::new(DetectorConfig::default())),
                qvga: &mut *addr_of_mut!(QVGA_WORKSPACE),
                vga: &mut *addr_of_mut!(VGA_WORKSPACE),
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
        ok &= run_frame(&mut pipeline, frame, &image);
    }
    hprintln!("m7bench: {}", if ok { "done" } else { "FAILED" });
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    #[allow(clippy::empty_loop)]
    loop {}
}
