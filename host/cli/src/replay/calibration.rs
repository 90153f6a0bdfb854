//! `--calibration-hover`: the flight a user makes before the one replayed.
//!
//! The set-up guides (docs/setup-ardupilot.md, docs/setup-px4.md, "Camera mount calibration")
//! ask for a still hover of 20 s at 2-5 m over the pad with TD_CAM_CAL at 2: the board
//! estimates the mount's roll and pitch from the level pad against the autopilot's attitude,
//! sets TD_CAM_ROLL and TD_CAM_PITCH once confident and saves them in flash; every later
//! flight starts with them. Within one landing the estimate becomes confident only near the
//! ground (too few frames with a sharp tilt above a few metres), so a landing is flown
//! calibrated only after such a hover.
//!
//! This module flies that hover (scenario `hover` over the replayed scenario's pad and
//! camera, the same flight effects and error model, the next seed: another flight, with its
//! own attitude bias) through the board's own path and companion, and hands on the
//! parameters the board left: nothing is taken from the truth.

use std::fmt::Write as _;
use std::io::{IsTerminal, Write};
use std::time::Instant;

use touchdown_core::family::Family;
use touchdown_core::params::ParamId;
use touchdown_eval::flight::FlightSetup;
use touchdown_eval::{Experiment, Method};
use touchdown_formats::families::{self, SelectedFamily};

use super::args::flight_effects;
use super::input::Input;
use super::{experiment_error, fly, CliError, Progress, ReplayArgs};

/// What the calibration hover left on the board.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct HoverCalibration {
    /// Frames flown.
    pub frames: usize,
    /// Frames with a pad fix.
    pub fixes: usize,
    /// TD_CAM_ROLL and TD_CAM_PITCH at the end, degrees.
    pub roll_deg: f32,
    pub pitch_deg: f32,
    /// Whether the board set them (a mount correction was applied).
    pub applied: bool,
    /// The true misalignment, degrees (roll, pitch), for the report.
    pub true_deg: Option<(f64, f64)>,
}

impl HoverCalibration {
    /// The parameters the next flight starts with: the ones the board saved (none when it set
    /// nothing: the landing then starts as an uncalibrated board would).
    pub fn params(&self) -> Vec<(String, f32)> {
        if !self.applied {
            return Vec::new();
        }
        vec![
            (ParamId::CamRoll.def().name.to_string(), self.roll_deg),
            (ParamId::CamPitch.def().name.to_string(), self.pitch_deg),
        ]
    }

    /// One line for the replay's flight header.
    pub fn describe(&self) -> String {
        let mut s = format!(
            "Calibration hover first (scenario hover, {} frames, {} with a fix): ",
            self.frames, self.fixes
        );
        if self.applied {
            let _ = write!(
                s,
                "the board set TD_CAM_ROLL {:+.2}, TD_CAM_PITCH {:+.2} deg",
                self.roll_deg, self.pitch_deg
            );
        } else {
            s.push_str("the board set no mount (not confident): this flight starts uncalibrated");
        }
        if let Some((r, p)) = self.true_deg {
            let _ = write!(s, " (true {r:+.2}, {p:+.2})");
        }
        s.push_str(".\n");
        s
    }
}

/// Flies the calibration hover for scenario `main` under `setup` (its seed + 1).
pub(super) fn calibration_hover(
    args: &ReplayArgs,
    main: &str,
    setup: &FlightSetup,
    err: &mut dyn Write,
) -> Result<HoverCalibration, CliError> {
    let effects = flight_effects(args);
    let input = Input::calibration_hover(main, args, &effects)?;
    let layout = input
        .pad
        .layout()
        .map_err(|e| CliError(format!("pad `{}`: invalid layout: {e:?}", input.pad.name)))?;
    let selected = families::resolve_pad(&input.pad).map_err(CliError::new)?;
    let views: Vec<Family<'_>> = selected.iter().map(SelectedFamily::family).collect();
    let family_refs: Vec<&Family<'_>> = views.iter().collect();
    let mut hover_setup = setup.clone();
    hover_setup.seed = setup.seed.wrapping_add(1);
    let methods = [Method::ours()];
    let mut experiment =
        Experiment::in_flight(input.camera, &family_refs, layout, &methods, &hover_setup)
            .map_err(|e| CliError(format!("cannot set up the calibration hover: {e:?}")))?;
    let mut progress = Progress {
        err,
        enabled: std::io::stderr().is_terminal(),
        name: "calibration hover".into(),
        total: input.frames,
        started: Instant::now(),
    };
    let (trace, _) = fly(&input, &mut experiment, &methods, true, None, &mut progress)?;
    let run = experiment
        .flight_run(0)
        .ok_or_else(|| experiment_error(touchdown_eval::ExperimentError::BadFlightSetup))?;
    let params = run.companion.params();
    Ok(HoverCalibration {
        frames: trace.frames.len(),
        fixes: trace
            .frames
            .iter()
            .filter(|f| f.outcomes.first().is_some_and(|o| o.pose_found))
            .count(),
        roll_deg: params.get(ParamId::CamRoll),
        pitch_deg: params.get(ParamId::CamPitch),
        applied: run.companion.stats().mount_corrections_applied > 0,
        true_deg: input.effects.map(|e| (e.mount_roll_deg, e.mount_pitch_deg)),
    })
}
