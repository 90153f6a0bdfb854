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
//! - **A moving pad** (PLND_OPTIONS bit 0, [`LandParams::moving_target`]; `AC_PrecLand`'s
//!   Kalman filter, PLND_EST_TYPE 1, and ArduCopter `mode.cpp`'s precision LAND): per
//!   horizontal axis a filter of the pad's position and velocity relative to the vehicle,
//!   predicted every loop with the vehicle's velocity change and a process noise of
//!   PLND_ACC_P_NSE (2.5 m/s^2) times the step on the velocity, fused with each measurement
//!   at a standard deviation of 1 cm per metre of the measured depth (raised by 1 % per
//!   rad/s of the vehicle's rotation rate) plus 2 cm, unless its normalised innovation
//!   squared reaches 3 on either axis (after three such rejections in a row the next is
//!   fused anyway). It starts at the first measurement with the pad at rest over the ground
//!   (a relative velocity of minus the vehicle's, 2 m/s of standard deviation) and steers the
//!   mode only once it has taken measurements for 2 s with no gap over 0.5 s; before that,
//!   and after 2 s without a measurement (the filter then starts again), the mode holds where
//!   it is (where LAND began, or the last goal). Acquired, the goal is the filter's position
//!   run on to the present at its velocity (PLND_LAG's history), and the filter's velocity
//!   of the pad over the ground is fed forward to the position controller, added to its
//!   position P's output (`input_pos_vel_accel_xy`). Without the option (the default, and
//!   the model for a pad at rest) none of this runs and the mode flies to the newest
//!   measurement as above (ArduPilot runs the filter then too, with no velocity fed
//!   forward; the model keeps its simpler path, whose figures are the documented ones). The
//!   filter here runs on the pad's position in a frame the mode dead-reckons from its
//!   velocity estimate, which is the same filter as ArduPilot's relative one: the vehicle's
//!   part is known, so the difference carries the same covariance. The shaping above is not
//!   modelled here either: a pad that drove off during the filter's settling is a jump of
//!   metres of the goal when it is acquired, flown as a step.
//!
//! It steers on its own estimates (position with its drift, [`super::LandingConfig`]'s error
//! model), never on the truth.

use std::collections::VecDeque;

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
    /// PLND_OPTIONS bit 0, a moving landing target: the pad's position and velocity come from
    /// the target filter ([`TargetFilter`]) and its velocity is fed forward to the position
    /// controller (see the module docs). Off by default, as in ArduPilot.
    pub moving_target: bool,
    /// PLND_ACC_P_NSE: the target filter's process noise, the change of the relative
    /// velocity it allows per second of prediction, m/s^2.
    pub acc_p_nse: f64,
    /// The target filter settles this long after its first measurement before the mode
    /// steers on it, seconds (AC_PrecLand's EKF_INIT_TIME_MS).
    pub filter_init_s: f64,
    /// While it settles, a gap between measurements longer than this restarts it, seconds
    /// (AC_PrecLand's EKF_INIT_SENSOR_MIN_UPDATE_MS).
    pub filter_init_gap_s: f64,
    /// The target filter settled before LAND began: AC_PrecLand runs its filter in every
    /// mode, and a landing starts from a hover with the pad in view (as the SITL rehearsals
    /// do, and as the model without the option steers on its first target), so its first
    /// start steers at once; a later restart (the target lost) settles for
    /// `filter_init_s` again. Off: the filter starts cold at LAND (the pad first seen then).
    pub filter_settled_at_land: bool,
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
            moving_target: false,
            acc_p_nse: 2.5,
            filter_init_s: 2.0,
            filter_init_gap_s: 0.5,
            filter_settled_at_land: true,
        }
    }

    /// ArduCopter's defaults with PLND_OPTIONS bit 0 set (a moving landing target).
    pub fn ardupilot_moving_target() -> Self {
        LandParams {
            moving_target: true,
            ..LandParams::ardupilot()
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
    /// With [`LandParams::moving_target`]: the target filter, from its first measurement until
    /// it fails to settle or loses the target.
    filter: Option<TargetFilter>,
    /// With [`LandParams::moving_target`]: the vehicle's position dead-reckoned from its
    /// velocity estimate (the target filter's frame), north and east.
    dead_reckoned: Vector2<f64>,
    /// Its recent values (time, position), to place a measurement at its own time.
    track: VecDeque<(f64, Vector2<f64>)>,
    /// The control loop's step, the target filter's prediction step, seconds.
    step_s: f64,
    /// The newest goal flown to on the target filter, kept when it loses the target.
    last_goal_ne: Option<Vector2<f64>>,
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
            filter: None,
            dead_reckoned: Vector2::zeros(),
            track: VecDeque::new(),
            step_s: DEFAULT_STEP_S,
            last_goal_ne: None,
        }
    }

    /// A measurement of the pad, for the time `measured_s`, used from `now_s` on: the
    /// reconstructed vector from the vehicle to the pad (local NED; its down part is the
    /// pad's depth below the vehicle) and the vehicle's position estimate at `measured_s`
    /// (their sum is the pad's position in the local frame); `gyro_rad_s` is the vehicle's
    /// rotation rate when it arrives (the target filter trusts a measurement less while
    /// the vehicle turns).
    pub fn measure(
        &mut self,
        now_s: f64,
        measured_s: f64,
        own_ned: &Vector3<f64>,
        relative_ned: &Vector3<f64>,
        gyro_rad_s: f64,
    ) {
        let pad_ned = own_ned + relative_ned;
        let down_m = relative_ned.z;
        if !pad_ned.iter().all(|v| v.is_finite()) || !down_m.is_finite() {
            return;
        }
        self.measured_down_m = Some(down_m);
        if let Some((t, _)) = self.target {
            self.longest_gap_s = self.longest_gap_s.max(measured_s - t);
        }
        self.targets_used += 1;
        self.target = Some((measured_s, pad_ned.xy()));
        if !self.params.moving_target {
            self.acquired_s.get_or_insert(now_s);
            return;
        }
        // The filter's measurement: the pad in the dead-reckoned frame at its time.
        let z = self.dead_reckoned_at(measured_s) + relative_ned.xy();
        let variance = measurement_variance(down_m, gyro_rad_s);
        let noise = self.params.acc_p_nse;
        let step_s = self.step_s;
        match &mut self.filter {
            None => {
                let mut filter = TargetFilter::start(now_s, measured_s, &z, variance);
                // Settled in the hover before LAND: steers on its first target.
                if self.params.filter_settled_at_land && self.acquired_s.is_none() {
                    filter.acquired = true;
                    self.acquired_s = Some(now_s);
                }
                self.filter = Some(filter);
            }
            Some(filter) => {
                filter.predict_to(measured_s, step_s, noise);
                filter.update(now_s, &z, variance);
            }
        }
    }

    /// The dead-reckoned position at `t_s`, from its recent track (the oldest or newest kept
    /// outside it).
    fn dead_reckoned_at(&self, t_s: f64) -> Vector2<f64> {
        let after = self.track.partition_point(|(t, _)| *t < t_s);
        match (
            after.checked_sub(1).map(|k| self.track[k]),
            self.track.get(after),
        ) {
            (Some((t0, p0)), Some(&(t1, p1))) if t1 > t0 => {
                p0 + (p1 - p0) * ((t_s - t0) / (t1 - t0))
            }
            (_, Some(&(_, p))) | (Some((_, p)), None) => p,
            (None, None) => self.dead_reckoned,
        }
    }

    /// Whether the mode steers on the target filter: [`LandParams::moving_target`], and the
    /// filter settled and not lost.
    pub fn filter_acquired(&self) -> bool {
        self.filter.as_ref().is_some_and(|f| f.acquired)
    }

    /// The pad's velocity fed forward to the position controller, north and east, m/s: the
    /// target filter's estimate while it is acquired with [`LandParams::moving_target`],
    /// else zero (a pad at rest).
    pub fn target_velocity_ne(&self) -> Vector2<f64> {
        match &self.filter {
            Some(f) if f.acquired => f.velocity(),
            _ => Vector2::zeros(),
        }
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
        let (offset, feed_forward, acquired) = if p.moving_target {
            self.follow_filter(now_s, dt_s, position_ned, velocity_ned)
        } else {
            let acquired = self
                .target
                .is_some_and(|(t, _)| now_s - t <= p.acquired_timeout_s);
            (self.goal_ne() - position_ned.xy(), None, acquired)
        };
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
        // AC_PosControl adds the velocity feed-forward after its position P's limit.
        if let Some(v) = feed_forward {
            wanted += v;
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

impl LandController {
    /// With [`LandParams::moving_target`], one step of the target filter's bookkeeping at
    /// `now_s`: the dead reckoning, the filter's settling and losing the target, and where
    /// to fly: (the horizontal offset to the goal, the velocity fed forward, whether the
    /// target is acquired).
    fn follow_filter(
        &mut self,
        now_s: f64,
        dt_s: f64,
        position_ned: &Vector3<f64>,
        velocity_ned: &Vector3<f64>,
    ) -> (Vector2<f64>, Option<Vector2<f64>>, bool) {
        let p = self.params;
        self.step_s = dt_s;
        self.track.push_back((now_s, self.dead_reckoned));
        while self
            .track
            .front()
            .is_some_and(|(t, _)| now_s - t > TRACK_KEPT_S)
        {
            self.track.pop_front();
        }
        let here = self.dead_reckoned;
        self.dead_reckoned += velocity_ned.xy() * dt_s;
        if let Some(f) = &mut self.filter {
            let silent_s = now_s - f.fused_s;
            if silent_s > p.acquired_timeout_s {
                // Lost: it holds where it last flew to until the filter starts again.
                self.filter = None;
            } else if !f.acquired {
                if silent_s > p.filter_init_gap_s {
                    self.filter = None;
                } else if now_s - f.started_s > p.filter_init_s {
                    f.acquired = true;
                    self.acquired_s.get_or_insert(now_s);
                }
            }
        }
        match &self.filter {
            Some(f) if f.acquired => {
                let goal = position_ned.xy() + (f.position_at(now_s) - here);
                self.last_goal_ne = Some(goal);
                (goal - position_ned.xy(), Some(f.velocity()), true)
            }
            _ => {
                let hold = self.last_goal_ne.unwrap_or(self.hold_ne);
                (hold - position_ned.xy(), None, false)
            }
        }
    }
}

/// ArduPilot's measurement variance of the target's horizontal position, m^2: a centimetre
/// per metre of depth, more while the vehicle turns, and two centimetres at any depth.
fn measurement_variance(down_m: f64, gyro_rad_s: f64) -> f64 {
    let sd = down_m * (0.01 + 0.01 * gyro_rad_s) + 0.02;
    sd * sd
}

/// How long the dead-reckoned track is kept, seconds: longer than a measurement's age
/// (PLND_LAG and the link) when it arrives.
const TRACK_KEPT_S: f64 = 1.0;
/// The target filter's prediction step until the first control step, seconds (400 Hz).
const DEFAULT_STEP_S: f64 = 0.0025;
/// The target filter's velocity uncertainty when it starts, m/s (the pad taken to be at rest
/// over the ground).
const FILTER_START_VEL_SD: f64 = 2.0;
/// Consecutive measurements the target filter rejects before it takes the next anyway.
const MAX_REJECTED: u32 = 3;
/// The normalised innovation squared beyond which a measurement is rejected.
const NIS_GATE: f64 = 3.0;

/// One axis of the target filter: the pad's position and velocity along it and their
/// covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Axis {
    pos: f64,
    vel: f64,
    var_pos: f64,
    cov: f64,
    var_vel: f64,
}

impl Axis {
    /// One prediction step of `dt_s`: the position runs on at the velocity, which may have
    /// changed by `noise` (a standard deviation).
    fn predict(&mut self, dt_s: f64, noise: f64) {
        self.pos += self.vel * dt_s;
        self.var_pos += dt_s * (2.0 * self.cov + dt_s * self.var_vel);
        self.cov += dt_s * self.var_vel;
        self.var_vel += noise * noise;
    }

    /// The normalised innovation squared of a position measurement `z` of variance `r`.
    fn nis(&self, z: f64, r: f64) -> f64 {
        let innovation = z - self.pos;
        innovation * innovation / (self.var_pos + r)
    }

    /// Fuses a position measurement `z` of variance `r`.
    fn fuse(&mut self, z: f64, r: f64) {
        let s = self.var_pos + r;
        let (k_pos, k_vel) = (self.var_pos / s, self.cov / s);
        let innovation = z - self.pos;
        self.pos += k_pos * innovation;
        self.vel += k_vel * innovation;
        self.var_vel -= k_vel * self.cov;
        self.var_pos *= r / s;
        self.cov *= r / s;
    }
}

/// AC_PrecLand's Kalman filter (PLND_EST_TYPE 1; module docs): per horizontal axis the
/// pad's position and velocity, in the frame the controller dead-reckons from its velocity
/// estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetFilter {
    north: Axis,
    east: Axis,
    /// The time its state is for (its newest measurement's), seconds.
    t_s: f64,
    /// When it started, seconds.
    started_s: f64,
    /// When it last took a measurement, seconds.
    fused_s: f64,
    /// Measurements rejected in a row.
    rejected: u32,
    /// Whether it has settled (the mode steers on it).
    acquired: bool,
}

impl TargetFilter {
    /// Started at `now_s` on a measurement `z` of variance `variance` for `measured_s`,
    /// the pad at rest.
    fn start(now_s: f64, measured_s: f64, z: &Vector2<f64>, variance: f64) -> Self {
        let axis = |pos| Axis {
            pos,
            vel: 0.0,
            var_pos: variance,
            cov: 0.0,
            var_vel: FILTER_START_VEL_SD * FILTER_START_VEL_SD,
        };
        TargetFilter {
            north: axis(z.x),
            east: axis(z.y),
            t_s: measured_s,
            started_s: now_s,
            fused_s: now_s,
            rejected: 0,
            acquired: false,
        }
    }

    /// Predicts to `t_s` in steps of at most `step_s`, with a velocity noise of `acc_p_nse`
    /// per second in each (as ArduPilot predicts every loop).
    fn predict_to(&mut self, t_s: f64, step_s: f64, acc_p_nse: f64) {
        let span = t_s - self.t_s;
        if span <= 0.0 {
            return;
        }
        let steps = (span / step_s).ceil().max(1.0);
        let dt = span / steps;
        for _ in 0..steps as usize {
            self.north.predict(dt, acc_p_nse * dt);
            self.east.predict(dt, acc_p_nse * dt);
        }
        self.t_s = t_s;
    }

    /// A measurement `z` of variance `variance`, arriving at `now_s`: fused unless it is an
    /// outlier on either axis, and then after [`MAX_REJECTED`] rejections in a row anyway.
    fn update(&mut self, now_s: f64, z: &Vector2<f64>, variance: f64) {
        let nis = self
            .north
            .nis(z.x, variance)
            .max(self.east.nis(z.y, variance));
        if nis < NIS_GATE || self.rejected >= MAX_REJECTED {
            self.rejected = 0;
            self.north.fuse(z.x, variance);
            self.east.fuse(z.y, variance);
            self.fused_s = now_s;
        } else {
            self.rejected += 1;
        }
    }

    /// The pad's position at `t_s`, run on from its state at its estimated velocity.
    fn position_at(&self, t_s: f64) -> Vector2<f64> {
        let dt = t_s - self.t_s;
        Vector2::new(
            self.north.pos + self.north.vel * dt,
            self.east.pos + self.east.vel * dt,
        )
    }

    /// The pad's estimated velocity over the ground, north and east, m/s.
    fn velocity(&self) -> Vector2<f64> {
        Vector2::new(self.north.vel, self.east.vel)
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
        c.measure(t, t, &start, &-start, 0.0);
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
        c.measure(
            1.0,
            0.98,
            &Vector3::zeros(),
            &Vector3::new(0.1, 0.2, 20.0),
            0.0,
        );
        assert!(c.target_fresh(1.5) && !c.target_fresh(2.5));
        // Past the timeout the last estimate is kept.
        assert_eq!(c.goal_ne(), Vector2::new(0.1, 0.2));
        assert_eq!(c.acquired_s, Some(1.0));
    }

    /// A pad driving at `pad_velocity` (north, east) from the origin, seen perfectly every
    /// 0.1 s with 30 ms of age, by a vehicle landing on it from 20 m with `params`: the
    /// vehicle's horizontal distance from the pad at touchdown, and the mode.
    fn land_on_a_moving_pad(
        params: LandParams,
        pad_velocity: Vector2<f64>,
    ) -> (f64, LandController) {
        let start = Vector3::new(1.5, -1.3, -20.0);
        let mut v = Vehicle::hovering(VehicleParams::typical(), start);
        let mut c = LandController::new(params, &start);
        let dt = 0.0025;
        let pad = |t: f64| pad_velocity * t;
        let mut history = vec![(0.0, v.position_ned)];
        let mut t = 0.0;
        let mut next_frame = 0.0;
        while v.height_m() > 0.0 && t < 120.0 {
            if t >= next_frame {
                next_frame += 0.1;
                let measured = t - 0.03;
                if let Some(&(_, own)) = history.iter().rev().find(|(s, _)| *s <= measured) {
                    let to_pad = pad(measured) - own.xy();
                    let relative = Vector3::new(to_pad.x, to_pad.y, -own.z);
                    c.measure(t, measured, &own, &relative, 0.0);
                }
            }
            let cmd = c.command(t, dt, &v.position_ned, &v.velocity_ned, v.height_m());
            v.step(dt, &cmd, &Vector3::zeros());
            t += dt;
            history.push((t, v.position_ned));
        }
        ((v.position_ned.xy() - pad(t)).norm(), c)
    }

    #[test]
    fn with_the_moving_target_option_it_lands_on_a_pad_driving_at_1_m_s() {
        let velocity = Vector2::new(1.0, 0.0);
        // Settled in the hover before LAND: it steers on its first measurement (at 0.1 s).
        let (miss, c) = land_on_a_moving_pad(LandParams::ardupilot_moving_target(), velocity);
        assert!(miss < 0.02, "{miss}");
        assert!(
            c.acquired_s.is_some_and(|t| (t - 0.1).abs() < 1e-6),
            "{:?}",
            c.acquired_s
        );
        // Starting cold at LAND: it steered on the filter 2 s after its first measurement,
        // and flies with the pad's velocity fed forward.
        let cold = LandParams {
            filter_settled_at_land: false,
            ..LandParams::ardupilot_moving_target()
        };
        let (miss, c) = land_on_a_moving_pad(cold, velocity);
        assert!(miss < 0.02, "{miss}");
        assert!(
            (c.acquired_s.unwrap() - 2.1).abs() < 0.01,
            "{:?}",
            c.acquired_s
        );
        assert!(c.filter_acquired());
        let ff = c.target_velocity_ne();
        assert!((ff - velocity).norm() < 0.05, "{ff}");
        // Without it the position controller trails the pad (its P on the position error
        // alone has to ask for the pad's speed).
        let (miss, c) = land_on_a_moving_pad(LandParams::ardupilot(), velocity);
        assert!(miss > 0.5, "{miss}");
        assert_eq!(c.target_velocity_ne(), Vector2::zeros());
        assert!(!c.filter_acquired());
    }

    #[test]
    fn the_target_filter_settles_before_it_steers_and_restarts_after_a_gap() {
        let start = Vector3::new(0.0, 0.0, -10.0);
        let cold = LandParams {
            filter_settled_at_land: false,
            ..LandParams::ardupilot_moving_target()
        };
        let mut c = LandController::new(cold, &start);
        let relative = Vector3::new(1.0, 0.0, 10.0);
        let mut t = 0.0;
        while t < 1.9 {
            c.measure(t, t, &start, &relative, 0.0);
            c.command(t, 0.1, &start, &Vector3::zeros(), 10.0);
            t += 0.1;
        }
        // Settling: it holds where LAND began, nothing fed forward, no descent pause.
        assert!(!c.filter_acquired());
        assert_eq!(c.acquired_s, None);
        assert_eq!(c.target_velocity_ne(), Vector2::zeros());
        let cmd = c.command(t, 0.1, &start, &Vector3::zeros(), 10.0);
        assert!(cmd.accel_ne.norm() < 1e-9, "{:?}", cmd.accel_ne);
        // A gap past the settling's limit: it starts again at the next measurement.
        t += 0.6;
        c.command(t, 0.1, &start, &Vector3::zeros(), 10.0);
        assert!(c.filter.is_none());
        c.measure(t, t, &start, &relative, 0.0);
        let restarted = t;
        while t < restarted + 2.15 {
            c.measure(t, t, &start, &relative, 0.0);
            c.command(t, 0.1, &start, &Vector3::zeros(), 10.0);
            t += 0.1;
        }
        assert!(c.filter_acquired());
        assert!(c.acquired_s.unwrap() > restarted + 2.0);
        // It flies toward the pad, 1 m north.
        let cmd = c.command(t, 0.1, &start, &Vector3::zeros(), 10.0);
        assert!(cmd.accel_ne.x > 0.5, "{:?}", cmd.accel_ne);
    }

    #[test]
    fn the_target_filter_learns_a_velocity_and_gates_outliers() {
        let variance = measurement_variance(5.0, 0.0);
        let mut f = TargetFilter::start(0.0, 0.0, &Vector2::zeros(), variance);
        // The pad drives 2 m/s east, measured every 0.1 s.
        for k in 1..=40 {
            let t = 0.1 * f64::from(k);
            f.predict_to(t, 0.0025, 2.5);
            f.update(t, &Vector2::new(0.0, 2.0 * t), variance);
        }
        assert!(
            (f.velocity() - Vector2::new(0.0, 2.0)).norm() < 0.05,
            "{}",
            f.velocity()
        );
        assert!((f.position_at(4.5) - Vector2::new(0.0, 9.0)).norm() < 0.05);
        // A measurement 3 m off is rejected three times in a row, and taken the fourth.
        let settled = f;
        for k in 1..=3 {
            f.update(4.0, &Vector2::new(3.0, 8.0), variance);
            assert_eq!(f.rejected, k);
            assert_eq!(f.north, settled.north);
        }
        f.update(4.0, &Vector2::new(3.0, 8.0), variance);
        assert_eq!(f.rejected, 0);
        assert!(f.north.pos > 0.3, "{:?}", f.north);
    }
}
