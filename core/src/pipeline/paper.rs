//! The reference paper's per-frame path, kept whole so its tables can be reproduced: its
//! detector ([`DetectorConfig::paper`]), the homography decomposition of the largest pad
//! marker in view ([`PoseMethod::PaperHomography`]), and its per-axis Kalman filter with
//! Table 1 ([`PaperKalman`]), on the camera's position in the pad frame.
//!
//! It is not what flies ([`super::FramePipeline`] is), and it is not part of the production
//! detector or estimator: it lives here, beside the pipeline, so that a replay can run both
//! on the same frames through the same kind of entry point. The paper's filter has no notion
//! of a missing measurement: a frame without the marker gives no estimate ("cannot provide
//! any results"), and the filter's time step is the time since its last measurement.
//!
//! The paper's camera looked straight down from a level hovering vehicle; given the
//! camera-to-pad rotation the vehicle knows (its attitude), the position is `-R t` from the
//! pose's translation alone, as ours uses the attitude; without it, the pose's own rotation.

use crate::camera::CameraModel;
use crate::detect::{Buffers, DetectError, Detector, DetectorConfig};
use crate::family::Family;
use crate::filter::{PaperConfig, PaperKalman};
use crate::image::GrayImage;
use crate::pad::PadLayout;
use crate::pose::{largest_layout_marker, marker_pose, marker_to_pad, PoseMethod};
use nalgebra::{Matrix3, Vector3};

/// What the paper's path made of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperReport {
    /// This frame's camera position in the pad frame, unfiltered, metres.
    pub raw: Option<Vector3<f32>>,
    /// The filter's output for this frame, metres (only on frames with a measurement).
    pub estimate: Option<Vector3<f32>>,
    /// Markers decoded in the frame.
    pub markers: usize,
    /// Why detection stopped, when it did.
    pub detect_error: Option<DetectError>,
}

/// The paper's detector, pose and filter, applied to one frame after another.
#[derive(Debug)]
pub struct PaperPipeline<'a> {
    detector: Detector,
    families: &'a [&'a Family<'a>],
    pad: PadLayout<'a>,
    camera: CameraModel,
    filter: PaperKalman,
    last_t_us: Option<u64>,
}

impl<'a> PaperPipeline<'a> {
    /// The paper's method searching `families` for `pad` through `camera`, filtered with
    /// `filter` (the paper's is [`PaperConfig::TABLE_1`]).
    pub fn new(
        families: &'a [&'a Family<'a>],
        pad: &PadLayout<'a>,
        camera: CameraModel,
        filter: PaperConfig,
    ) -> Self {
        PaperPipeline {
            detector: Detector::new(DetectorConfig::paper()),
            families,
            pad: *pad,
            camera,
            filter: PaperKalman::new(filter),
            last_t_us: None,
        }
    }

    /// Forgets the filter's state: the next frame starts a new, independent sequence.
    pub fn reset(&mut self) {
        self.filter.reset();
        self.last_t_us = None;
    }

    /// The paper's method on `image` exposed at `exposure_us`; `camera_to_pad` is the
    /// vehicle's knowledge of the camera's rotation into the pad frame, if any.
    pub fn process(
        &mut self,
        image: &GrayImage<'_>,
        exposure_us: u64,
        camera_to_pad: Option<&Matrix3<f32>>,
        buffers: &mut Buffers<'_>,
    ) -> PaperReport {
        let (raw, markers, detect_error) = match self.detector.detect(image, self.families, buffers)
        {
            Ok(detections) => {
                let raw = largest_layout_marker(detections, self.families, &self.pad).and_then(
                    |(detection, marker)| {
                        let marker_to_camera = marker_pose(
                            &detection.corners,
                            marker.size,
                            &self.camera,
                            PoseMethod::PaperHomography,
                        )
                        .ok()?
                        .best
                        .pose;
                        let pad_to_camera =
                            marker_to_camera.compose(&marker_to_pad(marker).inverse());
                        Some(match camera_to_pad {
                            Some(r) => -(r * pad_to_camera.translation),
                            None => pad_to_camera.camera_position(),
                        })
                    },
                );
                (raw, detections.len(), None)
            }
            Err(e) => (None, 0, Some(e)),
        };
        let estimate = raw.map(|position| {
            let dt = self
                .last_t_us
                .map_or(0.0, |last| exposure_us.saturating_sub(last) as f32 * 1e-6);
            self.last_t_us = Some(exposure_us);
            Vector3::from(self.filter.update([position.x, position.y, position.z], dt))
        });
        PaperReport {
            raw,
            estimate,
            markers,
            detect_error,
        }
    }
}
