//! Link-time proof that touchdown-core's per-frame path cannot panic.
//!
//! This image is never run. It is built for the firmware's target with the firmware's release
//! profile (see Cargo.toml), and its entry point calls the whole per-frame path on inputs the
//! optimiser cannot see through ([`black_box`]): the vision task's [`FramePipeline`]
//! (`process`: detection with any configuration, so both detection pipelines, any families,
//! any pixels, then the pad fix with its prediction and level steps and the estimator, with
//! the vehicle state the companion decoded; `apply`: the parameter hand-over), the
//! companion's MAVLink parse (any received bytes), its LANDING_TARGET and encode (draining
//! `poll_transmit`), the vision task's exposure loop (`AutoExposure::set_limits` included)
//! and its frame timing (`FrameTiming`: exposure time stamp, capture timeout, settling,
//! skipped frames), and the frame stream to a host viewer (the request parser on any bytes,
//! the switch, the record's head, the halving, the checksum). Also, off the firmware's path
//! but public and run by the host tools:
//! single-marker pose (IPPE + refinement).
//!
//! Not covered: `PoseMethod::PaperHomography`, the paper's homography decomposition, which
//! only reproduces the paper's tables on the host; it uses nalgebra's SVD, whose internal
//! indexing keeps panic paths.
//!
//! The panic handler calls [`touchdown_core_per_frame_path_can_panic`], a function that is
//! declared but defined nowhere. If, after inlining and dead-code elimination, any panic
//! (an index out of bounds, an `unwrap` on `None`, a division by zero, a slice of the wrong
//! length...) is still reachable from the entry point, the handler is reachable too and the
//! link fails with an undefined-symbol error naming that function. A clean link is the proof.
//!
//! `scripts/nopanic_check.sh` runs the build and explains a failure; with
//! `--features find-panics` the handler is an ordinary function instead, so the image links
//! and its disassembly shows which functions still call into `core::panicking`.
#![no_std]
#![no_main]

use core::hint::black_box;
use core::panic::PanicInfo;

use touchdown_core::camera::CameraModel;
use touchdown_core::companion::{Companion, CompanionConfig, MAX_FRAME_LEN};
use touchdown_core::detect::QvgaWorkspace;
use touchdown_core::family::{tables, Family};
use touchdown_core::filter::{FrameEstimate, VehicleState};
use touchdown_core::frame_stream::{
    encode_head, halve, Adler32, FrameMeta, RequestParser, StreamSwitch, MAX_HEAD_LEN,
};
use touchdown_core::image::GrayImage;
use touchdown_core::pad::{designs, PadLayout};
use touchdown_core::params::PipelineSettings;
use touchdown_core::pipeline::{FramePipeline, PipelineConfig};
use touchdown_core::pose::{marker_pose, PoseMethod};
use touchdown_core::sensor::{
    mean_brightness, AutoExposure, AutoExposureLimits, FrameTiming, Metering,
};

/// QVGA, the firmware's frame size.
const WIDTH: usize = 320;
const HEIGHT: usize = 240;

/// The frame, as the camera's DMA leaves it (contents unknown to the optimiser).
static mut FRAME: [u8; WIDTH * HEIGHT] = [0; WIDTH * HEIGHT];
/// Detector work memory, as the firmware provides it.
static mut WORKSPACE: QvgaWorkspace = QvgaWorkspace::new();
/// Bytes from the flight controller's UART (contents unknown to the optimiser).
static mut RX: [u8; 256] = [0; 256];

/// Everything the per-frame path keeps across frames.
struct Pipeline<'a> {
    /// The vision task's: detector, families, pad, camera, estimator.
    vision: FramePipeline<'a>,
    workspace: &'a mut QvgaWorkspace,
    companion: Companion,
    exposure: AutoExposure,
    /// The view task's switch (whether a host viewer asks).
    view: StreamSwitch,
}

/// One frame: the per-frame pipeline (detection, pad fix, estimator) with the vehicle state
/// the MAVLink side decoded, the host tools' single-marker poses, MAVLink in and out, the
/// settings hand-over. Every input comes through `black_box`, so no branch can be decided at
/// compile time.
#[inline(never)]
fn per_frame(pipeline: &mut Pipeline<'_>, pixels: &[u8], rx: &[u8], now_us: u64) {
    let exposure_us = black_box(now_us.wrapping_sub(25_000));
    pipeline.companion.receive(rx, now_us);
    let (estimate, metering) = match GrayImage::new(pixels, black_box(WIDTH), black_box(HEIGHT)) {
        Ok(image) => {
            let report = pipeline.vision.process(
                &image,
                exposure_us,
                pipeline.companion.vehicle(),
                &mut pipeline.workspace.buffers(),
            );
            (report.estimate, report.metering)
        }
        Err(_) => (
            FrameEstimate {
                exposure_us,
                fix_found: false,
                estimate: None,
                mount_correction: None,
            },
            Metering::mean_only(0),
        ),
    };
    // Not on the firmware's path, but a public core function the host tools call on the same
    // detections (the single-marker pose): covered here.
    let vision = &pipeline.vision;
    let (detections, camera) = (vision.detector().detections(), vision.camera());
    for d in detections {
        let size = black_box(0.16);
        let _ = black_box(marker_pose(&d.corners, size, camera, PoseMethod::Ippe));
    }
    // The vehicle state as the firmware's vision task reads it (a copy of the link's).
    let mut vehicle = black_box(VehicleState::new());
    vehicle.clone_from(pipeline.companion.vehicle());
    let _ = black_box(vehicle.attitude_at(black_box(exposure_us)));
    #[cfg(feature = "canary")]
    {
        // A deliberate bug: indexes one past the frame. The canary build must not link.
        let past_end = black_box(pixels.len());
        black_box(pixels[past_end]);
    }
    let companion = &mut pipeline.companion;
    let _ = black_box(companion.on_estimate(&estimate, now_us));
    let mut tx = [0u8; MAX_FRAME_LEN];
    while let Some(n) = companion.poll_transmit(now_us, &mut tx) {
        black_box(tx.get(..n));
    }
    let _ = black_box(companion.stats());
    // The vision task's exposure step and, after a PARAM_SET, its settings hand-over: the
    // pipeline's (the detector's correction cap, the scaled pad) and the exposure limits.
    let _ = black_box(pipeline.exposure.update_metered(&black_box(metering)));
    if let Ok(image) = GrayImage::new(pixels, black_box(WIDTH), black_box(HEIGHT)) {
        let mean = mean_brightness(&image, black_box(8));
        let _ = black_box(pipeline.exposure.update(mean));
    }
    let settings = PipelineSettings::from_params(pipeline.companion.params());
    let _ = black_box(pipeline.vision.apply(settings));
    let (line_ns, frame_lines) = (black_box(120_000), black_box(278));
    pipeline
        .exposure
        .set_limits(settings.exposure, line_ns, frame_lines);
    // The vision task's frame timing: the exposure time stamp, the capture timeout, the
    // settling wait and the skipped-frame count, on any timing a sensor driver could report.
    let timing = FrameTiming {
        pclk_hz: black_box(9_600_000),
        line_ns: black_box(line_ns),
        frame_lines: black_box(frame_lines),
        active_lines: black_box(240),
    };
    let lines = black_box(pipeline.exposure.setting().lines);
    let _ =
        black_box(timing.mid_exposure_before_frame_end_us(lines, black_box(240), black_box(240)));
    let _ = black_box(timing.capture_timeout_us());
    let _ = black_box(timing.settling_time_us());
    let _ = black_box(timing.frames_skipped(black_box(now_us)));
    // The frame stream to a host viewer: the request parser on any bytes the debugger wrote,
    // the switch, the record's head with the frame's detections and fix, and the halving.
    let mut requests = RequestParser::new();
    if let Some(request) = requests.push(black_box(rx)) {
        pipeline.view.requested(request, now_us);
    }
    if let Some(scale) = pipeline.view.take(black_box(now_us)) {
        let fix = black_box(None);
        let meta = FrameMeta {
            index: black_box(1),
            t_us: exposure_us,
            width: black_box(WIDTH as u16),
            height: black_box(HEIGHT as u16),
            scale,
            exposure_us: black_box(4000),
            gain_x16: black_box(16),
            process_us: black_box(9000),
            camera: pipeline.vision.camera(),
            families: black_box(tables::DEFAULT),
            pad_name: pipeline.vision.pad().name(),
            pad_scale: black_box(1.0),
            detections: pipeline.vision.detector().detections(),
            fix,
        };
        let mut head = [0u8; MAX_HEAD_LEN];
        let _ = black_box(encode_head(&meta, &mut head));
        let mut half = [0u8; WIDTH * HEIGHT / 4];
        let _ = black_box(halve(
            pixels,
            black_box(WIDTH),
            black_box(HEIGHT),
            &mut half,
        ));
        let mut sum = Adler32::new();
        sum.update(black_box(&head));
        black_box(sum.value());
    }
}

/// The entry point (lld's default `_start`): builds the pipeline and runs frames forever.
#[no_mangle]
pub extern "C" fn _start() -> ! {
    // SAFETY: `_start` runs once; each static is borrowed exactly once, here.
    let (workspace, frame, rx) = unsafe {
        (
            &mut *core::ptr::addr_of_mut!(WORKSPACE),
            &*core::ptr::addr_of!(FRAME),
            &*core::ptr::addr_of!(RX),
        )
    };
    let companion = Companion::new(black_box(CompanionConfig::default()));
    let exposure = AutoExposure::new(
        black_box(AutoExposureLimits::default()),
        black_box(120_000),
        black_box(278),
    );
    let families: &[&Family<'static>] = black_box(tables::DEFAULT);
    let layout: &PadLayout<'static> = black_box(&designs::NESTED);
    let camera = black_box(CameraModel::pinhole(
        WIDTH as u32,
        HEIGHT as u32,
        320.0,
        320.0,
        159.5,
        119.5,
    ));
    let Ok(vision) = FramePipeline::new(
        families,
        layout,
        camera,
        black_box(PipelineConfig::default()),
        black_box(PipelineSettings::default()),
    ) else {
        loop {
            core::hint::spin_loop();
        }
    };
    let mut pipeline = Pipeline {
        vision,
        workspace,
        companion,
        exposure,
        view: StreamSwitch::new(),
    };
    let mut now_us = 0u64;
    loop {
        now_us = now_us.wrapping_add(black_box(33_333));
        let pixels: &[u8] = black_box(&frame[..]);
        let rx_len = black_box(0usize).min(rx.len());
        let rx_bytes = rx.get(..rx_len).unwrap_or(&[]);
        per_frame(&mut pipeline, pixels, black_box(rx_bytes), now_us);
    }
}

#[cfg(not(feature = "find-panics"))]
extern "C" {
    /// Defined nowhere, on purpose: see the crate documentation.
    fn touchdown_core_per_frame_path_can_panic() -> !;
}

/// Reachable only if some panic in the per-frame path survived optimisation; then the link
/// fails on the undefined [`touchdown_core_per_frame_path_can_panic`].
#[cfg(not(feature = "find-panics"))]
#[panic_handler]
fn panic(_info: &PanicInfo<'_>) -> ! {
    // SAFETY: never executed in a linked image: if this is reachable, there is no image.
    unsafe { touchdown_core_per_frame_path_can_panic() }
}

/// `--features find-panics`: a real handler, so the image links and its disassembly shows the
/// callers of `core::panicking::*`.
#[cfg(feature = "find-panics")]
#[panic_handler]
#[inline(never)]
fn panic(_info: &PanicInfo<'_>) -> ! {
    loop {
        core::hint::spin_loop();
    }
}
