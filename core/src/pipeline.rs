//! The camera side of the per-frame path, in one place: frame -> candidates -> decoded markers
//! -> pad fix, with the parameters that tune it applied between frames.
//!
//! The firmware's vision task and the host's `touchdown companion` both run exactly this:
//! what a bench or a replay measures through [`FramePipeline`] is what the camera board does
//! with the same frame. Before it existed each caller wired the detector, the pad scaling and
//! the pose by hand, and the copies drifted: the host kept the pad it was started with while
//! the firmware followed TD_TAG_SIZE.
//!
//! What it owns: the [`Detector`] (with its configuration), the families searched, the pad as
//! built and as currently scaled, the camera model, and the [`VisionSettings`] in force. What
//! it is handed per frame: the image, its exposure time and the detector's frame-sized work
//! memory ([`Buffers`], which the firmware keeps in DMA-reachable RAM and the host sizes to
//! the image). What it returns: the [`FrameResult`] the companion's estimator takes, plus the
//! counts a log or a report wants.
//!
//! Settings ([`FramePipeline::apply`]) change the detector's correction cap and the pad's
//! scale; they are meant to be applied between frames (the firmware takes them from the link
//! task's signal before processing the next frame; the host after each received MAVLink
//! chunk). The exposure loop is not here: it drives a sensor, which the host does not have.

use crate::camera::CameraModel;
use crate::companion::{FrameResult, VisionSettings};
use crate::detect::{Buffers, DetectError, Detector, DetectorConfig};
use crate::family::Family;
use crate::image::GrayImage;
use crate::pad::{PadError, PadLayout};
use crate::pose::pad_pose;

/// What one frame gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameReport {
    /// What the companion's estimator takes: the exposure time and the pad fix, if any.
    pub result: FrameResult,
    /// Markers decoded in the frame (of any id, on the pad or not).
    pub markers: usize,
    /// Why detection stopped, when it did (the frame then has no fix).
    pub detect_error: Option<DetectError>,
}

/// The detector, the pad and the camera, applied to one frame after another.
#[derive(Debug)]
pub struct FramePipeline<'a> {
    detector: Detector,
    base_config: DetectorConfig,
    families: &'a [&'a Family<'a>],
    built_pad: PadLayout<'a>,
    pad: PadLayout<'a>,
    camera: CameraModel,
    settings: VisionSettings,
}

impl<'a> FramePipeline<'a> {
    /// A pipeline searching `families` for `built_pad` through `camera`, with the detector
    /// configured as `base_config` (e.g. [`DetectorConfig::default`], the camera's work
    /// budget) and then `settings` applied. When the pad cannot be scaled as `settings` ask
    /// (only an empty pad cannot), it is searched as built.
    pub fn new(
        families: &'a [&'a Family<'a>],
        built_pad: &PadLayout<'a>,
        camera: CameraModel,
        base_config: DetectorConfig,
        settings: VisionSettings,
    ) -> Self {
        let mut pipeline = FramePipeline {
            detector: Detector::new(base_config),
            base_config,
            families,
            built_pad: *built_pad,
            pad: *built_pad,
            camera,
            settings,
        };
        // The error is kept in the pad (as built); `apply` reports it to callers that ask.
        let _ = pipeline.apply(settings);
        pipeline
    }

    /// Takes new settings (call between frames): the detector's correction cap, and the pad
    /// scaled to TD_TAG_SIZE. If the pad cannot be scaled, the pad as built is searched and
    /// the error returned; the other settings apply either way.
    pub fn apply(&mut self, settings: VisionSettings) -> Result<(), PadError> {
        self.settings = settings;
        self.detector
            .set_config(settings.detector_config(self.base_config));
        match settings.pad(&self.built_pad) {
            Ok(pad) => {
                self.pad = pad;
                Ok(())
            }
            Err(e) => {
                self.pad = self.built_pad;
                Err(e)
            }
        }
    }

    /// Finds the pad in `image`, exposed at `exposure_us` (our clock, µs), using `buffers` as
    /// the detector's work memory.
    pub fn process(
        &mut self,
        image: &GrayImage<'_>,
        exposure_us: u64,
        buffers: &mut Buffers<'_>,
    ) -> FrameReport {
        let (markers, fix, detect_error) = match self.detector.detect(image, self.families, buffers)
        {
            Ok(detections) => (
                detections.len(),
                pad_pose(detections, self.families, &self.pad, &self.camera).ok(),
                None,
            ),
            Err(e) => (0, None, Some(e)),
        };
        FrameReport {
            result: FrameResult { exposure_us, fix },
            markers,
            detect_error,
        }
    }

    /// The settings in force.
    pub fn settings(&self) -> &VisionSettings {
        &self.settings
    }

    /// The pad searched for (scaled to TD_TAG_SIZE).
    pub fn pad(&self) -> &PadLayout<'a> {
        &self.pad
    }

    /// The pad as built (what TD_TAG_SIZE scales).
    pub fn built_pad(&self) -> &PadLayout<'a> {
        &self.built_pad
    }

    /// The camera model.
    pub fn camera(&self) -> &CameraModel {
        &self.camera
    }

    /// The detector (its statistics of the last frame, its configuration).
    pub fn detector(&self) -> &Detector {
        &self.detector
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::companion::{ParamId, ParamSet};
    use crate::family::tables;
    use crate::pad::designs;

    /// The firmware's set-up: the default families, the nested pad, a QVGA pinhole camera.
    fn nested_pipeline() -> FramePipeline<'static> {
        FramePipeline::new(
            tables::DEFAULT,
            &designs::NESTED,
            CameraModel::pinhole(320, 240, 233.5, 233.5, 159.5, 119.5),
            DetectorConfig::default(),
            VisionSettings::default(),
        )
    }

    #[test]
    fn settings_scale_the_pad_and_cap_the_correction() {
        let mut pipeline = nested_pipeline();
        assert_eq!(*pipeline.pad(), designs::NESTED);
        assert_eq!(pipeline.detector().config().max_hamming, 1);

        let mut params = ParamSet::default();
        params.set(ParamId::TagSize, 0.625).unwrap();
        params.set(ParamId::MaxHamming, 0.0).unwrap();
        assert_eq!(pipeline.apply(VisionSettings::from_params(&params)), Ok(()));
        // The nested pad's largest marker is 1.25 m: everything at half size.
        let (built, scaled) = (&designs::NESTED.markers()[1], &pipeline.pad().markers()[1]);
        assert_eq!(scaled.size, built.size * 0.5);
        assert_eq!(scaled.x, built.x * 0.5);
        assert_eq!(pipeline.detector().config().max_hamming, 0);
        // Back to the pad as built.
        assert_eq!(pipeline.apply(VisionSettings::default()), Ok(()));
        assert_eq!(*pipeline.pad(), designs::NESTED);
        assert_eq!(*pipeline.built_pad(), designs::NESTED);
    }

    #[test]
    fn a_blank_frame_has_no_fix_and_keeps_its_time() {
        let mut pipeline = nested_pipeline();
        let pixels = [200u8; 320 * 240];
        let image = GrayImage::new(&pixels, 320, 240).unwrap();
        let mut workspace = crate::detect::QvgaWorkspace::new();
        let report = pipeline.process(&image, 123_456, &mut workspace.buffers());
        assert_eq!(report.result.exposure_us, 123_456);
        assert_eq!(report.result.fix, None);
        assert_eq!((report.markers, report.detect_error), (0, None));
    }
}
