//! The per-frame path's parameters, turned into the settings [`crate::pipeline`] applies.
//!
//! Four groups of MAVLink parameters tune what happens between a frame and its estimate:
//! TD_MAX_HAMMING (the decoder's correction cap), TD_TAG_SIZE (the printed size of the pad),
//! the mount (TD_CAM_YAW, TD_CAM_ROLL, TD_CAM_PITCH: see [`PipelineSettings::mount`]; and
//! TD_CAM_CAL, whether the estimator calibrates it in flight) and
//! TD_EXP_MAX_US / TD_GAIN_MAX / TD_EXP_TARGET (the software auto-exposure's limits, see
//! [`crate::sensor::exposure`]). The MAVLink side ([`crate::companion::Companion`]) owns the
//! [`ParamSet`], but the detector, the pad layout, the estimator and the exposure loop live
//! with the camera (a separate task in the firmware). [`PipelineSettings::from_params`] is the
//! one place that converts: the firmware's link task calls it whenever the parameters change
//! and hands the result to the vision task, which applies it between frames
//! ([`crate::pipeline::FramePipeline::apply`]); the host's `touchdown companion` does the same
//! after every received chunk.
//!
//! Why here and not in `detect`, `pad` or `sensor`: those modules know nothing of MAVLink
//! parameter names and should not; the dependency points from the parameter table to them.
//!
//! # TD_TAG_SIZE
//!
//! A pad is built into the firmware (a single marker or several nested ones, see
//! [`crate::pad::designs`]), but users print it at whatever size their printer or field
//! allows. TD_TAG_SIZE is the edge of the pad's **largest** marker as printed; the whole
//! layout (every marker's size and position) is scaled by `TD_TAG_SIZE / built size`, which
//! is exactly what printing the pad at another scale does. For a single-marker pad it is
//! simply that marker's edge. 0 (the default) keeps the pad as built, so a build whose pad
//! matches the print needs no parameter.
//!
//! # The lens and the pad design (TD_CAM_FX ... TD_CAM_K3, TD_PAD)
//!
//! A builder who changes the lens, or prints another shipped pad, should not have to rebuild
//! the firmware: the lens's intrinsics and distortion and the choice of design are
//! parameters, saved and restored with the others. Each of TD_CAM_FX, TD_CAM_FY, TD_CAM_CX and
//! TD_CAM_CY left at 0 keeps the build's value, so a board runs with the build's lens until
//! they are set, and a ground station writing them one by one never gives the pipeline half a
//! camera; the distortion replaces the build's as soon as any coefficient is set. The frame
//! size is the build's: the values are in pixels of the board's frames, as `touchdown view
//! --record` records them at full resolution.

use super::{ParamId, ParamSet};
use crate::camera::{CameraError, CameraModel};
use crate::detect::DetectorConfig;
use crate::filter::{CameraMount, MountCalibrationMode};
use crate::pad::{PadError, PadLayout, PadMarker, MAX_PAD_MARKERS};
use crate::sensor::AutoExposureLimits;
use crate::sensor::GainX16;

/// What the per-frame path takes from the parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PipelineSettings {
    /// Upper bound on corrected bits per marker (each family's own bound applies too).
    pub max_hamming: u8,
    /// Edge of the pad's largest marker as printed, metres; `None`: the pad as built.
    pub tag_size_m: Option<f32>,
    /// The auto-exposure's limits and target.
    pub exposure: AutoExposureLimits,
    /// The camera's turn about its optical axis from the built mount, degrees (TD_CAM_YAW).
    pub cam_yaw_deg: f32,
    /// The mount's roll about body x after the yaw, degrees (TD_CAM_ROLL).
    pub cam_roll_deg: f32,
    /// The mount's pitch about body y after the roll, degrees (TD_CAM_PITCH).
    pub cam_pitch_deg: f32,
    /// The in-flight mount calibration (TD_CAM_CAL).
    pub mount_calibration: MountCalibrationMode,
    /// Each frame's view margin is worked out (`crate::pipeline::view_margin_m`): only the
    /// vision estimates carry it (TD_VPE_EN bit 0), so the per-frame path spends nothing on it
    /// otherwise.
    pub view_margin: bool,
    /// The lens parameters as set (TD_CAM_FX ... TD_CAM_K3; see [`PipelineSettings::camera`]).
    pub lens: LensSettings,
    /// The pad searched for (TD_PAD): 0 the build's, 1 nested-field, 2 nested-rest, 3
    /// nested, 4 paper-single ([`PipelineSettings::built_pad`]).
    pub pad_design: u8,
}

/// The lens parameters as set: 0 for each intrinsic the build's value stands for.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LensSettings {
    /// TD_CAM_FX, pixels.
    pub fx: f32,
    /// TD_CAM_FY, pixels.
    pub fy: f32,
    /// TD_CAM_CX, pixels.
    pub cx: f32,
    /// TD_CAM_CY, pixels.
    pub cy: f32,
    /// TD_CAM_K1, TD_CAM_K2, TD_CAM_P1, TD_CAM_P2, TD_CAM_K3.
    pub distortion: [f32; 5],
}

/// The shipped designs TD_PAD 1 to 4 choose, in that order.
pub const PAD_DESIGNS: [&PadLayout<'static>; 4] = [
    &crate::pad::designs::NESTED_FIELD,
    &crate::pad::designs::NESTED_REST,
    &crate::pad::designs::NESTED,
    &crate::pad::designs::PAPER_SINGLE,
];

/// TD_VPE_EN bit 0: VISION_POSITION_ESTIMATE (and with it the view margin).
pub const VPE_POSITION: i32 = 1;
/// TD_VPE_EN bit 1: the vehicle's velocity.
pub const VPE_VELOCITY: i32 = 2;

impl Default for PipelineSettings {
    /// The settings of the default parameters.
    fn default() -> Self {
        PipelineSettings::from_params(&ParamSet::default())
    }
}

impl PipelineSettings {
    /// The settings `params` ask for. Every value was range-checked when it was set, so this
    /// only converts units; the exposure loop's deadband is not a parameter and keeps
    /// [`AutoExposureLimits::default`]'s.
    pub fn from_params(params: &ParamSet) -> Self {
        let built = AutoExposureLimits::default();
        let tag_size = params.get(ParamId::TagSize);
        // The gain parameter is in times, the sensor's unit is sixteenths.
        let gain_x16 = libm::roundf(params.get(ParamId::GainMax) * 16.0);
        PipelineSettings {
            max_hamming: u8::try_from(params.get_int(ParamId::MaxHamming)).unwrap_or(0),
            tag_size_m: (tag_size > 0.0).then_some(tag_size),
            exposure: AutoExposureLimits {
                target: u8::try_from(params.get_int(ParamId::ExpTarget)).unwrap_or(built.target),
                deadband: built.deadband,
                max_exposure_us: u32::try_from(params.get_int(ParamId::ExpMaxUs))
                    .unwrap_or(built.max_exposure_us),
                // `as` saturates; the parameter's range keeps it within 16..=512 anyway.
                max_gain: GainX16((gain_x16 as u16).max(GainX16::ONE.0)),
            },
            cam_yaw_deg: params.get(ParamId::CamYaw),
            cam_roll_deg: params.get(ParamId::CamRoll),
            cam_pitch_deg: params.get(ParamId::CamPitch),
            mount_calibration: MountCalibrationMode::from_param(params.get_int(ParamId::CamCal)),
            view_margin: params.get_int(ParamId::VpeEnable) & VPE_POSITION != 0,
            lens: LensSettings {
                fx: params.get(ParamId::CamFx),
                fy: params.get(ParamId::CamFy),
                cx: params.get(ParamId::CamCx),
                cy: params.get(ParamId::CamCy),
                distortion: [
                    params.get(ParamId::CamK1),
                    params.get(ParamId::CamK2),
                    params.get(ParamId::CamP1),
                    params.get(ParamId::CamP2),
                    params.get(ParamId::CamK3),
                ],
            },
            pad_design: u8::try_from(params.get_int(ParamId::Pad)).unwrap_or(0),
        }
    }

    /// The camera in force for the `built` one: each intrinsic the lens parameters set (not
    /// 0) replaces the build's, the distortion replaces the build's when any coefficient is
    /// set; the frame size and line time stay the build's. An error when the result is not a
    /// usable camera ([`CameraModel::validate`]: e.g. a principal point off the frame).
    pub fn camera(&self, built: &CameraModel) -> Result<CameraModel, CameraError> {
        let l = &self.lens;
        let or_built = |set: f32, built: f32| if set != 0.0 { set } else { built };
        let camera = CameraModel {
            fx: or_built(l.fx, built.fx),
            fy: or_built(l.fy, built.fy),
            cx: or_built(l.cx, built.cx),
            cy: or_built(l.cy, built.cy),
            distortion: if l.distortion.iter().any(|&k| k != 0.0) {
                l.distortion
            } else {
                built.distortion
            },
            ..*built
        };
        camera.validate().map(|()| camera)
    }

    /// The pad searched for before TD_TAG_SIZE scales it: `build`'s own, or the shipped design
    /// TD_PAD names ([`PAD_DESIGNS`]).
    pub fn built_pad<'a>(&self, build: &PadLayout<'a>) -> PadLayout<'a> {
        match usize::from(self.pad_design)
            .checked_sub(1)
            .and_then(|i| PAD_DESIGNS.get(i))
        {
            Some(design) => **design,
            None => *build,
        }
    }

    /// The mount in force for the `configured` one (the build's, camera to body): turned by
    /// TD_CAM_YAW about the optical axis, then by TD_CAM_ROLL about body x, then by
    /// TD_CAM_PITCH about body y: camera-to-body = `R_y(pitch) R_x(roll) configured
    /// R_z(yaw)`, the simulator's misaligned mount `R_y(pitch) R_x(roll) nominal` for a
    /// yaw of 0 ([`CameraMount::turned_about_optical_axis`], [`CameraMount::tilted`]).
    pub fn mount(&self, configured: &CameraMount) -> CameraMount {
        configured
            .turned_about_optical_axis(self.cam_yaw_deg)
            .tilted(self.cam_roll_deg, self.cam_pitch_deg)
    }

    /// `base` with these settings' correction cap.
    pub fn detector_config(&self, base: DetectorConfig) -> DetectorConfig {
        DetectorConfig {
            max_hamming: self.max_hamming,
            ..base
        }
    }

    /// The factor the built pad is scaled by (1 when TD_TAG_SIZE is unset).
    pub fn pad_scale(&self, built: &PadLayout<'_>) -> f32 {
        match self.tag_size_m {
            Some(size) => size / largest_marker_size(built),
            None => 1.0,
        }
    }

    /// The pad to search for: `built` as is, or scaled so its largest marker is
    /// TD_TAG_SIZE. An error only for a layout that cannot be scaled (empty).
    pub fn pad<'a>(&self, built: &PadLayout<'a>) -> Result<PadLayout<'a>, PadError> {
        match self.tag_size_m {
            Some(_) => scale_pad(built, self.pad_scale(built)),
            None => Ok(*built),
        }
    }
}

/// Edge of the largest marker of `layout`, metres (0 for an empty layout).
pub fn largest_marker_size(layout: &PadLayout<'_>) -> f32 {
    layout.markers().iter().map(|m| m.size).fold(0.0, f32::max)
}

/// `layout` with every marker's size and position multiplied by `factor` (names, families,
/// ids and yaw unchanged). A factor that is not finite and positive gives
/// [`PadError::BadSize`], an empty layout [`PadError::Empty`].
pub fn scale_pad<'a>(layout: &PadLayout<'a>, factor: f32) -> Result<PadLayout<'a>, PadError> {
    let mut markers = [PadMarker::EMPTY; MAX_PAD_MARKERS];
    let mut len = 0;
    for (dst, src) in markers.iter_mut().zip(layout.markers()) {
        *dst = PadMarker {
            size: src.size * factor,
            x: src.x * factor,
            y: src.y * factor,
            ..*src
        };
        len += 1;
    }
    if !(factor.is_finite() && factor > 0.0) && len > 0 {
        return Err(PadError::BadSize { index: 0 });
    }
    PadLayout::new(layout.name(), markers.get(..len).unwrap_or(&[]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pad::designs;

    #[test]
    fn default_parameters_give_the_compile_time_defaults() {
        let s = PipelineSettings::default();
        assert_eq!(s, PipelineSettings::from_params(&ParamSet::default()));
        assert_eq!(s.exposure, AutoExposureLimits::default());
        assert_eq!(s.tag_size_m, None);
        assert_eq!(s.max_hamming, 1);
        // Every shipped pad is used as built.
        for pad in designs::ALL {
            assert_eq!(s.pad(pad), Ok(*pad));
            assert_eq!(s.pad_scale(pad), 1.0);
        }
        // Only the correction cap differs from the detector's own default.
        let base = DetectorConfig::default();
        assert_eq!(
            s.detector_config(base),
            DetectorConfig {
                max_hamming: 1,
                ..base
            }
        );
    }

    #[test]
    fn each_parameter_changes_its_setting() {
        let mut p = ParamSet::default();
        p.set(ParamId::MaxHamming, 3.0).unwrap();
        assert_eq!(PipelineSettings::from_params(&p).max_hamming, 3);
        assert_eq!(
            PipelineSettings::from_params(&p)
                .detector_config(DetectorConfig::default())
                .max_hamming,
            3
        );
        p.set(ParamId::ExpMaxUs, 1_000.0).unwrap();
        p.set(ParamId::GainMax, 2.5).unwrap();
        p.set(ParamId::ExpTarget, 150.0).unwrap();
        p.set(ParamId::TagSize, 0.625).unwrap();
        let s = PipelineSettings::from_params(&p);
        assert_eq!(
            s.exposure,
            AutoExposureLimits {
                target: 150,
                deadband: AutoExposureLimits::default().deadband,
                max_exposure_us: 1_000,
                max_gain: GainX16(40),
            }
        );
        assert_eq!(s.tag_size_m, Some(0.625));
        p.set(ParamId::CamYaw, 90.0).unwrap();
        p.set(ParamId::CamRoll, 1.5).unwrap();
        p.set(ParamId::CamPitch, -1.0).unwrap();
        p.set(ParamId::CamCal, 1.0).unwrap();
        let s = PipelineSettings::from_params(&p);
        assert_eq!(s.cam_yaw_deg, 90.0);
        assert_eq!((s.cam_roll_deg, s.cam_pitch_deg), (1.5, -1.0));
        assert_eq!(s.mount_calibration, MountCalibrationMode::Report);
        // Parameters of the MAVLink side change nothing here (the velocity alone included)...
        let mut q = p;
        q.set(ParamId::RateHz, 5.0).unwrap();
        q.set(ParamId::Profile, 1.0).unwrap();
        q.set(ParamId::VpeEnable, 2.0).unwrap();
        assert_eq!(PipelineSettings::from_params(&q), s);
        assert!(!s.view_margin);
        // ...but the vision estimates, which carry the view margin.
        q.set(ParamId::VpeEnable, 1.0).unwrap();
        let with_margin = PipelineSettings::from_params(&q);
        assert!(with_margin.view_margin);
        assert_eq!(
            PipelineSettings {
                view_margin: false,
                ..with_margin
            },
            s
        );
        // Back to 0: the pad as built again.
        p.set(ParamId::TagSize, 0.0).unwrap();
        assert_eq!(PipelineSettings::from_params(&p).tag_size_m, None);
    }

    #[test]
    fn settings_stay_in_range_at_the_parameter_limits() {
        for pick_max in [false, true] {
            let mut p = ParamSet::default();
            for id in [
                ParamId::MaxHamming,
                ParamId::TagSize,
                ParamId::ExpMaxUs,
                ParamId::GainMax,
                ParamId::ExpTarget,
            ] {
                let def = id.def();
                p.set(id, if pick_max { def.max } else { def.min }).unwrap();
            }
            let s = PipelineSettings::from_params(&p);
            let e = s.exposure;
            if pick_max {
                assert_eq!(s.max_hamming, 3);
                assert_eq!(s.tag_size_m, Some(5.0));
                assert_eq!(
                    (e.max_exposure_us, e.max_gain, e.target),
                    (33_000, GainX16(512), 220)
                );
            } else {
                assert_eq!(s.max_hamming, 0);
                assert_eq!(s.tag_size_m, Some(0.02));
                assert_eq!(
                    (e.max_exposure_us, e.max_gain, e.target),
                    (100, GainX16::ONE, 40)
                );
            }
            // The deadband keeps the target band inside the grey scale.
            assert!(e.target > e.deadband && e.target.checked_add(e.deadband).is_some());
            // Every pad scales to a valid layout.
            for pad in designs::ALL {
                let scaled = s.pad(pad).unwrap();
                let largest = largest_marker_size(&scaled);
                let want = s.tag_size_m.unwrap();
                assert!((largest - want).abs() <= 1e-6 * want, "{largest} vs {want}");
            }
        }
    }

    #[test]
    fn the_mount_is_the_simulators_misaligned_mount() {
        use nalgebra::Matrix3;
        let mut p = ParamSet::default();
        p.set(ParamId::CamRoll, 1.2).unwrap();
        p.set(ParamId::CamPitch, -1.6).unwrap();
        let s = PipelineSettings::from_params(&p);
        assert_eq!(s.mount_calibration, MountCalibrationMode::Apply);
        // touchdown-sim's mount: camera-to-body = R_y(pitch) R_x(roll) nominal, nominal the
        // downward mount (camera x = body y, camera y = body -x, camera z = body z).
        let (r, q) = (1.2f32.to_radians(), (-1.6f32).to_radians());
        let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, r.cos(), -r.sin(), 0.0, r.sin(), r.cos());
        let ry = Matrix3::new(q.cos(), 0.0, q.sin(), 0.0, 1.0, 0.0, -q.sin(), 0.0, q.cos());
        let nominal = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        let want = ry * rx * nominal;
        let got = s.mount(&CameraMount::downward()).matrix();
        assert!((got - want).amax() < 1e-6, "{got} vs {want}");
        // The yaw turns the camera about its own axis first.
        p.set(ParamId::CamYaw, 90.0).unwrap();
        let s = PipelineSettings::from_params(&p);
        let yawed = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        let want = ry * rx * nominal * yawed;
        let got = s.mount(&CameraMount::downward()).matrix();
        assert!((got - want).amax() < 1e-6, "{got} vs {want}");
        // The defaults: the built mount.
        let d = PipelineSettings::default().mount(&CameraMount::downward());
        assert!((d.matrix() - nominal).amax() < 1e-6);
    }

    #[test]
    fn a_multi_marker_pad_is_scaled_as_a_whole() {
        let mut p = ParamSet::default();
        // The nested pad printed at half size: its 1.25 m marker is 0.625 m.
        p.set(ParamId::TagSize, 0.625).unwrap();
        let s = PipelineSettings::from_params(&p);
        let built = &designs::NESTED;
        assert_eq!(s.pad_scale(built), 0.5);
        let scaled = s.pad(built).unwrap();
        assert_eq!(scaled.name(), built.name());
        assert_eq!(scaled.markers().len(), built.markers().len());
        for (a, b) in scaled.markers().iter().zip(built.markers()) {
            assert_eq!((a.family, a.id, a.yaw_deg), (b.family, b.id, b.yaw_deg));
            assert_eq!(a.size, b.size * 0.5);
            assert_eq!((a.x, a.y), (b.x * 0.5, b.y * 0.5));
        }
        assert_eq!(scaled.find("tag36h11", 5).map(|m| m.size), Some(0.08));
    }

    #[test]
    fn a_single_marker_pad_takes_the_tag_size() {
        let mut p = ParamSet::default();
        p.set(ParamId::TagSize, 0.2).unwrap();
        let s = PipelineSettings::from_params(&p);
        let scaled = s.pad(&designs::PAPER_SINGLE).unwrap();
        let m = scaled.markers()[0];
        assert_eq!((m.family, m.id, m.size), ("aruco_6x6_250", 0, 0.2));
        assert_eq!((m.x, m.y), (0.0, 0.0));
    }

    #[test]
    fn bad_scale_factors_are_errors() {
        let pad = &designs::NESTED;
        for factor in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(
                scale_pad(pad, factor),
                Err(PadError::BadSize { index: 0 }),
                "{factor}"
            );
        }
        assert_eq!(scale_pad(pad, 1.0), Ok(*pad));
        assert_eq!(largest_marker_size(pad), 1.25);
    }
}
