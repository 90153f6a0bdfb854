//! `touchdown replay`: run the firmware's pipeline (detector, pose, filter) on a recording or
//! on a scenario rendered in memory, for the paper's method and ours side by side, and print
//! paper-style tables and write figures.
//!
//! ## One path for both inputs
//! An [`Input`] yields frames, either decoded from a recording ([`RecordingReader`]) or
//! rendered by the [`Simulator`]; after that, everything is the same. Frames are produced on
//! a second thread, a couple ahead, while this one runs the methods on the previous frame,
//! so rendering (itself spread over the cores) and detection overlap and memory stays at a
//! few frames whatever the length.
//!
//! ## What the methods are given
//! Each frame goes through [`Experiment::process`] with both methods. With a truth, the
//! camera-to-pad rotation the vehicle would know (its flight controller's attitude with the
//! camera mount) is the truth's rotation, as in `eval::paper_geometry`: both methods are
//! attitude-aided. A recording without truth runs vision only (each pose's own rotation),
//! and the tables then give detection and estimate rates and the estimates, no errors.
//!
//! ## Sequences
//! A recording may jump: the paper scenario records only the hovers, one second apart, and
//! the vehicle is elsewhere at the next one. Whenever two frames are more than
//! [`SEQUENCE_GAP_S`] apart the filters are reset ([`Experiment::start_sequence`]), as a
//! restarted flight would; within a sequence they run on, through set-point changes.
//!
//! ## Set points
//! Frames labelled in `setpoints.csv` (or in the scenario's frame plans) are scored per label.
//! A label `x=1.2`, `y=2.4`, `z=5` (or `hover=3`, an altitude) gives the row's axis and
//! reference in metres, and so the paper's published values for that row where it has one;
//! any other label is a row of its own on the altitude axis without a reference.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Instant;

use clap::Args;
use nalgebra::{Matrix3, Vector3};
use touchdown_core::camera::CameraModel;
use touchdown_core::family::Family;
use touchdown_core::pipeline::PipelineConfig;

use super::{CliError, Outcome};
use crate::eval::{published, Axis, Experiment, ExperimentError, Frame, Method, Report, SetPoint};
use crate::families::{self, SelectedFamily};
use crate::formats::pad::PadConfig;
use crate::formats::recording::{CameraTruth, RecordingReader};
use crate::image_io::GrayFrame;
use crate::plot;
use crate::sim::scenario::{Scenario, SCENARIOS};
use crate::sim::{math, Simulator};
use crate::trace::{MethodSummary, Trace, TraceFrame};

/// Frames further apart than this (seconds) start a new sequence: the filters are reset.
pub const SEQUENCE_GAP_S: f64 = 0.5;
/// Altitudes (metres) at which a run without set points reports its error.
pub const ALTITUDE_CHECKPOINTS_M: [f64; 7] = [40.0, 20.0, 10.0, 5.0, 2.0, 1.0, 0.5];
/// Frames whose true altitude is within this fraction of a checkpoint count for it.
pub const ALTITUDE_TOLERANCE: f64 = 0.1;
/// Frames rendered or decoded ahead of the one being processed.
const FRAMES_AHEAD: usize = 2;

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
                     of paper, lateral, descent, landing, sun, shadow, occlusion (see
                     `touchdown simulate --help`); --seed picks the randomness

Methods:
  paper's method     the paper's detector, its homography pose of the largest pad marker,
                     and its per-axis Kalman filter with Table 1's values (lag included)
  ours               the board's pipeline as it ships: touchdown's detector, IPPE +
                     Levenberg-Marquardt fix of the whole pad (flip choice by prediction,
                     tilt from the attitude), the estimator; scored as the autopilot receives
                     it: the LANDING_TARGET's body FRD vector turned with the autopilot's
                     attitude
  --pose-steps       adds the board's pipeline without the level fix, without the flip
                     choice, and without both
Both are given the camera's attitude from the truth (what the flight controller knows);
a recording without truth runs vision only and prints no errors.

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
                     0.5 m (frames within 10 % of that altitude)
Frames more than 0.5 s apart (the paper scenario records only its hovers) start a new
sequence: the filters are reset.

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

    /// Render this scenario in memory instead (paper, lateral, descent, landing, sun, shadow,
    /// occlusion)
    #[arg(long, value_name = "NAME")]
    pub scenario: Option<String>,

    /// Seed of the scenario's randomness (texture, wobble, noise) [default: 1]
    #[arg(long, allow_negative_numbers = true, value_name = "N")]
    pub seed: Option<u64>,

    /// Replay only the first N frames
    #[arg(long, allow_negative_numbers = true, value_name = "N")]
    pub frames: Option<usize>,

    /// Directory for the figures [default: replay-<NAME>]
    #[arg(long, value_name = "DIR")]
    pub plots: Option<PathBuf>,

    /// Write no figures
    #[arg(long)]
    pub no_plots: bool,

    /// Also run the board's pipeline without each optional pad-fix step (the level fix, the
    /// flip choice by prediction): the measurement behind what ships
    #[arg(long)]
    pub pose_steps: bool,

    /// Rendering threads for --scenario [default: all cores]
    #[arg(
        long,
        allow_negative_numbers = true,
        value_name = "N",
        help_heading = "Advanced"
    )]
    pub threads: Option<usize>,
}

/// One frame from either input.
struct InputFrame {
    index: usize,
    t_us: u64,
    truth: Option<CameraTruth>,
    label: Option<String>,
    image: GrayFrame,
}

/// Where frames come from.
enum Source {
    Simulator(Box<Simulator>),
    Recording(RecordingReader),
}

/// The input of a replay: its description, camera, pad and frames.
struct Input {
    /// For the header and the figures' titles.
    title: String,
    /// For the default figure directory.
    short_name: String,
    camera: CameraModel,
    pad: PadConfig,
    has_truth: bool,
    frames: usize,
    /// Every label, in order of first appearance.
    labels: Vec<String>,
    source: Source,
}

impl Input {
    fn open(args: &ReplayArgs) -> Result<Input, CliError> {
        if args.frames == Some(0) {
            return Err(CliError("--frames must be at least 1".into()));
        }
        if args.threads == Some(0) {
            return Err(CliError("--threads must be at least 1".into()));
        }
        match (&args.recording, &args.scenario) {
            (Some(_), Some(_)) => Err(CliError(
                "give either a RECORDING directory or --scenario NAME, not both".into(),
            )),
            (None, None) => Err(CliError(
                "nothing to replay: give a RECORDING directory or --scenario NAME".into(),
            )),
            (None, Some(name)) => Self::scenario(name, args),
            (Some(dir), None) => {
                if args.seed.is_some() || args.threads.is_some() {
                    return Err(CliError(
                        "--seed and --threads apply to --scenario only".into(),
                    ));
                }
                Self::recording(dir, args.frames)
            }
        }
    }

    fn scenario(name: &str, args: &ReplayArgs) -> Result<Input, CliError> {
        let seed = args.seed.unwrap_or(1);
        let mut scenario = Scenario::named(name, seed).ok_or_else(|| {
            let names: Vec<&str> = SCENARIOS.iter().map(|s| s.0).collect();
            CliError(format!(
                "unknown scenario `{name}` (scenarios: {})",
                names.join(", ")
            ))
        })?;
        if let Some(n) = args.frames {
            scenario.truncate(n);
        }
        let labels = distinct(scenario.frames.iter().map(|f| f.label.as_deref()));
        let mut simulator = Simulator::new(scenario);
        if let Some(threads) = args.threads {
            simulator = simulator.with_threads(threads);
        }
        Ok(Input {
            title: format!("scenario {name}, seed {seed}"),
            short_name: name.to_string(),
            camera: simulator.scenario.camera.model,
            pad: simulator.scenario.pad.config.clone(),
            has_truth: true,
            frames: simulator.frame_count(),
            labels,
            source: Source::Simulator(Box::new(simulator)),
        })
    }

    fn recording(dir: &Path, frames: Option<usize>) -> Result<Input, CliError> {
        let reader = RecordingReader::open(dir).map_err(CliError::new)?;
        let count = frames.map_or(reader.len(), |n| n.min(reader.len()));
        if count == 0 {
            return Err(CliError(format!(
                "{}: the recording has no frames",
                dir.join("frames.csv").display()
            )));
        }
        let labels = distinct(reader.labels.iter().take(count).map(Option::as_deref));
        let short_name = dir
            .file_name()
            .map_or("recording".into(), |n| n.to_string_lossy().into_owned());
        Ok(Input {
            title: format!("recording {short_name}"),
            short_name,
            camera: reader.camera,
            pad: reader.pad.clone(),
            has_truth: reader.has_truth,
            frames: count,
            labels,
            source: Source::Recording(reader),
        })
    }

    /// Frame `k`.
    fn frame(&self, k: usize) -> Result<InputFrame, CliError> {
        match &self.source {
            Source::Simulator(simulator) => {
                let frame = simulator
                    .render(k)
                    .ok_or_else(|| CliError(format!("the scenario has no frame {k}")))?;
                Ok(InputFrame {
                    index: frame.index,
                    t_us: frame.t_us,
                    truth: Some(frame.truth),
                    label: frame.label,
                    image: frame.image,
                })
            }
            Source::Recording(reader) => {
                let frame = reader.frame(k).map_err(CliError::new)?;
                Ok(InputFrame {
                    index: frame.index,
                    t_us: frame.t_us,
                    truth: frame.truth,
                    label: frame.label,
                    image: frame.image,
                })
            }
        }
    }
}

/// The distinct labels, in order of first appearance.
fn distinct<'a>(labels: impl Iterator<Item = Option<&'a str>>) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for label in labels.flatten() {
        if !out.iter().any(|l| l == label) {
            out.push(label.to_string());
        }
    }
    out
}

/// The set point of a label (see the module docs).
pub fn set_point_of_label(label: &str) -> SetPoint {
    let parsed = label.split_once('=').and_then(|(key, value)| {
        let axis = match key.trim().to_ascii_lowercase().as_str() {
            "x" => Axis::X,
            "y" => Axis::Y,
            "z" | "hover" => Axis::Z,
            _ => return None,
        };
        let value: f64 = value.trim().parse().ok().filter(|v: &f64| v.is_finite())?;
        Some((axis, value))
    });
    let (axis, reference_m) = parsed.unwrap_or((Axis::Z, f64::NAN));
    SetPoint {
        label: label.to_string(),
        axis,
        reference_m,
    }
}

/// The rotation matrix of a truth quaternion (camera to pad).
fn attitude_of(truth: &CameraTruth) -> Matrix3<f32> {
    let m = math::quat_to_matrix(truth.orientation);
    Matrix3::from_fn(|i, j| m[i][j] as f32)
}

/// Progress on stderr: a bar, the frame count and the time left.
struct Progress<'a> {
    err: &'a mut dyn Write,
    enabled: bool,
    name: String,
    total: usize,
    started: Instant,
}

impl Progress<'_> {
    fn update(&mut self, done: usize) {
        if !self.enabled || (!done.is_multiple_of(4) && done != self.total) {
            return;
        }
        const WIDTH: usize = 30;
        let filled = WIDTH * done / self.total.max(1);
        let elapsed = self.started.elapsed().as_secs_f64();
        let left = elapsed / done.max(1) as f64 * (self.total - done.min(self.total)) as f64;
        // Progress is best effort: a closed stderr must not stop the run.
        let _ = write!(
            self.err,
            "\rreplay {}: [{}{}] {}/{} frames, {:.0} s left   ",
            self.name,
            "#".repeat(filled),
            "-".repeat(WIDTH - filled),
            done,
            self.total,
            left
        );
    }

    fn finish(&mut self) {
        if self.enabled {
            let _ = writeln!(self.err);
        }
    }
}

/// Runs `touchdown replay`.
pub fn run(
    args: &ReplayArgs,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<Outcome, CliError> {
    let started = Instant::now();
    let input = Input::open(args)?;
    let layout = input
        .pad
        .layout()
        .map_err(|e| CliError(format!("pad `{}`: invalid layout: {e:?}", input.pad.name)))?;
    let mut names: Vec<String> = input.pad.markers.iter().map(|m| m.family.clone()).collect();
    names.sort();
    names.dedup();
    let selected = families::resolve_all(&names).map_err(CliError::new)?;
    let views: Vec<Family<'_>> = selected.iter().map(SelectedFamily::family).collect();
    let family_refs: Vec<&Family<'_>> = views.iter().collect();
    let mut methods: Vec<Method> = vec![Method::paper().named("paper's method"), Method::ours()];
    if args.pose_steps {
        let steps = |flip_by_prediction, level_fix| PipelineConfig {
            flip_by_prediction,
            level_fix,
            ..PipelineConfig::default()
        };
        methods.extend([
            Method::board("no level fix", steps(true, false)),
            Method::board("no flip choice", steps(false, true)),
            Method::board("neither step", steps(false, false)),
        ]);
    }
    if !input.has_truth {
        methods = methods.into_iter().map(Method::without_attitude).collect();
    }
    let mut experiment = Experiment::new(input.camera, &family_refs, layout, &methods)
        .map_err(|e| CliError(format!("cannot set up the methods: {e:?}")))?;
    let set_points: BTreeMap<String, SetPoint> = input
        .labels
        .iter()
        .map(|l| (l.clone(), set_point_of_label(l)))
        .collect();
    let mut trace = Trace::new(methods.iter().map(|m| m.name.clone()).collect());
    let mut progress = Progress {
        err,
        enabled: std::io::stderr().is_terminal(),
        name: input.short_name.clone(),
        total: input.frames,
        started,
    };

    let (sender, receiver) = mpsc::sync_channel::<Result<InputFrame, CliError>>(FRAMES_AHEAD);
    let processed: Result<(), CliError> = std::thread::scope(|scope| {
        let input = &input;
        scope.spawn(move || {
            for k in 0..input.frames {
                let frame = input.frame(k);
                let failed = frame.is_err();
                // A closed channel means the replay stopped: nothing more to produce.
                if sender.send(frame).is_err() || failed {
                    break;
                }
            }
        });
        let mut previous_t_us: Option<u64> = None;
        let mut sequence = 0usize;
        for received in receiver {
            let frame = received?;
            if let Some(previous) = previous_t_us {
                if frame.t_us.saturating_sub(previous) as f64 * 1e-6 > SEQUENCE_GAP_S {
                    experiment.start_sequence().map_err(experiment_error)?;
                    sequence += 1;
                }
            }
            previous_t_us = Some(frame.t_us);
            let truth = frame.truth.as_ref().map(|t| Vector3::from(t.position));
            let set_point = frame
                .label
                .as_ref()
                .and_then(|l| set_points.get(l))
                // Frames that lost their truth in a recording with truth are not scored.
                .filter(|_| truth.is_some() || !input.has_truth);
            let outcomes = experiment
                .process(&Frame {
                    set_point,
                    t_us: frame.t_us,
                    truth: truth.unwrap_or_else(Vector3::zeros),
                    attitude: frame.truth.as_ref().map(attitude_of),
                    image: frame.image.view(),
                })
                .map_err(|e| match e {
                    ExperimentError::Detect(d) => CliError(format!(
                        "frame {}: the detector refused it: {d:?}",
                        frame.index
                    )),
                    other => experiment_error(other),
                })?;
            trace.frames.push(TraceFrame {
                index: frame.index,
                t_us: frame.t_us,
                sequence,
                truth,
                label: frame.label,
                outcomes,
            });
            progress.update(trace.frames.len());
        }
        Ok(())
    });
    progress.finish();
    processed?;
    let elapsed = started.elapsed().as_secs_f64();

    let report = experiment.report();
    let mut text = header(&input, &trace, elapsed);
    if !report.rows.is_empty() {
        if input.has_truth {
            text.push_str(&set_point_table(&report));
            text.push_str(&all_axes_table(&report));
        } else {
            text.push_str(&vision_only_table(&report));
        }
    }
    let summaries: Vec<MethodSummary> =
        (0..trace.methods.len()).map(|m| trace.summary(m)).collect();
    text.push_str(&summary_table(&trace, &summaries, input.has_truth));
    if report.rows.is_empty() && input.has_truth {
        text.push_str(&altitude_table(&trace));
    }
    if !args.no_plots {
        let dir = args
            .plots
            .clone()
            .unwrap_or_else(|| PathBuf::from(format!("replay-{}", input.short_name)));
        let written = plot::write_figures(&trace, &dir, &input.title).map_err(CliError::new)?;
        let _ = writeln!(
            text,
            "\nFigures: {} files in {} (position-x/y/z{}, .png and .svg)",
            written.len(),
            dir.display(),
            if trace.has_truth() {
                ", error-x/y/z"
            } else {
                ""
            }
        );
    }
    // Columns are padded to line up; the padding at the end of a line is noise.
    let text: String = text
        .lines()
        .map(|l| format!("{}\n", l.trim_end()))
        .collect();
    out.write_all(text.as_bytes())
        .map_err(|e| CliError(format!("cannot write to stdout: {e}")))?;
    Ok(Outcome::Success)
}

fn experiment_error(e: ExperimentError) -> CliError {
    CliError(format!("the replay failed: {e:?}"))
}

/// What was replayed, with what.
fn header(input: &Input, trace: &Trace, elapsed_s: f64) -> String {
    let mut s = String::new();
    let c = &input.camera;
    let markers = input.pad.markers.len();
    let sequences = trace.sequences();
    let _ = writeln!(
        s,
        "touchdown replay: {}: {} frames in {} sequence{} ({:.1} s of flight), replayed in {:.1} s",
        input.title,
        trace.frames.len(),
        sequences,
        if sequences == 1 { "" } else { "s" },
        trace
            .frames
            .last()
            .zip(trace.frames.first())
            .map_or(0.0, |(b, a)| b.t_s() - a.t_s()),
        elapsed_s
    );
    let _ = writeln!(
        s,
        "Camera {}x{} (f = {:.1} px{}), pad `{}` ({} marker{}). {}",
        c.width,
        c.height,
        c.fx,
        if c.has_distortion() {
            ", distorted"
        } else {
            ""
        },
        input.pad.name,
        markers,
        if markers == 1 { "" } else { "s" },
        if input.has_truth {
            "Both methods get the camera's attitude\nfrom the truth; positions are the camera \
             centre in the pad frame (x, y on the pad, z = altitude)."
        } else {
            "No truth in this recording: vision only\n(each pose's own rotation), no errors."
        }
    );
    s
}

/// `v` metres as centimetres in `width` columns, `-` when absent or not finite.
fn cm(v: Option<f64>, width: usize, decimals: usize) -> String {
    match v.filter(|v| v.is_finite()) {
        Some(v) => format!("{:>width$.decimals$}", 100.0 * v),
        None => format!("{:>width$}", "-"),
    }
}

fn percent(fraction: f64, width: usize) -> String {
    format!("{:>w$}%", format!("{:.0}", 100.0 * fraction), w = width - 1)
}

/// The row heading: axis and reference (cm) for a parsed label, else the label.
fn row_name(sp: &SetPoint) -> String {
    if sp.reference_m.is_finite() {
        format!("{} {:>5.0}", sp.axis.name(), 100.0 * sp.reference_m)
    } else {
        sp.label.chars().take(9).collect()
    }
}

/// Writes `text` centred in `width` columns.
fn centred(text: &str, width: usize) -> String {
    let text: String = text.chars().take(width).collect();
    format!("{text:^width$}")
}

/// The main table: per set point, on its axis.
fn set_point_table(report: &Report) -> String {
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
fn all_axes_table(report: &Report) -> String {
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
fn vision_only_table(report: &Report) -> String {
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

/// Over all frames, per method.
fn summary_table(trace: &Trace, summaries: &[MethodSummary], has_truth: bool) -> String {
    const LEFT: usize = 38;
    const COLUMN: usize = 30;
    let period = trace.frame_period_s();
    let mut s = format!(
        "\nSummary over all {} frames{}\n\n",
        trace.frames.len(),
        period.map_or(String::new(), |p| format!(" ({:.1} Hz)", 1.0 / p))
    );
    let _ = write!(s, "{:<LEFT$}", "");
    for name in &trace.methods {
        let _ = write!(s, "| {:<w$}", name, w = COLUMN - 2);
    }
    s.push('\n');
    let mut row = |name: &str, cell: &dyn Fn(&MethodSummary) -> String| {
        let _ = write!(s, "{name:<LEFT$}");
        for summary in summaries {
            let _ = write!(s, "| {:<w$}", cell(summary), w = COLUMN - 2);
        }
        s.push('\n');
    };
    let xyz = |v: Option<[f64; 3]>| match v {
        Some(v) => format!(
            "{:.2} / {:.2} / {:.2}",
            100.0 * v[0],
            100.0 * v[1],
            100.0 * v[2]
        ),
        None => "-".into(),
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
    s
}

/// Mean |error| near each altitude checkpoint (runs without set points).
fn altitude_table(trace: &Trace) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_give_axis_and_reference() {
        let sp = set_point_of_label("x=1.2");
        assert_eq!((sp.axis, sp.reference_m), (Axis::X, 1.2));
        let sp = set_point_of_label("hover=3");
        assert_eq!((sp.axis, sp.reference_m), (Axis::Z, 3.0));
        let sp = set_point_of_label("Y = 6");
        assert_eq!((sp.axis, sp.reference_m), (Axis::Y, 6.0));
        let sp = set_point_of_label("approach");
        assert!(sp.reference_m.is_nan() && sp.label == "approach");
        assert!(set_point_of_label("z=far").reference_m.is_nan());
    }

    #[test]
    fn help_names_every_scenario() {
        for (name, _) in SCENARIOS {
            assert!(LONG_HELP.contains(name), "LONG_HELP lacks {name}");
        }
    }

    /// A 15 Hz descent from 12 m to 0.4 m at 0.5 m/s; method 0 estimates 2 cm east of the
    /// truth in every frame, method 1 never finds the pad.
    fn descent_trace() -> Trace {
        use crate::eval::MethodOutcome;
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

    #[test]
    fn distinct_keeps_first_appearance_order() {
        let labels = [Some("b"), None, Some("a"), Some("b")];
        assert_eq!(distinct(labels.into_iter()), ["b", "a"]);
    }
}
