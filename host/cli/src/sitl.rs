//! `touchdown sitl`: closed-loop landings, the vehicle flying on the targets touchdown sends.
//!
//! Against the autopilot model ([`touchdown_eval::closed_loop`]): per camera frame the
//! simulator renders the pad from the vehicle's true pose, the board's per-frame path and
//! companion run on it against the simulated autopilot over MAVLink bytes, and the
//! ArduPilot-like LAND it flies steers a point-mass multicopter in wind and gusts on what it
//! reconstructs. It prints where the vehicle touched down against the pad's centre and the
//! timeline, or one JSON object (`--json`); `--seeds N` flies N seeds (on threads) and
//! prints the distribution; `--record DIR` writes the flight as a recording that
//! `touchdown replay DIR` replays.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use clap::{Args, ValueEnum};
use serde::Serialize;

mod connect;
pub mod gcs;
mod vision_check;

use super::{CliError, Outcome};
use crate::companion::endpoint::EndpointSpec;
use crate::effects::EffectArgs;
use crate::pad_motion::PadMotionArgs;
use crate::renderer::RendererArg;
use touchdown_core::pad::designs;
use touchdown_eval::closed_loop::land::LandParams;
use touchdown_eval::closed_loop::wind::WindProfile;
use touchdown_eval::closed_loop::{self, LandingConfig, LandingOutcome};
use touchdown_formats::recording::RecordingWriter;

/// `--help`'s long text.
pub const LONG_HELP: &str = "\
Closed-loop landings: the vehicle flies on the targets touchdown sends.

Per camera frame: the simulator renders the camera's view of the pad (--pad, by default the \
recommended nested-field) from the vehicle's TRUE pose (with the flight effects, as `touchdown simulate`: rolling \
shutter, vibration on the mount, mount misalignment; --ideal for none), the camera board's \
per-frame path (detector, pad fix, estimator) and MAVLink companion run on it, and talk \
MAVLink bytes with the autopilot model over a simulated UART (TIMESYNC, \
SET_MESSAGE_INTERVAL, the attitude stream, LANDING_TARGET), under the replay's error model \
(attitude noise and bias, latencies, clocks, PLND_LAG, position drift).

The autopilot model: ArduPilot's precision LAND as its source does it. The LANDING_TARGET's \
vector (BODY_FRD, or LOCAL_FRD with TD_PROFILE 3) turned with its attitude estimate at \
receipt - PLND_LAG, plus its position estimate, is the pad's position; the position controller (AC_PosControl's defaults: P 1.0 on \
position, PID 2.0 / 1.0 / 0.5 on the velocity error low-passed at 5 Hz) flies to the newest one (after 1 s without a \
target it keeps the last); it descends at LAND_SPEED_HIGH 1.5 m/s above LAND_ALT_LOW 10 m and \
LAND_SPEED 0.5 m/s below; with a target acquired (a measurement within 2 s) it does not \
descend farther than PLND_XY_DIST_MAX 2.5 m from the pad, and while the newest measurement \
puts the pad 0.35-2 m below it descends at half LAND_SPEED, down to 0.1 m/s from 15 cm of \
horizontal error on. The vehicle: a point mass whose tilt follows the commanded \
acceleration (0.15 s), 30 degrees at most, with ArduPilot SITL's default frame's drag (the \
rotors' 0.24 /s on the airspeed, the body's 0.036 /m on its square), in a mean wind \
(--wind-mps, seeded direction) and 1-cos gusts of peak --gust-mps (2-6 s long, every 6 s on \
average, seeded directions), the same at every height (--wind-profile sitl: scaled by \
sqrt(height / 60 m) below 60 m, ArduPilot SITL's default SIM_WIND_T). Touchdown: the camera's true height reaching the pad; the error \
is the true horizontal position then against the pad's centre (its origin, the landing point).

A moving pad (--pad-velocity, --pad-turn-rate, --deck-heave, --deck-roll; it starts moving \
with the LAND): the model flies with PLND_OPTIONS bit 0 (moving landing target) set whenever \
one of those flags is given. AC_PrecLand's Kalman filter (PLND_EST_TYPE 1) then estimates \
the pad's position and velocity per axis (process noise PLND_ACC_P_NSE 2.5, measurements \
trusted to 1 cm per metre of depth plus 2 cm, outliers gated), settled in the hover before \
the LAND (AC_PrecLand runs in every mode): it steers on the first target, and after 2 s \
without one it holds and starts again, steering 2 s after its next first measurement; the \
pad's velocity is fed forward to the position controller. The height LAND descends on is \
over the deck under the camera, and the touchdown error is against the pad where it is at \
touchdown. Without those flags the model is the one above (the option off).

Output: the start, the timeline (first LANDING_TARGET received, target acquired by LAND, the \
slow descent, the last target, touchdown, seconds from LAND), the touchdown error (north, \
east, horizontal, cm), frames and targets sent / received. With --seeds N (seeds --seed .. \
--seed + N - 1, flown on threads) one line per seed and the distribution (min, median, max) \
of the horizontal error. --json: one object, {\"landings\": [...], \"horizontal_cm\": {min, \
median, max}} (keys in docs/interfaces.md).

--record DIR (one seed): the flight as a recording (camera.toml, pad.toml, frames/, \
frames.csv with the truth and veh_ attitude columns) that `touchdown replay DIR` replays.

A running SITL (--tcp, --udp or --udp-listen) instead of the model: the SITL flies its own \
vehicle; touchdown reads its ground truth (ArduPilot's SIM_STATE, PX4's HIL_STATE_QUATERNION, \
asked for with SET_MESSAGE_INTERVAL), renders the pad from it, runs the per-frame path and the \
companion, and talks to the SITL over the link as the board would, in wall-clock time. The pad \
lies at --pad-at or under the vehicle where the first sample found it (start with the vehicle on \
the ground, then take off and LAND from the ground station). It ends at touchdown (on the pad \
plane at rest for 1 s after having been above 2 m) or --max-time, and prints the touchdown error \
against the pad's centre.

Exit status: 0 when every landing touched down; 2 with one line on stderr for a bad option, \
or when a landing did not touch down within --max-time.";

/// `--wind-profile`'s choices.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum WindProfileArg {
    /// The same wind at every height.
    Uniform,
    /// ArduPilot SITL's default: scaled by sqrt(height / 60 m) below 60 m.
    Sitl,
}

impl WindProfileArg {
    fn profile(self) -> WindProfile {
        match self {
            WindProfileArg::Uniform => WindProfile::Uniform,
            WindProfileArg::Sitl => WindProfile::sitl(),
        }
    }
}

/// Arguments of `touchdown sitl`.
#[derive(Debug, Clone, Args)]
pub struct SitlArgs {
    /// Seed of everything random (scene, wind, errors, start bearing); the first with --seeds
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seed: u64,

    /// Fly N seeds, --seed to --seed + N - 1, and print the distribution
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seeds: u64,

    /// Height of the camera over the pad when LAND begins, metres
    #[arg(long, value_name = "M", default_value_t = 20.0)]
    pub height: f64,

    /// Horizontal distance from the pad when LAND begins, metres (seeded bearing)
    #[arg(long, value_name = "M", default_value_t = 2.0)]
    pub offset: f64,

    /// Mean wind, m/s (seeded direction)
    #[arg(long, value_name = "MPS", default_value_t = 2.0)]
    pub wind_mps: f64,

    /// Peak of the 1-cos gusts, m/s
    #[arg(long, value_name = "MPS", default_value_t = 3.0)]
    pub gust_mps: f64,

    /// The wind over height: uniform (the same at every height, the gusts at their peak down
    /// to the ground) or sitl (ArduPilot SITL's default SIM_WIND_T 0: mean and gusts scaled
    /// by sqrt(height / 60 m) below 60 m)
    #[arg(long, value_enum, value_name = "PROFILE", default_value = "uniform")]
    pub wind_profile: WindProfileArg,

    /// Camera frames per second [default: 15, the landing scenario's]
    #[arg(long, value_name = "HZ", default_value_t = 15.0)]
    pub fps: f64,

    /// Render at 320x240 (the same lens) instead of 640x480
    #[arg(long)]
    pub qvga: bool,

    /// The pad drawn and looked for, a shipped design: nested-field, nested-rest, nested or
    /// paper-single [default: nested-field, the recommended pad]
    #[arg(long, value_name = "DESIGN")]
    pub pad: Option<String>,

    /// Give up on a landing after this long, seconds
    #[arg(long, value_name = "S", default_value_t = 90.0)]
    pub max_time: f64,

    /// Board parameters at start, NAME=VALUE,... (e.g. TD_CAM_ROLL=1.2,TD_CAM_PITCH=-1.6)
    #[arg(long, value_name = "LIST")]
    pub board_params: Option<String>,

    /// Write the flight as a recording into DIR (one seed; DIR must be empty or new)
    #[arg(long, value_name = "DIR")]
    pub record: Option<PathBuf>,

    /// One JSON object on stdout instead of the text
    #[arg(long)]
    pub json: bool,

    /// The flight effects' terms.
    #[command(flatten)]
    pub effect_terms: EffectArgs,

    /// How the pad moves (at rest by default).
    #[command(flatten)]
    pub pad_motion: PadMotionArgs,

    /// No flight effects: global shutter, no vibration, the nominal mount
    #[arg(long, help_heading = "Flight effects")]
    pub ideal: bool,

    /// The image model: raster (ray casting) or warp (pre-rasterised world, much
    /// faster, its own optics and sensor) [default: warp against a running SITL, which the
    /// frames must keep pace with; raster for the model's landings]
    #[arg(
        long,
        value_name = "NAME",
        value_parser = RendererArg::parse,
        help_heading = "Advanced"
    )]
    pub renderer: Option<RendererArg>,

    /// Threads [default: all cores]: seeds in parallel, or one seed's rendering
    #[arg(long, value_name = "N", help_heading = "Advanced")]
    pub threads: Option<usize>,

    /// Against a running SITL instead of the model: TCP client to HOST:PORT (ArduPilot
    /// SITL's SERIAL1, 5762)
    #[arg(long, value_name = "HOST:PORT", help_heading = "A running SITL",
          conflicts_with_all = ["udp", "udp_listen"])]
    pub tcp: Option<String>,

    /// Against a running SITL: UDP client to HOST:PORT (PX4 SITL's onboard link, 14580)
    #[arg(
        long,
        value_name = "HOST:PORT",
        help_heading = "A running SITL",
        conflicts_with = "udp_listen"
    )]
    pub udp: Option<String>,

    /// Our source port for --udp (PX4 answers only the first address that reached it)
    #[arg(
        long,
        value_name = "N",
        help_heading = "A running SITL",
        requires = "udp"
    )]
    pub udp_local_port: Option<u16>,

    /// Against a running SITL: UDP server on ADDR:PORT (ArduPilot SITL
    /// `--serial1 udpclient:127.0.0.1:14560`)
    #[arg(long, value_name = "ADDR:PORT", help_heading = "A running SITL")]
    pub udp_listen: Option<String>,

    /// With a running SITL: the pad's origin LAT,LON,ALT (degrees, metres AMSL) [default:
    /// under the vehicle at the first ground-truth sample, 0.1 m below its body origin]
    #[arg(long, value_name = "LAT,LON,ALT", help_heading = "A running SITL",
          value_parser = parse_pad_at, allow_hyphen_values = true)]
    pub pad_at: Option<[f64; 3]>,

    /// With a running SITL: fly the whole rehearsal from its ground-station port too
    /// (tcp:HOST:PORT, udp:HOST:PORT or udpin:ADDR:PORT; ArduPilot SITL tcp:127.0.0.1:5760,
    /// PX4 SITL udpin:0.0.0.0:14550): set the precision-landing parameters, arm, take off to
    /// --height, fly --offset from the pad, land, and watch until the autopilot disarms
    #[arg(long, value_name = "ADDRESS", help_heading = "A running SITL",
          value_parser = gcs::parse_gcs)]
    pub gcs: Option<EndpointSpec>,

    /// With --gcs on ArduPilot SITL: its wind turbulence, SIM_WIND_TURB, m/s (--wind-mps
    /// and --wind-profile set SIM_WIND_SPD and SIM_WIND_T; PX4's SIH has no wind)
    #[arg(
        long,
        value_name = "MPS",
        default_value_t = 0.0,
        help_heading = "A running SITL"
    )]
    pub turbulence: f64,

    /// With --gcs: turn to this heading (degrees from north) at the start point before the
    /// landing [default: the heading the vehicle has]
    #[arg(
        long,
        value_name = "DEG",
        help_heading = "A running SITL",
        allow_hyphen_values = true
    )]
    pub yaw: Option<f64>,

    /// With --gcs: how long the vehicle holds still at the start point before the landing,
    /// seconds (the board's position is checked against the truth while it holds)
    #[arg(
        long,
        value_name = "S",
        default_value_t = 3.0,
        help_heading = "A running SITL"
    )]
    pub hold: f64,

    /// With --gcs: the autopilot's own parameters to set too, NAME=VALUE,... (after the
    /// precision-landing ones, replacing any of them; a parameter that needs a reboot takes
    /// effect at the autopilot's next start)
    #[arg(long, value_name = "LIST", help_heading = "A running SITL")]
    pub autopilot_params: Option<String>,

    /// With --gcs on ArduPilot SITL: lose GPS on the climb at this height over the pad
    /// (at most --height): switch the EKF to source set 2, the board's
    /// VISION_POSITION_ESTIMATE (TD_VPE_EN 1 and TD_PAD_YAW 0 unless set), then turn the
    /// SITL's GPS off; the
    /// move and the landing fly on the board's position alone. Adds the external-navigation
    /// parameters to the recipe (docs/setup-ardupilot.md, "Without GPS")
    #[arg(long, value_name = "M", help_heading = "A running SITL")]
    pub gps_loss_height: Option<f64>,

    /// With --gcs: no GPS at all, from boot (ArduPilot GPS1_TYPE 0, PX4 EKF2_GPS_CTRL 0): the EKF's
    /// position is the board's VISION_POSITION_ESTIMATE (TD_VPE_EN 1, TD_PAD_YAW 0 unless set) from the
    /// ground up, its origin set at the pad; the vehicle arms once the board sends its
    /// position and has calibrated its mount on the pad, and on PX4 once PX4 has synced its
    /// clock with the board's (docs/setup-ardupilot.md, "Without GPS"; docs/setup-px4.md)
    #[arg(
        long,
        help_heading = "A running SITL",
        conflicts_with = "gps_loss_height"
    )]
    pub no_gps: bool,

    /// With --gcs on ArduPilot SITL: MAVLink 2 signing (docs/signing.md). KEY is 64 hex
    /// digits, or a passphrase (its SHA-256, as MAVProxy derives keys). The ground station
    /// sets it on the autopilot with SETUP_SIGNING and the board holds it and signs every
    /// frame; ArduPilot then drops unsigned frames on the board's port
    #[arg(long, value_name = "KEY", help_heading = "A running SITL")]
    pub signing_key: Option<String>,

    /// With --gcs: how long a refused connection to the ground-station port is tried again,
    /// seconds (a SITL just launched opens its port a few seconds later)
    #[arg(long, value_name = "S", default_value_t = gcs::CONNECT_PATIENCE.as_secs_f64(), value_parser = parse_timeout, help_heading = "A running SITL")]
    pub connect_timeout: f64,

    /// With --gcs: how long each of the three tries of a parameter read or write waits for
    /// the autopilot's answer, seconds
    #[arg(long, value_name = "S", default_value_t = gcs::PARAM_TRY.as_secs_f64(), value_parser = parse_timeout, help_heading = "A running SITL")]
    pub param_timeout: f64,
}

/// A timeout in seconds: finite, over 0 and at most an hour.
fn parse_timeout(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(s) if s.is_finite() && s > 0.0 && s <= 3600.0 => Ok(s),
        _ => Err("expected seconds, over 0 and at most 3600".to_string()),
    }
}

impl SitlArgs {
    /// The pad design to draw: `--pad`'s, or the recommended one.
    fn pad_name(&self) -> String {
        self.pad
            .clone()
            .unwrap_or_else(|| designs::RECOMMENDED.name().to_string())
    }
}

fn parse_pad_at(text: &str) -> Result<[f64; 3], String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| "expected LAT,LON,ALT: three numbers".to_string())?;
    match values.as_slice() {
        [lat, lon, alt] if lat.abs() <= 90.0 && lon.abs() <= 180.0 && alt.is_finite() => {
            Ok([*lat, *lon, *alt])
        }
        _ => Err(
            "expected LAT,LON,ALT: latitude within 90, longitude within 180 degrees, \
                  altitude in metres"
                .to_string(),
        ),
    }
}

impl SitlArgs {
    /// The running SITL's link, if one is named.
    fn sitl_endpoint(&self) -> Option<EndpointSpec> {
        if let Some(addr) = &self.tcp {
            Some(EndpointSpec::TcpClient(addr.clone()))
        } else if let Some(addr) = &self.udp_listen {
            Some(EndpointSpec::UdpListen(addr.clone()))
        } else {
            self.udp.as_ref().map(|remote| EndpointSpec::UdpClient {
                remote: remote.clone(),
                local_port: self.udp_local_port,
            })
        }
    }
}

fn check(args: &SitlArgs) -> Result<(), CliError> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    let non_negative = |v: f64| v.is_finite() && v >= 0.0;
    if !positive(args.height) {
        return Err(CliError("--height must be a number > 0".into()));
    }
    for (flag, v) in [
        ("--offset", args.offset),
        ("--wind-mps", args.wind_mps),
        ("--gust-mps", args.gust_mps),
        ("--turbulence", args.turbulence),
        ("--hold", args.hold),
    ] {
        if !non_negative(v) {
            return Err(CliError(format!("{flag} must be a number >= 0")));
        }
    }
    if !positive(args.fps) || args.fps > 120.0 {
        return Err(CliError("--fps must be in 0..120".into()));
    }
    if !positive(args.max_time) {
        return Err(CliError("--max-time must be a number > 0".into()));
    }
    if args.yaw.is_some_and(|y| !y.is_finite() || y.abs() > 360.0) {
        return Err(CliError(
            "--yaw must be a heading within -360..360 degrees".into(),
        ));
    }
    if let Some(h) = args.gps_loss_height {
        if !positive(h) || h > args.height {
            return Err(CliError(format!(
                "--gps-loss-height must be a height > 0 and at most --height ({} m): GPS is lost on the climb",
                args.height
            )));
        }
    }
    if let Some(name) = &args.pad {
        touchdown_sim::pad::shipped_design(name).map_err(|e| CliError(format!("--pad: {e}")))?;
    }
    if args.seeds == 0 {
        return Err(CliError("--seeds must be at least 1".into()));
    }
    if args.threads == Some(0) {
        return Err(CliError("--threads must be at least 1".into()));
    }
    if args.record.is_some() && args.seeds > 1 {
        return Err(CliError("--record takes one seed, not --seeds".into()));
    }
    if let Some(dir) = &args.record {
        if dir
            .read_dir()
            .is_ok_and(|mut entries| entries.next().is_some())
        {
            return Err(CliError(format!(
                "{}: directory is not empty",
                dir.display()
            )));
        }
    }
    Ok(())
}

/// A landing's JSON record.
#[derive(Debug, Serialize)]
struct LandingJson {
    seed: u64,
    start_north_m: f64,
    start_east_m: f64,
    touched_down: bool,
    touchdown_s: Option<f64>,
    north_cm: Option<f64>,
    east_cm: Option<f64>,
    horizontal_cm: Option<f64>,
    touchdown_speed_mps: Option<f64>,
    first_target_s: Option<f64>,
    target_acquired_s: Option<f64>,
    low_descent_s: Option<f64>,
    last_target_s: Option<f64>,
    last_target_height_m: Option<f64>,
    last_target_offset_m: Option<f64>,
    longest_target_gap_s: f64,
    frames: usize,
    frames_with_fix: usize,
    targets_sent: u32,
    targets_received: usize,
}

impl From<&LandingOutcome> for LandingJson {
    fn from(o: &LandingOutcome) -> Self {
        let td = o.touchdown;
        LandingJson {
            seed: o.seed,
            start_north_m: o.start_ne.0,
            start_east_m: o.start_ne.1,
            touched_down: td.is_some(),
            touchdown_s: td.map(|t| t.t_s),
            north_cm: td.map(|t| 100.0 * t.north_m),
            east_cm: td.map(|t| 100.0 * t.east_m),
            horizontal_cm: td.map(|t| 100.0 * t.horizontal_m()),
            touchdown_speed_mps: td.map(|t| t.speed_mps),
            first_target_s: o.first_target_s,
            target_acquired_s: o.acquired_s,
            low_descent_s: o.low_s,
            last_target_s: o.last_target_s,
            last_target_height_m: o.last_target_height_m,
            last_target_offset_m: o.last_target_offset_m,
            longest_target_gap_s: o.longest_gap_s,
            frames: o.frames,
            frames_with_fix: o.frames_with_fix,
            targets_sent: o.targets_sent,
            targets_received: o.targets_received,
        }
    }
}

/// Min, median and max, cm.
#[derive(Debug, Serialize)]
struct Distribution {
    min: f64,
    median: f64,
    max: f64,
}

fn distribution(values: &[f64]) -> Option<Distribution> {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let median = match n {
        0 => return None,
        _ if n % 2 == 1 => v[n / 2],
        _ => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    };
    Some(Distribution {
        min: v[0],
        median,
        max: v[n - 1],
    })
}

#[derive(Debug, Serialize)]
struct Report {
    autopilot: &'static str,
    landings: Vec<LandingJson>,
    horizontal_cm: Option<Distribution>,
    elapsed_s: f64,
}

/// Flies the seeds, `workers` at a time, each seed's rendering on `render_threads`.
fn fly_all(
    configs: Vec<LandingConfig>,
    workers: usize,
    record: Option<&PathBuf>,
) -> Result<Vec<LandingOutcome>, CliError> {
    if let (Some(dir), [config]) = (record, configs.as_slice()) {
        let scene = closed_loop::scene(config).map_err(CliError)?;
        let mut writer = RecordingWriter::create_with_vehicle_attitude(
            dir,
            &scene.camera.model,
            &scene.pad.config,
            true,
            true,
        )
        .map_err(CliError::new)?;
        let mut write = |f: &touchdown_sim::SimFrame| {
            writer
                .push_with_vehicle_attitude(
                    f.t_us,
                    Some(&f.truth),
                    Some(&f.vehicle_attitude),
                    None,
                    &f.image,
                )
                .map_err(|e| e.to_string())
        };
        let outcome = closed_loop::fly(config, &mut write).map_err(CliError)?;
        writer.finish().map_err(CliError::new)?;
        return Ok(vec![outcome]);
    }
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results: std::sync::Mutex<Vec<Option<Result<LandingOutcome, String>>>> =
        std::sync::Mutex::new((0..configs.len()).map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..workers.clamp(1, configs.len()) {
            s.spawn(|| loop {
                let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some(config) = configs.get(k) else {
                    break;
                };
                let r = closed_loop::fly(config, &mut |_| Ok(()));
                if let Ok(mut all) = results.lock() {
                    all[k] = Some(r);
                }
            });
        }
    });
    let all = results
        .into_inner()
        .map_err(|_| CliError("a landing's thread failed".into()))?;
    all.into_iter()
        .map(|r| match r {
            Some(Ok(o)) => Ok(o),
            Some(Err(e)) => Err(CliError(e)),
            None => Err(CliError("a landing's thread failed".into())),
        })
        .collect()
}

fn seconds(v: Option<f64>) -> String {
    v.map_or("-".into(), |s| format!("{s:.2}"))
}

/// The text of one landing.
fn landing_text(o: &LandingOutcome, config: &LandingConfig) -> String {
    let mut t = String::new();
    let (n, e) = o.start_ne;
    t.push_str(&format!(
        "seed {}: LAND from {:.1} m, {:.2} m off the pad (north {n:+.2}, east {e:+.2} m)\n",
        o.seed, config.start_height_m, config.offset_m
    ));
    t.push_str("timeline, s from LAND:\n");
    t.push_str(&format!(
        "  {:>7}  first LANDING_TARGET received\n",
        seconds(o.first_target_s)
    ));
    t.push_str(&format!(
        "  {:>7}  target acquired (LAND steers on the pad estimate)\n",
        seconds(o.acquired_s)
    ));
    t.push_str(&format!(
        "  {:>7}  below LAND_ALT_LOW {:.0} m: {:.1} m/s (above: {:.1} m/s)\n",
        seconds(o.low_s),
        config.land.land_alt_low_m,
        config.land.land_speed_mps,
        config.land.land_speed_high_mps
    ));
    t.push_str(&format!(
        "  {:>7}  last LANDING_TARGET received{}\n",
        seconds(o.last_target_s),
        match (o.last_target_height_m, o.last_target_offset_m) {
            (Some(h), Some(d)) => format!(" (camera at {h:.2} m, {:.0} cm off)", 100.0 * d),
            _ => String::new(),
        }
    ));
    match o.touchdown {
        Some(td) => {
            t.push_str(&format!("  {:>7}  touchdown\n", seconds(Some(td.t_s))));
            t.push_str(&format!(
                "touchdown: {:.1} cm from the pad centre (north {:+.1}, east {:+.1} cm), {:.2} m/s horizontal\n",
                100.0 * td.horizontal_m(),
                100.0 * td.north_m,
                100.0 * td.east_m,
                td.speed_mps
            ));
        }
        None => t.push_str(&format!(
            "no touchdown within {:.0} s\n",
            config.max_flight_s
        )),
    }
    t.push_str(&format!(
        "frames {} ({} with a pad fix), LANDING_TARGETs sent {}, received {}; longest gap between targets {:.2} s\n",
        o.frames, o.frames_with_fix, o.targets_sent, o.targets_received, o.longest_gap_s
    ));
    t
}

/// Runs `touchdown sitl`.
pub fn run(args: &SitlArgs, out: &mut dyn Write, err: &mut dyn Write) -> Result<Outcome, CliError> {
    check(args)?;
    let started = Instant::now();
    let params = crate::parse_board_params(args.board_params.as_deref())?;
    if let Some(endpoint) = args.sitl_endpoint() {
        return connect::run(args, endpoint, params, out, err);
    }
    if args.pad_at.is_some()
        || args.gcs.is_some()
        || args.yaw.is_some()
        || args.autopilot_params.is_some()
    {
        return Err(CliError::new(
            "--pad-at, --gcs, --yaw and --autopilot-params are for a running SITL: give the board's link too, \
             --tcp, --udp or --udp-listen",
        ));
    }
    if args.gps_loss_height.is_some() || args.no_gps || args.signing_key.is_some() {
        return Err(CliError::new(
            "--gps-loss-height, --no-gps and --signing-key are for a running SITL flown with \
             --gcs: give the board's link too, --tcp, --udp or --udp-listen",
        ));
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads = args.threads.unwrap_or(cores);
    let (workers, render_threads) = if args.seeds > 1 {
        (threads, 1)
    } else {
        (1, threads)
    };
    let pad_motion = args.pad_motion.motion(0.0)?;
    // A moving pad is what PLND_OPTIONS bit 0 is for: the model flies with it set then.
    let land = if args.pad_motion.any_given() {
        LandParams::ardupilot_moving_target()
    } else {
        LandParams::ardupilot()
    };
    let configs: Vec<LandingConfig> = (0..args.seeds)
        .map(|k| LandingConfig {
            start_height_m: args.height,
            offset_m: args.offset,
            wind_mps: args.wind_mps,
            gust_mps: args.gust_mps,
            wind_profile: args.wind_profile.profile(),
            effects: args.effect_terms.effects(args.ideal),
            params: params.clone(),
            fps: args.fps,
            qvga: args.qvga,
            renderer: args.renderer.unwrap_or(RendererArg::Raster).renderer(),
            pad: Some(args.pad_name()),
            threads: render_threads,
            max_flight_s: args.max_time,
            pad_motion,
            land,
            ..LandingConfig::issue_15(args.seed.wrapping_add(k))
        })
        .collect();
    let Some(first) = configs.first().cloned() else {
        return Err(CliError("--seeds must be at least 1".into()));
    };
    let outcomes = fly_all(configs, workers, args.record.as_ref())?;
    let horizontal: Vec<f64> = outcomes
        .iter()
        .filter_map(|o| o.touchdown.map(|t| 100.0 * t.horizontal_m()))
        .collect();
    let all_down = horizontal.len() == outcomes.len();
    let elapsed_s = started.elapsed().as_secs_f64();
    let write = |out: &mut dyn Write, text: &str| {
        out.write_all(text.as_bytes())
            .map_err(|e| CliError(format!("cannot write to stdout: {e}")))
    };
    if args.json {
        let report = Report {
            autopilot: "model",
            landings: outcomes.iter().map(LandingJson::from).collect(),
            horizontal_cm: distribution(&horizontal),
            elapsed_s,
        };
        let text = serde_json::to_string_pretty(&report).map_err(CliError::new)?;
        write(out, &format!("{text}\n"))?;
    } else {
        let e = &first.effects;
        let mut text = format!(
            "touchdown sitl: {} closed-loop landing{} against the autopilot model (ArduPilot-like precision LAND), flown in {elapsed_s:.1} s\n\
             wind {:.1} m/s, gusts {:.1} m/s peak{}; {} at {:.0} fps; flight effects: readout {} ms, vibration {} deg, mount roll {} pitch {} deg\n",
            outcomes.len(),
            if outcomes.len() == 1 { "" } else { "s" },
            first.wind_mps,
            first.gust_mps,
            if first.wind_profile == WindProfile::Uniform {
                ""
            } else {
                ", thinned toward the ground as SITL's (sqrt of height / 60 m)"
            },
            if first.qvga { "320x240" } else { "640x480" },
            first.fps,
            e.readout_ms,
            e.vibration_deg,
            e.mount_roll_deg,
            e.mount_pitch_deg
        );
        if let [o] = outcomes.as_slice() {
            text.push_str(&landing_text(o, &first));
        } else {
            text.push_str(
                "seed  touchdown s  north cm  east cm  horizontal cm  targets received\n",
            );
            for o in &outcomes {
                match o.touchdown {
                    Some(td) => text.push_str(&format!(
                        "{:>4}  {:>11.2}  {:>8.1}  {:>7.1}  {:>13.1}  {:>16}\n",
                        o.seed,
                        td.t_s,
                        100.0 * td.north_m,
                        100.0 * td.east_m,
                        100.0 * td.horizontal_m(),
                        o.targets_received
                    )),
                    None => text.push_str(&format!(
                        "{:>4}  no touchdown{:>43}\n",
                        o.seed, o.targets_received
                    )),
                }
            }
            if let Some(d) = distribution(&horizontal) {
                text.push_str(&format!(
                    "horizontal touchdown error over {} landings, cm: min {:.1}, median {:.1}, max {:.1}\n",
                    horizontal.len(),
                    d.min,
                    d.median,
                    d.max
                ));
            }
        }
        write(out, &text)?;
    }
    if !all_down {
        return Err(CliError(format!(
            "{} of {} landings did not touch down within --max-time {} s",
            outcomes.len() - horizontal.len(),
            outcomes.len(),
            args.max_time
        )));
    }
    Ok(Outcome::Success)
}
