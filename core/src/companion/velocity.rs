//! The vehicle's velocity over the ground for the autopilot's estimator (TD_VPE_EN bit 1): a
//! straight-line fit through the last [`VelocityFit::WINDOW_US`] of level pad positions.
//!
//! # Why not the tracker's own velocity
//! The tracker's constant-velocity filter is tuned to follow a vehicle that manoeuvres, so its
//! velocity moves with every frame's noise: about as uncertain as the GPS velocity an
//! autopilot already has, and fused beside it, it changes nothing. What the autopilot lacks
//! near the pad is a velocity that does not wander; the pad's position against the vehicle is
//! known to a centimetre or two in every frame, and the slope of a line through a few tenths
//! of a second of those positions is a velocity an order of magnitude steadier. Its price is
//! a lag under acceleration (the slope is the velocity at the window's middle while it is sent
//! with the newest exposure), `acceleration x WINDOW / 2`: small in a landing's gentle
//! manoeuvres, and an estimator that fuses it weighs it against its accelerometers.
//!
//! The fit restarts whenever the positions stop following one another (a gap longer than
//! [`VelocityFit::MAX_GAP_US`], a time that goes backwards, a jump of more than
//! [`VelocityFit::MAX_STEP_M`] from the last position: another track), so one line never spans
//! two tracks. A pad that moves is not the ground: the velocity sent is the
//! vehicle's against the pad.

use heapless::Deque;
use nalgebra::Vector3;

/// Least-squares slope of recent positions.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct VelocityFit {
    samples: Deque<(u64, Vector3<f32>), { VelocityFit::CAPACITY }>,
}

/// A fitted velocity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct FittedVelocity {
    /// The slope of the positions, m/s.
    pub velocity: Vector3<f32>,
    /// Its variance per axis from the fit's residuals, (m/s)².
    pub variance: Vector3<f32>,
}

impl VelocityFit {
    /// The window the line is fitted over, µs.
    pub const WINDOW_US: u64 = 400_000;
    /// A longer gap between positions starts a new fit, µs.
    pub const MAX_GAP_US: u64 = 200_000;
    /// A longer step from the last position starts a new fit, metres.
    pub const MAX_STEP_M: f32 = 0.5;
    /// Fewest positions, and shortest span of them, for a slope.
    const MIN_SAMPLES: usize = 4;
    const MIN_SPAN_US: u64 = 200_000;
    /// Positions kept: a window at 60 frames per second.
    const CAPACITY: usize = 24;
    /// The variance never claimed smaller than this, (m/s)²: a perfect line through a few
    /// filtered positions says little about the positions' own errors.
    const MIN_VARIANCE: f32 = 0.02 * 0.02;

    /// Filtered positions are not independent: neighbours share the tracker's filtering and
    /// the attitude's error, which a line through them cannot see, so the slope wanders more
    /// than independent positions would let it. The variance is claimed 4 times (the
    /// deviation twice) what independence gives, which covers the slope's error against the
    /// truth in the companion's simulated flights (core/tests/companion_profiles.rs).
    const SHARED_ERROR_FACTOR: f32 = 4.0;

    pub const fn new() -> Self {
        VelocityFit {
            samples: Deque::new(),
        }
    }

    /// Forgets every position (the pad lost, the track changed).
    pub fn clear(&mut self) {
        self.samples.clear();
    }

    /// Adds the position at `t_us`, whose variance per axis the estimator puts at
    /// `position_variance`, and fits the window ending there; `None` until the window holds
    /// enough positions over a long enough span.
    pub fn push(
        &mut self,
        t_us: u64,
        position: Vector3<f32>,
        position_variance: Vector3<f32>,
    ) -> Option<FittedVelocity> {
        if let Some(&(last, p)) = self.samples.back() {
            if t_us <= last
                || t_us - last > Self::MAX_GAP_US
                || (position - p).norm() > Self::MAX_STEP_M
            {
                self.samples.clear();
            }
        }
        while self
            .samples
            .front()
            .is_some_and(|&(t, _)| t_us - t > Self::WINDOW_US)
            || self.samples.is_full()
        {
            self.samples.pop_front();
        }
        // Cannot fail: a slot was freed above.
        let _ = self.samples.push_back((t_us, position));
        self.fit(position_variance)
    }

    fn fit(&self, position_variance: Vector3<f32>) -> Option<FittedVelocity> {
        let n = self.samples.len();
        let (&(first, _), &(last, _)) = (self.samples.front()?, self.samples.back()?);
        if n < Self::MIN_SAMPLES || last - first < Self::MIN_SPAN_US {
            return None;
        }
        // Times relative to the newest, in seconds: small numbers for f32.
        let time = |t: u64| -((last - t) as f32) * 1e-6;
        let nf = n as f32;
        let mut t_mean = 0.0;
        let mut p_mean = Vector3::zeros();
        for &(t, p) in &self.samples {
            t_mean += time(t);
            p_mean += p;
        }
        t_mean /= nf;
        p_mean /= nf;
        let mut stt = 0.0;
        let mut stp = Vector3::zeros();
        for &(t, p) in &self.samples {
            let dt = time(t) - t_mean;
            stt += dt * dt;
            stp += (p - p_mean) * dt;
        }
        if stt <= 0.0 {
            return None;
        }
        let slope = stp / stt;
        let mut residual = Vector3::<f32>::zeros();
        for &(t, p) in &self.samples {
            let r = p - p_mean - slope * (time(t) - t_mean);
            residual += r.component_mul(&r);
        }
        // What independent positions would give, from the residuals or the estimator's own
        // variance, whichever is larger; then doubled in deviation ([`SHARED_ERROR_FACTOR`]).
        let variance = (residual / (nf - 2.0))
            .zip_map(&position_variance, f32::max)
            .map(|v| (Self::SHARED_ERROR_FACTOR * v / stt).max(Self::MIN_VARIANCE));
        if !slope.iter().chain(variance.iter()).all(|v| v.is_finite()) {
            return None;
        }
        Some(FittedVelocity {
            velocity: slope,
            variance,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_straight_path_gives_its_velocity_and_a_gap_restarts() {
        let mut fit = VelocityFit::new();
        let v = Vector3::new(0.3, -0.2, 0.5);
        let at = |t_us: u64| Vector3::new(1.0, 2.0, 10.0) + v * (t_us as f32 * 1e-6);
        let mut last = None;
        for k in 0..12u64 {
            let t = 5_000_000 + k * 33_333;
            last = fit.push(t, at(t), Vector3::zeros());
            // At least four positions over at least 0.2 s before the first slope.
            assert_eq!(last.is_some(), k >= 7, "k {k}");
        }
        let got = last.unwrap();
        assert!((got.velocity - v).amax() < 1e-3, "{}", got.velocity);
        assert_eq!(got.variance, Vector3::repeat(VelocityFit::MIN_VARIANCE));
        // A gap longer than MAX_GAP_US: a new fit, no slope from one position.
        assert_eq!(fit.push(6_000_000, at(6_000_000), Vector3::zeros()), None);
        // Time going backwards: the same.
        assert_eq!(fit.push(5_900_000, at(5_900_000), Vector3::zeros()), None);
        // A jump to another track: the same.
        let mut fit = VelocityFit::new();
        for k in 0..12u64 {
            last = fit.push(k * 33_333, at(k * 33_333), Vector3::zeros());
        }
        assert!(last.is_some());
        assert_eq!(
            fit.push(
                12 * 33_333,
                at(0) + Vector3::new(0.6, 0.0, 0.0),
                Vector3::zeros()
            ),
            None
        );
    }

    #[test]
    fn the_slope_averages_noise_and_says_how_much_is_left() {
        // Alternating +-2 cm on a still vehicle at 30 Hz: the slope is near zero and its
        // claimed deviation covers what is left.
        let mut fit = VelocityFit::new();
        let mut got = None;
        for k in 0..30u64 {
            let e = if k % 2 == 0 { 0.02 } else { -0.02 };
            got = fit.push(k * 33_333, Vector3::new(e, -e, 8.0), Vector3::zeros());
        }
        let noisy = got.unwrap();
        assert!(noisy.velocity.amax() < 0.02, "{}", noisy.velocity);
        assert!(
            noisy.variance.x > VelocityFit::MIN_VARIANCE,
            "{}",
            noisy.variance
        );
        assert!(noisy.velocity.x.abs() < 3.0 * noisy.variance.x.sqrt());
        // Only the window's positions count: an old jump no longer shows.
        let mut fit = VelocityFit::new();
        fit.push(0, Vector3::new(5.0, 0.0, 0.0), Vector3::zeros());
        for k in 1..40u64 {
            got = fit.push(k * 33_333, Vector3::zeros(), Vector3::zeros());
        }
        assert_eq!(got.unwrap().velocity, Vector3::zeros());
        // The estimator's variance sets the floor: (3 cm)^2 over 13 positions 0.4 s wide.
        let mut fit = VelocityFit::new();
        for k in 0..13u64 {
            got = fit.push(k * 33_333, Vector3::zeros(), Vector3::repeat(0.03 * 0.03));
        }
        let stt: f32 = (0..13)
            .map(|k| ((k as f32 - 6.0) * 0.033_333).powi(2))
            .sum();
        let want = VelocityFit::SHARED_ERROR_FACTOR * 0.03 * 0.03 / stt;
        assert!(
            (got.unwrap().variance.x - want).abs() < 1e-3 * want,
            "{:?}",
            got
        );
    }
}
