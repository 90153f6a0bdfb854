//! The relation between our boot clock and the flight controller's: offset **and rate**.
//!
//! LANDING_TARGET's `time_usec` should be the frame's exposure time; the flight controller
//! can only use it in its own clock, and the vehicle state it sends (ATTITUDE's
//! `time_boot_ms`, LOCAL_POSITION_NED's) is in its clock too, so every received stamp is
//! mapped to ours before it is compared with an exposure time.
//!
//! # Why a rate
//!
//! Two crystals differ by tens of ppm, but simulated autopilots do not run at wall-clock speed
//! at all: PX4 SITL runs 1-2 % slow, lock-step SITL and HITL follow the simulator, and sim
//! speed factors scale it on purpose. At 2 % the offset moves by 20 ms every second; an
//! offset-only filter lags it by tens of milliseconds, long enough for the vehicle state to
//! be mapped beyond [`crate::filter::vehicle::MAX_EXTRAPOLATION_US`] (measured: a third of PX4
//! SITL's frames found no vehicle state). So the model is a line,
//!
//! `autopilot = ours + offset + drift * (ours - reference)`,
//!
//! fitted to the last [`WINDOW`] samples by weighted least squares (closed form, 2x2 normal
//! equations, f64: the M7 has a double-precision FPU). A window rather than a recursive
//! filter: it converges in two samples, forgets old samples on its own (a simulator's speed
//! wanders), is exact for a constant rate, and cannot diverge. PX4's own Timesync (Holt's
//! double exponential smoothing, converging over 500 samples) needs a 10 ms round trip limit
//! and minutes; at one TIMESYNC a second we cannot wait that long.
//!
//! # Samples
//!
//! - **TIMESYNC** (MAVLink's two-way exchange): we send `tc1 = 0, ts1 = our time (ns)`; the
//!   autopilot answers `tc1 = its time (ns), ts1 = ours, copied`. Its time is taken to be that
//!   of the midpoint of the round trip, wrong by at most `rtt / 2` (asymmetric delays). So a
//!   sample's weight is `1 / (rtt / 2 + SIGMA_FLOOR_US)²`: short round trips count more, a
//!   queue somewhere (a long round trip) hardly counts, and above [`MAX_RTT_US`] a sample is
//!   discarded. (Weighting by the excess over the window's shortest round trip, NTP's minimum
//!   filter, was tried: it leans on so few samples that the rate, hence the extrapolation to
//!   the present, gets worse.)
//! - **SYSTEM_TIME**'s `time_boot_ms`, used only while no TIMESYNC answer has arrived: late by
//!   the transport delay and quantised to 1 ms, weighted as [`SYSTEM_TIME_SIGMA_US`]. The first
//!   TIMESYNC sample restarts the window (the two kinds are biased differently).
//!
//! # Outliers and jumps
//!
//! A new sample is compared with the line's prediction at its time. Further than the gate
//! (`GATE_FLOOR_US + rtt / 2 + GATE_SIGMAS` times the prediction's own uncertainty, so that a
//! young estimate with an unknown rate is not over-confident) it is not fused: a single
//! delayed or mis-stamped reply changes nothing. It is a jump *candidate*. [`JUMP_CONFIRM`]
//! consecutive candidates that lie on a line of their own (same test, among themselves) are a
//! real change (the autopilot rebooted or changed its clock source): the window is replaced
//! by them and [`TimeSync::jumps`] counts it. Any sample that passes the gate clears the
//! candidates, so scattered outliers never add up to a reset. A reboot seen elsewhere (vehicle
//! time going backwards, see [`crate::filter::vehicle`]) resets the estimate at once with
//! [`TimeSync::reset`]; the rate is kept as the prior of the next fit (same crystal, same
//! simulator), with a weak weight that two samples outvote.
//!
//! Fixed capacity, no allocation, bounded work: a fit is `O(WINDOW)` once per sample (1 Hz),
//! a mapping `O(1)`.

/// Longest accepted TIMESYNC round trip, µs (longer ones are not even a jump candidate).
pub const MAX_RTT_US: u64 = 100_000;
/// Samples in the fitting window (32 s at one TIMESYNC a second).
pub const WINDOW: usize = 32;
/// Consecutive agreeing jump candidates that replace the estimate.
pub const JUMP_CONFIRM: usize = 3;
/// How many of our outstanding TIMESYNC requests are remembered (to match answers).
pub const PENDING_REQUESTS: usize = 4;
/// Uncertainty of a sample besides half its round trip (time stamping on both sides), µs.
pub const SIGMA_FLOOR_US: f64 = 200.0;
/// Uncertainty of a SYSTEM_TIME sample (transport delay, 1 ms quantisation), µs.
pub const SYSTEM_TIME_SIGMA_US: f64 = 5_000.0;
/// Part of the outlier gate that does not shrink with confidence, µs: well above round-trip
/// jitter, well below what would push vehicle state out of its extrapolation limit.
pub const GATE_FLOOR_US: f64 = 20_000.0;
/// The gate's width in standard deviations of the prediction.
pub const GATE_SIGMAS: f64 = 4.0;
/// Prior uncertainty of the drift, µs per s (5 %): weak, only decides the rate from a single
/// sample; two samples a second apart outweigh it a thousandfold.
pub const DRIFT_PRIOR_SIGMA: f64 = 50_000.0;
/// Accepted autopilot rates, autopilot seconds per our second (sim speed factors included);
/// a fit outside is clamped.
pub const MIN_RATE: f64 = 0.1;
/// See [`MIN_RATE`].
pub const MAX_RATE: f64 = 10.0;

/// Where the current estimate came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TimeSource {
    /// No offset known: `time_usec` is our boot time.
    None,
    /// From SYSTEM_TIME (coarse).
    SystemTime,
    /// From TIMESYNC round trips.
    Timesync,
}

/// One observation: at our time `x_us` the autopilot's clock read `x_us + offset_us`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sample {
    x_us: u64,
    offset_us: i64,
    /// Half the round trip (the bound on the midpoint's error), or SYSTEM_TIME's
    /// uncertainty, µs.
    sigma_us: f64,
}

const EMPTY: Sample = Sample {
    x_us: 0,
    offset_us: 0,
    sigma_us: 1.0,
};

/// A fixed ring of samples; `items[..len]` are valid (filled from 0, then overwritten in
/// order, so validity is a prefix).
#[derive(Debug, Clone, PartialEq)]
struct Samples<const N: usize> {
    items: [Sample; N],
    len: usize,
    next: usize,
}

impl<const N: usize> Samples<N> {
    const fn new() -> Self {
        Samples {
            items: [EMPTY; N],
            len: 0,
            next: 0,
        }
    }

    fn clear(&mut self) {
        self.len = 0;
        self.next = 0;
    }

    fn push(&mut self, s: Sample) {
        if let Some(slot) = self.items.get_mut(self.next) {
            *slot = s;
        }
        self.next = (self.next + 1) % N;
        self.len = (self.len + 1).min(N);
    }

    fn as_slice(&self) -> &[Sample] {
        self.items.get(..self.len).unwrap_or(&[])
    }
}

/// The fitted line: offset at `x_ref` is `o_ref + c_us`, changing by `drift` µs per s.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Line {
    x_ref: u64,
    o_ref: i64,
    c_us: f64,
    /// Autopilot rate minus one, µs per s (ppm).
    drift: f64,
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
    fn offset_at(&self, t_us: u64) -> Option<i64> {
        let dx = signed_diff(t_us, self.x_ref)? as f64 * 1e-6;
        self.o_ref.checked_add(round_i64(self.predict(dx).0)?)
    }
}

/// `a - b` as i64, `None` on overflow.
fn signed_diff(a: u64, b: u64) -> Option<i64> {
    i64::try_from(a).ok()?.checked_sub(i64::try_from(b).ok()?)
}

/// Rounds to i64 (`None` for NaN, infinities and out-of-range values).
fn round_i64(v: f64) -> Option<i64> {
    let r = libm::round(v);
    // i64::MAX is not exactly representable; stay clear of it.
    (r.is_finite() && r.abs() < 9.0e18).then_some(r as i64)
}

/// Weighted least squares line through `samples` (offsets relative to the newest's), with a
/// prior on the drift. `None` without samples.
fn fit(samples: &[Sample], prior_drift: f64) -> Option<Line> {
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
fn within_gate(line: &Line, s: &Sample) -> bool {
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

/// The clock offset and drift estimator.
#[derive(Debug, Clone)]
pub struct TimeSync {
    window: Samples<WINDOW>,
    candidates: Samples<JUMP_CONFIRM>,
    line: Option<Line>,
    /// The drift the next fit leans towards (the last fitted one: kept across resets).
    prior_drift: f64,
    source: TimeSource,
    pending: [Option<u64>; PENDING_REQUESTS],
    next_slot: usize,
    samples: u32,
    rejected: u32,
    outliers: u32,
    jumps: u32,
    last_rtt_us: Option<u64>,
}

impl Default for TimeSync {
    fn default() -> Self {
        Self::new()
    }
}

impl TimeSync {
    /// Nothing known.
    pub const fn new() -> Self {
        TimeSync {
            window: Samples::new(),
            candidates: Samples::new(),
            line: None,
            prior_drift: 0.0,
            source: TimeSource::None,
            pending: [None; PENDING_REQUESTS],
            next_slot: 0,
            samples: 0,
            rejected: 0,
            outliers: 0,
            jumps: 0,
            last_rtt_us: None,
        }
    }

    /// Forgets the estimate (the autopilot rebooted); the drift stays as the next prior.
    pub fn reset(&mut self) {
        if let Some(l) = &self.line {
            self.prior_drift = l.drift;
        }
        self.window.clear();
        self.candidates.clear();
        self.line = None;
        self.source = TimeSource::None;
        self.pending = [None; PENDING_REQUESTS];
    }

    /// Autopilot time minus ours at the newest sample, µs.
    pub fn offset_us(&self) -> Option<i64> {
        let l = self.line.as_ref()?;
        l.offset_at(l.x_ref)
    }

    /// Autopilot time minus ours at our time `t_us`, µs.
    pub fn offset_at_us(&self, t_us: u64) -> Option<i64> {
        self.line.as_ref()?.offset_at(t_us)
    }

    /// The autopilot's rate minus one, ppm (-20 000: 2 % slow).
    pub fn drift_ppm(&self) -> Option<f64> {
        self.line.as_ref().map(|l| l.drift)
    }

    /// Where the estimate came from.
    pub fn source(&self) -> TimeSource {
        self.source
    }

    /// Accepted TIMESYNC samples.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// TIMESYNC answers discarded (round trip too long, or not ours).
    pub fn rejected(&self) -> u32 {
        self.rejected
    }

    /// Samples outside the gate (outliers, or the first samples of a jump).
    pub fn outliers(&self) -> u32 {
        self.outliers
    }

    /// Times a confirmed jump replaced the estimate.
    pub fn jumps(&self) -> u32 {
        self.jumps
    }

    /// Round trip of the last accepted sample, µs.
    pub fn last_rtt_us(&self) -> Option<u64> {
        self.last_rtt_us
    }

    /// Our time `t_us` in the autopilot's clock (`None` when unknown or before its boot).
    pub fn to_autopilot(&self, t_us: u64) -> Option<u64> {
        let off = self.offset_at_us(t_us)?;
        let t = i64::try_from(t_us).ok()?.checked_add(off)?;
        u64::try_from(t).ok()
    }

    /// The autopilot's time `t_us` in our clock (the line inverted).
    pub fn from_autopilot(&self, t_us: u64) -> Option<u64> {
        let l = self.line.as_ref()?;
        // The autopilot's time at x_ref is x_ref + o_ref + c; it runs at 1 + drift/1e6.
        let base = i64::try_from(l.x_ref).ok()?.checked_add(l.o_ref)?;
        let u = i64::try_from(t_us).ok()?.checked_sub(base)? as f64 - l.c_us;
        let dx = round_i64(u / (1.0 + l.drift * 1e-6))?;
        let t = i64::try_from(l.x_ref).ok()?.checked_add(dx)?;
        u64::try_from(t).ok()
    }

    /// Remembers a request sent at `now_us`; returns the `ts1` to send (ns).
    pub fn request(&mut self, now_us: u64) -> i64 {
        if let Some(slot) = self.pending.get_mut(self.next_slot) {
            *slot = Some(now_us);
        }
        self.next_slot = (self.next_slot + 1) % PENDING_REQUESTS;
        i64::try_from(now_us.saturating_mul(1000)).unwrap_or(i64::MAX)
    }

    /// An answer to one of our requests: `tc1` the autopilot's time (ns), `ts1` our request's
    /// time (ns), received at `now_us`. Returns whether it was fused (an outlier or jump
    /// candidate is not).
    pub fn on_response(&mut self, tc1_ns: i64, ts1_ns: i64, now_us: u64) -> bool {
        let sent_us = u64::try_from(ts1_ns / 1000).unwrap_or(u64::MAX);
        let Some(slot) = self
            .pending
            .iter_mut()
            .find(|s| s.is_some_and(|t| t == sent_us))
        else {
            self.rejected = self.rejected.saturating_add(1);
            return false;
        };
        *slot = None;
        let rtt = now_us.saturating_sub(sent_us);
        if now_us < sent_us || rtt > MAX_RTT_US || tc1_ns <= 0 {
            self.rejected = self.rejected.saturating_add(1);
            return false;
        }
        let mid = sent_us + rtt / 2;
        let Some(offset_us) = i64::try_from(mid)
            .ok()
            .and_then(|m| (tc1_ns / 1000).checked_sub(m))
        else {
            self.rejected = self.rejected.saturating_add(1);
            return false;
        };
        self.last_rtt_us = Some(rtt);
        self.samples = self.samples.saturating_add(1);
        let sample = Sample {
            x_us: mid,
            offset_us,
            sigma_us: rtt as f64 / 2.0,
        };
        self.fuse(sample, TimeSource::Timesync)
    }

    /// SYSTEM_TIME's `time_boot_ms` received at `now_us` (used only without TIMESYNC).
    pub fn on_system_time(&mut self, time_boot_ms: u32, now_us: u64) {
        if self.source == TimeSource::Timesync {
            return;
        }
        let Ok(now) = i64::try_from(now_us) else {
            return;
        };
        let sample = Sample {
            x_us: now_us,
            offset_us: i64::from(time_boot_ms) * 1000 - now,
            sigma_us: SYSTEM_TIME_SIGMA_US,
        };
        self.fuse(sample, TimeSource::SystemTime);
    }

    fn fuse(&mut self, s: Sample, source: TimeSource) -> bool {
        if source == TimeSource::Timesync && self.source != TimeSource::Timesync {
            // TIMESYNC replaces SYSTEM_TIME's biased samples; their drift is still a guess.
            if let Some(l) = &self.line {
                self.prior_drift = l.drift;
            }
            self.window.clear();
            self.candidates.clear();
            self.line = None;
        }
        self.source = source;
        let accepted = match &self.line {
            None => true,
            Some(line) => within_gate(line, &s),
        };
        if accepted {
            self.candidates.clear();
            self.window.push(s);
            self.refit();
            return true;
        }
        self.outliers = self.outliers.saturating_add(1);
        self.candidates.push(s);
        if self.candidates.len == JUMP_CONFIRM {
            let agree = fit(
                self.candidates.as_slice(),
                self.line.map_or(0.0, |l| l.drift),
            )
            .is_some_and(|l| {
                self.candidates
                    .as_slice()
                    .iter()
                    .all(|c| within_gate(&l, c))
            });
            if agree {
                // A real change: start over from the candidates.
                self.window.clear();
                for c in self.candidates.as_slice() {
                    self.window.push(*c);
                }
                self.candidates.clear();
                self.jumps = self.jumps.saturating_add(1);
                self.refit();
            }
        }
        false
    }

    fn refit(&mut self) {
        let prior = self.line.map_or(self.prior_drift, |l| l.drift);
        // A degenerate fit (cannot happen with positive weights) keeps the last line.
        if let Some(l) = fit(self.window.as_slice(), prior) {
            self.line = Some(l);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// splitmix64: deterministic link jitter.
    struct Rng(u64);
    impl Rng {
        fn uniform(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        }
        /// One way of the link: 0.5-4 ms (round trips of 1-8 ms).
        fn delay(&mut self) -> u64 {
            500 + (self.uniform() * 3500.0) as u64
        }
    }

    /// An autopilot clock: `start + rate * t`, plus `jump` from `jump_at` on.
    #[derive(Clone, Copy)]
    struct Clock {
        start: f64,
        rate: f64,
        jump_at: u64,
        jump: f64,
    }
    impl Clock {
        fn new(rate: f64) -> Self {
            Clock {
                start: 100.0e6,
                rate,
                jump_at: u64::MAX,
                jump: 0.0,
            }
        }
        fn at(&self, t: u64) -> f64 {
            let j = if t >= self.jump_at { self.jump } else { 0.0 };
            self.start + self.rate * t as f64 + j
        }
    }

    /// One exchange sent at `now`; `extra_tc1_us` corrupts the answer's stamp. Returns
    /// whether it was fused.
    fn exchange(ts: &mut TimeSync, c: &Clock, rng: &mut Rng, now: u64, extra_tc1_us: f64) -> bool {
        let (up, down) = (rng.delay(), rng.delay());
        let ts1 = ts.request(now);
        let tc1 = ((c.at(now + up) + extra_tc1_us) * 1000.0) as i64;
        ts.on_response(tc1, ts1, now + up + down)
    }

    /// Largest |error| of the mapping, µs, over the second after `now` (where stamps are
    /// mapped until the next sample), both directions.
    fn error_after(ts: &TimeSync, c: &Clock, now: u64) -> f64 {
        let mut worst = 0.0f64;
        for k in 0..=10u64 {
            let t = now + k * 100_000;
            let ap = ts.to_autopilot(t).unwrap() as f64;
            worst = worst.max((ap - c.at(t)).abs());
            let back = ts.from_autopilot(c.at(t) as u64).unwrap() as f64;
            worst = worst.max((back - t as f64).abs());
        }
        worst
    }

    #[test]
    fn round_trip_gives_offset() {
        let mut ts = TimeSync::new();
        let ts1 = ts.request(1_000_000);
        // Autopilot 5 s ahead, answers at our 1.010 s (rtt 20 ms, midpoint 1.010).
        assert!(ts.on_response((6_010_000i64) * 1000, ts1, 1_020_000));
        assert_eq!(ts.offset_us(), Some(5_000_000));
        assert_eq!(ts.to_autopilot(2_000_000), Some(7_000_000));
        assert_eq!(ts.from_autopilot(7_000_000), Some(2_000_000));
        // A stale or foreign answer is refused.
        assert!(!ts.on_response(1, 12345, 1_030_000));
        assert_eq!(ts.rejected(), 1);
    }

    #[test]
    fn drift_of_two_percent_is_recovered() {
        for rate in [0.98, 1.02] {
            let c = Clock::new(rate);
            let mut ts = TimeSync::new();
            let mut rng = Rng(7);
            let truth = (rate - 1.0) * 1e6;
            let mut errors = [0.0; 40];
            for (k, e) in errors.iter_mut().enumerate() {
                let now = 1_000_000 + k as u64 * 1_000_000;
                assert!(exchange(&mut ts, &c, &mut rng, now, 0.0));
                *e = (ts.drift_ppm().unwrap() - truth).abs();
            }
            // Two samples give the rate to a few 1000 ppm (±4 ms over 1 s), five to a few
            // hundred, a full window to tens.
            assert!(errors[1] < 5_000.0, "{rate}: {errors:?}");
            assert!(errors[4] < 800.0, "{rate}: {errors:?}");
            assert!(
                errors[WINDOW..].iter().all(|e| *e < 150.0),
                "{rate}: {errors:?}"
            );
            assert_eq!(ts.jumps(), 0);
            assert_eq!(ts.outliers(), 0);
        }
    }

    #[test]
    fn offset_error_below_a_millisecond_at_two_percent() {
        for rate in [0.98, 1.0, 1.02] {
            let c = Clock::new(rate);
            let mut ts = TimeSync::new();
            let mut rng = Rng(42);
            let mut converged_after = None;
            let mut worst = 0.0f64;
            for k in 0..300u64 {
                let now = 1_000_000 + k * 1_000_000 + rng.delay();
                exchange(&mut ts, &c, &mut rng, now, 0.0);
                let e = error_after(&ts, &c, now);
                if e >= 1000.0 {
                    converged_after = None;
                } else if converged_after.is_none() {
                    converged_after = Some(k + 1);
                }
                if k >= 8 {
                    worst = worst.max(e);
                }
            }
            let n = converged_after.unwrap();
            assert!(n <= 8, "{rate}: within 1 ms only after {n} samples");
            assert!(worst < 1000.0, "{rate}: {worst:.0} µs after convergence");
            assert_eq!(ts.jumps(), 0);
        }
    }

    #[test]
    fn single_outlier_does_not_move_it() {
        let c = Clock::new(0.98);
        let mut ts = TimeSync::new();
        let mut rng = Rng(3);
        for k in 0..20u64 {
            exchange(&mut ts, &c, &mut rng, k * 1_000_000, 0.0);
        }
        let before = (ts.offset_at_us(25_000_000), ts.drift_ppm());
        // A reply mis-stamped by +200 ms: gated out.
        assert!(!exchange(&mut ts, &c, &mut rng, 20_000_000, 200_000.0));
        assert_eq!((ts.offset_at_us(25_000_000), ts.drift_ppm()), before);
        assert_eq!(ts.outliers(), 1);
        // A reply delayed by 200 ms: the round trip alone refuses it.
        let ts1 = ts.request(21_000_000);
        let tc1 = (c.at(21_001_000) * 1000.0) as i64;
        assert!(!ts.on_response(tc1, ts1, 21_202_000));
        assert_eq!((ts.offset_at_us(25_000_000), ts.drift_ppm()), before);
        // And the next good ones carry on.
        for k in 22..30u64 {
            assert!(exchange(&mut ts, &c, &mut rng, k * 1_000_000, 0.0));
        }
        assert!(error_after(&ts, &c, 29_000_000) < 1000.0);
        assert_eq!(ts.jumps(), 0);
    }

    #[test]
    fn real_jump_is_followed_within_a_few_samples() {
        let mut c = Clock::new(0.98);
        c.jump_at = 30_000_000;
        c.jump = 5.0e6;
        let mut ts = TimeSync::new();
        let mut rng = Rng(11);
        let mut followed_after = None;
        for k in 0..60u64 {
            let now = k * 1_000_000;
            exchange(&mut ts, &c, &mut rng, now, 0.0);
            if now >= c.jump_at && followed_after.is_none() && error_after(&ts, &c, now) < 2000.0 {
                followed_after = Some(k - 29);
            }
        }
        assert_eq!(followed_after, Some(JUMP_CONFIRM as u64));
        assert_eq!(ts.jumps(), 1);
        assert!(error_after(&ts, &c, 59_000_000) < 1000.0);
    }

    #[test]
    fn no_reset_storms() {
        // 10 minutes at 2 %: one reply in 7 mis-stamped by 50-500 ms either way, and pairs of
        // consecutive outliers now and then: never a jump, and the mapping stays right.
        let c = Clock::new(0.98);
        let mut ts = TimeSync::new();
        let mut rng = Rng(99);
        let mut worst = 0.0f64;
        for k in 0..600u64 {
            let now = k * 1_000_000;
            let bad = k > 2 && (k % 7 == 0 || k % 50 == 1 || k % 50 == 2);
            let extra = if bad {
                let m = 50_000.0 + rng.uniform() * 450_000.0;
                if rng.uniform() < 0.5 {
                    m
                } else {
                    -m
                }
            } else {
                0.0
            };
            exchange(&mut ts, &c, &mut rng, now, extra);
            if k >= 8 {
                worst = worst.max(error_after(&ts, &c, now));
            }
        }
        assert_eq!(ts.jumps(), 0);
        assert!(ts.outliers() > 90);
        // A sixth of the samples lost to outliers: slightly worse than the clean 1 ms.
        assert!(worst < 1500.0, "{worst:.0} µs");
    }

    #[test]
    fn reboot_reset_keeps_the_rate_as_prior() {
        let c = Clock::new(0.98);
        let mut ts = TimeSync::new();
        let mut rng = Rng(5);
        for k in 0..20u64 {
            exchange(&mut ts, &c, &mut rng, k * 1_000_000, 0.0);
        }
        ts.reset();
        assert_eq!(ts.offset_us(), None);
        assert_eq!(ts.source(), TimeSource::None);
        // The rebooted autopilot: its clock restarts near 0.
        let mut c2 = c;
        c2.start = -0.98 * 20.0e6 + 100_000.0;
        exchange(&mut ts, &c2, &mut rng, 20_000_000, 0.0);
        // One sample: offset from it, rate from before the reboot.
        assert!((ts.drift_ppm().unwrap() + 20_000.0).abs() < 200.0);
        assert!(error_after(&ts, &c2, 20_000_000) < 3000.0);
        assert_eq!(ts.jumps(), 0);
    }

    #[test]
    fn system_time_until_timesync() {
        let mut ts = TimeSync::new();
        // Autopilot 5 s ahead, SYSTEM_TIME arriving 3 ms late.
        for k in 0..3u64 {
            let now = k * 1_000_000 + 3_000;
            ts.on_system_time((5_000 + k * 1000) as u32, now);
        }
        assert_eq!(ts.source(), TimeSource::SystemTime);
        let off = ts.offset_us().unwrap();
        assert!((off - 4_997_000).abs() < 100, "{off}");
        let t = ts.request(3_000_000);
        assert!(ts.on_response(8_001_000_000, t, 3_002_000));
        assert_eq!(ts.source(), TimeSource::Timesync);
        assert_eq!(ts.offset_us(), Some(5_000_000));
        // SYSTEM_TIME no longer counts.
        ts.on_system_time(9_000, 4_000_000);
        assert_eq!(ts.offset_us(), Some(5_000_000));
    }

    #[test]
    fn extreme_values_do_not_panic() {
        let mut ts = TimeSync::new();
        let t = ts.request(u64::MAX / 2000);
        ts.on_response(i64::MAX, t, u64::MAX / 2000);
        let t = ts.request(u64::MAX);
        ts.on_response(i64::MAX, t, u64::MAX);
        ts.on_system_time(u32::MAX, u64::MAX);
        ts.on_system_time(0, 0);
        let _ = ts.to_autopilot(u64::MAX);
        let _ = ts.from_autopilot(u64::MAX);
        let _ = ts.from_autopilot(0);
        let _ = ts.offset_us();
    }
}
