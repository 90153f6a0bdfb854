//! Our pad tracker: a time-stamped 3-D constant-velocity Kalman filter with gating, recovery
//! and a lifecycle that never reports a stale pad.
//!
//! # Which frame to filter in
//!
//! The pad is static in the world; the camera moves and rotates with the vehicle. A
//! constant-velocity model is only a good model of something that moves smoothly, so the
//! frame matters:
//!
//! - **With the vehicle's attitude (the intended set-up)**: filter the pad position relative
//!   to the vehicle, expressed in **NED axes** (origin at the vehicle, axes north, east, down;
//!   MAVLink's LOCAL_OFFSET_NED). Rotating the vehicle does not move the pad in this frame, and
//!   the pad's relative velocity is minus the vehicle's velocity, which changes slowly during a
//!   landing: the constant-velocity model fits, with a small acceleration noise
//!   ([`TrackerConfig::level`]). NED rather than the yaw-aligned LOCAL_FRD, because a yaw
//!   rotation would turn a static pad in LOCAL_FRD. Rotate each camera-frame pose into this
//!   frame with [`super::axes::level_measurement`], add the error of the attitude it was
//!   rotated with to its covariance ([`super::level_covariance`]: without it a far fix's
//!   sideways shake reads as range), and convert the estimate back with the functions of
//!   [`super::axes`] (body FRD for ArduPilot, absolute LOCAL_NED for PX4).
//! - **Without attitude**: filter in the camera frame. Every tilt of the vehicle then moves
//!   the pad in the image (1° at 20 m is 35 cm), which the model can only absorb as
//!   acceleration noise, so [`TrackerConfig::camera_frame`] uses a much larger one and the
//!   smoothing is correspondingly weaker.
//!
//! The tracker itself is frame-agnostic: it filters whatever frame the measurements are in.
//! Do not mix frames in one track; call [`Tracker::reset`] when switching.
//!
//! # Model
//!
//! State `[p; v]` (6), `p` in metres, `v` in m/s. Between two time stamps `dt` apart,
//! `p += v dt`, with white acceleration noise of spectral density `q`
//! ([`TrackerConfig::accel_psd`], m²/s³) on each axis: `Q = q [dt³/3 I, dt²/2 I; dt²/2 I,
//! dt I]`. The time step comes from the measurements' time stamps, so a dropped frame is just
//! a longer step. A constant-velocity filter has no steady-state lag on a target moving at
//! constant velocity (a descent at constant speed): the estimate at the time of a measurement
//! is unbiased, unlike a random-walk filter such as the paper's.
//!
//! The measurement is the position with the pose's covariance `R` (plus a floor of
//! [`TrackerConfig::min_measurement_sigma`], and its smallest eigenvalues raised to at most
//! [`MAX_MEASUREMENT_ANISOTROPY`] below its largest): the filter trusts a near, sharp pose more
//! than a far one, and trusts the range of a pose less than its direction. The covariance update uses the Joseph form, `P = (I-KH) P (I-KH)^T + K R K^T`,
//! symmetrised, which stays symmetric positive definite in f32 where `(I-KH) P` does not; a
//! Cholesky check after each update repairs (keeps the diagonal) the never-yet-observed case
//! where rounding breaks it, and counts it ([`Tracker::repairs`]).
//!
//! Only the posterior at the last accepted update is stored. Predictions (for gating a new
//! measurement, or for [`Tracker::estimate`] at any later time) are computed from it, which for
//! this model is exact and avoids accumulating rounding over many small predictions.
//!
//! # Gating and recovery
//!
//! A measurement whose squared Mahalanobis distance to the prediction, `y^T S^-1 y`, exceeds
//! [`TrackerConfig::gate_d2`] (chi-square, 3 degrees of freedom: 16.27 is 99.9 %) is not fused
//! ([`UpdateOutcome::Gated`]). Gated measurements feed a second, *candidate* filter instead;
//! when [`TrackerConfig::recovery_count`] consecutive gated measurements agree with each other
//! (each passes the candidate's gate), the pad really did jump (a new marker, a yaw reset of the
//! flight controller, a wrong track) and the candidate, velocity included, replaces the track
//! ([`UpdateOutcome::Reset`]). Any accepted measurement discards the candidate, so isolated
//! outliers between good measurements never take over.
//!
//! # Lifecycle and time
//!
//! - [`TrackState::Searching`]: no confirmed track yet. A first measurement starts a tentative
//!   track, which is confirmed after [`TrackerConfig::confirm_count`] accepted measurements (a
//!   single false detection never reaches the flight controller). A tentative track that gates
//!   a measurement is replaced by a new one started from it.
//! - [`TrackState::Tracking`]: a confirmed track whose last accepted update is at most
//!   [`TrackerConfig::lost_timeout_us`] old.
//! - [`TrackState::Lost`]: there was a confirmed track and it timed out (or the clock jumped
//!   back); a new tentative track may be under way and becomes `Tracking` when confirmed.
//!
//! [`Tracker::estimate`] returns `None` unless the track is confirmed and its last accepted
//! update is at most [`TrackerConfig::max_coast_us`] old: a short gap (a dropped frame or two)
//! is bridged by prediction, a longer one yields nothing. Never stale.
//!
//! Time stamps are `u64` microseconds. Time going backwards: a measurement older than the
//! newest time seen by at most [`TrackerConfig::max_backwards_us`] is an out-of-order frame and
//! is ignored ([`RejectReason::OutOfOrder`]); further back, the clock itself was reset (a
//! reboot, a new time sync) and the tracker restarts from that measurement
//! ([`UpdateOutcome::Reset`]). [`Tracker::predict_to`] with an older time is a no-op.
//!
//! The Kalman filter itself (state, prediction, gated correction, covariance repair) is in
//! `kf`, and the 3x3 symmetric eigen-decomposition that conditions measurement covariances in
//! `eigen`: this module is the tracker's public surface and its track management (gating,
//! candidates, confirmation, loss).

mod eigen;
mod kf;

use eigen::symmetric_eigen3;
use kf::{block3, symmetrised3, Kf};

use super::Measurement;
use nalgebra::{Matrix3, Matrix6, Vector3};

/// Chi-square quantile, 3 degrees of freedom, 99.9 %.
pub const CHI2_3DOF_999: f32 = 16.27;

/// Largest accepted |position| coordinate, metres: anything beyond is not a landing pad.
const MAX_ABS_POSITION_M: f32 = 1.0e4;
/// Largest accepted measurement variance, m².
const MAX_VARIANCE_M2: f32 = 1.0e6;
/// Largest lost timeout, so a prediction step is bounded (and so is the covariance growth).
const MAX_LOST_TIMEOUT_US: u64 = 10_000_000;
/// Smallest variance kept by the (never-yet-needed) covariance repair, m² or (m/s)².
const REPAIR_FLOOR: f32 = 1.0e-9;
/// Largest ratio between a measurement covariance's largest and smallest eigenvalue: smaller
/// ones are raised to this ratio. A pose's range variance exceeds its cross-range variance by
/// `(k d / (k_c s))²`, a few thousand at 30 m; 10⁵ leaves room while keeping the 6x6 f32
/// covariance well enough conditioned to stay positive definite through the Joseph update.
pub const MAX_MEASUREMENT_ANISOTROPY: f32 = 1.0e5;
/// Smallest allowed `min_measurement_sigma`, metres (f32 conditioning, see above).
pub const MIN_MEASUREMENT_SIGMA_FLOOR: f32 = 1.0e-3;

/// Tuning of [`Tracker`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerConfig {
    /// White-acceleration spectral density per axis, m²/s³ (the process noise).
    pub accel_psd: f32,
    /// Gate on the squared Mahalanobis distance of a measurement (chi-square, 3 dof).
    pub gate_d2: f32,
    /// Consecutive, mutually consistent gated measurements that re-initialise the track (>= 2).
    pub recovery_count: u8,
    /// Accepted measurements before a new track is confirmed and reported (>= 1).
    pub confirm_count: u8,
    /// Longest time since the last accepted update for which an estimate is still given, µs.
    pub max_coast_us: u64,
    /// Time without an accepted update after which the track is dropped, µs
    /// (>= `max_coast_us`, <= 10 s).
    pub lost_timeout_us: u64,
    /// How far back a measurement may be and still count as merely out of order, µs; further
    /// back means the clock was reset.
    pub max_backwards_us: u64,
    /// Standard deviation of the velocity of a new track, m/s.
    pub initial_velocity_sigma: f32,
    /// Floor added to every measurement's standard deviation (in quadrature), metres
    /// (>= 1 mm: no pose is better, and f32 needs it).
    pub min_measurement_sigma: f32,
}

impl TrackerConfig {
    /// Filtering the pad relative to the vehicle in NED axes (attitude known): the pad is
    /// static there and its relative velocity is the vehicle's, so the process noise only has
    /// to cover the vehicle's acceleration changes. Tuned for 30 Hz.
    pub const fn level() -> Self {
        TrackerConfig {
            accel_psd: 0.5,
            gate_d2: CHI2_3DOF_999,
            recovery_count: 5,
            confirm_count: 3,
            max_coast_us: 100_000,
            lost_timeout_us: 1_000_000,
            max_backwards_us: 500_000,
            initial_velocity_sigma: 2.0,
            min_measurement_sigma: 0.005,
        }
    }

    /// Filtering in the camera frame (no attitude): the vehicle's tilting moves the pad in this
    /// frame, so a much larger process noise.
    pub const fn camera_frame() -> Self {
        let mut c = TrackerConfig::level();
        c.accel_psd = 8.0;
        c
    }

    /// Checks the values; [`Tracker::new`] calls it.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.accel_psd > 0.0) || !self.accel_psd.is_finite() {
            return Err(ConfigError::ProcessNoise);
        }
        if !(self.gate_d2 > 0.0) || !self.gate_d2.is_finite() {
            return Err(ConfigError::Gate);
        }
        if self.recovery_count < 2 {
            return Err(ConfigError::RecoveryCount);
        }
        if self.confirm_count < 1 {
            return Err(ConfigError::ConfirmCount);
        }
        if self.lost_timeout_us == 0
            || self.lost_timeout_us > MAX_LOST_TIMEOUT_US
            || self.max_coast_us > self.lost_timeout_us
        {
            return Err(ConfigError::Timeouts);
        }
        if !(self.initial_velocity_sigma > 0.0) || !self.initial_velocity_sigma.is_finite() {
            return Err(ConfigError::InitialVelocity);
        }
        if !(self.min_measurement_sigma >= MIN_MEASUREMENT_SIGMA_FLOOR)
            || !self.min_measurement_sigma.is_finite()
        {
            return Err(ConfigError::MeasurementFloor);
        }
        Ok(())
    }
}

impl Default for TrackerConfig {
    fn default() -> Self {
        TrackerConfig::level()
    }
}

/// A [`TrackerConfig`] value out of range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// `accel_psd` must be finite and > 0.
    ProcessNoise,
    /// `gate_d2` must be finite and > 0.
    Gate,
    /// `recovery_count` must be >= 2.
    RecoveryCount,
    /// `confirm_count` must be >= 1.
    ConfirmCount,
    /// Need `0 < lost_timeout_us <= 10 s` and `max_coast_us <= lost_timeout_us`.
    Timeouts,
    /// `initial_velocity_sigma` must be finite and > 0.
    InitialVelocity,
    /// `min_measurement_sigma` must be finite and >= 1 mm.
    MeasurementFloor,
    /// The estimator's `attitude_noise_deg` must be finite and >= 0
    /// ([`super::EstimatorConfig::attitude_noise_deg`]).
    AttitudeNoise,
}

/// Where the tracker is in its lifecycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TrackState {
    /// No confirmed track yet (since creation or [`Tracker::reset`]).
    Searching,
    /// A confirmed track, updated within the lost timeout.
    Tracking,
    /// The confirmed track timed out; searching again.
    Lost,
}

/// Why a measurement was not used at all.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RejectReason {
    /// Position not finite or implausibly far.
    BadPosition,
    /// Covariance not finite, too large, or not positive semi-definite.
    BadCovariance,
    /// Older than the newest time seen, by at most `max_backwards_us`.
    OutOfOrder,
}

/// What [`Tracker::update`] did with a measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UpdateOutcome {
    /// Fused into the track.
    Accepted,
    /// Outside the gate, not fused; the squared Mahalanobis distance.
    Gated(f32),
    /// The track was (re)started from this measurement: first sighting, after a loss, a gated
    /// tentative track, recovery after a real jump, or the clock going back.
    Reset,
    /// Not used.
    Rejected(RejectReason),
}

/// The filtered pad position at one time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Time of the estimate, µs.
    pub t_us: u64,
    /// Position, metres (in the frame of the measurements).
    pub position: Vector3<f32>,
    /// Velocity, m/s.
    pub velocity: Vector3<f32>,
    /// Covariance of `position`, m².
    pub position_covariance: Matrix3<f32>,
    /// Covariance of `velocity`, (m/s)².
    pub velocity_covariance: Matrix3<f32>,
    /// Time since the last accepted measurement, µs (0: the estimate is at a measurement).
    pub since_update_us: u64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Track {
    /// Posterior at the last accepted update.
    kf: Kf,
    hits: u8,
    confirmed: bool,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Candidate {
    kf: Kf,
    count: u8,
}

/// The pad tracker (see the module documentation).
#[derive(Debug, Clone)]
pub struct Tracker {
    config: TrackerConfig,
    track: Option<Track>,
    candidate: Option<Candidate>,
    had_confirmed: bool,
    latest_us: Option<u64>,
    repairs: u32,
}

impl Tracker {
    /// A tracker in [`TrackState::Searching`].
    pub fn new(config: TrackerConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        Ok(Tracker {
            config,
            track: None,
            candidate: None,
            had_confirmed: false,
            latest_us: None,
            repairs: 0,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    /// Forgets everything: back to [`TrackState::Searching`].
    pub fn reset(&mut self) {
        self.track = None;
        self.candidate = None;
        self.had_confirmed = false;
        self.latest_us = None;
    }

    /// The lifecycle state as of the newest time the tracker has seen (through
    /// [`Tracker::predict_to`] or [`Tracker::update`]).
    pub fn state(&self) -> TrackState {
        match self.track {
            Some(t) if t.confirmed => TrackState::Tracking,
            _ if self.had_confirmed => TrackState::Lost,
            _ => TrackState::Searching,
        }
    }

    /// Time of the last accepted (or track-starting) measurement, µs.
    pub fn last_update_us(&self) -> Option<u64> {
        self.track.map(|t| t.kf.t_us)
    }

    /// How many times the covariance had to be repaired (expected: 0).
    pub fn repairs(&self) -> u32 {
        self.repairs
    }

    /// The covariance of the track's state (position, velocity) at its last update.
    pub fn covariance(&self) -> Option<Matrix6<f32>> {
        self.track.map(|t| t.kf.p)
    }

    /// Advances the tracker's clock to `t_us`: the track is dropped once its last update is
    /// older than the lost timeout. Predictions themselves are computed on demand (exactly)
    /// from the last update. An older `t_us` than already seen changes nothing.
    pub fn predict_to(&mut self, t_us: u64) -> TrackState {
        if self.latest_us.is_some_and(|latest| t_us < latest) {
            return self.state();
        }
        self.latest_us = Some(t_us);
        let timeout = self.config.lost_timeout_us;
        if self
            .track
            .is_some_and(|t| t_us.saturating_sub(t.kf.t_us) > timeout)
        {
            self.track = None;
            self.candidate = None;
        }
        if self
            .candidate
            .is_some_and(|c| t_us.saturating_sub(c.kf.t_us) > timeout)
        {
            self.candidate = None;
        }
        self.state()
    }

    /// Feeds one measurement (see the module documentation for what each outcome means).
    pub fn update(&mut self, m: &Measurement) -> UpdateOutcome {
        if !m
            .position
            .iter()
            .all(|v| v.is_finite() && v.abs() <= MAX_ABS_POSITION_M)
        {
            return UpdateOutcome::Rejected(RejectReason::BadPosition);
        }
        let Some(r) = self.measurement_noise(&m.covariance) else {
            return UpdateOutcome::Rejected(RejectReason::BadCovariance);
        };
        if let Some(latest) = self.latest_us {
            if m.t_us < latest {
                if latest - m.t_us <= self.config.max_backwards_us {
                    return UpdateOutcome::Rejected(RejectReason::OutOfOrder);
                }
                // The clock was reset: nothing from before can be related to this time.
                self.track = None;
                self.candidate = None;
                self.latest_us = None;
            }
        }
        self.predict_to(m.t_us);
        let q = self.config.accel_psd;
        let Some(mut track) = self.track else {
            self.start_track(m, &r);
            return UpdateOutcome::Reset;
        };
        let prior = track.kf.predicted(m.t_us, q);
        let Some((y, chol, d2)) = prior.innovation(&m.position, &r) else {
            self.start_track(m, &r);
            return UpdateOutcome::Reset;
        };
        if d2 <= self.config.gate_d2 {
            let mut kf = prior;
            if kf.correct(&y, &chol, &r) {
                self.repairs = self.repairs.saturating_add(1);
            }
            track.kf = kf;
            track.hits = track.hits.saturating_add(1);
            if track.hits >= self.config.confirm_count {
                track.confirmed = true;
                self.had_confirmed = true;
            }
            self.track = Some(track);
            self.candidate = None;
            return UpdateOutcome::Accepted;
        }
        if !track.confirmed {
            self.start_track(m, &r);
            return UpdateOutcome::Reset;
        }
        if self.feed_candidate(m, &r) {
            return UpdateOutcome::Reset;
        }
        UpdateOutcome::Gated(d2)
    }

    /// The pad at `now_us`, predicted from the last accepted update; `None` when there is no
    /// confirmed track, when `now_us` is before the last update, or when the last update is
    /// older than `max_coast_us`.
    pub fn estimate(&self, now_us: u64) -> Option<Estimate> {
        let track = self.track.filter(|t| t.confirmed)?;
        if now_us < track.kf.t_us {
            return None;
        }
        let since_update_us = now_us - track.kf.t_us;
        if since_update_us > self.config.max_coast_us {
            return None;
        }
        let kf = track.kf.predicted(now_us, self.config.accel_psd);
        Some(Estimate {
            t_us: now_us,
            position: kf.position(),
            velocity: kf.x.fixed_rows::<3>(3).into_owned(),
            position_covariance: block3(&kf.p, 0),
            velocity_covariance: block3(&kf.p, 3),
            since_update_us,
        })
    }

    /// The measurement covariance as used: symmetrised, its eigenvalues floored (negative
    /// rounding noise to 0, then `+ min_measurement_sigma²`, then at least the largest over
    /// [`MAX_MEASUREMENT_ANISOTROPY`]). Only ever larger than what the pose reported, never more
    /// confident. `None` when not finite, too large, or clearly not positive semi-definite.
    fn measurement_noise(&self, c: &Matrix3<f32>) -> Option<Matrix3<f32>> {
        if !c
            .iter()
            .all(|v| v.is_finite() && v.abs() <= MAX_VARIANCE_M2)
        {
            return None;
        }
        let eig = symmetric_eigen3(&symmetrised3(c))?;
        let largest = eig.eigenvalues.max();
        // Negative beyond rounding: not a covariance.
        let tolerance = 1.0e-5 * largest.abs() + 1.0e-12;
        if eig.eigenvalues.iter().any(|&l| l < -tolerance) {
            return None;
        }
        let floor = self.config.min_measurement_sigma * self.config.min_measurement_sigma;
        let top = largest.max(0.0) + floor;
        let lambda = eig
            .eigenvalues
            .map(|l| (l.max(0.0) + floor).max(top / MAX_MEASUREMENT_ANISOTROPY));
        let v = eig.eigenvectors;
        let r = symmetrised3(&(v * Matrix3::from_diagonal(&lambda) * v.transpose()));
        r.cholesky()?;
        Some(r)
    }

    fn start_track(&mut self, m: &Measurement, r: &Matrix3<f32>) {
        let confirmed = self.config.confirm_count <= 1;
        self.track = Some(Track {
            kf: Kf::new(m, r, self.config.initial_velocity_sigma),
            hits: 1,
            confirmed,
        });
        self.had_confirmed |= confirmed;
        self.candidate = None;
    }

    /// Feeds a gated measurement to the candidate filter; returns true when the candidate has
    /// replaced the track.
    fn feed_candidate(&mut self, m: &Measurement, r: &Matrix3<f32>) -> bool {
        let q = self.config.accel_psd;
        let fresh = Candidate {
            kf: Kf::new(m, r, self.config.initial_velocity_sigma),
            count: 1,
        };
        let next = match self.candidate {
            None => fresh,
            Some(c) => {
                let prior = c.kf.predicted(m.t_us, q);
                match prior.innovation(&m.position, r) {
                    Some((y, chol, d2)) if d2 <= self.config.gate_d2 => {
                        let mut kf = prior;
                        if kf.correct(&y, &chol, r) {
                            self.repairs = self.repairs.saturating_add(1);
                        }
                        Candidate {
                            kf,
                            count: c.count.saturating_add(1),
                        }
                    }
                    _ => fresh,
                }
            }
        };
        if next.count >= self.config.recovery_count {
            self.track = Some(Track {
                kf: next.kf,
                hits: next.count,
                confirmed: true,
            });
            self.had_confirmed = true;
            self.candidate = None;
            true
        } else {
            self.candidate = Some(next);
            false
        }
    }
}
