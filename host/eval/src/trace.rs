//! The per-frame record of a replay and the figures computed from it: RMS error, detection
//! and estimate rates, the longest gap without an estimate, the filter's lag, and the error
//! at altitude checkpoints.
//!
//! A [`Trace`] holds, per frame, the time, the true camera position in the pad frame (when
//! known), the set-point label, the sequence the frame belongs to, and what every method made
//! of it ([`MethodOutcome`]: pose found, raw position, filtered estimate). `touchdown replay`
//! fills one from [`crate::Experiment::process`] and prints and plots from it
//! (the command line's plots); the set-point tables come from the experiment's own report.
//!
//! ## Definitions
//! - **error** = truth - estimate, per axis (the paper's sign, as in [`crate`]).
//! - **RMS**: over the frames with both a truth and an estimate.
//! - **gap**: within a sequence and after its first estimate, a run of consecutive frames
//!   without an estimate. Its length in seconds is the time between the estimates either
//!   side of it (or up to the sequence's last frame when no estimate follows), i.e. how long
//!   a flight controller would go without a fresh target. The frames before a sequence's
//!   first estimate are the **acquisition**, reported apart.
//! - **lag**: the time shift `tau` (frames) that minimises the weighted mean of
//!   `|estimate(t) - truth(t - tau)|^2`, the truth interpolated linearly between frames of
//!   the same sequence; weights `1 / max(z, 1 m)^2` (a position error grows about in
//!   proportion to the distance, so its variance with its square). Searched over
//!   [`LAG_SEARCH_FRAMES`] in steps of [`LAG_STEP_FRAMES`], using only the frames for which
//!   every shift stays inside their sequence. A hover gives no lag to measure: the lag is
//!   reported only when the truth moves at [`LAG_MIN_SPEED_M_S`] or more on average over
//!   those frames and there are at least [`LAG_MIN_FRAMES`] of them.

use nalgebra::Vector3;

use crate::MethodOutcome;

/// Range of time shifts searched for the lag, frames (negative: the estimate leads).
pub const LAG_SEARCH_FRAMES: (f64, f64) = (-5.0, 25.0);
/// Step of the lag search, frames.
pub const LAG_STEP_FRAMES: f64 = 0.05;
/// Mean true speed below which no lag is reported, m/s.
pub const LAG_MIN_SPEED_M_S: f64 = 0.2;
/// Fewest usable frames for a lag.
pub const LAG_MIN_FRAMES: usize = 30;

/// One frame of a replay.
#[derive(Debug, Clone, PartialEq)]
pub struct TraceFrame {
    /// Position in the input (0, 1, ...).
    pub index: usize,
    /// Time, microseconds.
    pub t_us: u64,
    /// The sequence (filters reset at its start), counting from 0.
    pub sequence: usize,
    /// True camera centre in the pad frame, metres, when known.
    pub truth: Option<Vector3<f64>>,
    /// Set-point label, if any.
    pub label: Option<String>,
    /// What each method made of the frame, in method order.
    pub outcomes: Vec<MethodOutcome>,
}

impl TraceFrame {
    /// Time in seconds.
    pub fn t_s(&self) -> f64 {
        self.t_us as f64 * 1e-6
    }
}

/// Every frame of a replay, for every method.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trace {
    /// Method names, in outcome order.
    pub methods: Vec<String>,
    /// The frames, in time order.
    pub frames: Vec<TraceFrame>,
}

/// A run of frames without an estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gap {
    /// Frames in the run.
    pub frames: usize,
    /// Time without a fresh estimate, seconds (see the module docs).
    pub seconds: f64,
    /// Index of the run's first frame.
    pub first_index: usize,
}

/// How long a sequence took to give its first estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Acquisition {
    /// Frames of the sequence before its first estimate.
    pub frames: usize,
    /// Index of the first frame with an estimate.
    pub index: usize,
    /// True altitude at that frame, metres, when known.
    pub altitude_m: Option<f64>,
}

/// The whole-replay figures of one method.
#[derive(Debug, Clone, PartialEq)]
pub struct MethodSummary {
    /// Frames replayed.
    pub frames: usize,
    /// Frames where the pose was computed.
    pub detected: usize,
    /// Frames with a filtered estimate.
    pub estimated: usize,
    /// Frames with both a truth and an estimate (the RMS is over these).
    pub scored: usize,
    /// RMS error of the filtered estimate per axis x, y, z, metres.
    pub rms: Option<[f64; 3]>,
    /// RMS error of the raw (unfiltered) positions per axis, metres.
    pub raw_rms: Option<[f64; 3]>,
    /// The longest gap after a first estimate (`None`: no estimate at all, or no gap).
    pub longest_gap: Option<Gap>,
    /// The slowest acquisition over the sequences (`None`: no estimate at all).
    pub slowest_acquisition: Option<Acquisition>,
    /// Sequences that never gave an estimate.
    pub sequences_without_estimate: usize,
    /// Lag, frames (`None`: not measurable, see the module docs).
    pub lag_frames: Option<f64>,
}

impl MethodSummary {
    /// Fraction of frames with a pose.
    pub fn detection_rate(&self) -> f64 {
        self.detected as f64 / self.frames.max(1) as f64
    }

    /// Fraction of frames with an estimate.
    pub fn estimate_rate(&self) -> f64 {
        self.estimated as f64 / self.frames.max(1) as f64
    }
}

/// One method's figures near one altitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AltitudeStats {
    /// The checkpoint, metres.
    pub altitude_m: f64,
    /// Frames whose true altitude is within the tolerance of it.
    pub frames: usize,
    /// Of those, frames with a pose.
    pub detected: usize,
    /// Of those, frames with an estimate.
    pub estimated: usize,
    /// Mean |error| of the estimates per axis, metres.
    pub mean_abs: Option<[f64; 3]>,
    /// Mean length of the error vector, metres.
    pub mean_norm: Option<f64>,
}

impl Trace {
    /// An empty trace for `methods`.
    pub fn new(methods: Vec<String>) -> Self {
        Trace {
            methods,
            frames: Vec::new(),
        }
    }

    /// Number of sequences.
    pub fn sequences(&self) -> usize {
        self.frames.last().map_or(0, |f| f.sequence + 1)
    }

    /// Whether any frame has a truth.
    pub fn has_truth(&self) -> bool {
        self.frames.iter().any(|f| f.truth.is_some())
    }

    /// The median time between consecutive frames of a sequence, seconds (the frame period;
    /// `None` with fewer than two frames in every sequence).
    pub fn frame_period_s(&self) -> Option<f64> {
        let mut steps: Vec<f64> = self
            .frames
            .windows(2)
            .filter(|w| w[0].sequence == w[1].sequence)
            .map(|w| (w[1].t_us.saturating_sub(w[0].t_us)) as f64 * 1e-6)
            .collect();
        if steps.is_empty() {
            return None;
        }
        steps.sort_by(f64::total_cmp);
        Some(steps[steps.len() / 2])
    }

    /// The frames of each sequence, in order.
    fn sequence_slices(&self) -> Vec<&[TraceFrame]> {
        let mut out = Vec::new();
        let mut start = 0;
        for k in 1..=self.frames.len() {
            if k == self.frames.len() || self.frames[k].sequence != self.frames[start].sequence {
                out.push(&self.frames[start..k]);
                start = k;
            }
        }
        out
    }

    /// The whole-replay figures of method `m` (index into [`Trace::methods`]).
    pub fn summary(&self, m: usize) -> MethodSummary {
        let outcome = |f: &TraceFrame| f.outcomes.get(m).copied();
        let mut summary = MethodSummary {
            frames: self.frames.len(),
            detected: 0,
            estimated: 0,
            scored: 0,
            rms: None,
            raw_rms: None,
            longest_gap: None,
            slowest_acquisition: None,
            sequences_without_estimate: 0,
            lag_frames: None,
        };
        let mut sq = [0.0f64; 3];
        let mut raw_sq = [0.0f64; 3];
        let mut raw_count = 0usize;
        for f in &self.frames {
            let Some(o) = outcome(f) else { continue };
            summary.detected += usize::from(o.pose_found);
            summary.estimated += usize::from(o.estimate.is_some());
            if let Some(truth) = f.truth {
                if let Some(e) = o.estimate {
                    summary.scored += 1;
                    add_squares(&mut sq, &(truth - e));
                }
                if let Some(r) = o.raw {
                    raw_count += 1;
                    add_squares(&mut raw_sq, &(truth - r));
                }
            }
        }
        summary.rms = rms(&sq, summary.scored);
        summary.raw_rms = rms(&raw_sq, raw_count);
        for sequence in self.sequence_slices() {
            let has = |f: &TraceFrame| outcome(f).is_some_and(|o| o.estimate.is_some());
            let Some(first) = sequence.iter().position(has) else {
                summary.sequences_without_estimate += 1;
                continue;
            };
            let acquisition = Acquisition {
                frames: first,
                index: sequence[first].index,
                altitude_m: sequence[first].truth.map(|t| t.z),
            };
            if summary
                .slowest_acquisition
                .is_none_or(|a| acquisition.frames > a.frames)
            {
                summary.slowest_acquisition = Some(acquisition);
            }
            let mut last_estimate = first;
            let mut k = first + 1;
            while k < sequence.len() {
                if has(&sequence[k]) {
                    last_estimate = k;
                    k += 1;
                    continue;
                }
                let run_start = k;
                while k < sequence.len() && !has(&sequence[k]) {
                    k += 1;
                }
                let until = sequence.get(k).unwrap_or(&sequence[sequence.len() - 1]);
                let gap = Gap {
                    frames: k - run_start,
                    seconds: until.t_s() - sequence[last_estimate].t_s(),
                    first_index: sequence[run_start].index,
                };
                if summary.longest_gap.is_none_or(|g| gap.frames > g.frames) {
                    summary.longest_gap = Some(gap);
                }
            }
        }
        summary.lag_frames = self.lag_frames(m);
        summary
    }

    /// The lag of method `m` in frames (see the module docs), `None` when not measurable.
    pub fn lag_frames(&self, m: usize) -> Option<f64> {
        let period = self.frame_period_s()?;
        let (lo, hi) = LAG_SEARCH_FRAMES;
        let sequences = self.sequence_slices();
        // Per sequence, its truth samples for interpolation.
        let truths: Vec<Vec<(f64, Vector3<f64>)>> = sequences
            .iter()
            .map(|s| {
                s.iter()
                    .filter_map(|f| f.truth.map(|t| (f.t_s(), t)))
                    .collect()
            })
            .collect();
        // (truth samples, t, estimate, weight) per usable frame.
        let mut points = Vec::new();
        let mut speed_sum = 0.0;
        for (sequence, samples) in sequences.iter().zip(&truths) {
            let (Some(begin), Some(end)) = (samples.first(), samples.last()) else {
                continue;
            };
            for f in sequence.iter() {
                let (Some(o), Some(truth)) = (f.outcomes.get(m), f.truth) else {
                    continue;
                };
                let Some(estimate) = o.estimate else { continue };
                let t = f.t_s();
                // Only frames whose every shift stays inside the sequence's truth.
                if t - hi * period < begin.0 || t - lo * period > end.0 {
                    continue;
                }
                let weight = 1.0 / truth.z.max(1.0).powi(2);
                let ahead = interpolate(samples, t + 0.5 * period);
                let behind = interpolate(samples, t - 0.5 * period);
                if let (Some(a), Some(b)) = (ahead, behind) {
                    speed_sum += (a - b).norm() / period;
                }
                points.push((samples.as_slice(), t, estimate, weight));
            }
        }
        if points.len() < LAG_MIN_FRAMES || speed_sum / (points.len() as f64) < LAG_MIN_SPEED_M_S {
            return None;
        }
        let steps = ((hi - lo) / LAG_STEP_FRAMES).round() as usize;
        let mut best: Option<(f64, f64)> = None;
        for step in 0..=steps {
            let tau = lo + step as f64 * LAG_STEP_FRAMES;
            let mut cost = 0.0;
            let mut weights = 0.0;
            for (samples, t, estimate, weight) in &points {
                if let Some(truth) = interpolate(samples, t - tau * period) {
                    cost += weight * (estimate - truth).norm_squared();
                    weights += weight;
                }
            }
            if weights > 0.0 {
                let cost = cost / weights;
                if best.is_none_or(|(c, _)| cost < c) {
                    best = Some((cost, tau));
                }
            }
        }
        best.map(|(_, tau)| tau)
    }

    /// Method `m`'s figures over the frames whose true altitude is within
    /// `tolerance * altitude_m` of `altitude_m`.
    pub fn at_altitude(&self, m: usize, altitude_m: f64, tolerance: f64) -> AltitudeStats {
        let mut stats = AltitudeStats {
            altitude_m,
            frames: 0,
            detected: 0,
            estimated: 0,
            mean_abs: None,
            mean_norm: None,
        };
        let mut abs = [0.0f64; 3];
        let mut norm = 0.0;
        for f in &self.frames {
            let (Some(truth), Some(o)) = (f.truth, f.outcomes.get(m)) else {
                continue;
            };
            if (truth.z - altitude_m).abs() > tolerance * altitude_m {
                continue;
            }
            stats.frames += 1;
            stats.detected += usize::from(o.pose_found);
            if let Some(e) = o.estimate {
                stats.estimated += 1;
                let error = truth - e;
                for (a, v) in abs.iter_mut().zip(error.iter()) {
                    *a += v.abs();
                }
                norm += error.norm();
            }
        }
        if stats.estimated > 0 {
            let n = stats.estimated as f64;
            stats.mean_abs = Some(abs.map(|a| a / n));
            stats.mean_norm = Some(norm / n);
        }
        stats
    }
}

fn add_squares(sums: &mut [f64; 3], error: &Vector3<f64>) {
    for (s, v) in sums.iter_mut().zip(error.iter()) {
        *s += v * v;
    }
}

fn rms(sums: &[f64; 3], count: usize) -> Option<[f64; 3]> {
    (count > 0).then(|| sums.map(|s| (s / count as f64).sqrt()))
}

/// The truth at time `t` (seconds) from samples sorted by time, linear between samples;
/// `None` outside them.
fn interpolate(samples: &[(f64, Vector3<f64>)], t: f64) -> Option<Vector3<f64>> {
    let (first, last) = (samples.first()?, samples.last()?);
    if t < first.0 || t > last.0 {
        return None;
    }
    let k = samples.partition_point(|s| s.0 <= t);
    if k == 0 {
        return Some(first.1);
    }
    let a = samples[k - 1];
    let Some(b) = samples.get(k) else {
        return Some(a.1);
    };
    let span = b.0 - a.0;
    if span <= 0.0 {
        return Some(a.1);
    }
    let w = (t - a.0) / span;
    Some(a.1 * (1.0 - w) + b.1 * w)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outcome(estimate: Option<Vector3<f64>>) -> MethodOutcome {
        MethodOutcome {
            pose_found: estimate.is_some(),
            raw: estimate,
            estimate,
        }
    }

    /// A 30 Hz descent at 1 m/s from 20 m, estimated `delay` frames late, with the frames in
    /// `missing` without an estimate.
    fn descent(delay: usize, missing: &[usize]) -> Trace {
        let mut trace = Trace::new(vec!["m".into()]);
        let truth = |k: usize| Vector3::new(0.0, 0.0, 20.0 - k as f64 / 30.0);
        for k in 0..300 {
            let estimate = (!missing.contains(&k)).then(|| truth(k.saturating_sub(delay)));
            trace.frames.push(TraceFrame {
                index: k,
                t_us: (k as u64 * 1_000_000) / 30,
                sequence: 0,
                truth: Some(truth(k)),
                label: None,
                outcomes: vec![outcome(estimate)],
            });
        }
        trace
    }

    #[test]
    fn lag_is_the_delay_of_a_delayed_estimate() {
        for delay in [0, 3, 7] {
            let lag = descent(delay, &[]).lag_frames(0).expect("a moving truth");
            assert!(
                (lag - delay as f64).abs() < 0.11,
                "delay {delay}: lag {lag}"
            );
        }
    }

    #[test]
    fn hover_has_no_lag() {
        let mut trace = descent(0, &[]);
        for f in &mut trace.frames {
            f.truth = Some(Vector3::new(0.0, 0.0, 10.0));
        }
        assert_eq!(trace.lag_frames(0), None);
    }

    #[test]
    fn gaps_and_rates() {
        let trace = descent(0, &[0, 1, 50, 51, 52, 200]);
        let s = trace.summary(0);
        assert_eq!(s.frames, 300);
        assert_eq!(s.estimated, 294);
        let gap = s.longest_gap.expect("a gap");
        assert_eq!((gap.frames, gap.first_index), (3, 50));
        // From frame 49 to frame 53.
        assert!((gap.seconds - 4.0 / 30.0).abs() < 1e-5, "{}", gap.seconds);
        let acquisition = s.slowest_acquisition.expect("an estimate");
        assert_eq!((acquisition.frames, acquisition.index), (2, 2));
        assert_eq!(s.rms, Some([0.0; 3]));
    }

    #[test]
    fn altitude_checkpoint_averages_the_frames_near_it() {
        let mut trace = descent(0, &[]);
        for f in &mut trace.frames {
            if let Some(e) = f.outcomes[0].estimate.as_mut() {
                e.x += 0.1;
            }
        }
        // 13.48..16.52 m at 1 m/s and 30 Hz: the frames 105..=195.
        let s = trace.at_altitude(0, 15.0, 0.101);
        assert_eq!(s.frames, 91);
        let mean_abs = s.mean_abs.expect("estimates");
        assert!((mean_abs[0] - 0.1).abs() < 1e-9 && mean_abs[2] < 1e-9);
        assert_eq!(trace.at_altitude(0, 100.0, 0.1).frames, 0);
    }

    #[test]
    fn interpolation_is_linear_and_bounded() {
        let s = [
            (0.0, Vector3::new(0.0, 0.0, 0.0)),
            (1.0, Vector3::new(2.0, 0.0, 0.0)),
        ];
        assert_eq!(interpolate(&s, 0.25), Some(Vector3::new(0.5, 0.0, 0.0)));
        assert_eq!(interpolate(&s, 1.0), Some(Vector3::new(2.0, 0.0, 0.0)));
        assert_eq!(interpolate(&s, 1.5), None);
    }
}
