//! The flight of a rehearsal as a state machine, polled by the board's loop on every tick:
//! arm (retried while the autopilot refuses), take off, fly to the start point, land in the
//! mode that uses targets, and watch until the autopilot disarms.

use std::io::Write;

use touchdown_core::companion::mavlink::dialects::common::{
    MavCmd, MavFrame, MavMessage, PositionTargetTypemask, COMMAND_INT_DATA,
    SET_POSITION_TARGET_GLOBAL_INT_DATA,
};
use touchdown_eval::flight::TrueState;

use super::{
    offset_lat_lon, px4_precland_mode, Autopilot, GcsLink, Plan, COPTER_GUIDED, COPTER_LAND,
    VISION_SOURCE_SET,
};
use crate::CliError;

/// Arming is retried (the estimator and GPS need their time after boot) for this long, s.
const ARMING_PATIENCE_S: f64 = 180.0;
/// The climb to `--height` may take this long, s.
const TAKEOFF_PATIENCE_S: f64 = 90.0;
/// The move to the start point may take this long (besides `--hold`) before the landing
/// starts anyway, s.
const MOVE_PATIENCE_S: f64 = 30.0;
/// At the start point: within this distance of it, horizontally, metres (PX4 may hold its
/// own set point tens of centimetres off in truth)...
const START_TOLERANCE_M: f64 = 1.0;
/// ... slower than this, m/s ...
const START_SPEED_MPS: f64 = 0.2;
/// ... for `--hold` seconds, and turned to the heading asked for within this, degrees.
const START_HEADING_DEG: f64 = 5.0;
/// Commands not yet taken are sent again after this long, seconds.
const RETRY_S: f64 = 2.0;
/// After the autopilot disarms the run watches this much longer (a re-take-off shows), s.
const AFTER_DISARM_S: f64 = 2.0;
/// ArduPilot's MAV_CMD_SET_EKF_SOURCE_SET (ardupilotmega.xml; not in the common dialect).
const MAV_CMD_SET_EKF_SOURCE_SET: u16 = 42007;
/// Each step of the GPS loss (the source switch acknowledged, the GPS switch echoed) may
/// take this long, seconds; the landing waits as long for the loss beyond the move's own
/// patience.
const GPS_LOSS_PATIENCE_S: f64 = 10.0;

/// What the board's position is at, for the GPS loss.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BoardPosition {
    /// A VISION_POSITION_ESTIMATE was sent lately.
    pub flowing: bool,
    /// The board says its position is fit to navigate on (`CompanionStats::vision_fit`).
    pub fit: bool,
    /// The board's mount calibration is done and in force: its position stays right at
    /// height, not only on the ground.
    pub mount_ready: bool,
    /// The board has answered enough of the autopilot's TIMESYNC requests for PX4 to stamp
    /// its estimates with their exposure times ([`PX4_TIMESYNC_ANSWERS`]).
    pub clock_synced: bool,
}

/// TIMESYNC answers after which PX4 has converged on the board's clock: its window is 500
/// round trips (`Timesync.hpp`, CONVERGENCE_WINDOW); before, it stamps every estimate on
/// arrival, some 70 ms later than its exposure, and EKF2_EV_DELAY cannot be right both before
/// and after (docs/setup-px4.md).
pub const PX4_TIMESYNC_ANSWERS: u32 = 520;

/// What a rehearsal without GPS waits for before it arms, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ArmingWait {
    /// The estimator's origin (SET_GPS_GLOBAL_ORIGIN at the pad).
    Origin,
    /// The board's VISION_POSITION_ESTIMATEs.
    BoardPosition,
    /// The board's mount calibration, made with the vehicle resting on the pad.
    Mount,
    /// PX4's clock sync with the board.
    ClockSync,
}

impl ArmingWait {
    fn says(self) -> &'static str {
        match self {
            ArmingWait::Origin => "setting the EKF origin at the pad (SET_GPS_GLOBAL_ORIGIN)",
            ArmingWait::BoardPosition => "waiting for the board's VISION_POSITION_ESTIMATEs",
            ArmingWait::Mount => {
                "waiting for the board's mount calibration (the vehicle resting on the pad)"
            }
            ArmingWait::ClockSync => {
                "waiting for PX4's clock sync with the board (500 TIMESYNC round trips)"
            }
        }
    }
}

/// Where the GPS loss of a GPS-denied rehearsal is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum GpsLoss {
    /// Not yet at its height, or the board not yet sending its position.
    Waiting { said: bool },
    /// MAV_CMD_SET_EKF_SOURCE_SET sent (again every [`RETRY_S`]) until acknowledged.
    Switching { since_s: f64, next_try_s: f64 },
    /// On the vision source set; the SITL's GPS switch sent until its echo says off.
    TurningOff { since_s: f64, next_try_s: f64 },
    /// The GPS is off.
    Done,
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
    /// GPS-denied rehearsal: when ArduPilot acknowledged the switch to the vision source set.
    pub source_switched_s: Option<f64>,
    /// The vehicle's height over the pad then (truth), metres.
    pub source_switched_height_m: Option<f64>,
    /// When the SITL answered that its GPS is off.
    pub gps_off_s: Option<f64>,
    /// Whether the board said its position was fit to navigate on when the switch began (the
    /// rehearsal does not wait for it).
    pub board_fit_at_switch: Option<bool>,
    /// Without GPS: when the autopilot had its origin.
    pub origin_set_s: Option<f64>,
    /// When the board's mount calibration was in force (any rehearsal: first seen).
    pub mount_ready_s: Option<f64>,
}

/// The flight's state machine (see the module documentation).
pub struct Flight {
    plan: Plan,
    stage: Stage,
    /// The pad's origin, latitude and longitude in degrees and AMSL altitude in metres.
    pad: Option<[f64; 3]>,
    /// PX4: the take-off altitude AMSL in its own estimate.
    target_amsl_m: Option<f64>,
    /// The GPS loss, when the plan asks for one.
    gps_loss: Option<GpsLoss>,
    /// The last wait before arming that was said (each is said once).
    arming_wait_said: Option<ArmingWait>,
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
            gps_loss: plan
                .gps_loss_height_m
                .map(|_| GpsLoss::Waiting { said: false }),
            plan,
            stage: Stage::Arming { next_try_s: 0.0 },
            pad: None,
            target_amsl_m: None,
            arming_wait_said: None,
            log: FlightLog::default(),
        }
    }

    /// The landing's start on the run's clock, once commanded: `--max-time` counts from it.
    pub fn landing_started_s(&self) -> Option<f64> {
        self.log.landing_s
    }

    /// Whether the vehicle is holding a position it was sent to: at the top of the climb
    /// while a GPS-denied rehearsal waits for its GPS loss, or settled at the start point
    /// before the landing (for the board position's accuracy while holding).
    pub fn holding(&self) -> bool {
        match self.stage {
            Stage::TakingOff { .. } => self.log.climbed_s.is_some(),
            Stage::Moving { settled_s, .. } => settled_s.is_some(),
            Stage::Arming { .. } | Stage::Landing { .. } | Stage::Disarmed { .. } => false,
        }
    }

    /// One step: reads the link, and sends what the stage needs. `truth` is the vehicle's
    /// true state in the pad frame (x east, y north, z up), `pad` the pad's geodetic origin,
    /// `board` what the board's position is at (VISION_POSITION_ESTIMATEs).
    pub fn poll(
        &mut self,
        link: &mut GcsLink,
        t: f64,
        truth: Option<(TrueState, f64)>,
        pad: Option<[f64; 3]>,
        board: BoardPosition,
        err: &mut dyn Write,
    ) -> Result<Option<FlightEnd>, CliError> {
        link.pump(err)?;
        self.pad = self.pad.or(pad);
        if board.mount_ready {
            self.log.mount_ready_s.get_or_insert(t);
        }
        if link.status.origin_set {
            self.log.origin_set_s.get_or_insert(t);
        }
        self.lose_gps(link, t, truth.map(|(s, _)| s.position.z), board, err)?;
        let gps_lost = self.gps_loss.is_none_or(|g| g == GpsLoss::Done);
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
                    return Err(CliError(match self.arming_wait_said {
                        Some(wait) => format!(
                            "{} never armed in {ARMING_PATIENCE_S:.0} s: still {}",
                            autopilot.name(),
                            wait.says()
                        ),
                        None => format!(
                            "{} never armed in {ARMING_PATIENCE_S:.0} s (estimator or GPS not ready?){}",
                            autopilot.name(),
                            last_refusal(link)
                        ),
                    }));
                } else if t >= next_try_s && self.pad.is_some() {
                    if let Some(wait) = self.arming_wait(link, board)? {
                        if self.arming_wait_said != Some(wait) {
                            self.arming_wait_said = Some(wait);
                            let _ = writeln!(err, "{t:7.2} s  {}", wait.says());
                        }
                    } else {
                        self.arming_wait_said = None;
                        if autopilot == Autopilot::ArduPilot
                            && link.status.custom_mode != COPTER_GUIDED
                        {
                            link.set_mode(COPTER_GUIDED)?;
                        } else {
                            link.command(
                                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                                [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                            )?;
                        }
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
                let climbed = height.is_some_and(|h| h >= self.plan.height_m - 0.5);
                if climbed {
                    self.log.climbed_s.get_or_insert(t);
                }
                if climbed && !gps_lost {
                    // A GPS-denied rehearsal hovers at the top until GPS is lost, so that the
                    // move flies on the board's position; `lose_gps` bounds the wait.
                } else if climbed {
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
                let held = settled_s.is_some_and(|s| t - s >= self.plan.hold_s);
                if !gps_lost && t - since_s > MOVE_PATIENCE_S + GPS_LOSS_PATIENCE_S {
                    return Err(CliError(format!(
                        "GPS not lost by the landing: the board sent no VISION_POSITION_ESTIMATE \
                         at {:.1} m (TD_VPE_EN bit 0 off, or the pad out of view?)",
                        self.plan.gps_loss_height_m.unwrap_or_default()
                    )));
                }
                let patience_s = MOVE_PATIENCE_S + self.plan.hold_s;
                if gps_lost && (held || t - since_s > patience_s) {
                    self.log.start_held = held;
                    if !held {
                        let _ = writeln!(
                            err,
                            "{t:7.2} s  not settled at the start point in {patience_s:.0} s: landing from here"
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

    /// The GPS loss of a GPS-denied rehearsal: at its height on the climb (or at the top of
    /// it), once the board sends its position, switch ArduPilot's EKF to the vision source set
    /// and then turn the SITL's GPS off, each retried until the autopilot confirms it.
    fn lose_gps(
        &mut self,
        link: &mut GcsLink,
        t: f64,
        height: Option<f64>,
        board: BoardPosition,
        err: &mut dyn Write,
    ) -> Result<(), CliError> {
        let (Some(state), Some(loss_m)) = (self.gps_loss, self.plan.gps_loss_height_m) else {
            return Ok(());
        };
        let next = match state {
            GpsLoss::Waiting { said } => {
                let climbing = matches!(
                    self.stage,
                    Stage::TakingOff { .. } | Stage::Moving { .. }
                );
                // At the top of the climb the take-off counts within its 0.5 m.
                let at = loss_m.min(self.plan.height_m - 0.5);
                if !(climbing && height.is_some_and(|h| h >= at)) {
                    return Ok(());
                }
                let h = height.unwrap_or_default();
                if !board.flowing {
                    if !said {
                        let _ = writeln!(
                            err,
                            "{t:7.2} s  at {h:.1} m: waiting for the board's VISION_POSITION_ESTIMATEs to lose GPS"
                        );
                    }
                    GpsLoss::Waiting { said: true }
                } else {
                    self.log.board_fit_at_switch = Some(board.fit);
                    self.log.source_switched_height_m = height;
                    GpsLoss::Switching {
                        since_s: t,
                        next_try_s: t,
                    }
                }
            }
            GpsLoss::Switching {
                since_s,
                next_try_s,
            } => match link.take_raw_ack(MAV_CMD_SET_EKF_SOURCE_SET) {
                Some(0) => {
                    self.log.source_switched_s = Some(t);
                    self.log.source_switched_height_m = height.or(self.log.source_switched_height_m);
                    let _ = writeln!(
                        err,
                        "{t:7.2} s  at {:.1} m: EKF source set {VISION_SOURCE_SET} (the board's position); turning the GPS off",
                        height.unwrap_or_default()
                    );
                    GpsLoss::TurningOff {
                        since_s: t,
                        next_try_s: t,
                    }
                }
                Some(result) => {
                    return Err(CliError(format!(
                        "{} refused MAV_CMD_SET_EKF_SOURCE_SET {VISION_SOURCE_SET} (MAV_RESULT {result})",
                        link.autopilot.name()
                    )))
                }
                None if t - since_s > GPS_LOSS_PATIENCE_S => {
                    return Err(CliError(format!(
                        "{} did not answer MAV_CMD_SET_EKF_SOURCE_SET in {GPS_LOSS_PATIENCE_S:.0} s",
                        link.autopilot.name()
                    )))
                }
                None if t >= next_try_s => {
                    let mut p = [0.0f32; 7];
                    p[0] = f32::from(VISION_SOURCE_SET);
                    link.command_raw(MAV_CMD_SET_EKF_SOURCE_SET, p)?;
                    GpsLoss::Switching {
                        since_s,
                        next_try_s: t + RETRY_S,
                    }
                }
                None => state,
            },
            GpsLoss::TurningOff {
                since_s,
                next_try_s,
            } => {
                let name = link
                    .gps_switch
                    .as_ref()
                    .map_or(String::new(), |s| format!("{} {}", s.name, s.off));
                if link.gps_switch_held() {
                    self.log.gps_off_s = Some(t);
                    let _ = writeln!(
                        err,
                        "{t:7.2} s  GPS off ({name}): flying on the board's position alone"
                    );
                    GpsLoss::Done
                } else if t - since_s > GPS_LOSS_PATIENCE_S {
                    return Err(CliError(format!(
                        "{} did not confirm {name} in {GPS_LOSS_PATIENCE_S:.0} s",
                        link.autopilot.name()
                    )));
                } else if t >= next_try_s {
                    link.turn_gps_off()?;
                    GpsLoss::TurningOff {
                        since_s,
                        next_try_s: t + RETRY_S,
                    }
                } else {
                    state
                }
            }
            GpsLoss::Done => GpsLoss::Done,
        };
        self.gps_loss = Some(next);
        Ok(())
    }

    /// Without GPS, what arming still waits for (the origin is asked for on the way); `None`
    /// when it may arm.
    fn arming_wait(
        &mut self,
        link: &mut GcsLink,
        board: BoardPosition,
    ) -> Result<Option<ArmingWait>, CliError> {
        if !self.plan.no_gps {
            return Ok(None);
        }
        if !link.status.origin_set {
            if let Some(pad) = self.pad {
                link.set_origin(pad)?;
            }
            return Ok(Some(ArmingWait::Origin));
        }
        // The board holds its position back until its mount is calibrated (or set by hand,
        // TD_CAM_CAL 0): what it sends is what arming may go on.
        Ok(if !board.flowing && !board.mount_ready {
            Some(ArmingWait::Mount)
        } else if !board.flowing {
            Some(ArmingWait::BoardPosition)
        } else if link.autopilot == Autopilot::Px4 && !board.clock_synced {
            Some(ArmingWait::ClockSync)
        } else {
            None
        })
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
