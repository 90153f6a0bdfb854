//! How right the board's VISION_POSITION_ESTIMATE is in `touchdown sitl`: each one the
//! companion sends is set against the SITL's truth at its frame's time.
//!
//! An autopilot that navigates on the board's position (TD_VPE_EN bit 0) fuses it as well as
//! its covariance says it may, so both need a figure from a real autopilot's flight: how far
//! the position is from the truth, and how often that error lies within two of the reported
//! horizontal sigmas (the rule of core's `vision_estimate_error_is_within_its_covariance`
//! test: the error within `2 * sqrt(max(var x, var y))`).
//!
//! - **What is checked is what went out**: the companion's outgoing bytes are parsed again,
//!   so the figure covers the message as the autopilot reads it (its float fields, its
//!   covariance's layout), not an estimate before it is turned into one.
//! - **The time is the frame's**: `usec` is the frame's exposure, in our clock (PX4's
//!   profile, or before the companion knows the autopilot's clock) or in the autopilot's
//!   (ArduPilot's, through TIMESYNC). Both are mapped back to the exposure of one of the
//!   frames handed to the companion lately, so the truth compared is the very one the frame
//!   was rendered from, and no clock error enters the figure.
//! - **Holding and airborne apart**: a hold at a point is where a position source earns its
//!   keep (the autopilot stays put on it), so it has its own figure; airborne is every
//!   estimate above the run's airborne height (`AIRBORNE_HEIGHT_M`), the climb and the
//!   descent too.
//! - **Bad input is counted, never trusted**: an estimate with a non-finite position has an
//!   infinite error, one with a non-finite or negative variance no sigma; neither is inside.

use std::collections::VecDeque;

use nalgebra::Vector3;
use touchdown_core::companion::mavlink::dialects::common::{
    MavMessage, VISION_POSITION_ESTIMATE_DATA,
};
use touchdown_core::companion::{FrameParser, TimeSync};
use touchdown_eval::flight::{TruthSource, NED_FROM_PAD};

/// Frames remembered for the mapping of `usec` back to an exposure: more than a message can
/// wait in the companion's queue before it is sent.
const RECENT_FRAMES: usize = 64;

/// A `usec` in the autopilot's clock, mapped back to ours, matches a frame this close, µs:
/// shorter than any frame period the board runs, longer than the step a new TIMESYNC sample
/// makes in the mapping between a message's queueing and its sending.
const MATCH_TOLERANCE_US: u64 = 5_000;

/// A frame handed to the companion.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameNote {
    /// Its exposure, the run's clock, µs (the pipeline's time of the frame).
    pub exposure_us: u64,
    /// Whether the flight was holding a position when it was processed (`None`: unknown,
    /// only watching).
    pub holding: Option<bool>,
}

/// One estimate against the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Horizontal distance from the true position, metres (infinite: no finite position).
    pub error_m: f64,
    /// The larger of the north and east one sigmas, metres (NaN: no valid variance).
    pub sigma_m: f64,
}

impl Sample {
    /// `vpe` against the vehicle origin's true position `truth_ned` (pad-centred NED, metres).
    pub fn of(vpe: &VISION_POSITION_ESTIMATE_DATA, truth_ned: &Vector3<f64>) -> Sample {
        let error = (f64::from(vpe.x) - truth_ned.x).hypot(f64::from(vpe.y) - truth_ned.y);
        let variance = |k: usize| vpe.covariance.get(k).map_or(f64::NAN, |v| f64::from(*v));
        let (north, east) = (variance(0), variance(6));
        // f64::max would pass over a NaN and take the other variance.
        let sigma = if north.is_nan() || east.is_nan() {
            f64::NAN
        } else {
            north.max(east).sqrt()
        };
        Sample {
            error_m: if error.is_finite() {
                error
            } else {
                f64::INFINITY
            },
            sigma_m: sigma,
        }
    }

    /// Within two sigmas, the rule of core's covariance test; false without a finite error
    /// or a valid sigma.
    pub fn within_2sigma(&self) -> bool {
        self.error_m.is_finite() && self.error_m <= 2.0 * self.sigma_m
    }
}

/// The accuracy of a set of estimates (JSON keys in docs/interfaces.md); every figure is
/// `None` without an estimate.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Accuracy {
    /// Estimates counted.
    pub messages: usize,
    /// Root mean square of the horizontal errors, metres.
    pub horizontal_rms_m: Option<f64>,
    /// The 95th percentile of the horizontal errors (nearest rank: the smallest error that
    /// at least 95 % of them do not exceed), metres.
    pub horizontal_p95_m: Option<f64>,
    /// The largest horizontal error, metres.
    pub horizontal_max_m: Option<f64>,
    /// Share of the estimates within two sigmas, percent.
    pub within_2sigma_pct: Option<f64>,
    /// Median of the horizontal one sigmas, metres.
    pub median_sigma_m: Option<f64>,
}

/// The statistics of `samples`.
pub fn accuracy(samples: &[Sample]) -> Accuracy {
    let n = samples.len();
    if n == 0 {
        return Accuracy::default();
    }
    let mut errors: Vec<f64> = samples.iter().map(|s| s.error_m).collect();
    errors.sort_by(f64::total_cmp);
    let mut sigmas: Vec<f64> = samples.iter().map(|s| s.sigma_m).collect();
    sigmas.sort_by(f64::total_cmp);
    // Nearest rank, in integers: ceil(0.95 n) - 1.
    let p95 = (95 * n).div_ceil(100).saturating_sub(1);
    let median = match (sigmas.get((n - 1) / 2), sigmas.get(n / 2)) {
        (Some(a), Some(b)) => Some(0.5 * (a + b)),
        _ => None,
    };
    let inside = samples.iter().filter(|s| s.within_2sigma()).count();
    Accuracy {
        messages: n,
        horizontal_rms_m: Some((errors.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt()),
        horizontal_p95_m: errors.get(p95).copied(),
        horizontal_max_m: errors.last().copied(),
        within_2sigma_pct: Some(100.0 * inside as f64 / n as f64),
        median_sigma_m: median,
    }
}

impl Accuracy {
    /// The text output's line for the estimates `while` (e.g. "while holding").
    pub fn line(&self, while_: &str) -> String {
        match (
            self.horizontal_rms_m,
            self.horizontal_p95_m,
            self.horizontal_max_m,
            self.within_2sigma_pct,
            self.median_sigma_m,
        ) {
            (Some(rms), Some(p95), Some(max), Some(pct), Some(sigma)) => format!(
                "board position {while_}: {} estimates, error rms {rms:.3} m, p95 {p95:.3}, \
                 max {max:.3}; {pct:.1} % within 2 sigma (median sigma {sigma:.3} m)",
                self.messages
            ),
            _ => format!("board position {while_}: no estimates"),
        }
    }
}

/// What the run's estimates came to (JSON keys in docs/interfaces.md).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct VisionAccuracy {
    /// VISION_POSITION_ESTIMATEs the companion sent.
    pub messages: usize,
    /// Of those, the ones whose time matched no recent frame or had no truth: not counted
    /// below.
    pub without_truth: usize,
    /// While the flight held a position (absent when only watching: unknown).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub holding: Option<Accuracy>,
    /// With the vehicle airborne, any phase.
    pub airborne: Accuracy,
}

/// The check, fed the frames handed to the companion and the bytes it sends.
#[derive(Debug)]
pub struct VisionCheck {
    parser: FrameParser,
    frames: VecDeque<FrameNote>,
    /// The flight's holding is known (a rehearsal, not a watch).
    holding_known: bool,
    holding: Vec<Sample>,
    airborne: Vec<Sample>,
    messages: usize,
    without_truth: usize,
}

impl VisionCheck {
    /// A check; `holding_known` when the run flies the vehicle and knows when it holds.
    pub fn new(holding_known: bool) -> Self {
        VisionCheck {
            parser: FrameParser::new(),
            frames: VecDeque::with_capacity(RECENT_FRAMES),
            holding_known,
            holding: Vec::new(),
            airborne: Vec::new(),
            messages: 0,
            without_truth: 0,
        }
    }

    /// A frame handed to the companion.
    pub fn on_frame(&mut self, note: FrameNote) {
        if self.frames.len() == RECENT_FRAMES {
            self.frames.pop_front();
        }
        self.frames.push_back(note);
    }

    /// Bytes the companion sent; `timesync` is its clock mapping, `truth` the run's truth (pad
    /// frame, run clock in seconds), `airborne_m` the height over the pad above which the
    /// vehicle counts as airborne.
    pub fn on_sent(
        &mut self,
        bytes: &[u8],
        timesync: &TimeSync,
        truth: &impl TruthSource,
        airborne_m: f64,
    ) {
        let mut sent = Vec::new();
        self.parser.push(bytes, |frame| {
            if let Ok(MavMessage::VISION_POSITION_ESTIMATE(v)) = frame.decode() {
                sent.push(v);
            }
        });
        for vpe in &sent {
            self.messages += 1;
            let at = frame_of(vpe.usec, timesync.from_autopilot(vpe.usec), &self.frames)
                .and_then(|note| Some((note, truth.at(note.exposure_us as f64 * 1e-6)?)));
            let Some((note, state)) = at else {
                self.without_truth += 1;
                continue;
            };
            let sample = Sample::of(vpe, &(NED_FROM_PAD * state.position));
            if state.position.z > airborne_m {
                self.airborne.push(sample);
            }
            if note.holding == Some(true) {
                self.holding.push(sample);
            }
        }
    }

    /// The figures; `None` when the companion sent no VISION_POSITION_ESTIMATE.
    pub fn report(&self) -> Option<VisionAccuracy> {
        (self.messages > 0).then(|| VisionAccuracy {
            messages: self.messages,
            without_truth: self.without_truth,
            holding: self.holding_known.then(|| accuracy(&self.holding)),
            airborne: accuracy(&self.airborne),
        })
    }
}

/// The frame among `frames` that an estimate stamped `usec` was made from: the one exposed at
/// `usec` exactly (a stamp in our clock), else the one nearest `usec` mapped from the
/// autopilot's clock to ours (`in_our_clock`) within [`MATCH_TOLERANCE_US`].
pub fn frame_of(
    usec: u64,
    in_our_clock: Option<u64>,
    frames: &VecDeque<FrameNote>,
) -> Option<FrameNote> {
    if let Some(exact) = frames.iter().find(|f| f.exposure_us == usec) {
        return Some(*exact);
    }
    let ours = in_our_clock?;
    frames
        .iter()
        .min_by_key(|f| f.exposure_us.abs_diff(ours))
        .filter(|f| f.exposure_us.abs_diff(ours) <= MATCH_TOLERANCE_US)
        .copied()
}

#[cfg(test)]
mod tests {
    use super::*;
    use touchdown_core::companion::mavlink::{MAVLinkV2MessageRaw, MavHeader};
    use touchdown_eval::flight::{TrueState, TruthTable};

    fn sample(error_m: f64, sigma_m: f64) -> Sample {
        Sample { error_m, sigma_m }
    }

    fn vpe(usec: u64, x: f32, y: f32, var_x: f32, var_y: f32) -> VISION_POSITION_ESTIMATE_DATA {
        let mut covariance = [0.0f32; 21];
        covariance[0] = var_x;
        covariance[6] = var_y;
        covariance[11] = 0.01;
        VISION_POSITION_ESTIMATE_DATA {
            usec,
            x,
            y,
            z: -10.0,
            covariance,
            ..VISION_POSITION_ESTIMATE_DATA::DEFAULT
        }
    }

    #[test]
    fn no_estimates_no_figures() {
        assert_eq!(
            accuracy(&[]),
            Accuracy {
                messages: 0,
                ..Accuracy::default()
            }
        );
        assert_eq!(
            accuracy(&[]).line("while holding"),
            "board position while holding: no estimates"
        );
    }

    #[test]
    fn statistics_of_known_errors() {
        // Errors 0.01 .. 1.00 m; sigmas 0.5 m: errors up to 1.0 m are inside (all), and with
        // sigma 0.2 m those up to 0.4 m.
        let wide: Vec<Sample> = (1..=100)
            .map(|k| sample(f64::from(k) / 100.0, 0.5))
            .collect();
        let a = accuracy(&wide);
        assert_eq!(a.messages, 100);
        assert_eq!(a.horizontal_p95_m, Some(0.95));
        assert_eq!(a.horizontal_max_m, Some(1.0));
        assert_eq!(a.within_2sigma_pct, Some(100.0));
        assert_eq!(a.median_sigma_m, Some(0.5));
        // The mean square of (k / 100)², k = 1..100: 101 * 201 / 60 000.
        let rms = a.horizontal_rms_m.unwrap();
        assert!(
            (rms - (101.0 * 201.0 / 60_000.0f64).sqrt()).abs() < 1e-12,
            "{rms}"
        );
        assert_eq!(
            a.line("while holding"),
            format!(
                "board position while holding: 100 estimates, error rms {rms:.3} m, p95 0.950, \
                 max 1.000; 100.0 % within 2 sigma (median sigma 0.500 m)"
            )
        );
        let narrow: Vec<Sample> = (1..=100)
            .map(|k| sample(f64::from(k) / 100.0, 0.2))
            .collect();
        assert_eq!(accuracy(&narrow).within_2sigma_pct, Some(40.0));
    }

    #[test]
    fn p95_is_the_nearest_rank_and_the_median_the_middle() {
        // 20 errors: ceil(19) = the 19th; 21: ceil(19.95) = the 20th; one: itself.
        let twenty: Vec<Sample> = (1..=20).map(|k| sample(f64::from(k), 1.0)).collect();
        assert_eq!(accuracy(&twenty).horizontal_p95_m, Some(19.0));
        let twenty_one: Vec<Sample> = (1..=21).map(|k| sample(f64::from(k), 1.0)).collect();
        assert_eq!(accuracy(&twenty_one).horizontal_p95_m, Some(20.0));
        let one = accuracy(&[sample(0.3, 0.1)]);
        assert_eq!(one.horizontal_p95_m, Some(0.3));
        assert_eq!(one.horizontal_rms_m, Some(0.3));
        assert_eq!(one.within_2sigma_pct, Some(0.0));
        // Sigmas 0.1, 0.4 (in any order): the median between them; odd count, the middle.
        let even = accuracy(&[sample(0.0, 0.4), sample(0.0, 0.1)]);
        assert_eq!(even.median_sigma_m, Some(0.25));
        let odd = accuracy(&[sample(0.0, 0.4), sample(0.0, 0.1), sample(0.0, 0.2)]);
        assert_eq!(odd.median_sigma_m, Some(0.2));
    }

    #[test]
    fn the_boundary_is_inside_and_bad_input_is_not() {
        assert!(sample(0.2, 0.1).within_2sigma());
        assert!(!sample(0.2001, 0.1).within_2sigma());
        assert!(!sample(0.0, f64::NAN).within_2sigma());
        assert!(!sample(f64::INFINITY, f64::INFINITY).within_2sigma());
        let truth = Vector3::new(1.0, 2.0, -10.0);
        // 3-4-5: an error of 0.5 m; sigma from the larger variance, east's.
        let s = Sample::of(&vpe(0, 1.3, 2.4, 0.01, 0.09), &truth);
        assert!((s.error_m - 0.5).abs() < 1e-6, "{s:?}");
        assert!((s.sigma_m - 0.3).abs() < 1e-6, "{s:?}");
        assert!(s.within_2sigma());
        // A NaN variance in either place, a negative one, a NaN position: never inside.
        for bad in [
            vpe(0, 1.0, 2.0, f32::NAN, 1.0),
            vpe(0, 1.0, 2.0, 1.0, f32::NAN),
            vpe(0, 1.0, 2.0, -1.0, -1.0),
            vpe(0, f32::NAN, 2.0, 1.0, 1.0),
            vpe(0, 1.0, f32::INFINITY, f32::INFINITY, 1.0),
        ] {
            let s = Sample::of(&bad, &truth);
            assert!(!s.within_2sigma(), "{s:?}");
        }
        let nan = Sample::of(&vpe(0, f32::NAN, 2.0, 1.0, 1.0), &truth);
        assert_eq!(nan.error_m, f64::INFINITY);
        let a = accuracy(&[nan, sample(0.1, 1.0)]);
        assert_eq!(a.within_2sigma_pct, Some(50.0));
        assert_eq!(a.horizontal_max_m, Some(f64::INFINITY));
    }

    #[test]
    fn a_stamp_maps_back_to_its_frame_in_either_clock() {
        let frames: VecDeque<FrameNote> = [1_000_000u64, 1_100_000, 1_200_000]
            .iter()
            .map(|&exposure_us| FrameNote {
                exposure_us,
                holding: Some(exposure_us == 1_100_000),
            })
            .collect();
        // Our clock: exactly a frame's exposure, whatever the autopilot's mapping says.
        assert_eq!(
            frame_of(1_100_000, Some(7), &frames).map(|f| f.exposure_us),
            Some(1_100_000)
        );
        // The autopilot's clock, mapped back a little off: the nearest frame.
        let note = frame_of(51_100_000, Some(1_100_900), &frames).expect("a frame");
        assert_eq!(note.exposure_us, 1_100_000);
        assert_eq!(note.holding, Some(true));
        assert_eq!(
            frame_of(51_200_000, Some(1_196_000), &frames).map(|f| f.exposure_us),
            Some(1_200_000)
        );
        // Too far from any frame, or no mapping: none.
        assert_eq!(frame_of(51_150_000, Some(1_150_000), &frames), None);
        assert_eq!(frame_of(51_100_000, None, &frames), None);
        assert_eq!(frame_of(1_100_000, None, &VecDeque::new()), None);
    }

    #[test]
    fn sent_bytes_are_checked_against_the_truth_at_their_frame() {
        // The vehicle 10 m up, 1 m east and 2 m north of the pad (pad frame x east, y north).
        let mut truth = TruthTable::new();
        for t in [0.0, 10.0] {
            truth.push(
                t,
                TrueState {
                    position: Vector3::new(1.0, 2.0, 10.0),
                    body_to_ned: nalgebra::Matrix3::identity(),
                },
            );
        }
        let mut check = VisionCheck::new(true);
        assert_eq!(check.report(), None);
        check.on_frame(FrameNote {
            exposure_us: 2_000_000,
            holding: Some(true),
        });
        check.on_frame(FrameNote {
            exposure_us: 2_100_000,
            holding: Some(false),
        });
        let mut bytes = Vec::new();
        for (sequence, message) in (0u8..).zip([
            // 0.1 m off north (NED x), sigma 0.1 m: inside; holding.
            vpe(2_000_000, 2.1, 1.0, 0.01, 0.0),
            // 0.3 m off east, sigma 0.1 m: outside; not holding.
            vpe(2_100_000, 2.0, 1.3, 0.0, 0.01),
            // No frame at this time.
            vpe(3_000_000, 2.0, 1.0, 0.01, 0.01),
        ]) {
            let mut raw = MAVLinkV2MessageRaw::new();
            raw.serialize_message(
                MavHeader {
                    system_id: 1,
                    component_id: 191,
                    sequence,
                },
                &MavMessage::VISION_POSITION_ESTIMATE(message),
            );
            bytes.extend_from_slice(raw.raw_bytes());
        }
        // Split anywhere: the parser carries a frame over.
        let (a, b) = bytes.split_at(40);
        let timesync = TimeSync::new();
        check.on_sent(a, &timesync, &truth, 2.0);
        check.on_sent(b, &timesync, &truth, 2.0);
        let report = check.report().expect("estimates sent");
        assert_eq!(report.messages, 3);
        assert_eq!(report.without_truth, 1);
        assert_eq!(report.airborne.messages, 2);
        assert_eq!(report.airborne.within_2sigma_pct, Some(50.0));
        let holding = report.holding.expect("holding known");
        assert_eq!(holding.messages, 1);
        assert!((holding.horizontal_max_m.unwrap() - 0.1).abs() < 1e-6);
        // Only watching: no holding figure.
        assert_eq!(VisionCheck::new(false).report(), None);
        let mut watch = VisionCheck::new(false);
        watch.on_frame(FrameNote {
            exposure_us: 2_000_000,
            holding: None,
        });
        watch.on_sent(&bytes, &timesync, &truth, 2.0);
        assert_eq!(watch.report().expect("sent").holding, None);
        // Below the airborne height: counted, but not airborne.
        let mut low = VisionCheck::new(true);
        low.on_frame(FrameNote {
            exposure_us: 2_000_000,
            holding: Some(true),
        });
        low.on_sent(&bytes, &timesync, &truth, 20.0);
        let report = low.report().expect("sent");
        assert_eq!(report.airborne.messages, 0);
        assert_eq!(report.holding.map(|h| h.messages), Some(1));
    }
}
