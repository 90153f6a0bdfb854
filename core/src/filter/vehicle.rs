//! The vehicle state the flight controller streams: attitude and local position, kept in
//! short histories so they can be read at a frame's **exposure** time.
//!
//! A frame is processed tens of milliseconds after its exposure; a vehicle rolling at
//! 90 °/s turns 3° in 30 ms, which moves the pad by 1 m at 20 m height. So the attitude used
//! to level a pose must be the one at exposure, not the latest: each history is a ring of
//! time-stamped samples (our clock) and is read by interpolation between the two samples
//! around the requested time (spherical for attitude, linear for position). A time outside
//! the history, or in a gap longer than [`MAX_GAP_US`], has no state: never extrapolate far,
//! never use an old sample as if it were current. Slightly past the newest sample (up to
//! [`MAX_EXTRAPOLATION_US`]) the newest is used (the position advanced by its velocity).
//!
//! Time stamps: a sample's `time_boot_ms` is in the autopilot's clock; with a known clock
//! offset ([`crate::companion::timesync`]) it is converted to ours, else the receive time is used (late by
//! the transport delay, a few ms on a fast UART). When the offset changes (first known, or
//! reset) the histories are cleared, since old and new stamps are not comparable.
//!
//! Body rates: the rolling-shutter correction ([`crate::pipeline`]) needs how fast the vehicle
//! turns during a frame's readout. They are the difference of the two attitude samples around
//! the exposure ([`VehicleState::body_rate_at`]), not ATTITUDE_QUATERNION's
//! rollspeed/pitchspeed/yawspeed: the difference is the mean rate over the 20 ms between
//! samples, which is what matters over a 30 ms readout (the gyro's instantaneous rate carries
//! the vibration the attitude filter smooths out), it is on the same time base as the attitude
//! it goes with, and it needs no second history.
//!
//! Reboot detection: the autopilot's `time_boot_ms` must advance with our clock. A value more
//! than [`REBOOT_BACKWARDS_US`] behind what the previous one predicts means the autopilot
//! restarted (or its clock was reset): [`VehicleState::observe_time`] reports it and the
//! companion drops everything it knew of the vehicle.

use super::axes::Attitude;
use nalgebra::{UnitQuaternion, Vector3};

/// Attitude samples kept (0.64 s at 50 Hz).
pub const ATTITUDE_HISTORY: usize = 32;
/// Position samples kept (0.5 s at 30 Hz).
pub const POSITION_HISTORY: usize = 16;
/// Longest gap between two samples that is interpolated across, µs.
pub const MAX_GAP_US: u64 = 200_000;
/// How far past the newest sample it is still used, µs.
pub const MAX_EXTRAPOLATION_US: u64 = 60_000;
/// The autopilot clock going back by more than this means it rebooted, µs.
pub const REBOOT_BACKWARDS_US: u64 = 1_000_000;
/// Longest interval between the two attitude samples a body rate is differenced from, µs:
/// five samples at 50 Hz. Over a longer one the mean rate says little about the 30 ms of a
/// readout (a roll manoeuvre lasts a few hundred milliseconds).
pub const MAX_RATE_GAP_US: u64 = 100_000;

/// One local position sample (LOCAL_POSITION_NED).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionSample {
    /// Position, metres, NED.
    pub position: Vector3<f32>,
    /// Velocity, m/s, NED.
    pub velocity: Vector3<f32>,
}

/// A fixed ring of time-stamped samples, oldest overwritten first; times non-decreasing.
#[derive(Debug, Clone)]
struct Ring<T: Copy, const N: usize> {
    items: [Option<(u64, T)>; N],
    head: usize,
}

impl<T: Copy, const N: usize> Ring<T, N> {
    const fn new() -> Self {
        Ring {
            items: [None; N],
            head: 0,
        }
    }

    fn clear(&mut self) {
        self.items = [None; N];
        self.head = 0;
    }

    fn newest(&self) -> Option<(u64, T)> {
        let i = (self.head + N - 1) % N;
        self.items.get(i).copied().flatten()
    }

    fn push(&mut self, t_us: u64, v: T) {
        // Out-of-order samples (older than the newest) are dropped: the ring stays sorted.
        if self.newest().is_some_and(|(t, _)| t_us < t) {
            return;
        }
        if let Some(slot) = self.items.get_mut(self.head) {
            *slot = Some((t_us, v));
        }
        self.head = (self.head + 1) % N;
    }

    /// The samples just before-or-at and just after `t_us`, or the newest when `t_us` is past
    /// it by at most `MAX_EXTRAPOLATION_US`.
    fn around(&self, t_us: u64) -> Option<Around<T>> {
        let (newest_t, newest) = self.newest()?;
        if t_us >= newest_t {
            return (t_us - newest_t <= MAX_EXTRAPOLATION_US)
                .then_some(Around::After(newest_t, newest));
        }
        // Walk from newest to oldest.
        let mut later = (newest_t, newest);
        for k in 2..=N {
            let i = (self.head + N - k) % N;
            let (t, v) = self.items.get(i).copied().flatten()?;
            if t <= t_us {
                if later.0 - t > MAX_GAP_US {
                    return None;
                }
                return Some(Around::Between((t, v), later));
            }
            later = (t, v);
        }
        None
    }

    /// The newest sample and the one before it, if there are two.
    fn newest_two(&self) -> Option<((u64, T), (u64, T))> {
        let newest = self.newest()?;
        let i = (self.head + N - 2) % N;
        let before = self.items.get(i).copied().flatten()?;
        Some((before, newest))
    }
}

enum Around<T> {
    Between((u64, T), (u64, T)),
    After(u64, T),
}

/// The rotation vector (axis times angle, radians) of `q`, the shorter way round. From the
/// vector part's length and `atan2`, not `acos` of the scalar part: a 20 ms step at 30 °/s
/// turns 0.01 rad, where `acos` near 1 keeps only a few bits in f32.
fn rotation_vector(q: &UnitQuaternion<f32>) -> Vector3<f32> {
    let (w, v) = if q.w < 0.0 {
        (-q.w, -q.imag())
    } else {
        (q.w, q.imag())
    };
    let sin_half = v.norm();
    // angle / sin(angle / 2) -> 2 / cos(angle / 2) as the angle goes to 0.
    let scale = if sin_half > 1.0e-6 {
        2.0 * libm::atan2f(sin_half, w) / sin_half
    } else {
        2.0 / w
    };
    v * scale
}

fn fraction(t0: u64, t1: u64, t: u64) -> f32 {
    if t1 <= t0 {
        return 0.0;
    }
    (t.saturating_sub(t0) as f32 / (t1 - t0) as f32).clamp(0.0, 1.0)
}

/// The vehicle state read at one exposure time: what the per-frame path needs of it, read
/// once per frame ([`VehicleState::at`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleAtExposure {
    /// The exposure time, our clock, µs.
    pub t_us: u64,
    /// The attitude then, if the history covers it.
    pub attitude: Option<Attitude>,
    /// The local position then, if the history covers it.
    pub position: Option<PositionSample>,
    /// The body angular rate then, rad/s, body FRD axes ([`VehicleState::body_rate_at`]).
    pub body_rate: Option<Vector3<f32>>,
    /// [`VehicleState::reboots`] at the time of reading.
    pub reboots: u32,
}

/// The vehicle state histories.
#[derive(Debug, Clone)]
pub struct VehicleState {
    attitude: Ring<UnitQuaternion<f32>, ATTITUDE_HISTORY>,
    position: Ring<PositionSample, POSITION_HISTORY>,
    /// Last autopilot time seen (µs, its clock) and our time then.
    last_time: Option<(u64, u64)>,
    /// Our time of the newest sample received.
    last_rx_us: Option<u64>,
    /// Autopilot reboots seen ([`VehicleState::on_reboot`]).
    reboots: u32,
    /// Changes of what the readers see (samples added or cleared, reboots), wrapping.
    revision: u32,
}

impl Default for VehicleState {
    fn default() -> Self {
        Self::new()
    }
}

impl VehicleState {
    /// Nothing known (`const`, so the firmware can keep one in a static).
    pub const fn new() -> Self {
        VehicleState {
            attitude: Ring::new(),
            position: Ring::new(),
            last_time: None,
            last_rx_us: None,
            reboots: 0,
            revision: 0,
        }
    }

    /// What the per-frame path reads at `t_us` (our clock): the attitude, the position, the
    /// body rate and the reboot count, in one pass.
    pub fn at(&self, t_us: u64) -> VehicleAtExposure {
        VehicleAtExposure {
            t_us,
            attitude: self.attitude_at(t_us),
            position: self.position_at(t_us),
            body_rate: self.body_rate_at(t_us),
            reboots: self.reboots,
        }
    }

    /// Changes since start (wrapping): a copy with the same revision reads the same, so the
    /// firmware's link task copies the state for the vision task only when it moved.
    pub fn revision(&self) -> u32 {
        self.revision
    }

    /// Forgets everything (reboot, clock offset change).
    pub fn clear(&mut self) {
        self.revision = self.revision.wrapping_add(1);
        self.attitude.clear();
        self.position.clear();
        self.last_time = None;
        self.last_rx_us = None;
    }

    /// Forgets the samples but keeps the reboot detector's reference.
    pub fn clear_samples(&mut self) {
        self.revision = self.revision.wrapping_add(1);
        self.attitude.clear();
        self.position.clear();
    }

    /// The autopilot rebooted: forgets the samples and counts the reboot, so that whoever
    /// filters positions in the autopilot's frames ([`super::PadEstimator`]) restarts too.
    pub fn on_reboot(&mut self) {
        self.clear_samples();
        self.reboots = self.reboots.wrapping_add(1);
    }

    /// Autopilot reboots seen since start (wrapping): compare two readings for "changed".
    pub fn reboots(&self) -> u32 {
        self.reboots
    }

    /// Checks an autopilot time stamp (µs, its clock) received at `now_us`; returns true when
    /// it went back by more than [`REBOOT_BACKWARDS_US`] (the autopilot rebooted). Updates the
    /// reference either way.
    pub fn observe_time(&mut self, autopilot_us: u64, now_us: u64) -> bool {
        let rebooted = self.last_time.is_some_and(|(ap, ours)| {
            let expected = ap.saturating_add(now_us.saturating_sub(ours));
            autopilot_us.saturating_add(REBOOT_BACKWARDS_US) < expected
        });
        self.last_time = Some((autopilot_us, now_us));
        rebooted
    }

    /// Adds an attitude sample at `t_us` (our clock), received at `now_us`.
    pub fn push_attitude(&mut self, t_us: u64, attitude: &Attitude, now_us: u64) {
        let [w, x, y, z] = attitude.quaternion_wxyz();
        let q = UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(w, x, y, z));
        self.attitude.push(t_us, q);
        self.last_rx_us = Some(now_us);
        self.revision = self.revision.wrapping_add(1);
    }

    /// Adds a position sample at `t_us` (our clock), received at `now_us`.
    pub fn push_position(&mut self, t_us: u64, sample: PositionSample, now_us: u64) {
        self.position.push(t_us, sample);
        self.last_rx_us = Some(now_us);
        self.revision = self.revision.wrapping_add(1);
    }

    /// Our time of the newest sample received.
    pub fn last_rx_us(&self) -> Option<u64> {
        self.last_rx_us
    }

    /// The attitude at `t_us` (our clock), interpolated; `None` outside the history.
    pub fn attitude_at(&self, t_us: u64) -> Option<Attitude> {
        let q = match self.attitude.around(t_us)? {
            Around::After(_, q) => q,
            Around::Between((t0, q0), (t1, q1)) => {
                let f = fraction(t0, t1, t_us);
                q0.try_slerp(&q1, f, 1.0e-6)
                    .unwrap_or(if f < 0.5 { q0 } else { q1 })
            }
        };
        Attitude::from_quaternion_wxyz([q.w, q.i, q.j, q.k]).ok()
    }

    /// The body angular rate at `t_us` (our clock), rad/s in body FRD axes: the rotation from
    /// the attitude sample just before-or-at `t_us` to the one just after, over their
    /// interval (past the newest sample, by up to [`MAX_EXTRAPOLATION_US`], the newest two).
    /// `None` when the history does not cover `t_us`, the two samples are more than
    /// [`MAX_RATE_GAP_US`] apart or share a time stamp.
    ///
    /// With `q` the rotation body FRD to NED, `q1 = q0 exp(w dt / 2)` for a body rate `w`
    /// constant over `dt`, so `w = log(q0^-1 q1) / dt`: the rate in the body's own axes, as a
    /// gyro measures it.
    pub fn body_rate_at(&self, t_us: u64) -> Option<Vector3<f32>> {
        let ((t0, q0), (t1, q1)) = match self.attitude.around(t_us)? {
            Around::Between(a, b) => (a, b),
            Around::After(..) => self.attitude.newest_two()?,
        };
        if t1 <= t0 || t1 - t0 > MAX_RATE_GAP_US {
            return None;
        }
        let dt = (t1 - t0) as f32 * 1.0e-6;
        let rate = rotation_vector(&(q0.inverse() * q1)) / dt;
        rate.iter().all(|c| c.is_finite()).then_some(rate)
    }

    /// The local position at `t_us` (our clock); `None` outside the history.
    pub fn position_at(&self, t_us: u64) -> Option<PositionSample> {
        match self.position.around(t_us)? {
            Around::After(t0, s) => {
                let dt = t_us.saturating_sub(t0) as f32 * 1.0e-6;
                Some(PositionSample {
                    position: s.position + s.velocity * dt,
                    velocity: s.velocity,
                })
            }
            Around::Between((t0, a), (t1, b)) => {
                let f = fraction(t0, t1, t_us);
                Some(PositionSample {
                    position: a.position.lerp(&b.position, f),
                    velocity: a.velocity.lerp(&b.velocity, f),
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_and_refuses_outside() {
        let mut v = VehicleState::new();
        for k in 0..10u64 {
            let yaw = k as f32 * 0.1;
            v.push_attitude(k * 20_000, &Attitude::from_euler(0.0, 0.0, yaw).unwrap(), 0);
        }
        let a = v.attitude_at(30_000).unwrap();
        assert!((a.yaw() - 0.15).abs() < 1e-4);
        assert!(v.attitude_at(180_000 + MAX_EXTRAPOLATION_US + 1).is_none());
        assert!(v.attitude_at(180_000 + 10_000).is_some());
        v.clear();
        assert!(v.attitude_at(30_000).is_none());
    }

    #[test]
    fn reboot_is_time_going_back() {
        let mut v = VehicleState::new();
        assert!(!v.observe_time(100_000_000, 0));
        assert!(!v.observe_time(101_000_000, 1_000_000));
        assert!(v.observe_time(500_000, 2_000_000));
    }

    #[test]
    fn a_reading_at_exposure_is_the_histories_there_and_changes_move_the_revision() {
        let mut v = VehicleState::new();
        let r0 = v.revision();
        v.push_attitude(1_000, &Attitude::level_north(), 1_000);
        let sample = PositionSample {
            position: Vector3::new(1.0, 2.0, -3.0),
            velocity: Vector3::new(0.5, 0.0, 0.0),
        };
        v.push_position(1_000, sample, 1_000);
        let r1 = v.revision();
        assert_ne!(r0, r1);
        let at = v.at(11_000);
        assert_eq!(at.t_us, 11_000);
        assert_eq!(at.attitude, v.attitude_at(11_000));
        assert_eq!(at.position, v.position_at(11_000));
        assert_eq!(at.reboots, 0);
        // Reading changes nothing; a reboot does, and is counted.
        assert_eq!(v.revision(), r1);
        v.on_reboot();
        assert_ne!(v.revision(), r1);
        assert_eq!(v.at(11_000).reboots, 1);
        assert_eq!(v.at(11_000).attitude, None);
    }

    #[test]
    fn body_rate_is_the_rotation_between_the_samples_in_body_axes() {
        // A vehicle pitched and headed north-east, turning at 30 °/s about each body axis.
        let rate = Vector3::new(1.0, 1.0, 1.0) * 30.0f32.to_radians();
        let start = Attitude::from_euler(0.1, -0.2, 0.8).unwrap();
        let [w, x, y, z] = start.quaternion_wxyz();
        let q0 = UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(w, x, y, z));
        let mut v = VehicleState::new();
        for k in 0..10u64 {
            let t = k as f32 * 0.02;
            // Body-axis rate: the turn is applied on the right.
            let q = q0 * UnitQuaternion::from_scaled_axis(rate * t);
            let att = Attitude::from_quaternion_wxyz([q.w, q.i, q.j, q.k]).unwrap();
            v.push_attitude(1_000_000 + k * 20_000, &att, 0);
        }
        for t_us in [1_000_000, 1_050_000, 1_079_999, 1_180_000, 1_230_000] {
            let got = v.body_rate_at(t_us).unwrap();
            assert!((got - rate).norm() < 2e-3 * rate.norm(), "{t_us}: {got:?}");
            assert_eq!(v.at(t_us).body_rate, Some(got));
        }
        // Before the history, or past it beyond the extrapolation limit: unknown.
        assert_eq!(v.body_rate_at(999_999), None);
        assert_eq!(v.body_rate_at(1_180_000 + MAX_EXTRAPOLATION_US + 1), None);
    }

    #[test]
    fn body_rate_needs_two_close_samples() {
        let mut v = VehicleState::new();
        v.push_attitude(0, &Attitude::level_north(), 0);
        assert_eq!(v.body_rate_at(10_000), None);
        // Two samples further apart than MAX_RATE_GAP_US: no rate, though the attitude is
        // still interpolated across them.
        let turned = Attitude::from_euler(0.0, 0.0, 0.5).unwrap();
        v.push_attitude(MAX_RATE_GAP_US + 1, &turned, 0);
        assert_eq!(v.body_rate_at(50_000), None);
        assert!(v.attitude_at(50_000).is_some());
        // The same time stamp twice: no interval to divide by.
        let mut v = VehicleState::new();
        v.push_attitude(0, &Attitude::level_north(), 0);
        v.push_attitude(0, &turned, 0);
        assert_eq!(v.body_rate_at(0), None);
        // A yaw of 0.5 rad over 50 ms, read past the newest sample.
        let mut v = VehicleState::new();
        v.push_attitude(0, &Attitude::level_north(), 0);
        v.push_attitude(50_000, &turned, 0);
        let r = v.body_rate_at(60_000).unwrap();
        assert!((r - Vector3::new(0.0, 0.0, 10.0)).norm() < 1e-3, "{r:?}");
    }
}
