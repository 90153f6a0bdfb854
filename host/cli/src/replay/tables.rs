//! The text tables `touchdown replay` prints: per set point, on all axes, vision only,
//! the summary (rates, RMS, gaps, lag) and the error at altitude checkpoints.

use std::fmt::Write as _;

use super::{ALTITUDE_CHECKPOINTS_M, ALTITUDE_TOLERANCE};
use touchdown_eval::flight::{ErrorKind, ErrorStats, FlightTrace};
use touchdown_eval::trace::{MethodSummary, Trace};
use touchdown_eval::{published, Report, SetPoint};

/// `v` metres as centimetres in `width` columns, `-` when absent or not finite.
pub(super) fn cm(v: Option<f64>, width: usize, decimals: usize) -> String {
    match v.filter(|v| v.is_finite()) {
        Some(v) => format!("{:>width$.decimals$}", 100.0 * v),
        None => format!("{:>width$}", "-"),
    }
}

pub(super) fn percent(fraction: f64, width: usize) -> String {
    format!("{:>w$}%", format!("{:.0}", 100.0 * fraction), w = width - 1)
}

/// The row heading: axis and reference (cm) for a parsed label, else the label.
pub(super) fn row_name(sp: &SetPoint) -> String {
    if sp.reference_m.is_finite() {
        format!("{} {:>5.0}", sp.axis.name(), 100.0 * sp.reference_m)
    } else {
        sp.label.chars().take(9).collect()
    }
}

/// Writes `text` centred in `width` columns.
pub(super) fn centred(text: &str, width: usize) -> String {
    let text: String = text.chars().take(width).collect();
    format!("{text:^width$}")
}

/// The main table: per set point, on its axis.
pub(super) fn set_point_table(report: &Report) -> String {
    const BLOCK: usize = 44;
    let mut s = String::from(
        "\nSet points: mean over each set point's frames, on the row's axis, cm \
         (error = truth - estimate;\n|err| = mean |error|; det = frames with a pose, est = \
         frames with a filtered estimate)\n\n",
    );
    let _ = write!(s, "{:<7} | {:^16} ", "", "paper, published");
    for name in &report.methods {
        let _ = write!(s, "|{} ", centred(name, BLOCK));
    }
    s.push('\n');
    let _ = write!(s, "{:<7} | {:>7} {:>8} ", "ref", "est", "err");
    for _ in &report.methods {
        let _ = write!(
            s,
            "| {:>7} {:>7} {:>6} {:>6} {:>5} {:>5} ",
            "est", "err", "|err|", "RMS", "det", "est"
        );
    }
    s.push('\n');
    for results in &report.rows {
        let Some(first) = results.first() else {
            continue;
        };
        let sp = &first.set_point;
        let _ = write!(s, "{:<7} | ", row_name(sp));
        match published(sp.axis, sp.reference_m) {
            Some(p) => {
                let _ = write!(s, "{:>7.0} {:>8.1} ", p.estimate_cm, p.error_cm);
            }
            None => {
                let _ = write!(s, "{:>7} {:>8} ", "-", "-");
            }
        }
        for r in results {
            let a = r.on_axis();
            let _ = write!(
                s,
                "| {} {} {} {} {} {} ",
                cm(a.mean_estimate(), 7, 1),
                cm(a.mean_error(), 7, 2),
                cm(a.mean_abs_error(), 6, 2),
                cm(a.rms_error(), 6, 2),
                percent(r.detection_rate(), 5),
                percent(r.estimate_rate(), 5)
            );
        }
        s.push('\n');
    }
    s
}

/// Mean error on every axis per set point, and the raw pose's mean |error| on the row's axis.
pub(super) fn all_axes_table(report: &Report) -> String {
    const BLOCK: usize = 32;
    let mut s = String::from(
        "\nMean error on every axis, cm (truth - estimate), and the raw pose's mean |error| on \
         the row's axis\n(before filtering)\n\n",
    );
    let _ = write!(s, "{:<7} ", "");
    for name in &report.methods {
        let _ = write!(s, "|{} ", centred(name, BLOCK));
    }
    s.push('\n');
    let _ = write!(s, "{:<7} ", "ref");
    for _ in &report.methods {
        let _ = write!(s, "| {:>7} {:>7} {:>7} {:>7} ", "x", "y", "z", "raw");
    }
    s.push('\n');
    for results in &report.rows {
        let Some(first) = results.first() else {
            continue;
        };
        let _ = write!(s, "{:<7} ", row_name(&first.set_point));
        for r in results {
            let _ = write!(
                s,
                "| {} {} {} {} ",
                cm(r.filtered[0].mean_error(), 7, 2),
                cm(r.filtered[1].mean_error(), 7, 2),
                cm(r.filtered[2].mean_error(), 7, 2),
                cm(r.raw_on_axis().mean_abs_error(), 7, 2)
            );
        }
        s.push('\n');
    }
    s
}

/// Without truth: per set point, the mean estimate and the rates.
pub(super) fn vision_only_table(report: &Report) -> String {
    const BLOCK: usize = 38;
    let mut s = String::from(
        "\nSet points (no truth): mean estimate, cm; det = frames with a pose, est = frames \
         with a filtered estimate\n\n",
    );
    let _ = write!(s, "{:<9} ", "");
    for name in &report.methods {
        let _ = write!(s, "|{} ", centred(name, BLOCK));
    }
    s.push('\n');
    let _ = write!(s, "{:<9} ", "set point");
    for _ in &report.methods {
        let _ = write!(
            s,
            "| {:>7} {:>7} {:>7} {:>5} {:>5} ",
            "x", "y", "z", "det", "est"
        );
    }
    s.push('\n');
    for results in &report.rows {
        let Some(first) = results.first() else {
            continue;
        };
        let label: String = first.set_point.label.chars().take(9).collect();
        let _ = write!(s, "{label:<9} ");
        for r in results {
            let e = |k: usize| cm(r.filtered[k].mean_estimate(), 7, 1);
            let _ = write!(
                s,
                "| {} {} {} {} {} ",
                e(0),
                e(1),
                e(2),
                percent(r.detection_rate(), 5),
                percent(r.estimate_rate(), 5)
            );
        }
        s.push('\n');
    }
    s
}

/// A table with one column per method (the summary tables' layout): a heading column
/// [`MethodTable::LEFT`] characters wide, then a cell [`MethodTable::COLUMN`] wide per method.
pub(super) struct MethodTable {
    text: String,
}

impl MethodTable {
    const LEFT: usize = 38;
    const COLUMN: usize = 30;

    /// The table under `title` (its blank lines included), with a header of `methods`.
    pub(super) fn new(title: &str, methods: &[String]) -> Self {
        let mut text = String::from(title);
        let _ = write!(text, "{:<w$}", "", w = Self::LEFT);
        for name in methods {
            let _ = write!(text, "| {:<w$}", name, w = Self::COLUMN - 2);
        }
        text.push('\n');
        MethodTable { text }
    }

    /// A row: its heading and one cell per method, in the header's order.
    pub(super) fn row(&mut self, name: &str, cells: impl IntoIterator<Item = String>) {
        let _ = write!(self.text, "{name:<w$}", w = Self::LEFT);
        for cell in cells {
            let _ = write!(self.text, "| {:<w$}", cell, w = Self::COLUMN - 2);
        }
        self.text.push('\n');
    }

    /// The table's text.
    pub(super) fn finish(self) -> String {
        self.text
    }
}

/// Over all frames, per method.
pub(super) fn summary_table(trace: &Trace, summaries: &[MethodSummary], has_truth: bool) -> String {
    let period = trace.frame_period_s();
    let title = format!(
        "\nSummary over all {} frames{}\n\n",
        trace.frames.len(),
        period.map_or(String::new(), |p| format!(" ({:.1} Hz)", 1.0 / p))
    );
    let mut table = MethodTable::new(&title, &trace.methods);
    let mut row = |name: &str, cell: &dyn Fn(&MethodSummary) -> String| {
        table.row(name, summaries.iter().map(cell))
    };
    row("frames with a pose (detection)", &|m| {
        format!("{} ({:.1} %)", m.detected, 100.0 * m.detection_rate())
    });
    row("frames with an estimate", &|m| {
        format!("{} ({:.1} %)", m.estimated, 100.0 * m.estimate_rate())
    });
    if has_truth {
        row("RMS error x / y / z, cm (filtered)", &|m| xyz(m.rms));
        row("RMS error x / y / z, cm (raw pose)", &|m| xyz(m.raw_rms));
    }
    row(
        "longest gap without an estimate",
        &|m| match m.longest_gap {
            Some(g) => format!("{} frames ({:.2} s)", g.frames, g.seconds),
            None if m.estimated > 0 => "none".into(),
            None => "no estimate at all".into(),
        },
    );
    row("slowest first estimate", &|m| match m.slowest_acquisition {
        Some(a) => {
            let at = a
                .altitude_m
                .map_or(String::new(), |z| format!(", at {z:.1} m"));
            format!("after {} frames{at}", a.frames)
        }
        None => "-".into(),
    });
    if summaries.iter().any(|m| m.sequences_without_estimate > 0) {
        row("sequences without any estimate", &|m| {
            m.sequences_without_estimate.to_string()
        });
    }
    if has_truth {
        row(
            "lag, frames (estimate behind truth)",
            &|m| match m.lag_frames {
                Some(lag) => format!("{lag:.2}"),
                None => "- (no motion to align)".into(),
            },
        );
    }
    table.finish()
}

/// Mean |error| near each altitude checkpoint (runs without set points).
pub(super) fn altitude_table(trace: &Trace) -> String {
    const BLOCK: usize = 40;
    let mut s = format!(
        "\nError at altitude (frames whose true altitude is within {:.0} % of the checkpoint): \
         mean |error| per axis and\nof the error vector |e|, cm; det = frames with a pose, \
         est = frames with a filtered estimate\n\n",
        100.0 * ALTITUDE_TOLERANCE
    );
    let _ = write!(s, "{:<16} ", "");
    for name in &trace.methods {
        let _ = write!(s, "|{} ", centred(name, BLOCK));
    }
    s.push('\n');
    let _ = write!(s, "{:>8} {:>7} ", "altitude", "frames");
    for _ in &trace.methods {
        let _ = write!(
            s,
            "| {:>4} {:>4} {:>6} {:>6} {:>6} {:>6} ",
            "det", "est", "|x|", "|y|", "|z|", "|e|"
        );
    }
    s.push('\n');
    let mut rows = 0;
    for altitude in ALTITUDE_CHECKPOINTS_M {
        let stats: Vec<_> = (0..trace.methods.len())
            .map(|m| trace.at_altitude(m, altitude, ALTITUDE_TOLERANCE))
            .collect();
        let frames = stats.first().map_or(0, |a| a.frames);
        if frames == 0 {
            continue;
        }
        rows += 1;
        let _ = write!(s, "{:>6} m {:>7} ", format!("{altitude}"), frames);
        for a in &stats {
            let n = a.frames.max(1) as f64;
            let axis = |k: usize| cm(a.mean_abs.map(|v| v[k]), 6, 2);
            let _ = write!(
                s,
                "| {:>4} {:>4} {} {} {} {} ",
                format!("{:.0}%", 100.0 * a.detected as f64 / n),
                format!("{:.0}%", 100.0 * a.estimated as f64 / n),
                axis(0),
                axis(1),
                axis(2),
                cm(a.mean_norm, 6, 2)
            );
        }
        s.push('\n');
    }
    // A flight that never comes near a checkpoint (a hover at 12 m) gets no table.
    if rows == 0 {
        s.clear();
    }
    s
}

/// In flight, over all frames: the three errors per method (RMS per axis, mean horizontal
/// and vertical |error|) and the targets' latency.
pub(super) fn flight_summary_table(flight: &FlightTrace, trace: &Trace) -> String {
    let mut table = MethodTable::new(
        "\nIn flight, over all frames: (a) what touchdown sends, in the true body axes at the \
         exposure; (b) what the\nautopilot reconstructs from it, against the truth at the time \
         it assigns it to; (c) the same from an ideal sensor\n\n",
        &trace.methods,
    );
    let methods = trace.methods.len();
    let mut row =
        |name: &str, cell: &dyn Fn(usize) -> String| table.row(name, (0..methods).map(cell));
    for kind in ErrorKind::ALL {
        let name = match kind {
            ErrorKind::Sent => "(a) sent: RMS x / y / z, cm",
            ErrorKind::Reconstructed => "(b) autopilot: RMS x / y / z, cm",
            ErrorKind::Ideal => "(c) ideal sensor: RMS x / y / z, cm",
        };
        row(name, &|m| xyz(flight.summary(m, kind).rms));
    }
    let three = |f: &dyn Fn(&ErrorStats) -> Option<f64>, m: usize| {
        let v: Vec<String> = ErrorKind::ALL
            .iter()
            .map(|&k| match f(&flight.summary(m, k)) {
                Some(v) => format!("{:.2}", 100.0 * v),
                None => "-".into(),
            })
            .collect();
        v.join(" / ")
    };
    row("(a) / (b) / (c) horizontal mean |e|, cm", &|m| {
        three(&|e| e.mean_horizontal, m)
    });
    row("(a) / (b) / (c) mean |z|, cm", &|m| {
        three(&|e| e.mean_abs.map(|v| v[2]), m)
    });
    row("targets received by the autopilot", &|m| {
        flight
            .summary(m, ErrorKind::Reconstructed)
            .frames
            .to_string()
    });
    row(
        "exposure to receipt, ms: mean / max",
        &|m| match flight.latency_ms(m) {
            Some((mean, max)) => format!("{mean:.1} / {max:.1}"),
            None => "-".into(),
        },
    );
    // Only where a board took the pad as moving (a moving pad, or a wrong decision).
    if (0..methods).any(|m| flight.pad_moving_from(m).is_some()) {
        row("pad taken as moving (TD_PAD_MOTION)", &|m| match (
            flight.pad_moving_from(m),
            trace.frames.first(),
        ) {
            (Some(k), Some(first)) => {
                let t = trace
                    .frames
                    .get(k)
                    .map_or(0.0, |f| f.t_us.saturating_sub(first.t_us) as f64 * 1e-6);
                format!("from frame {k} ({t:.1} s)")
            }
            _ => "no".into(),
        });
    }
    table.finish()
}

/// In flight: the three errors near each altitude checkpoint (runs without set points).
pub(super) fn flight_altitude_table(flight: &FlightTrace, trace: &Trace) -> String {
    const BLOCK: usize = 50;
    let mut s = format!(
        "\nError at altitude in flight (each error's frames whose true altitude is within {:.0} % \
         of the checkpoint): horizontal\nmean |e| (mean of sqrt(ex^2 + ey^2)) of (a) sent, \
         (b) autopilot, (c) ideal sensor, (b) - (c), and mean |z| of each, cm\n\n",
        100.0 * ALTITUDE_TOLERANCE
    );
    let _ = write!(s, "{:<16} ", "");
    for name in &trace.methods {
        let _ = write!(s, "|{} ", centred(name, BLOCK));
    }
    s.push('\n');
    let _ = write!(s, "{:>8} {:>7} ", "altitude", "frames");
    for _ in &trace.methods {
        let _ = write!(
            s,
            "| {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} ",
            "a h", "b h", "c h", "b-c", "a z", "b z", "c z"
        );
    }
    s.push('\n');
    let mut rows = 0;
    for altitude in ALTITUDE_CHECKPOINTS_M {
        let frames = trace.at_altitude(0, altitude, ALTITUDE_TOLERANCE).frames;
        if frames == 0 {
            continue;
        }
        rows += 1;
        let _ = write!(s, "{:>6} m {:>7} ", format!("{altitude}"), frames);
        for m in 0..trace.methods.len() {
            let at = |k: ErrorKind| flight.at_altitude(m, k, altitude, ALTITUDE_TOLERANCE);
            let (a, b, c) = (
                at(ErrorKind::Sent),
                at(ErrorKind::Reconstructed),
                at(ErrorKind::Ideal),
            );
            let difference = b.mean_horizontal.zip(c.mean_horizontal).map(|(b, c)| b - c);
            let z = |e: &ErrorStats| cm(e.mean_abs.map(|v| v[2]), 6, 2);
            let _ = write!(
                s,
                "| {} {} {} {} {} {} {} ",
                cm(a.mean_horizontal, 6, 2),
                cm(b.mean_horizontal, 6, 2),
                cm(c.mean_horizontal, 6, 2),
                cm(difference, 6, 2),
                z(&a),
                z(&b),
                z(&c)
            );
        }
        s.push('\n');
    }
    if rows == 0 {
        s.clear();
    }
    s
}

/// x / y / z in centimetres with two decimals (metres in), `-` when unknown: one summary cell.
fn xyz(v: Option<[f64; 3]>) -> String {
    match v {
        Some(v) => format!(
            "{:.2} / {:.2} / {:.2}",
            100.0 * v[0],
            100.0 * v[1],
            100.0 * v[2]
        ),
        None => "-".into(),
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;
    use touchdown_eval::trace::TraceFrame;

    use super::*;

    /// A 15 Hz descent from 12 m to 0.4 m at 0.5 m/s; method 0 estimates 2 cm east of the
    /// truth in every frame, method 1 never finds the pad.
    fn descent_trace() -> Trace {
        use touchdown_eval::MethodOutcome;
        let mut trace = Trace::new(vec!["good".into(), "blind".into()]);
        for k in 0..349 {
            let truth = Vector3::new(0.0, 0.0, 12.0 - 0.5 * k as f64 / 15.0);
            let seen = Some(truth + Vector3::new(0.02, 0.0, 0.0));
            trace.frames.push(TraceFrame {
                index: k,
                t_us: k as u64 * 66_667,
                sequence: 0,
                truth: Some(truth),
                label: None,
                outcomes: vec![
                    MethodOutcome {
                        pose_found: true,
                        raw: seen,
                        estimate: seen,
                    },
                    MethodOutcome {
                        pose_found: false,
                        raw: None,
                        estimate: None,
                    },
                ],
            });
        }
        trace
    }

    #[test]
    fn altitude_table_has_the_checkpoints_the_flight_passes() {
        let table = altitude_table(&descent_trace());
        let row = |altitude: &str| {
            table
                .lines()
                .find(|l| l.trim_start().starts_with(altitude))
                .unwrap_or_else(|| panic!("no {altitude} row:\n{table}"))
                .to_string()
        };
        // 2 cm in x, nothing in y and z: |x| 2.00, |e| 2.00; the blind method has dashes.
        let ten = row("10 m");
        assert!(
            ten.contains("100% 100%   2.00   0.00   0.00   2.00"),
            "{ten}"
        );
        assert!(
            ten.trim_end()
                .ends_with("0%   0%      -      -      -      -"),
            "{ten}"
        );
        assert!(row("0.5 m").contains("2.00"));
        assert!(
            !table.contains("  40 m") && !table.contains("  20 m"),
            "{table}"
        );
    }

    #[test]
    fn summary_reports_gaps_rates_and_lag() {
        let trace = descent_trace();
        let summaries: Vec<MethodSummary> = (0..2).map(|m| trace.summary(m)).collect();
        let table = summary_table(&trace, &summaries, true);
        assert!(table.contains("(15.0 Hz)"), "{table}");
        let line = |start: &str| {
            table
                .lines()
                .find(|l| l.starts_with(start))
                .unwrap_or_else(|| panic!("no `{start}`:\n{table}"))
                .to_string()
        };
        assert!(line("frames with a pose").contains("349 (100.0 %)"));
        assert!(line("longest gap").contains("none"));
        assert!(line("longest gap").contains("no estimate at all"));
        assert!(line("RMS error x / y / z, cm (filtered)").contains("2.00 / 0.00 / 0.00"));
        // The estimate follows the truth without delay.
        assert!(line("lag").contains("| 0.00"), "{}", line("lag"));
    }
}
