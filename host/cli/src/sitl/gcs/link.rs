//! The ground station's link to the autopilot: the socket, the autopilot's identity and what
//! it last reported, its parameters read and written (in each autopilot's encoding), and
//! [`prepare`]: connect, identify, set the recipe, reboot once where it is needed.

use std::collections::HashMap;
use std::io::Write;
use std::time::{Duration, Instant};

use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavParamType, MavResult, MavSeverity, MavState,
    MavType, COMMAND_LONG_DATA, HEARTBEAT_DATA, PARAM_REQUEST_READ_DATA, PARAM_SET_DATA,
    SETUP_SIGNING_DATA,
};
use touchdown_core::companion::mavlink::error::ParserError;
use touchdown_core::companion::mavlink::{
    MAVLinkV2MessageRaw, MavHeader, MavlinkVersion, MessageData,
};
use touchdown_core::companion::FrameParser;

use super::{recipe, Autopilot, Plan, SIM_GPS_SWITCHES};
use crate::companion::endpoint::{Endpoint, EndpointSpec};
use crate::CliError;

/// Our system id: the ground station's customary 255.
const GCS_SYSTEM_ID: u8 = 255;
/// Our component id: MAV_COMP_ID_MISSIONPLANNER.
const GCS_COMPONENT_ID: u8 = 190;
/// How long a connection to a SITL that is not there yet is retried.
pub const CONNECT_PATIENCE: Duration = Duration::from_secs(10);
/// How long to wait for the autopilot's first HEARTBEAT.
const HEARTBEAT_PATIENCE: Duration = Duration::from_secs(30);
/// How long a rebooting SITL may take to answer again.
const REBOOT_PATIENCE: Duration = Duration::from_secs(60);
/// A parameter read or write is retried this often, each try waiting [`PARAM_TRY`].
const PARAM_TRIES: u32 = 3;
/// How long each of a parameter read's or write's tries waits for the answer by default
/// (`--param-timeout`).
pub const PARAM_TRY: Duration = Duration::from_millis(1500);

/// The vehicle as the ground-station link reports it.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Status {
    /// HEARTBEAT: armed.
    pub armed: bool,
    /// HEARTBEAT: the flight mode.
    pub custom_mode: u32,
    /// GLOBAL_POSITION_INT: the autopilot's own altitude AMSL, metres.
    pub altitude_m: Option<f64>,
    /// The estimator has its origin: a GPS_GLOBAL_ORIGIN came, or ArduPilot said "origin set".
    pub origin_set: bool,
}

/// A parameter as the autopilot last reported it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ParamValue {
    value: f32,
    kind: MavParamType,
}

/// The SITL's GPS switch, found by [`prepare`] for a GPS-denied rehearsal.
#[derive(Debug, Clone, PartialEq)]
pub struct GpsSwitch {
    /// SIM_GPS1_ENABLE or SIM_GPS_DISABLE.
    pub name: String,
    /// The value that turns the simulated GPS off.
    pub off: f32,
    /// Its type, for the PARAM_SET.
    kind: MavParamType,
}

/// MAVLink's COMMAND_LONG id and CRC extra.
const COMMAND_LONG_ID: u32 = 76;
/// See [`COMMAND_LONG_ID`].
const COMMAND_LONG_EXTRA_CRC: u8 = 152;
/// COMMAND_ACK's id.
const COMMAND_ACK_ID: u32 = 77;

/// A COMMAND_LONG with a command number the common dialect lacks (ArduPilot's own, e.g.
/// MAV_CMD_SET_EKF_SOURCE_SET 42007), serialised by hand: the dialect's `MavCmd` cannot hold it.
struct RawCommandLong {
    params: [f32; 7],
    command: u16,
    target_system: u8,
}

impl MessageData for RawCommandLong {
    type Message = MavMessage;
    const ID: u32 = COMMAND_LONG_ID;
    const NAME: &'static str = "COMMAND_LONG";
    const EXTRA_CRC: u8 = COMMAND_LONG_EXTRA_CRC;
    const ENCODED_LEN: usize = 33;

    fn ser(&self, _version: MavlinkVersion, payload: &mut [u8]) -> usize {
        // The wire order: the seven floats, command, target system, target component,
        // confirmation; MAVLink 2 trims the trailing zeros.
        let mut bytes = [0u8; 33];
        for (k, p) in self.params.iter().enumerate() {
            bytes[4 * k..4 * k + 4].copy_from_slice(&p.to_le_bytes());
        }
        bytes[28..30].copy_from_slice(&self.command.to_le_bytes());
        bytes[30] = self.target_system;
        bytes[31] = 1;
        let len = bytes.iter().rposition(|b| *b != 0).map_or(1, |k| k + 1);
        let n = len.min(payload.len());
        payload[..n].copy_from_slice(&bytes[..n]);
        n
    }

    fn deser(_version: MavlinkVersion, _payload: &[u8]) -> Result<Self, ParserError> {
        Err(ParserError::UnknownMessage {
            id: COMMAND_LONG_ID,
        })
    }
}

/// The ground station's link: the socket, the autopilot's identity and what it last said.
pub struct GcsLink {
    spec: EndpointSpec,
    endpoint: Endpoint,
    parser: FrameParser,
    sequence: u8,
    /// The autopilot's system id (from its first HEARTBEAT).
    pub(super) system_id: u8,
    /// Which autopilot.
    pub autopilot: Autopilot,
    /// What it last reported.
    pub status: Status,
    params: HashMap<String, ParamValue>,
    acks: Vec<(MavCmd, MavResult)>,
    /// COMMAND_ACKs of commands the dialect lacks: command number, result.
    raw_acks: Vec<(u16, u8)>,
    /// The SITL's GPS switch, for a GPS-denied rehearsal.
    pub gps_switch: Option<GpsSwitch>,
    /// Its STATUSTEXTs, with the run's seconds when they came.
    pub texts: Vec<(f64, String)>,
    /// A chunked STATUSTEXT so far: its `id` and text.
    chunks: Option<(u16, String)>,
    next_heartbeat: Instant,
    /// The run's clock offset: [`GcsLink::texts`] are stamped in the board loop's seconds.
    clock_zero: Instant,
    /// How long each try of a parameter read or write waits ([`PARAM_TRY`] unless the plan
    /// says otherwise).
    param_try: Duration,
}

impl GcsLink {
    fn describe(&self) -> String {
        format!("--gcs {}", describe_spec(&self.spec))
    }

    /// Stamps the autopilot's STATUSTEXTs in seconds from `zero` from now on.
    pub fn set_clock_zero(&mut self, zero: Instant) {
        self.clock_zero = zero;
    }

    /// Reads what arrived and sends our HEARTBEAT once a second; STATUSTEXTs are echoed to
    /// `err` as they come.
    pub fn pump(&mut self, err: &mut dyn Write) -> Result<(), CliError> {
        let (messages, drained) = self.receive();

        for (_, message) in messages {
            self.take(&message, err);
        }
        drained?;
        self.heartbeat_when_due()
    }

    /// The messages that arrived from component 1 of the autopilot's system (of any system
    /// until the autopilot is known, `system_id` 0), with their sender's system id; and
    /// whether the link still stands (what arrived before it fell is returned too).
    fn receive(&mut self) -> (Vec<(u8, MavMessage)>, Result<(), CliError>) {
        let mut rx = [0u8; 4096];
        let mut messages = Vec::new();
        let parser = &mut self.parser;
        let raw_acks = &mut self.raw_acks;
        let system_id = self.system_id;
        let drained = self.endpoint.drain(&mut rx, |bytes| {
            parser.push(bytes, |frame| {
                let ours = system_id == 0 || frame.system_id == system_id;
                if ours && frame.component_id == 1 {
                    match frame.decode() {
                        Ok(message) => messages.push((frame.system_id, message)),
                        // A COMMAND_ACK of a command the dialect lacks: command, result (the
                        // payload's first three bytes; MAVLink 2 trims trailing zeros).
                        Err(_) if frame.message_id == COMMAND_ACK_ID => {
                            let byte = |k: usize| frame.payload.get(k).copied().unwrap_or(0);
                            raw_acks.push((u16::from_le_bytes([byte(0), byte(1)]), byte(2)));
                        }
                        Err(_) => {}
                    }
                }
            });
        });
        let drained = drained.map_err(|lost| CliError(format!("{}: {lost}", self.describe())));
        (messages, drained)
    }

    /// Our HEARTBEAT, once a second: it tells a UDP autopilot where we are, and an
    /// autopilot's ground-station failsafe that we are there.
    fn heartbeat_when_due(&mut self) -> Result<(), CliError> {
        if Instant::now() >= self.next_heartbeat {
            self.next_heartbeat = Instant::now() + Duration::from_secs(1);
            self.send(&MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 0,
                mavtype: MavType::MAV_TYPE_GCS,
                autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                base_mode: MavModeFlag::empty(),
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            }))?;
        }
        Ok(())
    }

    fn take(&mut self, message: &MavMessage, err: &mut dyn Write) {
        match message {
            MavMessage::HEARTBEAT(h) => {
                self.status.armed = h
                    .base_mode
                    .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
                self.status.custom_mode = h.custom_mode;
            }
            MavMessage::GLOBAL_POSITION_INT(g) => {
                self.status.altitude_m = Some(f64::from(g.alt) * 1e-3);
            }
            MavMessage::PARAM_VALUE(v) => {
                let name = touchdown_core::params::name_str(&v.param_id[..]).to_string();
                self.params.insert(
                    name,
                    ParamValue {
                        value: v.param_value,
                        kind: v.param_type,
                    },
                );
            }
            MavMessage::GPS_GLOBAL_ORIGIN(_) => self.status.origin_set = true,
            MavMessage::COMMAND_ACK(a) => self.acks.push((a.command, a.result)),
            MavMessage::STATUSTEXT(s) => {
                let chunk = touchdown_core::params::name_str(&s.text[..]);
                // A text longer than one message comes in chunks of one `id`; the last is
                // the one that does not fill its 50 bytes.
                let text = match self.chunks.take() {
                    Some((id, mut head)) if id == s.id && s.id != 0 => {
                        head.push_str(chunk);
                        head
                    }
                    _ => chunk.to_string(),
                };
                if s.id != 0 && chunk.len() == s.text.len() {
                    self.chunks = Some((s.id, text));
                    return;
                }
                let t = self.clock_zero.elapsed().as_secs_f64();
                // ArduPilot's EKF3: "EKF3 IMU0 origin set".
                if text.contains("origin set") {
                    self.status.origin_set = true;
                }
                if s.severity as u8 <= MavSeverity::MAV_SEVERITY_INFO as u8 {
                    let _ = writeln!(err, "{t:7.2} s  {}: {text}", self.autopilot.name());
                }
                self.texts.push((t, text));
            }
            _ => {}
        }
    }

    pub(super) fn send(&mut self, message: &MavMessage) -> Result<(), CliError> {
        let frame = gcs_frame(self.sequence, message);
        self.sequence = self.sequence.wrapping_add(1);
        self.endpoint
            .send(&frame)
            .map(|_| ())
            .map_err(|e| CliError(format!("{}: {e}", self.describe())))
    }

    /// Sends COMMAND_LONG `command` with its seven parameters.
    pub fn command(&mut self, command: MavCmd, p: [f32; 7]) -> Result<(), CliError> {
        self.send(&MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            param5: p[4],
            param6: p[5],
            param7: p[6],
            command,
            target_system: self.system_id,
            target_component: 1,
            confirmation: 0,
        }))
    }

    /// Sends COMMAND_LONG with a command number the common dialect lacks.
    pub fn command_raw(&mut self, command: u16, params: [f32; 7]) -> Result<(), CliError> {
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message_data(
            MavHeader {
                system_id: GCS_SYSTEM_ID.into(),
                component_id: GCS_COMPONENT_ID,
                sequence: self.sequence,
            },
            &RawCommandLong {
                params,
                command,
                target_system: self.system_id,
            },
        );
        self.sequence = self.sequence.wrapping_add(1);
        self.endpoint
            .send(raw.raw_bytes())
            .map(|_| ())
            .map_err(|e| CliError(format!("{}: {e}", self.describe())))
    }

    /// The newest answer (MAV_RESULT as a number) to a command sent with
    /// [`GcsLink::command_raw`], taken off the list.
    pub fn take_raw_ack(&mut self, command: u16) -> Option<u8> {
        let k = self.raw_acks.iter().rposition(|(c, _)| *c == command)?;
        let (_, result) = self.raw_acks.remove(k);
        self.raw_acks.retain(|(c, _)| *c != command);
        Some(result)
    }

    /// Sends a PARAM_SET for the SITL's GPS switch without waiting (the board's loop must go
    /// on): [`GcsLink::gps_switch_held`] tells what the autopilot then holds.
    pub fn turn_gps_off(&mut self) -> Result<(), CliError> {
        let Some(switch) = self.gps_switch.clone() else {
            return Ok(());
        };
        self.params.remove(&switch.name);
        self.send(&MavMessage::PARAM_SET(PARAM_SET_DATA {
            param_value: encode_param(self.autopilot, switch.off, switch.kind),
            target_system: self.system_id,
            target_component: 1,
            param_id: switch.name.as_str().into(),
            param_type: switch.kind,
        }))
    }

    /// Sets the estimator's origin (SET_GPS_GLOBAL_ORIGIN): latitude and longitude in
    /// degrees, altitude AMSL in metres. An autopilot that has its origin ignores it.
    // The message MAVLink now calls superseded by MAV_CMD_DO_SET_GLOBAL_ORIGIN is the one
    // ArduPilot 4.x and PX4 handle.
    #[allow(deprecated)]
    pub fn set_origin(&mut self, at: [f64; 3]) -> Result<(), CliError> {
        use touchdown_core::companion::mavlink::dialects::common::SET_GPS_GLOBAL_ORIGIN_DATA;
        self.send(&MavMessage::SET_GPS_GLOBAL_ORIGIN(
            SET_GPS_GLOBAL_ORIGIN_DATA {
                latitude: (at[0] * 1e7).round() as i32,
                longitude: (at[1] * 1e7).round() as i32,
                altitude: (at[2] * 1e3).round() as i32,
                target_system: self.system_id,
                ..SET_GPS_GLOBAL_ORIGIN_DATA::DEFAULT
            },
        ))
    }

    /// Whether the autopilot has answered that its simulated GPS is off.
    pub fn gps_switch_held(&self) -> bool {
        self.gps_switch.as_ref().is_some_and(|s| {
            self.params
                .get(&s.name)
                .is_some_and(|v| same_value(decode_param(self.autopilot, v.value, v.kind), s.off))
        })
    }

    /// The newest answer to `command` since the last call, taken off the list.
    pub fn take_ack(&mut self, command: MavCmd) -> Option<MavResult> {
        let k = self.acks.iter().rposition(|(c, _)| *c == command)?;
        let (_, result) = self.acks.remove(k);
        self.acks.retain(|(c, _)| *c != command);
        Some(result)
    }

    /// Asks for a message stream on this link (MAV_CMD_SET_MESSAGE_INTERVAL).
    fn request_stream(&mut self, message_id: u32, interval_us: f32) -> Result<(), CliError> {
        self.command(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            [message_id as f32, interval_us, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
    }

    /// Switches the flight mode (MAV_CMD_DO_SET_MODE with a custom mode).
    pub fn set_mode(&mut self, custom_mode: u32) -> Result<(), CliError> {
        let custom = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.bits() as f32;
        let p = match self.autopilot {
            Autopilot::ArduPilot => [custom, custom_mode as f32, 0.0, 0.0, 0.0, 0.0, 0.0],
            Autopilot::Px4 => [
                custom,
                ((custom_mode >> 16) & 0xFF) as f32,
                ((custom_mode >> 24) & 0xFF) as f32,
                0.0,
                0.0,
                0.0,
                0.0,
            ],
        };
        self.command(MavCmd::MAV_CMD_DO_SET_MODE, p)
    }

    /// Pumps the link until `done` gives a value or `patience` runs out (`None`).
    fn wait<T>(
        &mut self,
        patience: Duration,
        err: &mut dyn Write,
        mut done: impl FnMut(&mut GcsLink) -> Option<T>,
    ) -> Result<Option<T>, CliError> {
        let until = Instant::now() + patience;
        loop {
            self.pump(err)?;
            if let Some(v) = done(self) {
                return Ok(Some(v));
            }
            if Instant::now() >= until {
                return Ok(None);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// The parameter's value as the autopilot reports it; `None` when it never answers
    /// (ArduPilot and PX4 say nothing of a name they do not have).
    fn read_param(
        &mut self,
        name: &str,
        err: &mut dyn Write,
    ) -> Result<Option<ParamValue>, CliError> {
        self.params.remove(name);
        for _ in 0..PARAM_TRIES {
            self.send(&MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
                param_index: -1,
                target_system: self.system_id,
                target_component: 1,
                param_id: name.into(),
            }))?;
            if let Some(v) = self.wait(self.param_try, err, |l| l.params.get(name).copied())? {
                return Ok(Some(v));
            }
        }
        Ok(None)
    }

    /// Sets `name` to `value` in the autopilot's encoding of `kind` and returns what the
    /// autopilot answers it holds afterwards.
    fn write_param(
        &mut self,
        name: &str,
        value: f32,
        kind: MavParamType,
        err: &mut dyn Write,
    ) -> Result<Option<f32>, CliError> {
        let wire = encode_param(self.autopilot, value, kind);
        for _ in 0..PARAM_TRIES {
            self.params.remove(name);
            self.send(&MavMessage::PARAM_SET(PARAM_SET_DATA {
                param_value: wire,
                target_system: self.system_id,
                target_component: 1,
                param_id: name.into(),
                param_type: kind,
            }))?;
            if let Some(v) = self.wait(self.param_try, err, |l| l.params.get(name).copied())? {
                return Ok(Some(decode_param(self.autopilot, v.value, v.kind)));
            }
        }
        Ok(None)
    }
}

/// `message` as a ground station (255/190) sends it: an unsigned MAVLink 2 frame.
pub(crate) fn gcs_frame(sequence: u8, message: &MavMessage) -> Vec<u8> {
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message(
        MavHeader {
            system_id: GCS_SYSTEM_ID.into(),
            component_id: GCS_COMPONENT_ID,
            sequence,
        },
        message,
    );
    raw.raw_bytes().to_vec()
}

/// A parameter's value on the wire: ArduPilot casts integers to the float
/// (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST); PX4 sends their bits in it
/// (PARAM_ENCODE_BYTEWISE).
fn encode_param(autopilot: Autopilot, value: f32, kind: MavParamType) -> f32 {
    match (autopilot, kind) {
        (Autopilot::Px4, MavParamType::MAV_PARAM_TYPE_INT32) => {
            f32::from_bits((value.round() as i32) as u32)
        }
        (
            Autopilot::Px4,
            MavParamType::MAV_PARAM_TYPE_UINT8 | MavParamType::MAV_PARAM_TYPE_INT8,
        ) => f32::from_bits(u32::from(value.round() as i8 as u8)),
        _ => value,
    }
}

/// The inverse of [`encode_param`].
fn decode_param(autopilot: Autopilot, wire: f32, kind: MavParamType) -> f32 {
    match (autopilot, kind) {
        (Autopilot::Px4, MavParamType::MAV_PARAM_TYPE_INT32) => wire.to_bits() as i32 as f32,
        (
            Autopilot::Px4,
            MavParamType::MAV_PARAM_TYPE_UINT8 | MavParamType::MAV_PARAM_TYPE_INT8,
        ) => (wire.to_bits() & 0xFF) as u8 as i8 as f32,
        _ => wire,
    }
}

/// Whether two parameter values are the same setting (a float parameter comes back in f32).
fn same_value(a: f32, b: f32) -> bool {
    (a - b).abs() <= 1e-4 * a.abs().max(1.0)
}

fn describe_spec(spec: &EndpointSpec) -> String {
    match spec {
        EndpointSpec::TcpClient(a) => format!("tcp:{a}"),
        EndpointSpec::UdpClient { remote, .. } => format!("udp:{remote}"),
        EndpointSpec::UdpListen(a) => format!("udpin:{a}"),
        other => other.describe(),
    }
}

/// Opens the link, retrying a refused TCP connection for [`CONNECT_PATIENCE`] (a SITL that is
/// still starting, or rebooting).
fn open(spec: &EndpointSpec, patience: Duration) -> Result<Endpoint, CliError> {
    let until = Instant::now() + patience;
    loop {
        match Endpoint::open(spec) {
            Ok(e) => return Ok(e),
            Err(e) if Instant::now() < until => {
                let _ = e;
                std::thread::sleep(Duration::from_millis(250));
            }
            Err(e) => {
                return Err(CliError(format!(
                    "--gcs {}: {e} (is the SITL running?)",
                    describe_spec(spec)
                )))
            }
        }
    }
}

/// Connects and waits for the autopilot's HEARTBEAT (system 1..254, component 1).
fn connect(spec: &EndpointSpec, connect_patience: Duration) -> Result<GcsLink, CliError> {
    let endpoint = open(spec, connect_patience)?;
    let now = Instant::now();
    let mut link = GcsLink {
        spec: spec.clone(),
        endpoint,
        parser: FrameParser::new(),
        sequence: 0,
        system_id: 0,
        autopilot: Autopilot::ArduPilot,
        status: Status::default(),
        params: HashMap::new(),
        acks: Vec::new(),
        raw_acks: Vec::new(),
        gps_switch: None,
        texts: Vec::new(),
        chunks: None,
        next_heartbeat: now,
        clock_zero: now,
        param_try: PARAM_TRY,
    };
    // Until the autopilot is known (system id 0) every sender's frames are read.
    let until = Instant::now() + HEARTBEAT_PATIENCE;
    loop {
        let (messages, drained) = link.receive();
        drained?;
        let found = messages.into_iter().find_map(|(system_id, message)| {
            let MavMessage::HEARTBEAT(h) = message else {
                return None;
            };
            let autopilot = match h.autopilot {
                MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA => Autopilot::ArduPilot,
                MavAutopilot::MAV_AUTOPILOT_PX4 => Autopilot::Px4,
                _ => return None,
            };
            Some((system_id, autopilot, h))
        });
        if let Some((system_id, autopilot, h)) = found {
            link.system_id = system_id;
            link.autopilot = autopilot;
            link.status.armed = h
                .base_mode
                .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
            link.status.custom_mode = h.custom_mode;
            return Ok(link);
        }
        if Instant::now() >= until {
            return Err(CliError(format!(
                "{}: no autopilot HEARTBEAT in {} s (is it the SITL's ground-station port?)",
                link.describe(),
                HEARTBEAT_PATIENCE.as_secs()
            )));
        }
        link.heartbeat_when_due()?;
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// What [`prepare`] did to the autopilot's parameters.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Prepared {
    /// `NAME=VALUE` of each parameter changed.
    pub changed: Vec<String>,
    /// Whether the autopilot was rebooted.
    pub rebooted: bool,
}

/// Connects to the ground-station port, identifies the autopilot, sets the recipe's
/// parameters and reboots once if one of them needs it. The vehicle must be disarmed.
pub fn prepare(
    spec: &EndpointSpec,
    plan: &Plan,
    err: &mut dyn Write,
) -> Result<(GcsLink, Prepared), CliError> {
    let mut link = connect(spec, plan.patience.connect)?;
    link.param_try = plan.patience.param_try;
    let _ = writeln!(
        err,
        "{}: {} (system {})",
        link.describe(),
        link.autopilot.name(),
        link.system_id
    );
    if link.status.armed {
        return Err(CliError(format!(
            "{}: the vehicle is armed: start the rehearsal on the ground, disarmed",
            link.describe()
        )));
    }
    let gps_switch = match (plan.gps_loss_height_m, link.autopilot) {
        (None, _) => None,
        (Some(_), Autopilot::Px4) => {
            return Err(CliError::new(
                "--gps-loss-height: not supported on PX4 yet (ArduPilot SITL only)",
            ))
        }
        (Some(_), Autopilot::ArduPilot) => Some(find_gps_switch(&mut link, err)?),
    };
    if let Some((key, timestamp)) = plan.signing {
        if link.autopilot == Autopilot::Px4 {
            return Err(CliError::new(
                "--signing-key: not supported on PX4 yet (ArduPilot SITL only)",
            ));
        }
        // To the autopilot itself (component 1): a broadcast would be forwarded to the
        // board's link too, unsigned.
        link.send(&MavMessage::SETUP_SIGNING(SETUP_SIGNING_DATA {
            initial_timestamp: timestamp,
            target_system: link.system_id,
            target_component: 1,
            secret_key: key,
        }))?;
        let _ = writeln!(
            err,
            "{}: signing key set on the autopilot (SETUP_SIGNING); the board signs with it",
            link.describe()
        );
    }
    let settings = recipe(link.autopilot, plan);
    let mut prepared = Prepared::default();
    let mut reboot = false;
    for s in &settings {
        let Some(current) = link.read_param(&s.name, err)? else {
            if s.optional {
                let _ = writeln!(
                    err,
                    "{}: no parameter {} in this version: left out",
                    link.describe(),
                    s.name
                );
                continue;
            }
            let hint = match s.name.as_str() {
                "ARMING_SKIPCHK" => {
                    " (ArduPilot 4.6 and older: give ARMING_CHECK without bit 18, visual \
                     odometry, in --autopilot-params)"
                        .to_string()
                }
                "VISO_TYPE" => " (a build without visual odometry?)".to_string(),
                _ => format!(" (a {} build without it?)", link.autopilot.name()),
            };
            return Err(CliError(format!(
                "{}: the autopilot has no parameter {}{hint}",
                link.describe(),
                s.name,
            )));
        };
        let held = decode_param(link.autopilot, current.value, current.kind);
        let want = s.wanted(held);
        if same_value(held, want) {
            continue;
        }
        match link.write_param(&s.name, want, current.kind, err)? {
            Some(v) if same_value(v, want) => {}
            Some(v) => {
                return Err(CliError(format!(
                    "{}: the autopilot refused {} = {want} (it keeps {v})",
                    link.describe(),
                    s.name,
                )))
            }
            None => {
                return Err(CliError(format!(
                    "{}: no answer to setting {} = {want}",
                    link.describe(),
                    s.name,
                )))
            }
        }
        prepared.changed.push(format!("{}={want}", s.name));
        reboot |= s.needs_reboot;
    }
    if !prepared.changed.is_empty() {
        let _ = writeln!(
            err,
            "{}: set {}",
            link.describe(),
            prepared.changed.join(", ")
        );
    }
    if reboot {
        let _ = writeln!(
            err,
            "{}: rebooting (the precision-landing backend is created at boot)",
            link.describe()
        );
        link.command(
            MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )?;
        // The SITL closes its ports as it restarts; what it says meanwhile does not matter.
        let _ = link.wait(Duration::from_secs(2), err, |l| {
            l.take_ack(MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN)
                .filter(|r| *r != MavResult::MAV_RESULT_ACCEPTED)
        });
        drop(link);
        std::thread::sleep(Duration::from_secs(1));
        link = connect(spec, REBOOT_PATIENCE)?;
        link.param_try = plan.patience.param_try;
        prepared.rebooted = true;
        for s in &settings {
            let Some(v) = link.read_param(&s.name, err)? else {
                if s.optional {
                    continue;
                }
                return Err(CliError(format!(
                    "{}: parameter {} gone after the reboot",
                    link.describe(),
                    s.name
                )));
            };
            let held = decode_param(link.autopilot, v.value, v.kind);
            if !same_value(held, s.wanted(held)) {
                return Err(CliError(format!(
                    "{}: {} = {held} after the reboot, not {} (not saved?)",
                    link.describe(),
                    s.name,
                    s.wanted(held)
                )));
            }
        }
    }
    link.gps_switch = gps_switch;
    // The autopilot's own altitude, for PX4's take-off and reposition in AMSL.
    link.request_stream(33, 200_000.0)?;
    Ok((link, prepared))
}

/// The SITL's GPS switch of this build ([`SIM_GPS_SWITCHES`]), or one line saying there is none.
fn find_gps_switch(link: &mut GcsLink, err: &mut dyn Write) -> Result<GpsSwitch, CliError> {
    for (name, off) in SIM_GPS_SWITCHES {
        if let Some(v) = link.read_param(name, err)? {
            return Ok(GpsSwitch {
                name: name.to_string(),
                off,
                kind: v.kind,
            });
        }
    }
    Err(CliError(format!(
        "{}: --gps-loss-height: the autopilot has neither {} nor {} (not an ArduPilot SITL?)",
        link.describe(),
        SIM_GPS_SWITCHES[0].0,
        SIM_GPS_SWITCHES[1].0
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_raw_command_long_is_what_pymavlink_would_send() {
        let mut payload = [0u8; 255];
        let n = RawCommandLong {
            params: [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            command: 42007,
            target_system: 1,
        }
        .ser(MavlinkVersion::V2, &mut payload);
        // param1 2.0, the command at 28, target 1/1, confirmation 0 trimmed.
        assert_eq!(n, 32);
        assert_eq!(&payload[..4], &2.0f32.to_le_bytes());
        assert_eq!(&payload[28..32], &[0x17, 0xA4, 1, 1]);
    }

    #[test]
    fn px4_integers_go_bytewise_and_ardupilot_ones_as_floats() {
        let int = MavParamType::MAV_PARAM_TYPE_INT32;
        let wire = encode_param(Autopilot::Px4, 2.0, int);
        assert_eq!(wire.to_bits(), 2);
        assert_eq!(decode_param(Autopilot::Px4, wire, int), 2.0);
        assert_eq!(encode_param(Autopilot::Px4, -3.0, int).to_bits() as i32, -3);
        assert_eq!(encode_param(Autopilot::ArduPilot, 2.0, int), 2.0);
        let real = MavParamType::MAV_PARAM_TYPE_REAL32;
        assert_eq!(encode_param(Autopilot::Px4, 0.5, real), 0.5);
        assert_eq!(decode_param(Autopilot::Px4, 0.5, real), 0.5);
    }
}
