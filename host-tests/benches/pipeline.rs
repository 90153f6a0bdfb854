//! Host benchmarks (criterion) of the per-frame path, stage by stage and whole, on the same
//! frames as the Cortex-M7 instruction counts (`bench/m7/frames`, rendered by the simulator):
//!
//! ```text
//! cargo bench -p touchdown-host --bench pipeline [-- FILTER]
//! ```
//!
//! Stages: `detect` (the default families, the firmware's configuration), `pose` (the pad
//! fix of a one-marker pad of the first detection, as `bench/m7` does), `filter` (the
//! companion's trackers on that fix) and `encode` (draining the companion's MAVLink output),
//! then `frame`: all four, as the camera board runs them. Speed goals are judged on the
//! instruction counts of `scripts/m7_check.sh`; these host timings are for profiling and for
//! the side-by-side with AprilTag 3 and OpenCV (`scripts/compare_peers.py`).

use std::hint::black_box;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use touchdown_core::camera::CameraModel;
use touchdown_core::companion::{Companion, CompanionConfig, FrameResult, Profile, MAX_FRAME_LEN};
use touchdown_core::detect::{Detection, Detector, DetectorConfig};
use touchdown_core::family::tables;
use touchdown_core::pad::{PadLayout, PadMarker};
use touchdown_core::pose::{pad_pose, PadFix};
use touchdown_host::image_io::GrayFrame;
use touchdown_host::recording::parse_pgm;
use touchdown_host::workspace::HostWorkspace;

/// The benchmark frames (committed with the M7 benchmark).
const FRAMES: [&str; 4] = [
    "qvga-landing-1",
    "qvga-multi-6",
    "qvga-far-1",
    "vga-landing-3",
];
/// Marker edge for the pose, metres (any positive size costs the same).
const MARKER_SIZE_M: f32 = 0.16;
/// 30 Hz.
const FRAME_PERIOD_US: u64 = 33_333;

fn load(name: &str) -> GrayFrame {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../bench/m7/frames")
        .join(format!("{name}.pgm"));
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    parse_pgm(&bytes, None).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The simulator's camera for the frame (as `bench/m7` uses).
fn camera_for(frame: &GrayFrame) -> CameraModel {
    let focal = frame.width.max(frame.height) as f32;
    CameraModel::pinhole(
        frame.width as u32,
        frame.height as u32,
        focal,
        focal,
        (frame.width as f32 - 1.0) * 0.5,
        (frame.height as f32 - 1.0) * 0.5,
    )
}

/// A one-marker pad made of the first detection.
fn layout_of(detections: &[Detection]) -> PadLayout<'static> {
    let d = detections.first().expect("the frame has a marker");
    let family = tables::DEFAULT[usize::from(d.family)];
    PadLayout::new(
        "bench",
        &[PadMarker {
            family: family.name,
            id: d.id,
            size: MARKER_SIZE_M,
            x: 0.0,
            y: 0.0,
            yaw_deg: 0.0,
        }],
    )
    .expect("a one-marker layout is valid")
}

/// A companion whose track on `fix` is confirmed, so the next frame sends a target.
fn warmed_companion(fix: PadFix, now_us: &mut u64) -> Companion {
    let mut companion = Companion::new(CompanionConfig::with_profile(Profile::ArduPilot))
        .expect("default configuration");
    let mut uart = [0u8; MAX_FRAME_LEN];
    for _ in 0..6 {
        *now_us += FRAME_PERIOD_US;
        companion.on_frame(
            FrameResult {
                exposure_us: *now_us,
                fix: Some(fix),
            },
            *now_us,
        );
        while companion.poll_transmit(*now_us, &mut uart).is_some() {}
    }
    companion
}

fn stages(c: &mut Criterion) {
    for name in FRAMES {
        let frame = load(name);
        let image = frame.view();
        let camera = camera_for(&frame);
        let mut workspace = HostWorkspace::new();
        let mut detector = Detector::new(DetectorConfig::default());
        let detections = workspace
            .detect(&mut detector, &image, tables::DEFAULT)
            .expect("valid frame");
        let layout = layout_of(&detections);
        let fix = pad_pose(&detections, tables::DEFAULT, &layout, &camera).expect("pose");

        c.bench_function(&format!("{name}/detect"), |b| {
            b.iter(|| {
                let mut buffers = workspace.buffers(frame.width, frame.height);
                black_box(
                    detector
                        .detect(black_box(&image), tables::DEFAULT, &mut buffers)
                        .map(|d| d.len()),
                )
            })
        });
        c.bench_function(&format!("{name}/pose"), |b| {
            b.iter(|| pad_pose(black_box(&detections), tables::DEFAULT, &layout, &camera))
        });
        let mut now_us = 0u64;
        let mut companion = warmed_companion(fix, &mut now_us);
        let mut uart = [0u8; MAX_FRAME_LEN];
        c.bench_function(&format!("{name}/filter+encode"), |b| {
            b.iter(|| {
                now_us += FRAME_PERIOD_US;
                companion.on_frame(
                    FrameResult {
                        exposure_us: now_us,
                        fix: Some(black_box(fix)),
                    },
                    now_us,
                );
                let mut bytes = 0usize;
                while let Some(n) = companion.poll_transmit(now_us, &mut uart) {
                    bytes += n;
                }
                black_box(bytes)
            })
        });
        c.bench_function(&format!("{name}/frame"), |b| {
            b.iter(|| {
                let mut buffers = workspace.buffers(frame.width, frame.height);
                let fix = detector
                    .detect(black_box(&image), tables::DEFAULT, &mut buffers)
                    .ok()
                    .and_then(|d| pad_pose(d, tables::DEFAULT, &layout, &camera).ok());
                now_us += FRAME_PERIOD_US;
                companion.on_frame(
                    FrameResult {
                        exposure_us: now_us,
                        fix,
                    },
                    now_us,
                );
                let mut bytes = 0usize;
                while let Some(n) = companion.poll_transmit(now_us, &mut uart) {
                    bytes += n;
                }
                black_box(bytes)
            })
        });
    }
}

criterion_group!(benches, stages);
criterion_main!(benches);
