//! `touchdown replay`'s arguments (`--help` text and the clap struct) and what they set up:
//! the flight effects a scenario is rendered with, the error model of the simulated autopilot,
//! and whether the board is told the true mount. Kept apart from the run itself
//! (the parent module), which only reads the values these give.

use super::CliError;
use crate::effects::EffectArgs;
use crate::pad_motion::PadMotionArgs;
use crate::renderer::{LensArgs, RendererArg};
use clap::Args;
use std::path::PathBuf;
use touchdown_eval::flight::{AutopilotKind, ErrorModel};
use touchdown_sim::effects::FlightEffects;

/// `touchdown replay --help`.
pub const LONG_HELP: &str = "\
Replay a recording, or a simulated scenario, through the per-frame path the camera board
runs (core's FramePipeline: detector, pad fix, estimator), beside the paper's method (in our
code); print the paper's kind of tables and write figures of the estimates against the truth.

Input, one of:
  RECORDING          a recording directory (camera.toml, pad.toml, frames/NNNNNN.pgm,
                     frames.csv and optionally setpoints.csv), written by `touchdown simulate`
                     or dumped by the camera board
  --scenario NAME    render the scenario in memory (nothing is written to disk); NAME is one
                     of paper, margin, lateral, descent, landing, hover, rest, sun, shadow,
                     occlusion (see `touchdown simulate --help`); --seed picks the randomness
  --exposure WHO     who sets a scenario's exposure: board (the board's auto-exposure,
                     metering the decoded markers, closed around the rendering: each frame
                     rendered with the exposure time and gain it chose two frames before,
                     after 30 frames of settling at the first frame's pose) or scenario (the
                     scenario's own: fixed, or the simulated sensor's AEC on the frame's
                     mean); default board for sun and shadow, scenario for the others

Methods:
  paper's method     the paper's detector, its homography pose of the largest pad marker,
                     and its per-axis Kalman filter with Table 1's values (lag included)
  ours               the board's pipeline as it ships: touchdown's detector, IPPE +
                     Levenberg-Marquardt fix of the whole pad (flip choice by prediction,
                     tilt from the attitude, rolling-shutter correction), the estimator; its
                     LANDING_TARGET scored as below
  --pose-steps       adds the board's pipeline without the level fix, without the flip
                     choice, without both, without the detector's pattern fit of small
                     markers' corners on far frames (no pattern fit), without the
                     rolling-shutter correction (no shutter correction), and without the
                     second look where a tracked pad was lost (no second look), in that
                     order
A recording without truth runs vision only and prints no errors.

In flight (any input with truth): every method runs with the board's MAVLink companion (the
firmware's code) against a simulated autopilot that speaks MAVLink bytes over a serial link:
HEARTBEAT, the ATTITUDE_QUATERNION and LOCAL_POSITION_NED streams the companion asks for,
TIMESYNC, each sample its estimate (the truth plus the error model) stamped in its own
drifting clock; it decodes the LANDING_TARGETs and reconstructs the pad as the autopilot does:
  --autopilot ardupilot  (default) the body vector (BODY_FRD) turned with its own attitude
                         at receipt minus PLND_LAG (its inertial history), PLND_CAM_POS = 0;
                         with --board-params TD_PROFILE=3 the board sends LOCAL_FRD instead
                         (levelled with the board's attitude at the exposure), which it turns
                         with the yaw alone of its attitude at receipt minus PLND_LAG
                         (ArduPilot 4.7+); the header says which
  --autopilot px4        the LOCAL_NED point minus its own position at the time stamp it
                         converts with its TIMESYNC estimate
The paper's method gets the attitude the board received and goes through the same
reconstruction. Three errors are reported side by side:
  (a) what touchdown sends, turned with the true body attitude at the exposure (the set-point
      table and the summary's RMS rows are of this one)
  (b) what the autopilot reconstructs from it, against the truth at the time it assigns it to
  (c) what it would reconstruct from an ideal sensor (the exact body vector, sent at the same
      time by the same path, in the same frame): the autopilot's own share of (b)
Flight effects (--scenario only; default typical): rolling-shutter readout 30.5 ms, camera
vibration 0.03 deg RMS, mount misalignment roll 1.2 / pitch -1.6 deg, unknown to the board,
which calibrates it in flight (TD_CAM_CAL 2; --no-calibration: never). --mount-known gives
the board the true mount (TD_CAM_ROLL, TD_CAM_PITCH): on by default for --scenario paper only
(the paper's mount was known). Error model (default typical, every term a flag, 0 = off):
attitude noise 0.02 deg per sample, tilt bias 0.3 deg, heading bias 0.5 deg, sample latency
5 +- 2 ms, link 1 ms + the bytes at 921600 baud, autopilot clock 12.3 s ahead and 30 ppm fast,
board processing 20 +- 5 ms, PLND_LAG 0.02 s, PX4 position drift 0.3 m. --ideal: no flight
effects and an ideal autopilot (knows the truth exactly and at once, assigns each target to
its exposure).

Tables (centimetres; error = truth - estimate, the paper's sign):
  set points         per set point (setpoints.csv label such as z=5, x=1.2, y=2.4): the
                     reference, the paper's published estimate and error where it has the
                     row, then per method the mean estimate, mean error, mean |error| and RMS
                     on the row's axis, the detection rate (frames with a pose) and the
                     estimate rate (frames with a filtered output); then the mean error on
                     every axis
  summary            over all frames: RMS error per axis (filtered and raw pose), detection
                     and estimate rates, the longest gap without an estimate (frames and
                     seconds), the slowest acquisition, and the filter lag in frames (the
                     time shift that best aligns the estimate with the truth; not measurable
                     while hovering)
  altitudes          without set points: mean |error| per axis at 40, 20, 10, 5, 2, 1 and
                     0.5 m (frames within 10 % of that altitude); in flight instead the
                     horizontal mean |e| (mean of sqrt(ex^2 + ey^2)) of (a), (b), (c), (b) -
                     (c), and the mean |z| of each
  in flight          over all frames: RMS per axis of (a), (b), (c), their horizontal mean |e|
                     and mean |z|, and the targets' exposure-to-receipt time
Frames more than 0.5 s apart (the paper scenario records only its hovers) start a new
sequence: the filters are reset.

JSON (--json): one JSON object on stdout instead of the text, with every table's numbers
unrounded (\"setup\": input, seed, frames, camera, pad, the methods and their settings;
\"set_points\", \"summary\", \"altitudes\", \"figures\"): lengths in cm (keys ending in _cm),
altitudes in m (_m), rates as fractions (0-1); keys in docs/interfaces.md. Figures are
written only with --plots DIR.

Figures (--plots DIR, default replay-NAME in the current directory; PNG and SVG):
  position-x, -y, -z  truth, each method's filtered estimate (line) and raw pose (dots)
  error-x, -y, -z     truth - estimate over time, filtered (line) and raw (dots), cm

Exit status: 0 on success; 2 with one line on stderr for a bad option or an unreadable or
corrupt recording (the line names the file, and the line of a CSV file).";

/// Arguments of `touchdown replay`.
#[derive(Debug, Clone, Args)]
pub struct ReplayArgs {
    /// Recording directory to replay
    #[arg(value_name = "RECORDING")]
    pub recording: Option<PathBuf>,

    /// Render this scenario in memory instead (paper, margin, lateral, descent, landing, hover,
    /// rest, sun, shadow, occlusion)
    #[arg(long, value_name = "NAME")]
    pub scenario: Option<String>,

    /// Seed of the scenario's randomness (texture, wobble, noise) [default: 1]
    #[arg(long, allow_negative_numbers = true, value_name = "N")]
    pub seed: Option<u64>,

    /// Replay only the first N frames
    #[arg(long, allow_negative_numbers = true, value_name = "N")]
    pub frames: Option<usize>,

    /// Who sets each frame's exposure (--scenario only): `board`, the board's auto-exposure
    /// closed around the rendering, or `scenario`, the scenario's own (fixed, or the
    /// simulated sensor's AEC on the frame's mean) [default: board for sun and shadow, else
    /// scenario]
    #[arg(long, value_name = "WHO")]
    pub exposure: Option<String>,

    /// Directory for the figures [default: replay-<NAME>]
    // The doc comment is clap's help text, printed verbatim: `<NAME>` stays as it is.
    #[allow(rustdoc::invalid_html_tags)]
    #[arg(long, value_name = "DIR")]
    pub plots: Option<PathBuf>,

    /// Write no figures
    #[arg(long)]
    pub no_plots: bool,

    /// Print one JSON object with every table and the replay's setup instead of the text
    /// (figures only with --plots)
    #[arg(long)]
    pub json: bool,

    /// Also run the board's pipeline without each optional step (the pad fix's level fix and
    /// flip choice by prediction, the detector's pattern fit): the measurement behind what
    /// ships
    #[arg(long)]
    pub pose_steps: bool,

    /// The autopilot the board talks to, whose reconstruction is scored: ardupilot or px4
    /// [default: ardupilot]
    #[arg(long, value_name = "NAME", help_heading = "Flight")]
    pub autopilot: Option<String>,

    /// No flight effects and an ideal autopilot (FlightEffects::none, ErrorModel::none); the
    /// flags below still override single terms
    #[arg(long, help_heading = "Flight")]
    pub ideal: bool,

    /// The board is configured with the true camera mount (TD_CAM_ROLL, TD_CAM_PITCH set to
    /// the scenario's misalignment at start) [default: true for --scenario paper, else false]
    #[arg(
        long,
        value_name = "BOOL",
        num_args = 0..=1,
        default_missing_value = "true",
        help_heading = "Flight"
    )]
    pub mount_known: Option<bool>,

    /// The board never adopts an in-flight mount calibration (TD_CAM_CAL = 0)
    #[arg(long, help_heading = "Flight")]
    pub no_calibration: bool,

    /// Fly the set-up guide's mount-calibration hover first (scenario `hover`: 3 m over this
    /// scenario's pad for 20 s, same flight effects and error model, the next seed) through
    /// the board's companion, and start this flight with the TD_CAM_ROLL / TD_CAM_PITCH the
    /// board set in it, as its flash keeps them
    #[arg(
        long,
        requires = "scenario",
        conflicts_with_all = ["no_calibration", "mount_known"],
        help_heading = "Flight"
    )]
    pub calibration_hover: bool,

    /// Board parameters set before the flight, NAME=VALUE[,NAME=VALUE...] (e.g. the mount a
    /// hover's `touchdown calibrate` gave: TD_CAM_ROLL=1.59,TD_CAM_PITCH=-0.86); applied after
    /// --no-calibration and --mount-known, so they win
    #[arg(long, value_name = "LIST", help_heading = "Flight")]
    pub board_params: Option<String>,

    /// The flight effects' terms (--scenario only).
    #[command(flatten)]
    pub effect_terms: EffectArgs,

    /// How the pad moves (--scenario only; at rest by default).
    #[command(flatten)]
    pub pad_motion: PadMotionArgs,

    /// Attitude white noise per sample, degrees [default: 0.02]
    #[arg(
        long,
        value_name = "DEG",
        allow_negative_numbers = true,
        help_heading = "Error model"
    )]
    pub attitude_noise_deg: Option<f32>,

    /// Slowly varying roll/pitch bias, RMS, degrees [default: 0.3]
    #[arg(
        long,
        value_name = "DEG",
        allow_negative_numbers = true,
        help_heading = "Error model"
    )]
    pub tilt_bias_deg: Option<f32>,

    /// Heading bias, degrees [default: 0.5]
    #[arg(
        long,
        value_name = "DEG",
        allow_negative_numbers = true,
        help_heading = "Error model"
    )]
    pub heading_bias_deg: Option<f32>,

    /// An attitude sample's time stamp to its transmission, ms [default: 5]
    #[arg(
        long,
        value_name = "MS",
        allow_negative_numbers = true,
        help_heading = "Error model"
    )]
    pub sample_latency_ms: Option<f32>,

    /// Jitter of that latency, +- ms [default: 2]
    #[arg(
        long,
        value_name = "MS",
        allow_negative_numbers = true,
        help_heading = "Error model"
    )]
    pub sample_jitter_ms: Option<f32>,

    /// Fixed link delay per message, ms [default: 1]
    #[arg(
        long,
        value_name = "MS",
        allow_negative_numbers = true,
        help_heading = "Error model"
    )]
    pub link_delay_ms: Option<f32>,

    /// Link speed, bit/s (0: bytes take no time) [default: 921600]
    #[arg(
        long,
        value_name = "BAUD",
        allow_negative_numbers = true,
        help_heading = "Error model"
    )]
    pub baud: Option<f32>,

    /// The autopilot booted this long before the board, s [default: 12.3]
    #[arg(
        long,
        value_name = "S",
        allow_negative_numbers = true,
        help_heading = "Error model"
    )]
    pub clock_offset_s: Option<f32>,

    /// The autopilot's clock rate error, ppm [default: 30]
    #[arg(
        long,
        value_name = "PPM",
        allow_negative_numbers = true,
        help_heading = "Error model"
    )]
    pub clock_drift_ppm: Option<f32>,

    /// The board's exposure-to-send time, ms [default: 20]
    #[arg(
        long,
        value_name = "MS",
        allow_negative_numbers = true,
        help_heading = "Error model"
    )]
    pub processing_ms: Option<f32>,

    /// Its jitter, +- ms [default: 5]
    #[arg(
        long,
        value_name = "MS",
        allow_negative_numbers = true,
        help_heading = "Error model"
    )]
    pub processing_jitter_ms: Option<f32>,

    /// ArduPilot's PLND_LAG, s (0: the ideal autopilot, which assigns a target to its
    /// exposure) [default: 0.02]
    #[arg(
        long,
        value_name = "S",
        allow_negative_numbers = true,
        help_heading = "Error model"
    )]
    pub plnd_lag_s: Option<f32>,

    /// PX4's local position drift, RMS per axis, m [default: 0.3]
    #[arg(
        long,
        value_name = "M",
        allow_negative_numbers = true,
        help_heading = "Error model"
    )]
    pub position_drift_m: Option<f32>,

    /// The image model for --scenario: raster (ray casting) or warp (pre-rasterised world,
    /// much faster, its own optics and sensor) [default: raster]
    #[arg(
        long,
        value_name = "NAME",
        value_parser = RendererArg::parse,
        help_heading = "Advanced"
    )]
    pub renderer: Option<RendererArg>,

    #[command(flatten)]
    pub lens: LensArgs,

    /// Rendering threads for --scenario [default: all cores]
    #[arg(
        long,
        allow_negative_numbers = true,
        value_name = "N",
        help_heading = "Advanced"
    )]
    pub threads: Option<usize>,
}

/// The flight effects a scenario is rendered with: typical (none with --ideal), each term
/// overridden by its flag.
pub(super) fn flight_effects(args: &ReplayArgs) -> FlightEffects {
    args.effect_terms.effects(args.ideal)
}

/// A flag's value as the decimal it was written as (`0.02`, not `0.0199999995`).
fn widen(x: f32) -> f64 {
    x.to_string().parse().unwrap_or(f64::from(x))
}

/// Whether a flag that only a scenario takes was given.
pub(super) fn effect_flag_given(args: &ReplayArgs) -> bool {
    args.effect_terms.any_given() || args.mount_known.is_some()
}

/// The error model: typical (none with --ideal), each term overridden by its flag.
pub(super) fn error_model(args: &ReplayArgs) -> Result<ErrorModel, CliError> {
    let mut m = if args.ideal {
        ErrorModel::none()
    } else {
        ErrorModel::typical()
    };
    let flags = [
        (
            &mut m.attitude_noise_deg,
            args.attitude_noise_deg,
            "--attitude-noise-deg",
        ),
        (&mut m.tilt_bias_deg, args.tilt_bias_deg, "--tilt-bias-deg"),
        (
            &mut m.heading_bias_deg,
            args.heading_bias_deg,
            "--heading-bias-deg",
        ),
        (
            &mut m.sample_latency_ms,
            args.sample_latency_ms,
            "--sample-latency-ms",
        ),
        (
            &mut m.sample_jitter_ms,
            args.sample_jitter_ms,
            "--sample-jitter-ms",
        ),
        (&mut m.link_delay_ms, args.link_delay_ms, "--link-delay-ms"),
        (&mut m.baud, args.baud, "--baud"),
        (
            &mut m.clock_offset_s,
            args.clock_offset_s,
            "--clock-offset-s",
        ),
        (
            &mut m.clock_drift_ppm,
            args.clock_drift_ppm,
            "--clock-drift-ppm",
        ),
        (&mut m.processing_ms, args.processing_ms, "--processing-ms"),
        (
            &mut m.processing_jitter_ms,
            args.processing_jitter_ms,
            "--processing-jitter-ms",
        ),
        (&mut m.plnd_lag_s, args.plnd_lag_s, "--plnd-lag-s"),
        (
            &mut m.position_drift_m,
            args.position_drift_m,
            "--position-drift-m",
        ),
    ];
    for (slot, flag, name) in flags {
        if let Some(v) = flag.map(widen) {
            if !v.is_finite() {
                return Err(CliError(format!("{name} must be a number")));
            }
            *slot = v;
        }
    }
    // Only the clock drift and the heading bias have a meaningful sign.
    let non_negative = [
        (m.attitude_noise_deg, "--attitude-noise-deg"),
        (m.tilt_bias_deg, "--tilt-bias-deg"),
        (m.sample_latency_ms, "--sample-latency-ms"),
        (m.sample_jitter_ms, "--sample-jitter-ms"),
        (m.link_delay_ms, "--link-delay-ms"),
        (m.baud, "--baud"),
        (m.clock_offset_s, "--clock-offset-s"),
        (m.processing_ms, "--processing-ms"),
        (m.processing_jitter_ms, "--processing-jitter-ms"),
        (m.plnd_lag_s, "--plnd-lag-s"),
        (m.position_drift_m, "--position-drift-m"),
    ];
    if let Some((_, name)) = non_negative.iter().find(|(v, _)| *v < 0.0) {
        return Err(CliError(format!("{name} must not be negative")));
    }
    if m.clock_drift_ppm.abs() >= 1e5 {
        return Err(CliError("--clock-drift-ppm must be within +-100000".into()));
    }
    Ok(m)
}

/// The autopilot of --autopilot.
pub(super) fn autopilot_kind(args: &ReplayArgs) -> Result<AutopilotKind, CliError> {
    match args
        .autopilot
        .as_deref()
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        None | Some("ardupilot") => Ok(AutopilotKind::ArduPilot),
        Some("px4") => Ok(AutopilotKind::Px4),
        Some(other) => Err(CliError(format!(
            "unknown autopilot `{other}` (autopilots: ardupilot, px4)"
        ))),
    }
}

/// Whether the board starts with the true mount: --mount-known, by default for the paper
/// scenario only.
pub(super) fn mount_known(args: &ReplayArgs) -> bool {
    args.mount_known
        .unwrap_or_else(|| args.scenario.as_deref() == Some("paper") && !args.calibration_hover)
}

/// `--board-params`: `NAME=VALUE` pairs, comma-separated, in order.
pub(super) fn board_params(args: &ReplayArgs) -> Result<Vec<(String, f32)>, CliError> {
    crate::parse_board_params(args.board_params.as_deref())
}
