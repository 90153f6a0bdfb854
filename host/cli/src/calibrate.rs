//! `touchdown calibrate`: the camera mount's roll and pitch (TD_CAM_ROLL, TD_CAM_PITCH) from
//! a recording of a hover over the pad.
//!
//! It runs the board's per-frame path (`touchdown_core::pipeline::FramePipeline`, the same
//! detector, pad fix and estimator) over the recording's frames with the vehicle's attitude at
//! each exposure (frames.csv's `veh_qw..veh_qz` columns), so the estimate is the one the
//! board's in-flight calibrator (`touchdown_core::filter::MountCalibrator`) makes from the
//! same frames, with the same refusals, the same uncertainty and the same confidence test. It
//! prints the estimate with its uncertainty and the parameters to set, or one JSON object
//! with `--json`.
//!
//! Errors (one line, exit status 2): an unreadable recording, a recording without the `veh_`
//! columns (the attitude is what the tilt is compared with), or too few good frames for a
//! confident estimate (the counts say which frames were refused and why).

use std::io::Write;
use std::path::PathBuf;

use clap::Args;
use serde::Serialize;
use touchdown_core::family::Family;
use touchdown_core::filter::{
    Attitude, EstimatorConfig, MountCalibrationConfig, MountCalibrationStats, MountEstimate,
    VehicleState,
};
use touchdown_core::params::{ParamId, ParamSet, PipelineSettings};
use touchdown_core::pipeline::{FramePipeline, PipelineConfig};

use super::{CliError, Outcome};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_formats::families::{self, SelectedFamily};
use touchdown_formats::recording::RecordingReader;

/// `--help`'s long text.
pub const LONG_HELP: &str = "\
Estimate the camera mount's roll and pitch (TD_CAM_ROLL, TD_CAM_PITCH) from a recording of a \
hover over the pad.

The pad lies level, so every close pad fix measures the camera's tilt against gravity; \
compared with the vehicle's attitude at the exposure (frames.csv's veh_qw,veh_qx,veh_qy,veh_qz: \
body FRD to NED, NED being north = pad +y, east = pad +x, down = pad -z) it measures the \
mount's misalignment. The frames run through the camera board's own per-frame path and mount \
calibrator (the one TD_CAM_CAL runs in flight): the same refusals (tilt sigma over 1 degree, \
the flip ambiguity of a marker seen head-on, a misalignment over 12 degrees, outliers beyond \
3 sigma), the same weighted mean and the same uncertainty: the scatter of the frames plus the \
autopilot attitude's slowly varying bias (--attitude-bias-deg, 0.25 degrees with a 20 s \
correlation time by default), which no hover of a few tens of seconds averages away. Yaw is \
not observable from a level pad: TD_CAM_YAW stays the user's.

Record a hover over the pad at 2-5 m for at least 20 s. The estimate needs 100 good frames \
over at least 10 s and a noise sigma of at most 0.1 degrees.

Output: the estimate, its uncertainty, the frame counts and the parameter lines to set \
(MAVProxy `param set` syntax); with --json one object: roll_deg, pitch_deg, roll_sigma_deg, \
pitch_sigma_deg, noise_sigma_deg, bias_sigma_deg, frames (accepted), span_s, \
frames_in_recording, frames_with_fix, refused (poor_tilt, tilt_not_measured, ambiguous, \
not_level, outliers), params (TD_CAM_ROLL, TD_CAM_PITCH).

Exit status: 0 with an estimate; 2 with one line on stderr for a bad option, an unreadable \
recording, a recording without the veh_ columns or without enough good frames.";

/// Arguments of `touchdown calibrate`.
#[derive(Debug, Clone, Args)]
pub struct CalibrateArgs {
    /// Recording directory (camera.toml, pad.toml, frames/, frames.csv with veh_ columns)
    #[arg(value_name = "RECORDING")]
    pub recording: PathBuf,

    /// Print one JSON object instead of text
    #[arg(long)]
    pub json: bool,

    /// TD_CAM_YAW the board is configured with, degrees (the mount is measured after it)
    #[arg(
        long,
        allow_negative_numbers = true,
        value_name = "DEG",
        default_value_t = 0.0
    )]
    pub cam_yaw_deg: f32,

    /// The autopilot attitude's slowly varying roll/pitch bias, one sigma, degrees (0: the
    /// attitude is exact, as a simulator's truth)
    #[arg(long, value_name = "DEG", default_value_t = MountCalibrationConfig::default().attitude_bias_deg)]
    pub attitude_bias_deg: f32,
}

/// `--json`'s refusal counts.
#[derive(Debug, Serialize)]
struct Refused {
    poor_tilt: u32,
    tilt_not_measured: u32,
    ambiguous: u32,
    not_level: u32,
    outliers: u32,
}

/// `--json`'s object (see [`LONG_HELP`]).
#[derive(Debug, Serialize)]
struct Report {
    roll_deg: f32,
    pitch_deg: f32,
    roll_sigma_deg: f32,
    pitch_sigma_deg: f32,
    noise_sigma_deg: f32,
    bias_sigma_deg: f32,
    frames: u32,
    span_s: f64,
    frames_in_recording: usize,
    frames_with_fix: usize,
    refused: Refused,
    params: serde_json::Map<String, serde_json::Value>,
}

/// Runs `touchdown calibrate`.
pub fn run(
    args: &CalibrateArgs,
    out: &mut dyn Write,
    _err: &mut dyn Write,
) -> Result<Outcome, CliError> {
    let name = args.recording.display().to_string();
    if !(args.cam_yaw_deg.is_finite() && args.cam_yaw_deg.abs() <= 180.0) {
        return Err(CliError::new("--cam-yaw-deg must be within -180..180"));
    }
    if !(args.attitude_bias_deg.is_finite() && args.attitude_bias_deg >= 0.0) {
        return Err(CliError::new("--attitude-bias-deg must be a number >= 0"));
    }
    let reader = RecordingReader::open(&args.recording).map_err(CliError::new)?;
    if !reader.has_vehicle_attitude {
        return Err(CliError(format!(
            "{name}: frames.csv has no vehicle attitude (veh_qw,veh_qx,veh_qy,veh_qz): the \
             mount is measured against it"
        )));
    }
    let layout = reader
        .pad
        .layout()
        .map_err(|e| CliError(format!("{name}: pad.toml: {e:?}")))?;
    let selected = families::resolve_pad(&reader.pad).map_err(CliError::new)?;
    let views: Vec<Family<'_>> = selected.iter().map(SelectedFamily::family).collect();
    let family_refs: Vec<&Family<'_>> = views.iter().collect();

    let calibration = MountCalibrationConfig {
        attitude_bias_deg: args.attitude_bias_deg,
        ..MountCalibrationConfig::default()
    };
    let config = PipelineConfig {
        estimator: EstimatorConfig {
            mount_calibration: calibration,
            ..EstimatorConfig::default()
        },
        ..PipelineConfig::default()
    };
    // The board's parameters, TD_CAM_YAW as configured, the mount's tilt at 0: the estimate
    // is then the tilt to set.
    let mut params = ParamSet::default();
    params
        .set(ParamId::CamYaw, args.cam_yaw_deg)
        .map_err(|e| CliError(format!("--cam-yaw-deg: {e:?}")))?;
    let settings = PipelineSettings::from_params(&params);
    let mut pipeline = FramePipeline::new(&family_refs, &layout, reader.camera, config, settings)
        .map_err(|e| CliError(format!("pipeline configuration: {e:?}")))?;
    let mut workspace = HostWorkspace::new();
    let mut vehicle = VehicleState::new();
    let mut with_fix = 0usize;
    for k in 0..reader.len() {
        let frame = reader.frame(k).map_err(CliError::new)?;
        let Some(q) = frame.vehicle_attitude else {
            continue;
        };
        let q = q.map(|v| v as f32);
        let attitude = Attitude::from_quaternion_wxyz(q).map_err(|e| {
            CliError(format!(
                "{name}: frames.csv frame {}: vehicle attitude {e:?}",
                frame.index
            ))
        })?;
        // The attitude exactly at the exposure, received at once.
        vehicle.push_attitude(frame.t_us, &attitude, frame.t_us);
        let view = frame.image.view();
        let mut buffers = workspace.buffers(frame.image.width, frame.image.height);
        let report = pipeline.process(&view, frame.t_us, &vehicle, &mut buffers);
        if report.fix.is_some() {
            with_fix += 1;
        }
    }
    let calibrator = pipeline.estimator().mount_calibrator();
    let stats = calibrator.stats();
    let refused = refusals(&stats);
    let estimate = calibrator.estimate().filter(|e| e.confident);
    let Some(e) = estimate else {
        let c = calibrator.config();
        let have = calibrator
            .estimate()
            .map_or(String::from("no frame used"), |e| {
                format!(
                    "{} frames over {:.1} s used, noise sigma {:.3} deg",
                    e.frames,
                    e.span_us as f64 * 1e-6,
                    e.noise_sigma_deg
                )
            });
        return Err(CliError(format!(
            "{name}: not enough good frames for a mount estimate: {} frames, {with_fix} with a \
             pad fix, {have} ({refused}); it needs {} frames over {} s with a noise sigma of \
             at most {} deg (a hover over the pad at 2-5 m for 20 s)",
            reader.len(),
            c.min_frames,
            c.min_span_us / 1_000_000,
            c.max_noise_sigma_deg
        )));
    };
    if args.json {
        let report = json_report(&e, &stats, reader.len(), with_fix);
        let text = serde_json::to_string_pretty(&report).map_err(CliError::new)?;
        writeln!(out, "{text}").map_err(CliError::new)?;
    } else {
        write_text(out, &name, &e, reader.len(), with_fix, &refused).map_err(CliError::new)?;
    }
    Ok(Outcome::Success)
}

/// The refusal counts as text.
fn refusals(s: &MountCalibrationStats) -> String {
    format!(
        "refused: {} poor tilt, {} tilt not measured, {} flip-ambiguous, {} not level, {} \
         outliers",
        s.poor_tilt, s.tilt_not_measured, s.ambiguous, s.not_level, s.outliers
    )
}

/// Rounded to what a parameter is set to (hundredths of a degree).
fn param_value(v: f32) -> f64 {
    (f64::from(v) * 100.0).round() / 100.0
}

fn json_report(
    e: &MountEstimate,
    s: &MountCalibrationStats,
    frames_in_recording: usize,
    frames_with_fix: usize,
) -> Report {
    let mut params = serde_json::Map::new();
    params.insert("TD_CAM_ROLL".into(), param_value(e.roll_deg).into());
    params.insert("TD_CAM_PITCH".into(), param_value(e.pitch_deg).into());
    Report {
        roll_deg: e.roll_deg,
        pitch_deg: e.pitch_deg,
        roll_sigma_deg: e.roll_sigma_deg,
        pitch_sigma_deg: e.pitch_sigma_deg,
        noise_sigma_deg: e.noise_sigma_deg,
        bias_sigma_deg: e.bias_sigma_deg,
        frames: e.frames,
        span_s: e.span_us as f64 * 1e-6,
        frames_in_recording,
        frames_with_fix,
        refused: Refused {
            poor_tilt: s.poor_tilt,
            tilt_not_measured: s.tilt_not_measured,
            ambiguous: s.ambiguous,
            not_level: s.not_level,
            outliers: s.outliers,
        },
        params,
    }
}

fn write_text(
    out: &mut dyn Write,
    name: &str,
    e: &MountEstimate,
    frames: usize,
    with_fix: usize,
    refused: &str,
) -> std::io::Result<()> {
    writeln!(
        out,
        "touchdown calibrate: {name}: {frames} frames, {with_fix} with a pad fix, {} used over \
         {:.1} s ({refused})",
        e.frames,
        e.span_us as f64 * 1e-6
    )?;
    writeln!(
        out,
        "mount roll {:+.3} deg +-{:.3}, pitch {:+.3} deg +-{:.3} (one sigma: noise {:.3}, \
         autopilot attitude bias {:.3})",
        e.roll_deg,
        e.roll_sigma_deg,
        e.pitch_deg,
        e.pitch_sigma_deg,
        e.noise_sigma_deg,
        e.bias_sigma_deg
    )?;
    writeln!(
        out,
        "Set on the camera board (or leave TD_CAM_CAL at 2 and it sets them in flight):"
    )?;
    writeln!(out, "param set TD_CAM_ROLL {:.2}", param_value(e.roll_deg))?;
    writeln!(
        out,
        "param set TD_CAM_PITCH {:.2}",
        param_value(e.pitch_deg)
    )
}
