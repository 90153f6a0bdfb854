//! The summary `touchdown companion` prints when a run ends (normally, on a signal, or when
//! the link is lost): one line per fact, `what: figures`, in words a user can act on.
//!
//! The receive counters keep apart what the link did and what the dialect cannot read: a
//! frame whose message id is outside MAVLink's common set (ArduPilot's and PX4's own
//! messages, forwarded by a router) is normal traffic, not a corrupt link, and is counted
//! once as "not in the dialect"; only a corrupted frame is counted as a bad CRC: a checksum
//! that fails, or a frame of an unknown id whose declared length does not end where the next
//! frame starts (`touchdown_core::companion::FrameParser`), once however many start markers
//! are inside it.

use std::io::{self, Write};
use std::time::Duration;

use touchdown_core::companion::{CompanionStats, TimeSource};

use super::interrupt::StopSignal;

/// Why the run ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Stop {
    /// The recording was replayed and the linger time is over.
    Finished,
    /// A signal, after this long.
    Signal(StopSignal, Duration),
    /// The link failed or its peer closed it: the one-line reason, after this long.
    LinkLost(String, Duration),
}

/// What the loop counted besides the companion's own counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RunCounts {
    /// Frames of the recording processed.
    pub frames: usize,
    /// Frames in the recording.
    pub recording_frames: usize,
    /// Frames for which the companion queued a LANDING_TARGET.
    pub targets_queued: usize,
    /// Frames the link refused to send.
    pub send_errors: usize,
    /// Frames dropped because no peer was connected (a server between two clients).
    pub not_sent_no_peer: usize,
}

/// Writes the summary.
pub fn write(
    out: &mut dyn Write,
    counts: &RunCounts,
    stats: &CompanionStats,
    stop: &Stop,
) -> io::Result<()> {
    for line in lines(counts, stats, stop) {
        writeln!(out, "{line}")?;
    }
    Ok(())
}

/// The summary's lines.
pub fn lines(counts: &RunCounts, s: &CompanionStats, stop: &Stop) -> Vec<String> {
    let mut lines = Vec::new();
    match stop {
        Stop::Finished => {}
        Stop::Signal(signal, after) => lines.push(format!(
            "stopped: by {} after {:.1} s",
            signal.name(),
            after.as_secs_f64()
        )),
        Stop::LinkLost(reason, after) => lines.push(format!(
            "stopped: {reason} after {:.1} s",
            after.as_secs_f64()
        )),
    }
    lines.push(format!(
        "frames: {} of {} replayed",
        counts.frames, counts.recording_frames
    ));
    lines.push(format!(
        "LANDING_TARGET: {} queued, {} sent",
        counts.targets_queued, s.landing_targets
    ));
    if let Some(mean) = s.target_latency.mean_us() {
        lines.push(format!(
            "exposure to send: mean {:.1} ms, max {:.1} ms",
            f64::from(mean) / 1000.0,
            f64::from(s.target_latency.max_us) / 1000.0
        ));
    }
    let mut sent = format!(
        "sent: {} MAVLink frames ({} bytes), {} send errors",
        s.tx_frames, s.tx_bytes, counts.send_errors
    );
    if counts.not_sent_no_peer > 0 {
        sent.push_str(&format!(
            ", {} not sent (no peer connected)",
            counts.not_sent_no_peer
        ));
    }
    lines.push(sent);
    lines.push(format!(
        "received: {} MAVLink frames ({} bytes), {} of them not decodable",
        s.link.frames, s.link.bytes, s.decode_errors
    ));
    lines.push(format!(
        "not in the dialect: {} (message ids outside MAVLink common, skipped)",
        s.link.unknown
    ));
    lines.push(format!(
        "bad CRC: {} (corrupted frames, or garbage that looked like a frame)",
        s.link.bad_crc
    ));
    lines.push(format!(
        "garbage: {} bytes outside any frame",
        s.link.garbage_bytes
    ));
    lines.push(match s.autopilot {
        Some((system, component)) => format!("autopilot: system {system}, component {component}"),
        None => "autopilot: none heard".to_string(),
    });
    lines.push(clock_line(s.clock_offset_us, s.time_source));
    lines
}

/// The clock offset: autopilot minus our clock, and where it is from.
fn clock_line(offset_us: Option<i64>, source: Option<TimeSource>) -> String {
    match (offset_us, source) {
        (Some(offset), Some(TimeSource::Timesync)) => {
            format!("autopilot clock: {offset:+} us from ours (TIMESYNC)")
        }
        (Some(offset), Some(TimeSource::SystemTime)) => {
            format!("autopilot clock: {offset:+} us from ours (SYSTEM_TIME, coarse)")
        }
        _ => "autopilot clock: unknown (no TIMESYNC or SYSTEM_TIME answer)".to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Nothing a user reads is Rust's debug formatting, and unknown ids are not bad CRCs.
    #[test]
    fn lines_are_plain_and_keep_unknown_apart_from_bad_crc() {
        let mut stats = CompanionStats::default();
        stats.link.unknown = 79;
        stats.link.bad_crc = 1;
        let counts = RunCounts::default();
        for stop in [
            Stop::Finished,
            Stop::Signal(StopSignal::Interrupt, Duration::from_millis(3200)),
            Stop::LinkLost("the peer closed".into(), Duration::ZERO),
        ] {
            let lines = lines(&counts, &stats, &stop);
            for line in &lines {
                assert!(
                    !line.contains("Some(") && !line.contains("None") && !line.contains('\n'),
                    "{line}"
                );
            }
            assert!(lines
                .iter()
                .any(|l| l.starts_with("not in the dialect: 79 ")));
            assert!(lines.iter().any(|l| l.starts_with("bad CRC: 1 ")));
            assert!(lines.iter().any(|l| l == "autopilot: none heard"));
            assert!(lines
                .iter()
                .any(|l| l == "autopilot clock: unknown (no TIMESYNC or SYSTEM_TIME answer)"));
        }
        let signalled = lines(
            &counts,
            &stats,
            &Stop::Signal(StopSignal::Terminate, Duration::from_millis(3200)),
        );
        assert_eq!(signalled[0], "stopped: by SIGTERM after 3.2 s");
    }
}
