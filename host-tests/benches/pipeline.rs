//! Host benchmarks (criterion) of the per-frame path, on the same frames as the Cortex-M7
//! instruction counts (`bench/m7/frames`, rendered by the simulator):
//!
//! ```text
//! cargo bench -p touchdown-host-tests --bench pipeline [-- FILTER]
//! ```
//!
//! Benches, per frame: `pipeline` ([`FramePipeline::process`]: detection with the default
//! families and the firmware's configuration, the pad fix on a one-marker pad of the marker
//! `bench/m7` fixes on, and the estimator), `target+encode` (the companion's LANDING_TARGET
//! of that estimate and draining its MAVLink output), then `frame`: both, as the camera board
//! runs them. Speed
//! goals are judged on the instruction counts of `scripts/m7_check.sh`; these host timings
//! are for profiling and for the side-by-side with AprilTag 3 and OpenCV
//! (`scripts/compare_peers.py`).

use std::hint::black_box;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use touchdown_core::camera::CameraModel;
use touchdown_core::companion::{Companion, CompanionConfig, Profile, MAX_FRAME_LEN};
use touchdown_core::family::tables;
use touchdown_core::filter::{FrameEstimate, VehicleState};
use touchdown_core::pad::{PadLayout, PadMarker};
use touchdown_core::params::PipelineSettings;
use touchdown_core::pipeline::{FramePipeline, PipelineConfig};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_formats::image_io::GrayFrame;
use touchdown_formats::pgm::parse_pgm;

/// The benchmark frames (committed with the M7 benchmark), each with the tag36h11 id its pad
/// is made of: the marker `bench/m7` fixes on, so both measure the same pose.
const FRAMES: [(&str, u16); 4] = [
    ("qvga-landing-1", 7),
    ("qvga-multi-6", 0),
    ("qvga-far-1", 11),
    ("vga-landing-3", 22),
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

/// A pad of one tag36h11 marker, centred on the landing point.
fn one_tag(id: u16) -> PadLayout<'static> {
    PadLayout::new(
        "bench",
        &[PadMarker {
            family: "tag36h11",
            id,
            size: MARKER_SIZE_M,
            x: 0.0,
            y: 0.0,
            yaw_deg: 0.0,
        }],
    )
    .expect("a one-marker layout is valid")
}

fn stages(c: &mut Criterion) {
    for (name, id) in FRAMES {
        let frame = load(name);
        let image = frame.view();
        let pad = one_tag(id);
        // As the vision task sets it up: the default configuration, the default parameters;
        // no attitude streamed (the estimator's camera-frame track; ArduPilot needs no more).
        let mut pipeline = FramePipeline::new(
            tables::DEFAULT,
            &pad,
            camera_for(&frame),
            PipelineConfig::default(),
            PipelineSettings::default(),
        )
        .expect("the default trackers are valid");
        let vehicle = VehicleState::new();
        let mut workspace = HostWorkspace::new();
        let mut companion = Companion::new(CompanionConfig::with_profile(Profile::ArduPilot));
        let mut uart = [0u8; MAX_FRAME_LEN];
        // A hover over the frame's pad until the track is confirmed and a target goes out.
        let mut now_us = 0u64;
        let mut estimate = None;
        for _ in 0..6 {
            now_us += FRAME_PERIOD_US;
            let mut buffers = workspace.buffers(frame.width, frame.height);
            let report = pipeline.process(&image, now_us, &vehicle, &mut buffers);
            assert!(report.fix.is_some(), "the frame shows its pad's marker");
            companion.on_estimate(&report.estimate, now_us);
            while companion.poll_transmit(now_us, &mut uart).is_some() {}
            estimate = Some(report.estimate);
        }
        let estimate = estimate.expect("six frames ran");
        assert!(estimate.estimate.is_some(), "the track is confirmed");

        c.bench_function(&format!("{name}/pipeline"), |b| {
            b.iter(|| {
                now_us += FRAME_PERIOD_US;
                let mut buffers = workspace.buffers(frame.width, frame.height);
                black_box(pipeline.process(black_box(&image), now_us, &vehicle, &mut buffers))
            })
        });
        c.bench_function(&format!("{name}/target+encode"), |b| {
            b.iter(|| {
                now_us += FRAME_PERIOD_US;
                let frame_estimate = FrameEstimate {
                    exposure_us: now_us,
                    ..black_box(estimate)
                };
                companion.on_estimate(&frame_estimate, now_us);
                let mut bytes = 0usize;
                while let Some(n) = companion.poll_transmit(now_us, &mut uart) {
                    bytes += n;
                }
                black_box(bytes)
            })
        });
        c.bench_function(&format!("{name}/frame"), |b| {
            b.iter(|| {
                now_us += FRAME_PERIOD_US;
                let mut buffers = workspace.buffers(frame.width, frame.height);
                let report = pipeline.process(black_box(&image), now_us, &vehicle, &mut buffers);
                companion.on_estimate(&report.estimate, now_us);
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
