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
//!
//! One module per half: `link` (the socket, the parameters, [`prepare`]) and `flight`
//! (the flight's state machine); this one holds what both share: the autopilot, its modes,
//! the plan and the parameter recipe.

use crate::companion::endpoint::EndpointSpec;

mod flight;
mod link;

pub use flight::{BoardPosition, Flight, FlightEnd, FlightLog, PX4_TIMESYNC_ANSWERS};
pub(crate) use link::gcs_frame;
pub use link::{prepare, GcsLink, GpsSwitch, Prepared, Status, CONNECT_PATIENCE, PARAM_TRY};

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
    pub name: String,
    /// Its value.
    pub value: f32,
    /// Takes effect only after a reboot.
    pub needs_reboot: bool,
    /// Absent in some versions: skipped (with a line) instead of an error.
    pub optional: bool,
    /// A bitmask to add to: these bits set in what the autopilot holds, the others kept
    /// (`value` is then unused).
    pub set_bits: Option<u32>,
}

fn setting(name: &str, value: f32) -> ParamSetting {
    ParamSetting {
        name: name.to_string(),
        value,
        needs_reboot: false,
        optional: false,
        set_bits: None,
    }
}

impl ParamSetting {
    /// The value to set where the autopilot holds `held`.
    pub fn wanted(&self, held: f32) -> f32 {
        match self.set_bits {
            // Bitmask parameters are integers, exact in an f32 up to 2^24.
            Some(bits) => ((held.max(0.0) as u32) | bits) as f32,
            None => self.value,
        }
    }
}

/// ArduPilot's ARMING_SKIPCHK bit for the visual odometry check (`ARMING_CHECK_VISION`, bit
/// 18 of `AP_Arming::Check`): "VisOdom: not healthy" while the board sends nothing.
pub const ARMING_SKIP_VISION: u32 = 1 << 18;
/// The simulated GPS's switch: SIM_GPS1_ENABLE (ArduPilot 4.5 and newer) and the value that
/// turns it off, or SIM_GPS_DISABLE (older) and its value.
pub const SIM_GPS_SWITCHES: [(&str, f32); 2] = [("SIM_GPS1_ENABLE", 0.0), ("SIM_GPS_DISABLE", 1.0)];
/// ArduPilot's source set the GPS-denied rehearsal switches to (MAV_CMD_SET_EKF_SOURCE_SET's
/// param1, 1-based): EK3_SRC2_*.
pub const VISION_SOURCE_SET: u8 = 2;

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
    /// How long the vehicle holds still at the start point before the landing, seconds.
    pub hold_s: f64,
    /// The user's own autopilot parameters (`--autopilot-params`), set after the recipe's.
    pub extra: Vec<(String, f32)>,
    /// ArduPilot SITL's wind: mean speed (m/s), direction it blows from (degrees), profile
    /// (SIM_WIND_T) and turbulence (SIM_WIND_TURB, m/s). PX4's SIH has no wind.
    pub wind: Option<SitlWind>,
    /// GPS lost on the climb at this height over the pad, metres (`--gps-loss-height`):
    /// ArduPilot switches to the vision source set and the SITL's GPS is turned off.
    pub gps_loss_height_m: Option<f64>,
    /// No GPS from boot (`--no-gps`): ArduPilot's GPS off and its position from the board
    /// (source set 1); the EKF origin set at the pad; arming waits for the board.
    pub no_gps: bool,
    /// The board sends its velocity too (TD_VPE_EN bit 1): the vision source set fuses it.
    pub vision_velocity: bool,
    /// The pad moves (`--pad-velocity`): ArduPilot's precision landing tracks a moving target
    /// (PLND_OPTIONS bit 0, docs/setup-ardupilot.md, "A moving pad").
    pub moving_pad: bool,
    /// MAVLink 2 signing (`--signing-key`): the key the ground station sets on the autopilot
    /// with SETUP_SIGNING, and its initial timestamp.
    pub signing: Option<([u8; 32], u64)>,
    /// How long the ground station waits for the SITL.
    pub patience: Patience,
}

/// How long the ground station waits for the SITL (`--connect-timeout`, `--param-timeout`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Patience {
    /// A refused connection to the ground-station port is tried again for this long (a SITL
    /// still starting opens its port seconds after it is launched).
    pub connect: std::time::Duration,
    /// Each of a parameter read's or write's three tries waits this long for its answer.
    pub param_try: std::time::Duration,
}

impl Default for Patience {
    fn default() -> Self {
        Patience {
            connect: link::CONNECT_PATIENCE,
            param_try: link::PARAM_TRY,
        }
    }
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
    if let (Autopilot::ArduPilot, true) = (autopilot, plan.moving_pad) {
        // Bit 0: the target's velocity from AC_PrecLand's estimator is flown as a feed-forward.
        list.push(setting("PLND_OPTIONS", 1.0));
    }
    if plan.no_gps {
        list.extend(match autopilot {
            Autopilot::ArduPilot => no_gps_recipe(plan.vision_velocity),
            Autopilot::Px4 => px4_no_gps_recipe(),
        });
    } else if let (Autopilot::ArduPilot, Some(_)) = (autopilot, plan.gps_loss_height_m) {
        let own_arming = plan.extra.iter().any(|(name, _)| name == "ARMING_CHECK");
        list.extend(
            gps_denied_recipe(plan.vision_velocity)
                .into_iter()
                // ArduPilot 4.6 and older: the user's ARMING_CHECK instead.
                .filter(|s| !(own_arming && s.name == "ARMING_SKIPCHK")),
        );
    }
    if let (Autopilot::ArduPilot, Some(w)) = (autopilot, plan.wind) {
        list.extend([
            setting("SIM_WIND_SPD", w.speed_mps),
            setting("SIM_WIND_DIR", w.from_deg),
            setting("SIM_WIND_T", w.profile),
            setting("SIM_WIND_TURB", w.turbulence_mps),
        ]);
    }
    // The user's last: their value wins over the recipe's.
    list.retain(|s| plan.extra.iter().all(|(name, _)| *name != s.name));
    list.extend(plan.extra.iter().map(|(name, value)| setting(name, *value)));
    list
}

/// ArduPilot set up to navigate on the board's VISION_POSITION_ESTIMATE with EKF source set
/// `set` (docs/setup-ardupilot.md, "Without GPS"): the board's position, baro height, compass
/// yaw; its velocity only when the board sends one.
fn external_nav_recipe(set: u8, vision_velocity: bool) -> Vec<ParamSetting> {
    let source = |what: &str, value: f32| setting(&format!("EK3_SRC{set}_{what}"), value);
    let mut list = vec![
        // The MAVLink visual-odometry backend, created at boot (AP_VisualOdom::init).
        ParamSetting {
            needs_reboot: true,
            ..setting("VISO_TYPE", 1.0)
        },
        // The estimate's age on arrival: the board's lag from exposure to sending plus the
        // link (docs/setup-ardupilot.md, VISO_DELAY_MS).
        setting("VISO_DELAY_MS", 80.0),
        source("POSXY", 6.0),
        source("VELXY", if vision_velocity { 6.0 } else { 0.0 }),
        source("POSZ", 1.0),
        source("VELZ", 0.0),
        source("YAW", 1.0),
    ];
    if vision_velocity {
        // ArduPilot weighs VISION_SPEED_ESTIMATE by this, not by the message's covariance:
        // at its default the board's velocity, noisy and late while the vehicle manoeuvres,
        // made the vehicle oscillate and lose the pad (docs/setup-ardupilot.md).
        list.push(setting("VISO_VEL_M_NSE", 1.0));
    }
    list
}

/// GPS lost in flight: source set 2 is the board's, set 1 (GPS) stays as it is for the arming
/// and the climb, and the visual-odometry arming check is skipped (a pad without a rest field
/// has nothing in view on the ground).
fn gps_denied_recipe(vision_velocity: bool) -> Vec<ParamSetting> {
    let mut list = external_nav_recipe(VISION_SOURCE_SET, vision_velocity);
    list.push(ParamSetting {
        set_bits: Some(ARMING_SKIP_VISION),
        ..setting("ARMING_SKIPCHK", 0.0)
    });
    list
}

/// No GPS from boot: source set 1 is the board's, as a vehicle with no GPS receiver is set up.
/// The visual-odometry arming check stays on: the board sends its position with the vehicle on
/// the pad, and a vehicle that cannot see the pad must not take off on it.
fn no_gps_recipe(vision_velocity: bool) -> Vec<ParamSetting> {
    let mut list = external_nav_recipe(1, vision_velocity);
    // No receiver: GPS1_TYPE (ArduPilot 4.6 and newer) or GPS_TYPE (older), read at boot.
    for name in ["GPS1_TYPE", "GPS_TYPE"] {
        list.push(ParamSetting {
            needs_reboot: true,
            optional: true,
            ..setting(name, 0.0)
        });
    }
    list
}

/// No GPS from boot on PX4 (docs/setup-px4.md, "Without GPS"): EKF2 fuses no GPS, the
/// board's horizontal position, baro height; the estimates' delay 0, since once PX4 has
/// synced its clock with the board's (which arming waits for) their time stamps are their
/// exposures.
fn px4_no_gps_recipe() -> Vec<ParamSetting> {
    vec![
        setting("EKF2_GPS_CTRL", 0.0),
        setting("EKF2_EV_CTRL", 1.0),
        setting("EKF2_HGT_REF", 0.0),
        setting("EKF2_EV_DELAY", 0.0),
    ]
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

    /// A plan 2.2 m off the pad at 12 m, nothing else asked for.
    fn plain_plan() -> Plan {
        Plan {
            height_m: 12.0,
            start_north_m: 1.0,
            start_east_m: 2.0,
            yaw_deg: None,
            hold_s: 3.0,
            extra: vec![],
            wind: None,
            gps_loss_height_m: None,
            no_gps: false,
            vision_velocity: false,
            moving_pad: false,
            signing: None,
            patience: Patience::default(),
        }
    }

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
    fn precland_mode_is_px4s_auto_precland() {
        // PX4's custom_mode: main mode in bits 16-23, sub mode in bits 24-31.
        assert_eq!(px4_precland_mode(), 0x0904_0000);
    }

    #[test]
    fn ardupilot_recipe_enables_before_it_reboots_and_px4s_needs_no_reboot() {
        let plan = Plan {
            extra: vec![("PLND_EST_TYPE".into(), 0.0), ("PSC_POSXY_P".into(), 1.5)],
            wind: Some(SitlWind {
                speed_mps: 3.0,
                from_deg: 90.0,
                profile: 1.0,
                turbulence_mps: 1.0,
            }),
            ..plain_plan()
        };
        let ap = recipe(Autopilot::ArduPilot, &plan);
        assert!(ap.iter().all(|s| !s.name.starts_with("VISO_")));
        assert!(ap.iter().all(|s| s.name != "PLND_OPTIONS"));
        let moving = recipe(
            Autopilot::ArduPilot,
            &Plan {
                moving_pad: true,
                signing: None,
                ..plain_plan()
            },
        );
        assert!(moving
            .iter()
            .any(|s| s.name == "PLND_OPTIONS" && s.value == 1.0));
        assert_eq!(ap[0].name, "PLND_ENABLED");
        assert!(ap.iter().any(|s| s.name == "PLND_TYPE" && s.needs_reboot));
        assert!(ap
            .iter()
            .any(|s| s.name == "SIM_WIND_SPD" && s.value == 3.0));
        let px4 = recipe(Autopilot::Px4, &plan);
        assert!(px4.iter().all(|s| !s.needs_reboot));
        assert!(px4.iter().any(|s| s.name == "PSC_POSXY_P"));
        assert!(px4.iter().all(|s| !s.name.starts_with("SIM_")));
    }

    #[test]
    fn the_gps_denied_recipe_comes_only_when_asked_and_adds_the_vision_check_bit() {
        let plan = Plan {
            extra: vec![("VISO_DELAY_MS".into(), 60.0)],
            gps_loss_height_m: Some(12.0),
            vision_velocity: true,
            ..plain_plan()
        };
        let ap = recipe(Autopilot::ArduPilot, &plan);
        let names: Vec<&str> = ap.iter().map(|s| s.name.as_str()).collect();
        let viso = names
            .iter()
            .position(|n| *n == "VISO_TYPE")
            .expect("VISO_TYPE");
        let delay = names
            .iter()
            .position(|n| *n == "VISO_DELAY_MS")
            .expect("delay");
        // The enable parameter first; the user's value last, replacing the recipe's.
        assert!(viso < delay && delay == names.len() - 1, "{names:?}");
        assert!(ap.iter().any(|s| s.name == "VISO_TYPE" && s.needs_reboot));
        assert!(ap
            .iter()
            .any(|s| s.name == "EK3_SRC2_VELXY" && s.value == 6.0));
        assert!(ap
            .iter()
            .any(|s| s.name == "VISO_VEL_M_NSE" && s.value == 1.0));
        let skip = ap
            .iter()
            .find(|s| s.name == "ARMING_SKIPCHK")
            .expect("arming");
        // Bits already skipped stay skipped.
        assert_eq!(skip.wanted(0.0), 262_144.0);
        assert_eq!(skip.wanted(6.0), 262_150.0);
        assert_eq!(skip.wanted(262_144.0), 262_144.0);
        // PX4: nothing of it (the rehearsal refuses it there).
        let px4 = recipe(Autopilot::Px4, &plan);
        assert!(px4.iter().all(|s| !s.name.starts_with("EK3_")));
    }

    /// The value `list` sets `name` to, if it sets it.
    fn value_in(list: &[ParamSetting], name: &str) -> Option<f32> {
        list.iter().find(|s| s.name == name).map(|s| s.value)
    }

    #[test]
    fn without_gps_from_boot_the_first_source_set_is_the_board_and_arming_is_checked() {
        let plan = Plan {
            no_gps: true,
            ..plain_plan()
        };
        let ap = recipe(Autopilot::ArduPilot, &plan);
        let value = |name: &str| value_in(&ap, name);
        assert_eq!(value("EK3_SRC1_POSXY"), Some(6.0));
        assert_eq!(value("EK3_SRC1_VELXY"), Some(0.0));
        assert_eq!(value("EK3_SRC1_POSZ"), Some(1.0));
        assert_eq!(value("GPS1_TYPE"), Some(0.0));
        assert!(ap.iter().all(|s| !s.name.starts_with("EK3_SRC2")));
        // The receiver and the odometry backend are read at boot; the vision arming check
        // stays.
        assert!(ap
            .iter()
            .filter(|s| ["VISO_TYPE", "GPS1_TYPE", "GPS_TYPE"].contains(&s.name.as_str()))
            .all(|s| s.needs_reboot));
        assert!(ap.iter().all(|s| s.name != "ARMING_SKIPCHK"));
        // PX4: EKF2 on the board's horizontal position and the barometer, no GPS, the
        // estimates' delay 0 (their stamps are their exposures once PX4 has synced its clock,
        // which arming waits for).
        let px4 = recipe(Autopilot::Px4, &plan);
        let value = |name: &str| value_in(&px4, name);
        assert_eq!(value("EKF2_GPS_CTRL"), Some(0.0));
        assert_eq!(value("EKF2_EV_CTRL"), Some(1.0));
        assert_eq!(value("EKF2_HGT_REF"), Some(0.0));
        assert_eq!(value("EKF2_EV_DELAY"), Some(0.0));
        assert!(px4
            .iter()
            .all(|s| !s.name.starts_with("EK3_") && !s.name.starts_with("GPS") && !s.needs_reboot));
    }

    #[test]
    fn an_offset_point_is_that_far_from_the_pad() {
        let (lat, lon) = offset_lat_lon(47.0, 8.0, 3.0, -4.0);
        let north = (lat - 47.0).to_radians() * 6_378_137.0;
        let east = (lon - 8.0).to_radians() * 6_378_137.0 * 47f64.to_radians().cos();
        assert!((north - 3.0).abs() < 1e-6 && (east + 4.0).abs() < 1e-6);
    }
}
