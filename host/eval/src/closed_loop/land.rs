//! The closed loop's autopilot mode: an ArduPilot-like LAND with precision landing.
//!
//! What it does, and where ArduPilot does it (read in its source; our words, our code):
//! - **Descent** (ArduCopter `mode_land.cpp`, `Mode::land_run_vertical_control`): at
//!   LAND_SPEED_HIGH above LAND_ALT_LOW, at LAND_SPEED below. ArduCopter's defaults
//!   (`Parameters.cpp`, `config.h`, AC_WPNav's WPNAV_SPEED_DN): LAND_SPEED 50 cm/s,
//!   LAND_SPEED_HIGH 0 meaning WPNAV_SPEED_DN, 150 cm/s, LAND_ALT_LOW 1000 cm. The height is
//!   the true height over the pad here (a rangefinder's, without its noise).
//! - **Where to** (`AC_PrecLand`, `mode_land.cpp` with precision landing): the target it
//!   receives becomes the pad's position in its local frame: the LANDING_TARGET's body FRD
//!   vector turned with its attitude at receipt - PLND_LAG
//!   ([`crate::flight::FlightRun::reconstruct_received`], [`crate::flight::reconstruct`]),
//!   plus its own position estimate at that time. The position controller flies to the
//!   newest such estimate; with no target for [`LandParams::target_timeout_s`] (AC_PrecLand's
//!   1 s) the last estimate is kept (a hold over where the pad was last seen); before the
//!   first target it holds where LAND began.
//! - **Pause and final descent** (ArduCopter `mode.cpp`, `Mode::land_run_vertical_control`
//!   with a target acquired): farther than PLND_XY_DIST_MAX (`AC_PrecLand`, default 2.5 m)
//!   from the pad estimate it does not descend; when the newest measurement puts the pad
//!   35-200 cm below, it descends at half LAND_SPEED, slowed by the horizontal error (the
//!   full half at no error, down to 10 cm/s from 15 cm of error on), so that the last
//!   metres give the position controller time. AC_PrecLand keeps its last measurement, so a
//!   pad seen last inside that band keeps the slow descent to the ground; below 35 cm it is
//!   LAND_SPEED again. A target is acquired until 2 s without a measurement
//!   (`LANDING_TARGET_TIMEOUT_MS`).
//! - **Horizontal position control** (`AC_PosControl`, multicopter defaults
//!   PSC_POSXY_P 1.0, PSC_VELXY_P 2.0, PSC_VELXY_I 1.0, PSC_VELXY_D 0.5, PSC_VELXY_IMAX
//!   1000 cm/s/s, PSC_VELXY_FLTE and _FLTD 5 Hz): P on the position error gives a velocity
//!   (limited to [`LandParams::max_speed_mps`]); the velocity PID (`AC_PID_2D::update_all`)
//!   low-passes the velocity error at FLTE, takes P and I on that filtered error and D on its
//!   rate low-passed again at FLTD, and its integrator does not grow while the output is cut
//!   to the lean-angle limit (ANGLE_MAX, [`LandParams::max_tilt_deg`]); that sum is the
//!   acceleration asked of the vehicle ([`super::vehicle::Command`]). Not modelled:
//!   AC_PosControl's jerk-limited shaping of a new target position (`input_pos_vel_accel_xy`,
//!   PSC_JERK_XY): a jump of the pad estimate is a step of the position error here, where
//!   ArduCopter slews its position target to it; a still pad's estimate moves by
//!   centimetres, and the shaping does not change how a gust is rejected.
//!
//! It steers on its own estimates (position with its drift, [`super::LandingConfig`]'s error
//! model), never on the truth.

use nalgebra::{Vector2, Vector3};

use touchdown_sim::trajectory::GRAVITY;

use super::vehicle::Command;

/// The mode's parameters (see the module docs for where each default comes from).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LandParams {
    /// Descent above `land_alt_low_m`, m/s.
    pub land_speed_high_mps: f64,
    /// Where the slow descent starts, metres over the ground.
    pub land_alt_low_m: f64,
    /// Descent below it, m/s.
    pub land_speed_mps: f64,
    /// A target older than this no longer updates the estimate's freshness, seconds.
    pub target_timeout_s: f64,
    /// Position error to velocity, 1/s.
    pub pos_p: f64,
    /// Velocity error to acceleration, 1/s.
    pub vel_p: f64,
    /// Integral gain, 1/s^2.
    pub vel_i: f64,
    /// Derivative gain (on the velocity error), dimensionless.
    pub vel_d: f64,
    /// Largest integral term, m/s^2.
    pub vel_imax: f64,
    /// Cut-off of the velocity error's filter (P and I terms), Hz (PSC_VELXY_FLTE).
    pub vel_error_filter_hz: f64,
    /// Cut-off of the derivative's filter, Hz (PSC_VELXY_FLTD).
    pub vel_d_filter_hz: f64,
    /// The lean-angle limit the integrator stops growing at, degrees (ANGLE_MAX).
    pub max_tilt_deg: f64,
    /// Largest horizontal speed asked, m/s.
    pub max_speed_mps: f64,
    /// PLND_XY_DIST_MAX: no descent farther than this from the pad estimate, metres (0: off).
    pub xy_dist_max_m: f64,
    /// The final descent's band of the measured pad depth, metres (AC_PrecLand's 35-200 cm).
    pub final_band_m: (f64, f64),
    /// Horizontal error at which the final descent is slowed to its least, metres (15 cm).
    pub final_acceptable_error_m: f64,
    /// The final descent's least speed, m/s (10 cm/s).
    pub final_min_speed_mps: f64,
    /// A target keeps the mode precision-landing this long after its last measurement,
    /// seconds (AC_PrecLand's LANDING_TARGET_TIMEOUT_MS, 2 s).
    pub acquired_timeout_s: f64,
}

impl LandParams {
    /// ArduCopter's defaults (module docs).
    pub fn ardupilot() -> Self {
        LandParams {
            land_speed_high_mps: 1.5,
            land_alt_low_m: 10.0,
            land_speed_mps: 0.5,
            target_timeout_s: 1.0,
            pos_p: 1.0,
            vel_p: 2.0,
            vel_i: 1.0,
            vel_d: 0.5,
            vel_imax: 10.0,
            vel_error_filter_hz: 5.0,
            vel_d_filter_hz: 5.0,
            max_tilt_deg: 30.0,
            max_speed_mps: 5.0,
            xy_dist_max_m: 2.5,
            final_band_m: (0.35, 2.0),
            final_acceptable_error_m: 0.15,
            final_min_speed_mps: 0.1,
            acquired_timeout_s: 2.0,
        }
    }
}

/// Which part of the descent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Above LAND_ALT_LOW, at LAND_SPEED_HIGH.
    High,
    /// Below it, at LAND_SPEED.
    Low,
}

/// The mode's state (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct LandController {
    /// Its parameters.
    pub params: LandParams,
    hold_ne: Vector2<f64>,
    /// The pad's estimated position (local NED, north and east) and when it was measured.
    target: Option<(f64, Vector2<f64>)>,
    /// The newest measurement's depth of the pad below the vehicle, metres.
    measured_down_m: Option<f64>,
    integral: Vector2<f64>,
    /// The velocity error low-passed at FLTE (`None` until the first step).
    error: Option<Vector2<f64>>,
    derivative: Vector2<f64>,
    /// The last output when it was beyond the lean-angle limit (zero when it was not).
    limited: Vector2<f64>,
    /// When the first target was used, seconds.
    pub acquired_s: Option<f64>,
    /// When the slow descent began, seconds.
    pub low_s: Option<f64>,
    /// Targets used.
    pub targets_used: usize,
    /// Longest time without a fresh target after the first one, seconds.
    pub longest_gap_s: f64,
}

impl LandController {
    /// LAND engaged at the local position `start_ned` (where it holds until a target comes).
    pub fn new(params: LandParams, start_ned: &Vector3<f64>) -> Self {
        LandController {
            params,
            hold_ne: start_ned.xy(),
            target: None,
            measured_down_m: None,
            integral: Vector2::zeros(),
            error: None,
            derivative: Vector2::zeros(),
            limited: Vector2::zeros(),
            acquired_s: None,
            low_s: None,
            targets_used: 0,
            longest_gap_s: 0.0,
        }
    }

    /// A measurement of the pad's position in the local frame (its position estimate plus the
    /// reconstructed target), for the time `measured_s`, used from `now_s` on; `down_m` is
    /// the reconstructed target's down part (the pad's depth below the vehicle).
    pub fn measure(&mut self, now_s: f64, measured_s: f64, pad_ned: &Vector3<f64>, down_m: f64) {
        if !pad_ned.iter().all(|v| v.is_finite()) || !down_m.is_finite() {
            return;
        }
        self.measured_down_m = Some(down_m);
        if let Some((t, _)) = self.target {
            self.longest_gap_s = self.longest_gap_s.max(measured_s - t);
        }
        self.acquired_s.get_or_insert(now_s);
        self.targets_used += 1;
        self.target = Some((measured_s, pad_ned.xy()));
    }

    /// Whether the newest target is fresh at `now_s`.
    pub fn target_fresh(&self, now_s: f64) -> bool {
        self.target
            .is_some_and(|(t, _)| now_s - t <= self.params.target_timeout_s)
    }

    /// Where it flies to, local north and east: the newest pad estimate (kept past the
    /// timeout), else where LAND began.
    pub fn goal_ne(&self) -> Vector2<f64> {
        self.target.map_or(self.hold_ne, |(_, p)| p)
    }

    /// The command at `now_s` for a step of `dt_s`, from its position and velocity estimates
    /// (local NED) and the height over the ground.
    pub fn command(
        &mut self,
        now_s: f64,
        dt_s: f64,
        position_ned: &Vector3<f64>,
        velocity_ned: &Vector3<f64>,
        height_m: f64,
    ) -> Command {
        let p = self.params;
        let phase = if height_m > p.land_alt_low_m {
            Phase::High
        } else {
            Phase::Low
        };
        if phase == Phase::Low {
            self.low_s.get_or_insert(now_s);
        }
        let mut down_mps = match phase {
            Phase::High => p.land_speed_high_mps,
            Phase::Low => p.land_speed_mps,
        };
        let offset = self.goal_ne() - position_ned.xy();
        let acquired = self
            .target
            .is_some_and(|(t, _)| now_s - t <= p.acquired_timeout_s);
        if acquired {
            let error = offset.norm();
            let (low, high) = p.final_band_m;
            if p.xy_dist_max_m > 0.0 && error > p.xy_dist_max_m {
                down_mps = 0.0;
            } else if self.measured_down_m.is_some_and(|d| d > low && d < high) {
                let half = 0.5 * p.land_speed_mps;
                let slowdown = error * half / p.final_acceptable_error_m;
                down_mps = (half - slowdown).max(p.final_min_speed_mps);
            }
        }
        let mut wanted = offset * p.pos_p;
        if wanted.norm() > p.max_speed_mps {
            wanted *= p.max_speed_mps / wanted.norm();
        }
        // AC_PID_2D: the first step takes the error as it is; later ones low-pass it.
        let raw_error = wanted - velocity_ned.xy();
        let error = match self.error {
            None => raw_error,
            Some(last) => {
                let e = last + (raw_error - last) * low_pass_alpha(dt_s, p.vel_error_filter_hz);
                let rate = (e - last) / dt_s;
                self.derivative +=
                    (rate - self.derivative) * low_pass_alpha(dt_s, p.vel_d_filter_hz);
                e
            }
        };
        self.error = Some(error);
        // While the last output was cut, a step toward the cut may turn the integrator but
        // not lengthen it.
        let step = error * (p.vel_i * dt_s);
        let before = self.integral.norm();
        self.integral += step;
        if step.dot(&self.limited) > 0.0 && self.integral.norm() > before {
            self.integral *= before / self.integral.norm();
        }
        if self.integral.norm() > p.vel_imax {
            self.integral *= p.vel_imax / self.integral.norm();
        }
        let accel = error * p.vel_p + self.integral + self.derivative * p.vel_d;
        let limit = GRAVITY * p.max_tilt_deg.to_radians().tan();
        self.limited = if accel.norm() > limit {
            accel
        } else {
            Vector2::zeros()
        };
        Command {
            accel_ne: accel,
            down_mps,
        }
    }
}

/// The smoothing factor of a first-order low-pass at `cutoff_hz` sampled every `dt_s`
/// (ArduPilot's `calc_lowpass_alpha_dt`).
fn low_pass_alpha(dt_s: f64, cutoff_hz: f64) -> f64 {
    if cutoff_hz <= 0.0 {
        return 1.0;
    }
    let rc = 1.0 / (std::f64::consts::TAU * cutoff_hz);
    dt_s / (dt_s + rc)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::closed_loop::vehicle::{Vehicle, VehicleParams};

    /// The vehicle and the mode with a perfect target from the start: it lands on the pad.
    fn land(wind: Vector3<f64>) -> (Vehicle, LandController) {
        let start = Vector3::new(1.5, -1.3, -20.0);
        let mut v = Vehicle::hovering(VehicleParams::typical(), start);
        let mut c = LandController::new(LandParams::ardupilot(), &start);
        let dt = 0.0025;
        let mut t = 0.0;
        c.measure(t, t, &Vector3::zeros(), 20.0);
        while v.height_m() > 0.0 && t < 120.0 {
            let cmd = c.command(t, dt, &v.position_ned, &v.velocity_ned, v.height_m());
            v.step(dt, &cmd, &wind);
            t += dt;
        }
        (v, c)
    }

    #[test]
    fn a_perfect_target_lands_on_the_pad() {
        let (v, c) = land(Vector3::zeros());
        assert!(v.position_ned.xy().norm() < 0.005, "{}", v.position_ned);
        // 10 m at 1.5 m/s, then 10 m at 0.5 m/s.
        let low = c.low_s.unwrap();
        assert!((low - 6.97).abs() < 0.2, "{low}");
        // In a steady wind the integrator takes it out.
        let (v, _) = land(Vector3::new(4.0, -3.0, 0.0));
        assert!(v.position_ned.xy().norm() < 0.01, "{}", v.position_ned);
    }

    #[test]
    fn without_a_target_it_holds_where_it_began() {
        let start = Vector3::new(2.0, 0.0, -20.0);
        let mut c = LandController::new(LandParams::ardupilot(), &start);
        assert_eq!(c.goal_ne(), start.xy());
        assert!(!c.target_fresh(0.0));
        c.measure(1.0, 0.98, &Vector3::new(0.1, 0.2, 0.0), 20.0);
        assert!(c.target_fresh(1.5) && !c.target_fresh(2.5));
        // Past the timeout the last estimate is kept.
        assert_eq!(c.goal_ne(), Vector2::new(0.1, 0.2));
        assert_eq!(c.acquired_s, Some(1.0));
    }
}
