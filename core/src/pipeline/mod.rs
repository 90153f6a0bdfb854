//! The per-frame path, in one place: frame -> candidates -> decoded markers -> pad fix ->
//! estimate, with the parameters that tune it applied between frames.
//!
//! What this module offers: [`FramePipeline`] (configured by [`PipelineConfig`]), whose
//! [`FramePipeline::process`] runs one frame through [`crate::detect`], [`crate::pose`] and
//! [`crate::filter`] and returns a [`FrameReport`], whose estimate goes on to the messages,
//! [`crate::companion`]; and the reference paper's chain, [`PaperPipeline`] with its
//! [`PaperReport`].
//!
//! The firmware's vision task, the host's `touchdown companion` and `touchdown replay`, the
//! benchmarks and the no-panic and fuzz harnesses all run exactly this: what a bench or a
//! replay measures through [`FramePipeline`] is what the camera board does with the same
//! frame and the same vehicle state. Before it existed each caller wired the detector, the pad
//! scaling, the pose and the filters by hand, and the copies drifted: the host kept the pad
//! it was started with while the firmware followed TD_TAG_SIZE, and the replay scored a pose
//! and filter chain the board did not run.
//!
//! What it owns: the [`Detector`] (with its configuration), the families searched, the pad as
//! built and as currently scaled, the camera model (the detector's too: it fits long
//! boundaries through the lens, [`Detector::set_camera`]), the [`PadEstimator`] and the
//! [`PipelineSettings`] in force. What it is handed per frame: the image, its exposure time,
//! what the vehicle has told us ([`VehicleState`], which the MAVLink side keeps) and the
//! detector's frame-sized work memory ([`Buffers`], which the firmware keeps in DMA-reachable
//! RAM and the host sizes to the image). What it returns ([`FrameReport`]): the
//! [`FrameEstimate`] the MAVLink side turns into a LANDING_TARGET
//! ([`crate::companion::Companion::on_estimate`]), plus the fix and the counts a log or a
//! report wants.
//!
//! # The pad fix
//!
//! [`pad_pose_with_prediction`] fits every corner of every pad marker in view. Two optional
//! steps follow the measurement on the replay ([`PipelineConfig`]):
//!
//! - **flip by prediction**: a single small marker seen nearly head-on has two mirror poses
//!   that reproject almost equally well; the one nearer the estimator's prediction wins.
//! - **level fix** ([`PipelineConfig::level_fix`]): with the attitude at the exposure, the pad's tilt is
//!   taken from gravity instead of the image (where it is barely observable on a small
//!   marker), which removes the range bias the tilt-range coupling gives at altitude.
//!
//! # A second look where the pad was lost
//!
//! When a frame gives no fix while the last one, at most [`LOOK_AGAIN_MAX_AGE_US`] before,
//! did, the detector searches again where that fix places the pad
//! ([`Detector::detect_region`]), binarised at the ratio of the levels instead of their
//! mid-level ([`PipelineConfig::look_again`]). A hard shadow across a marker (a building's, a
//! tree's, the vehicle's own) is the case: the mid-level turns the shadowed paper along the
//! shadow's edge dark and the marker's outline stops being a quad, while the ratio keeps paper
//! and ink apart on both sides. The region is the whole pad (every marker, seen or not: a far
//! frame may have decoded only a small one) grown by half its size on every side; when that
//! is more than [`LOOK_AGAIN_MAX_FRACTION`] of the frame there is no second look, so a frame
//! costs at most that fraction more than its own search. A frame without a recent fix (and
//! every frame of a benchmark) is searched once.
//!
//! Before the fix, on a rolling-shutter camera ([`CameraModel::line_time_us`] above 0), the
//! pad's corners are moved to where the camera saw them at the frame's time, from the body
//! rates and the velocity at the exposure ([`PipelineConfig::correct_rolling_shutter`], in
//! `shutter`): both the fix and the level fix are solved on the corrected corners.
//!
//! # Settings
//!
//! [`FramePipeline::apply`] changes the detector's correction cap, the pad's scale and the
//! estimator's mount; it is meant to be called between frames (the firmware takes the settings
//! from the link task's signal before processing the next frame; the host after each received
//! MAVLink chunk). The exposure loop is not here: it drives a sensor, which the host does not
//! have. What it is fed is: [`FrameReport::metering`] (the decoded markers' levels, the
//! scene's, the motion cap), measured here so that the firmware and a replay that closes the
//! loop ([`crate::sensor::AutoExposure::update_metered`]) meter the same way.
//!
//! The reference paper's method is [`PaperPipeline`], beside this one and apart from it, so
//! that its tables can be reproduced on the same frames.

mod paper;
mod shutter;
mod view;

pub use paper::{PaperPipeline, PaperReport};
pub use view::{view_margin_m, DECODABLE_PX};

use crate::camera::CameraModel;
use crate::detect::{Buffers, DetectError, Detection, Detector, DetectorConfig};
use crate::family::Family;
use crate::filter::{
    camera_to_ned_matrix, ConfigError, EstimatorConfig, FrameEstimate, PadEstimator,
    VehicleAtExposure, VehicleState,
};
use crate::geometry::Point;
use crate::image::{GrayImage, ImageRegion};
use crate::pad::{PadError, PadLayout};
use crate::params::{ParamSet, PipelineSettings};
use crate::pose::{level_pad_fix, pad_pose_with_prediction, PadFix, Pose, MAX_FIX_MARKERS};
use crate::sensor::{motion_cap_us, pad_levels, scene_levels, Metering, SCENE_STEP};
use nalgebra::{Matrix3, Vector3};

/// Everything about the pipeline that is fixed at start-up (the tunable part is
/// [`PipelineSettings`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PipelineConfig {
    /// The detector before the settings' correction cap (e.g. [`DetectorConfig::default`], the
    /// camera's work budget).
    pub detector: DetectorConfig,
    /// The estimator's mount and trackers.
    pub estimator: EstimatorConfig,
    /// Choose between a fix's two mirror solutions by the estimator's prediction.
    pub flip_by_prediction: bool,
    /// Re-solve the fix with the tilt from the attitude at the exposure, when known.
    pub level_fix: bool,
    /// Correct the corners for the rolling shutter (the camera's turn and travel between a
    /// corner's row time and the frame's), when the camera has a line time and the body rates
    /// at the exposure are known. False solves on the corners as detected.
    pub correct_rolling_shutter: bool,
    /// Search again where a recently fixed pad was lost (see the module docs).
    pub look_again: bool,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        PipelineConfig {
            detector: DetectorConfig::default(),
            estimator: EstimatorConfig::default(),
            flip_by_prediction: true,
            level_fix: true,
            correct_rolling_shutter: true,
            look_again: true,
        }
    }
}

/// What one frame gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameReport {
    /// What the MAVLink side takes: the exposure time and the estimate at it.
    pub estimate: FrameEstimate,
    /// This frame's pad fix (levelled when the level fix ran), if the pad was found.
    pub fix: Option<PadFix>,
    /// Markers decoded in the frame (of any id, on the pad or not).
    pub markers: usize,
    /// Why detection stopped, when it did (the frame then has no fix).
    pub detect_error: Option<DetectError>,
    /// Whether the frame's own search lost a recently fixed pad and the detector searched
    /// where the pad was again (see the module docs); the detector's statistics and
    /// detections are then the second look's, and so are `fix` and `markers` when it found
    /// the pad.
    pub looked_again: bool,
    /// What the exposure loop is fed ([`crate::sensor::AutoExposure::update_metered`]): the
    /// decoded markers' white and black, the scene's mean and highlight, and the longest
    /// exposure the body rate at the exposure allows through this camera.
    pub metering: Metering,
}

/// Oldest last fix whose translation places the pad's plane for the rolling-shutter
/// correction, µs (a hover's drift over it is centimetres).
const MAX_PLANE_AGE_US: u64 = 500_000;

/// Oldest fix whose pad's place is searched again when a frame gives none, µs: at 30 Hz
/// fifteen frames, over which a hovering or descending vehicle moves the pad by less than the
/// region's margin.
pub const LOOK_AGAIN_MAX_AGE_US: u64 = 500_000;

/// Largest part of a frame the second look searches (1/2: a lost frame costs at most one and
/// a half searches).
pub const LOOK_AGAIN_MAX_FRACTION: f32 = 0.5;

/// Smallest margin around the last fix's pad, pixels: a far pad moves by more than its
/// own few pixels between frames.
const LOOK_AGAIN_MIN_MARGIN_PX: f32 = 16.0;

/// `R_ned_from_level`: the level frame of [`level_pad_fix`] (x north, y west, z up) in NED.
const NED_FROM_LEVEL: Matrix3<f32> = Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0);

/// Why settings were not all taken ([`FramePipeline::apply`]); the others were.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SettingsError {
    /// The pad could not be scaled: searched as built.
    Pad(PadError),
    /// The lens parameters make no usable camera: the built camera is used.
    Camera(crate::camera::CameraError),
}

/// The detector, the pad, the camera and the estimator, applied to one frame after another.
#[derive(Debug)]
pub struct FramePipeline<'a> {
    detector: Detector,
    config: PipelineConfig,
    families: &'a [&'a Family<'a>],
    /// The pad the pipeline was built with (TD_PAD 0).
    build_pad: PadLayout<'a>,
    /// The pad in force before TD_TAG_SIZE scales it (TD_PAD's choice).
    built_pad: PadLayout<'a>,
    pad: PadLayout<'a>,
    /// The camera the pipeline was built with (the lens parameters at 0).
    build_camera: CameraModel,
    camera: CameraModel,
    settings: PipelineSettings,
    estimator: PadEstimator,
    /// The rotation of the last fix (pad to camera), to turn the estimator's prediction of the
    /// pad's position into one of the camera's position in the pad frame.
    last_rotation: Option<Matrix3<f32>>,
    /// The exposure time of the last fix and its translation (the pad in the camera frame):
    /// the pad's plane for the rolling-shutter correction while the estimator has no
    /// prediction (its tracks are confirmed only after a few fixes), and with the rotation
    /// where a frame that lost the pad looks again.
    last_translation: Option<(u64, Vector3<f32>)>,
}

/// The smallest axis-aligned box around some image points, pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PixelBox {
    min: Point,
    max: Point,
}

impl PixelBox {
    /// Around every marker of `pad` as `pose` (pad to camera) shows it through `camera`,
    /// seen or not (a far frame may have decoded only one small marker, and the one it lost
    /// is another); `None` if none projects. Each marker counts as the square around its
    /// circumscribed circle, whatever its turn on the pad.
    fn around_pad(pose: &Pose, pad: &PadLayout<'_>, camera: &CameraModel) -> Option<Self> {
        const SIGNS: [(f32, f32); 4] = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
        pad.markers()
            .iter()
            .flat_map(|m| {
                let reach = m.size * core::f32::consts::FRAC_1_SQRT_2;
                SIGNS.map(|(sx, sy)| Vector3::new(m.x + sx * reach, m.y + sy * reach, 0.0))
            })
            .filter_map(|corner| camera.project(&pose.transform(&corner)))
            .fold(None, |bounds: Option<PixelBox>, p| {
                Some(match bounds {
                    None => PixelBox { min: p, max: p },
                    Some(b) => PixelBox {
                        min: Point::new(b.min.x.min(p.x), b.min.y.min(p.y)),
                        max: Point::new(b.max.x.max(p.x), b.max.y.max(p.y)),
                    },
                })
            })
    }

    /// This box grown by half its larger side (at least [`LOOK_AGAIN_MIN_MARGIN_PX`]) on
    /// every side and cut to a `width` x `height` frame, in whole pixels; `None` when that is
    /// more than [`LOOK_AGAIN_MAX_FRACTION`] of the frame or nothing of it is inside.
    fn look_again_region(&self, width: usize, height: usize) -> Option<ImageRegion> {
        let size = (self.max.x - self.min.x).max(self.max.y - self.min.y);
        let margin = (0.5 * size).max(LOOK_AGAIN_MIN_MARGIN_PX);
        let clamp = |v: f32, end: usize| {
            if v.is_nan() {
                0
            } else {
                (v.max(0.0) as usize).min(end)
            }
        };
        let (x0, y0) = (
            clamp(self.min.x - margin, width),
            clamp(self.min.y - margin, height),
        );
        let x1 = clamp(self.max.x + margin + 1.0, width);
        let y1 = clamp(self.max.y + margin + 1.0, height);
        let region = ImageRegion {
            x: x0,
            y: y0,
            width: x1.saturating_sub(x0),
            height: y1.saturating_sub(y0),
        };
        let frame = (width * height) as f32;
        let small_enough = (region.width * region.height) as f32 <= LOOK_AGAIN_MAX_FRACTION * frame;
        (region.width > 0 && region.height > 0 && small_enough).then_some(region)
    }
}

/// What a frame's detections gave.
struct Found {
    /// Markers decoded (of any id, on the pad or not).
    markers: usize,
    /// The fix from the image alone, kept for the mount calibration (it needs the tilt the
    /// image measured; the levelled fix's is the attitude's).
    image_fix: Option<PadFix>,
    /// The fix passed on: levelled when the level fix ran.
    fix: Option<PadFix>,
    /// The markers' levels where the detector saw them (before any correction).
    pad: Option<crate::sensor::PadLevels>,
    /// Why detection stopped, when it did.
    error: Option<DetectError>,
}

impl Found {
    fn error(error: DetectError) -> Self {
        Found {
            markers: 0,
            image_fix: None,
            fix: None,
            pad: None,
            error: Some(error),
        }
    }
}

/// What the fixes of a frame's detections are made with: the pad, the camera and the vehicle
/// state at the exposure.
struct Fixes<'f, 'a> {
    families: &'a [&'a Family<'a>],
    pad: &'f PadLayout<'a>,
    camera: &'f CameraModel,
    readout_motion: Option<&'f shutter::ReadoutMotion>,
    camera_from_level: Option<&'f Matrix3<f32>>,
    predicted: Option<&'f Vector3<f32>>,
}

impl Fixes<'_, '_> {
    /// The pad fixes from `raw`, the detections in `image`.
    fn found_in(&self, image: &GrayImage<'_>, raw: &[Detection]) -> Found {
        let (families, pad, camera) = (self.families, self.pad, self.camera);
        // The pad's markers as a global shutter would have seen them (both fixes solve on
        // these); the count reported is the detector's.
        let mut corrected = heapless::Vec::<Detection, MAX_FIX_MARKERS>::new();
        let detections = match self.readout_motion {
            Some(motion) => {
                shutter::correct_pad_detections(raw, families, pad, camera, motion, &mut corrected);
                &corrected[..]
            }
            None => raw,
        };
        let image_fix =
            pad_pose_with_prediction(detections, families, pad, camera, self.predicted).ok();
        // The level fix falls back to the image's own fix when it cannot be solved.
        let fix = image_fix.map(|fix| match self.camera_from_level {
            Some(c) => level_pad_fix(&fix, detections, families, pad, camera, c).unwrap_or(fix),
            None => fix,
        });
        Found {
            markers: raw.len(),
            image_fix,
            fix,
            pad: pad_levels(image, raw, families),
            error: None,
        }
    }
}

impl<'a> FramePipeline<'a> {
    /// A pipeline searching `families` for `built_pad` through `camera`, configured as
    /// `config` and then `settings` applied. When the pad cannot be scaled as `settings` ask
    /// (only an empty pad cannot), it is searched as built. Fails when a tracker configuration
    /// is invalid.
    pub fn new(
        families: &'a [&'a Family<'a>],
        built_pad: &PadLayout<'a>,
        camera: CameraModel,
        config: PipelineConfig,
        settings: PipelineSettings,
    ) -> Result<Self, ConfigError> {
        let estimator = PadEstimator::new(config.estimator)?;
        Ok(Self::with_estimator(
            families, built_pad, camera, config, estimator, settings,
        ))
    }

    /// [`FramePipeline::new`] with the estimator built (and its configuration checked) by the
    /// caller; `config.estimator` is not read. Infallible, so the pipeline (tens of KiB: the
    /// detector's contour buffer) can be built straight into its final place: the firmware's
    /// vision task does: built through `new`'s `Result` (and an `Option`), the stack's
    /// high-water mark was 53,464 bytes against 32,256 this way (scripts/emu_boot.sh).
    pub fn with_estimator(
        families: &'a [&'a Family<'a>],
        built_pad: &PadLayout<'a>,
        camera: CameraModel,
        config: PipelineConfig,
        estimator: PadEstimator,
        settings: PipelineSettings,
    ) -> Self {
        let mut pipeline = FramePipeline {
            detector: Detector::new(config.detector),
            config,
            families,
            build_pad: *built_pad,
            built_pad: *built_pad,
            pad: *built_pad,
            build_camera: camera,
            camera,
            settings,
            estimator,
            last_rotation: None,
            last_translation: None,
        };
        // The detector fits long boundaries through the same lens as the pose (a
        // distortion-free camera leaves it as without one), so that what a replay or a bench
        // measures is what the board runs. Set in place, not on a local detector moved in
        // after: the detector is tens of KiB, and the firmware's stack is measured.
        pipeline.detector.set_camera(Some(camera));
        // The error is kept in the pad (as built); `apply` reports it to callers that ask.
        let _ = pipeline.apply(settings);
        pipeline
    }

    /// Takes new settings (call between frames): the detector's correction cap, the pad
    /// scaled to TD_TAG_SIZE, the whole mount (turned by TD_CAM_YAW, tilted by TD_CAM_ROLL
    /// and TD_CAM_PITCH: [`PipelineSettings::mount`]; a changed yaw restarts the estimator, a
    /// changed tilt does not, see [`PadEstimator::set_mount`]) and whether the mount is
    /// calibrated in flight (TD_CAM_CAL), the lens (TD_CAM_FX ... TD_CAM_K3, over the camera
    /// the pipeline was built with: [`PipelineSettings::camera`]; a changed lens restarts the
    /// estimator, whose tracks were measured through the other one) and the pad's design
    /// (TD_PAD). If the lens makes no usable camera, the built camera is used and the error
    /// returned; if the pad cannot be scaled, the pad as built is searched and the error
    /// returned; the other settings apply either way.
    pub fn apply(&mut self, settings: PipelineSettings) -> Result<(), SettingsError> {
        self.settings = settings;
        let (camera, camera_result) = match settings.camera(&self.build_camera) {
            Ok(camera) => (camera, Ok(())),
            Err(e) => (self.build_camera, Err(SettingsError::Camera(e))),
        };
        if camera != self.camera {
            self.camera = camera;
            self.detector.set_camera(Some(camera));
            self.reset();
        }
        self.built_pad = settings.built_pad(&self.build_pad);
        self.detector
            .set_config(settings.detector_config(self.config.detector));
        self.estimator.set_mount(
            settings.cam_yaw_deg,
            settings.cam_roll_deg,
            settings.cam_pitch_deg,
        );
        self.estimator
            .set_mount_calibration(settings.mount_calibration.estimates());
        match settings.pad(&self.built_pad) {
            Ok(pad) => {
                self.pad = pad;
                camera_result
            }
            Err(e) => {
                self.pad = self.built_pad;
                Err(SettingsError::Pad(e))
            }
        }
    }

    /// Follows the parameters (call between frames): takes their settings
    /// ([`PipelineSettings::from_params`]) when they differ from the ones it runs with, and
    /// says whether they did (`Ok(true)`), so that every caller that holds the parameters
    /// itself (the host's companion, replay and sitl loops) hands them over the same way.
    /// The firmware does not call this: its link task owns the parameters and sends the
    /// settings to the vision task, which calls [`FramePipeline::apply`].
    pub fn follow_params(&mut self, params: &ParamSet) -> Result<bool, SettingsError> {
        let settings = PipelineSettings::from_params(params);
        if settings == self.settings {
            return Ok(false);
        }
        self.apply(settings).map(|()| true)
    }

    /// Forgets the tracks: the next frame starts a new, independent sequence.
    pub fn reset(&mut self) {
        self.estimator.reset();
        self.last_rotation = None;
        self.last_translation = None;
    }

    /// Finds the pad in `image`, exposed at `exposure_us` (our clock, µs), and estimates it
    /// with `vehicle`'s state at that time, using `buffers` as the detector's work memory.
    pub fn process(
        &mut self,
        image: &GrayImage<'_>,
        exposure_us: u64,
        vehicle: &VehicleState,
        buffers: &mut Buffers<'_>,
    ) -> FrameReport {
        // The vehicle state is read once, at the exposure, for every step that needs it.
        let at_exposure = vehicle.at(exposure_us);
        // The prediction is of use with a last fix's rotation, to the flip choice or (as the
        // pad's plane) to the rolling-shutter correction.
        let wants_prediction = self.config.flip_by_prediction
            || (self.config.correct_rolling_shutter && self.camera.line_time_us > 0.0);
        let pad_in_camera = (wants_prediction && self.last_rotation.is_some())
            .then(|| self.estimator.predicted_in_camera(&at_exposure))
            .flatten();
        let predicted = self.predicted_camera_position(pad_in_camera.as_ref());
        let camera_from_level = at_exposure
            .attitude
            .as_ref()
            .filter(|_| self.config.level_fix)
            .map(|att| {
                camera_to_ned_matrix(att, self.estimator.mount()).transpose() * NED_FROM_LEVEL
            });
        let readout_motion = self.readout_motion(
            &at_exposure,
            pad_in_camera.as_ref(),
            camera_from_level.as_ref(),
        );
        let fixes = Fixes {
            families: self.families,
            pad: &self.pad,
            camera: &self.camera,
            readout_motion: readout_motion.as_ref(),
            camera_from_level: camera_from_level.as_ref(),
            predicted: predicted.as_ref(),
        };
        let mut found = match self.detector.detect(image, self.families, buffers) {
            Ok(raw) => fixes.found_in(image, raw),
            Err(e) => Found::error(e),
        };
        // A second look where the last fix, if recent, placed the pad (see the module docs):
        // the region is worked out only for a frame that lost the pad.
        let lost = self.config.look_again && found.fix.is_none() && found.error.is_none();
        let region = match (self.last_rotation, self.last_translation) {
            (Some(rotation), Some((t_us, translation)))
                if lost && exposure_us.abs_diff(t_us) <= LOOK_AGAIN_MAX_AGE_US =>
            {
                let last = Pose {
                    rotation,
                    translation,
                };
                PixelBox::around_pad(&last, &self.pad, &self.camera)
                    .and_then(|pad| pad.look_again_region(image.width(), image.height()))
            }
            _ => None,
        };
        let looked_again = region.is_some();
        if let Some(region) = region {
            if let Ok(raw) = self
                .detector
                .detect_region(image, &region, self.families, buffers)
            {
                let again = fixes.found_in(image, raw);
                if again.fix.is_some() {
                    found = again;
                }
            }
        }
        let Found {
            markers,
            image_fix,
            fix,
            pad,
            error: detect_error,
        } = found;
        if let Some(f) = &fix {
            self.last_rotation = Some(f.pose.rotation);
            self.last_translation = Some((exposure_us, f.pose.translation));
        }
        let (mean, highlight) = scene_levels(image, SCENE_STEP);
        let max_exposure_us = at_exposure
            .body_rate
            .and_then(|w| motion_cap_us(w.norm(), self.camera.fx.max(self.camera.fy)));
        let mut estimate =
            self.estimator
                .update_with_image_fix(fix.as_ref(), image_fix.as_ref(), &at_exposure);
        if let (Some(e), Some(f), true) = (
            estimate.estimate.as_mut(),
            image_fix.as_ref(),
            self.settings.view_margin,
        ) {
            e.view_margin_m = view::view_margin_m(&f.pose, &self.pad, &self.camera);
        }
        FrameReport {
            estimate,
            fix,
            markers,
            detect_error,
            looked_again,
            metering: Metering {
                mean,
                highlight,
                pad,
                max_exposure_us,
            },
        }
    }

    /// The camera's position in the pad frame that the estimator predicts at the exposure, for
    /// the flip choice: its predicted pad position (`pad_in_camera`, camera frame) turned with
    /// the last fix's rotation. `None` when the step is off or there is no track.
    fn predicted_camera_position(
        &self,
        pad_in_camera: Option<&Vector3<f32>>,
    ) -> Option<Vector3<f32>> {
        if !self.config.flip_by_prediction {
            return None;
        }
        let rotation = self.last_rotation?;
        Some(-(rotation.transpose() * pad_in_camera?))
    }

    /// How the camera moves over this frame's readout, for the rolling-shutter correction:
    /// the body rates through the mount and, with the attitude at the exposure, the NED
    /// velocity in the camera's axes, over the pad's plane as predicted (the estimator's pad
    /// position in the camera frame, `pad_in_camera`, and the plane's normal: up in the
    /// camera frame when the level fix runs, `camera_from_level`, as it assumes a level pad;
    /// else the last fix's; without a prediction, the last fix's translation if at most
    /// [`MAX_PLANE_AGE_US`] old). `None` when the correction is off, the camera has a global
    /// shutter or the body rates are unknown; without the attitude, the velocity or a plane
    /// only the rotation is corrected.
    fn readout_motion(
        &self,
        vehicle: &VehicleAtExposure,
        pad_in_camera: Option<&Vector3<f32>>,
        camera_from_level: Option<&Matrix3<f32>>,
    ) -> Option<shutter::ReadoutMotion> {
        if !(self.config.correct_rolling_shutter && self.camera.line_time_us > 0.0) {
            return None;
        }
        let mount = self.estimator.mount();
        let rate = mount.body_to_camera(&vehicle.body_rate?);
        // Against the pad: the level track's where there is one (a pad that moves too), else
        // the vehicle's over the ground (a pad at rest).
        let against_pad = self
            .estimator
            .velocity_against_pad(vehicle.t_us)
            .or_else(|| vehicle.position.as_ref().map(|p| p.velocity));
        let velocity = vehicle
            .attitude
            .as_ref()
            .zip(against_pad)
            .map(|(att, v)| camera_to_ned_matrix(att, mount).transpose() * v);
        let normal = camera_from_level
            .or(self.last_rotation.as_ref())
            // The third column, as a product: a column view's `into_owned` keeps a panic
            // path (nopanic/).
            .map(|r| r * Vector3::z());
        // Without a prediction, the last fix, if recent: the camera has moved a few
        // centimetres since, a fraction of a percent of the depth.
        let recent_fix = self
            .last_translation
            .as_ref()
            .and_then(|(t_us, p)| (vehicle.t_us.abs_diff(*t_us) <= MAX_PLANE_AGE_US).then_some(p));
        let plane = pad_in_camera
            .or(recent_fix)
            .zip(normal)
            .and_then(|(p, n)| shutter::PadPlane::through(p, &n));
        shutter::ReadoutMotion::new(&self.camera, rate, velocity, plane)
    }

    /// The settings in force.
    pub fn settings(&self) -> &PipelineSettings {
        &self.settings
    }

    /// The start-up configuration.
    pub fn config(&self) -> &PipelineConfig {
        &self.config
    }

    /// The pad searched for (scaled to TD_TAG_SIZE).
    pub fn pad(&self) -> &PadLayout<'a> {
        &self.pad
    }

    /// The pad as built, or the design TD_PAD chose (what TD_TAG_SIZE scales).
    pub fn built_pad(&self) -> &PadLayout<'a> {
        &self.built_pad
    }

    /// The camera model in force (the built one, or the lens parameters').
    pub fn camera(&self) -> &CameraModel {
        &self.camera
    }

    /// The detector (its configuration, and its statistics and detections of the last search:
    /// the frame's own, or the second look's, [`FrameReport::looked_again`]).
    pub fn detector(&self) -> &Detector {
        &self.detector
    }

    /// The estimator (its mount in force).
    pub fn estimator(&self) -> &PadEstimator {
        &self.estimator
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::family::tables;
    use crate::pad::designs;
    use crate::params::{ParamId, ParamSet};

    #[test]
    fn the_second_look_searches_around_the_pad_within_half_the_frame() {
        let boxed = |x0, y0, x1, y1| PixelBox {
            min: Point::new(x0, y0),
            max: Point::new(x1, y1),
        };
        let region = |x, y, width, height| {
            Some(ImageRegion {
                x,
                y,
                width,
                height,
            })
        };
        // A 40 x 20 pad at (100, 100): grown by 20 px each way.
        let found = boxed(100.0, 100.0, 140.0, 120.0).look_again_region(320, 240);
        assert_eq!(found, region(80, 80, 81, 61));
        // A far pad of 6 px: at least LOOK_AGAIN_MIN_MARGIN_PX; cut at the frame's edge.
        let found = boxed(2.0, 230.0, 8.0, 236.0).look_again_region(320, 240);
        assert_eq!(found, region(0, 214, 25, 26));
        // Grown past half the frame: no second look; a box off the frame or not a number:
        // none either.
        assert_eq!(
            boxed(60.0, 40.0, 260.0, 200.0).look_again_region(320, 240),
            None
        );
        assert_eq!(
            boxed(400.0, 10.0, 420.0, 30.0).look_again_region(320, 240),
            None
        );
        let nan = boxed(f32::NAN, 10.0, 20.0, f32::NAN).look_again_region(320, 240);
        assert!(nan.is_none_or(|r| r.width * r.height <= 320 * 240 / 2));
    }

    /// The firmware's set-up: the default families, the nested pad, a QVGA pinhole camera.
    fn nested_pipeline() -> FramePipeline<'static> {
        FramePipeline::new(
            tables::DEFAULT,
            &designs::NESTED,
            CameraModel::pinhole(320, 240, 233.5, 233.5, 159.5, 119.5),
            PipelineConfig::default(),
            PipelineSettings::default(),
        )
        .unwrap()
    }

    #[test]
    fn settings_scale_the_pad_and_cap_the_correction() {
        let mut pipeline = nested_pipeline();
        assert_eq!(*pipeline.pad(), designs::NESTED);
        assert_eq!(pipeline.detector().config().max_hamming, 1);

        let mut params = ParamSet::default();
        params.set(ParamId::TagSize, 0.625).unwrap();
        params.set(ParamId::MaxHamming, 0.0).unwrap();
        assert_eq!(
            pipeline.apply(PipelineSettings::from_params(&params)),
            Ok(())
        );
        // The nested pad's largest marker is 1.25 m: everything at half size.
        let (built, scaled) = (&designs::NESTED.markers()[1], &pipeline.pad().markers()[1]);
        assert_eq!(scaled.size, built.size * 0.5);
        assert_eq!(scaled.x, built.x * 0.5);
        assert_eq!(pipeline.detector().config().max_hamming, 0);
        // Back to the pad as built.
        assert_eq!(pipeline.apply(PipelineSettings::default()), Ok(()));
        assert_eq!(*pipeline.pad(), designs::NESTED);
        assert_eq!(*pipeline.built_pad(), designs::NESTED);
    }

    #[test]
    fn the_lens_and_pad_parameters_replace_the_build_s() {
        let mut pipeline = nested_pipeline();
        let built = *pipeline.camera();
        let mut params = ParamSet::default();
        // Half a lens: the focal lengths set, the principal point still the build's.
        params.set(ParamId::CamFx, 300.0).unwrap();
        params.set(ParamId::CamFy, 301.0).unwrap();
        params.set(ParamId::CamK1, -0.2).unwrap();
        params.set(ParamId::CamK2, 0.05).unwrap();
        params.set(ParamId::Pad, 3.0).unwrap();
        params.set(ParamId::TagSize, 0.625).unwrap();
        assert_eq!(pipeline.follow_params(&params), Ok(true));
        let camera = *pipeline.camera();
        assert_eq!(
            (camera.fx, camera.fy, camera.cx, camera.cy),
            (300.0, 301.0, 159.5, 119.5)
        );
        assert_eq!(camera.distortion, [-0.2, 0.05, 0.0, 0.0, 0.0]);
        assert_eq!((camera.width, camera.height), (built.width, built.height));
        // TD_PAD 3: the shipped `nested`, scaled by TD_TAG_SIZE as a built pad is.
        assert_eq!(*pipeline.built_pad(), designs::NESTED);
        params.set(ParamId::Pad, 1.0).unwrap();
        assert_eq!(pipeline.follow_params(&params), Ok(true));
        assert_eq!(*pipeline.built_pad(), designs::NESTED_FIELD);
        assert_eq!(pipeline.pad().name(), "nested-field");
        assert_eq!(pipeline.pad().markers()[0].size, 0.625);
        // A principal point off the frame makes no camera: the build's, and the error.
        params.set(ParamId::CamCx, 5000.0).unwrap();
        assert!(matches!(
            pipeline.follow_params(&params),
            Err(SettingsError::Camera(_))
        ));
        assert_eq!(*pipeline.camera(), built);
        // All back at 0: the build's lens and pad.
        assert_eq!(pipeline.apply(PipelineSettings::default()), Ok(()));
        assert_eq!(*pipeline.camera(), built);
        assert_eq!(*pipeline.built_pad(), designs::NESTED);
    }

    #[test]
    fn following_the_parameters_applies_only_a_change() {
        let mut pipeline = nested_pipeline();
        let mut params = ParamSet::default();
        assert_eq!(pipeline.follow_params(&params), Ok(false));
        params.set(ParamId::MaxHamming, 0.0).unwrap();
        assert_eq!(pipeline.follow_params(&params), Ok(true));
        assert_eq!(pipeline.detector().config().max_hamming, 0);
        assert_eq!(pipeline.follow_params(&params), Ok(false));
        params.set(ParamId::TagSize, 0.625).unwrap();
        assert_eq!(pipeline.follow_params(&params), Ok(true));
        let largest = pipeline
            .pad()
            .markers()
            .iter()
            .map(|m| m.size)
            .fold(0.0, f32::max);
        assert_eq!(largest, 0.625);
        assert_eq!(pipeline.follow_params(&params), Ok(false));
    }

    #[test]
    fn a_blank_frame_has_no_fix_and_keeps_its_time() {
        let mut pipeline = nested_pipeline();
        let pixels = [200u8; 320 * 240];
        let image = GrayImage::new(&pixels, 320, 240).unwrap();
        let mut workspace = crate::detect::QvgaWorkspace::new();
        let report = pipeline.process(
            &image,
            123_456,
            &VehicleState::new(),
            &mut workspace.buffers(),
        );
        assert_eq!(report.estimate.exposure_us, 123_456);
        assert_eq!((report.fix, report.estimate.estimate), (None, None));
        assert!(!report.estimate.fix_found);
        assert_eq!((report.markers, report.detect_error), (0, None));
    }
}
