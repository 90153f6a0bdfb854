//! From the estimator's output to the LANDING_TARGET (and the optional VISION_POSITION_ESTIMATE
//! and velocity, TD_VPE_EN) queued for the autopilot, in the format of the profile in force.
//!
//! - ArduPilot: body FRD, from [`PadEstimate::body_frd`] (the level estimate rotated with the
//!   attitude at exposure, or the camera-frame estimate through the mount). ArduPilot needs
//!   none of our vehicle state, so targets keep flowing when its messages stop.
//! - ArduPilot 4.7+ LOCAL_FRD: the level estimate turned back by the heading at the exposure;
//!   without the attitude at the exposure (no level estimate), BODY_FRD as above, which the
//!   same autopilot also takes, so targets keep flowing when its messages stop.
//! - PX4: LOCAL_NED, the vehicle's position at the exposure plus TD_CAM_POS and the level
//!   estimate; nothing without both the attitude and LOCAL_POSITION_NED at the exposure.
//!
//! Then TD_RATE_HZ's pacing (by exposure time), the time base of `time_usec`, and the newest
//! target replacing an unsent older one.

use core::fmt::Write;

use super::bearing::turn_matrix;
use super::pad_motion::{PadMotionChange, PadMotionSetting};
use super::profile::{self, Profile, TargetFrame};
use super::velocity::FittedVelocity;
use super::{
    PendingTarget, PendingVelocity, PendingVpe, State, TargetOutcome, TimeBase, VelocityMessage,
    UNKNOWN_Q,
};
use crate::filter::{Estimate, FrameEstimate};
use crate::params::{ParamId, VPE_POSITION, VPE_VELOCITY};
use mavlink::dialects::common::{
    LandingTargetType, MavBool, MavEstimatorType, MavFrame, MavSeverity, LANDING_TARGET_DATA,
    ODOMETRY_DATA, VISION_SPEED_ESTIMATE_DATA,
};
use nalgebra::{Matrix3, Vector3};

impl State {
    pub(super) fn on_estimate(&mut self, frame: &FrameEstimate, now_us: u64) -> TargetOutcome {
        self.stats.frames = self.stats.frames.saturating_add(1);
        if let Some(c) = &frame.mount_correction {
            self.on_mount_correction(c);
        }
        let fitted = self.fit_velocity(frame);
        self.vision_gap(frame.exposure_us);
        if !frame.fix_found {
            self.shift.on_gap(&self.config.px4_shift, frame.exposure_us);
            return TargetOutcome::NoFix;
        }
        self.stats.frames_with_fix = self.stats.frames_with_fix.saturating_add(1);
        self.observe_pad_bearing(frame, now_us);
        self.watch_pad_motion(frame);
        let t = frame.exposure_us;
        let Some(profile) = self.profile() else {
            self.stats.no_profile = self.stats.no_profile.saturating_add(1);
            return TargetOutcome::NoProfile;
        };
        let level = frame.estimate.as_ref().and_then(|e| Some((e, e.level?)));
        let fields = match (profile, level) {
            (Profile::ArduPilotLocalFrd, Some((e, l))) => profile::local_frd_fields(
                &l.estimate.position,
                &l.attitude,
                e.orientation_ned.unwrap_or(UNKNOWN_Q),
            ),
            // LOCAL_FRD without the attitude at the exposure: BODY_FRD.
            (Profile::ArduPilot | Profile::ArduPilotLocalFrd, _) => {
                let Some(e) = &frame.estimate else {
                    self.stats.no_estimate = self.stats.no_estimate.saturating_add(1);
                    return TargetOutcome::NoEstimate;
                };
                // Body FRD needs no attitude: the camera is fixed to the body.
                profile::ardupilot_fields(&e.body_frd, e.orientation_body.unwrap_or(UNKNOWN_Q))
            }
            (Profile::Px4, _) => {
                let estimate = frame.estimate.as_ref();
                match estimate.and_then(|e| Some((e, e.level?, e.vehicle_position?))) {
                    Some((e, l, pos)) => {
                        let cam = self.camera_position();
                        let fields = profile::px4_fields(
                            &pos.position,
                            &l.estimate.position,
                            &l.attitude,
                            &cam,
                            e.orientation_ned.unwrap_or(UNKNOWN_Q),
                        );
                        // The pad from the vehicle's origin, as the point itself adds it.
                        let from_origin = l.attitude.body_to_ned(&cam) + l.estimate.position;
                        let shift = self.px4_shift_at(t, &from_origin, &l.estimate);
                        fields.map(|mut f| {
                            f.position.x += shift.x;
                            f.position.y += shift.y;
                            f
                        })
                    }
                    None => {
                        self.shift.on_gap(&self.config.px4_shift, t);
                        // Which of the two is missing: the vehicle state at the exposure, or
                        // (with it) a confirmed, fresh level estimate.
                        let at = self.vehicle.at(t);
                        if at.attitude.is_none() || at.position.is_none() {
                            self.stats.no_vehicle_state =
                                self.stats.no_vehicle_state.saturating_add(1);
                            return TargetOutcome::NoVehicleState;
                        }
                        self.stats.no_estimate = self.stats.no_estimate.saturating_add(1);
                        return TargetOutcome::NoEstimate;
                    }
                }
            }
        };
        let Some(fields) = fields else {
            return TargetOutcome::Invalid;
        };
        let rate = self.params.get(ParamId::RateHz).max(1.0);
        let min_interval_us = (0.9e6 / rate) as u64;
        if self
            .last_target_exposure_us
            .is_some_and(|last| t > last && t - last < min_interval_us)
        {
            return TargetOutcome::RateLimited;
        }
        self.last_target_exposure_us = Some(t);
        let time_usec = match self.time_base() {
            TimeBase::Companion | TimeBase::ByProfile => t,
            TimeBase::Autopilot => self.timesync.to_autopilot(t).unwrap_or(t),
        };
        let data = LANDING_TARGET_DATA {
            time_usec,
            angle_x: fields.angle_x,
            angle_y: fields.angle_y,
            distance: fields.distance,
            size_x: 0.0,
            size_y: 0.0,
            target_num: 0,
            frame: match fields.frame {
                TargetFrame::BodyFrd => MavFrame::MAV_FRAME_BODY_FRD,
                TargetFrame::LocalNed => MavFrame::MAV_FRAME_LOCAL_NED,
                TargetFrame::LocalFrd => MavFrame::MAV_FRAME_LOCAL_FRD,
            },
            x: fields.position.x,
            y: fields.position.y,
            z: fields.position.z,
            q: fields.q,
            mavtype: LandingTargetType::LANDING_TARGET_TYPE_VISION_FIDUCIAL,
            position_valid: MavBool::MAV_BOOL_TRUE,
        };
        if self.target.is_some() {
            self.stats.targets_replaced = self.stats.targets_replaced.saturating_add(1);
        }
        self.target = Some(PendingTarget {
            created_us: now_us,
            exposure_us: t,
            data,
        });
        // Held to the pad (TD_PAD_YAW) or the autopilot's own frame; nothing until the pad's
        // bearing is known, rather than a frame that turns once it is.
        // Nothing from the pad as a fixed point of the world while it moves (`pad_motion`).
        let vpe_enable = if self.pad_moving() {
            0
        } else {
            self.params.get_int(ParamId::VpeEnable)
        };
        let turn = if vpe_enable != 0 {
            self.pad_turn()
        } else {
            None
        };
        // A position held back before take-off holds its velocity back too: either would
        // count as the board's estimates flowing for the autopilot's arming check.
        let mut held = false;
        if vpe_enable & VPE_POSITION != 0 {
            let level = frame.estimate.as_ref().and_then(|e| Some((e, e.level?)));
            if let Some(((e, l), turn)) = level.zip(turn) {
                match self.vision_estimate_for(t, time_usec, &l, turn) {
                    Some(data) => {
                        self.report_view_margin(t, e.view_margin_m, now_us);
                        self.vpe = Some(PendingVpe {
                            created_us: now_us,
                            data,
                        });
                    }
                    None => held = true,
                }
            }
        }
        if let Some((f, turn)) = fitted.zip(turn).filter(|_| !held && vpe_enable != 0) {
            let message = match profile {
                Profile::Px4 => VelocityMessage::Odometry(velocity_odometry(time_usec, &f, turn)),
                Profile::ArduPilot | Profile::ArduPilotLocalFrd => {
                    VelocityMessage::Speed(velocity_speed_estimate(time_usec, &f, turn))
                }
            };
            self.velocity = Some(PendingVelocity {
                created_us: now_us,
                message,
            });
        }
        TargetOutcome::TargetQueued
    }

    /// TD_PAD_MOTION auto: the frame's place of the pad on the ground (the vehicle's position
    /// at the exposure plus the level estimate of the pad against it) into the watch,
    /// and a STATUSTEXT when its decision changes (`pad_motion`).
    fn watch_pad_motion(&mut self, frame: &FrameEstimate) {
        if self.pad_motion_setting() != PadMotionSetting::Auto {
            return;
        }
        let Some((l, p)) = frame
            .estimate
            .as_ref()
            .and_then(|e| Some((e.level?, e.vehicle_position?)))
        else {
            return;
        };
        let place = l.estimate.position + p.position;
        let change = self
            .pad_motion
            .update(frame.exposure_us, nalgebra::Vector2::new(place.x, place.y));
        let mut text = heapless::String::<64>::new();
        let severity = match change {
            None => return,
            Some(PadMotionChange::Moving(speed)) => {
                // Tenths in integers: core's float formatting keeps panic paths (nopanic/).
                let tenths = (speed.clamp(0.0, 999.0) * 10.0 + 0.5) as u32;
                let _ = write!(
                    text,
                    "touchdown: pad moving {}.{} m/s",
                    tenths / 10,
                    tenths % 10
                );
                if self.params.get_int(ParamId::VpeEnable) != 0 {
                    let _ = text.push_str(", vision msgs off");
                }
                MavSeverity::MAV_SEVERITY_WARNING
            }
            Some(PadMotionChange::AtRest) => {
                let _ = text.push_str("touchdown: pad at rest again");
                MavSeverity::MAV_SEVERITY_INFO
            }
        };
        self.stats.pad_motion_changes = self.stats.pad_motion_changes.saturating_add(1);
        self.queue_status_text(severity, &text);
    }

    /// With TD_VPE_EN bit 1, the frame's level position into the velocity fit, and the fit;
    /// `None` (and the fit restarted) for a frame without a level estimate.
    fn fit_velocity(&mut self, frame: &FrameEstimate) -> Option<FittedVelocity> {
        if self.params.get_int(ParamId::VpeEnable) & VPE_VELOCITY == 0 {
            return None;
        }
        let level = frame.estimate.as_ref().and_then(|e| e.level);
        match level.filter(|_| frame.fix_found) {
            Some(l) => self.velocity_fit.push(
                frame.exposure_us,
                l.estimate.position,
                l.estimate.position_covariance.diagonal(),
            ),
            None => {
                self.velocity_fit.clear();
                None
            }
        }
    }

    /// The outer loop's shift for a PX4 target exposed at `t_us` with the pad at `from_origin`
    /// (NED axes, metres) from the vehicle's origin, `level` the estimate (the pad's depth
    /// below the camera, its velocity against the vehicle) ([`super::shift`]).
    fn px4_shift_at(
        &mut self,
        t_us: u64,
        from_origin: &Vector3<f32>,
        level: &Estimate,
    ) -> nalgebra::Vector2<f32> {
        let active = self
            .autopilot_mode
            .is_some_and(|(custom, mode)| super::shift::px4_mode_lands_on_target(custom, mode));
        self.shift.update(
            &self.config.px4_shift,
            self.params.get(ParamId::Px4OuterLoopAlt),
            active,
            &super::shift::ShiftMeasurement {
                exposure_us: t_us,
                offset_ne: nalgebra::Vector2::new(from_origin.x, from_origin.y),
                rate_ne: nalgebra::Vector2::new(level.velocity.x, level.velocity.y),
                height_m: level.position.z,
            },
        )
    }

    /// TD_CAM_POS_X/Y/Z: the camera's position on the vehicle, body FRD, metres.
    pub(super) fn camera_position(&self) -> Vector3<f32> {
        Vector3::new(
            self.params.get(ParamId::CamPosX),
            self.params.get(ParamId::CamPosY),
            self.params.get(ParamId::CamPosZ),
        )
    }
}

/// The vehicle's velocity over the ground, NED turned by `turn` (radians, see
/// [`super::bearing`]), with its covariance: the opposite of the slope of the pad's position
/// against the vehicle, true for a pad that stays where it is.
fn vehicle_velocity(f: &FittedVelocity, turn: f32) -> (Vector3<f32>, Matrix3<f32>) {
    let r = turn_matrix(turn);
    let covariance = r * Matrix3::from_diagonal(&f.variance) * r.transpose();
    (-(r * f.velocity), covariance)
}

/// ODOMETRY carrying the velocity alone (PX4's EKF2 fuses it with EKF2_EV_CTRL bit 2): position
/// and attitude NaN (PX4 takes a field only when it is finite), the velocity in the vision
/// estimate's NED axes turned by `turn` (`child_frame_id` LOCAL_NED: the level estimate is
/// turned by the autopilot's attitude, heading included, then held to the pad, TD_PAD_YAW), its
/// covariance from the fit, the angular rates unknown.
fn velocity_odometry(time_usec: u64, f: &FittedVelocity, turn: f32) -> ODOMETRY_DATA {
    let (v, cov) = vehicle_velocity(f, turn);
    // The 6 x 6 upper triangle, row-major: the velocity's 3 x 3 block at 0-2, 6-7 and 11, the
    // angular rates' variances at 15, 18 and 20 unknown.
    let mut velocity_covariance = [0.0f32; 21];
    for (slot, (r, c)) in [
        (0, (0, 0)),
        (1, (0, 1)),
        (2, (0, 2)),
        (6, (1, 1)),
        (7, (1, 2)),
        (11, (2, 2)),
    ] {
        if let (Some(out), Some(v)) = (velocity_covariance.get_mut(slot), cov.get((r, c))) {
            *out = *v;
        }
    }
    for slot in [15, 18, 20] {
        if let Some(c) = velocity_covariance.get_mut(slot) {
            *c = f32::NAN;
        }
    }
    let mut pose_covariance = [0.0f32; 21];
    pose_covariance[0] = f32::NAN;
    ODOMETRY_DATA {
        time_usec,
        x: f32::NAN,
        y: f32::NAN,
        z: f32::NAN,
        q: [f32::NAN, 0.0, 0.0, 0.0],
        vx: v.x,
        vy: v.y,
        vz: v.z,
        rollspeed: f32::NAN,
        pitchspeed: f32::NAN,
        yawspeed: f32::NAN,
        pose_covariance,
        velocity_covariance,
        frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        child_frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        reset_counter: 0,
        estimator_type: MavEstimatorType::MAV_ESTIMATOR_TYPE_VISION,
        quality: 0,
    }
}

/// VISION_SPEED_ESTIMATE (ArduPilot's AP_VisualOdom): the velocity, NED turned by `turn` (as
/// the vision estimate), with its 3 x 3 covariance row-major.
fn velocity_speed_estimate(
    time_usec: u64,
    f: &FittedVelocity,
    turn: f32,
) -> VISION_SPEED_ESTIMATE_DATA {
    let (v, cov) = vehicle_velocity(f, turn);
    let mut covariance = [0.0f32; 9];
    for (k, slot) in covariance.iter_mut().enumerate() {
        if let Some(c) = cov.get((k / 3, k % 3)) {
            *slot = *c;
        }
    }
    VISION_SPEED_ESTIMATE_DATA {
        usec: time_usec,
        x: v.x,
        y: v.y,
        z: v.z,
        covariance,
        reset_counter: 0,
    }
}
