//! The loop itself: render, run the board and the simulated autopilot, steer, step the
//! vehicle (see [`super`]).

use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use touchdown_core::image::GrayImage;
use touchdown_formats::families::{self, SelectedFamily};
use touchdown_sim::camera::SimCamera;
use touchdown_sim::effects::FlightEffects;
use touchdown_sim::pad_motion::PadMotion;
use touchdown_sim::scenario::{FramePlan, Scenario};
use touchdown_sim::trajectory::{Profile, Segment, Trajectory, Wobble};
use touchdown_sim::{Renderer, SimFrame, Simulator};

use super::land::{LandController, LandParams};
use super::px4::{Px4Params, Px4PrecLand, Px4State};
use super::vehicle::{Vehicle, VehicleParams};
use super::wind::{Wind, WindProfile};
use crate::flight::{
    belief, relative_ned, AutopilotKind, ErrorModel, FlightSetup, TruthSource, TruthTable,
    NED_FROM_PAD, PAD_NED,
};
use crate::{Experiment, Frame, Method};

/// The vehicle's time step, seconds (ArduPilot's 400 Hz loop).
pub const STEP_S: f64 = 0.0025;
/// How far ahead of a frame's time the vehicle is flown before the frame is rendered and
/// processed, seconds: past the last row's exposure (15 ms at the default readout) and the
/// frame's delivery plus the settling of the link (up to 40 ms).
pub const LOOKAHEAD_S: f64 = 0.045;
/// Sub-samples per pixel side at 320x240: a quarter of the landing scenario's 4 x 4 (a
/// QVGA pixel is four VGA ones), so a frame costs about a sixteenth of a VGA frame's.
pub const QVGA_SUPERSAMPLING: usize = 2;
/// Half the span of the differences that give the velocity and attitude rates a frame is
/// rendered with, seconds.
const RATE_SPAN_S: f64 = 0.01;
/// The landing scenario's lens: its horizontal field of view, degrees.
const LANDING_HFOV_DEG: f64 = 60.0;

/// What is flown.
#[derive(Debug, Clone, PartialEq)]
pub struct LandingConfig {
    /// Seed of everything random: the scene, the wind, the error realisation, the start.
    pub seed: u64,
    /// Height of the camera over the pad when LAND begins, metres.
    pub start_height_m: f64,
    /// Horizontal distance from the pad when LAND begins, metres (bearing seeded).
    pub offset_m: f64,
    /// Mean wind, m/s (direction seeded).
    pub wind_mps: f64,
    /// Peak of the gusts, m/s ([`super::wind`]).
    pub gust_mps: f64,
    /// How the wind changes with height ([`WindProfile`]).
    pub wind_profile: WindProfile,
    /// The flight effects the camera is rendered with.
    pub effects: FlightEffects,
    /// The autopilot's error model.
    pub model: ErrorModel,
    /// Board parameters set before the flight, by name.
    pub params: Vec<(String, f32)>,
    /// Camera frames per second.
    pub fps: f64,
    /// Render at 320x240 instead of the landing scenario's 640x480 (same lens), with
    /// `QVGA_SUPERSAMPLING`.
    pub qvga: bool,
    /// The simulator's image model ([`Renderer::Raster`] in [`LandingConfig::issue_15`]).
    pub renderer: Renderer,
    /// The shipped pad design drawn and looked for, by name; `None`: the landing
    /// scenario's own (nested).
    pub pad: Option<String>,
    /// Rendering threads per frame.
    pub threads: usize,
    /// Give up after this long without a touchdown, seconds.
    pub max_flight_s: f64,
    /// The vehicle.
    pub vehicle: VehicleParams,
    /// The LAND mode (ArduPilot).
    pub land: LandParams,
    /// Which autopilot flies the landing.
    pub autopilot: Autopilot,
    /// How the pad moves ([`PadMotion`]; at rest in [`LandingConfig::issue_15`]); its clock is
    /// the flight's, which starts with the LAND.
    pub pad_motion: PadMotion,
}

/// The autopilot of the closed loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Autopilot {
    /// ArduPilot's precision LAND ([`super::land`], [`LandingConfig::land`]), BODY_FRD targets.
    ArduPilot,
    /// PX4's Precision Land ([`super::px4`]), LOCAL_NED targets; its HEARTBEAT reports
    /// AUTO.PRECLAND.
    Px4(Px4Params),
}

/// PX4's `custom_mode` for AUTO.PRECLAND (main mode 4 in bits 16-23, sub-mode 9 above).
pub const PX4_MODE_PRECLAND: u32 = (9 << 24) | (4 << 16);

impl LandingConfig {
    /// Issue 15's landing: from 20 m, 2 m off the pad, 2 m/s of mean wind and 3 m/s gusts,
    /// the typical flight effects and error model, 15 frames per second (the landing
    /// scenario's), VGA.
    pub fn issue_15(seed: u64) -> Self {
        LandingConfig {
            seed,
            start_height_m: 20.0,
            offset_m: 2.0,
            wind_mps: 2.0,
            gust_mps: 3.0,
            wind_profile: WindProfile::Uniform,
            effects: FlightEffects::typical(),
            model: ErrorModel::typical(),
            params: Vec::new(),
            fps: 15.0,
            qvga: false,
            renderer: Renderer::Raster,
            pad: None,
            threads: 1,
            max_flight_s: 90.0,
            vehicle: VehicleParams::typical(),
            land: LandParams::ardupilot(),
            autopilot: Autopilot::ArduPilot,
            pad_motion: PadMotion::at_rest(),
        }
    }
}

/// Where and when the vehicle touched down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Touchdown {
    /// When, seconds from the start of LAND.
    pub t_s: f64,
    /// North of the pad's origin, metres (a moving pad's: along its own north where it is
    /// then).
    pub north_m: f64,
    /// East of it, metres.
    pub east_m: f64,
    /// Horizontal speed then (over the pad, a moving one's deck), m/s.
    pub speed_mps: f64,
}

impl Touchdown {
    /// Horizontal distance from the pad's origin, metres.
    pub fn horizontal_m(&self) -> f64 {
        self.north_m.hypot(self.east_m)
    }
}

/// What a landing gave.
#[derive(Debug, Clone, PartialEq)]
pub struct LandingOutcome {
    /// Its seed.
    pub seed: u64,
    /// Where LAND began, north and east of the pad, metres.
    pub start_ne: (f64, f64),
    /// The touchdown (`None`: none within the time limit).
    pub touchdown: Option<Touchdown>,
    /// When the autopilot received its first LANDING_TARGET, seconds.
    pub first_target_s: Option<f64>,
    /// When the LAND mode first steered on a target (its pad estimate), seconds.
    pub acquired_s: Option<f64>,
    /// When the slow descent (below LAND_ALT_LOW) began, seconds (PX4: when the descent
    /// above the target began).
    pub low_s: Option<f64>,
    /// PX4: when it declared the target lost while landing (and climbed away), seconds.
    pub lost_s: Option<f64>,
    /// PX4: the board's outer-loop shift when the last target was sent, north and east, m.
    pub last_shift_ne: (f64, f64),
    /// When the last target was received, seconds.
    pub last_target_s: Option<f64>,
    /// The height of the camera then, metres.
    pub last_target_height_m: Option<f64>,
    /// The camera's horizontal distance from the landing point then, metres.
    pub last_target_offset_m: Option<f64>,
    /// Longest time between two targets the mode used, seconds.
    pub longest_gap_s: f64,
    /// Frames rendered and processed.
    pub frames: usize,
    /// Frames with a pad fix.
    pub frames_with_fix: usize,
    /// LANDING_TARGETs the companion sent.
    pub targets_sent: u32,
    /// LANDING_TARGETs the autopilot received and reconstructed.
    pub targets_received: usize,
    /// How long the flight ran, seconds.
    pub flight_s: f64,
}

/// The autopilot's mode in the air.
#[allow(clippy::large_enum_variant)]
enum Mode {
    ArduPilot(LandController),
    Px4(Px4PrecLand),
}

/// The flight's moving parts.
struct Air {
    vehicle: Vehicle,
    land: Mode,
    wind: Wind,
    wind_profile: WindProfile,
    truth: TruthTable,
    t_s: f64,
    touchdown: Option<Touchdown>,
    /// How the pad moves (the flight's clock).
    pad_motion: PadMotion,
    /// The vehicle's rotation rate over the last step, rad/s (the autopilot's gyro).
    gyro_rad_s: f64,
}

impl Air {
    /// The height of the vehicle's body origin (the camera) over the pad's plane at `t_s`,
    /// measured straight down (a rangefinder's): over the deck under it as the deck heaves
    /// and rolls.
    fn height_over_pad(&self, vehicle: &Vehicle, t_s: f64) -> f64 {
        if self.pad_motion.is_at_rest() {
            return vehicle.height_m();
        }
        let on_pad = self.on_pad(vehicle, t_s);
        // The deck's up axis in the world: its vertical part turns the height along it into
        // the height straight down.
        let up = self.pad_motion.pose(t_s).rotation[2][2];
        on_pad.z / up
    }

    /// The vehicle's body origin in the moving pad's frame at `t_s` (x east, y north, z up
    /// along the pad's own axes).
    fn on_pad(&self, vehicle: &Vehicle, t_s: f64) -> Vector3<f64> {
        let world = NED_FROM_PAD * vehicle.position_ned;
        Vector3::from(
            self.pad_motion
                .point_relative(t_s, [world.x, world.y, world.z]),
        )
    }

    /// Where the touchdown was: the vehicle between `before` and `after` (a step ending at
    /// `t_s`) where its height over the pad crossed zero, against the pad there and then.
    fn touchdown_between(&self, before: &Vehicle, after: &Vehicle, t_s: f64) -> Touchdown {
        let (h0, h1) = (
            self.height_over_pad(before, t_s - STEP_S),
            self.height_over_pad(after, t_s),
        );
        let w = h0 / (h0 - h1).max(1e-12);
        let p = before.position_ned + (after.position_ned - before.position_ned) * w;
        let at_s = t_s - STEP_S * (1.0 - w);
        if self.pad_motion.is_at_rest() {
            return Touchdown {
                t_s: at_s,
                north_m: p.x,
                east_m: p.y,
                speed_mps: after.velocity_ned.xy().norm(),
            };
        }
        let crossing = Vehicle {
            position_ned: p,
            ..*after
        };
        let on_pad = self.on_pad(&crossing, at_s);
        let deck = Vector3::from(self.pad_motion.velocity_ned(at_s));
        Touchdown {
            t_s: at_s,
            north_m: on_pad.y,
            east_m: on_pad.x,
            speed_mps: (after.velocity_ned - deck).xy().norm(),
        }
    }

    /// Flies to `until_s` (or the touchdown); the autopilot steers on its estimates.
    fn fly_to(&mut self, until_s: f64, errors: &crate::flight::Realisation) {
        while self.t_s < until_s - 1e-9 && self.touchdown.is_none() {
            let own = PAD_NED + self.vehicle.position_ned + errors.position_error(self.t_s);
            let height_m = self.height_over_pad(&self.vehicle, self.t_s);
            let command = match &mut self.land {
                Mode::ArduPilot(land) => {
                    land.command(self.t_s, STEP_S, &own, &self.vehicle.velocity_ned, height_m)
                }
                Mode::Px4(px4) => {
                    px4.command(self.t_s, STEP_S, &own, &self.vehicle.velocity_ned, height_m)
                }
            };
            let before = self.vehicle;
            let wind = self.wind.at(self.t_s) * self.wind_profile.scale(self.vehicle.height_m());
            self.vehicle.step(STEP_S, &command, &wind);
            self.t_s += STEP_S;
            let after = self.vehicle;
            self.gyro_rad_s = rotation_rate(&before.body_to_ned(), &after.body_to_ned(), STEP_S);
            if self.height_over_pad(&after, self.t_s) <= 0.0 {
                self.touchdown = Some(self.touchdown_between(&before, &after, self.t_s));
            }
            self.truth.push(self.t_s, self.vehicle.truth());
        }
    }
}

/// The rotation rate that turns `from` into `to` in `dt_s`, rad/s.
fn rotation_rate(from: &Matrix3<f64>, to: &Matrix3<f64>, dt_s: f64) -> f64 {
    let turn = from.transpose() * to;
    let cos = ((turn.trace() - 1.0) / 2.0).clamp(-1.0, 1.0);
    cos.acos() / dt_s
}

/// The simulator's trajectory for the frame at `t_s`: the vehicle's motion linearised about
/// that time (position and velocity; roll, pitch, yaw and their rates, as slow sines through
/// their value at `t_s`), exact at `t_s` (see [`super`]).
pub fn local_trajectory(truth: &TruthTable, t_s: f64) -> Option<Trajectory> {
    let at = |t: f64| truth.at(t);
    let (now, before, after) = (at(t_s)?, at(t_s - RATE_SPAN_S)?, at(t_s + RATE_SPAN_S)?);
    let euler = |m| Rotation3::from_matrix_unchecked(m).euler_angles();
    let (roll, pitch, yaw) = euler(now.body_to_ned);
    let (r0, p0, y0) = euler(before.body_to_ned);
    let (r1, p1, y1) = euler(after.body_to_ned);
    let wrap = |a: f64| {
        (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
    };
    let span = 2.0 * RATE_SPAN_S;
    let rates = [
        wrap(r1 - r0) / span,
        wrap(p1 - p0) / span,
        wrap(y1 - y0) / span,
    ];
    let velocity = (after.position - before.position) / span;
    // A sine of frequency f and amplitude rate / (2 pi f) through zero at t_s turns at
    // `rate` there; at 0.01 Hz it stays within 1e-9 of that line over a frame.
    let f = 0.01;
    let omega = std::f64::consts::TAU * f;
    let mut terms = [[(0.0, 0.0, 0.0); 3]; 6];
    for (k, rate) in rates.iter().enumerate() {
        terms[3 + k][0] = (rate / omega, f, -omega * t_s);
    }
    let hold = 1.0;
    let p = now.position;
    let from = p - velocity * hold;
    let to = p + velocity * hold;
    Some(Trajectory {
        segments: vec![Segment {
            t0: t_s - hold,
            t1: t_s + hold,
            from: [from.x, from.y, from.z],
            to: [to.x, to.y, to.z],
            profile: Profile::Linear,
        }],
        yaw,
        wobble: Wobble::from_terms(terms),
        tilt_with_acceleration: false,
        trim: (roll, pitch),
    })
}

/// The landing scenario's scene, camera and pad for `config` (no frames: the loop adds them).
pub fn scene(config: &LandingConfig) -> Result<Scenario, String> {
    let mut scenario =
        Scenario::named("landing", config.seed).ok_or("the landing scenario is missing")?;
    if config.qvga {
        let lens = scenario.camera.model.distortion;
        scenario.camera = SimCamera::with_fov(320, 240, LANDING_HFOV_DEG, lens);
        scenario.supersampling = QVGA_SUPERSAMPLING;
    }
    if let Some(name) = &config.pad {
        scenario.pad = touchdown_sim::pad::shipped_design(name)?;
    }
    scenario.frames.clear();
    config.pad_motion.validate()?;
    scenario.pad_motion = config.pad_motion;
    scenario.apply_effects(&config.effects);
    scenario
        .camera
        .model
        .validate()
        .map_err(|e| format!("the camera refuses the readout: {e:?}"))?;
    Ok(scenario)
}

/// Flies one landing of `config`; `on_frame` sees every rendered frame (to record it).
pub fn fly(
    config: &LandingConfig,
    on_frame: &mut dyn FnMut(&SimFrame) -> Result<(), String>,
) -> Result<LandingOutcome, String> {
    if !(config.fps.is_finite() && config.fps > 0.0) {
        return Err(format!("frame rate {} is not positive", config.fps));
    }
    let mut simulator = Simulator::new(scene(config)?)
        .with_threads(config.threads)
        .with_renderer(config.renderer);
    let camera = simulator.scenario.camera.model;
    let pad = simulator.scenario.pad.config.clone();
    let layout = pad
        .layout()
        .map_err(|e| format!("pad `{}`: invalid layout: {e:?}", pad.name))?;
    let selected = families::resolve_pad(&pad).map_err(|e| e.to_string())?;
    let views: Vec<_> = selected.iter().map(SelectedFamily::family).collect();
    let family_refs: Vec<_> = views.iter().collect();
    let kind = match config.autopilot {
        Autopilot::ArduPilot => AutopilotKind::ArduPilot,
        Autopilot::Px4(_) => AutopilotKind::Px4,
    };
    let mut setup = FlightSetup::new(kind, config.model);
    setup.seed = config.seed;
    if kind == AutopilotKind::Px4 {
        setup.autopilot_mode = Some(PX4_MODE_PRECLAND);
    }
    setup.params = config.params.clone();
    let mut experiment =
        Experiment::in_flight(camera, &family_refs, layout, &[Method::ours()], &setup)
            .map_err(|e| format!("cannot set up the board: {e:?}"))?;

    let mut rng = ChaCha8Rng::seed_from_u64(config.seed ^ 0x0073_7461_7274); // "start"
    let bearing: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let start = Vector3::new(
        config.offset_m * bearing.cos(),
        config.offset_m * bearing.sin(),
        -config.start_height_m,
    );
    let vehicle = Vehicle::hovering(config.vehicle, start);
    let errors = experiment
        .flight_run(0)
        .ok_or("no flight")?
        .errors()
        .clone();
    let mut air = Air {
        vehicle,
        land: match config.autopilot {
            Autopilot::ArduPilot => Mode::ArduPilot(LandController::new(
                config.land,
                &(PAD_NED + start + errors.position_error(0.0)),
            )),
            Autopilot::Px4(params) => Mode::Px4(Px4PrecLand::new(
                params,
                &(PAD_NED + start + errors.position_error(0.0)),
            )),
        },
        wind: Wind::new(
            config.wind_mps,
            config.gust_mps,
            config.max_flight_s,
            config.seed,
        ),
        wind_profile: config.wind_profile,
        truth: TruthTable::new(),
        t_s: 0.0,
        touchdown: None,
        pad_motion: config.pad_motion,
        gyro_rad_s: 0.0,
    };
    air.truth.push(0.0, vehicle.truth());

    let mut outcome = LandingOutcome {
        seed: config.seed,
        start_ne: (start.x, start.y),
        touchdown: None,
        first_target_s: None,
        acquired_s: None,
        low_s: None,
        lost_s: None,
        last_shift_ne: (0.0, 0.0),
        last_target_s: None,
        last_target_height_m: None,
        last_target_offset_m: None,
        longest_gap_s: 0.0,
        frames: 0,
        frames_with_fix: 0,
        targets_sent: 0,
        targets_received: 0,
        flight_s: 0.0,
    };
    for k in 0.. {
        let t_s = k as f64 / config.fps;
        if t_s > config.max_flight_s {
            break;
        }
        air.fly_to(t_s + LOOKAHEAD_S, &errors);
        if air.touchdown.is_some_and(|td| td.t_s <= t_s) {
            break;
        }
        let t_us = (t_s * 1e6).round() as u64;
        simulator.scenario.trajectory =
            local_trajectory(&air.truth, t_s).ok_or("no vehicle state")?;
        simulator
            .scenario
            .frames
            .push(FramePlan { t_us, label: None });
        let frame = simulator
            .render(k)
            .ok_or("the simulator rendered nothing")?;
        on_frame(&frame)?;
        let image = GrayImage::new(&frame.image.pixels, frame.image.width, frame.image.height)
            .map_err(|e| format!("frame {k}: {e:?}"))?;
        let board_frame = Frame {
            set_point: None,
            t_us,
            truth: Vector3::from(frame.truth.position),
            attitude: None,
            image,
        };
        let methods = experiment
            .process_with(&board_frame, Some(&air.truth as &dyn TruthSource))
            .map_err(|e| format!("frame {k}: {e:?}"))?;
        outcome.frames += 1;
        outcome.frames_with_fix += usize::from(methods.first().is_some_and(|m| m.pose_found));
        let flight = experiment.flight_run(0).ok_or("no flight")?;
        let Some(result) = experiment.flight_outcomes().first().copied() else {
            continue;
        };
        if let Some(latency) = result.latency_us {
            let receipt_s = t_s + latency as f64 * 1e-6;
            outcome.first_target_s.get_or_insert(receipt_s);
            outcome.last_target_s = Some(receipt_s);
            outcome.last_target_height_m = Some(frame.truth.position[2]);
            outcome.last_target_offset_m =
                Some(frame.truth.position[0].hypot(frame.truth.position[1]));
            let shift = flight.companion.px4_shift();
            outcome.last_shift_ne = (f64::from(shift.x), f64::from(shift.y));
        }
        if let Some(reconstructed) = result.reconstructed {
            // The pad in its local frame: its position estimate at the measurement's time
            // plus the reconstructed vector to the pad.
            let clock = flight.clock();
            let board_us = clock.board_us(reconstructed.t_us);
            let own = belief(&air.truth, clock, flight.errors(), &PAD_NED, board_us)
                .ok_or("no vehicle state")?;
            let relative = relative_ned(&reconstructed.value);
            let pad_ned = own.position_ned + relative;
            outcome.targets_received += 1;
            match &mut air.land {
                Mode::ArduPilot(land) => land.measure(
                    air.t_s,
                    reconstructed.t_us as f64 * 1e-6,
                    &own.position_ned,
                    &relative,
                    air.gyro_rad_s,
                ),
                // PX4 stamps it with the converted time_usec and uses it at once.
                Mode::Px4(px4) => px4.measure(reconstructed.t_us as f64 * 1e-6, &pad_ned),
            }
        }
    }
    // Past the last frame (the pad too close to see, or the time limit) it flies on.
    if air.touchdown.is_none() {
        air.fly_to(config.max_flight_s, &errors);
    }
    let flight = experiment.flight_run(0).ok_or("no flight")?;
    outcome.targets_sent = flight.companion.stats().landing_targets;
    outcome.touchdown = air.touchdown;
    match &air.land {
        Mode::ArduPilot(land) => {
            outcome.acquired_s = land.acquired_s;
            outcome.low_s = land.low_s;
            outcome.longest_gap_s = land.longest_gap_s;
        }
        Mode::Px4(px4) => {
            outcome.acquired_s = px4.approach_s;
            outcome.low_s = px4.descend_s;
            outcome.longest_gap_s = px4.longest_gap_s;
            outcome.lost_s = px4.lost_s;
            debug_assert!(px4.state != Px4State::Start || px4.targets_used == 0);
        }
    }
    outcome.flight_s = air.touchdown.map_or(air.t_s, |t| t.t_s);
    Ok(outcome)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rendered_motion_is_the_vehicle_s_at_the_frame_time() {
        let mut truth = TruthTable::new();
        let mut v = Vehicle::hovering(VehicleParams::typical(), Vector3::new(1.0, 2.0, -10.0));
        let cmd = super::super::vehicle::Command {
            accel_ne: nalgebra::Vector2::new(1.0, -2.0),
            down_mps: 1.0,
        };
        let mut t = 0.0;
        truth.push(t, v.truth());
        while t < 1.0 {
            v.step(STEP_S, &cmd, &Vector3::new(2.0, 0.0, 0.0));
            t += STEP_S;
            truth.push(t, v.truth());
        }
        let at = 0.5;
        let traj = local_trajectory(&truth, at).unwrap();
        let state = traj.state(at);
        let want = truth.at(at).unwrap();
        let p = Vector3::from(state.position);
        assert!((p - want.position).norm() < 1e-9, "{p} {}", want.position);
        let m = nalgebra::Matrix3::from_fn(|i, j| state.attitude[i][j]);
        assert!((m - want.body_to_ned).norm() < 1e-9);
        // 5 ms later, within the readout: the motion followed to well under a millimetre.
        let later = truth.at(at + 0.005).unwrap();
        let p5 = Vector3::from(traj.state(at + 0.005).position);
        assert!((p5 - later.position).norm() < 1e-4);
        let m5 = nalgebra::Matrix3::from_fn(|i, j| traj.state(at + 0.005).attitude[i][j]);
        assert!((m5 - later.body_to_ned).norm() < 1e-4);
    }

    /// The flight's moving parts over a pad moving as `pad_motion`, the vehicle at `ned`.
    fn air(pad_motion: PadMotion, ned: Vector3<f64>) -> Air {
        let vehicle = Vehicle::hovering(VehicleParams::typical(), ned);
        Air {
            vehicle,
            land: Mode::ArduPilot(LandController::new(LandParams::ardupilot(), &ned)),
            wind: Wind::new(0.0, 0.0, 10.0, 1),
            wind_profile: WindProfile::Uniform,
            truth: TruthTable::new(),
            t_s: 0.0,
            touchdown: None,
            pad_motion,
            gyro_rad_s: 0.0,
        }
    }

    #[test]
    fn touchdown_is_on_the_deck_where_it_is_then() {
        // A deck driving 1 m/s north and heaving 0.5 m every 8 s: at 2 s it is 2 m north
        // and at the top of its heave, 0.5 m up.
        let deck = PadMotion {
            velocity_ne_mps: [1.0, 0.0],
            heave_m: 0.5,
            heave_period_s: 8.0,
            ..PadMotion::at_rest()
        };
        let a = air(deck, Vector3::zeros());
        let t = 2.0;
        let before = Vehicle {
            position_ned: Vector3::new(2.1, -0.05, -0.6),
            velocity_ned: Vector3::new(1.2, 0.0, 80.0),
            ..a.vehicle
        };
        assert!((a.height_over_pad(&before, t - STEP_S) - 0.1).abs() < 1e-3);
        let after = Vehicle {
            position_ned: Vector3::new(2.1, -0.05, -0.4),
            ..before
        };
        assert!((a.height_over_pad(&after, t) + 0.1).abs() < 1e-3);
        // Half-way through the step, 0.5 m up: 10 cm north of the deck's centre (and the
        // 1.25 mm it had still to drive), 5 cm west; 0.2 m/s faster than the deck.
        let td = a.touchdown_between(&before, &after, t);
        assert!((td.t_s - (t - 0.5 * STEP_S)).abs() < 1e-4, "{td:?}");
        assert!((td.north_m - 0.10125).abs() < 1e-4, "{td:?}");
        assert!((td.east_m + 0.05).abs() < 1e-9, "{td:?}");
        assert!((td.speed_mps - 0.2).abs() < 1e-6, "{td:?}");
        // Against the pad's start it would have been 2.1 m off.
        let at_rest = air(PadMotion::at_rest(), Vector3::zeros());
        assert!(at_rest.height_over_pad(&after, t) > 0.3);
    }

    #[test]
    fn the_height_over_a_rolling_deck_is_straight_down_to_it() {
        // Rolled 10 degrees about its keel (north) at the top of its roll: one edge down, the
        // other up, the plane through its centre.
        let deck = PadMotion {
            roll_deg: 10.0,
            roll_period_s: 4.0,
            ..PadMotion::at_rest()
        };
        let t = 1.0;
        let pose = deck.pose(t);
        let a = air(deck, Vector3::zeros());
        let over = |ned: Vector3<f64>| {
            a.height_over_pad(
                &Vehicle {
                    position_ned: ned,
                    ..a.vehicle
                },
                t,
            )
        };
        // Over the centre, the height is the height.
        assert!((over(Vector3::new(0.0, 0.0, -1.0)) - 1.0).abs() < 1e-9);
        // A metre to either side, the deck is tan(10 degrees) nearer or farther.
        let tilt = 10f64.to_radians().tan();
        let (east, west) = (
            over(Vector3::new(0.0, 1.0, -1.0)),
            over(Vector3::new(0.0, -1.0, -1.0)),
        );
        assert!(
            ((east - west).abs() - 2.0 * tilt).abs() < 1e-9,
            "{east} {west}"
        );
        // The deck's own down axis says which side is low.
        let side_down = pose.rotation[2][1];
        assert_eq!(east > west, side_down > 0.0, "{east} {west} {side_down}");
    }
}
