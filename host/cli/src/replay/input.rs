//! Where a replay's frames come from: a recording read from disk or a scenario rendered in
//! memory, behind one [`Input`], and the set points and attitudes derived from their truth.

use super::ReplayArgs;
use crate::CliError;
use nalgebra::{Matrix3, Vector3};
use std::path::Path;
use touchdown_core::camera::CameraModel;
use touchdown_eval::flight::{TrueState, TruthSource, TruthTable, NED_FROM_PAD};
use touchdown_eval::{Axis, SetPoint};
use touchdown_formats::image_io::GrayFrame;
use touchdown_formats::pad::PadConfig;
use touchdown_formats::recording::{CameraTruth, RecordingReader};
use touchdown_sim::effects::FlightEffects;
use touchdown_sim::scenario::{Scenario, SCENARIOS};
use touchdown_sim::sensor::ManualExposure;
use touchdown_sim::{math, Simulator};

/// One frame from either input.
pub(super) struct InputFrame {
    pub(super) index: usize,
    pub(super) t_us: u64,
    pub(super) truth: Option<CameraTruth>,
    pub(super) label: Option<String>,
    pub(super) image: GrayFrame,
}

/// Where frames come from.
pub(super) enum Source {
    Simulator(Box<Simulator>),
    Recording(RecordingReader),
}

/// The input of a replay: its description, camera, pad and frames.
pub(super) struct Input {
    /// For the header and the figures' titles.
    pub(super) title: String,
    /// For the default figure directory.
    pub(super) short_name: String,
    pub(super) camera: CameraModel,
    pub(super) pad: PadConfig,
    pub(super) has_truth: bool,
    pub(super) frames: usize,
    /// Every label, in order of first appearance.
    pub(super) labels: Vec<String>,
    /// The flight effects rendered (a scenario only).
    pub(super) effects: Option<FlightEffects>,
    /// The true camera mount, camera to body FRD (a scenario only).
    pub(super) true_mount: Option<Matrix3<f32>>,
    /// The scenario asks for the board's exposure loop by default
    /// ([`Scenario::board_exposure`]; false for a recording).
    pub(super) board_exposure: bool,
    /// A recording's truth between frames.
    truth_table: Option<TruthTable>,
    pub(super) source: Source,
}

/// The simulator's truth between frames: the vehicle's path and attitude (without the
/// camera's vibration).
struct SimulatorTruth<'a>(&'a Simulator);

impl TruthSource for SimulatorTruth<'_> {
    fn at(&self, t_s: f64) -> Option<TrueState> {
        let state = self.0.vehicle_state(t_s.max(0.0));
        let a = state.attitude;
        Some(TrueState {
            position: Vector3::from(state.position),
            body_to_ned: Matrix3::from_fn(|i, j| a[i][j]),
        })
    }

    fn pad_origin(&self, t_s: f64) -> Vector3<f64> {
        let o = self.0.scenario.pad_motion.pose(t_s.max(0.0)).origin_ned;
        NED_FROM_PAD.transpose() * Vector3::new(o[0], o[1], o[2])
    }
}

impl Input {
    pub(super) fn open(args: &ReplayArgs) -> Result<Input, CliError> {
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
            (None, Some(name)) => Self::scenario(name, args, &super::flight_effects(args)),
            (Some(dir), None) => {
                if args.seed.is_some()
                    || args.threads.is_some()
                    || args.renderer.is_some()
                    || args.lens.any()
                {
                    return Err(CliError(
                        "--seed, --threads, --renderer, --psf and --response apply to --scenario only"
                            .into(),
                    ));
                }
                if args.pad_motion.any_given() {
                    return Err(CliError(
                        "--pad-velocity, --pad-turn-rate, --deck-heave and --deck-roll apply to \
                         --scenario only (a recording's pad moved as it was recorded)"
                            .into(),
                    ));
                }
                if super::effect_flag_given(args) {
                    return Err(CliError(
                        "--readout-ms, --vibration-deg, --mount-roll-deg, --mount-pitch-deg and \
                         --mount-known apply to --scenario only (a recording has its effects)"
                            .into(),
                    ));
                }
                Self::recording(dir, args.frames)
            }
        }
    }

    pub(super) fn scenario(
        name: &str,
        args: &ReplayArgs,
        effects: &FlightEffects,
    ) -> Result<Input, CliError> {
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
        Self::rendered(scenario, args, effects)
    }

    /// The set-up guide's mount-calibration hover (scenario `hover`) over scenario `main`'s
    /// pad, seen by its camera, with the same flight effects: the flight a user makes before
    /// the one replayed (`--calibration-hover`). Its seed is the next one: another flight,
    /// with its own wobble, noise and attitude errors.
    pub(super) fn calibration_hover(
        main: &str,
        args: &ReplayArgs,
        effects: &FlightEffects,
    ) -> Result<Input, CliError> {
        let seed = args.seed.unwrap_or(1).wrapping_add(1);
        let (Some(main), Some(mut hover)) =
            (Scenario::named(main, seed), Scenario::named("hover", seed))
        else {
            return Err(CliError(format!("unknown scenario `{main}`")));
        };
        hover.pad = main.pad;
        hover.camera = main.camera;
        hover.optics = main.optics;
        hover.sensor = main.sensor;
        Self::rendered(hover, args, effects)
    }

    /// `scenario` rendered in memory with `effects`.
    fn rendered(
        mut scenario: Scenario,
        args: &ReplayArgs,
        effects: &FlightEffects,
    ) -> Result<Input, CliError> {
        let (name, seed) = (scenario.name.clone(), scenario.seed);
        // Over a moving pad the scenario's flight is flown against the pad, carried along.
        scenario.pad_motion = args.pad_motion.motion(0.0)?;
        scenario.flight_follows_pad = true;
        scenario.apply_effects(effects);
        let mount = scenario.mount.rotation;
        let labels = distinct(scenario.frames.iter().map(|f| f.label.as_deref()));
        let mut simulator = Simulator::new(scenario);
        if let Some(threads) = args.threads {
            simulator = simulator.with_threads(threads);
        }
        let simulator =
            crate::renderer::configure(simulator, args.renderer.unwrap_or_default(), &args.lens)?;
        Ok(Input {
            title: format!("scenario {name}, seed {seed}"),
            short_name: name.to_string(),
            camera: simulator.scenario.camera.model,
            pad: simulator.scenario.pad.config.clone(),
            has_truth: true,
            frames: simulator.frame_count(),
            labels,
            effects: Some(*effects),
            true_mount: Some(Matrix3::from_fn(|i, j| mount[i][j] as f32)),
            board_exposure: simulator.scenario.board_exposure,
            truth_table: None,
            source: Source::Simulator(Box::new(simulator)),
        })
    }

    pub(super) fn recording(dir: &Path, frames: Option<usize>) -> Result<Input, CliError> {
        let reader = RecordingReader::open(dir).map_err(CliError::new)?;
        let count = frames.map_or(reader.len(), |n| n.min(reader.len()));
        if count == 0 {
            return Err(CliError(format!(
                "{}: the recording has no frames",
                dir.join("frames.csv").display()
            )));
        }
        let labels = distinct(reader.labels.iter().take(count).map(Option::as_deref));
        // The truth between frames, interpolated; the vehicle's attitude from the veh_
        // columns, else from the camera's through the nominal mount.
        let nominal = touchdown_core::filter::CameraMount::downward()
            .matrix()
            .cast::<f64>();
        let mut table = TruthTable::new();
        for e in &reader.entries {
            if let Some(t) = &e.truth {
                let m = math::quat_to_matrix(t.orientation);
                let camera_to_pad = Matrix3::from_fn(|i, j| m[i][j]);
                let body_to_ned = match e.vehicle_attitude {
                    Some(q) => {
                        let v = math::quat_to_matrix(q);
                        Matrix3::from_fn(|i, j| v[i][j])
                    }
                    None => NED_FROM_PAD * camera_to_pad * nominal.transpose(),
                };
                table.push(
                    e.t_us as f64 * 1e-6,
                    TrueState {
                        position: Vector3::from(t.position),
                        body_to_ned,
                    },
                );
            }
        }
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
            effects: None,
            true_mount: None,
            board_exposure: false,
            truth_table: (!table.is_empty()).then_some(table),
            source: Source::Recording(reader),
        })
    }

    /// The truth between frames, for the simulated autopilot (`None`: no truth).
    pub(super) fn truth_source(&self) -> Option<Box<dyn TruthSource + '_>> {
        match &self.source {
            Source::Simulator(simulator) => Some(Box::new(SimulatorTruth(simulator))),
            Source::Recording(_) => self
                .truth_table
                .as_ref()
                .map(|t| Box::new(t.clone()) as Box<dyn TruthSource>),
        }
    }

    /// Frame `k`, a scenario's rendered with `exposure` when given (see the submodule
    /// `exposure`; a recording's frames are as recorded).
    pub(super) fn frame(
        &self,
        k: usize,
        exposure: Option<ManualExposure>,
    ) -> Result<InputFrame, CliError> {
        match &self.source {
            Source::Simulator(simulator) => {
                let frame = simulator
                    .render_exposed(k, exposure)
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
pub(super) fn distinct<'a>(labels: impl Iterator<Item = Option<&'a str>>) -> Vec<String> {
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
pub(super) fn attitude_of(truth: &CameraTruth) -> Matrix3<f32> {
    let m = math::quat_to_matrix(truth.orientation);
    Matrix3::from_fn(|i, j| m[i][j] as f32)
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
    fn distinct_keeps_first_appearance_order() {
        let labels = [Some("b"), None, Some("a"), Some("b")];
        assert_eq!(distinct(labels.into_iter()), ["b", "a"]);
    }
}
