//! The offset between our boot clock and the flight controller's.
//!
//! LANDING_TARGET's `time_usec` should be the frame's exposure time; the flight controller
//! can only use it in its own clock, and the vehicle state it sends (ATTITUDE's
//! `time_boot_ms`) is in its clock too. Two sources, best first:
//!
//! - **TIMESYNC** (MAVLink's two-way exchange): we send `tc1 = 0, ts1 = our time (ns)`; the
//!   autopilot answers `tc1 = its time (ns), ts1 = ours, copied`. With the round trip `rtt`
//!   measured on our clock, its time at the midpoint of the exchange gives
//!   `offset = tc1 - (ts1 + now) / 2` (autopilot minus ours), uncertain by `rtt / 2` at most.
//!   Samples with a round trip above [`MAX_RTT_US`] (a queue somewhere) are discarded; the
//!   others are smoothed (a 1/8 exponential filter: enough to follow crystal drift of tens of
//!   ppm, quiet against UART jitter).
//! - **SYSTEM_TIME**'s `time_boot_ms`, used only while no TIMESYNC answer has arrived: it is
//!   late by the transport delay and quantised to 1 ms, still far better than nothing.
//!
//! A sample that disagrees with the estimate by more than [`JUMP_US`] is either an outlier or
//! a real change (the autopilot rebooted: its clock restarted near zero). One such sample is
//! ignored; [`JUMP_CONFIRM`] consecutive ones that agree with each other replace the estimate.
//! A reboot seen elsewhere (vehicle time going backwards, see [`super::vehicle`]) resets the
//! estimate at once with [`TimeSync::reset`].

/// Longest accepted TIMESYNC round trip, µs.
pub const MAX_RTT_US: u64 = 100_000;
/// A sample further than this from the estimate is a jump candidate, µs.
pub const JUMP_US: i64 = 50_000;
/// Consecutive agreeing jump candidates that replace the estimate.
pub const JUMP_CONFIRM: u8 = 2;
/// How many of our outstanding TIMESYNC requests are remembered (to match answers).
pub const PENDING_REQUESTS: usize = 4;

/// Where the current offset came from.
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

/// The clock offset estimator.
#[derive(Debug, Clone)]
pub struct TimeSync {
    offset_us: Option<i64>,
    source: TimeSource,
    pending: [Option<u64>; PENDING_REQUESTS],
    next_slot: usize,
    jump: Option<(i64, u8)>,
    samples: u32,
    rejected: u32,
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
            offset_us: None,
            source: TimeSource::None,
            pending: [None; PENDING_REQUESTS],
            next_slot: 0,
            jump: None,
            samples: 0,
            rejected: 0,
            jumps: 0,
            last_rtt_us: None,
        }
    }

    /// Forgets the offset (the autopilot rebooted).
    pub fn reset(&mut self) {
        self.offset_us = None;
        self.source = TimeSource::None;
        self.pending = [None; PENDING_REQUESTS];
        self.jump = None;
    }

    /// Autopilot time minus ours, µs.
    pub fn offset_us(&self) -> Option<i64> {
        self.offset_us
    }

    /// Where the offset came from.
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
        let off = self.offset_us?;
        let t = i64::try_from(t_us).ok()?.checked_add(off)?;
        u64::try_from(t).ok()
    }

    /// The autopilot's time `t_us` in our clock.
    pub fn from_autopilot(&self, t_us: u64) -> Option<u64> {
        let off = self.offset_us?;
        let t = i64::try_from(t_us).ok()?.checked_sub(off)?;
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
    /// time (ns), received at `now_us`. Returns whether it was used.
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
        let mid = i64::try_from(sent_us + rtt / 2).unwrap_or(i64::MAX);
        let sample = tc1_ns / 1000 - mid;
        self.last_rtt_us = Some(rtt);
        self.samples = self.samples.saturating_add(1);
        self.fuse(sample, TimeSource::Timesync);
        true
    }

    /// SYSTEM_TIME's `time_boot_ms` received at `now_us` (used only without TIMESYNC).
    pub fn on_system_time(&mut self, time_boot_ms: u32, now_us: u64) {
        if self.source == TimeSource::Timesync {
            return;
        }
        let sample = i64::from(time_boot_ms) * 1000 - i64::try_from(now_us).unwrap_or(i64::MAX);
        self.fuse(sample, TimeSource::SystemTime);
    }

    fn fuse(&mut self, sample: i64, source: TimeSource) {
        let upgrade = source == TimeSource::Timesync && self.source != TimeSource::Timesync;
        match self.offset_us {
            Some(off) if !upgrade => {
                if (sample - off).abs() <= JUMP_US {
                    self.offset_us = Some(off + (sample - off) / 8);
                    self.jump = None;
                    return;
                }
                let count = match self.jump {
                    Some((j, n)) if (sample - j).abs() <= JUMP_US => n.saturating_add(1),
                    _ => 1,
                };
                if count >= JUMP_CONFIRM {
                    self.offset_us = Some(sample);
                    self.jumps = self.jumps.saturating_add(1);
                    self.jump = None;
                } else {
                    self.jump = Some((sample, count));
                }
            }
            _ => {
                self.offset_us = Some(sample);
                self.source = source;
                self.jump = None;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_gives_offset() {
        let mut ts = TimeSync::new();
        let ts1 = ts.request(1_000_000);
        // Autopilot 5 s ahead, answers at our 1.010 s (rtt 20 ms, midpoint 1.010).
        assert!(ts.on_response((6_010_000i64) * 1000, ts1, 1_020_000));
        assert_eq!(ts.offset_us(), Some(5_000_000));
        assert_eq!(ts.to_autopilot(2_000_000), Some(7_000_000));
        // A stale or foreign answer is refused.
        assert!(!ts.on_response(1, 12345, 1_030_000));
    }

    #[test]
    fn jump_needs_confirmation() {
        let mut ts = TimeSync::new();
        let t = ts.request(0);
        ts.on_response(5_000_000_000, t, 0);
        for k in 1..=2u64 {
            let now = k * 1_000_000;
            let t = ts.request(now);
            // Rebooted autopilot: its clock at 0.1 s.
            ts.on_response(100_000_000 + (k as i64 - 1) * 1_000_000_000, t, now);
        }
        assert_eq!(ts.offset_us(), Some(100_000 - 1_000_000));
        assert_eq!(ts.jumps(), 1);
    }
}
