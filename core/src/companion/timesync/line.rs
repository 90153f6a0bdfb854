//! The offset line of the clock estimator: the samples it is fitted to (fixed rings), the
//! weighted least-squares fit with its drift prior, and the gate a new sample must pass.
//!
//! Separate from [`super::TimeSync`] because it is the statistics alone, on plain values: the
//! estimator decides what goes into the window and when to refit.

use super::{DRIFT_PRIOR_SIGMA, GATE_FLOOR_US, GATE_SIGMAS, MAX_RATE, MIN_RATE, SIGMA_FLOOR_US};

/// One observation: at our time `x_us` the autopilot's clock read `x_us + offset_us`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Sample {
    pub(super) x_us: u64,
    pub(super) offset_us: i64,
    /// Half the round trip (the bound on the midpoint's error), or SYSTEM_TIME's
    /// uncertainty, µs.
    pub(super) sigma_us: f64,
}

const EMPTY: Sample = Sample {
    x_us: 0,
    offset_us: 0,
    sigma_us: 1.0,
};

/// A fixed ring of samples; `items[..len]` are valid (filled from 0, then overwritten in
/// order, so validity is a prefix).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Samples<const N: usize> {
    items: [Sample; N],
    pub(super) len: usize,
    next: usize,
}

impl<const N: usize> Samples<N> {
    pub(super) const fn new() -> Self {
        Samples {
            items: [EMPTY; N],
            len: 0,
            next: 0,
        }
    }

    pub(super) fn clear(&mut self) {
        self.len = 0;
        self.next = 0;
    }

    pub(super) fn push(&mut self, s: Sample) {
        if let Some(slot) = self.items.get_mut(self.next) {
            *slot = s;
        }
        self.next = (self.next + 1) % N;
        self.len = (self.len + 1).min(N);
    }

    pub(super) fn as_slice(&self) -> &[Sample] {
        self.items.get(..self.len).unwrap_or(&[])
    }
}

/// The fitted line: offset at `x_ref` is `o_ref + c_us`, changing by `drift` µs per s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Line {
    pub(super) x_ref: u64,
    pub(super) o_ref: i64,
    pub(super) c_us: f64,
    /// Autopilot rate minus one, µs per s (ppm).
    pub(super) drift: f64,
    /// The inverse normal matrix (covariance of `c_us`, `drift`): `[cc, cd, dd]`.
    cov: [f64; 3],
}

impl Line {
    /// Predicted offset (relative to `o_ref`) at `dx` seconds from `x_ref`, and its variance.
    fn predict(&self, dx: f64) -> (f64, f64) {
        let [cc, cd, dd] = self.cov;
        (
            self.c_us + self.drift * dx,
            cc + 2.0 * cd * dx + dd * dx * dx,
        )
    }

    /// Offset (autopilot minus ours) at our time `t_us`, µs.
    pub(super) fn offset_at(&self, t_us: u64) -> Option<i64> {
        let dx = signed_diff(t_us, self.x_ref)? as f64 * 1e-6;
        self.o_ref.checked_add(round_i64(self.predict(dx).0)?)
    }
}

/// `a - b` as i64, `None` on overflow.
fn signed_diff(a: u64, b: u64) -> Option<i64> {
    i64::try_from(a).ok()?.checked_sub(i64::try_from(b).ok()?)
}

/// Rounds to i64 (`None` for NaN, infinities and out-of-range values).
pub(super) fn round_i64(v: f64) -> Option<i64> {
    let r = libm::round(v);
    // i64::MAX is not exactly representable; stay clear of it.
    (r.is_finite() && r.abs() < 9.0e18).then_some(r as i64)
}

/// Weighted least squares line through `samples` (offsets relative to the newest's), with a
/// prior on the drift. `None` without samples.
pub(super) fn fit(samples: &[Sample], prior_drift: f64) -> Option<Line> {
    let newest = samples.iter().max_by_key(|s| s.x_us)?;
    let (x_ref, o_ref) = (newest.x_us, newest.offset_us);
    let (mut s0, mut s1, mut s2, mut t0, mut t1) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for s in samples {
        let sigma = s.sigma_us + SIGMA_FLOOR_US;
        let w = 1.0 / (sigma * sigma);
        let dx = signed_diff(s.x_us, x_ref)? as f64 * 1e-6;
        let o = s.offset_us.checked_sub(o_ref)? as f64;
        s0 += w;
        s1 += w * dx;
        s2 += w * dx * dx;
        t0 += w * o;
        t1 += w * o * dx;
    }
    let wp = 1.0 / (DRIFT_PRIOR_SIGMA * DRIFT_PRIOR_SIGMA);
    let (s2p, t1p) = (s2 + wp, t1 + wp * prior_drift);
    let det = s0 * s2p - s1 * s1;
    if !(det.is_finite() && det > 0.0) {
        return None;
    }
    let c_us = (t0 * s2p - s1 * t1p) / det;
    let drift = ((s0 * t1p - s1 * t0) / det).clamp((MIN_RATE - 1.0) * 1e6, (MAX_RATE - 1.0) * 1e6);
    if !c_us.is_finite() || !drift.is_finite() {
        return None;
    }
    Some(Line {
        x_ref,
        o_ref,
        c_us,
        drift,
        cov: [s2p / det, -s1 / det, s0 / det],
    })
}

/// Whether `s` is within the gate of `line`.
pub(super) fn within_gate(line: &Line, s: &Sample) -> bool {
    let (Some(dx), Some(o)) = (
        signed_diff(s.x_us, line.x_ref),
        s.offset_us.checked_sub(line.o_ref),
    ) else {
        return false;
    };
    let (pred, var) = line.predict(dx as f64 * 1e-6);
    let gate = GATE_FLOOR_US + s.sigma_us + SIGMA_FLOOR_US + GATE_SIGMAS * libm::sqrt(var.max(0.0));
    let r = o as f64 - pred;
    r.abs() <= gate
}
