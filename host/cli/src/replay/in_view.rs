//! Detection over the frames that show a pad marker whole (a simulated scenario only): the
//! frames a detector could have decoded. `lateral`'s 30 degree tilts swing the view off the
//! pad for part of each dash, so its all-frames rate mixes the detector's misses with frames
//! that hold nothing to find; the simulator knows where the markers' corners land
//! ([`touchdown_sim::Simulator::markers_in_view`]) and this keeps the two apart.
//!
//! - **in view**: at least one marker with its four outer corners [`MARGIN_PX`] inside the
//!   image and every side at least [`MIN_SIDE_PX`] long.
//! - **in-view gap**: within a stretch of consecutive in-view frames of one sequence, a run
//!   of frames without a pose. Its length in seconds runs from the frame before the run to
//!   the frame after it, each taken inside the stretch (the run's own first or last frame at
//!   the stretch's ends): as the all-frames gap, the time between poses either side, but
//!   never counting the frames out of view.

use super::input::{Input, Source};
use super::tables::MethodTable;
use touchdown_eval::trace::{Trace, TraceFrame};

/// How far inside the image each corner must be, pixels: the border's outer edge needs a
/// pixel of something else around it to be found.
pub(super) const MARGIN_PX: f64 = 1.0;
/// The shortest side of a marker in view, pixels: the detector's smallest quad edge
/// (`DetectorConfig::min_edge_px`, 7) with a pixel to spare.
pub(super) const MIN_SIDE_PX: f64 = 8.0;

/// One method's figures over the in-view frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct InViewSummary {
    /// Frames with a marker in view.
    pub(super) frames: usize,
    /// Of those, frames with a pose.
    pub(super) detected: usize,
    /// The longest in-view gap (module docs): frames, seconds, index of its first frame.
    pub(super) longest_gap: Option<(usize, f64, usize)>,
}

impl InViewSummary {
    /// Fraction of the in-view frames with a pose (0 without any in-view frame).
    pub(super) fn detection_rate(&self) -> f64 {
        self.detected as f64 / self.frames.max(1) as f64
    }
}

/// Per frame of `trace`, whether a marker is in view; `None` for a recording (no corners to
/// project).
pub(super) fn flags(input: &Input, trace: &Trace) -> Option<Vec<bool>> {
    let Source::Simulator(simulator) = &input.source else {
        return None;
    };
    Some(
        trace
            .frames
            .iter()
            .map(|f| {
                simulator
                    .markers_in_view(f.index, MARGIN_PX, MIN_SIDE_PX)
                    .is_some_and(|n| n > 0)
            })
            .collect(),
    )
}

/// The text table: per method, detection and the longest gap over the in-view frames.
pub(super) fn table(trace: &Trace, summaries: &[InViewSummary]) -> String {
    let frames = summaries.first().map_or(0, |s| s.frames);
    let title = format!(
        "\nOver the {frames} of {} frames with a marker whole in view (simulated corners)\n\n",
        trace.frames.len()
    );
    let mut table = MethodTable::new(&title, &trace.methods);
    let mut row = |name: &str, cell: &dyn Fn(&InViewSummary) -> String| {
        table.row(name, summaries.iter().map(cell))
    };
    row("in view: frames with a pose", &|m| {
        format!("{} ({:.1} %)", m.detected, 100.0 * m.detection_rate())
    });
    row(
        "in view: longest gap without a pose",
        &|m| match m.longest_gap {
            Some((n, seconds, first)) => format!("{n} frames ({seconds:.2} s) at {first}"),
            None => "none".into(),
        },
    );
    table.finish()
}

/// Per method, its in-view figures for `trace` whose frame `k` is in view when `in_view[k]`.
pub(super) fn summaries(trace: &Trace, in_view: &[bool]) -> Vec<InViewSummary> {
    (0..trace.methods.len())
        .map(|m| summary(&trace.frames, in_view, m))
        .collect()
}

fn summary(frames: &[TraceFrame], in_view: &[bool], m: usize) -> InViewSummary {
    let seen = |k: usize| in_view.get(k).copied().unwrap_or(false);
    let posed = |k: usize| {
        frames
            .get(k)
            .and_then(|f| f.outcomes.get(m))
            .is_some_and(|o| o.pose_found)
    };
    let mut s = InViewSummary {
        frames: 0,
        detected: 0,
        longest_gap: None,
    };
    let mut k = 0;
    while k < frames.len() {
        if !seen(k) {
            k += 1;
            continue;
        }
        // One stretch: consecutive in-view frames of one sequence.
        let start = k;
        while k + 1 < frames.len()
            && seen(k + 1)
            && frames[k + 1].sequence == frames[start].sequence
        {
            k += 1;
        }
        let end = k;
        k += 1;
        s.frames += end - start + 1;
        s.detected += (start..=end).filter(|&i| posed(i)).count();
        let mut i = start;
        while i <= end {
            if posed(i) {
                i += 1;
                continue;
            }
            let run_start = i;
            while i <= end && !posed(i) {
                i += 1;
            }
            let run_end = i - 1;
            let before = if run_start > start {
                run_start - 1
            } else {
                run_start
            };
            let after = if run_end < end { run_end + 1 } else { run_end };
            let seconds = frames[after].t_s() - frames[before].t_s();
            let run = run_end - run_start + 1;
            if s.longest_gap.is_none_or(|(n, _, _)| run > n) {
                s.longest_gap = Some((run, seconds, frames[run_start].index));
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use touchdown_eval::MethodOutcome;

    fn trace(posed: &[bool], sequences: &[usize]) -> Trace {
        let frames = posed
            .iter()
            .zip(sequences)
            .enumerate()
            .map(|(k, (&p, &sequence))| TraceFrame {
                index: k,
                t_us: k as u64 * 100_000,
                sequence,
                truth: None,
                label: None,
                outcomes: vec![MethodOutcome {
                    pose_found: p,
                    raw: None,
                    estimate: None,
                }],
            })
            .collect();
        Trace {
            methods: vec!["ours".into()],
            frames,
        }
    }

    #[test]
    fn frames_out_of_view_are_neither_misses_nor_gaps() {
        // Frames 0-3 in view (a miss at 2), 4-7 out (no pose), 8-11 in view (misses 8, 9).
        let posed = [
            true, true, false, true, false, false, false, false, false, false, true, true,
        ];
        let in_view = [
            true, true, true, true, false, false, false, false, true, true, true, true,
        ];
        let s = summaries(&trace(&posed, &[0; 12]), &in_view)[0];
        assert_eq!((s.frames, s.detected), (8, 5));
        // The longest: frames 8-9 at the stretch's start, from frame 8 to frame 10.
        let (n, seconds, first) = s.longest_gap.unwrap();
        assert_eq!((n, first), (2, 8));
        assert!((seconds - 0.2).abs() < 1e-9, "{seconds}");
        assert!((s.detection_rate() - 5.0 / 8.0).abs() < 1e-12);
    }

    #[test]
    fn a_new_sequence_ends_a_stretch() {
        // All in view; a miss at 1-2 in sequence 0 and at 3 in sequence 1: the run does not
        // join across the sequences.
        let posed = [true, false, false, false, true];
        let s = summaries(&trace(&posed, &[0, 0, 0, 1, 1]), &[true; 5])[0];
        let (n, seconds, first) = s.longest_gap.unwrap();
        assert_eq!((n, first), (2, 1));
        // From frame 0 to frame 2 (the stretch's last).
        assert!((seconds - 0.2).abs() < 1e-9, "{seconds}");
        // Nothing in view: no frames, no gap, rate 0.
        let none = summaries(&trace(&posed, &[0; 5]), &[false; 5])[0];
        assert_eq!((none.frames, none.longest_gap), (0, None));
        assert_eq!(none.detection_rate(), 0.0);
    }
}
