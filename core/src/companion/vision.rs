//! The vehicle's position for an autopilot that navigates on the pad (TD_VPE_EN bit 0): the
//! VISION_POSITION_ESTIMATE, and the board's word on whether that position is fit to
//! navigate on.
//!
//! Why each part is as it is:
//! - **The vehicle's origin**, not the camera: the lens sits TD_CAM_POS from the point the
//!   autopilot's estimator tracks, turned with the attitude, so the message needs no lever arm
//!   on the autopilot's side (ArduPilot's VISO_POS_*, PX4's EKF2_EV_POS_* stay 0). It is the
//!   same offset the PX4 profile's targets add.
//! - **The covariance holds what the board does not know**: the level track's (the fixes'
//!   noise and the attitude's frame-to-frame noise), plus the tilt errors that no filtering
//!   removes, turned over the line of sight ([`crate::filter::turn_covariance`]): the
//!   mount's ([`LevelEstimate::mount_sigma_deg`]) and the autopilot's slowly varying roll and
//!   pitch error ([`ATTITUDE_BIAS_DEG`]), and the autopilot's heading error
//!   ([`HEADING_SIGMA_DEG`]) turned about the pad's vertical. Each grows with the distance:
//!   before the mount calibration the position high above the pad is worth decimetres, and
//!   a heading error moves a vehicle beside the pad around it; an estimator that fuses the
//!   position must be told so rather than trust centimetres.
//! - **The frame** is the autopilot's, or with TD_PAD_YAW the pad's ([`super::bearing`]):
//!   position, covariance and yaw turned alike, so that what goes out is one frame.
//! - **The reset counter steps when the stream resumes after a gap** ([`RESUME_GAP_US`]):
//!   the track that resumes is a new one, whose first positions need not continue the old
//!   track's last. Both autopilots take a stepped counter as a jump to adopt (ArduPilot's
//!   AP_VisualOdom hands the EKF a reset time, PX4's EKF2 resets its vision fusion), rather
//!   than a measurement to reject against the old track.
//! - **Fit to navigate**: the position's horizontal one sigma within [`FIT_SIGMA_M`] (and
//!   still within [`UNFIT_SIGMA_M`] once fit, so that a sigma near the limit does not
//!   chatter). The board says so, and when it stops being so, in a STATUSTEXT
//!   (`touchdown: position fit to navigate +-0.04 m`, `touchdown: position not fit +-0.31 m`,
//!   `touchdown: position not fit: pad lost`), and keeps the state in its counters
//!   ([`super::CompanionStats::vision_fit`]), and in its SYS_STATUS health (the
//!   vision-position sensor). A pilot or a ground station waits for the first before making
//!   the board the only position source.
//! - **Nothing unfit goes out before take-off**: while the autopilot is disarmed only a fit
//!   position is sent, and a position seen on the ground counts as fit only once the mount is
//!   known to [`TAKE_OFF_MOUNT_SIGMA_DEG`] (calibrated on the pad, or TD_CAM_CAL 0: set by
//!   hand). On the ground the mount's error is a millimetre; at the take-off height it is
//!   decimetres, too late to find out. The autopilots' own arming checks then hold the
//!   vehicle: ArduPilot's visual odometry counts as unhealthy 0.3 s after its last estimate
//!   (`PreArm: VisOdom: not healthy`) and neither autopilot has a position to arm a position
//!   mode on. Once armed every estimate goes out, with its covariance: a vehicle in the air
//!   is better off with a wide estimate than with none. STATUSTEXT `touchdown: position
//!   held: mount not calibrated` says why, once each time a hold starts.
//! - **The view margin**, NAMED_VALUE_FLOAT `TD_VIEW` every [`REPORT_PERIOD_US`] while
//!   estimates flow: how far the vehicle can move before the pad leaves the view
//!   ([`crate::pipeline::view_margin_m`]). Past it the autopilot coasts on its own estimate;
//!   a ground station can plot it, and a pilot flying on the board keeps moves under it.

use core::fmt::Write;

use super::bearing::turn_matrix;
use super::State;
use crate::filter::{turn_covariance, Attitude, LevelEstimate, ATTITUDE_BIAS_DEG};
use crate::params::{ParamId, ParamSet};
use mavlink::dialects::common::{MavSeverity, VISION_POSITION_ESTIMATE_DATA};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// A VISION_POSITION_ESTIMATE this long after the previous one starts a new track (the reset
/// counter steps) and ends a fit position ("pad lost"), µs: longer than a few dropped frames
/// at any frame rate the board runs, shorter than the autopilots' own timeouts for vision
/// data (ArduPilot's VisOdom counts as unhealthy after 0.3 s without, and its EKF stops
/// fusing soon after).
pub const RESUME_GAP_US: u64 = 500_000;

/// The horizontal one sigma at or under which the position becomes fit to navigate, metres:
/// what a landing within 5 cm needs of its source of position.
pub const FIT_SIGMA_M: f32 = 0.10;

/// The horizontal one sigma over which a fit position stops being fit, metres.
pub const UNFIT_SIGMA_M: f32 = 0.15;

/// The mount's tilt error (one sigma, degrees) at or under which a position seen on the
/// ground is fit to take off on: the calibrator's own confidence bound
/// ([`crate::filter::MountCalibrationConfig::max_sigma_deg`]'s default), a tenth of a metre
/// at 12 m.
pub const TAKE_OFF_MOUNT_SIGMA_DEG: f32 = 0.5;

/// Whether the mount is known well enough to take off on the board's position: its one sigma
/// (`mount_sigma_deg`, [`LevelEstimate::mount_sigma_deg`]) within
/// [`TAKE_OFF_MOUNT_SIGMA_DEG`], or TD_CAM_CAL 0 in `params` (the user set the mount by hand,
/// and the board has no way to know it better). What the board holds its position back for
/// before take-off, and what a ground station waits for.
pub fn mount_known_for_take_off(params: &ParamSet, mount_sigma_deg: f32) -> bool {
    params.get_int(ParamId::CamCal) == 0 || mount_sigma_deg <= TAKE_OFF_MOUNT_SIGMA_DEG
}

/// The period of the named values the board reports (the view margin, the pad's bearing),
/// µs: enough to watch, a small part of the link.
pub const REPORT_PERIOD_US: u64 = 500_000;

/// NAMED_VALUE_FLOAT's name for the view margin.
pub const VIEW_MARGIN_NAME: &str = "TD_VIEW";

/// The vision estimate's own state: its reset counter and whether it is fit to navigate.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct VisionState {
    /// The exposure of the last estimate queued, our clock, µs.
    last_exposure_us: Option<u64>,
    /// The reset counter sent.
    reset_counter: u8,
    /// The position is fit to navigate (announced).
    fit: bool,
    /// A hold before take-off has been announced and no estimate has gone out since.
    hold_said: bool,
    /// The exposure after which the next view margin is due, our clock, µs.
    next_margin_us: u64,
}

impl VisionState {
    /// More than [`RESUME_GAP_US`] between the last estimate and an exposure at `exposure_us`.
    fn gap_before(&self, exposure_us: u64) -> bool {
        resumes_after_gap(self.last_exposure_us, exposure_us)
    }
}

/// More than [`RESUME_GAP_US`] between `last_us` (none: nothing yet) and `exposure_us`: what
/// resumes is a new track.
pub(super) fn resumes_after_gap(last_us: Option<u64>, exposure_us: u64) -> bool {
    last_us.is_some_and(|last| exposure_us.saturating_sub(last) > RESUME_GAP_US)
}

/// Whether a report every [`REPORT_PERIOD_US`] of exposures is due at `exposure_us`; if so
/// `next_us`, the exposure after which the next one is, moves on.
pub(super) fn report_due(next_us: &mut u64, exposure_us: u64) -> bool {
    if exposure_us < *next_us {
        return false;
    }
    *next_us = exposure_us.saturating_add(REPORT_PERIOD_US);
    true
}

impl State {
    /// Whether the position is fit to navigate on (announced).
    pub(super) fn vision_fit(&self) -> bool {
        self.vision.fit
    }

    /// With TD_VPE_EN bit 0, the frame's VISION_POSITION_ESTIMATE, stamped `time_usec`, from
    /// `level` exposed at `exposure_us` (our clock), turned by `turn` ([`super::bearing`]);
    /// the reset counter and the fit state move with it. `None`: held back, the autopilot
    /// disarmed and the position not fit to take off on.
    pub(super) fn vision_estimate_for(
        &mut self,
        exposure_us: u64,
        time_usec: u64,
        level: &LevelEstimate,
        turn: f32,
    ) -> Option<VISION_POSITION_ESTIMATE_DATA> {
        let gap = self.vision.gap_before(exposure_us);
        let reset_counter = self.vision.reset_counter.wrapping_add(u8::from(gap));
        let data = vision_estimate(
            time_usec,
            level,
            &self.camera_position(),
            reset_counter,
            turn,
        );
        let sigma = horizontal_sigma(&data);
        let limit = if self.vision.fit {
            UNFIT_SIGMA_M
        } else {
            FIT_SIGMA_M
        };
        let mount_known = mount_known_for_take_off(&self.params, level.mount_sigma_deg);
        let fit = sigma <= limit && (self.autopilot_armed || mount_known);
        self.set_vision_fit(fit, sigma);
        if !fit && !self.autopilot_armed {
            self.stats.vision_held = self.stats.vision_held.saturating_add(1);
            if !self.vision.hold_said {
                self.vision.hold_said = true;
                let text = if mount_known {
                    "touchdown: position held: not fit"
                } else {
                    "touchdown: position held: mount not calibrated"
                };
                self.queue_status_text(MavSeverity::MAV_SEVERITY_WARNING, text);
            }
            return None;
        }
        self.vision.hold_said = false;
        if gap {
            self.stats.vision_resets = self.stats.vision_resets.saturating_add(1);
        }
        self.vision.reset_counter = reset_counter;
        self.vision.last_exposure_us = Some(exposure_us);
        Some(data)
    }

    /// Queues the view margin of the frame exposed at `exposure_us` (our clock), if known and
    /// due, stamped with `now_us`.
    pub(super) fn report_view_margin(
        &mut self,
        exposure_us: u64,
        margin_m: Option<f32>,
        now_us: u64,
    ) {
        let Some(metres) = margin_m.filter(|m| m.is_finite()) else {
            return;
        };
        if report_due(&mut self.vision.next_margin_us, exposure_us) {
            self.queue_named_value(VIEW_MARGIN_NAME, metres, now_us);
        }
    }

    /// Queues NAMED_VALUE_FLOAT `name` = `value`, stamped with `now_us`.
    pub(super) fn queue_named_value(&mut self, name: &'static str, value: f32, now_us: u64) {
        self.enqueue(super::Pending::NamedValue {
            name,
            // MAVLink's milliseconds since boot wrap after 49 days, as the field does.
            time_boot_ms: (now_us / 1000) as u32,
            value,
        });
    }

    /// A frame exposed at `exposure_us` without a vision estimate: a fit position that has
    /// had none for [`RESUME_GAP_US`] is no longer fit.
    pub(super) fn vision_gap(&mut self, exposure_us: u64) {
        if self.vision.fit && self.vision.gap_before(exposure_us) {
            self.set_vision_fit(false, f32::INFINITY);
        }
    }

    /// Moves the fit state to `fit`, announcing a change; `sigma` is the horizontal one
    /// sigma, metres (infinite: the pad was lost).
    fn set_vision_fit(&mut self, fit: bool, sigma: f32) {
        if fit == self.vision.fit {
            return;
        }
        self.vision.fit = fit;
        let mut text = heapless::String::<64>::new();
        // Integers only (core's float formatting keeps panic paths, see nopanic/); `as`
        // saturates. Every text fits MAVLink's 50 bytes.
        let cm = libm::roundf(sigma * 100.0) as u32;
        let (severity, verdict) = if fit {
            (MavSeverity::MAV_SEVERITY_NOTICE, "fit to navigate")
        } else {
            (MavSeverity::MAV_SEVERITY_WARNING, "not fit")
        };
        let _ = if sigma.is_finite() && cm < 10_000 {
            write!(
                text,
                "touchdown: position {verdict} +-{}.{}{} m",
                cm / 100,
                cm / 10 % 10,
                cm % 10
            )
        } else {
            write!(text, "touchdown: position {verdict}: pad lost")
        };
        self.queue_status_text(severity, &text);
    }
}

/// The larger of the north and east one sigmas in a VISION_POSITION_ESTIMATE's covariance,
/// metres (its upper triangle: x x at 0, y y at 6).
fn horizontal_sigma(data: &VISION_POSITION_ESTIMATE_DATA) -> f32 {
    let north = data.covariance.first().copied().unwrap_or(f32::INFINITY);
    let east = data.covariance.get(6).copied().unwrap_or(f32::INFINITY);
    libm::sqrtf(north.max(east))
}

/// One sigma of the frame's heading error, degrees: the board levels the pad with the
/// autopilot's attitude, heading included, so the pad-centred frame is turned by the
/// autopilot's heading error, a compass's: a few degrees; or, held to the pad (TD_PAD_YAW), by
/// the error of the bearing the user measured, no better known.
pub const HEADING_SIGMA_DEG: f32 = 2.0;

/// The covariance a heading error of `sigma_rad` gives the end of `p` (NED): a turn about
/// the vertical, which moves it horizontally, across its horizontal part, by `sigma` times
/// that part's length.
pub(super) fn heading_covariance(p: &Vector3<f32>, sigma_rad: f32) -> Matrix3<f32> {
    let across = Vector3::new(-p.y, p.x, 0.0);
    across * across.transpose() * (sigma_rad * sigma_rad)
}

/// VISION_POSITION_ESTIMATE: the vehicle's origin in a pad-centred frame with NED axes
/// (origin at the pad), i.e. minus the pad's level position from the origin, with the
/// vehicle's attitude; covariance upper triangle (x, y, z, roll, pitch, yaw), row-major: the
/// level track's position covariance plus the mount's and the attitude's tilt errors across
/// the line of sight and the heading's about the vertical, the attitude entries (0.05 rad)²,
/// since the attitude is the autopilot's own.
fn vision_estimate(
    time_usec: u64,
    level: &LevelEstimate,
    cam_pos_body: &Vector3<f32>,
    reset_counter: u8,
    turn: f32,
) -> VISION_POSITION_ESTIMATE_DATA {
    let e = &level.estimate;
    let att: &Attitude = &level.attitude;
    let [w, x, y, z] = att.quaternion_wxyz();
    let q = UnitQuaternion::new_normalize(nalgebra::Quaternion::new(w, x, y, z));
    let (roll, pitch, yaw) = q.euler_angles();
    let mut full = nalgebra::Matrix6::<f32>::zeros();
    let tilt_deg = libm::hypotf(level.mount_sigma_deg, ATTITUDE_BIAS_DEG);
    let position_covariance = e.position_covariance
        + turn_covariance(&e.position, tilt_deg.to_radians())
        + heading_covariance(&e.position, HEADING_SIGMA_DEG.to_radians());
    let r = turn_matrix(turn);
    full.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(r * position_covariance * r.transpose()));
    for k in 3..6 {
        if let Some(v) = full.get_mut((k, k)) {
            *v = 0.05 * 0.05;
        }
    }
    let mut covariance = [0.0f32; 21];
    let mut slots = covariance.iter_mut();
    for r in 0..6 {
        for c in r..6 {
            if let (Some(slot), Some(v)) = (slots.next(), full.get((r, c))) {
                *slot = *v;
            }
        }
    }
    let p = -(r * (att.body_to_ned(cam_pos_body) + e.position));
    // Wrapped into (-pi, pi], where Euler yaw lives.
    let yaw = libm::atan2f(libm::sinf(yaw + turn), libm::cosf(yaw + turn));
    VISION_POSITION_ESTIMATE_DATA {
        usec: time_usec,
        x: p.x,
        y: p.y,
        z: p.z,
        roll,
        pitch,
        yaw,
        covariance,
        reset_counter,
    }
}
