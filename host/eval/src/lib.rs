//! Evaluation of touchdown's per-frame path on frames with a known truth: set-point
//! experiments scored as the reference paper scores its Tables 2-4 (this module), the paper's
//! geometry simulated in memory ([`paper_geometry`]), a replay's per-frame record and the
//! figures computed from it ([`trace`]), a detector's output scored against a rendered
//! frame's truth ([`scoring`]) and the hard still set it is measured on ([`stills`]);
//! [`workspace`] is the heap work memory the detector runs in.
//!
//! It is a library of measurements, not a tool: it prints tables as text but has no command
//! line and draws no plots (that is `touchdown-cli`, whose `replay` runs it), and it renders
//! no frames itself (it asks `touchdown-sim`). A crate of its own so that the command line,
//! the examples and the integration tests score with one definition, without a command line's
//! dependencies.
//!
//! ## Set-point experiments
//! How well a pipeline (detector, pose, filter) estimates the vehicle's position at a series
//! of hover points.
//!
//! ## What is compared
//! The paper reports "local x, y and z" of the aircraft with the tag as the reference point,
//! averaged per set point. Here that is the **camera centre in the pad frame** (contract: x
//! right, y up on the printed pad, z up out of the pad), in metres:
//! - paper Z = pad z, the altitude above the pad;
//! - paper X = pad x, paper Y = pad y, the horizontal offsets.
//!
//! (For a single-marker pad, the pad frame is the marker frame.)
//!
//! ## How a method turns a frame into that position
//! A [`Method`] is one of two per-frame paths of core, run as they are:
//! - **ours** ([`MethodKind::Board`]): [`FramePipeline`], the very path the camera board runs
//!   (detection, the pad fix with its prediction and level steps as its [`PipelineConfig`]
//!   says, the estimator), fed with the vehicle's attitude at each exposure as the
//!   autopilot would stream it ([`Method::use_attitude`]; without it the estimator runs its
//!   camera-frame track). Its output is scored as the autopilot receives it: the pad in body
//!   FRD, what the ArduPilot profile's LANDING_TARGET carries, turned into the pad frame with
//!   the autopilot's own attitude at that exposure (the frame's true camera-to-pad rotation;
//!   without one, this frame's pose rotation), exactly what ArduPilot's precision landing
//!   does with it. The raw position is the frame's pad fix (levelled when the level step
//!   ran): `c = -R^T t`;
//! - **the paper's** ([`MethodKind::Paper`]): [`PaperPipeline`], the paper's detector,
//!   homography decomposition of the largest marker and per-axis Kalman filter (equations
//!   8-14, Table 1), on `c = -R_attitude t` (the pose's translation turned with the attitude)
//!   or, without an attitude, `c = -R_pose^T t`.
//!
//! Why the attitude matters: the tilt of a single small marker is barely observable (at 15 m
//! a 1 m marker spans 37 px), and every degree of tilt error moves `-R_pose^T t` sideways by
//! 1.7 % of the range, metres at altitude, while `t` itself is well determined.
//!
//! Both the filtered output (what the paper averages per set point) and the raw per-frame
//! position are scored, so a table can tell the pose's share from the filter's.
//!
//! ## Scoring
//! Per set point and method, over the *scored* frames (frames carrying a [`SetPoint`]; frames
//! without one still run through the pipeline, e.g. while the vehicle settles or travels):
//! - **error = truth - estimate** per frame and axis (the paper's sign: its Table 2 lists
//!   500 cm, estimate 502 cm, error -2.1 cm), truth being the frame's own true position (the
//!   hover wanders), metres;
//! - mean estimate, mean error, mean |error| (over frames, so noise counts, not only bias),
//!   RMS error, per axis;
//! - detection rate (frames where the pose was computed) and estimate rate (frames with a
//!   filter output; our tracker reports nothing until a track is confirmed and nothing stale).
//!
//! ## Use
//! [`Experiment`] takes frames one at a time ([`Experiment::process`]), so a simulator
//! ([`paper_geometry`]) and a recording replay feed it the same way;
//! [`Experiment::start_sequence`] resets the filters between independent flights or hovers;
//! [`Experiment::report`] gives the statistics and [`Report::table`] prints them next to the
//! paper's published values ([`PAPER_TABLES`]).

use std::fmt::Write as _;

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use touchdown_core::camera::CameraModel;
use touchdown_core::detect::DetectError;
use touchdown_core::family::Family;
use touchdown_core::filter::{Attitude, PaperConfig, VehicleState};
use touchdown_core::image::GrayImage;
use touchdown_core::pad::PadLayout;
use touchdown_core::params::PipelineSettings;
use touchdown_core::pipeline::{FramePipeline, PaperPipeline, PipelineConfig};
use touchdown_core::sensor::Metering;

pub mod closed_loop;
pub mod flight;
pub mod paper_geometry;
pub mod scoring;
pub mod stills;
pub mod trace;
pub mod workspace;

use crate::flight::{FlightOutcome, FlightRun, FlightSetup, TruthSource};
use crate::workspace::HostWorkspace;

/// One of the paper's position axes (see the module docs for the mapping to the pad frame).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Axis {
    /// Pad x: horizontal offset (Table 4).
    X,
    /// Pad y: horizontal offset (Table 3).
    Y,
    /// Pad z: altitude above the pad (Table 2).
    Z,
}

impl Axis {
    /// All three, in x, y, z order.
    pub const ALL: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];

    /// Index into an x, y, z vector.
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }

    /// "X", "Y" or "Z".
    pub fn name(self) -> &'static str {
        match self {
            Axis::X => "X",
            Axis::Y => "Y",
            Axis::Z => "Z",
        }
    }
}

/// A hover point of an experiment: the row of a results table.
#[derive(Debug, Clone, PartialEq)]
pub struct SetPoint {
    /// Unique name of the row (frames with the same label are pooled).
    pub label: String,
    /// The axis the row reports (the others are scored too).
    pub axis: Axis,
    /// The commanded value on that axis, metres (the table's "reference").
    pub reference_m: f64,
}

/// One frame of an experiment.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    /// The set point the frame scores for; `None`: run the pipelines (the filters see the
    /// frame) but score nothing, e.g. while the vehicle settles at a set point.
    pub set_point: Option<&'a SetPoint>,
    /// Exposure time, microseconds, increasing within a sequence.
    pub t_us: u64,
    /// True camera centre in the pad frame, metres.
    pub truth: Vector3<f64>,
    /// The camera-to-pad rotation as the vehicle knows it (flight controller attitude, camera
    /// mount and pad heading), if known; see [`Method::use_attitude`].
    pub attitude: Option<Matrix3<f32>>,
    /// The grey frame.
    pub image: GrayImage<'a>,
}

/// Which per-frame path of core a method runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MethodKind {
    /// The reference paper's: [`PaperPipeline`] with this filter configuration.
    Paper(PaperConfig),
    /// The camera board's: [`FramePipeline`] with this configuration.
    Board(PipelineConfig),
}

/// A path to evaluate (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Method {
    /// Column heading.
    pub name: String,
    /// Which path, configured how.
    pub kind: MethodKind,
    /// The vehicle knows its attitude: the paper's path turns its translation with it, the
    /// board's estimator gets it as the autopilot's attitude stream.
    pub use_attitude: bool,
}

impl Method {
    /// The paper's pipeline in our code: its detector, its homography decomposition, its
    /// filter with Table 1; given the vehicle attitude like ours (the paper's camera looked
    /// straight down from a level hovering vehicle).
    pub fn paper() -> Self {
        Method {
            name: "paper's method".into(),
            kind: MethodKind::Paper(PaperConfig::TABLE_1),
            use_attitude: true,
        }
    }

    /// touchdown's: the camera board's [`FramePipeline`] as it ships
    /// ([`PipelineConfig::default`]).
    pub fn ours() -> Self {
        Method::board("ours", PipelineConfig::default())
    }

    /// The board's pipeline with another configuration (a variant column).
    pub fn board(name: &str, config: PipelineConfig) -> Self {
        Method {
            name: name.into(),
            kind: MethodKind::Board(config),
            use_attitude: true,
        }
    }

    /// The same path with a different name, for a variant column.
    pub fn named(mut self, name: &str) -> Self {
        self.name = name.into();
        self
    }

    /// The same path without the attitude (vision only).
    pub fn without_attitude(mut self) -> Self {
        self.use_attitude = false;
        self
    }
}

/// What one method made of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MethodOutcome {
    /// The pose was computed (the pad was detected and the solver succeeded).
    pub pose_found: bool,
    /// This frame's camera position in the pad frame, unfiltered, metres.
    pub raw: Option<Vector3<f64>>,
    /// The filter's output for this frame, metres.
    pub estimate: Option<Vector3<f64>>,
}

/// Running sums for one axis.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AxisStats {
    count: usize,
    sum_truth: f64,
    sum_estimate: f64,
    sum_error: f64,
    sum_abs_error: f64,
    sum_squared_error: f64,
}

impl AxisStats {
    /// Adds one frame.
    pub fn add(&mut self, truth: f64, estimate: f64) {
        let error = truth - estimate;
        self.count += 1;
        self.sum_truth += truth;
        self.sum_estimate += estimate;
        self.sum_error += error;
        self.sum_abs_error += error.abs();
        self.sum_squared_error += error * error;
    }

    /// Frames added.
    pub fn count(&self) -> usize {
        self.count
    }

    fn mean(&self, sum: f64) -> Option<f64> {
        (self.count > 0).then(|| sum / self.count as f64)
    }

    /// Mean true value, metres.
    pub fn mean_truth(&self) -> Option<f64> {
        self.mean(self.sum_truth)
    }

    /// Mean estimate, metres.
    pub fn mean_estimate(&self) -> Option<f64> {
        self.mean(self.sum_estimate)
    }

    /// Mean of truth - estimate, metres.
    pub fn mean_error(&self) -> Option<f64> {
        self.mean(self.sum_error)
    }

    /// Mean of |truth - estimate|, metres.
    pub fn mean_abs_error(&self) -> Option<f64> {
        self.mean(self.sum_abs_error)
    }

    /// Root mean square of truth - estimate, metres.
    pub fn rms_error(&self) -> Option<f64> {
        self.mean(self.sum_squared_error).map(f64::sqrt)
    }
}

/// One method's statistics at one set point.
#[derive(Debug, Clone, PartialEq)]
pub struct SetPointResult {
    /// The set point.
    pub set_point: SetPoint,
    /// Scored frames.
    pub frames: usize,
    /// Scored frames where the pose was computed.
    pub detected: usize,
    /// Filtered estimates, per axis x, y, z.
    pub filtered: [AxisStats; 3],
    /// Unfiltered per-frame positions, per axis x, y, z.
    pub raw: [AxisStats; 3],
}

impl SetPointResult {
    fn new(set_point: SetPoint) -> Self {
        SetPointResult {
            set_point,
            frames: 0,
            detected: 0,
            filtered: [AxisStats::default(); 3],
            raw: [AxisStats::default(); 3],
        }
    }

    fn add(&mut self, truth: &Vector3<f64>, outcome: &MethodOutcome) {
        self.frames += 1;
        self.detected += usize::from(outcome.pose_found);
        for (stats, value) in [
            (&mut self.raw, outcome.raw),
            (&mut self.filtered, outcome.estimate),
        ] {
            if let Some(v) = value {
                for (k, s) in stats.iter_mut().enumerate() {
                    s.add(truth[k], v[k]);
                }
            }
        }
    }

    /// Fraction of scored frames with a pose (0 when there were none).
    pub fn detection_rate(&self) -> f64 {
        self.detected as f64 / self.frames.max(1) as f64
    }

    /// Fraction of scored frames with a filtered estimate.
    pub fn estimate_rate(&self) -> f64 {
        self.filtered[0].count() as f64 / self.frames.max(1) as f64
    }

    /// The filtered statistics of the row's own axis.
    pub fn on_axis(&self) -> &AxisStats {
        &self.filtered[self.set_point.axis.index()]
    }

    /// The unfiltered statistics of the row's own axis.
    pub fn raw_on_axis(&self) -> &AxisStats {
        &self.raw[self.set_point.axis.index()]
    }
}

/// One row of the paper's Tables 2-4, centimetres as published.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PublishedRow {
    /// The table's axis.
    pub axis: Axis,
    /// Reference, cm.
    pub reference_cm: f64,
    /// The paper's mean estimate, cm.
    pub estimate_cm: f64,
    /// The paper's mean error, cm (its sign: reference - estimate, give or take rounding).
    pub error_cm: f64,
}

const fn row(axis: Axis, reference_cm: f64, estimate_cm: f64, error_cm: f64) -> PublishedRow {
    PublishedRow {
        axis,
        reference_cm,
        estimate_cm,
        error_cm,
    }
}

/// The paper's Tables 2 (Z), 3 (Y, at 15 m altitude) and 4 (X, at 15 m altitude).
pub const PAPER_TABLES: [PublishedRow; 15] = [
    row(Axis::Z, 500.0, 502.0, -2.1),
    row(Axis::Z, 1000.0, 1003.0, -2.6),
    row(Axis::Z, 1500.0, 1505.0, -4.8),
    row(Axis::Z, 2000.0, 1995.0, 5.1),
    row(Axis::Z, 2500.0, 2483.0, 16.6),
    row(Axis::Y, 120.0, 122.0, -2.8),
    row(Axis::Y, 240.0, 234.0, 6.0),
    row(Axis::Y, 360.0, 350.0, 9.7),
    row(Axis::Y, 480.0, 462.0, 18.0),
    row(Axis::Y, 600.0, 575.0, 25.0),
    row(Axis::X, 120.0, 117.0, 3.1),
    row(Axis::X, 240.0, 245.0, -5.0),
    row(Axis::X, 360.0, 371.0, -11.0),
    row(Axis::X, 480.0, 496.0, -18.2),
    row(Axis::X, 600.0, 626.0, -26.0),
];

/// The published row for `axis` at `reference_m`, if the paper has one.
pub fn published(axis: Axis, reference_m: f64) -> Option<&'static PublishedRow> {
    PAPER_TABLES
        .iter()
        .find(|r| r.axis == axis && (r.reference_cm - 100.0 * reference_m).abs() < 0.5)
}

/// `R_ned_from_pad`: the pad frame (x right, y up on the print, z up) in NED axes, the
/// simulator's convention (pad +x east, +y north; [`flight::NED_FROM_PAD`]), so that a
/// recording's vehicle attitude and the simulated autopilot agree with it.
const NED_FROM_PAD: Matrix3<f32> = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0);

/// A method's path with its state.
#[derive(Debug)]
// Both paths boxed: each holds a detector with its contour buffer (tens of KiB).
enum Runner<'a> {
    Paper {
        paper: Box<PaperPipeline<'a>>,
        /// In flight: the companion (for the attitude it received) and the autopilot.
        flight: Option<Box<FlightRun>>,
    },
    Board {
        pipeline: Box<FramePipeline<'a>>,
        /// The attitude stream the autopilot would send, as the companion keeps it.
        vehicle: Box<VehicleState>,
        /// In flight: the companion and the simulated autopilot, which then replace
        /// `vehicle`.
        flight: Option<Box<FlightRun>>,
    },
}

/// A method with its path.
#[derive(Debug)]
struct Pipeline<'a> {
    method: Method,
    runner: Runner<'a>,
    /// The board path's metering of the last frame, for an exposure loop closed around it.
    metering: Option<Metering>,
}

impl<'a> Pipeline<'a> {
    fn new(
        method: &Method,
        camera: CameraModel,
        families: &'a [&'a Family<'a>],
        layout: &PadLayout<'a>,
        flight: Option<&FlightSetup>,
    ) -> Result<Self, ExperimentError> {
        let flight_run = || -> Result<Option<Box<FlightRun>>, ExperimentError> {
            flight
                .map(|s| FlightRun::new(s).map(Box::new))
                .transpose()
                .map_err(|_| ExperimentError::BadFlightSetup)
        };
        let runner = match method.kind {
            MethodKind::Paper(filter) => Runner::Paper {
                paper: Box::new(PaperPipeline::new(families, layout, camera, filter)),
                flight: flight_run()?,
            },
            MethodKind::Board(config) => Runner::Board {
                pipeline: Box::new(
                    FramePipeline::new(
                        families,
                        layout,
                        camera,
                        config,
                        PipelineSettings::default(),
                    )
                    .map_err(|_| ExperimentError::BadTrackerConfig)?,
                ),
                vehicle: Box::new(VehicleState::new()),
                flight: flight_run()?,
            },
        };
        Ok(Pipeline {
            method: method.clone(),
            runner,
            metering: None,
        })
    }

    fn reset(&mut self) {
        match &mut self.runner {
            Runner::Paper { paper, .. } => paper.reset(),
            Runner::Board {
                pipeline, vehicle, ..
            } => {
                pipeline.reset();
                vehicle.clear();
            }
        }
    }

    /// Runs the path on `frame`; in flight (the method has a [`FlightRun`]) with the truth
    /// between frames from `truth`, and then also returns the three errors.
    fn process(
        &mut self,
        frame: &Frame<'_>,
        workspace: &mut HostWorkspace,
        truth: Option<&dyn TruthSource>,
    ) -> Result<(MethodOutcome, Option<FlightOutcome>), ExperimentError> {
        let mut buffers = workspace.buffers(frame.image.width(), frame.image.height());
        let use_attitude = self.method.use_attitude;
        let attitude = frame.attitude.filter(|_| use_attitude);
        match &mut self.runner {
            Runner::Paper {
                paper,
                flight: Some(flight),
            } => {
                let truth = truth.ok_or(ExperimentError::NoTruthSource)?;
                let exposure = flight.clock().board_us(frame.t_us);
                let delivery = flight.delivery_us(exposure);
                flight.advance_to(delivery, truth);
                let vehicle = flight.companion.vehicle().at(exposure);
                // The attitude it is given is the one the board received, with the mount it
                // believes.
                let given = vehicle
                    .attitude
                    .filter(|_| use_attitude)
                    .map(|a| NED_FROM_PAD * a.matrix() * flight_paper_mount(flight).matrix());
                let report = paper.process(&frame.image, exposure, given.as_ref(), &mut buffers);
                if let Some(e) = report.detect_error {
                    return Err(ExperimentError::Detect(e));
                }
                // Its estimate as a body vector, turned with the attitude it was given.
                let body = report.estimate.zip(vehicle.attitude).map(|(c, a)| {
                    a.matrix().cast::<f64>().transpose() * flight::relative_ned(&c.cast::<f64>())
                });
                let mut outcome = FlightOutcome::default();
                if let Some(body) = body {
                    let receipt = flight.arrival_us(delivery);
                    outcome.sent = flight.sent(&body, exposure, &frame.truth, truth);
                    outcome.reconstructed =
                        flight.reconstruct(&body, exposure, receipt, &vehicle, truth);
                    outcome.ideal =
                        flight.reconstruct_ideal(exposure, receipt, &vehicle, &frame.truth, truth);
                    outcome.latency_us = Some(receipt - exposure);
                }
                // Keep the link running while the next frame is processed.
                flight.advance_to(delivery + flight::SETTLE_US, truth);
                Ok((
                    MethodOutcome {
                        pose_found: report.raw.is_some(),
                        raw: report.raw.map(|r| r.cast::<f64>()),
                        estimate: outcome.sent.map(|s| s.value),
                    },
                    Some(outcome),
                ))
            }
            Runner::Paper {
                paper,
                flight: None,
            } => {
                let report =
                    paper.process(&frame.image, frame.t_us, attitude.as_ref(), &mut buffers);
                if let Some(e) = report.detect_error {
                    return Err(ExperimentError::Detect(e));
                }
                Ok((
                    MethodOutcome {
                        pose_found: report.raw.is_some(),
                        raw: report.raw.map(|r| r.cast::<f64>()),
                        estimate: report.estimate.map(|e| e.cast::<f64>()),
                    },
                    None,
                ))
            }
            Runner::Board {
                pipeline,
                flight: Some(flight),
                ..
            } => {
                let truth = truth.ok_or(ExperimentError::NoTruthSource)?;
                let exposure = flight.clock().board_us(frame.t_us);
                let delivery = flight.delivery_us(exposure);
                flight.advance_to(delivery, truth);
                let report = pipeline.process(
                    &frame.image,
                    exposure,
                    flight.companion.vehicle(),
                    &mut buffers,
                );
                if let Some(e) = report.detect_error {
                    return Err(ExperimentError::Detect(e));
                }
                self.metering = Some(report.metering);
                let vehicle = flight.companion.vehicle().at(exposure);
                let _ = flight.take_targets();
                let queued = flight.companion.on_estimate(&report.estimate, delivery)
                    == touchdown_core::companion::TargetOutcome::TargetQueued;
                // The companion may have adopted a mount correction (TD_CAM_ROLL/PITCH): the
                // pipeline takes the new settings before the next frame, as the firmware's
                // vision task does.
                let _ = pipeline.follow_params(flight.companion.params());
                flight.advance_to(delivery + flight::SETTLE_US, truth);
                let received = flight.take_targets().pop();
                let mut outcome = FlightOutcome {
                    pad_moving: flight.companion.pad_moving(),
                    ..FlightOutcome::default()
                };
                let estimate_body = report
                    .estimate
                    .estimate
                    .map(|e| e.body_frd.cast::<f64>())
                    .filter(|_| queued);
                let decoded = received.as_ref().and_then(|r| {
                    let d = &r.data;
                    (d.frame
                        == touchdown_core::companion::mavlink::dialects::common::MavFrame::MAV_FRAME_BODY_FRD)
                        .then(|| Vector3::new(d.x, d.y, d.z).cast::<f64>())
                });
                if let Some(body) = decoded.or(estimate_body) {
                    outcome.sent = flight.sent(&body, exposure, &frame.truth, truth);
                }
                if let Some(r) = &received {
                    outcome.reconstructed = flight.reconstruct_received(r, exposure, truth);
                    outcome.ideal = flight.reconstruct_ideal(
                        exposure,
                        r.receipt_us,
                        &vehicle,
                        &frame.truth,
                        truth,
                    );
                    outcome.latency_us = Some(r.receipt_us.saturating_sub(exposure));
                }
                Ok((
                    MethodOutcome {
                        pose_found: report.fix.is_some(),
                        raw: report.fix.map(|f| f.camera_position().cast::<f64>()),
                        estimate: outcome.sent.map(|s| s.value),
                    },
                    Some(outcome),
                ))
            }
            Runner::Board {
                pipeline,
                vehicle,
                flight: None,
            } => {
                // The mount in force, the one the estimator turns body FRD with.
                let mount = *pipeline.estimator().mount();
                if let Some(r) = &attitude {
                    // What the autopilot streams: its attitude (body FRD to NED) at the
                    // exposure, from the camera's rotation into the pad frame and the mount.
                    let ned_from_body = NED_FROM_PAD * r * mount.matrix().transpose();
                    let q = UnitQuaternion::from_rotation_matrix(
                        &Rotation3::from_matrix_unchecked(ned_from_body),
                    );
                    if let Ok(att) = Attitude::from_quaternion_wxyz([q.w, q.i, q.j, q.k]) {
                        vehicle.push_attitude(frame.t_us, &att, frame.t_us);
                    }
                }
                let report = pipeline.process(&frame.image, frame.t_us, vehicle, &mut buffers);
                if let Some(e) = report.detect_error {
                    return Err(ExperimentError::Detect(e));
                }
                self.metering = Some(report.metering);
                // What the autopilot makes of the LANDING_TARGET: body FRD turned with its own
                // attitude (the true one); without one, with this frame's pose rotation.
                let camera_to_pad = frame
                    .attitude
                    .or_else(|| report.fix.map(|f| f.pose.rotation.transpose()));
                let estimate = report
                    .estimate
                    .estimate
                    .zip(camera_to_pad)
                    .map(|(e, r)| (-(r * mount.body_to_camera(&e.body_frd))).cast::<f64>());
                Ok((
                    MethodOutcome {
                        pose_found: report.fix.is_some(),
                        raw: report.fix.map(|f| f.camera_position().cast::<f64>()),
                        estimate,
                    },
                    None,
                ))
            }
        }
    }
}

/// The mount the paper's method believes in flight.
fn flight_paper_mount(flight: &FlightRun) -> touchdown_core::filter::CameraMount {
    flight.paper_mount()
}

/// Why an experiment could not be set up or run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExperimentError {
    /// A method's tracker configuration does not validate.
    BadTrackerConfig,
    /// A family or pad the experiment needs is not available.
    MissingFamily,
    /// The detector refused a frame.
    Detect(DetectError),
    /// A flight's setup is refused (a parameter unknown or out of range).
    BadFlightSetup,
    /// A method in flight was given a frame without a truth source.
    NoTruthSource,
}

/// Methods run side by side on the same frames, with per-set-point statistics.
#[derive(Debug)]
pub struct Experiment<'a> {
    pipelines: Vec<Pipeline<'a>>,
    workspace: HostWorkspace,
    /// The set points seen, in order of first appearance.
    set_points: Vec<SetPoint>,
    /// Per set point (same order), one result per method.
    results: Vec<Vec<SetPointResult>>,
    /// In flight, the last frame's three errors per method.
    flight: Vec<FlightOutcome>,
}

impl<'a> Experiment<'a> {
    /// An experiment on frames from `camera` of the pad `layout`, searching `families`; the
    /// methods are given each frame's attitude directly (no autopilot, no errors).
    pub fn new(
        camera: CameraModel,
        families: &'a [&'a Family<'a>],
        layout: PadLayout<'a>,
        methods: &[Method],
    ) -> Result<Self, ExperimentError> {
        Self::build(camera, families, layout, methods, None)
    }

    /// The same in flight ([`flight`]): every method runs with the board's companion against
    /// a simulated autopilot of `setup` (each method its own, with the same errors), and
    /// [`Experiment::process_with`] scores what the autopilot reconstructs.
    pub fn in_flight(
        camera: CameraModel,
        families: &'a [&'a Family<'a>],
        layout: PadLayout<'a>,
        methods: &[Method],
        setup: &FlightSetup,
    ) -> Result<Self, ExperimentError> {
        Self::build(camera, families, layout, methods, Some(setup))
    }

    fn build(
        camera: CameraModel,
        families: &'a [&'a Family<'a>],
        layout: PadLayout<'a>,
        methods: &[Method],
        setup: Option<&FlightSetup>,
    ) -> Result<Self, ExperimentError> {
        Ok(Experiment {
            pipelines: methods
                .iter()
                .map(|m| Pipeline::new(m, camera, families, &layout, setup))
                .collect::<Result<_, _>>()?,
            workspace: HostWorkspace::new(),
            set_points: Vec::new(),
            results: Vec::new(),
            flight: Vec::new(),
        })
    }

    /// What method `method`'s board path metered in the last frame processed (what the
    /// board's exposure loop is fed); `None` for the paper's method or before any frame.
    pub fn metering(&self, method: usize) -> Option<Metering> {
        self.pipelines.get(method)?.metering
    }

    /// The three errors of the last frame processed, per method (empty unless in flight).
    pub fn flight_outcomes(&self) -> &[FlightOutcome] {
        &self.flight
    }

    /// Method `method`'s flight: its companion (the board's parameters as it left them, e.g.
    /// the mount it calibrated) and the simulated autopilot. `None` unless in flight.
    pub fn flight_run(&self, method: usize) -> Option<&FlightRun> {
        match &self.pipelines.get(method)?.runner {
            Runner::Paper { flight, .. } | Runner::Board { flight, .. } => flight.as_deref(),
        }
    }

    /// Resets every method's filter: the next frame starts a new, independent sequence.
    pub fn start_sequence(&mut self) -> Result<(), ExperimentError> {
        self.pipelines.iter_mut().for_each(Pipeline::reset);
        Ok(())
    }

    /// Runs every method on `frame` and scores it if it carries a set point; returns what each
    /// method made of it, in method order.
    pub fn process(&mut self, frame: &Frame<'_>) -> Result<Vec<MethodOutcome>, ExperimentError> {
        self.process_with(frame, None)
    }

    /// [`Experiment::process`] with the truth between frames from `truth`, which an
    /// experiment in flight needs; the three errors are then in
    /// [`Experiment::flight_outcomes`].
    pub fn process_with(
        &mut self,
        frame: &Frame<'_>,
        truth: Option<&dyn TruthSource>,
    ) -> Result<Vec<MethodOutcome>, ExperimentError> {
        let mut outcomes = Vec::with_capacity(self.pipelines.len());
        self.flight.clear();
        for pipeline in &mut self.pipelines {
            let (outcome, flight) = pipeline.process(frame, &mut self.workspace, truth)?;
            outcomes.push(outcome);
            if let Some(f) = flight {
                self.flight.push(f);
            }
        }
        if let Some(set_point) = frame.set_point {
            let index = match self
                .set_points
                .iter()
                .position(|s| s.label == set_point.label)
            {
                Some(k) => k,
                None => {
                    self.set_points.push(set_point.clone());
                    self.results.push(
                        (0..self.pipelines.len())
                            .map(|_| SetPointResult::new(set_point.clone()))
                            .collect(),
                    );
                    self.results.len() - 1
                }
            };
            for (result, outcome) in self.results[index].iter_mut().zip(&outcomes) {
                result.add(&frame.truth, outcome);
            }
        }
        Ok(outcomes)
    }

    /// The statistics so far.
    pub fn report(&self) -> Report {
        Report {
            methods: self
                .pipelines
                .iter()
                .map(|p| p.method.name.clone())
                .collect(),
            rows: self.results.clone(),
        }
    }
}

/// Which statistics a table shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// The filters' outputs (what the paper averages).
    Filtered,
    /// The per-frame positions before filtering.
    Raw,
}

/// Results of an [`Experiment`]: per set point, one [`SetPointResult`] per method.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Method names, in column order.
    pub methods: Vec<String>,
    /// Per set point (order of first appearance), one result per method.
    pub rows: Vec<Vec<SetPointResult>>,
}

impl Report {
    /// The result of method `method` (index) at the set point labelled `label`.
    pub fn result(&self, method: usize, label: &str) -> Option<&SetPointResult> {
        self.rows
            .iter()
            .find(|r| r.first().is_some_and(|s| s.set_point.label == label))?
            .get(method)
    }

    /// A paper-style table, centimetres: the row's axis and reference, the paper's published
    /// estimate and error (where it has the row), then per method the mean estimate, mean
    /// error (truth - estimate), mean |error| and detection rate on the row's axis.
    pub fn table(&self, stage: Stage) -> String {
        let cm = |v: Option<f64>, width: usize, decimals: usize| match v {
            Some(v) => format!("{:>width$.decimals$}", 100.0 * v),
            None => format!("{:>width$}", "-"),
        };
        let mut out = String::new();
        let _ = write!(out, "{:<4}{:>6} | {:>16} ", "", "ref", "paper (published)");
        for name in &self.methods {
            let _ = write!(out, "| {:^34} ", name);
        }
        out.push('\n');
        let _ = write!(out, "{:<4}{:>6} | {:>7} {:>8} ", "axis", "cm", "est", "err");
        for _ in &self.methods {
            let _ = write!(
                out,
                "| {:>7} {:>7} {:>7} {:>9} ",
                "est", "err", "|err|", "detected"
            );
        }
        out.push('\n');
        for results in &self.rows {
            let Some(first) = results.first() else {
                continue;
            };
            let sp = &first.set_point;
            let _ = write!(
                out,
                "{:<4}{:>6.0} | ",
                sp.axis.name(),
                100.0 * sp.reference_m
            );
            match published(sp.axis, sp.reference_m) {
                Some(p) => {
                    let _ = write!(out, "{:>7.0} {:>8.1} ", p.estimate_cm, p.error_cm);
                }
                None => {
                    let _ = write!(out, "{:>7} {:>8} ", "-", "-");
                }
            }
            for r in results {
                let stats = match stage {
                    Stage::Filtered => r.on_axis(),
                    Stage::Raw => r.raw_on_axis(),
                };
                let _ = write!(
                    out,
                    "| {} {} {} {:>8.0}% ",
                    cm(stats.mean_estimate(), 7, 1),
                    cm(stats.mean_error(), 7, 2),
                    cm(stats.mean_abs_error(), 7, 2),
                    100.0 * r.detection_rate()
                );
            }
            out.push('\n');
        }
        out
    }
}
