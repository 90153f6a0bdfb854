//! What the time axis names under its tick labels: the set points (runs of frames with one
//! label, each named at its middle in staggered rows) or, without labels, the true altitude
//! at a few round times.

use super::*;

/// What the time axis names under its tick labels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum MarkKind {
    /// Each set point (a run of frames with one label), at its middle.
    SetPoints,
    /// The true altitude at a few round times.
    Altitudes,
}

/// A text on the time axis at time `t` (seconds from the first frame).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Mark {
    pub(super) t: f64,
    pub(super) text: String,
}

/// A run of consecutive frames of one sequence with the same label: first and last frame's
/// time (seconds from `t0`) and the label.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct SetPointRun {
    pub(super) start: f64,
    pub(super) end: f64,
    pub(super) label: String,
}

/// The set points of `frames` in time order. An unlabelled frame or a new sequence ends a
/// run, so a label that comes back later is a run (and a name on the axis) of its own.
pub(super) fn set_point_runs(frames: &[TraceFrame], t0: f64) -> Vec<SetPointRun> {
    let mut runs: Vec<SetPointRun> = Vec::new();
    let mut previous: Option<(usize, &str)> = None;
    for f in frames {
        let t = f.t_s() - t0;
        let Some(label) = f.label.as_deref() else {
            previous = None;
            continue;
        };
        match runs.last_mut() {
            Some(run) if previous == Some((f.sequence, label)) => run.end = t,
            _ => runs.push(SetPointRun {
                start: t,
                end: t,
                label: label.to_string(),
            }),
        }
        previous = Some((f.sequence, label));
    }
    runs
}

/// A round step (1, 2 or 5 times a power of ten) that cuts `span` into at most `count`
/// pieces.
pub(super) fn round_step(span: f64, count: usize) -> f64 {
    let raw = span / count.max(1) as f64;
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let power = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * power)
        .find(|&s| s >= raw)
        .unwrap_or(10.0 * power)
}

/// The true altitude at round times: at each multiple of a round step, the altitude of the
/// nearest frame with a truth if one lies within half a step (none in a gap between
/// sequences).
pub(super) fn altitude_marks(frames: &[TraceFrame], t0: f64, span: f64) -> Vec<Mark> {
    let step = round_step(span, ALTITUDE_MARKS);
    let with_truth: Vec<(f64, f64)> = frames
        .iter()
        .filter_map(|f| f.truth.map(|t| (f.t_s() - t0, t.z)))
        .filter(|(_, z)| z.is_finite())
        .collect();
    let mut marks = Vec::new();
    let mut k = 0u32;
    loop {
        let t = f64::from(k) * step;
        if t > span + 1e-9 || marks.len() > ALTITUDE_MARKS {
            break;
        }
        k += 1;
        let nearest = with_truth
            .iter()
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()));
        if let Some(&(_, z)) = nearest.filter(|(tf, _)| (tf - t).abs() <= 0.5 * step) {
            let decimals = if z.abs() >= 10.0 { 0 } else { 1 };
            marks.push(Mark {
                t,
                text: format!("{z:.decimals$} m"),
            });
        }
    }
    marks
}

/// Where each text goes on the time axis: boxes of `widths` centred on `centres` (clamped
/// inside `bounds`), each in the first of `rows` rows where it keeps [`MARK_GAP`] from the
/// previous text of that row; `None` when no row has room. Returns `(row, left)`.
pub(super) fn place_marks(
    centres: &[i32],
    widths: &[i32],
    bounds: (i32, i32),
    rows: usize,
) -> Vec<Option<(usize, i32)>> {
    let mut row_end = vec![i32::MIN / 2; rows];
    centres
        .iter()
        .zip(widths)
        .map(|(&c, &w)| {
            let left = (c - w / 2).min(bounds.1 - w).max(bounds.0);
            let row = row_end.iter().position(|&end| left >= end + MARK_GAP)?;
            row_end[row] = left + w;
            Some((row, left))
        })
        .collect()
}
