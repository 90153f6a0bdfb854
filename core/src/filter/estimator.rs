//! The estimator: from one frame's pad fix and the vehicle's state to the pad's place
//! relative to the vehicle, filtered, at the frame's exposure time.
//!
//! This is the stage between the camera and the MAVLink messages. It owns two trackers
//! ([`super::tracker`]) that see every fix:
//!
//! - the **level** tracker filters the pad relative to the vehicle in NED axes, each fix
//!   rotated with the attitude *at the frame's exposure* ([`super::vehicle`] keeps a short
//!   history and interpolates). This is the good one: the pad is static in that frame, so the
//!   constant-velocity model holds while the vehicle tilts. A levelled fix is only as good
//!   as the attitude it was levelled with, so its covariance gets the attitude's error
//!   ([`level_covariance`], [`EstimatorConfig::attitude_noise_deg`]) on top of the pose's.
//! - the **camera-frame** tracker filters the raw camera-frame positions; its larger process
//!   noise absorbs the vehicle's tilting. It is the fallback when there is no attitude (the
//!   autopilot silent, or not streaming it).
//!
//! What it gives ([`PadEstimate`]) is independent of the autopilot: the pad in body FRD (from
//! the level estimate and the attitude at exposure, else from the camera-frame estimate
//! through the mount), the level estimate with that attitude, the vehicle's local position at
//! the exposure where known, and the pad's orientation. Which of those a LANDING_TARGET carries
//! is the MAVLink side's choice ([`crate::companion::profile`]).
//!
//! Why the vehicle state is an argument and not owned here: it arrives with the autopilot's
//! messages, which the MAVLink side decodes (and, on the board, in another task than the
//! camera's). It is read once per frame, at the exposure ([`VehicleAtExposure`], from
//! [`super::VehicleState::at`]), with the state's reboot counter; when that moves, the level
//! tracker restarts, since NED positions from before an autopilot reboot are in a frame that
//! no longer exists.
//!
//! The camera mount is set between frames ([`PadEstimator::set_mount`]): the configured mount
//! turned by TD_CAM_YAW about the optical axis, then tilted by TD_CAM_ROLL about body x and
//! TD_CAM_PITCH about body y ([`CameraMount::tilted`]). A changed yaw restarts both trackers:
//! it is a reconfiguration (often by 90 or 180 degrees) after which the camera-to-body
//! positions before and after are unrelated. A changed roll or pitch restarts neither: it is a
//! mount calibration of a few degrees at most, the camera-frame track does not depend on the
//! mount at all, and the level track sees its measurements move by the change times the range
//! (3.5 cm at 2 m for a degree), which it fuses or, beyond its gate, takes over through its
//! jump recovery after a few frames, where a restart would drop every target until a new
//! track is confirmed, in the middle of a landing.
//!
//! Every frame with a fix and the attitude also feeds the [`MountCalibrator`]
//! ([`super::mount_calibration`]), unless TD_CAM_CAL is off
//! ([`PadEstimator::set_mount_calibration`]); a confident estimate comes out as
//! [`FrameEstimate::mount_correction`], which the MAVLink side adopts into
//! TD_CAM_ROLL/TD_CAM_PITCH. The calibrator needs the tilt the *image* measured: a fix
//! levelled with the attitude ([`crate::pose::level_pad_fix`]) has the attitude's tilt
//! through the mount in force, so the pipeline hands the image's fix separately
//! ([`PadEstimator::update_with_image_fix`]); a levelled fix given alone is refused by the
//! calibrator (its tilt covariance shows it was not measured).

use super::axes::{level_measurement, pad_orientation, Attitude, CameraMount};
use super::mount_calibration::{
    MountCalibrationConfig, MountCalibrator, MountCorrection, MountEstimate,
};
use super::tracker::{ConfigError, Estimate, Tracker, TrackerConfig};
use super::vehicle::{PositionSample, VehicleAtExposure};
use super::Measurement;
use crate::pose::PadFix;
use nalgebra::{Matrix3, Vector3};

/// Everything about the estimator that is fixed at start-up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimatorConfig {
    /// The camera mount before TD_CAM_YAW's turn about the optical axis.
    pub mount: CameraMount,
    /// The level (NED axes) tracker.
    pub level_tracker: TrackerConfig,
    /// The camera-frame tracker (no attitude).
    pub camera_tracker: TrackerConfig,
    /// The mount calibrator's thresholds and error model.
    pub mount_calibration: MountCalibrationConfig,
    /// One sigma of the error of the attitude a fix is levelled with, degrees, frame to
    /// frame (see [`level_covariance`]): the autopilot's attitude noise, the camera's
    /// vibration on its mount and the error of reading the attitude at the exposure time.
    /// Finite and at least 0 ([`ConfigError::AttitudeNoise`]).
    pub attitude_noise_deg: f32,
}

/// [`EstimatorConfig::attitude_noise_deg`] of the default estimator. A multicopter's EKF
/// attitude is good to a few hundredths of a degree from sample to sample, the camera's mount
/// vibrates by a few hundredths more, and a few milliseconds of error in the time the attitude
/// is read at turn into a few hundredths at a hover's body rates (10-20 deg/s): about 0.1
/// degree together. It is what the mount calibrator's frame noise
/// ([`MountCalibrationConfig::frame_noise_deg`]) is, taken with margin, since a level fix
/// trusted too much moves the filtered altitude (see [`level_covariance`]).
pub const ATTITUDE_NOISE_DEG: f32 = 0.1;

impl Default for EstimatorConfig {
    fn default() -> Self {
        EstimatorConfig {
            mount: CameraMount::downward(),
            level_tracker: TrackerConfig::level(),
            camera_tracker: TrackerConfig::camera_frame(),
            mount_calibration: MountCalibrationConfig::default(),
            attitude_noise_deg: ATTITUDE_NOISE_DEG,
        }
    }
}

/// The covariance of a fix levelled with an attitude whose error is `sigma_rad` about each
/// axis: the fix's own, rotated (`level.covariance`), plus the attitude's, which turns the
/// vector `p` to the pad by a small angle and so moves it perpendicular to itself, by
/// `sigma * |p|` in each of the two directions across it: `sigma^2 (|p|^2 I - p p^T)`.
///
/// Why it matters: the pose measures the pad's direction far better than its range (at 20 m
/// on one 1 m marker, 5 mm across against 14 cm along the line of sight), so a rotated fix
/// without this term is a long, thin ellipsoid, a few degrees off the vertical when the
/// vehicle tilts. The attitude's frame-to-frame error moves the levelled pad by more than
/// the 5 mm across (1.7 cm at 20 m for 0.05 degrees); a filter that takes the thin
/// ellipsoid at its word reads that sideways move as a range change along the tilted line
/// of sight. In the replayed `sun` hover at 20 m it drove the level track's vertical speed to
/// 0.8 m/s and its altitude 14 cm below every fix of the last four frames.
pub fn level_covariance(level: &Measurement, sigma_rad: f32) -> Matrix3<f32> {
    level.covariance + turn_covariance(&level.position, sigma_rad)
}

/// The covariance a turn of `sigma_rad` (one sigma about each axis) gives the end of the
/// vector `p`: `sigma^2 (|p|^2 I - p p^T)`, across `p` only (see [`level_covariance`]).
pub fn turn_covariance(p: &Vector3<f32>, sigma_rad: f32) -> Matrix3<f32> {
    (Matrix3::identity() * p.norm_squared() - p * p.transpose()) * (sigma_rad * sigma_rad)
}

/// One sigma of the tilt error of a camera mount that no calibration has measured, degrees:
/// what a mount aligned by eye or a printed bracket is good to (see
/// [`PadEstimator::mount_sigma_deg`]).
pub const MOUNT_PRIOR_SIGMA_DEG: f32 = 2.0;

/// The level estimate with the attitude it was read with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelEstimate {
    /// The pad relative to the vehicle, NED axes, metres (and its velocity, covariances).
    pub estimate: Estimate,
    /// The vehicle's attitude at the exposure (body FRD to NED).
    pub attitude: Attitude,
    /// One sigma of the mount's tilt error the estimate was levelled with, degrees
    /// ([`PadEstimator::mount_sigma_deg`]). Unlike the attitude's frame-to-frame noise it is
    /// the same in every frame, so no filtering removes it and `estimate`'s covariance does
    /// not hold it: a position for navigation adds it ([`turn_covariance`]).
    pub mount_sigma_deg: f32,
}

/// The filtered pad at one frame's exposure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PadEstimate {
    /// The pad relative to the vehicle in body FRD, metres: from the level estimate where there
    /// is one, else from the camera-frame estimate through the mount.
    pub body_frd: Vector3<f32>,
    /// The level estimate, when the attitude at the exposure is known and the level track is
    /// confirmed and fresh.
    pub level: Option<LevelEstimate>,
    /// The vehicle's local position at the exposure, when the autopilot streams it.
    pub vehicle_position: Option<PositionSample>,
    /// The pad's orientation from this frame's fix (the trackers filter positions only), pad
    /// frame to body FRD, `[w, x, y, z]`; `None` when the fix's rotation is unusable.
    pub orientation_body: Option<[f32; 4]>,
    /// The same, pad frame to NED (needs the attitude at the exposure).
    pub orientation_ned: Option<[f32; 4]>,
    /// How far the vehicle can move before the pad leaves the view, metres, from this frame's
    /// fix (`crate::pipeline::view_margin_m`): set by the per-frame pipeline, which knows the
    /// camera; `None` from the estimator alone.
    pub view_margin_m: Option<f32>,
}

/// What the estimator made of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameEstimate {
    /// The frame's exposure time, our clock, µs.
    pub exposure_us: u64,
    /// The frame had a pad fix.
    pub fix_found: bool,
    /// The estimate at the exposure: `None` without a fix, or while no tracker has a confirmed
    /// estimate whose last measurement is fresh (see [`TrackerConfig::max_coast_us`]).
    pub estimate: Option<PadEstimate>,
    /// A confident mount estimate, as the change to the mount in force, on the frame the
    /// calibrator first becomes confident and again only when it moves significantly
    /// ([`super::MountCalibrator`]); `None` on every other frame.
    pub mount_correction: Option<MountCorrection>,
}

/// The two trackers and the mount (see the module docs).
#[derive(Debug, Clone)]
pub struct PadEstimator {
    config: EstimatorConfig,
    /// The configured mount turned by TD_CAM_YAW (what the calibrator measures against).
    base_mount: CameraMount,
    /// `base_mount` tilted by TD_CAM_ROLL and TD_CAM_PITCH: the mount in force.
    mount: CameraMount,
    /// TD_CAM_YAW in force, degrees.
    mount_yaw_deg: f32,
    /// TD_CAM_ROLL and TD_CAM_PITCH in force, degrees.
    mount_tilt_deg: (f32, f32),
    calibrator: MountCalibrator,
    calibrating: bool,
    level: Tracker,
    camera: Tracker,
    /// [`super::VehicleState::reboots`] when the level tracker last ran.
    vehicle_reboots: u32,
}

impl PadEstimator {
    /// An estimator with no track. Fails when a tracker configuration is invalid.
    pub fn new(config: EstimatorConfig) -> Result<Self, ConfigError> {
        if !(config.attitude_noise_deg >= 0.0) || !config.attitude_noise_deg.is_finite() {
            return Err(ConfigError::AttitudeNoise);
        }
        Ok(PadEstimator {
            config,
            base_mount: config.mount,
            mount: config.mount,
            mount_yaw_deg: 0.0,
            mount_tilt_deg: (0.0, 0.0),
            calibrator: MountCalibrator::new(config.mount_calibration),
            calibrating: true,
            level: Tracker::new(config.level_tracker)?,
            camera: Tracker::new(config.camera_tracker)?,
            vehicle_reboots: 0,
        })
    }

    /// Turns the configured mount by `yaw_deg` about the optical axis (TD_CAM_YAW), keeping
    /// the roll and pitch in force. A change restarts both trackers.
    pub fn set_mount_yaw(&mut self, yaw_deg: f32) {
        let (roll, pitch) = self.mount_tilt_deg;
        self.set_mount(yaw_deg, roll, pitch);
    }

    /// The mount in force: the configured one turned by `yaw_deg` about the optical axis
    /// (TD_CAM_YAW), then by `roll_deg` about body x (TD_CAM_ROLL) and `pitch_deg` about
    /// body y (TD_CAM_PITCH), degrees: camera-to-body = `R_y(pitch) R_x(roll) M R_z(yaw)`
    /// with `M` the configured mount. A changed yaw restarts both trackers and the mount
    /// calibration; a changed roll or pitch neither (see the module docs). A value that is
    /// not finite keeps its old one.
    pub fn set_mount(&mut self, yaw_deg: f32, roll_deg: f32, pitch_deg: f32) {
        // Compared as the parameters, not as the turned quaternion, whose last bits a turn by
        // zero may change.
        let keep = |new: f32, old: f32| if new.is_finite() { new } else { old };
        let yaw = keep(yaw_deg, self.mount_yaw_deg);
        let tilt = (
            keep(roll_deg, self.mount_tilt_deg.0),
            keep(pitch_deg, self.mount_tilt_deg.1),
        );
        if yaw != self.mount_yaw_deg {
            self.mount_yaw_deg = yaw;
            self.base_mount = self.config.mount.turned_about_optical_axis(yaw);
            self.calibrator.reset();
            self.reset();
        } else if tilt == self.mount_tilt_deg {
            return;
        }
        self.mount_tilt_deg = tilt;
        self.mount = self.base_mount.tilted(tilt.0, tilt.1);
    }

    /// The mount in force (the configured one turned by TD_CAM_YAW, tilted by TD_CAM_ROLL
    /// and TD_CAM_PITCH).
    pub fn mount(&self) -> &CameraMount {
        &self.mount
    }

    /// TD_CAM_ROLL and TD_CAM_PITCH in force, degrees.
    pub fn mount_tilt_deg(&self) -> (f32, f32) {
        self.mount_tilt_deg
    }

    /// Feeds the mount calibrator or not (TD_CAM_CAL off). Turning it off keeps what it has
    /// accumulated.
    pub fn set_mount_calibration(&mut self, on: bool) {
        self.calibrating = on;
    }

    /// The mount calibrator (its estimate and counts).
    pub fn mount_calibrator(&self) -> &MountCalibrator {
        &self.calibrator
    }

    /// The mount calibrator's estimate so far.
    pub fn mount_estimate(&self) -> Option<MountEstimate> {
        self.calibrator.estimate()
    }

    /// One sigma of the mount in force's tilt error, degrees: once the calibrator has the
    /// frames and the time span a report needs, its sigma plus the mount in force's distance
    /// from it (a correction reported but not applied, TD_CAM_CAL = 1, leaves that distance),
    /// at most [`MOUNT_PRIOR_SIGMA_DEG`]; before that (or with TD_CAM_CAL off, when the board
    /// cannot know how well the mount was set), [`MOUNT_PRIOR_SIGMA_DEG`]. Not its
    /// confidence: that gates a report on a steady estimate, and a calibration made in a calm
    /// hover stays as good when a gusty descent later adds scattered frames to it.
    pub fn mount_sigma_deg(&self) -> f32 {
        let c = self.calibrator.config();
        match self
            .calibrator
            .estimate()
            .filter(|e| e.frames >= c.min_frames && e.span_us >= c.min_span_us)
        {
            Some(e) => {
                let (roll, pitch) = self.mount_tilt_deg;
                let sigma = e.sigma_deg() + libm::hypotf(e.roll_deg - roll, e.pitch_deg - pitch);
                sigma.min(MOUNT_PRIOR_SIGMA_DEG)
            }
            None => MOUNT_PRIOR_SIGMA_DEG,
        }
    }

    /// Forgets both tracks (a new, independent flight). The mount calibration is kept: the
    /// mount belongs to the airframe.
    pub fn reset(&mut self) {
        self.level.reset();
        self.camera.reset();
    }

    /// The pad in the camera frame predicted at the exposure from the tracks (before this
    /// frame's fix), for choosing between a fix's two mirror solutions; `None` without a track.
    pub fn predicted_in_camera(&self, vehicle: &VehicleAtExposure) -> Option<Vector3<f32>> {
        let t_us = vehicle.t_us;
        let level = vehicle.attitude.as_ref().and_then(|att| {
            let e = self.level.estimate(t_us)?;
            Some(self.mount.body_to_camera(&att.ned_to_body(&e.position)))
        });
        level.or_else(|| self.camera.estimate(t_us).map(|e| e.position))
    }

    /// The camera's velocity against the pad at `t_us` from the level track, NED, m/s: the
    /// opposite of the pad's velocity against the vehicle, whether the pad stands still or
    /// moves (a deck, a roof), where the autopilot's velocity is the vehicle's over the ground
    /// and right only for a pad at rest. `None` without a confirmed level track.
    pub fn velocity_against_pad(&self, t_us: u64) -> Option<Vector3<f32>> {
        self.level.estimate(t_us).map(|e| -e.velocity)
    }

    /// Feeds one frame: `fix` (if the pad was found), exposed at `vehicle.t_us`, with the
    /// vehicle state read at that time when the frame was processed. The mount calibrator
    /// gets `fix` too (see [`PadEstimator::update_with_image_fix`] for a levelled fix).
    pub fn update(&mut self, fix: Option<&PadFix>, vehicle: &VehicleAtExposure) -> FrameEstimate {
        self.update_with_image_fix(fix, fix, vehicle)
    }

    /// [`PadEstimator::update`] with the fix the image alone measured, `image_fix`, for the
    /// mount calibrator, when `fix` is that fix levelled with the attitude (whose tilt is the
    /// attitude's through the mount in force, useless for calibrating it).
    pub fn update_with_image_fix(
        &mut self,
        fix: Option<&PadFix>,
        image_fix: Option<&PadFix>,
        vehicle: &VehicleAtExposure,
    ) -> FrameEstimate {
        let mount_correction = match (image_fix, &vehicle.attitude) {
            (Some(f), Some(att)) if self.calibrating => self
                .calibrator
                .observe(f, att, &self.base_mount, vehicle.t_us, self.mount_tilt_deg)
                .ok()
                .flatten(),
            _ => None,
        };
        FrameEstimate {
            mount_correction,
            ..self.track(fix, vehicle)
        }
    }

    fn track(&mut self, fix: Option<&PadFix>, vehicle: &VehicleAtExposure) -> FrameEstimate {
        if vehicle.reboots != self.vehicle_reboots {
            self.vehicle_reboots = vehicle.reboots;
            self.level.reset();
        }
        let t = vehicle.t_us;
        self.level.predict_to(t);
        self.camera.predict_to(t);
        let Some(fix) = fix else {
            return FrameEstimate {
                exposure_us: t,
                fix_found: false,
                estimate: None,
                mount_correction: None,
            };
        };
        let m = Measurement {
            t_us: t,
            position: fix.pose.translation,
            covariance: fix.pad_position_covariance(),
        };
        self.camera.update(&m);
        let attitude = vehicle.attitude;
        if let Some(att) = &attitude {
            let mut level = level_measurement(&m, att, &self.mount);
            level.covariance =
                level_covariance(&level, self.config.attitude_noise_deg.to_radians());
            self.level.update(&level);
        }
        let mount_sigma_deg = self.mount_sigma_deg();
        let level = attitude.and_then(|attitude| {
            self.level.estimate(t).map(|estimate| LevelEstimate {
                estimate,
                attitude,
                mount_sigma_deg,
            })
        });
        let body_frd = match &level {
            Some(l) => Some(l.attitude.ned_to_body(&l.estimate.position)),
            None => self
                .camera
                .estimate(t)
                .map(|e| self.mount.camera_to_body(&e.position)),
        };
        let estimate = body_frd.map(|body_frd| PadEstimate {
            body_frd,
            level,
            vehicle_position: vehicle.position,
            orientation_body: pad_orientation(&fix.pose.rotation, &self.mount, None),
            orientation_ned: attitude
                .as_ref()
                .and_then(|att| pad_orientation(&fix.pose.rotation, &self.mount, Some(att))),
            view_margin_m: None,
        });
        FrameEstimate {
            exposure_us: t,
            fix_found: true,
            estimate,
            mount_correction: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::ned_to_camera;
    use crate::filter::VehicleState;
    use crate::pose::Pose;
    use nalgebra::Matrix6;

    const PERIOD_US: u64 = 33_333;

    /// A pad 5 m below a level camera, slightly forward and right, as a confident fix.
    fn fix() -> PadFix {
        PadFix {
            pose: Pose {
                rotation: Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0),
                translation: Vector3::new(0.3, -0.2, 5.0),
            },
            covariance: Matrix6::identity() * 1e-6,
            markers_used: 1,
            reprojection_rms_px: 0.2,
            alternative_rms_px: f32::INFINITY,
        }
    }

    /// Feeds `frames` fixes from `t0`; returns the last frame's estimate and its time.
    fn feed(
        e: &mut PadEstimator,
        vehicle: &mut VehicleState,
        level: bool,
        t0: u64,
        frames: u64,
    ) -> (FrameEstimate, u64) {
        let mut last = None;
        let mut t = t0;
        for k in 0..frames {
            t = t0 + k * PERIOD_US;
            if level {
                vehicle.push_attitude(t, &Attitude::level_north(), t);
            }
            last = Some(e.update(Some(&fix()), &vehicle.at(t)));
        }
        (last.unwrap(), t)
    }

    #[test]
    fn without_attitude_the_camera_track_gives_body_frd_and_no_level() {
        let mut e = PadEstimator::new(EstimatorConfig::default()).unwrap();
        let mut vehicle = VehicleState::new();
        let first = e.update(Some(&fix()), &vehicle.at(0));
        assert!(
            first.fix_found && first.estimate.is_none(),
            "not yet confirmed"
        );
        let (last, _) = feed(&mut e, &mut vehicle, false, PERIOD_US, 5);
        let est = last.estimate.expect("confirmed");
        assert!(est.level.is_none());
        // Downward mount: camera x (right) is body y, camera y (down the image) is body -x.
        let want = Vector3::new(0.2, 0.3, 5.0);
        assert!((est.body_frd - want).amax() < 1e-3, "{}", est.body_frd);
        assert!(est.orientation_body.is_some() && est.orientation_ned.is_none());
        // A frame without a fix: nothing, but the exposure time is kept.
        let none = e.update(None, &vehicle.at(10 * PERIOD_US));
        assert_eq!((none.exposure_us, none.fix_found), (10 * PERIOD_US, false));
        assert!(none.estimate.is_none());
    }

    #[test]
    fn level_covariance_adds_the_attitude_across_the_line_of_sight_only() {
        let m = Measurement {
            t_us: 0,
            position: Vector3::new(0.0, 0.0, 20.0),
            covariance: Matrix3::identity() * 1e-4,
        };
        let sigma = 0.1f32.to_radians();
        let c = level_covariance(&m, sigma);
        // Across: (20 m * 1.745 mrad)^2 = 1.22e-3 m^2 more; along: nothing more.
        let across = (20.0 * sigma) * (20.0 * sigma);
        assert!((c[(0, 0)] - 1e-4 - across).abs() < 1e-7, "{c}");
        assert!((c[(1, 1)] - 1e-4 - across).abs() < 1e-7, "{c}");
        assert!((c[(2, 2)] - 1e-4).abs() < 1e-9, "{c}");
        assert_eq!(level_covariance(&m, 0.0), m.covariance);
        // A bad configuration is refused, not used.
        let bad = EstimatorConfig {
            attitude_noise_deg: f32::NAN,
            ..EstimatorConfig::default()
        };
        assert_eq!(
            PadEstimator::new(bad).err(),
            Some(ConfigError::AttitudeNoise)
        );
    }

    /// A hover at 20 m over a 1 m marker, the vehicle tilted 3 degrees, the attitude it
    /// reports off the true one by +-0.05 degrees from frame to frame (what a real autopilot's
    /// attitude and a vibrating mount do). The fix itself is exact but for that, with the
    /// covariance a single far marker has: 5 mm across the line of sight, 14 cm along it.
    /// Returns the level track's largest altitude error and vertical speed, metres and m/s.
    fn shaken_hover(attitude_noise_deg: f32) -> (f32, f32) {
        let config = EstimatorConfig {
            attitude_noise_deg,
            ..EstimatorConfig::default()
        };
        let mut e = PadEstimator::new(config).unwrap();
        let mut vehicle = VehicleState::new();
        let pad_ned = Vector3::new(0.5, 0.4, 20.0);
        let truth = Attitude::from_euler(3f32.to_radians(), -1f32.to_radians(), 0.3).unwrap();
        let mount = CameraMount::downward();
        let mut covariance = Matrix6::zeros();
        covariance[(3, 3)] = 0.005 * 0.005;
        covariance[(4, 4)] = 0.005 * 0.005;
        covariance[(5, 5)] = 0.14 * 0.14;
        // A fixed pattern of errors (degrees about roll and pitch), zero mean.
        let shake = [
            (1.0, -1.0),
            (-1.0, -1.0),
            (1.0, 1.0),
            (-1.0, 1.0),
            (0.0, 1.0),
        ];
        let (mut worst_z, mut worst_v) = (0.0f32, 0.0f32);
        for k in 0..15u64 {
            let t = k * 66_666;
            let (dr, dp) = shake[(k % 5) as usize];
            let reported = Attitude::from_euler(
                (3.0 + 0.05 * dr as f32).to_radians(),
                (-1.0 + 0.05 * dp as f32).to_radians(),
                0.3,
            )
            .unwrap();
            vehicle.push_attitude(t, &reported, t);
            let fix = PadFix {
                pose: Pose {
                    rotation: Matrix3::identity(),
                    translation: ned_to_camera(&pad_ned, &truth, &mount),
                },
                covariance,
                markers_used: 1,
                reprojection_rms_px: 0.2,
                alternative_rms_px: f32::INFINITY,
            };
            let out = e.update(Some(&fix), &vehicle.at(t));
            if let Some(level) = out.estimate.and_then(|e| e.level) {
                worst_z = worst_z.max((level.estimate.position.z - pad_ned.z).abs());
                worst_v = worst_v.max(level.estimate.velocity.z.abs());
            }
        }
        (worst_z, worst_v)
    }

    #[test]
    fn a_far_fix_shaken_by_the_attitude_keeps_its_altitude() {
        // The sideways shake is 1.7 cm at 20 m; the altitude stays within 3 mm (measured:
        // 0.8 mm, 5 mm/s).
        let (z, v) = shaken_hover(ATTITUDE_NOISE_DEG);
        assert!(
            z < 0.003 && v < 0.01,
            "altitude off by {z} m, vertical speed {v} m/s"
        );
        // Without the attitude's term the thin ellipsoid turns that shake into altitude
        // (measured: 7.6 mm, 26 mm/s).
        let (z0, v0) = shaken_hover(0.0);
        assert!(z0 > 4.0 * z && v0 > 4.0 * v, "{z0} m, {v0} m/s");
    }

    #[test]
    fn with_attitude_the_level_track_is_used() {
        let mut e = PadEstimator::new(EstimatorConfig::default()).unwrap();
        let mut vehicle = VehicleState::new();
        let (last, _) = feed(&mut e, &mut vehicle, true, 0, 6);
        let est = last.estimate.expect("confirmed");
        let level = est.level.expect("attitude known");
        // Level, nose north: body FRD is NED.
        assert!((level.estimate.position - est.body_frd).amax() < 1e-4);
        assert!((est.body_frd - Vector3::new(0.2, 0.3, 5.0)).amax() < 1e-3);
        assert!(est.orientation_ned.is_some());
    }

    #[test]
    fn an_autopilot_reboot_restarts_the_level_track_and_a_mount_change_both() {
        let mut e = PadEstimator::new(EstimatorConfig::default()).unwrap();
        let mut vehicle = VehicleState::new();
        let (_, t) = feed(&mut e, &mut vehicle, true, 0, 6);
        vehicle.on_reboot();
        let (after, t) = feed(&mut e, &mut vehicle, true, t + PERIOD_US, 1);
        let est = after.estimate.expect("the camera track carries on");
        assert!(est.level.is_none(), "the level track restarted");
        let (again, t) = feed(&mut e, &mut vehicle, true, t + PERIOD_US, 6);
        assert!(again.estimate.and_then(|e| e.level).is_some());
        // The same yaw changes nothing; another one restarts both tracks.
        e.set_mount_yaw(0.0);
        let (same, t) = feed(&mut e, &mut vehicle, true, t + PERIOD_US, 1);
        assert!(same.estimate.is_some());
        e.set_mount_yaw(90.0);
        let (turned, _) = feed(&mut e, &mut vehicle, true, t + PERIOD_US, 1);
        assert!(turned.fix_found && turned.estimate.is_none());
    }

    #[test]
    fn a_mount_tilt_keeps_the_tracks_and_the_yaw_is_kept_with_it() {
        let mut e = PadEstimator::new(EstimatorConfig::default()).unwrap();
        let mut vehicle = VehicleState::new();
        e.set_mount(30.0, 0.0, 0.0);
        let (_, t) = feed(&mut e, &mut vehicle, true, 0, 6);
        e.set_mount(30.0, 1.5, -1.0);
        assert_eq!(e.mount_tilt_deg(), (1.5, -1.0));
        let want = CameraMount::downward()
            .turned_about_optical_axis(30.0)
            .tilted(1.5, -1.0);
        assert_eq!(*e.mount(), want);
        let (after, t) = feed(&mut e, &mut vehicle, true, t + PERIOD_US, 1);
        assert!(
            after.estimate.and_then(|e| e.level).is_some(),
            "not restarted"
        );
        // Not finite: the old values stay; set_mount_yaw keeps the tilt.
        e.set_mount(f32::NAN, f32::INFINITY, -1.0);
        assert_eq!(*e.mount(), want);
        e.set_mount_yaw(30.0);
        assert_eq!(e.mount_tilt_deg(), (1.5, -1.0));
        let (still, _) = feed(&mut e, &mut vehicle, true, t + PERIOD_US, 1);
        assert!(still.estimate.is_some());
    }

    /// The fix a camera on the mount tilted by (1.5, -1.0) degrees sees of a level pad below
    /// a level vehicle, with a small isotropic tilt sigma (a close multi-marker fix).
    fn misaligned_fix() -> PadFix {
        let truth = CameraMount::downward().tilted(1.5, -1.0);
        let ned_from_pad = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0);
        let mut covariance = Matrix6::identity() * 1e-6;
        for k in 0..3 {
            covariance[(k, k)] = 0.05f32.to_radians().powi(2);
        }
        PadFix {
            pose: Pose {
                rotation: truth.matrix().transpose() * ned_from_pad,
                translation: Vector3::new(0.1, 0.1, 3.0),
            },
            covariance,
            ..fix()
        }
    }

    #[test]
    fn the_calibrator_reports_once_from_the_image_fix_and_not_when_off() {
        for (on, levelled) in [(true, false), (true, true), (false, false)] {
            let mut e = PadEstimator::new(EstimatorConfig::default()).unwrap();
            e.set_mount_calibration(on);
            let mut vehicle = VehicleState::new();
            let image = misaligned_fix();
            // A levelled fix: the tilt's covariance gone (only the heading left).
            let mut flat = image;
            for r in 0..3 {
                for c in 0..3 {
                    flat.covariance[(r, c)] = if r == 2 && c == 2 { 1e-4 } else { 0.0 };
                }
            }
            let mut reports = 0;
            for k in 0..400u64 {
                let t = k * PERIOD_US;
                vehicle.push_attitude(t, &Attitude::level_north(), t);
                let f = if levelled { &flat } else { &image };
                let out = e.update_with_image_fix(Some(f), Some(f), &vehicle.at(t));
                if let Some(c) = out.mount_correction {
                    reports += 1;
                    assert!((c.roll_deg - 1.5).abs() < 0.01, "{c:?}");
                    assert!((c.pitch_deg + 1.0).abs() < 0.01, "{c:?}");
                    assert!(c.sigma_deg > 0.1 && c.sigma_deg < 0.5, "{c:?}");
                }
            }
            let want = if on && !levelled { 1 } else { 0 };
            assert_eq!(reports, want, "on {on}, levelled {levelled}");
            if on && levelled {
                assert_eq!(e.mount_calibrator().stats().tilt_not_measured, 400);
            }
        }
    }

    #[test]
    fn the_mount_sigma_is_the_prior_until_a_calibration_has_its_frames_and_is_applied() {
        let mut e = PadEstimator::new(EstimatorConfig::default()).unwrap();
        let mut vehicle = VehicleState::new();
        let fix = misaligned_fix();
        let mut level_sigma = |e: &mut PadEstimator, k: u64| {
            let t = k * PERIOD_US;
            vehicle.push_attitude(t, &Attitude::level_north(), t);
            let out = e.update(Some(&fix), &vehicle.at(t));
            out.estimate
                .and_then(|p| p.level)
                .map(|l| l.mount_sigma_deg)
        };
        assert_eq!(level_sigma(&mut e, 0), None, "no track yet");
        let mut tracked = 0;
        for k in 1..20 {
            if let Some(sigma) = level_sigma(&mut e, k) {
                assert_eq!(sigma, MOUNT_PRIOR_SIGMA_DEG, "frame {k}");
                tracked += 1;
            }
        }
        assert!(tracked > 10, "{tracked}");
        for k in 20..400 {
            level_sigma(&mut e, k);
        }
        let calibration = e.mount_estimate().unwrap();
        assert!(calibration.confident);
        // Not applied: at most the prior (1.8 degrees from the mount in force, plus its sigma).
        assert_eq!(level_sigma(&mut e, 400), Some(MOUNT_PRIOR_SIGMA_DEG));
        // Half applied: its sigma plus the distance left.
        e.set_mount(0.0, 1.0, -0.5);
        let half = level_sigma(&mut e, 401).unwrap();
        let distance = libm::hypotf(calibration.roll_deg - 1.0, calibration.pitch_deg + 0.5);
        assert!(
            (half - calibration.sigma_deg() - distance).abs() < 0.01,
            "{half}"
        );
        assert!(half < MOUNT_PRIOR_SIGMA_DEG, "{half}");
        // Applied (TD_CAM_ROLL/PITCH set to it): its own sigma.
        e.set_mount(0.0, calibration.roll_deg, calibration.pitch_deg);
        let applied = level_sigma(&mut e, 402).unwrap();
        assert!(
            (applied - calibration.sigma_deg()).abs() < 1e-3,
            "{applied}"
        );
        assert!(applied < 0.5, "{applied}");
    }

    #[test]
    fn a_reset_keeps_the_mount_calibration_and_a_yaw_change_drops_it() {
        let mut e = PadEstimator::new(EstimatorConfig::default()).unwrap();
        let mut vehicle = VehicleState::new();
        for k in 0..50u64 {
            let t = k * PERIOD_US;
            vehicle.push_attitude(t, &Attitude::level_north(), t);
            e.update(Some(&misaligned_fix()), &vehicle.at(t));
        }
        e.reset();
        assert_eq!(e.mount_estimate().map(|m| m.frames), Some(50));
        e.set_mount(5.0, 0.0, 0.0);
        assert_eq!(e.mount_estimate(), None);
    }
}
