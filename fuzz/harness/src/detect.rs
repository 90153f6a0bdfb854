//! The `detect` target: an arbitrary frame through the default and the paper's detector,
//! marker pose and the per-frame pipeline; the detection checks are shared with
//! [`crate::family_file`].

use touchdown_core::camera::CameraModel;
use touchdown_core::detect::{Detection, DetectorConfig, VgaWorkspace};
use touchdown_core::family::{tables, Family};
use touchdown_core::filter::VehicleState;
use touchdown_core::image::GrayImage;
use touchdown_core::pad::designs;
use touchdown_core::params::PipelineSettings;
use touchdown_core::pipeline::{FramePipeline, PipelineConfig};
use touchdown_core::pose::{marker_pose, PoseMethod};

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
            // The view margin on, so that its projections are fuzzed too.
            let settings = PipelineSettings {
                max_hamming: config.max_hamming,
                view_margin: true,
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
