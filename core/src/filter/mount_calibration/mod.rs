//! In-flight calibration of the camera mount's roll and pitch (TD_CAM_ROLL, TD_CAM_PITCH)
//! from the level pad and the autopilot's attitude.
//!
//! A camera screwed to a frame by hand is a degree or two off the body axes, and every degree
//! moves the pad by 1.7 % of the range in what the autopilot receives (35 cm at 10 m for a
//! 2 degree error). The pad lies level, so each pad fix measures the camera's "down" (the
//! pad's -z in camera axes) while the autopilot's attitude gives the body's "down" (NED +z in
//! body axes). Through a correct mount the two agree; the rotation that aligns them is the
//! mount's misalignment. At close range a multi-marker fix measures its tilt to a few
//! hundredths of a degree, far better than the misalignment, so the misalignment becomes
//! observable in flight. Yaw about the optical axis is not: a level pad looks the same turned
//! about the vertical, so TD_CAM_YAW stays the user's.
//!
//! # One measurement per frame
//!
//! With `N` the configured mount turned by TD_CAM_YAW (camera to body, **without** roll and
//! pitch), `u = N d_cam` the camera's measured down in body axes and `d_body` the attitude's,
//! the mount in the parameters' form (`R_y(pitch) R_x(roll) N`, see
//! [`super::CameraMount::tilted`]) satisfies `d_body = R_y(pitch) R_x(roll) u`, which fixes
//! both angles exactly (roll from the y component, then pitch in the x-z plane). Measuring
//! against `N` rather than the mount in force makes every frame's measurement absolute: an
//! adopted correction changes nothing already accumulated, and no linearisation error builds
//! up over successive corrections.
//!
//! Each measurement's variance is the fix's rotation covariance turned into body axes (its
//! x and y diagonal: the tilt about body x and y), plus a floor for what the fix's covariance
//! does not contain, the attitude's own sample noise and the camera's vibration on its mount
//! ([`MountCalibrationConfig::frame_noise_deg`]). A frame is refused when
//!
//! - its tilt sigma exceeds [`MountCalibrationConfig::max_tilt_sigma_deg`] (a small marker
//!   far away measures its tilt to degrees: it would only add noise);
//! - its tilt was not measured by the image at all (the tilt block of its covariance is
//!   degenerate, as in a fix levelled with the attitude, [`crate::pose::level_pad_fix`], whose
//!   tilt *is* the attitude through the mount: it would confirm whatever mount is in force);
//! - it rests on a single marker whose mirror solution fits almost as well (the flip
//!   ambiguity of a marker seen nearly head-on: the two solutions differ by their tilt);
//! - the misalignment it implies exceeds [`MountCalibrationConfig::max_misalignment_deg`] (a
//!   pad that is not level, a wrong fix);
//! - once there is an estimate, it lies more than 3 sigma from it (outliers).
//!
//! # The estimate and its uncertainty
//!
//! A running weighted mean per axis (West's weighted form of Welford's update: no
//! cancellation in f32). Its uncertainty has two parts:
//!
//! - **noise**, from the scatter of the accepted measurements about the mean (not from the
//!   nominal weights alone, which trust the fixes' covariances blindly), divided by an
//!   effective sample count: the weights' own `(Σw)² / Σw²`, but at most one sample per
//!   [`FRAME_DECORRELATION_US`] of time span, because consecutive frames share slowly
//!   varying errors (vibration aliasing, the attitude filter's sample-to-sample behaviour)
//!   and a 60 Hz camera does not know the mount twice as well as a 30 Hz one;
//! - **the autopilot's attitude bias**: its roll and pitch carry a slowly varying error of a
//!   few tenths of a degree (accelerometer bias, the filter's tuning) that does not average
//!   away over a short hover and that no scatter reveals, since every frame shares it. It is
//!   modelled as a first-order Gauss-Markov process of standard deviation
//!   [`MountCalibrationConfig::attitude_bias_deg`] and correlation time
//!   [`MountCalibrationConfig::attitude_bias_time_s`]; the variance of its mean over the span
//!   `T` is `σ² 2 (τ/T)² (T/τ - 1 + e^(-T/τ))`: the whole `σ²` for a short hover, `σ² 2τ/T`
//!   for a long one.
//!
//! The reported sigma is the root sum of squares of the two, the larger of the two axes. The
//! bias part usually dominates: a 20 s hover leaves most of the autopilot's bias in the
//! estimate, which is why the estimate keeps accumulating over the whole flight.
//!
//! # When a correction is reported
//!
//! The calibrator is **confident** once it has [`MountCalibrationConfig::min_frames`] accepted
//! frames over at least [`MountCalibrationConfig::min_span_us`], a noise sigma of at most
//! [`MountCalibrationConfig::max_noise_sigma_deg`] and a total sigma of at most
//! [`MountCalibrationConfig::max_sigma_deg`]. [`MountCalibrator::observe`] returns a
//! [`MountCorrection`] on the frame it first becomes confident, then again only when the
//! estimate has moved from the last reported one by more than [`REREPORT_SIGMAS`] sigma (and
//! at least [`MIN_REREPORT_DEG`]): one report per flight normally, never a stream of small
//! changes. The accumulated frames survive a reported correction (the measurements do not
//! depend on the mount in force) and [`super::PadEstimator::reset`] (the mount belongs to the
//! airframe, not to a flight); a changed TD_CAM_YAW, which changes `N`, starts afresh.

use super::axes::{Attitude, CameraMount};
use crate::pose::PadFix;
use nalgebra::{Matrix3, Vector3};

/// One sigma of a multicopter autopilot's slowly varying roll and pitch error in flight,
/// degrees: its EKF's attitude drifts by a few tenths of a degree over tens of seconds
/// (accelerometer bias, the filter's tuning). The calibration's default
/// ([`MountCalibrationConfig::attitude_bias_deg`]), and what a position levelled with that
/// attitude is worth besides its mount ([`crate::companion`]'s VISION_POSITION_ESTIMATE).
pub const ATTITUDE_BIAS_DEG: f32 = 0.25;
/// At most one effective sample per this much time span (see the module docs), µs.
pub const FRAME_DECORRELATION_US: u64 = 100_000;
/// A later estimate is reported when it moved by more than this many sigma from the last
/// reported one.
pub const REREPORT_SIGMAS: f32 = 3.0;
/// ...and by at least this much, degrees.
pub const MIN_REREPORT_DEG: f32 = 0.2;
/// A fix whose smaller tilt sigma is below this did not measure its tilt from the image (a
/// levelled fix), degrees. Real fixes are above 0.01 degrees (a 1.25 m marker at 2 m on a
/// QVGA sensor measures its tilt to about 0.04 degrees).
const MIN_TILT_SIGMA_DEG: f32 = 0.001;
/// A single-marker fix whose mirror solution reprojects within this factor of its own (or of
/// [`AMBIGUITY_FLOOR_PX`]) is ambiguous.
const AMBIGUITY_RATIO: f32 = 2.0;
/// Reprojection errors below this are noise, pixels.
const AMBIGUITY_FLOOR_PX: f32 = 0.1;
/// Accepted frames before the outlier gate closes (the first estimate needs some frames).
const GATE_AFTER_FRAMES: u32 = 30;
/// The outlier gate, sigma.
const GATE_SIGMAS: f32 = 3.0;
/// This many consecutive outliers (3 s at 30 Hz) mean the mount itself moved (knocked in a
/// hard landing): the accumulation restarts, the last report is kept to compare against.
pub const RESTART_AFTER_OUTLIERS: u32 = 90;

/// What TD_CAM_CAL asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MountCalibrationMode {
    /// 0: no calibration.
    Off,
    /// 1: estimate and report (STATUSTEXT), leave TD_CAM_ROLL/PITCH alone.
    Report,
    /// 2: estimate, report and set TD_CAM_ROLL/PITCH (the default).
    Apply,
}

impl MountCalibrationMode {
    /// From TD_CAM_CAL's value (anything unknown: off).
    pub fn from_param(v: i32) -> Self {
        match v {
            1 => MountCalibrationMode::Report,
            2 => MountCalibrationMode::Apply,
            _ => MountCalibrationMode::Off,
        }
    }

    /// True unless off.
    pub fn estimates(self) -> bool {
        self != MountCalibrationMode::Off
    }
}

/// The calibrator's thresholds and error model (see the module docs for each).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountCalibrationConfig {
    /// A frame whose tilt sigma (the larger axis) exceeds this is refused, degrees.
    pub max_tilt_sigma_deg: f32,
    /// Per-frame noise the fix's covariance does not contain (the attitude's sample noise,
    /// vibration), degrees, added in quadrature to every frame's sigma.
    pub frame_noise_deg: f32,
    /// A frame implying a larger misalignment than this is refused, degrees.
    pub max_misalignment_deg: f32,
    /// Accepted frames before the estimate can be confident.
    pub min_frames: u32,
    /// Time span of the accepted frames before the estimate can be confident, µs.
    pub min_span_us: u64,
    /// Largest noise sigma of a confident estimate, degrees.
    pub max_noise_sigma_deg: f32,
    /// Largest total sigma of a confident estimate, degrees.
    pub max_sigma_deg: f32,
    /// The autopilot's slowly varying roll/pitch bias, one sigma, degrees (0: none).
    pub attitude_bias_deg: f32,
    /// Its correlation time, seconds.
    pub attitude_bias_time_s: f32,
}

impl Default for MountCalibrationConfig {
    /// The board's: 100 frames (7 s at 15 Hz) over at least 10 s, noise sigma 0.1 degrees,
    /// total at most 0.5 degrees; a 0.25 degree attitude bias with a 20 s correlation time
    /// (a multicopter EKF's roll and pitch in a hover: a few tenths of a degree, drifting over
    /// tens of seconds).
    fn default() -> Self {
        MountCalibrationConfig {
            max_tilt_sigma_deg: 1.0,
            frame_noise_deg: 0.05,
            max_misalignment_deg: 12.0,
            min_frames: 100,
            min_span_us: 10_000_000,
            max_noise_sigma_deg: 0.1,
            max_sigma_deg: 0.5,
            attitude_bias_deg: ATTITUDE_BIAS_DEG,
            attitude_bias_time_s: 20.0,
        }
    }
}

/// The calibrator's current estimate of the mount (TD_CAM_ROLL, TD_CAM_PITCH).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountEstimate {
    /// Estimated mount roll (what TD_CAM_ROLL should be), degrees.
    pub roll_deg: f32,
    /// Estimated mount pitch (TD_CAM_PITCH), degrees.
    pub pitch_deg: f32,
    /// One-sigma uncertainty of `roll_deg` (noise and attitude bias), degrees.
    pub roll_sigma_deg: f32,
    /// One-sigma uncertainty of `pitch_deg`, degrees.
    pub pitch_sigma_deg: f32,
    /// The noise part of the larger sigma (from the scatter), degrees.
    pub noise_sigma_deg: f32,
    /// The attitude-bias part (the same on both axes), degrees.
    pub bias_sigma_deg: f32,
    /// Accepted frames.
    pub frames: u32,
    /// Time from the first to the last accepted frame, µs.
    pub span_us: u64,
    /// Good enough to report (see the module docs).
    pub confident: bool,
}

impl MountEstimate {
    /// The larger of the two axes' sigmas, degrees.
    pub fn sigma_deg(&self) -> f32 {
        self.roll_sigma_deg.max(self.pitch_sigma_deg)
    }
}

/// A confident mount estimate that differs from the mount in force: what to add to
/// TD_CAM_ROLL and TD_CAM_PITCH.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MountCorrection {
    /// Change of the mount's roll (to add to TD_CAM_ROLL), degrees.
    pub roll_deg: f32,
    /// Change of the mount's pitch (to add to TD_CAM_PITCH), degrees.
    pub pitch_deg: f32,
    /// The estimated roll itself (the mount in force's plus `roll_deg`), degrees.
    pub mount_roll_deg: f32,
    /// The estimated pitch itself, degrees.
    pub mount_pitch_deg: f32,
    /// One-sigma uncertainty, the larger axis, degrees.
    pub sigma_deg: f32,
    /// Accepted frames behind it.
    pub frames: u32,
}

/// Why a frame was not used (counts in [`MountCalibrationStats`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MountRefusal {
    /// The fix's tilt sigma exceeds the limit.
    PoorTilt,
    /// The fix's tilt was not measured by the image (a levelled fix).
    TiltNotMeasured,
    /// The fix's mirror solution fits almost as well.
    Ambiguous,
    /// The implied misalignment is too large (a tilted pad, a wrong fix), or the geometry has
    /// no solution.
    NotLevel,
    /// More than 3 sigma from the estimate.
    Outlier,
}

/// What the calibrator did with the frames it was given.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MountCalibrationStats {
    /// Frames used.
    pub accepted: u32,
    /// Refused: tilt sigma over the limit.
    pub poor_tilt: u32,
    /// Refused: tilt not measured by the image.
    pub tilt_not_measured: u32,
    /// Refused: flip ambiguity.
    pub ambiguous: u32,
    /// Refused: misalignment over the limit.
    pub not_level: u32,
    /// Refused: outlier.
    pub outliers: u32,
    /// Corrections reported.
    pub reports: u32,
    /// Accumulations restarted after [`RESTART_AFTER_OUTLIERS`] consecutive outliers.
    pub restarts: u32,
}

/// One axis's weighted running mean and scatter.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Axis {
    sum_w: f32,
    sum_w2: f32,
    mean: f32,
    /// Σ w (x - mean)², West's accumulator.
    m2: f32,
}

impl Axis {
    fn push(&mut self, x: f32, w: f32) {
        let sum_w = self.sum_w + w;
        let delta = x - self.mean;
        let mean = self.mean + delta * (w / sum_w);
        self.m2 += w * delta * (x - mean);
        self.mean = mean;
        self.sum_w = sum_w;
        self.sum_w2 += w * w;
    }

    /// Weighted variance of one measurement about the mean (unbiased with the effective
    /// count), degrees²; 0 without two measurements.
    fn scatter_var(&self) -> f32 {
        let n = self.effective_count();
        if !(n > 1.0 && self.sum_w > 0.0) {
            return 0.0;
        }
        (self.m2 / self.sum_w).max(0.0) * n / (n - 1.0)
    }

    /// `(Σw)² / Σw²`.
    fn effective_count(&self) -> f32 {
        if self.sum_w2 > 0.0 {
            self.sum_w * self.sum_w / self.sum_w2
        } else {
            0.0
        }
    }
}

/// The mount calibrator (see the module docs).
///
/// A frame far outside the estimate is refused, but [`RESTART_AFTER_OUTLIERS`] of them in a
/// row restart the accumulation: a mount knocked in flight gets a new estimate, reported if
/// it differs significantly from the last report.
#[derive(Debug, Clone, PartialEq)]
pub struct MountCalibrator {
    config: MountCalibrationConfig,
    roll: Axis,
    pitch: Axis,
    first_us: Option<u64>,
    last_us: u64,
    reported: Option<(f32, f32)>,
    consecutive_outliers: u32,
    stats: MountCalibrationStats,
}

impl MountCalibrator {
    /// A calibrator with no frames.
    pub fn new(config: MountCalibrationConfig) -> Self {
        MountCalibrator {
            config,
            roll: Axis::default(),
            pitch: Axis::default(),
            first_us: None,
            last_us: 0,
            reported: None,
            consecutive_outliers: 0,
            stats: MountCalibrationStats::default(),
        }
    }

    /// Forgets every frame and report (the mount's base changed: a new TD_CAM_YAW).
    pub fn reset(&mut self) {
        *self = MountCalibrator::new(self.config);
    }

    /// Drops the accumulated frames, keeping the counts and the last report.
    fn restart_accumulation(&mut self) {
        self.roll = Axis::default();
        self.pitch = Axis::default();
        self.first_us = None;
        self.last_us = 0;
        self.consecutive_outliers = 0;
        self.stats.accepted = 0;
        self.stats.restarts = self.stats.restarts.saturating_add(1);
    }

    /// The thresholds in use.
    pub fn config(&self) -> &MountCalibrationConfig {
        &self.config
    }

    /// What was done with the frames so far.
    pub fn stats(&self) -> MountCalibrationStats {
        self.stats
    }

    /// Feeds one frame: `fix` as the image measured it, `attitude` at its exposure `t_us`,
    /// `base` the mount without roll and pitch (the configured one turned by TD_CAM_YAW),
    /// `in_force` the roll and pitch of the mount in force, degrees. Returns a correction on
    /// the frames described in the module docs. Returns the refusal reason as `Err`.
    pub fn observe(
        &mut self,
        fix: &PadFix,
        attitude: &Attitude,
        base: &CameraMount,
        t_us: u64,
        in_force: (f32, f32),
    ) -> Result<Option<MountCorrection>, MountRefusal> {
        let measured = self.measure(fix, attitude, base);
        let (roll, pitch, sigma_roll, sigma_pitch) = match measured {
            Ok(m) => m,
            Err(r) => {
                self.count(r);
                return Err(r);
            }
        };
        if self.stats.accepted >= GATE_AFTER_FRAMES {
            let far = |axis: &Axis, x: f32, sigma: f32| {
                let bound = GATE_SIGMAS * libm::sqrtf(axis.scatter_var() + sigma * sigma);
                !((x - axis.mean).abs() <= bound)
            };
            if far(&self.roll, roll, sigma_roll) || far(&self.pitch, pitch, sigma_pitch) {
                self.count(MountRefusal::Outlier);
                self.consecutive_outliers = self.consecutive_outliers.saturating_add(1);
                if self.consecutive_outliers >= RESTART_AFTER_OUTLIERS {
                    self.restart_accumulation();
                }
                return Err(MountRefusal::Outlier);
            }
        }
        self.consecutive_outliers = 0;
        self.roll.push(roll, 1.0 / (sigma_roll * sigma_roll));
        self.pitch.push(pitch, 1.0 / (sigma_pitch * sigma_pitch));
        self.stats.accepted = self.stats.accepted.saturating_add(1);
        if self.first_us.is_none() {
            self.first_us = Some(t_us);
        }
        self.last_us = self.last_us.max(t_us);
        Ok(self.report(in_force))
    }

    /// The estimate so far; `None` before the first accepted frame.
    pub fn estimate(&self) -> Option<MountEstimate> {
        let first = self.first_us?;
        let span_us = self.last_us.saturating_sub(first);
        let span_s = span_us as f32 * 1e-6;
        let time_count = 1.0 + (span_us / FRAME_DECORRELATION_US) as f32;
        let noise_var = |axis: &Axis| {
            let n = axis.effective_count().min(time_count).max(1.0);
            // The nominal weights' variance of the mean, or the scatter's if larger.
            let nominal = if axis.sum_w > 0.0 {
                1.0 / axis.sum_w
            } else {
                f32::INFINITY
            };
            (axis.scatter_var() / n).max(nominal)
        };
        let bias_var = self.bias_variance(span_s);
        let (roll_noise, pitch_noise) = (noise_var(&self.roll), noise_var(&self.pitch));
        let roll_sigma = libm::sqrtf(roll_noise + bias_var);
        let pitch_sigma = libm::sqrtf(pitch_noise + bias_var);
        let noise_sigma = libm::sqrtf(roll_noise.max(pitch_noise));
        let c = &self.config;
        let confident = self.stats.accepted >= c.min_frames
            && span_us >= c.min_span_us
            && noise_sigma <= c.max_noise_sigma_deg
            && roll_sigma.max(pitch_sigma) <= c.max_sigma_deg;
        Some(MountEstimate {
            roll_deg: self.roll.mean,
            pitch_deg: self.pitch.mean,
            roll_sigma_deg: roll_sigma,
            pitch_sigma_deg: pitch_sigma,
            noise_sigma_deg: noise_sigma,
            bias_sigma_deg: libm::sqrtf(bias_var),
            frames: self.stats.accepted,
            span_us,
            confident,
        })
    }

    /// The variance of the attitude bias's mean over `span_s`, degrees².
    fn bias_variance(&self, span_s: f32) -> f32 {
        let sigma = self.config.attitude_bias_deg;
        let tau = self.config.attitude_bias_time_s;
        if !(sigma > 0.0) {
            return 0.0;
        }
        if !(tau > 0.0) || !(span_s > 0.0) {
            return sigma * sigma;
        }
        let x = span_s / tau;
        // 2 (x - 1 + e^-x) / x², which tends to 1 for a short span (use its series there:
        // the closed form cancels in f32).
        let factor = if x < 1e-2 {
            1.0 - x / 3.0
        } else {
            2.0 * (x - 1.0 + libm::expf(-x)) / (x * x)
        };
        sigma * sigma * factor.clamp(0.0, 1.0)
    }

    fn report(&mut self, in_force: (f32, f32)) -> Option<MountCorrection> {
        let e = self.estimate()?;
        if !e.confident {
            return None;
        }
        if let Some((roll, pitch)) = self.reported {
            let bound = (REREPORT_SIGMAS * e.sigma_deg()).max(MIN_REREPORT_DEG);
            if (e.roll_deg - roll).abs() <= bound && (e.pitch_deg - pitch).abs() <= bound {
                return None;
            }
        }
        self.reported = Some((e.roll_deg, e.pitch_deg));
        self.stats.reports = self.stats.reports.saturating_add(1);
        let (roll, pitch) = in_force;
        Some(MountCorrection {
            roll_deg: e.roll_deg - roll,
            pitch_deg: e.pitch_deg - pitch,
            mount_roll_deg: e.roll_deg,
            mount_pitch_deg: e.pitch_deg,
            sigma_deg: e.sigma_deg(),
            frames: e.frames,
        })
    }

    /// One frame's roll and pitch and their sigmas, degrees.
    fn measure(
        &self,
        fix: &PadFix,
        attitude: &Attitude,
        base: &CameraMount,
    ) -> Result<(f32, f32, f32, f32), MountRefusal> {
        // Only a single marker has two genuinely different solutions: with several, both
        // starts of the fit converge on the same pose (and the same error).
        let floor = AMBIGUITY_FLOOR_PX.max(fix.reprojection_rms_px);
        if fix.markers_used <= 1
            && fix.alternative_rms_px.is_finite()
            && !(fix.alternative_rms_px > AMBIGUITY_RATIO * floor)
        {
            return Err(MountRefusal::Ambiguous);
        }
        // The tilt's covariance in body axes: the fix's rotation block (left increments,
        // camera frame) turned by the mount; x and y are the tilts about body x and y.
        let n = base.matrix();
        let rotation_cov =
            Matrix3::from_fn(|r, c| fix.covariance.get((r, c)).copied().unwrap_or(f32::NAN));
        let body_cov = n * rotation_cov * n.transpose();
        let (xx, yy, xy) = (body_cov.m11, body_cov.m22, body_cov.m12);
        if !(xx.is_finite() && yy.is_finite() && xy.is_finite()) {
            return Err(MountRefusal::PoorTilt);
        }
        let max_var = self.config.max_tilt_sigma_deg.to_radians();
        if !(xx.max(yy) <= max_var * max_var) {
            return Err(MountRefusal::PoorTilt);
        }
        // The smaller eigenvalue of the 2x2 tilt block.
        let half_trace = 0.5 * (xx + yy);
        let det = xx * yy - xy * xy;
        let min_eig = half_trace - libm::sqrtf((half_trace * half_trace - det).max(0.0));
        let floor = MIN_TILT_SIGMA_DEG.to_radians();
        if !(min_eig >= floor * floor) {
            return Err(MountRefusal::TiltNotMeasured);
        }
        let rotation = &fix.pose.rotation;
        // The pad's -z (NED down, the pad being level) in camera axes, then in body axes
        // through the base mount; the attitude's down in body axes.
        let down_camera = -(rotation * Vector3::z());
        let u = n * down_camera;
        let d = attitude.ned_to_body(&Vector3::z());
        let (roll, pitch) = roll_pitch_aligning(&u, &d).ok_or(MountRefusal::NotLevel)?;
        let (roll, pitch) = (roll.to_degrees(), pitch.to_degrees());
        let limit = self.config.max_misalignment_deg;
        if !(roll.abs() <= limit && pitch.abs() <= limit) {
            return Err(MountRefusal::NotLevel);
        }
        let noise = self.config.frame_noise_deg;
        let sigma = |var: f32| {
            let s = libm::sqrtf(var.max(0.0)).to_degrees();
            libm::sqrtf(s * s + noise * noise).max(MIN_TILT_SIGMA_DEG)
        };
        Ok((roll, pitch, sigma(xx), sigma(yy)))
    }

    fn count(&mut self, r: MountRefusal) {
        let s = &mut self.stats;
        let c = match r {
            MountRefusal::PoorTilt => &mut s.poor_tilt,
            MountRefusal::TiltNotMeasured => &mut s.tilt_not_measured,
            MountRefusal::Ambiguous => &mut s.ambiguous,
            MountRefusal::NotLevel => &mut s.not_level,
            MountRefusal::Outlier => &mut s.outliers,
        };
        *c = c.saturating_add(1);
    }
}

/// The roll and pitch, radians, with `d = R_y(pitch) R_x(roll) u` for unit vectors `u`, `d`
/// (the solution nearest zero roll); `None` when there is none (not finite, or `d`'s y
/// component out of reach of `u` turned about x).
pub fn roll_pitch_aligning(u: &Vector3<f32>, d: &Vector3<f32>) -> Option<(f32, f32)> {
    let (u, d) = (u.try_normalize(1e-6)?, d.try_normalize(1e-6)?);
    // y is untouched by R_y: d_y = u_y cos r - u_z sin r = rho cos(r + alpha).
    let rho = libm::sqrtf(u.y * u.y + u.z * u.z);
    if !(rho > 1e-3) || !(d.y.abs() <= rho * (1.0 + 1e-5)) {
        return None;
    }
    let alpha = libm::atan2f(u.z, u.y);
    let a = libm::acosf((d.y / rho).clamp(-1.0, 1.0));
    let wrap = |x: f32| libm::atan2f(libm::sinf(x), libm::cosf(x));
    let (r1, r2) = (wrap(a - alpha), wrap(-a - alpha));
    let roll = if r1.abs() <= r2.abs() { r1 } else { r2 };
    // Then R_y(pitch) takes v = R_x(roll) u to d in the x-z plane.
    let (s, c) = (libm::sinf(roll), libm::cosf(roll));
    let (vx, vz) = (u.x, u.y * s + u.z * c);
    let pitch = libm::atan2f(vz * d.x - vx * d.z, vx * d.x + vz * d.z);
    (roll.is_finite() && pitch.is_finite()).then_some((roll, pitch))
}

#[cfg(test)]
mod tests;
