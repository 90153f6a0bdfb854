//! `touchdown companion`: the board's MAVLink companion logic against a real endpoint.
//!
//! Runs the same per-frame path as the camera board (`touchdown_core::pipeline::FramePipeline`,
//! with the TD_* parameters applied between frames as the board applies them, then
//! `touchdown_core::companion::Companion`) on a recording, in real time at the recording's
//! frame times, and exchanges MAVLink with a flight controller or SITL over UDP or a serial
//! port: with `--udp HOST:PORT` a datagram socket sends there (for example MAVProxy's
//! `--out udpin:0.0.0.0:14550` or PX4 SITL's onboard port 14540) and reads whatever comes back
//! on the same socket; with `--serial PATH --baud N` it talks to a real flight controller's
//! TELEM port through a USB-serial adapter, exactly as the board would (8N1, raw, no flow
//! control; Linux/Unix termios). The companion state machine is sans-IO, so this file is only
//! the loop: read bytes, feed frames when due, drain `poll_transmit` into the endpoint.

use std::fs::File;
use std::io::{ErrorKind, Read, Write};
use std::net::UdpSocket;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::{Args, ValueEnum};
use touchdown_core::companion::{
    Companion, CompanionConfig, Profile, TargetLatency, TargetOutcome, TimeSource, MAX_FRAME_LEN,
};
use touchdown_core::family::Family;
use touchdown_core::params::PipelineSettings;
use touchdown_core::pipeline::{FramePipeline, PipelineConfig};

use super::{CliError, Outcome};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_formats::families::{self, SelectedFamily};
use touchdown_formats::recording::RecordingReader;

/// Arguments of `touchdown companion`.
#[derive(Debug, Clone, Args)]
pub struct CompanionArgs {
    /// MAVLink endpoint to send to (UDP), e.g. 127.0.0.1:14550
    #[arg(
        long,
        value_name = "HOST:PORT",
        conflicts_with = "serial",
        required_unless_present = "serial"
    )]
    pub udp: Option<String>,

    /// Serial port to the flight controller instead of UDP, e.g. /dev/ttyUSB0
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
    /// default: TD_PROFILE 2), or forced
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
}

/// The exposure-to-send delay of the targets sent, for the summary line (empty when none).
fn latency_summary(latency: &TargetLatency) -> String {
    match latency.mean_us() {
        Some(mean) => format!(
            " (exposure to send: mean {:.1} ms, max {:.1} ms)",
            f64::from(mean) / 1000.0,
            f64::from(latency.max_us) / 1000.0
        ),
        None => String::new(),
    }
}

/// The autopilot as the summary names it.
fn autopilot_summary(autopilot: Option<(u8, u8)>) -> String {
    match autopilot {
        Some((system, component)) => format!("autopilot {system}/{component}"),
        None => "no autopilot heard".to_string(),
    }
}

/// The clock offset as the summary gives it: autopilot minus our clock, and where it is from.
fn clock_summary(offset_us: Option<i64>, source: Option<TimeSource>) -> String {
    match (offset_us, source) {
        (Some(offset), Some(TimeSource::Timesync)) => {
            format!("autopilot clock {offset:+} us from ours (TIMESYNC)")
        }
        (Some(offset), Some(TimeSource::SystemTime)) => {
            format!("autopilot clock {offset:+} us from ours (SYSTEM_TIME, coarse)")
        }
        _ => "autopilot clock unknown (no TIMESYNC or SYSTEM_TIME answer)".to_string(),
    }
}

/// Where MAVLink goes: a UDP socket or a serial port, both non-blocking.
enum Endpoint {
    Udp(UdpSocket),
    Serial(File),
}

impl Endpoint {
    /// Opens `--udp` or `--serial`.
    fn open(args: &CompanionArgs) -> Result<(Endpoint, String), CliError> {
        if let Some(path) = &args.serial {
            let name = path.display().to_string();
            let file = open_serial(path, args.baud)
                .map_err(|e| CliError(format!("--serial {name}: {e}")))?;
            return Ok((Endpoint::Serial(file), format!("--serial {name}")));
        }
        let addr = args.udp.as_deref().unwrap_or_default();
        let name = format!("--udp {addr}");
        let socket = UdpSocket::bind("0.0.0.0:0").map_err(CliError::new)?;
        socket
            .connect(addr)
            .map_err(|e| CliError(format!("{name}: {e}")))?;
        socket.set_nonblocking(true).map_err(CliError::new)?;
        Ok((Endpoint::Udp(socket), name))
    }

    /// Bytes received, 0 when nothing is waiting.
    fn recv(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let r = match self {
            Endpoint::Udp(s) => s.recv(buf),
            Endpoint::Serial(f) => f.read(buf),
        };
        match r {
            Ok(n) => Ok(n),
            Err(e) if e.kind() == ErrorKind::WouldBlock => Ok(0),
            // ICMP "port unreachable" until the UDP endpoint is up: keep going.
            Err(e) if e.kind() == ErrorKind::ConnectionRefused => Ok(0),
            Err(e) => Err(e),
        }
    }

    /// Sends one MAVLink frame.
    fn send(&mut self, frame: &[u8]) -> std::io::Result<()> {
        match self {
            Endpoint::Udp(s) => s.send(frame).map(|_| ()),
            Endpoint::Serial(f) => f.write_all(frame),
        }
    }
}

/// Opens a serial port raw (8N1, no echo, no flow control, non-blocking) at `baud`.
fn open_serial(path: &std::path::Path, baud: u32) -> std::io::Result<File> {
    use rustix::fs::{Mode, OFlags};
    use rustix::termios::{self, ControlModes, OptionalActions};
    // NOCTTY: the port must not become our controlling terminal.
    let fd = rustix::fs::open(
        path,
        OFlags::RDWR | OFlags::NOCTTY | OFlags::NONBLOCK | OFlags::CLOEXEC,
        Mode::empty(),
    )?;
    let mut t = termios::tcgetattr(&fd)?;
    t.make_raw();
    // Ignore modem lines (CLOCAL), enable the receiver (CREAD), no hardware flow control.
    t.control_modes |= ControlModes::CLOCAL | ControlModes::CREAD;
    t.control_modes -= ControlModes::CRTSCTS;
    t.set_speed(baud)?;
    termios::tcsetattr(&fd, OptionalActions::Now, &t)?;
    termios::tcflush(&fd, termios::QueueSelector::IFlush)?;
    Ok(File::from(fd))
}

/// Runs `touchdown companion`.
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
    let reader = RecordingReader::open(&args.recording).map_err(CliError::new)?;
    let layout = reader
        .pad
        .layout()
        .map_err(|e| CliError(format!("{}: pad.toml: {e:?}", args.recording.display())))?;
    let selected = families::resolve_pad(&reader.pad).map_err(CliError::new)?;
    let views: Vec<Family<'_>> = selected.iter().map(SelectedFamily::family).collect();
    let family_refs: Vec<&Family<'_>> = views.iter().collect();

    let (mut endpoint, endpoint_name) = Endpoint::open(args)?;

    let config = match args.profile {
        ProfileArg::Auto => CompanionConfig::default(),
        ProfileArg::Ardupilot => CompanionConfig::with_profile(Profile::ArduPilot),
        ProfileArg::Px4 => CompanionConfig::with_profile(Profile::Px4),
    };
    let mut companion = Companion::new(config);
    // The camera board's per-frame path, with the parameters applied between frames exactly
    // as its vision task applies them (TD_TAG_SIZE, TD_MAX_HAMMING, TD_CAM_YAW over MAVLink
    // included, and TD_CAM_ROLL/TD_CAM_PITCH when the companion adopts the estimator's mount
    // calibration in `on_estimate`: applied before the next frame), and the estimator reading
    // the vehicle state the companion decodes.
    let mut pipeline_settings = PipelineSettings::from_params(companion.params());
    let mut pipeline = FramePipeline::new(
        &family_refs,
        &layout,
        reader.camera,
        PipelineConfig::default(),
        pipeline_settings,
    )
    .map_err(|e| CliError(format!("pipeline configuration: {e:?}")))?;
    let mut workspace = HostWorkspace::new();

    let start = Instant::now();
    let now_us = || start.elapsed().as_micros() as u64;
    let lead_us = (args.lead * 1e6) as u64;
    let t0 = reader.entries.first().map_or(0, |e| e.t_us);
    let last = reader.entries.last().map_or(0, |e| e.t_us - t0);
    let end_us = lead_us + last + (args.linger * 1e6) as u64;
    let mut next = 0usize;
    let mut rx = [0u8; 2048];
    let mut tx = [0u8; MAX_FRAME_LEN];
    let mut targets = 0usize;
    let mut send_errors = 0usize;

    while now_us() < end_us {
        loop {
            match endpoint.recv(&mut rx) {
                Ok(0) => break,
                Ok(n) => companion.receive(rx.get(..n).unwrap_or(&[]), now_us()),
                Err(e) => return Err(CliError(format!("{endpoint_name}: {e}"))),
            }
        }
        let settings = PipelineSettings::from_params(companion.params());
        if settings != pipeline_settings {
            if let Err(e) = pipeline.apply(settings) {
                let _ = writeln!(
                    err,
                    "warning: pad not scaled ({e:?}): searching it as built"
                );
            }
            pipeline_settings = settings;
        }
        if let Some(entry) = reader.entries.get(next) {
            let exposure_us = lead_us + (entry.t_us - t0);
            if now_us() >= exposure_us {
                next += 1;
                let frame = reader.frame(next - 1).map_err(CliError::new)?;
                let view = frame.image.view();
                let mut buffers = workspace.buffers(frame.image.width, frame.image.height);
                let report =
                    pipeline.process(&view, exposure_us, companion.vehicle(), &mut buffers);
                if let Some(e) = report.detect_error {
                    let _ = writeln!(err, "warning: frame {}: {e:?}", frame.index);
                }
                let outcome = companion.on_estimate(&report.estimate, now_us());
                if outcome == TargetOutcome::TargetQueued {
                    targets += 1;
                }
            }
        }
        while let Some(n) = companion.poll_transmit(now_us(), &mut tx) {
            if endpoint.send(tx.get(..n).unwrap_or(&[])).is_err() {
                send_errors += 1;
            }
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let s = companion.stats();
    writeln!(
        out,
        "{next} frames, {targets} LANDING_TARGET queued, {} sent{}; tx {} frames ({send_errors} \
         send errors); rx {} frames ({} with a bad CRC, {} of messages outside the \
         common dialect, skipped; {} garbage bytes); {}; {}",
        s.landing_targets,
        latency_summary(&s.target_latency),
        s.tx_frames,
        s.link.frames,
        s.link.bad_crc,
        s.link.unknown,
        s.link.garbage_bytes,
        autopilot_summary(s.autopilot),
        clock_summary(s.clock_offset_us, s.time_source)
    )
    .map_err(CliError::new)?;
    Ok(Outcome::Success)
}
