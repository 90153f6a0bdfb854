//! `touchdown board`: the board's lens and pad set from files, over MAVLink, and read back.
//!
//! The lens and the pad's design are board parameters (TD_CAM_FX ... TD_CAM_K3, TD_PAD,
//! TD_TAG_SIZE: `touchdown_core::params`), saved by the board in its power-safe parameter
//! flash, so this tool is a ground station that knows which parameters a CAMERA.toml or a
//! pad means: it checks the file first (a file that does not make a camera or a shipped pad
//! for this board is a one-line error and nothing is sent), then writes each parameter with
//! PARAM_SET and waits for the board's PARAM_VALUE, and finally reads them all back. With
//! `--signing-key` every frame is signed (MAVLink 2, link 0) as a board with a key requires.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use clap::{Args, Subcommand};
use touchdown_core::camera::CameraModel;
use touchdown_core::companion::mavlink::dialects::common::{
    MavMessage, MavParamType, PARAM_REQUEST_READ_DATA, PARAM_SET_DATA,
};
use touchdown_core::companion::mavlink::Message;
use touchdown_core::companion::FrameParser;
use touchdown_core::crc::crc16_x25;
use touchdown_core::params::{ParamId, PAD_DESIGNS};
use touchdown_core::sha256::Sha256;
use touchdown_formats::camera::load_camera;
use touchdown_formats::pad::{config_of_layout, load_pad, PadConfig};

use super::companion::endpoint::{Endpoint, EndpointSpec, LinkOptions, Received};
use super::sitl::gcs::gcs_frame;
use super::{signing_key, CliError, Outcome};

/// `--help`'s long text.
pub const LONG_HELP: &str = "\
Set the board's lens or pad from a file, over MAVLink, and read it back.

The link is the board's UART: through the flight controller (which routes MAVLink between its \
ports), or a USB-serial adapter on the board's TX and RX. `set-camera CAMERA.toml` writes the \
lens (TD_CAM_FX, TD_CAM_FY, TD_CAM_CX, TD_CAM_CY, TD_CAM_K1, TD_CAM_K2, TD_CAM_P1, \
TD_CAM_P2, TD_CAM_K3) in the pixels of the board's frames: the file must be 320x240 (a QVGA \
board), 640x400 (a VGA board) or 320x200 (a VGA board's halved frames, as `touchdown view \
--record` records them; scaled back). `set-pad DESIGN|pad.toml` chooses a shipped design \
(TD_PAD), by name or by a pad.toml that is one (at any scale: TD_TAG_SIZE is set to its \
largest marker); a layout of your own still needs a firmware build. `reset-camera` puts the \
build's lens back (all nine at 0). `show` reads them.

Each parameter is written with PARAM_SET and confirmed by the board's PARAM_VALUE (three \
tries). Errors (one line, exit status 2), before anything is sent: a file that cannot be read \
or is not a camera or pad for the board; after: a board that does not answer, refuses (a \
signing key or the flight lock, TD_LOCK, while armed: its STATUSTEXT is quoted) or keeps \
another value.";

/// Options of `touchdown board`.
#[derive(Debug, Args)]
pub struct BoardArgs {
    /// UDP HOST:PORT to send to (a flight controller's or a MAVLink router's port).
    #[arg(long, value_name = "HOST:PORT", conflicts_with_all = ["tcp", "serial"])]
    pub udp: Option<String>,
    /// TCP HOST:PORT to connect to.
    #[arg(long, value_name = "HOST:PORT", conflicts_with = "serial")]
    pub tcp: Option<String>,
    /// A serial port (the board's UART through a USB adapter, or the flight controller's USB).
    #[arg(long, value_name = "PATH")]
    pub serial: Option<PathBuf>,
    /// Baud rate of --serial.
    #[arg(long, value_name = "N", default_value_t = 921_600, requires = "serial")]
    pub baud: u32,
    /// The board's MAVLink system id (TD_SYSID).
    #[arg(long, default_value_t = 1)]
    pub sysid: u8,
    /// The board's component id (TD_COMPID).
    #[arg(long, default_value_t = 191)]
    pub compid: u8,
    /// MAVLink 2 signing key of the board (64 hex digits or a passphrase; docs/signing.md).
    #[arg(long, value_name = "KEY")]
    pub signing_key: Option<String>,
    /// Seconds to wait for each answer.
    #[arg(long, default_value_t = 1.5)]
    pub timeout: f64,
    /// What to do.
    #[command(subcommand)]
    pub action: BoardAction,
}

/// `touchdown board`'s actions.
#[derive(Debug, Subcommand)]
pub enum BoardAction {
    /// Write the lens of CAMERA.toml (its size must be the board's frames').
    SetCamera {
        /// The camera file (`touchdown calibrate-lens --out`).
        camera: PathBuf,
    },
    /// Put the build's lens back (TD_CAM_* all 0).
    ResetCamera,
    /// Choose a shipped pad design, by name or by a pad.toml that is one.
    SetPad {
        /// `nested-field`, `nested-rest`, `nested`, `paper-single`, or a pad.toml.
        pad: String,
    },
    /// Read the lens and pad parameters.
    Show,
}

/// The lens parameters, in the table's order.
const LENS: [ParamId; 9] = [
    ParamId::CamFx,
    ParamId::CamFy,
    ParamId::CamCx,
    ParamId::CamCy,
    ParamId::CamK1,
    ParamId::CamK2,
    ParamId::CamP1,
    ParamId::CamP2,
    ParamId::CamK3,
];

/// Tries per parameter.
const TRIES: u32 = 3;

/// A frame size, width and height.
type Size = (u32, u32);

/// The frame sizes a camera file may have, the factor to the board's own pixels, and the
/// board's frame size.
const FRAME_SIZES: [(Size, f32, Size); 3] = [
    // A QVGA board.
    ((320, 240), 1.0, (320, 240)),
    // A VGA board (the sensor's middle 400 rows).
    ((640, 400), 1.0, (640, 400)),
    // A VGA board's halved frames, as `touchdown view --record` records them.
    ((320, 200), 2.0, (640, 400)),
];

/// The lens parameters a camera file means for the board.
pub fn lens_values(camera: &CameraModel) -> Result<Vec<(ParamId, f32)>, String> {
    camera
        .validate()
        .map_err(|e| format!("not a usable camera ({e:?})"))?;
    let size = (camera.width, camera.height);
    let Some((_, scale, board_size)) = FRAME_SIZES.iter().find(|(s, _, _)| *s == size) else {
        return Err(format!(
            "the camera is {}x{}; the board's frames are 320x240 (QVGA) or 640x400 (VGA; 320x200 \
             halved): calibrate on frames recorded from the board (touchdown view --record)",
            size.0, size.1
        ));
    };
    let values = lens_parameters(&camera.resampled(*scale, board_size.0, board_size.1));
    for &(id, value) in &values {
        let def = id.def();
        // 0 would mean "the build's": a principal point on the top-left pixel is not a lens.
        if !(value >= def.min && value <= def.max) {
            return Err(format!(
                "{} {value} is outside the board's range {} to {}",
                def.name, def.min, def.max
            ));
        }
    }
    Ok(values.to_vec())
}

/// The lens parameters (TD_CAM_*, in the table's order) of `camera`, which must already be
/// in the pixels of the board's frames.
pub fn lens_parameters(camera: &CameraModel) -> [(ParamId, f32); 9] {
    let [k1, k2, p1, p2, k3] = camera.distortion;
    let values = [
        camera.fx, camera.fy, camera.cx, camera.cy, k1, k2, p1, p2, k3,
    ];
    core::array::from_fn(|i| (LENS[i], values[i]))
}

/// TD_PAD (and TD_TAG_SIZE) for a design's name or a pad.toml that is a shipped design.
pub fn pad_values(spec: &str) -> Result<Vec<(ParamId, f32)>, String> {
    if let Some(i) = PAD_DESIGNS.iter().position(|d| d.name() == spec) {
        return Ok(vec![(ParamId::Pad, (i + 1) as f32)]);
    }
    let path = Path::new(spec);
    if !path.exists() {
        let names: Vec<&str> = PAD_DESIGNS.iter().map(|d| d.name()).collect();
        return Err(format!(
            "{spec}: neither a shipped design ({}) nor a pad.toml",
            names.join(", ")
        ));
    }
    let pad = load_pad(path).map_err(|e| e.to_string())?;
    let largest = |p: &PadConfig| p.markers.iter().map(|m| m.size).fold(0.0, f64::max);
    for (i, design) in PAD_DESIGNS.iter().enumerate() {
        let built = config_of_layout(design);
        let scale = largest(&pad) / largest(&built);
        let same = pad.markers.len() == built.markers.len()
            && pad.markers.iter().zip(&built.markers).all(|(a, b)| {
                let near = |x: f64, y: f64| (x - y * scale).abs() <= 1e-4 * scale.max(1e-9);
                a.family.eq_ignore_ascii_case(&b.family)
                    && a.id == b.id
                    && near(a.size, b.size)
                    && near(a.x, b.x)
                    && near(a.y, b.y)
                    && (a.yaw_deg - b.yaw_deg).abs() < 1e-3
            });
        if same {
            let tag_size = largest(&pad) as f32;
            let def = ParamId::TagSize.def();
            if !(tag_size >= def.min && tag_size <= def.max) {
                return Err(format!(
                    "{spec}: its largest marker, {tag_size} m, is outside TD_TAG_SIZE's {} to {} m",
                    def.min, def.max
                ));
            }
            return Ok(vec![
                (ParamId::Pad, (i + 1) as f32),
                (ParamId::TagSize, tag_size),
            ]);
        }
    }
    Err(format!(
        "{spec}: a layout of its own, not a shipped design at some scale: the board takes only \
         shipped designs without a firmware build (firmware/src/config.rs)"
    ))
}

/// The link to the board and what it said.
struct BoardLink {
    endpoint: Endpoint,
    describe: String,
    parser: FrameParser,
    sequence: u8,
    key: Option<[u8; 32]>,
    timestamp: u64,
    board: (u8, u8),
    /// The newest PARAM_VALUEs by name, and the STATUSTEXTs, since the last take.
    values: Vec<(String, f32)>,
    texts: Vec<String>,
}

impl BoardLink {
    /// Sends `message`, signed when a key is held.
    fn send(&mut self, message: &MavMessage) -> Result<(), CliError> {
        let mut frame = gcs_frame(self.sequence, message);
        self.sequence = self.sequence.wrapping_add(1);
        if let Some(key) = &self.key {
            self.timestamp += 1;
            frame = signed(&frame, message.message_id(), key, self.timestamp);
        }
        self.endpoint
            .send(&frame)
            .map(|_| ())
            .map_err(|e| CliError(format!("{}: {e}", self.describe)))
    }

    /// Reads what came for up to `wait`, or until `done` says enough.
    fn pump(&mut self, wait: Duration, done: impl Fn(&Self) -> bool) -> Result<(), CliError> {
        let until = Instant::now() + wait;
        let mut buf = [0u8; 2048];
        while Instant::now() < until && !done(self) {
            match self
                .endpoint
                .recv(&mut buf)
                .map_err(|e| CliError(format!("{}: {e}", self.describe)))?
            {
                Received::Closed => {
                    return Err(CliError(format!(
                        "{}: the peer closed the link",
                        self.describe
                    )))
                }
                Received::Bytes(0) => std::thread::sleep(Duration::from_millis(2)),
                Received::Bytes(n) => {
                    let board = self.board;
                    let mut values = Vec::new();
                    let mut texts = Vec::new();
                    self.parser.push(&buf[..n], |frame| {
                        if (frame.system_id, frame.component_id) != board {
                            return;
                        }
                        match MavMessage::parse(frame.version, frame.message_id, frame.payload) {
                            Ok(MavMessage::PARAM_VALUE(v)) => values.push((
                                v.param_id.to_str().unwrap_or("").to_string(),
                                v.param_value,
                            )),
                            Ok(MavMessage::STATUSTEXT(t)) => {
                                texts.push(t.text.to_str().unwrap_or("").to_string())
                            }
                            _ => {}
                        }
                    });
                    self.values.extend(values);
                    self.texts.extend(texts);
                }
            }
        }
        Ok(())
    }

    fn value(&self, name: &str) -> Option<f32> {
        self.values
            .iter()
            .rev()
            .find(|(n, _)| n == name)
            .map(|&(_, v)| v)
    }

    /// Writes one parameter and returns the value the board answers it holds.
    fn write(&mut self, id: ParamId, value: f32, wait: Duration) -> Result<f32, CliError> {
        let name = id.def().name;
        for _ in 0..TRIES {
            self.values.clear();
            self.texts.clear();
            self.send(&MavMessage::PARAM_SET(PARAM_SET_DATA {
                param_value: value,
                target_system: self.board.0,
                target_component: self.board.1,
                param_id: name.into(),
                param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
            }))?;
            self.pump(wait, |l| l.value(name).is_some())?;
            if let Some(v) = self.value(name) {
                // A refusal answers with the old value and says why.
                if (v - value).abs() > 1e-4 * value.abs().max(1.0) {
                    self.pump(Duration::from_millis(200), |_| false)?;
                    let why = self
                        .texts
                        .iter()
                        .find(|t| t.contains("refused") || t.contains("TD_"))
                        .cloned()
                        .unwrap_or_else(|| "no reason given".to_string());
                    return Err(CliError(format!(
                        "the board kept {name} at {v} (asked {value}): {why}"
                    )));
                }
                return Ok(v);
            }
        }
        Err(CliError(format!(
            "{}: no answer to PARAM_SET {name} from the board ({}, {}) after {TRIES} tries",
            self.describe, self.board.0, self.board.1
        )))
    }

    /// Reads one parameter.
    fn read(&mut self, id: ParamId, wait: Duration) -> Result<f32, CliError> {
        let name = id.def().name;
        for _ in 0..TRIES {
            self.values.clear();
            self.send(&MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
                param_index: -1,
                target_system: self.board.0,
                target_component: self.board.1,
                param_id: name.into(),
            }))?;
            self.pump(wait, |l| l.value(name).is_some())?;
            if let Some(v) = self.value(name) {
                return Ok(v);
            }
        }
        Err(CliError(format!(
            "{}: no answer to PARAM_REQUEST_READ {name} from the board ({}, {}) after {TRIES} tries",
            self.describe, self.board.0, self.board.1
        )))
    }
}

/// `frame` (MAVLink 2, unsigned) signed with `key` at `timestamp` on link 0: the signed flag
/// set, the checksum over the new header, then link id, timestamp and the SHA-256 tag.
fn signed(frame: &[u8], message_id: u32, key: &[u8; 32], timestamp: u64) -> Vec<u8> {
    let mut out = frame.to_vec();
    if out.len() < 12 {
        return out;
    }
    out[2] |= 0x01;
    let end = out.len() - 2;
    let extra = MavMessage::extra_crc(message_id);
    let crc = crc16_x25(crc16_x25(0xFFFF, &out[1..end]), &[extra]);
    out[end..].copy_from_slice(&crc.to_le_bytes());
    let link_id = 0u8;
    let stamp = &timestamp.to_le_bytes()[..6];
    let mut h = Sha256::new();
    h.update(key);
    h.update(&out);
    h.update(&[link_id]);
    h.update(stamp);
    let tag = h.finish();
    out.push(link_id);
    out.extend_from_slice(stamp);
    out.extend_from_slice(&tag[..6]);
    out
}

impl BoardArgs {
    fn endpoint(&self) -> Result<EndpointSpec, CliError> {
        LinkOptions {
            serial: self.serial.as_deref().map(|path| (path, self.baud)),
            tcp: self.tcp.as_deref(),
            udp: self.udp.as_deref().map(|r| (r, None)),
            ..LinkOptions::default()
        }
        .spec()
        .ok_or_else(|| CliError::new("no link to the board: give one of --udp, --tcp or --serial"))
    }
}

/// Runs `touchdown board`.
pub fn run(
    args: &BoardArgs,
    out: &mut dyn Write,
    _err: &mut dyn Write,
) -> Result<Outcome, CliError> {
    if !(args.timeout.is_finite() && args.timeout > 0.0) {
        return Err(CliError::new(
            "--timeout: must be a number of seconds over 0",
        ));
    }
    // The file first: nothing is sent for a file that is not a lens or pad for the board.
    let writes: Vec<(ParamId, f32)> = match &args.action {
        BoardAction::SetCamera { camera } => {
            let model = load_camera(camera).map_err(CliError::new)?;
            lens_values(&model).map_err(|e| CliError(format!("{}: {e}", camera.display())))?
        }
        BoardAction::ResetCamera => LENS.iter().map(|&id| (id, 0.0)).collect(),
        BoardAction::SetPad { pad } => pad_values(pad).map_err(CliError)?,
        BoardAction::Show => Vec::new(),
    };
    let key = match &args.signing_key {
        Some(text) => {
            Some(signing_key::parse(text).map_err(|e| CliError(format!("--signing-key: {e}")))?)
        }
        None => None,
    };
    let spec = args.endpoint()?;
    let describe = spec.describe();
    let endpoint =
        Endpoint::open(&spec).map_err(|e| CliError(format!("{describe}: cannot open: {e}")))?;
    let mut link = BoardLink {
        endpoint,
        describe,
        parser: FrameParser::new(),
        sequence: 0,
        key,
        timestamp: signing_key::timestamp_now(),
        board: (args.sysid, args.compid),
        values: Vec::new(),
        texts: Vec::new(),
    };
    let wait = Duration::from_secs_f64(args.timeout);
    let werr = |e: std::io::Error| CliError(format!("stdout: {e}"));
    for &(id, value) in &writes {
        let got = link.write(id, value, wait)?;
        writeln!(out, "{} = {got} (set)", id.def().name).map_err(werr)?;
    }
    let shown: Vec<ParamId> = match &args.action {
        BoardAction::SetPad { .. } => vec![ParamId::Pad, ParamId::TagSize],
        BoardAction::Show => {
            let mut all = LENS.to_vec();
            all.extend([ParamId::Pad, ParamId::TagSize]);
            all
        }
        _ => LENS.to_vec(),
    };
    // Read back: what the board holds now (and, after a reboot, restores).
    for id in shown {
        let value = link.read(id, wait)?;
        if let Some(&(_, want)) = writes.iter().find(|(w, _)| *w == id) {
            if (value - want).abs() > 1e-4 * want.abs().max(1.0) {
                return Err(CliError(format!(
                    "read back {} = {value}, {want} was set",
                    id.def().name
                )));
            }
        }
        writeln!(out, "{} = {value}", id.def().name).map_err(werr)?;
    }
    Ok(Outcome::Success)
}
