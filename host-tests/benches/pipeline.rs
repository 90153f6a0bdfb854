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
//! runs them. Then `detect/IMAGE`: the detector alone (`touchdown detect`'s settings,
//! tag36h11), warm, on the larger images of the side-by-side with AprilTag 3 and OpenCV
//! (`scripts/compare_peers.py`): AprilTag 3's three test photos (799 x 533), ViSP's
//! 1920 x 1080 benchmark frame and its AprilTag.png, read from the shared data
//! (`$TOUCHDOWN_DATA` or `shared/data` beside the repository; skipped when absent). Speed
//! goals on the board are judged on the instruction counts of `scripts/m7_check.sh`; these
//! host timings are for profiling and for A/B comparisons of the host's detector, steadier
//! than the side-by-side's subprocess runs (`-- detect/` runs only these).

use std::hint::black_box;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use touchdown_core::camera::CameraModel;
use touchdown_core::companion::{Companion, CompanionConfig, Profile, MAX_FRAME_LEN};
use touchdown_core::detect::{Detector, DetectorConfig};
use touchdown_core::family::tables;
use touchdown_core::filter::{FrameEstimate, VehicleState};
use touchdown_core::pad::{PadLayout, PadMarker};
use touchdown_core::params::PipelineSettings;
use touchdown_core::pipeline::{FramePipeline, PipelineConfig};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_formats::image_io::{load_gray, GrayFrame};
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

/// The shared data's images of `detect/...`, relative to its directory.
const PHOTOS: [&str; 5] = [
    "apriltag-test/33369213973_9d9bb4cc96_c.jpg",
    "apriltag-test/34085369442_304b6bafd9_c.jpg",
    "apriltag-test/34139872896_defdb2f8d9_c.jpg",
    "visp-apriltag/benchmark-1920x1080/tag36_11_1920x1080.png",
    "visp-apriltag/AprilTag.png",
];

fn photos(c: &mut Criterion) {
    let Some(data) = touchdown_host_tests::shared_data_or_skip() else {
        return;
    };
    let families = [&tables::TAG36H11];
    let mut detector = Detector::new(DetectorConfig::offline());
    let mut workspace = HostWorkspace::new();
    for relative in PHOTOS {
        let path = data.join(relative);
        let frame = load_gray(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let image = frame.view();
        let name = Path::new(relative)
            .file_stem()
            .and_then(|stem| stem.to_str())
            .unwrap_or(relative);
        let found = workspace
            .detect(&mut detector, &image, &families)
            .expect("the buffers fit the image");
        assert!(!found.is_empty(), "{relative}: its markers are found");
        c.bench_function(&format!("detect/{name}"), |b| {
            b.iter(|| {
                let mut buffers = workspace.buffers(frame.width, frame.height);
                black_box(detector.detect(black_box(&image), &families, &mut buffers)).is_ok()
            })
        });
    }
}

criterion_group!(benches, stages, photos);
criterion_main!(benches);
