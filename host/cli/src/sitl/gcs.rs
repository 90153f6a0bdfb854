//! `touchdown sitl --gcs`: the ground station's half of a rehearsal against a running SITL.
//!
//! What a user would otherwise do by hand in Mission Planner, QGroundControl or a script:
//! set the autopilot's precision-landing parameters, reboot once where the autopilot creates
//! its precision-landing backend only at boot (ArduPilot's `PLND_TYPE`), wait for its
//! estimator, arm, take off to `--height`, fly `--offset` away from the pad and start the
//! landing in the mode that uses landing targets, then watch until the autopilot disarms.
//!
//! Two halves, because the board's link must not exist while the autopilot reboots and must
//! run beside the flight:
//! - [`prepare`], before the board's link opens: connect, identify the autopilot by its
//!   HEARTBEAT, set the parameters of [`recipe`], reboot and reconnect if one of them needs it.
//! - [`Flight`], polled by the board's loop on every tick: the flight itself as a state
//!   machine driven by the autopilot's own replies (HEARTBEAT mode and arming state,
//!   COMMAND_ACK, STATUSTEXT) and by the SITL's ground truth (heights and positions).
//!
//! What each autopilot needs comes from its own code (docs/setup-ardupilot.md,
//! docs/setup-px4.md): ArduCopter takes off in GUIDED and lands in LAND, which uses
//! precision landing when `PLND_ENABLED`; PX4's LAND ignores targets, its Precision Land mode
//! (AUTO / PRECLAND) uses them. Every failure the user can meet (no SITL on the port, no
//! HEARTBEAT, a parameter refused, an estimator never ready, a vehicle that never arms)
//! ends the run with one line saying which.

use std::collections::HashMap;
use std::io::Write;
use std::time::{Duration, Instant};

use touchdown_core::companion::mavlink::dialects::common::{
    MavAutopilot, MavCmd, MavFrame, MavMessage, MavModeFlag, MavParamType, MavResult, MavSeverity,
    MavState, MavType, PositionTargetTypemask, COMMAND_INT_DATA, COMMAND_LONG_DATA, HEARTBEAT_DATA,
    PARAM_REQUEST_READ_DATA, PARAM_SET_DATA, SET_POSITION_TARGET_GLOBAL_INT_DATA,
};
use touchdown_core::companion::mavlink::{MAVLinkV2MessageRaw, MavHeader};
use touchdown_core::companion::FrameParser;
use touchdown_eval::flight::TrueState;

use crate::companion::endpoint::{Endpoint, EndpointSpec};
use crate::CliError;

/// Our system id: the ground station's customary 255.
const GCS_SYSTEM_ID: u8 = 255;
/// Our component id: MAV_COMP_ID_MISSIONPLANNER.
const GCS_COMPONENT_ID: u8 = 190;
/// How long a connection to a SITL that is not there yet is retried.
const CONNECT_PATIENCE: Duration = Duration::from_secs(10);
/// How long to wait for the autopilot's first HEARTBEAT.
const HEARTBEAT_PATIENCE: Duration = Duration::from_secs(30);
/// How long a rebooting SITL may take to answer again.
const REBOOT_PATIENCE: Duration = Duration::from_secs(60);
/// A parameter read or write is retried this often, each try waiting [`PARAM_TRY`].
const PARAM_TRIES: u32 = 3;
/// See [`PARAM_TRIES`].
const PARAM_TRY: Duration = Duration::from_millis(1500);
/// Arming is retried (the estimator and GPS need their time after boot) for this long, s.
const ARMING_PATIENCE_S: f64 = 180.0;
/// The climb to `--height` may take this long, s.
const TAKEOFF_PATIENCE_S: f64 = 90.0;
/// The move to the start point may take this long before the landing starts anyway, s.
const MOVE_PATIENCE_S: f64 = 60.0;
/// At the start point: within this distance of it, horizontally, metres (PX4 may hold its
/// own set point tens of centimetres off in truth)...
const START_TOLERANCE_M: f64 = 1.0;
/// ... slower than this, m/s ...
const START_SPEED_MPS: f64 = 0.2;
/// ... for this long, seconds, and turned to the heading asked for within this, degrees.
const START_HOLD_S: f64 = 3.0;
/// See [`START_HOLD_S`].
const START_HEADING_DEG: f64 = 5.0;
/// Commands not yet taken are sent again after this long, seconds.
const RETRY_S: f64 = 2.0;
/// After the autopilot disarms the run watches this much longer (a re-take-off shows), s.
const AFTER_DISARM_S: f64 = 2.0;

/// The autopilot at the other end, from its HEARTBEAT.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Autopilot {
    /// ArduPilot (MAV_AUTOPILOT_ARDUPILOTMEGA).
    ArduPilot,
    /// PX4 (MAV_AUTOPILOT_PX4).
    Px4,
}

impl Autopilot {
    /// Its name in messages and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Autopilot::ArduPilot => "ArduPilot",
            Autopilot::Px4 => "PX4",
        }
    }
}

/// ArduCopter's flight modes used here (HEARTBEAT `custom_mode`).
const COPTER_GUIDED: u32 = 4;
/// See [`COPTER_GUIDED`].
const COPTER_LAND: u32 = 9;
/// PX4's main mode AUTO (bits 16-23 of `custom_mode`) ...
const PX4_MAIN_AUTO: u32 = 4;
/// ... and its sub mode PRECLAND (bits 24-31).
const PX4_SUB_PRECLAND: u32 = 9;

/// The `custom_mode` PX4 reports in Precision Land.
fn px4_precland_mode() -> u32 {
    (PX4_MAIN_AUTO << 16) | (PX4_SUB_PRECLAND << 24)
}

/// One autopilot parameter a rehearsal sets.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamSetting {
    /// Its name.
    pub name: &'static str,
    /// Its value.
    pub value: f32,
    /// Takes effect only after a reboot.
    pub needs_reboot: bool,
    /// Absent in some versions: skipped (with a line) instead of an error.
    pub optional: bool,
}

const fn setting(name: &'static str, value: f32) -> ParamSetting {
    ParamSetting {
        name,
        value,
        needs_reboot: false,
        optional: false,
    }
}

/// What the rehearsal is asked to fly, besides the autopilot's own settings.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Take-off height above the pad, metres.
    pub height_m: f64,
    /// Where the landing starts, metres north and east of the pad.
    pub start_north_m: f64,
    /// See `start_north_m`.
    pub start_east_m: f64,
    /// The heading to turn to at the start point, degrees from north (`None`: as it is).
    pub yaw_deg: Option<f64>,
    /// ArduPilot SITL's wind: mean speed (m/s), direction it blows from (degrees), profile
    /// (SIM_WIND_T) and turbulence (SIM_WIND_TURB, m/s). PX4's SIH has no wind.
    pub wind: Option<SitlWind>,
}

/// ArduPilot SITL's wind parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SitlWind {
    /// SIM_WIND_SPD, m/s.
    pub speed_mps: f32,
    /// SIM_WIND_DIR, degrees, where it comes from.
    pub from_deg: f32,
    /// SIM_WIND_T: 0 square law below SIM_WIND_T_ALT, 1 the same at every height.
    pub profile: f32,
    /// SIM_WIND_TURB, m/s.
    pub turbulence_mps: f32,
}

/// The parameters our setup pages ask for on `autopilot`, in the order they must be set
/// (an enable parameter before the group it reveals), then the SITL's wind.
pub fn recipe(autopilot: Autopilot, plan: &Plan) -> Vec<ParamSetting> {
    let mut list = match autopilot {
        // docs/setup-ardupilot.md, section 3.
        Autopilot::ArduPilot => vec![
            setting("PLND_ENABLED", 1.0),
            ParamSetting {
                needs_reboot: true,
                ..setting("PLND_TYPE", 1.0)
            },
            setting("PLND_EST_TYPE", 1.0),
            ParamSetting {
                needs_reboot: true,
                optional: true,
                ..setting("PLND_ORIENT", 25.0)
            },
            setting("PLND_YAW_ALIGN", 0.0),
        ],
        // docs/setup-px4.md, section 3.
        Autopilot::Px4 => vec![setting("PLD_FAPPR_ALT", 0.5), setting("PLD_BTOUT", 5.0)],
    };
    if let (Autopilot::ArduPilot, Some(w)) = (autopilot, plan.wind) {
        list.extend([
            setting("SIM_WIND_SPD", w.speed_mps),
            setting("SIM_WIND_DIR", w.from_deg),
            setting("SIM_WIND_T", w.profile),
            setting("SIM_WIND_TURB", w.turbulence_mps),
        ]);
    }
    list
}

/// `--gcs`'s value: `tcp:HOST:PORT` (client), `udp:HOST:PORT` (client), `udpin:ADDR:PORT`
/// (server: answers whoever sends, as PX4 SITL's ground-station port sends to 14550).
pub fn parse_gcs(text: &str) -> Result<EndpointSpec, String> {
    let (kind, addr) = text
        .split_once(':')
        .ok_or("expected tcp:HOST:PORT, udp:HOST:PORT or udpin:ADDR:PORT")?;
    if addr
        .rsplit_once(':')
        .is_none_or(|(host, port)| host.is_empty() || port.parse::<u16>().is_err())
    {
        return Err(format!("`{addr}`: expected HOST:PORT"));
    }
    match kind {
        "tcp" => Ok(EndpointSpec::TcpClient(addr.to_string())),
        "udp" => Ok(EndpointSpec::UdpClient {
            remote: addr.to_string(),
            local_port: None,
        }),
        "udpin" => Ok(EndpointSpec::UdpListen(addr.to_string())),
        _ => Err(format!(
            "`{kind}`: expected tcp:HOST:PORT, udp:HOST:PORT or udpin:ADDR:PORT"
        )),
    }
}

/// The vehicle as the ground-station link reports it.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Status {
    /// HEARTBEAT: armed.
    pub armed: bool,
    /// HEARTBEAT: the flight mode.
    pub custom_mode: u32,
    /// GLOBAL_POSITION_INT: the autopilot's own altitude AMSL, metres.
    pub altitude_m: Option<f64>,
}

/// A parameter as the autopilot last reported it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ParamValue {
    value: f32,
    kind: MavParamType,
}

/// The ground station's link: the socket, the autopilot's identity and what it last said.
pub struct GcsLink {
    spec: EndpointSpec,
    endpoint: Endpoint,
    parser: FrameParser,
    sequence: u8,
    /// The autopilot's system id (from its first HEARTBEAT).
    system_id: u8,
    /// Which autopilot.
    pub autopilot: Autopilot,
    /// What it last reported.
    pub status: Status,
    params: HashMap<String, ParamValue>,
    acks: Vec<(MavCmd, MavResult)>,
    /// Its STATUSTEXTs, with the run's seconds when they came.
    pub texts: Vec<(f64, String)>,
    next_heartbeat: Instant,
    /// The run's clock offset: [`GcsLink::texts`] are stamped in the board loop's seconds.
    clock_zero: Instant,
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
        let mut rx = [0u8; 4096];
        let mut messages = Vec::new();
        let parser = &mut self.parser;
        let system_id = self.system_id;
        let drained = self.endpoint.drain(&mut rx, |bytes| {
            parser.push(bytes, |frame| {
                if frame.system_id == system_id && frame.component_id == 1 {
                    if let Ok(message) = frame.decode() {
                        messages.push(message);
                    }
                }
            });
        });
        for message in messages {
            self.take(&message, err);
        }
        if let Err(lost) = drained {
            return Err(CliError(format!("{}: {lost}", self.describe())));
        }
        self.heartbeat_when_due()
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
            MavMessage::COMMAND_ACK(a) => self.acks.push((a.command, a.result)),
            MavMessage::STATUSTEXT(s) => {
                let text = touchdown_core::params::name_str(&s.text[..]).to_string();
                let t = self.clock_zero.elapsed().as_secs_f64();
                if s.severity as u8 <= MavSeverity::MAV_SEVERITY_INFO as u8 {
                    let _ = writeln!(err, "{t:7.2} s  {}: {text}", self.autopilot.name());
                }
                self.texts.push((t, text));
            }
            _ => {}
        }
    }

    fn send(&mut self, message: &MavMessage) -> Result<(), CliError> {
        let mut raw = MAVLinkV2MessageRaw::new();
        raw.serialize_message(
            MavHeader {
                system_id: GCS_SYSTEM_ID.into(),
                component_id: GCS_COMPONENT_ID,
                sequence: self.sequence,
            },
            message,
        );
        self.sequence = self.sequence.wrapping_add(1);
        self.endpoint
            .send(raw.raw_bytes())
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
            if let Some(v) = self.wait(PARAM_TRY, err, |l| l.params.get(name).copied())? {
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
            if let Some(v) = self.wait(PARAM_TRY, err, |l| l.params.get(name).copied())? {
                return Ok(Some(decode_param(self.autopilot, v.value, v.kind)));
            }
        }
        Ok(None)
    }
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
        texts: Vec::new(),
        next_heartbeat: now,
        clock_zero: now,
    };
    // Until the autopilot is known the parser hands out every sender's frames.
    let until = Instant::now() + HEARTBEAT_PATIENCE;
    let mut rx = [0u8; 4096];
    loop {
        let mut found = None;
        let parser = &mut link.parser;
        let drained = link.endpoint.drain(&mut rx, |bytes| {
            parser.push(bytes, |frame| {
                if let (1, Ok(MavMessage::HEARTBEAT(h))) = (frame.component_id, frame.decode()) {
                    let autopilot = match h.autopilot {
                        MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA => Some(Autopilot::ArduPilot),
                        MavAutopilot::MAV_AUTOPILOT_PX4 => Some(Autopilot::Px4),
                        _ => None,
                    };
                    if let Some(a) = autopilot {
                        found.get_or_insert((frame.system_id, a, h));
                    }
                }
            });
        });
        if let Err(lost) = drained {
            return Err(CliError(format!("{}: {lost}", link.describe())));
        }
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
    let mut link = connect(spec, CONNECT_PATIENCE)?;
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
    let settings = recipe(link.autopilot, plan);
    let mut prepared = Prepared::default();
    let mut reboot = false;
    for s in &settings {
        let Some(current) = link.read_param(s.name, err)? else {
            if s.optional {
                let _ = writeln!(
                    err,
                    "{}: no parameter {} in this version: left out",
                    link.describe(),
                    s.name
                );
                continue;
            }
            return Err(CliError(format!(
                "{}: the autopilot has no parameter {} (a {} build without it?)",
                link.describe(),
                s.name,
                link.autopilot.name()
            )));
        };
        let held = decode_param(link.autopilot, current.value, current.kind);
        if same_value(held, s.value) {
            continue;
        }
        match link.write_param(s.name, s.value, current.kind, err)? {
            Some(v) if same_value(v, s.value) => {}
            Some(v) => {
                return Err(CliError(format!(
                    "{}: the autopilot refused {} = {} (it keeps {v})",
                    link.describe(),
                    s.name,
                    s.value
                )))
            }
            None => {
                return Err(CliError(format!(
                    "{}: no answer to setting {} = {}",
                    link.describe(),
                    s.name,
                    s.value
                )))
            }
        }
        prepared.changed.push(format!("{}={}", s.name, s.value));
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
        prepared.rebooted = true;
        for s in &settings {
            let Some(v) = link.read_param(s.name, err)? else {
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
            if !same_value(held, s.value) {
                return Err(CliError(format!(
                    "{}: {} = {held} after the reboot, not {} (not saved?)",
                    link.describe(),
                    s.name,
                    s.value
                )));
            }
        }
    }
    // The autopilot's own altitude, for PX4's take-off and reposition in AMSL.
    link.request_stream(33, 200_000.0)?;
    Ok((link, prepared))
}

/// Where the flight is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Stage {
    /// Switching to the take-off mode and arming, retried until the autopilot takes it.
    Arming { next_try_s: f64 },
    /// Armed; the take-off command sent (again every [`RETRY_S`] until it climbs).
    TakingOff { since_s: f64, next_try_s: f64 },
    /// Flying to the start point; `settled_s` since when it has held there.
    Moving {
        since_s: f64,
        next_try_s: f64,
        settled_s: Option<f64>,
    },
    /// The landing commanded at `since_s`; the mode asked for again until it shows.
    Landing { since_s: f64, next_try_s: f64 },
    /// Disarmed at `at_s`.
    Disarmed { at_s: f64 },
}

/// What the flight saw, for the report.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FlightLog {
    /// Seconds (run clock) when the vehicle armed.
    pub armed_s: Option<f64>,
    /// When it reached the take-off height.
    pub climbed_s: Option<f64>,
    /// When the landing command was taken.
    pub landing_s: Option<f64>,
    /// Where the vehicle was then, metres north and east of the pad (truth).
    pub landing_start_ne: Option<(f64, f64)>,
    /// Its height over the pad then (truth), metres.
    pub landing_height_m: Option<f64>,
    /// When the autopilot disarmed after the landing.
    pub disarmed_s: Option<f64>,
    /// Whether the start point was reached and held before the landing began.
    pub start_held: bool,
}

/// The flight's state machine (see the module documentation).
pub struct Flight {
    plan: Plan,
    stage: Stage,
    /// The pad's origin, latitude and longitude in degrees and AMSL altitude in metres.
    pad: Option<[f64; 3]>,
    /// PX4: the take-off altitude AMSL in its own estimate.
    target_amsl_m: Option<f64>,
    /// What happened when.
    pub log: FlightLog,
}

/// Why [`Flight::poll`] says the flight is over.
#[derive(Debug, Clone, PartialEq)]
pub enum FlightEnd {
    /// The autopilot disarmed after the landing, and the watch after it is over.
    Disarmed,
}

impl Flight {
    /// A flight to fly `plan`.
    pub fn new(plan: Plan) -> Self {
        Flight {
            plan,
            stage: Stage::Arming { next_try_s: 0.0 },
            pad: None,
            target_amsl_m: None,
            log: FlightLog::default(),
        }
    }

    /// The landing's start on the run's clock, once commanded: `--max-time` counts from it.
    pub fn landing_started_s(&self) -> Option<f64> {
        self.log.landing_s
    }

    /// One step: reads the link, and sends what the stage needs. `truth` is the vehicle's
    /// true state in the pad frame (x east, y north, z up), `pad` the pad's geodetic origin.
    pub fn poll(
        &mut self,
        link: &mut GcsLink,
        t: f64,
        truth: Option<(TrueState, f64)>,
        pad: Option<[f64; 3]>,
        err: &mut dyn Write,
    ) -> Result<Option<FlightEnd>, CliError> {
        link.pump(err)?;
        self.pad = self.pad.or(pad);
        let autopilot = link.autopilot;
        match self.stage {
            Stage::Arming { next_try_s } => {
                if link.status.armed {
                    self.log.armed_s = Some(t);
                    let _ = writeln!(
                        err,
                        "{t:7.2} s  armed; taking off to {:.1} m",
                        self.plan.height_m
                    );
                    self.stage = Stage::TakingOff {
                        since_s: t,
                        next_try_s: t,
                    };
                } else if t > ARMING_PATIENCE_S {
                    return Err(CliError(format!(
                        "{} never armed in {ARMING_PATIENCE_S:.0} s (estimator or GPS not ready?){}",
                        autopilot.name(),
                        last_refusal(link)
                    )));
                } else if t >= next_try_s && self.pad.is_some() {
                    if autopilot == Autopilot::ArduPilot && link.status.custom_mode != COPTER_GUIDED
                    {
                        link.set_mode(COPTER_GUIDED)?;
                    } else {
                        link.command(
                            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                        )?;
                    }
                    self.stage = Stage::Arming {
                        next_try_s: t + RETRY_S,
                    };
                }
            }
            Stage::TakingOff {
                since_s,
                next_try_s,
            } => {
                let height = truth.map(|(s, _)| s.position.z);
                if height.is_some_and(|h| h >= self.plan.height_m - 0.5) {
                    self.log.climbed_s = Some(t);
                    let _ = writeln!(
                        err,
                        "{t:7.2} s  at {:.1} m; flying to {:+.2} m north, {:+.2} m east of the pad",
                        height.unwrap_or_default(),
                        self.plan.start_north_m,
                        self.plan.start_east_m
                    );
                    self.stage = Stage::Moving {
                        since_s: t,
                        next_try_s: t,
                        settled_s: None,
                    };
                } else if !link.status.armed {
                    // ArduPilot disarms a vehicle that does not take off within seconds.
                    self.stage = Stage::Arming { next_try_s: t };
                } else if t - since_s > TAKEOFF_PATIENCE_S {
                    return Err(CliError(format!(
                        "{} did not climb to {:.1} m in {TAKEOFF_PATIENCE_S:.0} s{}",
                        autopilot.name(),
                        self.plan.height_m,
                        last_refusal(link)
                    )));
                } else if t >= next_try_s && height.is_some_and(|h| h < 1.0) {
                    self.take_off(link)?;
                    self.stage = Stage::TakingOff {
                        since_s,
                        next_try_s: t + RETRY_S,
                    };
                }
            }
            Stage::Moving {
                since_s,
                next_try_s,
                settled_s,
            } => {
                let (north, east) = (self.plan.start_north_m, self.plan.start_east_m);
                let heading_ok = |s: &TrueState| {
                    self.plan.yaw_deg.is_none_or(|want| {
                        let heading = s.body_to_ned[(1, 0)].atan2(s.body_to_ned[(0, 0)]);
                        let off = (heading.to_degrees() - want).rem_euclid(360.0);
                        off.min(360.0 - off) < START_HEADING_DEG
                    })
                };
                let at_start = truth.is_some_and(|(s, speed)| {
                    (s.position.y - north).hypot(s.position.x - east) < START_TOLERANCE_M
                        && speed < START_SPEED_MPS
                        && heading_ok(&s)
                });
                let settled_s = if at_start {
                    settled_s.or(Some(t))
                } else {
                    None
                };
                let held = settled_s.is_some_and(|s| t - s >= START_HOLD_S);
                if held || t - since_s > MOVE_PATIENCE_S {
                    self.log.start_held = held;
                    if !held {
                        let _ = writeln!(
                            err,
                            "{t:7.2} s  not settled at the start point in {MOVE_PATIENCE_S:.0} s: landing from here"
                        );
                    }
                    self.log.landing_start_ne = truth.map(|(s, _)| (s.position.y, s.position.x));
                    self.log.landing_height_m = truth.map(|(s, _)| s.position.z);
                    self.land(link)?;
                    self.log.landing_s = Some(t);
                    let _ = writeln!(
                        err,
                        "{t:7.2} s  landing ({})",
                        match autopilot {
                            Autopilot::ArduPilot => "LAND",
                            Autopilot::Px4 => "Precision Land",
                        }
                    );
                    self.stage = Stage::Landing {
                        since_s: t,
                        next_try_s: t + RETRY_S,
                    };
                } else {
                    let next_try_s = if t >= next_try_s {
                        self.go_to_start(link)?;
                        t + RETRY_S
                    } else {
                        next_try_s
                    };
                    self.stage = Stage::Moving {
                        since_s,
                        next_try_s,
                        settled_s,
                    };
                }
            }
            Stage::Landing {
                since_s,
                next_try_s,
            } => {
                let wanted = match autopilot {
                    Autopilot::ArduPilot => COPTER_LAND,
                    Autopilot::Px4 => px4_precland_mode(),
                };
                if !link.status.armed {
                    self.log.disarmed_s = Some(t);
                    let _ = writeln!(err, "{t:7.2} s  disarmed");
                    self.stage = Stage::Disarmed { at_s: t };
                } else if link.status.custom_mode != wanted && t >= next_try_s {
                    // Once: a mode the autopilot left by itself (a PX4 fallback to LAND)
                    // is part of what the rehearsal shows, not something to fight.
                    if t - since_s < 10.0 {
                        self.land(link)?;
                    }
                    self.stage = Stage::Landing {
                        since_s,
                        next_try_s: t + RETRY_S,
                    };
                }
            }
            Stage::Disarmed { at_s } => {
                if link.status.armed {
                    // Re-armed by the autopilot itself: watch on.
                    self.stage = Stage::Landing {
                        since_s: t,
                        next_try_s: f64::INFINITY,
                    };
                } else if t - at_s >= AFTER_DISARM_S {
                    return Ok(Some(FlightEnd::Disarmed));
                }
            }
        }
        Ok(None)
    }

    fn take_off(&mut self, link: &mut GcsLink) -> Result<(), CliError> {
        match link.autopilot {
            // GUIDED take-off: param 7 is the height above home.
            Autopilot::ArduPilot => link.command(
                MavCmd::MAV_CMD_NAV_TAKEOFF,
                [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, self.plan.height_m as f32],
            ),
            // PX4: param 7 is AMSL, in its own estimate; latitude and longitude unset keep
            // the vehicle where it is.
            Autopilot::Px4 => {
                let base = link.status.altitude_m.unwrap_or(0.0);
                let target = *self.target_amsl_m.get_or_insert(base + self.plan.height_m);
                link.command(
                    MavCmd::MAV_CMD_NAV_TAKEOFF,
                    [0.0, 0.0, 0.0, f32::NAN, f32::NAN, f32::NAN, target as f32],
                )
            }
        }
    }

    /// The start point as latitude and longitude (1e-7 degrees).
    fn start_lat_lon(&self) -> Option<(i32, i32)> {
        let pad = self.pad?;
        let (lat, lon) = offset_lat_lon(
            pad[0],
            pad[1],
            self.plan.start_north_m,
            self.plan.start_east_m,
        );
        Some(((lat * 1e7).round() as i32, (lon * 1e7).round() as i32))
    }

    fn go_to_start(&mut self, link: &mut GcsLink) -> Result<(), CliError> {
        let Some((lat, lon)) = self.start_lat_lon() else {
            return Ok(());
        };
        match link.autopilot {
            Autopilot::ArduPilot => {
                let mut ignore = PositionTargetTypemask::all();
                ignore.remove(
                    PositionTargetTypemask::POSITION_TARGET_TYPEMASK_X_IGNORE
                        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Y_IGNORE
                        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Z_IGNORE,
                );
                ignore.remove(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_FORCE_SET);
                if self.plan.yaw_deg.is_some() {
                    ignore.remove(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE);
                }
                link.send(&MavMessage::SET_POSITION_TARGET_GLOBAL_INT(
                    SET_POSITION_TARGET_GLOBAL_INT_DATA {
                        time_boot_ms: 0,
                        lat_int: lat,
                        lon_int: lon,
                        alt: self.plan.height_m as f32,
                        yaw: self.plan.yaw_deg.unwrap_or(0.0).to_radians() as f32,
                        type_mask: ignore,
                        target_system: link.system_id,
                        target_component: 1,
                        coordinate_frame: MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT,
                        ..SET_POSITION_TARGET_GLOBAL_INT_DATA::DEFAULT
                    },
                ))
            }
            Autopilot::Px4 => {
                let alt = self
                    .target_amsl_m
                    .or(link.status.altitude_m)
                    .unwrap_or(f64::NAN);
                link.send(&MavMessage::COMMAND_INT(COMMAND_INT_DATA {
                    param1: -1.0,
                    // MAV_DO_REPOSITION_FLAGS_CHANGE_MODE: into PX4's hold mode at the point.
                    param2: 1.0,
                    param3: 0.0,
                    // The heading in radians, NaN: as PX4's yaw mode has it.
                    param4: self
                        .plan
                        .yaw_deg
                        .map_or(f32::NAN, |d| d.to_radians() as f32),
                    x: lat,
                    y: lon,
                    z: alt as f32,
                    command: MavCmd::MAV_CMD_DO_REPOSITION,
                    target_system: link.system_id,
                    target_component: 1,
                    frame: MavFrame::MAV_FRAME_GLOBAL,
                    current: 0,
                    autocontinue: 0,
                }))
            }
        }
    }

    fn land(&mut self, link: &mut GcsLink) -> Result<(), CliError> {
        match link.autopilot {
            Autopilot::ArduPilot => link.set_mode(COPTER_LAND),
            Autopilot::Px4 => link.set_mode(px4_precland_mode()),
        }
    }
}

/// The autopilot's last STATUSTEXT, as the reason it refused: ": last message \"...\"".
fn last_refusal(link: &GcsLink) -> String {
    link.texts
        .last()
        .map_or(String::new(), |(_, t)| format!(": last message \"{t}\""))
}

/// The point `north_m`, `east_m` from `lat`, `lon` (degrees), on the local tangent plane.
pub fn offset_lat_lon(lat: f64, lon: f64, north_m: f64, east_m: f64) -> (f64, f64) {
    const EARTH_RADIUS_M: f64 = 6_378_137.0;
    let dlat = (north_m / EARTH_RADIUS_M).to_degrees();
    let dlon = (east_m / (EARTH_RADIUS_M * lat.to_radians().cos())).to_degrees();
    (lat + dlat, lon + dlon)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gcs_addresses_parse_and_bad_ones_say_why() {
        assert_eq!(
            parse_gcs("tcp:127.0.0.1:5760"),
            Ok(EndpointSpec::TcpClient("127.0.0.1:5760".into()))
        );
        assert_eq!(
            parse_gcs("udpin:0.0.0.0:14550"),
            Ok(EndpointSpec::UdpListen("0.0.0.0:14550".into()))
        );
        assert!(matches!(
            parse_gcs("udp:127.0.0.1:18570"),
            Ok(EndpointSpec::UdpClient { .. })
        ));
        for bad in [
            "127.0.0.1:5760",
            "tcp:5760",
            "tcp:host:port",
            "serial:/dev/tty:1",
            "tcp::1",
        ] {
            assert!(parse_gcs(bad).is_err(), "{bad}");
        }
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

    #[test]
    fn precland_mode_is_px4s_auto_precland() {
        // PX4's custom_mode: main mode in bits 16-23, sub mode in bits 24-31.
        assert_eq!(px4_precland_mode(), 0x0904_0000);
    }

    #[test]
    fn ardupilot_recipe_enables_before_it_reboots_and_px4s_needs_no_reboot() {
        let plan = Plan {
            height_m: 12.0,
            start_north_m: 1.0,
            start_east_m: 2.0,
            yaw_deg: None,
            wind: Some(SitlWind {
                speed_mps: 3.0,
                from_deg: 90.0,
                profile: 1.0,
                turbulence_mps: 1.0,
            }),
        };
        let ap = recipe(Autopilot::ArduPilot, &plan);
        assert_eq!(ap[0].name, "PLND_ENABLED");
        assert!(ap.iter().any(|s| s.name == "PLND_TYPE" && s.needs_reboot));
        assert!(ap
            .iter()
            .any(|s| s.name == "SIM_WIND_SPD" && s.value == 3.0));
        let px4 = recipe(Autopilot::Px4, &plan);
        assert!(px4.iter().all(|s| !s.needs_reboot));
        assert!(px4.iter().all(|s| !s.name.starts_with("SIM_")));
    }

    #[test]
    fn an_offset_point_is_that_far_from_the_pad() {
        let (lat, lon) = offset_lat_lon(47.0, 8.0, 3.0, -4.0);
        let north = (lat - 47.0).to_radians() * 6_378_137.0;
        let east = (lon - 8.0).to_radians() * 6_378_137.0 * 47f64.to_radians().cos();
        assert!((north - 3.0).abs() < 1e-6 && (east + 4.0).abs() < 1e-6);
    }
}
