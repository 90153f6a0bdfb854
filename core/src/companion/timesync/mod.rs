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
//!
//! The sample windows and the weighted line fit with its gate are in `line`; this module is
//! the estimator's public surface and its decisions (which sample to fuse, when a jump is
//! real, what the mapping is).

mod line;
#[cfg(test)]
mod tests;

use line::{fit, round_i64, within_gate, Line, Sample, Samples};

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
