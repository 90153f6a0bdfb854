//! `touchdown companion`: the board's MAVLink companion logic against a real endpoint.
//!
//! Runs the same per-frame path as the camera board (`touchdown_core::pipeline::FramePipeline`,
//! with the TD_* parameters applied between frames as the board applies them, then
//! `touchdown_core::companion::Companion`) on a recording, in real time at the recording's
//! frame times, and exchanges MAVLink with a flight controller or SITL over the link the user
//! names ([`endpoint`]: UDP or TCP, as client or server, or a serial port, exactly as the board
//! would talk on its UART: 8N1, raw, no flow control). The companion state machine is sans-IO,
//! so this file is only the loop: read bytes, feed frames when due, drain `poll_transmit` into
//! the endpoint; and at the end, or on SIGINT/SIGTERM ([`interrupt`]), the [`summary`].

pub mod endpoint;
pub mod interrupt;
pub mod summary;

use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::{ArgGroup, Args, ValueEnum};
use touchdown_core::companion::{
    Companion, CompanionConfig, Profile, TargetOutcome, MAX_FRAME_LEN,
};
use touchdown_core::family::Family;
use touchdown_core::params::{PipelineSettings, SigningSecret};
use touchdown_core::pipeline::{FramePipeline, PipelineConfig};

use super::{CliError, Outcome};
use endpoint::{Endpoint, EndpointSpec, LinkOptions, Received, Sent};
use summary::{RunCounts, Stop};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_formats::families::{self, SelectedFamily};
use touchdown_formats::recording::RecordingReader;

/// `touchdown companion --help`'s examples: each is a command that works as written against
/// the set-up it names (DIR is a recording, e.g. from `touchdown simulate --out DIR`).
pub const EXAMPLES: &str = "\
Examples (DIR: a recording, e.g. from `touchdown simulate --out DIR`):

  ArduPilot SITL (sim_vehicle.py or the arducopter binary): its SERIAL1 is a TCP server on
  port 5762 (SERIAL0, 5760, is the ground station's):
    touchdown companion --recording DIR --tcp 127.0.0.1:5762

  ArduPilot SITL started with --serial1 udpclient:127.0.0.1:14560 (it sends, we answer):
    touchdown companion --recording DIR --udp-listen 127.0.0.1:14560

  PX4 SITL's onboard link (PX4 listens on 14580 and sends to 14540); the fixed local port
  makes a second run reach PX4 again (it answers only the first address it heard):
    touchdown companion --recording DIR --udp 127.0.0.1:14580 --udp-local-port 14540

  Through MAVProxy (`--out tcpin:0.0.0.0:5770`) or anything that connects to us:
    touchdown companion --recording DIR --tcp 127.0.0.1:5770
    touchdown companion --recording DIR --tcp-listen 127.0.0.1:5770

  A flight controller's TELEM port through a USB-serial adapter (SERIALn_BAUD 921):
    touchdown companion --recording DIR --serial /dev/ttyUSB0 --baud 921600

The servers (--udp-listen, --tcp-listen) wait for their first peer before the recording
starts. --tcp ends the run when the autopilot closes the connection (exit status 2);
--tcp-listen waits for the next client. The summary is printed at the end and on SIGINT
(Ctrl-C) or SIGTERM, which exit with status 130 or 143.";

/// Arguments of `touchdown companion`.
#[derive(Debug, Clone, Args)]
#[command(
    after_long_help = EXAMPLES,
    group(
        // Not `required`: clap's message for a missing group lists the options on a line
        // the contract's one-line error drops; `run` names them instead.
        ArgGroup::new("endpoint")
            .args(["udp", "udp_listen", "tcp", "tcp_listen", "serial"])
    )
)]
pub struct CompanionArgs {
    /// UDP client: send to HOST:PORT and read the answers on the same socket (PX4 SITL's
    /// onboard port 14580, MAVProxy's `--out udpin:...`)
    #[arg(long, value_name = "HOST:PORT")]
    pub udp: Option<String>,

    /// Our source port for --udp (default: any free one). PX4 answers only the first address
    /// that reaches its UDP link: a fixed port lets the next run reach it again
    #[arg(long, value_name = "N", requires = "udp")]
    pub udp_local_port: Option<u16>,

    /// UDP server: bind ADDR:PORT, wait for a datagram and answer whoever sent the last one
    /// (ArduPilot SITL `--serial1 udpclient:127.0.0.1:14560`)
    #[arg(long, value_name = "ADDR:PORT")]
    pub udp_listen: Option<String>,

    /// TCP client: connect to HOST:PORT (ArduPilot SITL's 5762, MAVProxy's
    /// `--out tcpin:...`); the run ends if the peer closes
    #[arg(long, value_name = "HOST:PORT")]
    pub tcp: Option<String>,

    /// TCP server: listen on ADDR:PORT for one client at a time (a ground station or bridge)
    #[arg(long, value_name = "ADDR:PORT")]
    pub tcp_listen: Option<String>,

    /// Serial port to the flight controller, e.g. /dev/ttyUSB0
    #[arg(long, value_name = "PATH")]
    pub serial: Option<PathBuf>,

    /// Baud rate of --serial (ArduPilot SERIALn_BAUD 921 = 921600)
    #[arg(
        long,
        allow_negative_numbers = true,
        value_name = "N",
        default_value_t = 921_600,
        requires = "serial"
    )]
    pub baud: u32,

    /// Recording directory (camera.toml, pad.toml, frames/, frames.csv) to replay
    #[arg(long, value_name = "DIR")]
    pub recording: PathBuf,

    /// LANDING_TARGET format: from the autopilot's HEARTBEAT (auto, as the board does by
    /// default: TD_PROFILE 2), or forced (ardupilot TD_PROFILE 0, px4 1,
    /// ardupilot-local-frd 3)
    #[arg(long, value_enum, default_value_t = ProfileArg::Auto)]
    pub profile: ProfileArg,

    /// Seconds of MAVLink before the first frame (time sync, stream requests)
    #[arg(
        long,
        allow_negative_numbers = true,
        value_name = "S",
        default_value_t = 2.0
    )]
    pub lead: f64,

    /// Seconds to keep the link up after the last frame
    #[arg(
        long,
        allow_negative_numbers = true,
        value_name = "S",
        default_value_t = 1.0
    )]
    pub linger: f64,

    /// MAVLink 2 signing (docs/signing.md): hold KEY, 64 hex digits or a passphrase (its
    /// SHA-256, as MAVProxy derives keys), as the board holds a key set by SETUP_SIGNING:
    /// every frame sent is signed, writes are taken only when signed with it
    #[arg(long, value_name = "KEY")]
    pub signing_key: Option<String>,
}

/// `--profile`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ProfileArg {
    /// ArduPilot's or PX4's format, whichever the autopilot's HEARTBEAT names (nothing is sent
    /// until it is heard).
    Auto,
    /// LANDING_TARGET in MAV_FRAME_BODY_FRD (ArduPilot).
    Ardupilot,
    /// LANDING_TARGET in MAV_FRAME_LOCAL_NED (PX4; needs its attitude and local position).
    Px4,
    /// LANDING_TARGET in MAV_FRAME_LOCAL_FRD (ArduPilot 4.7+ with the yaw sign fix; needs its
    /// attitude, else BODY_FRD). Never chosen by auto: HEARTBEAT does not tell the version.
    ArdupilotLocalFrd,
}

impl CompanionArgs {
    /// The link the options name (clap lets at most one through).
    fn endpoint(&self) -> Result<EndpointSpec, CliError> {
        LinkOptions {
            serial: self.serial.as_deref().map(|path| (path, self.baud)),
            tcp: self.tcp.as_deref(),
            tcp_listen: self.tcp_listen.as_deref(),
            udp_listen: self.udp_listen.as_deref(),
            udp: self.udp.as_deref().map(|r| (r, self.udp_local_port)),
        }
        .spec()
        .ok_or_else(|| {
            CliError::new(
                "no link to the autopilot: give one of --udp, --udp-listen, --tcp, --tcp-listen \
                 or --serial (examples: touchdown companion --help)",
            )
        })
    }
}

/// How often the loop looks at the link, the clock and the signals.
const TICK: Duration = Duration::from_millis(1);

/// Runs `touchdown companion`.
///
/// Ends with the summary on stdout in every case the run got going: the recording's end
/// (`Success`), a lost link (the summary, then the error: exit status 2), or SIGINT/SIGTERM
/// (the summary, then [`Outcome::Stopped`] with 130/143: returned, not exited here, so that
/// the endpoint is closed and every buffer flushed on the way out, as after a finished run).
pub fn run(
    args: &CompanionArgs,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<Outcome, CliError> {
    if !(args.lead.is_finite() && args.lead >= 0.0 && args.linger.is_finite() && args.linger >= 0.0)
    {
        return Err(CliError::new(
            "--lead and --linger must be non-negative seconds",
        ));
    }
    let spec = args.endpoint()?;
    let reader = RecordingReader::open(&args.recording).map_err(CliError::new)?;
    let layout = reader
        .pad
        .layout()
        .map_err(|e| CliError(format!("{}: pad.toml: {e:?}", args.recording.display())))?;
    let selected = families::resolve_pad(&reader.pad).map_err(CliError::new)?;
    let views: Vec<Family<'_>> = selected.iter().map(SelectedFamily::family).collect();
    let family_refs: Vec<&Family<'_>> = views.iter().collect();

    // Checked before the endpoint opens (a server waits there for its peer).
    let signing = args
        .signing_key
        .as_deref()
        .map(|text| {
            crate::signing_key::parse(text)
                .map(|key| SigningSecret::new(key, crate::signing_key::timestamp_now()))
                .map_err(|e| CliError(format!("--signing-key: {e}")))
        })
        .transpose()?;
    let endpoint_name = spec.describe();
    interrupt::install().map_err(|e| CliError(format!("signal handlers: {e}")))?;
    let mut endpoint =
        Endpoint::open(&spec).map_err(|e| CliError(format!("{endpoint_name}: {e}")))?;

    let config = match args.profile {
        ProfileArg::Auto => CompanionConfig::default(),
        ProfileArg::Ardupilot => CompanionConfig::with_profile(Profile::ArduPilot),
        ProfileArg::Px4 => CompanionConfig::with_profile(Profile::Px4),
        ProfileArg::ArdupilotLocalFrd => CompanionConfig::with_profile(Profile::ArduPilotLocalFrd),
    };
    let mut companion = Companion::new(config);
    if let Some(secret) = signing {
        companion.set_signing_secret(secret, 0);
    }
    // The camera board's per-frame path, with the parameters applied between frames exactly
    // as its vision task applies them (TD_TAG_SIZE, TD_MAX_HAMMING, TD_CAM_YAW over MAVLink
    // included, and TD_CAM_ROLL/TD_CAM_PITCH when the companion adopts the estimator's mount
    // calibration in `on_estimate`: applied before the next frame), and the estimator reading
    // the vehicle state the companion decodes.
    let pipeline_settings = PipelineSettings::from_params(companion.params());
    let mut pipeline = FramePipeline::new(
        &family_refs,
        &layout,
        reader.camera,
        PipelineConfig::default(),
        pipeline_settings,
    )
    .map_err(|e| CliError(format!("pipeline configuration: {e:?}")))?;
    let mut workspace = HostWorkspace::new();
    let mut counts = RunCounts {
        recording_frames: reader.entries.len(),
        ..RunCounts::default()
    };
    let mut rx = [0u8; 2048];
    let mut tx = [0u8; MAX_FRAME_LEN];

    // A server has nobody to talk to until its first peer comes: the recording's clock
    // starts then, so that the lead time is spent with the autopilot.
    let mut first = 0usize;
    if endpoint.waits_for_peer() {
        let _ = writeln!(
            err,
            "{endpoint_name}: waiting for the autopilot or a bridge"
        );
        let waited = Instant::now();
        while endpoint.peer().is_none() {
            if let Some(signal) = interrupt::received() {
                let stop = Stop::Signal(signal, waited.elapsed());
                return finish(out, &counts, &companion, stop);
            }
            match endpoint.recv(&mut rx) {
                Ok(Received::Bytes(n)) => first = n,
                Ok(Received::Closed) => {}
                Err(e) => {
                    let stop = Stop::LinkLost(format!("{endpoint_name}: {e}"), waited.elapsed());
                    return finish(out, &counts, &companion, stop);
                }
            }
            std::thread::sleep(TICK);
        }
    }

    let start = Instant::now();
    let now_us = || start.elapsed().as_micros() as u64;
    companion.receive(rx.get(..first).unwrap_or(&[]), now_us());
    let mut peer = endpoint.peer();
    if let Some(addr) = peer {
        let _ = writeln!(err, "{endpoint_name}: peer {addr}");
    }
    let lead_us = (args.lead * 1e6) as u64;
    let t0 = reader.entries.first().map_or(0, |e| e.t_us);
    let last = reader.entries.last().map_or(0, |e| e.t_us - t0);
    let end_us = lead_us + last + (args.linger * 1e6) as u64;

    let stop = 'run: loop {
        if now_us() >= end_us {
            break Stop::Finished;
        }
        if let Some(signal) = interrupt::received() {
            break Stop::Signal(signal, start.elapsed());
        }
        if let Err(lost) = endpoint.drain(&mut rx, |bytes| companion.receive(bytes, now_us())) {
            break 'run Stop::LinkLost(format!("{endpoint_name}: {lost}"), start.elapsed());
        }
        if endpoint.peer() != peer {
            peer = endpoint.peer();
            let _ = match peer {
                Some(addr) => writeln!(err, "{endpoint_name}: peer {addr}"),
                None => writeln!(err, "{endpoint_name}: the peer left; waiting for the next"),
            };
        }
        if let Err(e) = pipeline.follow_params(companion.params()) {
            let _ = writeln!(
                err,
                "warning: board settings not all taken ({e:?}): the pad as built or the built camera in their place"
            );
        }
        if let Some(entry) = reader.entries.get(counts.frames) {
            let exposure_us = lead_us + (entry.t_us - t0);
            if now_us() >= exposure_us {
                let frame = reader.frame(counts.frames).map_err(CliError::new)?;
                counts.frames += 1;
                let view = frame.image.view();
                let mut buffers = workspace.buffers(frame.image.width, frame.image.height);
                let report =
                    pipeline.process(&view, exposure_us, companion.vehicle(), &mut buffers);
                if let Some(e) = report.detect_error {
                    let _ = writeln!(err, "warning: frame {}: {e:?}", frame.index);
                }
                let outcome = companion.on_estimate(&report.estimate, now_us());
                if outcome == TargetOutcome::TargetQueued {
                    counts.targets_queued += 1;
                }
            }
        }
        while let Some(n) = companion.poll_transmit(now_us(), &mut tx) {
            match endpoint.send(tx.get(..n).unwrap_or(&[])) {
                Ok(Sent::Sent) => {}
                Ok(Sent::NoPeer) => counts.not_sent_no_peer += 1,
                Err(_) => counts.send_errors += 1,
            }
        }
        std::thread::sleep(TICK);
    };
    finish(out, &counts, &companion, stop)
}

/// Prints the summary and ends the run as `stop` says (see [`run`]).
fn finish(
    out: &mut dyn Write,
    counts: &RunCounts,
    companion: &Companion,
    stop: Stop,
) -> Result<Outcome, CliError> {
    summary::write(out, counts, &companion.stats(), &stop).map_err(CliError::new)?;
    match stop {
        Stop::Finished => Ok(Outcome::Success),
        Stop::LinkLost(reason, _) => Err(CliError(reason)),
        Stop::Signal(signal, _) => Ok(Outcome::Stopped {
            status: signal.exit_status(),
        }),
    }
}
