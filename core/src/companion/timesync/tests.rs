//! Tests of the clock estimator through its public surface, against a simulated autopilot
//! clock (offset, rate, jumps) and a jittery link.

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
