//! `touchdown simulate`: render a named scenario into a recording (the contract's format).
//!
//! Frames are rendered and written one at a time, so memory does not grow with the length
//! of the scenario. Progress goes to stderr only when it is a terminal, so logs and tests
//! see one summary line on stdout.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::builder::{PossibleValue, PossibleValuesParser};
use clap::Args;

use super::{CliError, Outcome};
use crate::effects::EffectArgs;
use crate::pad_motion::PadMotionArgs;
use crate::renderer::{LensArgs, PsfArg, RendererArg};
use touchdown_formats::recording::RecordingWriter;
use touchdown_sim::effects::FlightEffects;
use touchdown_sim::pad::shipped_design;
use touchdown_sim::pad_motion::PadMotion;
use touchdown_sim::scenario::{Scenario, SCENARIOS};
use touchdown_sim::{Renderer, Simulator};

/// `touchdown simulate --help`.
pub const LONG_HELP: &str = "\
Render a simulated flight over a landing pad into a recording.

The simulator draws a textured ground plane with the pad's markers at true size, seen
through a calibrated camera (intrinsics and Brown-Conrady distortion) on a vehicle whose
attitude follows its motion; area sampling, motion blur over the exposure, lens blur and
defocus, vignetting, exposure and gain, shot and read noise, clipping and blooming. Every
frame carries the camera's true pose. The same --seed gives the same bytes.

Flight effects (on by default, each set to a typical small multicopter; 0 turns one off,
--ideal turns all off):
  rolling shutter  --readout-ms (30.5: the OV7725 at 30 fps, 480 active rows of 63.5 us):
                   every row is exposed at its own time, (row - (height-1)/2) * line time
                   after the frame's time, while the vehicle moves and turns; camera.toml
                   gets line_time_us = readout / height
  vibration        --vibration-deg (0.03 RMS per axis: ~25 deg/s of jitter): the camera
                   turns on its mount at 50-200 Hz (seeded sinusoids); the vehicle's
                   attitude does not see it
  mount            --mount-roll-deg (1.2), --mount-pitch-deg (-1.6): the true mount is the
                   nominal downward one turned by roll about body x, then pitch about body y
                   (camera-to-body = R_y(pitch) R_x(roll) nominal); camera.toml and the board
                   know only the nominal one

The recording (DIR) is the contract's format, the one `replay` reads and the camera board
dumps: camera.toml, pad.toml, frames/000000.pgm ..., frames.csv (index,t_us and the truth
cam_x,cam_y,cam_z,cam_qw,cam_qx,cam_qy,cam_qz: the camera's position in the pad frame,
metres, and its camera-to-pad rotation, at the frame's time, the middle row's exposure
middle; then veh_qw,veh_qx,veh_qy,veh_qz: the vehicle's true body FRD to NED attitude,
without the vibration, NED being north = pad +y, east = pad +x, down = pad -z), plus
setpoints.csv (index,label) for scenarios with set points, and simulation.toml describing
the run and its effects.

Exit status: 0 on success; 2 with one line on stderr for a bad option or a write error.";

/// Arguments of `touchdown simulate`.
#[derive(Debug, Clone, Args)]
pub struct SimulateArgs {
    /// The scenario to fly
    #[arg(long, value_name = "NAME", value_parser = scenario_parser())]
    pub scenario: String,

    /// Seed of everything random (texture, wobble, noise)
    #[arg(
        long,
        allow_negative_numbers = true,
        value_name = "N",
        default_value_t = 1
    )]
    pub seed: u64,

    /// Recording directory to write [default: sim-<SCENARIO>]
    // The doc comment is clap's help text, printed verbatim: `<SCENARIO>` stays as it is.
    #[allow(rustdoc::invalid_html_tags)]
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,

    /// Render only the first N frames
    #[arg(long, allow_negative_numbers = true, value_name = "N")]
    pub frames: Option<usize>,

    /// Write into DIR even if it already holds files
    #[arg(long)]
    pub force: bool,

    /// Draw this shipped pad design (nested-field, nested-rest, nested, paper-single) instead
    /// of the scenario's own; the flight is the same
    #[arg(long, value_name = "DESIGN")]
    pub pad: Option<String>,

    /// The flight effects' terms.
    #[command(flatten)]
    pub effect_terms: EffectArgs,

    /// How the pad moves (at rest by default).
    #[command(flatten)]
    pub pad_motion: PadMotionArgs,

    /// No flight effects: global shutter, no vibration, the nominal mount (the other effect
    /// flags then set only what they name)
    #[arg(long, help_heading = "Flight effects")]
    pub ideal: bool,

    /// The image model: raster (ray casting, the default) or warp (pre-rasterised world,
    /// much faster, its own optics and sensor)
    #[arg(
        long,
        value_name = "NAME",
        value_parser = RendererArg::parse,
        default_value = "raster",
        help_heading = "Advanced"
    )]
    pub renderer: RendererArg,

    #[command(flatten)]
    pub lens: LensArgs,

    /// Rendering threads [default: all cores]
    #[arg(
        long,
        allow_negative_numbers = true,
        value_name = "N",
        help_heading = "Advanced"
    )]
    pub threads: Option<usize>,
}

impl SimulateArgs {
    /// The flight effects asked for: typical (or none with `--ideal`), each flag overriding
    /// its term.
    pub fn effects(&self) -> FlightEffects {
        self.effect_terms.effects(self.ideal)
    }
}

fn scenario_parser() -> PossibleValuesParser {
    PossibleValuesParser::new(
        SCENARIOS
            .iter()
            .map(|(name, help)| PossibleValue::new(*name).help(*help)),
    )
}

/// Refuses to mix a new recording into a directory that holds something else.
fn check_out_dir(dir: &Path, force: bool) -> Result<(), CliError> {
    if dir.exists() && !dir.is_dir() {
        return Err(CliError(format!(
            "{}: exists and is not a directory",
            dir.display()
        )));
    }
    if force || !dir.exists() {
        return Ok(());
    }
    let mut entries = std::fs::read_dir(dir)
        .map_err(|e| CliError(format!("{}: cannot read directory: {e}", dir.display())))?;
    if entries.next().is_some() {
        return Err(CliError(format!(
            "{}: directory is not empty (use --force to write into it anyway)",
            dir.display()
        )));
    }
    Ok(())
}

/// Runs `touchdown simulate`.
pub fn run(
    args: &SimulateArgs,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<Outcome, CliError> {
    let mut scenario = Scenario::named(&args.scenario, args.seed)
        .ok_or_else(|| CliError(format!("unknown scenario `{}`", args.scenario)))?;
    if let Some(n) = args.frames {
        if n == 0 {
            return Err(CliError("--frames must be at least 1".into()));
        }
        scenario.truncate(n);
    }
    if let Some(name) = &args.pad {
        scenario.pad = shipped_design(name).map_err(|e| CliError(format!("--pad: {e}")))?;
    }
    // Over a moving pad the scenario's flight is flown against the pad, carried along.
    scenario.pad_motion = args.pad_motion.motion(0.0)?;
    scenario.flight_follows_pad = true;
    let effects = args.effects();
    scenario.apply_effects(&effects);
    scenario.camera.model.validate().map_err(|e| {
        CliError(format!(
            "--readout-ms {}: the camera refuses it ({e:?})",
            effects.readout_ms
        ))
    })?;
    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("sim-{}", args.scenario)));
    check_out_dir(&dir, args.force)?;
    let started = Instant::now();
    let mut simulator = Simulator::new(scenario);
    if let Some(threads) = args.threads {
        simulator = simulator.with_threads(threads);
    }
    let simulator = crate::renderer::configure(simulator, args.renderer, &args.lens)?;
    let camera = simulator.scenario.camera.model;
    let pad = simulator.scenario.pad.config.clone();
    let mut writer = RecordingWriter::create_with_vehicle_attitude(&dir, &camera, &pad, true, true)
        .map_err(CliError::new)?;
    std::fs::write(
        dir.join("simulation.toml"),
        simulation_toml(
            &simulator.scenario,
            &effects,
            args.renderer.renderer(),
            &args.lens,
        ),
    )
    .map_err(|e| {
        CliError(format!(
            "{}: cannot write: {e}",
            dir.join("simulation.toml").display()
        ))
    })?;
    let total = simulator.frame_count();
    let progress = std::io::stderr().is_terminal();
    for k in 0..total {
        let Some(frame) = simulator.render(k) else {
            break;
        };
        writer
            .push_with_vehicle_attitude(
                frame.t_us,
                Some(&frame.truth),
                Some(&frame.vehicle_attitude),
                frame.label.as_deref(),
                &frame.image,
            )
            .map_err(CliError::new)?;
        if progress && (k % 5 == 0 || k + 1 == total) {
            let elapsed = started.elapsed().as_secs_f64();
            let eta = elapsed / (k + 1) as f64 * (total - k - 1) as f64;
            // Progress is best effort: a closed stderr must not stop the run.
            let _ = write!(
                err,
                "\rrendering {}: frame {}/{} ({:.0} s left)   ",
                args.scenario,
                k + 1,
                total,
                eta
            );
        }
    }
    if progress {
        let _ = writeln!(err);
    }
    let written = writer.finish().map_err(CliError::new)?;
    writeln!(
        out,
        "wrote {written} frames of scenario `{}` (seed {}) to {} in {:.1} s",
        args.scenario,
        args.seed,
        dir.display(),
        started.elapsed().as_secs_f64()
    )
    .map_err(|e| CliError(format!("cannot write to stdout: {e}")))?;
    Ok(Outcome::Success)
}

/// `simulation.toml`: what produced the recording (informational; readers ignore it).
fn simulation_toml(
    s: &Scenario,
    effects: &FlightEffects,
    renderer: Renderer,
    optics: &LensArgs,
) -> String {
    let lens = s.camera.model.distortion;
    let mut psf = optics.psf.as_ref().map_or(String::new(), |PsfArg(psfs)| {
        format!(
            "psf = {}\n",
            touchdown_formats::toml_string(&format!("{psfs:?}"))
        )
    });
    if let Some(response) = &optics.response {
        psf.push_str(&format!(
            "response = {}\n",
            touchdown_formats::toml_string(&format!("{response:?}"))
        ));
    }
    format!(
        "# How this recording was simulated (touchdown simulate); informational.\n\
         scenario = {}\ndescription = {}\nseed = {}\nframes = {}\nexposure_time_s = {:?}\n\
         supersampling = {}\nground = {}\ndistortion = {:?}\n\
         readout_ms = {:?}\nvibration_deg = {:?}\nmount_roll_deg = {:?}\nmount_pitch_deg = {:?}\n\
         renderer = {}\n{}{}",
        touchdown_formats::toml_string(&s.name),
        touchdown_formats::toml_string(&s.description),
        s.seed,
        s.frames.len(),
        s.exposure_time_s,
        s.supersampling,
        touchdown_formats::toml_string(&format!("{:?}", s.ground)),
        lens,
        effects.readout_ms,
        effects.vibration_deg,
        effects.mount_roll_deg,
        effects.mount_pitch_deg,
        touchdown_formats::toml_string(renderer.name()),
        psf,
        pad_motion_toml(&s.pad_motion)
    )
}

/// The pad's motion in `simulation.toml` (nothing for a pad at rest).
fn pad_motion_toml(m: &PadMotion) -> String {
    if m.is_at_rest() {
        return String::new();
    }
    format!(
        "pad_velocity_ne_mps = [{:?}, {:?}]\npad_turn_rate_deg_s = {:?}\n\
         deck_heave_m = {:?}\ndeck_heave_period_s = {:?}\n\
         deck_roll_deg = {:?}\ndeck_roll_period_s = {:?}\n",
        m.velocity_ne_mps[0],
        m.velocity_ne_mps[1],
        m.turn_rate_deg_s,
        m.heave_m,
        m.heave_period_s,
        m.roll_deg,
        m.roll_period_s
    )
}
