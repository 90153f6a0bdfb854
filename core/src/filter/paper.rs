//! The reference paper's filter (section 2.3), reproduced literally, lag included.
//!
//! The paper smooths the pose's x, y and z independently with a one-dimensional Kalman filter
//! (equations 8-14) started from Table 1: initial estimate `x̂(1,0) = 5`, initial uncertainty
//! `p(1,0) = 1000`, measurement uncertainty `r = 3`, process noise `q = 0.09`. This module
//! exists so that the project can show what the paper's filter does on the same data as ours
//! ([`super::tracker`]); it is not meant to land a drone.
//!
//! How each equation is read (per axis, `n` the measurement index):
//!
//! - (8)  `K = p(n,n-1) / (p(n,n-1) + r)`: the gain from the predicted uncertainty.
//! - (9)  `0 <= K <= 1`: a property, true here because `p >= 0` and `r > 0`; the code clamps
//!   it anyway so a non-finite intermediate cannot leave the range.
//! - (10) `x̂(n,n) = x̂(n,n-1) + K (z - x̂(n,n-1))`: the state update.
//! - (11) `p(n,n) = (1 - K) p(n,n-1)`: the uncertainty update.
//! - (12) `x̂(n+1,n) = x̂(n,n) + Δt ẋ(n,n)`: position extrapolation with a velocity.
//! - (13) `ẋ(n+1,n) = ẋ(n,n)`: the velocity is carried unchanged.
//! - (14) `p(n+1,n) = p(n,n) + q`: the uncertainty extrapolation, `q` added once per step
//!   (not scaled by Δt).
//!
//! The state is scalar (one `p`, no position-velocity covariance) and no equation updates the
//! velocity from the measurements, and Table 1 gives no initial velocity. So the velocity
//! stays at its initial value, zero (kept as [`PaperConfig::v0`] to make that reading explicit),
//! and (12) reduces to `x̂(n+1,n) = x̂(n,n)`: a random-walk model. On a vehicle descending at
//! constant speed the steady-state gain is `K ≈ 0.159` (from `p = (1-K)(p+q)`), which makes
//! the output trail the truth by `(1-K)/K ≈ 5.3` measurement steps: the "delay error" the
//! paper reports and tried to reduce by adding `q`.
//!
//! The time step of (12) is the one between consecutive measurements, known when the next
//! measurement arrives, so [`PaperKalman::update`] first extrapolates with it, (12)-(14), and
//! then updates, (8)-(11). The first call does not extrapolate: Table 1 already gives the
//! predicted state `x̂(1,0)`, `p(1,0)`.

/// The paper's initial values (Table 1), the same for x, y and z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperConfig {
    /// Initial predicted state `x̂(1,0)` (Table 1: 5).
    pub x0: f32,
    /// Initial velocity of equations 12-13 (not in the paper: 0, which is what its equations
    /// imply since nothing estimates it).
    pub v0: f32,
    /// Initial predicted uncertainty `p(1,0)` (Table 1: 1000).
    pub p0: f32,
    /// Measurement uncertainty `r` (Table 1: 3).
    pub r: f32,
    /// Process noise `q` (Table 1: 0.09).
    pub q: f32,
}

impl PaperConfig {
    /// Table 1 of the paper.
    pub const TABLE_1: PaperConfig = PaperConfig {
        x0: 5.0,
        v0: 0.0,
        p0: 1000.0,
        r: 3.0,
        q: 0.09,
    };
}

impl Default for PaperConfig {
    fn default() -> Self {
        PaperConfig::TABLE_1
    }
}

/// One axis of the paper's filter.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Axis {
    /// `x̂(n,n-1)`: the predicted state before the next measurement.
    x_pred: f32,
    /// `ẋ`: the velocity of equations 12-13.
    v: f32,
    /// `p(n,n-1)`: the predicted uncertainty.
    p_pred: f32,
    /// `x̂(n,n)`: the latest estimate (the filter's output).
    x_est: f32,
    /// `p(n,n)`: the latest estimate's uncertainty.
    p_est: f32,
}

impl Axis {
    fn new(c: &PaperConfig) -> Self {
        Axis {
            x_pred: c.x0,
            v: c.v0,
            p_pred: c.p0,
            x_est: c.x0,
            p_est: c.p0,
        }
    }

    /// Equations 12-14 over `dt` seconds.
    fn extrapolate(&mut self, dt: f32, q: f32) {
        // (12) x̂(n+1,n) = x̂(n,n) + Δt ẋ(n,n)
        self.x_pred = self.x_est + dt * self.v;
        // (13) ẋ(n+1,n) = ẋ(n,n): nothing to do, the velocity is carried.
        // (14) p(n+1,n) = p(n,n) + q
        self.p_pred = self.p_est + q;
    }

    /// Equations 8-11 with measurement `z`; a non-finite `z` is skipped (the paper does not
    /// say; skipping keeps the filter finite) and the prediction becomes the estimate.
    fn update(&mut self, z: f32, r: f32) {
        if !z.is_finite() {
            self.x_est = self.x_pred;
            self.p_est = self.p_pred;
            return;
        }
        // (8) K = p(n,n-1) / (p(n,n-1) + r), and (9) 0 <= K <= 1.
        let k = (self.p_pred / (self.p_pred + r)).clamp(0.0, 1.0);
        let k = if k.is_finite() { k } else { 1.0 };
        // (10) x̂(n,n) = x̂(n,n-1) + K (z - x̂(n,n-1))
        self.x_est = self.x_pred + k * (z - self.x_pred);
        // (11) p(n,n) = (1 - K) p(n,n-1)
        self.p_est = (1.0 - k) * self.p_pred;
    }
}

/// The paper's per-axis Kalman filter (equations 8-14), three independent axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperKalman {
    config: PaperConfig,
    axes: [Axis; 3],
    started: bool,
}

impl Default for PaperKalman {
    fn default() -> Self {
        PaperKalman::new(PaperConfig::TABLE_1)
    }
}

impl PaperKalman {
    /// A filter in its initial state (Table 1 for [`PaperConfig::TABLE_1`]).
    pub fn new(config: PaperConfig) -> Self {
        let axis = Axis::new(&config);
        PaperKalman {
            config,
            axes: [axis; 3],
            started: false,
        }
    }

    /// Feeds one measurement `[x, y, z]` taken `dt` seconds after the previous one and returns
    /// the new estimate `x̂(n,n)` per axis. `dt` is ignored on the first call; a negative or
    /// non-finite `dt` counts as 0.
    pub fn update(&mut self, measurement: [f32; 3], dt: f32) -> [f32; 3] {
        let dt = if dt.is_finite() && dt > 0.0 { dt } else { 0.0 };
        let c = self.config;
        for (axis, z) in self.axes.iter_mut().zip(measurement) {
            if self.started {
                axis.extrapolate(dt, c.q);
            }
            axis.update(z, c.r);
        }
        self.started = true;
        self.estimate()
    }

    /// The latest estimate `x̂(n,n)` per axis (Table 1's `x̂(1,0)` before any measurement).
    pub fn estimate(&self) -> [f32; 3] {
        self.axes.map(|a| a.x_est)
    }

    /// The latest estimate's uncertainty `p(n,n)` per axis.
    pub fn uncertainty(&self) -> [f32; 3] {
        self.axes.map(|a| a.p_est)
    }

    /// Back to the initial state.
    pub fn reset(&mut self) {
        *self = PaperKalman::new(self.config);
    }
}
