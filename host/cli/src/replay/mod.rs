//! `touchdown replay`: run the firmware's pipeline (detector, pose, filter) on a recording or
//! on a scenario rendered in memory, for the paper's method and ours side by side, and print
//! paper-style tables (submodule `tables`), or the same numbers as one JSON object with the
//! replay's setup (`--json`, submodule `json`), and write figures ([`crate::plot`]).
//!
//! ## One path for both inputs
//! An `Input` (submodule `input`) yields frames, either decoded from a recording
//! ([`RecordingReader`](touchdown_formats::recording::RecordingReader)) or rendered by the
//! [`Simulator`](touchdown_sim::Simulator); after that, everything is the same. Frames are produced on
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

use super::{CliError, Outcome};
use crate::plot;
use nalgebra::Vector3;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::sync::mpsc;
use std::time::Instant;
use touchdown_core::companion::mavlink::dialects::common::MavAutopilot;
use touchdown_core::companion::{Profile, ProfileSetting};
use touchdown_core::family::Family;
use touchdown_core::filter::CameraMount;
use touchdown_core::params::{ParamId, ParamSet};
use touchdown_core::pipeline::PipelineConfig;
use touchdown_eval::flight::{AutopilotKind, ErrorModel, FlightSetup, FlightTrace};
use touchdown_eval::trace::{MethodSummary, Trace, TraceFrame};
use touchdown_eval::{Experiment, ExperimentError, Frame, Method, SetPoint};
use touchdown_formats::families::{self, SelectedFamily};

mod args;
mod calibration;
mod exposure;
mod in_view;
mod input;
mod json;
mod tables;

use args::{
    autopilot_kind, board_params, effect_flag_given, error_model, flight_effects, mount_known,
};
pub use args::{ReplayArgs, LONG_HELP};
use calibration::calibration_hover;

pub use input::set_point_of_label;
use input::{attitude_of, Input, InputFrame};
use tables::{
    all_axes_table, altitude_table, flight_altitude_table, flight_summary_table, set_point_table,
    summary_table, vision_only_table,
};

/// Frames further apart than this (seconds) start a new sequence: the filters are reset.
pub const SEQUENCE_GAP_S: f64 = 0.5;
/// Altitudes (metres) at which a run without set points reports its error.
pub const ALTITUDE_CHECKPOINTS_M: [f64; 7] = [40.0, 20.0, 10.0, 5.0, 2.0, 1.0, 0.5];
/// Frames whose true altitude is within this fraction of a checkpoint count for it.
pub const ALTITUDE_TOLERANCE: f64 = 0.1;
/// Frames rendered or decoded ahead of the one being processed.
const FRAMES_AHEAD: usize = 2;

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
    let model = error_model(args)?;
    let autopilot = autopilot_kind(args)?;
    let input = Input::open(args)?;
    let layout = input
        .pad
        .layout()
        .map_err(|e| CliError(format!("pad `{}`: invalid layout: {e:?}", input.pad.name)))?;
    let selected = families::resolve_pad(&input.pad).map_err(CliError::new)?;
    let views: Vec<Family<'_>> = selected.iter().map(SelectedFamily::family).collect();
    let family_refs: Vec<&Family<'_>> = views.iter().collect();
    let mut methods: Vec<Method> = vec![Method::paper().named("paper's method"), Method::ours()];
    if args.pose_steps {
        let steps = |flip_by_prediction, level_fix| PipelineConfig {
            flip_by_prediction,
            level_fix,
            ..PipelineConfig::default()
        };
        let mut no_pattern_fit = PipelineConfig::default();
        no_pattern_fit.detector.fit_small_markers = false;
        let no_shutter_correction = PipelineConfig {
            correct_rolling_shutter: false,
            ..PipelineConfig::default()
        };
        methods.extend([
            Method::board("no level fix", steps(true, false)),
            Method::board("no flip choice", steps(false, true)),
            Method::board("neither step", steps(false, false)),
            Method::board("no pattern fit", no_pattern_fit),
            Method::board("no shutter correction", no_shutter_correction),
            Method::board(
                "no second look",
                PipelineConfig {
                    look_again: false,
                    ..PipelineConfig::default()
                },
            ),
        ]);
    }
    if !input.has_truth {
        methods = methods.into_iter().map(Method::without_attitude).collect();
    }
    let mut flight = flight_setup(args, &input, autopilot, model)?;
    let hover = match (&mut flight, &args.scenario, args.calibration_hover) {
        (Some(setup), Some(name), true) => {
            let hover = calibration_hover(args, name, setup, err)?;
            setup.params.extend(hover.params());
            Some(hover)
        }
        _ => None,
    };
    let mut experiment = match (&flight, input.has_truth) {
        (Some(setup), true) => {
            // Mount known: the board's mount is the true one (the paper's method is given it
            // too) instead of the nominal one plus its calibration.
            Experiment::in_flight(input.camera, &family_refs, layout, &methods, setup)
        }
        _ => Experiment::new(input.camera, &family_refs, layout, &methods),
    }
    .map_err(|e| CliError(format!("cannot set up the methods: {e:?}")))?;
    let in_flight = flight.is_some() && input.has_truth;
    let mut board_exposure = match exposure_control(args, &input)? {
        ExposureControl::Scenario => None,
        ExposureControl::Board => {
            let limits = board_settings(flight.as_ref()).exposure;
            let mut loop_ = exposure::BoardExposure::new(limits);
            exposure::preroll(&mut loop_, &input, &family_refs, layout)?;
            // The board's loop meters what the board's own method decodes.
            let method = methods
                .iter()
                .position(|m| m.name == Method::ours().name)
                .ok_or_else(|| {
                    CliError::new("--exposure board: the board's method (ours) is not replayed")
                })?;
            Some(ClosedExposure { loop_, method })
        }
    };
    let mut progress = Progress {
        err,
        enabled: std::io::stderr().is_terminal(),
        name: input.short_name.clone(),
        total: input.frames,
        started,
    };
    let (trace, flight_trace) = fly(
        &input,
        &mut experiment,
        &methods,
        in_flight,
        board_exposure.as_mut(),
        &mut progress,
    )?;
    let elapsed = started.elapsed().as_secs_f64();

    let in_view = in_view::flags(&input, &trace).map(|flags| in_view::summaries(&trace, &flags));
    let report = experiment.report();
    let summaries: Vec<MethodSummary> =
        (0..trace.methods.len()).map(|m| trace.summary(m)).collect();
    let figure_dir = match (&args.plots, args.no_plots) {
        (_, true) => None,
        (Some(dir), false) => Some(dir.clone()),
        // A script asking for JSON gets no directory it did not ask for.
        (None, false) if args.json => None,
        (None, false) => Some(PathBuf::from(format!("replay-{}", input.short_name))),
    };
    let figures = match &figure_dir {
        Some(dir) => Some(plot::write_figures(&trace, dir, &input.title).map_err(CliError::new)?),
        None => None,
    };
    if args.json {
        let document = json::document(
            args,
            &input,
            &methods,
            &json::Results {
                report: &report,
                trace: &trace,
                summaries: &summaries,
                elapsed_s: elapsed,
                flight: flight
                    .as_ref()
                    .filter(|_| in_flight)
                    .map(|setup| json::FlightResults {
                        setup,
                        effects: input.effects.as_ref(),
                        mount_known: mount_known(args) && input.effects.is_some(),
                        hover: hover.as_ref(),
                        trace: &flight_trace,
                    }),
                in_view: in_view.as_deref(),
            },
            figure_dir.as_deref().zip(figures.as_ref().map(Vec::len)),
        );
        let mut line = serde_json::to_string(&document)
            .map_err(|e| CliError(format!("cannot write the JSON: {e}")))?;
        line.push('\n');
        out.write_all(line.as_bytes())
            .map_err(|e| CliError(format!("cannot write to stdout: {e}")))?;
        return Ok(Outcome::Success);
    }
    let mut text = header(&input, &trace, elapsed, in_flight);
    text.push_str(&exposure_header(&input, board_exposure.as_ref()));
    if let Some(setup) = flight.as_ref().filter(|_| in_flight) {
        text.push_str(&flight_header(args, &input, setup));
        if let Some(hover) = &hover {
            text.push_str(&hover.describe());
        }
    }
    if !report.rows.is_empty() {
        if input.has_truth {
            text.push_str(&set_point_table(&report));
            text.push_str(&all_axes_table(&report));
        } else {
            text.push_str(&vision_only_table(&report));
        }
    }
    text.push_str(&summary_table(&trace, &summaries, input.has_truth));
    if let Some(in_view) = &in_view {
        text.push_str(&in_view::table(&trace, in_view));
    }
    if in_flight {
        text.push_str(&flight_summary_table(&flight_trace, &trace));
    }
    if report.rows.is_empty() && input.has_truth {
        if in_flight {
            text.push_str(&flight_altitude_table(&flight_trace, &trace));
        } else {
            text.push_str(&altitude_table(&trace));
        }
    }
    if let Some((dir, written)) = figure_dir.as_ref().zip(figures.as_ref()) {
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

/// Who sets a scenario's exposure (`--exposure`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ExposureControl {
    /// The scenario's own (fixed, or the simulated sensor's AEC).
    Scenario,
    /// The board's loop, closed around the rendering (submodule `exposure`).
    Board,
}

/// `--exposure`, or the scenario's default.
fn exposure_control(args: &ReplayArgs, input: &Input) -> Result<ExposureControl, CliError> {
    let given = match args.exposure.as_deref() {
        None => None,
        Some("board") => Some(ExposureControl::Board),
        Some("scenario") => Some(ExposureControl::Scenario),
        Some(other) => {
            return Err(CliError(format!(
                "--exposure: unknown `{other}` (board or scenario)"
            )))
        }
    };
    match (given, &input.source) {
        (Some(_), input::Source::Recording(_)) => Err(CliError(
            "--exposure applies to --scenario only (a recording's exposure is recorded)".into(),
        )),
        (Some(c), _) => Ok(c),
        (None, _) if input.board_exposure => Ok(ExposureControl::Board),
        (None, _) => Ok(ExposureControl::Scenario),
    }
}

/// The board's exposure loop closed around the rendering, and the method whose metering
/// feeds it.
struct ClosedExposure {
    loop_: exposure::BoardExposure,
    method: usize,
}

/// The header's line on who set the exposure.
fn exposure_header(input: &Input, closed: Option<&ClosedExposure>) -> String {
    match (closed, &input.source) {
        (Some(_), _) => format!(
            "Exposure: the board's auto-exposure (metering the decoded markers, the scene's \
             highlight, the body rate), closed around\nthe rendering: each frame exposed with \
             the setting chosen {} frames before; {} frames of settling at the first frame's \
             pose.\n",
            exposure::LATENCY_FRAMES,
            exposure::PREROLL_FRAMES
        ),
        (None, input::Source::Simulator(_)) => {
            "Exposure: the scenario's own (fixed, or the simulated sensor's AEC on the frame's \
             mean).\n"
                .into()
        }
        (None, input::Source::Recording(_)) => String::new(),
    }
}

/// Runs every frame of `input` through `experiment`, in flight (with the truth between
/// frames) when `in_flight`: the frames are rendered or decoded on a second thread, a couple
/// ahead of the one processed. With `closed`, each frame is rendered with the exposure the
/// board's loop chose [`exposure::LATENCY_FRAMES`] frames before (the loop is fed the
/// metering of `closed.method` after each frame and its new setting is sent back to the
/// rendering thread). Returns the per-frame trace and, in flight, the three errors per frame.
fn fly(
    input: &Input,
    experiment: &mut Experiment<'_>,
    methods: &[Method],
    in_flight: bool,
    mut closed: Option<&mut ClosedExposure>,
    progress: &mut Progress<'_>,
) -> Result<(Trace, FlightTrace), CliError> {
    let mut flight_trace = FlightTrace::new(methods.iter().map(|m| m.name.clone()).collect());
    let set_points: BTreeMap<String, SetPoint> = input
        .labels
        .iter()
        .map(|l| (l.clone(), set_point_of_label(l)))
        .collect();
    let mut trace = Trace::new(methods.iter().map(|m| m.name.clone()).collect());

    let truth_source = input.truth_source();
    let (sender, receiver) = mpsc::sync_channel::<Result<InputFrame, CliError>>(FRAMES_AHEAD);
    // The exposures of the first frames, then one back from each frame processed.
    let mut queued: std::collections::VecDeque<_> = closed
        .as_ref()
        .map(|c| c.loop_.queued())
        .unwrap_or_default()
        .into();
    let is_closed = closed.is_some();
    let (feedback, exposures) = mpsc::channel();
    let processed: Result<(), CliError> = std::thread::scope(|scope| {
        // Owned by this side, so that it is dropped (and the rendering thread, waiting on
        // it, stops) when this side returns early.
        let feedback = feedback;
        scope.spawn(move || {
            for k in 0..input.frames {
                let exposure = match (is_closed, queued.pop_front()) {
                    (false, _) => None,
                    (true, Some(e)) => Some(e),
                    (true, None) => match exposures.recv() {
                        Ok(e) => Some(e),
                        // The replay stopped.
                        Err(_) => break,
                    },
                };
                let frame = input.frame(k, exposure);
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
                .process_with(
                    &Frame {
                        set_point,
                        t_us: frame.t_us,
                        truth: truth.unwrap_or_else(Vector3::zeros),
                        attitude: frame.truth.as_ref().map(attitude_of),
                        image: frame.image.view(),
                    },
                    truth_source.as_deref().filter(|_| in_flight),
                )
                .map_err(|e| match e {
                    ExperimentError::Detect(d) => CliError(format!(
                        "frame {}: the detector refused it: {d:?}",
                        frame.index
                    )),
                    other => experiment_error(other),
                })?;
            if let Some(c) = closed.as_deref_mut() {
                c.loop_.after_frame(experiment.metering(c.method).as_ref());
                // The rendering thread may have stopped (an error): nothing to tell it.
                let _ = feedback.send(c.loop_.newest());
            }
            if in_flight {
                flight_trace
                    .frames
                    .push(experiment.flight_outcomes().to_vec());
            }
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
    Ok((trace, flight_trace))
}

fn experiment_error(e: ExperimentError) -> CliError {
    CliError(format!("the replay failed: {e:?}"))
}

/// The flight every method runs in (`None`: no truth, vision only).
fn flight_setup(
    args: &ReplayArgs,
    input: &Input,
    autopilot: AutopilotKind,
    model: ErrorModel,
) -> Result<Option<FlightSetup>, CliError> {
    if !input.has_truth {
        return Ok(None);
    }
    let mut setup = FlightSetup::new(autopilot, model);
    setup.seed = args.seed.unwrap_or(1);
    if args.no_calibration {
        setup.params.push(("TD_CAM_CAL".into(), 0.0));
    }
    if let (true, Some(effects), Some(mount)) =
        (mount_known(args), &input.effects, &input.true_mount)
    {
        setup
            .params
            .push(("TD_CAM_ROLL".into(), effects.mount_roll_deg as f32));
        setup
            .params
            .push(("TD_CAM_PITCH".into(), effects.mount_pitch_deg as f32));
        setup.paper_mount = CameraMount::from_matrix(mount)
            .map_err(|e| CliError(format!("the scenario's mount is not a rotation: {e:?}")))?;
    }
    setup.params.extend(board_params(args)?);
    for (name, _) in &setup.params {
        if touchdown_core::params::ParamId::from_name(name).is_none() {
            return Err(CliError(format!(
                "this build of the board has no parameter {name}"
            )));
        }
    }
    Ok(Some(setup))
}

/// The board's settings after `setup`'s parameters (the defaults without a flight).
fn board_settings(setup: Option<&FlightSetup>) -> touchdown_core::params::PipelineSettings {
    let params = board_param_set(setup.map_or(&[][..], |s| &s.params[..]));
    touchdown_core::params::PipelineSettings::from_params(&params)
}

/// The board's parameters after `params` (TD_* names and values): the flight's own
/// companion applies the same list and reports what it refuses, so unknown names and refused
/// values are skipped here.
fn board_param_set(params: &[(String, f32)]) -> ParamSet {
    let mut set = ParamSet::default();
    for (name, value) in params {
        if let Some(id) = ParamId::from_name(name) {
            let _ = set.set(id, *value);
        }
    }
    set
}

/// The profile the board sends its targets in during `setup`'s flight: TD_PROFILE after
/// `setup.params` (applied as the flight applies them), auto resolved with the simulated
/// autopilot's HEARTBEAT.
fn board_profile(setup: &FlightSetup) -> Option<Profile> {
    let params = board_param_set(&setup.params);
    let heartbeat = match setup.autopilot {
        AutopilotKind::ArduPilot => MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        AutopilotKind::Px4 => MavAutopilot::MAV_AUTOPILOT_PX4,
    };
    ProfileSetting::from_param(params.get_int(ParamId::Profile))
        .resolve(Profile::from_autopilot(heartbeat))
}

/// What the simulated autopilot reconstructs the pad from, for the header: it depends on the
/// frame the board sends (TD_PROFILE), not on the autopilot alone.
fn reconstruction(setup: &FlightSetup) -> &'static str {
    match (setup.autopilot, board_profile(setup)) {
        // The BODY_FRD text is the one docs/accuracy.md's example output shows.
        (AutopilotKind::ArduPilot, Some(Profile::ArduPilot)) => {
            "ArduPilot (body vector, its attitude at receipt - PLND_LAG)"
        }
        (AutopilotKind::ArduPilot, Some(Profile::ArduPilotLocalFrd)) => {
            "ArduPilot 4.7+ (LOCAL_FRD: the vector levelled with the board's attitude at the \
             exposure, the yaw alone of its attitude at receipt - PLND_LAG)"
        }
        (AutopilotKind::ArduPilot, _) => {
            "ArduPilot (refuses the LOCAL_NED targets of TD_PROFILE 1: no (b))"
        }
        (AutopilotKind::Px4, Some(Profile::Px4)) => "PX4 (LOCAL_NED point, minus its own position)",
        (AutopilotKind::Px4, _) => {
            "PX4 (sent ArduPilot's frame, TD_PROFILE 0 or 3, which a real PX4 refuses; x, y, z \
             read as a LOCAL_NED point, minus its own position)"
        }
    }
}

/// The flight the methods ran in: the autopilot, the effects and the error model.
fn flight_header(args: &ReplayArgs, input: &Input, setup: &FlightSetup) -> String {
    let m = &setup.model;
    let mut s = format!(
        "In flight: the board's companion against a simulated {} over MAVLink; scored as \
         (a) what touchdown sends,\n(b) what the autopilot reconstructs from it, (c) what it \
         would reconstruct from an ideal sensor.\n",
        reconstruction(setup)
    );
    if let Some(e) = &input.effects {
        let _ = writeln!(
            s,
            "Flight effects: readout {} ms, vibration {} deg, mount roll {} pitch {} deg ({}).",
            e.readout_ms,
            e.vibration_deg,
            e.mount_roll_deg,
            e.mount_pitch_deg,
            if mount_known(args) {
                "known to the board"
            } else if args.no_calibration {
                "not calibrated"
            } else if args.calibration_hover {
                "calibrated in the hover before, and on in flight"
            } else {
                "calibrated in flight"
            }
        );
    }
    let _ = writeln!(
        s,
        "Error model: attitude noise {} deg, tilt bias {} deg, heading bias {} deg, sample \
         latency {} +- {} ms,\nlink {} ms + bytes at {} baud, clock +{} s at {} ppm, \
         processing {} +- {} ms, PLND_LAG {} s, position drift {} m.",
        m.attitude_noise_deg,
        m.tilt_bias_deg,
        m.heading_bias_deg,
        m.sample_latency_ms,
        m.sample_jitter_ms,
        m.link_delay_ms,
        m.baud,
        m.clock_offset_s,
        m.clock_drift_ppm,
        m.processing_ms,
        m.processing_jitter_ms,
        m.plnd_lag_s,
        m.position_drift_m
    );
    s
}

/// What was replayed, with what.
fn header(input: &Input, trace: &Trace, elapsed_s: f64, in_flight: bool) -> String {
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
        if in_flight {
            "The methods get the attitude the board\nreceives from the autopilot; positions are \
             the camera centre in the pad frame (x, y on the pad, z = altitude)."
        } else if input.has_truth {
            "Both methods get the camera's attitude\nfrom the truth; positions are the camera \
             centre in the pad frame (x, y on the pad, z = altitude)."
        } else {
            "No truth in this recording: vision only\n(each pose's own rotation), no errors."
        }
    );
    s
}

#[cfg(test)]
mod tests {
    use touchdown_sim::scenario::SCENARIOS;

    use super::*;

    /// The header names the frame the board sends and how the simulated autopilot turns it:
    /// TD_PROFILE 3 is LOCAL_FRD and the yaw alone, whatever the `--board-params` order.
    #[test]
    fn the_header_says_what_the_autopilot_reconstructs() {
        let with = |kind, params: &[(&str, f32)]| {
            let mut setup = FlightSetup::new(kind, ErrorModel::none());
            setup.params = params.iter().map(|&(n, v)| (n.to_string(), v)).collect();
            reconstruction(&setup)
        };
        let ardupilot = with(AutopilotKind::ArduPilot, &[]);
        assert_eq!(
            ardupilot,
            "ArduPilot (body vector, its attitude at receipt - PLND_LAG)"
        );
        assert_eq!(
            with(AutopilotKind::ArduPilot, &[("TD_PROFILE", 0.0)]),
            ardupilot
        );
        let local_frd = with(
            AutopilotKind::ArduPilot,
            &[
                ("TD_PROFILE", 0.0),
                ("TD_CAM_CAL", 0.0),
                ("TD_PROFILE", 3.0),
            ],
        );
        assert!(
            local_frd.contains("LOCAL_FRD") && local_frd.contains("yaw alone"),
            "{local_frd}"
        );
        assert!(!local_frd.contains("body vector"), "{local_frd}");
        let refused = with(AutopilotKind::ArduPilot, &[("TD_PROFILE", 1.0)]);
        assert!(refused.contains("refuses"), "{refused}");
        let px4 = with(AutopilotKind::Px4, &[]);
        assert!(px4.contains("LOCAL_NED point"), "{px4}");
        assert!(with(AutopilotKind::Px4, &[("TD_PROFILE", 3.0)]).contains("refuses"));
    }

    #[test]
    fn help_names_every_scenario() {
        for (name, _) in SCENARIOS {
            assert!(LONG_HELP.contains(name), "LONG_HELP lacks {name}");
        }
    }
}
