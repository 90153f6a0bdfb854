//! `touchdown sitl --tcp | --udp | --udp-listen`: a landing against a running ArduPilot or PX4
//! SITL instead of the autopilot model.
//!
//! The SITL flies its own vehicle in its own physics; we only watch it and play the camera
//! board. Its *true* state comes from the simulator's ground-truth message, ArduPilot's
//! SIM_STATE (108: `lat_int`/`lon_int` in 1e-7 degrees, altitude AMSL in metres, attitude
//! quaternion body FRD to NED; its float `lat`/`lon` carry 1e-7 degrees too, which a 32-bit
//! float rounds to some 40 cm, so the integers are used when present) or PX4's
//! HIL_STATE_QUATERNION (115: PX4 streams its ground truth in it). The one of the autopilot
//! that answers (its HEARTBEAT) is asked for by the companion itself
//! ([`touchdown_core::companion::Companion::request_stream`]), with SET_MESSAGE_INTERVAL once a
//! second until it flows: in the companion's own sequence, so the SITL's link statistics see
//! one sender, as they would see the board. From that truth, linearised about each
//! frame's time exactly as the model's closed loop does, the simulator renders the camera's
//! view of the pad (`--pad`, by default the recommended pad, which stays in view with the
//! vehicle resting on it); the board's per-frame path
//! ([`touchdown_core::pipeline::FramePipeline`]) and its
//! [`touchdown_core::companion::Companion`] run on it, and every byte the companion sends goes
//! to the SITL over the link, every byte from it to the companion: the SITL sees exactly what
//! the board would send it on its UART, in wall-clock time.
//!
//! The pad lies where `--pad-at` puts it, or, by default, under the vehicle where it was when
//! the first truth sample arrived (start the run with the vehicle on the ground, take off
//! and land with the ground station), its plane [`GEAR_HEIGHT_M`] below the body origin then.
//! Touchdown is the first time the body origin is within [`LANDED_HEIGHT_M`] of the pad
//! plane after it has been above [`AIRBORNE_HEIGHT_M`], once it has stayed there at walking
//! pace for [`LANDED_HOLD_S`]; the error is the horizontal position then against the pad's
//! origin, as in the model's closed loop.
//!
//! With TD_VPE_EN bit 0 the board's VISION_POSITION_ESTIMATEs are set against the truth at
//! their frames' times as they go out (`vision_check`), while the flight holds a position and
//! while airborne: how right the position an autopilot would navigate on is.
//!
//! Each frame is rendered [`FRAME_DELAY_S`] in the past, so that the truth is interpolated
//! between two samples instead of extrapolated: like the board, which processes a frame
//! after its readout, the frame is older than the moment it is processed.

use std::io::Write;
use std::time::{Duration, Instant};

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use touchdown_core::companion::mavlink::dialects::common::MavMessage;
use touchdown_core::companion::{mount_known_for_take_off, FrameParser, Profile, MAX_FRAME_LEN};
use touchdown_core::image::GrayImage;
use touchdown_core::params::PipelineSettings;
use touchdown_core::params::SigningSecret;
use touchdown_core::pipeline::{FramePipeline, PipelineConfig};
use touchdown_eval::closed_loop::{self, LandingConfig};
use touchdown_eval::flight::{board_companion, TrueState, TruthSource, TruthTable, NED_FROM_PAD};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_formats::families::{self, SelectedFamily};
use touchdown_sim::pad_motion::PadMotion;
use touchdown_sim::Simulator;

use super::gcs::{self, Flight, GcsLink};
use super::vision_check::{FrameNote, VisionAccuracy, VisionCheck};
use crate::companion::endpoint::{Endpoint, EndpointSpec};
use crate::companion::interrupt;
use crate::CliError;

/// Metres per radian of latitude (the WGS-84 equatorial radius, ArduPilot's scaling too).
const EARTH_RADIUS_M: f64 = 6_378_137.0;
/// The pad plane below the body origin at the first sample (landing gear).
pub const GEAR_HEIGHT_M: f64 = 0.1;
/// The body origin this close to the pad plane counts as on the ground, metres.
pub const LANDED_HEIGHT_M: f64 = 0.3;
/// The body origin this close to its resting height over the pad plane ([`GEAR_HEIGHT_M`])
/// has reached the ground, metres.
const CONTACT_MARGIN_M: f64 = 0.05;
/// A landing counts only after the vehicle has been this high, metres.
pub const AIRBORNE_HEIGHT_M: f64 = 2.0;
/// On the ground at below [`LANDED_SPEED_MPS`] for this long: landed, seconds.
pub const LANDED_HOLD_S: f64 = 1.0;
/// Slower than this on the ground: at rest, m/s.
const LANDED_SPEED_MPS: f64 = 0.2;
/// A frame is rendered this long before it is processed, seconds.
pub const FRAME_DELAY_S: f64 = 0.05;
/// Below this height no frame is rendered, metres: under the camera's height with the vehicle
/// resting on the pad ([`GEAR_HEIGHT_M`]), so that the board keeps looking (and sending) after
/// touchdown, as it would on the vehicle, while the autopilot finishes its landing.
const MIN_RENDER_HEIGHT_M: f64 = 0.05;
/// After touchdown, the body origin this far above the pad plane again is a re-take-off, m.
const RETAKEOFF_HEIGHT_M: f64 = 0.8;
/// The landing's frames are late when they reach the companion more than this after their
/// exposure, on average, seconds: the run then says it does not keep pace.
pub const LAG_WARNING_S: f64 = 0.1;
/// The bearing of the rehearsal pad's top edge (its +y axis) in the simulator's NED
/// ([`NED_FROM_PAD`]), degrees 0-360.
fn rehearsal_pad_bearing_deg() -> f32 {
    let top = NED_FROM_PAD * nalgebra::Vector3::y();
    (top.y.atan2(top.x).to_degrees() as f32).rem_euclid(360.0)
}
/// Ground-truth rate asked for, µs between samples (50 Hz).
const TRUTH_INTERVAL_US: u32 = 20_000;
/// ArduPilot's ground truth, SIM_STATE (its own entry in ArduPilot's message-id map, beside
/// SIMSTATE 164, which is not in the common dialect).
const MSG_SIM_STATE: u32 = 108;
/// PX4's ground truth, HIL_STATE_QUATERNION.
const MSG_HIL_STATE_QUATERNION: u32 = 115;
/// How often the loop looks at the link and the clock.
const TICK: Duration = Duration::from_millis(1);
/// The board's VISION_POSITION_ESTIMATEs count as flowing while the last is this recent, s
/// (a GPS-denied rehearsal loses GPS only then).
const VISION_FLOWING_S: f64 = 0.5;

/// What a connected landing is told.
#[derive(Debug, Clone)]
pub struct ConnectConfig {
    /// The link to the SITL.
    pub endpoint: EndpointSpec,
    /// The scene, camera, effects, parameters and frame rate (the landing's other fields,
    /// wind and autopilot model, are the SITL's own here).
    pub landing: LandingConfig,
    /// The pad's origin: latitude and longitude (degrees), altitude AMSL (metres).
    pub pad_at: Option<[f64; 3]>,
    /// Give up after this long, seconds (with a rehearsal: after the landing command).
    pub max_time_s: f64,
    /// MAVLink 2 signing (`--signing-key`): the board's key and initial timestamp.
    pub signing: Option<([u8; 32], u64)>,
}

/// A whole rehearsal: the ground station's link and the flight it flies.
pub struct Rehearsal {
    /// The ground-station link, prepared ([`gcs::prepare`]).
    pub link: GcsLink,
    /// The flight.
    pub flight: Flight,
}

/// A ground-truth sample as the SITL sent it, in its geodetic terms.
#[derive(Debug, Clone, Copy, PartialEq)]
struct GeoSample {
    lat_deg: f64,
    lon_deg: f64,
    alt_m: f64,
    body_to_ned: UnitQuaternion<f64>,
}

/// The ground truth of a decoded message, if it is one.
fn ground_truth(message: &MavMessage) -> Option<GeoSample> {
    let quaternion = |w: f32, x: f32, y: f32, z: f32| {
        let q = Quaternion::new(f64::from(w), f64::from(x), f64::from(y), f64::from(z));
        (q.norm() > 0.5).then(|| UnitQuaternion::from_quaternion(q))
    };
    match message {
        MavMessage::SIM_STATE(s) => {
            // ArduPilot fills the float fields with 1e-7 degrees as well; a |value| beyond
            // 180 can only be that.
            let float_deg = |v: f32| {
                let v = f64::from(v);
                if v.abs() > 180.0 {
                    v * 1e-7
                } else {
                    v
                }
            };
            let (lat_deg, lon_deg) = if s.lat_int != 0 || s.lon_int != 0 {
                (f64::from(s.lat_int) * 1e-7, f64::from(s.lon_int) * 1e-7)
            } else {
                (float_deg(s.lat), float_deg(s.lon))
            };
            Some(GeoSample {
                lat_deg,
                lon_deg,
                alt_m: f64::from(s.alt),
                body_to_ned: quaternion(s.q1, s.q2, s.q3, s.q4)?,
            })
        }
        MavMessage::HIL_STATE_QUATERNION(s) => {
            let [w, x, y, z] = s.attitude_quaternion;
            Some(GeoSample {
                lat_deg: f64::from(s.lat) * 1e-7,
                lon_deg: f64::from(s.lon) * 1e-7,
                alt_m: f64::from(s.alt) * 1e-3,
                body_to_ned: quaternion(w, x, y, z)?,
            })
        }
        _ => None,
    }
}

/// The truth in the pad frame (x east, y north, z up from the pad's origin), on a local
/// tangent plane: at the few hundred metres of a landing its error is far below a millimetre.
fn in_pad_frame(sample: &GeoSample, pad: &[f64; 3]) -> TrueState {
    let north = (sample.lat_deg - pad[0]).to_radians() * EARTH_RADIUS_M;
    let east = (sample.lon_deg - pad[1]).to_radians() * EARTH_RADIUS_M * pad[0].to_radians().cos();
    let ned = Vector3::new(north, east, -(sample.alt_m - pad[2]));
    TrueState {
        position: NED_FROM_PAD * ned,
        body_to_ned: *sample.body_to_ned.to_rotation_matrix().matrix(),
    }
}

/// Where and when the vehicle came down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConnectedTouchdown {
    /// Seconds from the start of the run.
    pub t_s: f64,
    /// North and east of the pad's origin, metres.
    pub north_m: f64,
    /// See `north_m`.
    pub east_m: f64,
}

/// What a connected landing did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ConnectedOutcome {
    /// Ground-truth samples received.
    pub truth_samples: usize,
    /// Frames rendered and processed.
    pub frames: usize,
    /// Frames with a pad fix.
    pub frames_with_fix: usize,
    /// LANDING_TARGETs sent.
    pub targets_sent: u32,
    /// Seconds from the start to the first LANDING_TARGET sent.
    pub first_target_s: Option<f64>,
    /// The touchdown, if it came.
    pub touchdown: Option<ConnectedTouchdown>,
    /// Seconds run.
    pub run_s: f64,
    /// Why the run ended early (a lost link, a signal), if it did.
    pub stopped: Option<String>,
    /// Frames the frame rate asked for that were not rendered, the loop being busy.
    pub frames_skipped: usize,
    /// From a frame's exposure to its estimate reaching the companion, seconds: mean, max.
    pub lag_s: Option<(f64, f64)>,
    /// The vehicle rose again after touchdown (seconds, run clock).
    pub retakeoff_s: Option<f64>,
    /// VISION_POSITION_ESTIMATEs sent (TD_VPE_EN bit 0).
    pub vision_estimates_sent: u32,
    /// How right those were against the truth (`None`: none sent).
    pub vision_accuracy: Option<VisionAccuracy>,
}

/// Flies one landing against the SITL at `config.endpoint`; progress lines go to `err`. With a
/// `rehearsal` the ground station flies the vehicle too, and the run ends when the autopilot
/// has disarmed after the landing; without one it ends at touchdown.
pub fn fly(
    config: &ConnectConfig,
    mut rehearsal: Option<&mut Rehearsal>,
    err: &mut dyn Write,
) -> Result<ConnectedOutcome, CliError> {
    let scenario = closed_loop::scene(&config.landing).map_err(CliError)?;
    let mut simulator = Simulator::new(scenario)
        .with_threads(config.landing.threads)
        .with_renderer(config.landing.renderer);
    // The pad lies still until the LAND; from then on it moves as asked, on the run's clock.
    let motion = simulator.scenario.pad_motion;
    simulator.scenario.pad_motion = PadMotion::at_rest();
    let camera = simulator.scenario.camera.model;
    let pad = simulator.scenario.pad.config.clone();
    let layout = pad
        .layout()
        .map_err(|e| CliError(format!("pad `{}`: invalid layout: {e:?}", pad.name)))?;
    let selected = families::resolve_pad(&pad).map_err(CliError::new)?;
    let views: Vec<_> = selected.iter().map(SelectedFamily::family).collect();
    let family_refs: Vec<_> = views.iter().collect();

    let mut companion = board_companion(&config.landing.params).map_err(CliError)?;
    if let Some((key, timestamp)) = config.signing {
        companion.set_signing_secret(SigningSecret::new(key, timestamp), 0);
    }
    let settings = PipelineSettings::from_params(companion.params());
    let mut pipeline = FramePipeline::new(
        &family_refs,
        &layout,
        camera,
        PipelineConfig::default(),
        settings,
    )
    .map_err(|e| CliError(format!("pipeline configuration: {e:?}")))?;
    let mut workspace = HostWorkspace::new();

    let name = config.endpoint.describe();
    interrupt::install().map_err(|e| CliError(format!("signal handlers: {e}")))?;
    let mut endpoint =
        Endpoint::open(&config.endpoint).map_err(|e| CliError(format!("{name}: {e}")))?;
    let mut parser = FrameParser::new();
    // The ground-truth samples of one loop tick (kept to reuse its allocation).
    let mut samples: Vec<GeoSample> = Vec::new();
    let mut truth = TruthTable::new();
    let mut pad_at = config.pad_at;
    let mut outcome = ConnectedOutcome::default();
    let mut rx = [0u8; 4096];
    let mut tx = [0u8; MAX_FRAME_LEN];
    let mut truth_requested = false;
    let mut airborne = false;
    let mut on_ground_since: Option<(f64, Vector3<f64>)> = None;
    // On a moving pad: when and where (in the world) the vehicle first reached the ground,
    // since the pad goes on moving while it settles.
    let mut contact: Option<(f64, Vector3<f64>)> = None;
    let frame_period_s = 1.0 / config.landing.fps;
    let mut next_frame_s = 0.0;
    let start = Instant::now();
    let now_s = || start.elapsed().as_secs_f64();
    if let Some(r) = rehearsal.as_deref_mut() {
        r.link.set_clock_zero(start);
    }
    let (mut lag_sum, mut lag_max, mut lag_count) = (0.0, 0.0_f64, 0usize);
    // The board's VISION_POSITION_ESTIMATEs: how many, and when the count last grew.
    let (mut vision_sent, mut vision_sent_s) = (0u32, f64::NEG_INFINITY);
    // The board's mount calibration in force, as of the last frame (it changes only there).
    let mut mount_ready = false;
    let mut vision_check = VisionCheck::new(rehearsal.is_some());
    // What the board made of the pad's motion (TD_PAD_MOTION), as of the last frame.
    let mut board_pad_moving = false;

    let _ = writeln!(
        err,
        "{name}: waiting for the SITL's ground truth (SIM_STATE or HIL_STATE_QUATERNION)"
    );
    'run: loop {
        let t = now_s();
        outcome.run_s = t;
        let landing_s = match rehearsal.as_deref() {
            Some(r) => r.flight.landing_started_s(),
            None => Some(0.0),
        };
        if landing_s.is_some_and(|l| t - l > config.max_time_s) {
            break;
        }
        if let (Some(_), Some(l), false) = (
            rehearsal.as_deref(),
            landing_s,
            motion.is_at_rest() || !simulator.scenario.pad_motion.is_at_rest(),
        ) {
            simulator.scenario.pad_motion = PadMotion {
                start_s: l,
                ..motion
            };
            let [n, e] = motion.velocity_ne_mps;
            let _ = writeln!(
                err,
                "{t:7.2} s  the pad starts to move: north {n:+.2}, east {e:+.2} m/s, turning {:.1} deg/s",
                motion.turn_rate_deg_s
            );
        }
        let pad_motion = simulator.scenario.pad_motion;
        if let Some(signal) = interrupt::received() {
            outcome.stopped = Some(format!("stopped by {}", signal.name()));
            break;
        }
        // Bytes in: to the companion as they come, and the ground truth out of them.
        samples.clear();
        let drained = endpoint.drain(&mut rx, |bytes| {
            companion.receive(bytes, (now_s() * 1e6) as u64);
            parser.push(bytes, |frame| {
                if let Some(sample) = frame.decode().ok().as_ref().and_then(ground_truth) {
                    samples.push(sample);
                }
            });
        });
        for &sample in &samples {
            let pad = *pad_at.get_or_insert([
                sample.lat_deg,
                sample.lon_deg,
                sample.alt_m - GEAR_HEIGHT_M,
            ]);
            if outcome.truth_samples == 0 {
                let _ = writeln!(
                    err,
                    "{name}: ground truth flowing; the pad at {:.7}, {:.7}, {:.2} m AMSL",
                    pad[0], pad[1], pad[2]
                );
            }
            outcome.truth_samples += 1;
            truth.push(now_s(), in_pad_frame(&sample, &pad));
        }
        if let Err(lost) = drained {
            outcome.stopped = Some(format!("{name}: {lost}"));
            break 'run;
        }
        // The autopilot's ground truth, once its HEARTBEAT has said which autopilot it is (the
        // SITL may not stream it on this port unasked).
        if let (false, Some(profile)) = (truth_requested, companion.profile()) {
            truth_requested = true;
            let message_id = match profile {
                Profile::Px4 => MSG_HIL_STATE_QUATERNION,
                Profile::ArduPilot | Profile::ArduPilotLocalFrd => MSG_SIM_STATE,
            };
            companion
                .request_stream(message_id, TRUTH_INTERVAL_US)
                .map_err(|e| CliError(format!("asking for the ground truth: {e:?}")))?;
        }
        if let Err(e) = pipeline.follow_params(companion.params()) {
            let _ = writeln!(
                err,
                "warning: board settings not all taken ({e:?}): the pad as built or the built camera in their place"
            );
        }
        // The landing's state from the newest truth.
        let now_truth = truth.at(t).map(|state| {
            let speed = truth.at(t - 0.1).map_or(0.0, |before| {
                (state.position - before.position).norm() / 0.1
            });
            (state, speed)
        });
        if let Some((state, speed)) = now_truth {
            let height = state.position.z;
            airborne |= height > AIRBORNE_HEIGHT_M;
            if airborne && outcome.touchdown.is_none() {
                if height <= GEAR_HEIGHT_M + CONTACT_MARGIN_M && contact.is_none() {
                    contact = Some((t, state.position));
                    // The deck carries the vehicle on; the SITL's ground stands still.
                    simulator.scenario.pad_motion.stop_s = t;
                } else if height > LANDED_HEIGHT_M && contact.is_some() {
                    // A bounce: the deck moves on under the vehicle until it is down again.
                    contact = None;
                    simulator.scenario.pad_motion.stop_s = f64::INFINITY;
                }
            }
            if let Some(td) = outcome.touchdown {
                if height > RETAKEOFF_HEIGHT_M && outcome.retakeoff_s.is_none() {
                    outcome.retakeoff_s = Some(t);
                    let _ = writeln!(
                        err,
                        "{t:7.2} s  the vehicle rose again after its touchdown at {:.2} s",
                        td.t_s
                    );
                }
            } else if airborne && height < LANDED_HEIGHT_M && speed < LANDED_SPEED_MPS {
                let (since, at) = *on_ground_since.get_or_insert((t, state.position));
                if t - since >= LANDED_HOLD_S {
                    // On a moving pad, where the pad was when the vehicle reached the ground.
                    let (since, at) = match contact {
                        Some((t_c, p)) if !pad_motion.is_at_rest() => {
                            (t_c, Vector3::from(pad_motion.point_relative(t_c, p.into())))
                        }
                        _ => (since, at),
                    };
                    outcome.touchdown = Some(ConnectedTouchdown {
                        t_s: since,
                        north_m: at.y,
                        east_m: at.x,
                    });
                    if rehearsal.is_none() {
                        break;
                    }
                    let _ = writeln!(
                        err,
                        "{since:7.2} s  touchdown {:.1} cm from the pad centre",
                        100.0 * at.y.hypot(at.x)
                    );
                }
            } else {
                on_ground_since = None;
            }
        }
        if let Some(r) = rehearsal.as_deref_mut() {
            let board = gcs::BoardPosition {
                flowing: t - vision_sent_s < VISION_FLOWING_S,
                fit: companion.stats().vision_fit,
                mount_ready,
                clock_synced: companion.stats().timesync_answers >= gcs::PX4_TIMESYNC_ANSWERS,
            };
            match r.flight.poll(&mut r.link, t, now_truth, pad_at, board, err) {
                Ok(Some(_)) => break,
                Ok(None) => {}
                Err(e) => {
                    say_mount_calibration(&pipeline, err);
                    return Err(e);
                }
            }
        }
        // A frame when one is due and the truth covers its time.
        let frame_s = t - FRAME_DELAY_S;
        if t >= next_frame_s && !truth.is_empty() && frame_s > 0.0 {
            if next_frame_s > 0.0 {
                outcome.frames_skipped += ((t - next_frame_s) / frame_period_s).floor() as usize;
            }
            next_frame_s = (next_frame_s + frame_period_s).max(t);
            let high_enough = truth
                .at(frame_s)
                .is_some_and(|s| s.position.z > MIN_RENDER_HEIGHT_M);
            if let (true, Some(trajectory)) =
                (high_enough, closed_loop::local_trajectory(&truth, frame_s))
            {
                let t_us = (frame_s * 1e6).round() as u64;
                simulator.scenario.trajectory = trajectory;
                let index = outcome.frames;
                let frame = simulator.render_at(t_us, index);
                let image =
                    GrayImage::new(&frame.image.pixels, frame.image.width, frame.image.height)
                        .map_err(|e| CliError(format!("frame {index}: {e:?}")))?;
                let mut buffers = workspace.buffers(frame.image.width, frame.image.height);
                let report = pipeline.process(&image, t_us, companion.vehicle(), &mut buffers);
                // The board's own rule for a position to take off on.
                mount_ready = mount_known_for_take_off(
                    companion.params(),
                    pipeline.estimator().mount_sigma_deg(),
                );
                outcome.frames += 1;
                outcome.frames_with_fix += usize::from(report.fix.is_some());
                let handed_s = now_s();
                vision_check.on_frame(FrameNote {
                    exposure_us: t_us,
                    holding: rehearsal.as_deref().map(|r| r.flight.holding()),
                });
                companion.on_estimate(&report.estimate, (handed_s * 1e6) as u64);
                if companion.pad_moving() != board_pad_moving {
                    board_pad_moving = companion.pad_moving();
                    let speed = companion.pad_velocity_ne().map_or(0.0, |v| v.norm());
                    let _ = writeln!(
                        err,
                        "{handed_s:7.2} s  the board takes the pad as {} ({speed:.2} m/s over the ground)",
                        if board_pad_moving { "moving" } else { "at rest" }
                    );
                }
                let lag = handed_s - frame_s;
                lag_sum += lag;
                lag_max = lag_max.max(lag);
                lag_count += 1;
            }
        }
        while let Some(n) = companion.poll_transmit((now_s() * 1e6) as u64, &mut tx) {
            let bytes = tx.get(..n).unwrap_or(&[]);
            let _ = endpoint.send(bytes);
            vision_check.on_sent(bytes, companion.timesync(), &truth, AIRBORNE_HEIGHT_M);
        }
        let sent = companion.stats().landing_targets;
        if sent > 0 && outcome.first_target_s.is_none() {
            outcome.first_target_s = Some(now_s());
        }
        outcome.targets_sent = sent;
        let vision = companion.stats().vision_estimates;
        if vision != vision_sent {
            (vision_sent, vision_sent_s) = (vision, now_s());
        }
        outcome.vision_estimates_sent = vision;
        std::thread::sleep(TICK);
    }
    outcome.lag_s = (lag_count > 0).then(|| (lag_sum / lag_count as f64, lag_max));
    outcome.vision_accuracy = vision_check.report();
    say_mount_calibration(&pipeline, err);
    Ok(outcome)
}

/// The board's mount calibration: what it made of the flight (a rehearsal without GPS waits
/// for it), for whoever wonders why the board's position was or was not fit, or why the
/// vehicle never armed.
fn say_mount_calibration(pipeline: &FramePipeline, err: &mut dyn Write) {
    let calibrator = pipeline.estimator().mount_calibrator();
    let st = calibrator.stats();
    let estimate = calibrator
        .estimate()
        .map_or("no estimate".to_string(), |e| {
            format!(
                "roll {:+.2} pitch {:+.2} deg +-{:.2}{}",
                e.roll_deg,
                e.pitch_deg,
                e.sigma_deg(),
                if e.confident { ", confident" } else { "" }
            )
        });
    let _ = writeln!(
        err,
        "board's mount calibration: {estimate}; frames accepted {}, refused: poor tilt {}, \
         tilt not measured {}, ambiguous {}, not level {}, outliers {}",
        st.accepted, st.poor_tilt, st.tilt_not_measured, st.ambiguous, st.not_level, st.outliers
    );
}

/// The JSON record of a rehearsal's ground-station part (keys in docs/interfaces.md).
#[derive(Debug, serde::Serialize)]
struct RehearsalJson {
    autopilot: &'static str,
    params_changed: Vec<String>,
    rebooted: bool,
    armed_s: Option<f64>,
    landing_command_s: Option<f64>,
    landing_start_north_m: Option<f64>,
    landing_start_east_m: Option<f64>,
    landing_height_m: Option<f64>,
    start_held: bool,
    landing_to_touchdown_s: Option<f64>,
    disarmed_s: Option<f64>,
    /// When the autopilot had its EKF origin, and when the board's mount calibration was in
    /// force (first seen; null: never).
    origin_set_s: Option<f64>,
    mount_ready_s: Option<f64>,
    autopilot_messages: Vec<(f64, String)>,
    /// Only with --gps-loss-height: the key is absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    gps_loss: Option<GpsLossJson>,
}

/// What happened to the GPS in a GPS-denied rehearsal (keys in docs/interfaces.md).
#[derive(Debug, serde::Serialize)]
struct GpsLossJson {
    /// `--gps-loss-height`, metres.
    height_m: f64,
    /// When ArduPilot acknowledged the vision source set, and the height then (truth).
    source_switched_s: Option<f64>,
    source_switched_height_m: Option<f64>,
    /// When the SITL answered that its GPS is off, and which parameter turned it off.
    gps_off_s: Option<f64>,
    gps_param: Option<String>,
    /// Whether the board's position was fit to navigate on when the switch began.
    board_fit_at_switch: Option<bool>,
    /// VISION_POSITION_ESTIMATEs the board sent over the whole run.
    vision_estimates_sent: u32,
}

/// The JSON record of a connected landing (keys in docs/interfaces.md).
#[derive(Debug, serde::Serialize)]
struct ConnectedJson {
    autopilot: &'static str,
    endpoint: String,
    touched_down: bool,
    touchdown_s: Option<f64>,
    north_cm: Option<f64>,
    east_cm: Option<f64>,
    horizontal_cm: Option<f64>,
    first_target_s: Option<f64>,
    truth_samples: usize,
    frames: usize,
    frames_with_fix: usize,
    frames_skipped: usize,
    lag_ms_mean: Option<f64>,
    lag_ms_max: Option<f64>,
    targets_sent: u32,
    retakeoff_s: Option<f64>,
    run_s: f64,
    stopped: Option<String>,
    rehearsal: Option<RehearsalJson>,
    /// Only when the board sent VISION_POSITION_ESTIMATEs: the key is absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    vision_accuracy: Option<VisionAccuracy>,
}

/// The rehearsal's plan from the command line: the start point at `--offset` on a bearing
/// the seed picks (golden-ratio steps, so that consecutive seeds spread around the pad), the
/// wind from `--wind-mps`, `--wind-profile` and `--turbulence`, from a seeded direction.
fn plan(args: &super::SitlArgs, extra: Vec<(String, f32)>, vision_velocity: bool) -> gcs::Plan {
    let golden = 0.618_033_988_749_895;
    let bearing = ((args.seed as f64) * golden).fract() * std::f64::consts::TAU;
    let wind_from = ((args.seed as f64 + 0.5) * golden).fract() * 360.0;
    gcs::Plan {
        height_m: args.height,
        start_north_m: args.offset * bearing.cos(),
        start_east_m: args.offset * bearing.sin(),
        yaw_deg: args.yaw,
        hold_s: args.hold,
        extra,
        wind: Some(gcs::SitlWind {
            speed_mps: args.wind_mps as f32,
            from_deg: wind_from.round() as f32,
            profile: match args.wind_profile {
                super::WindProfileArg::Uniform => 1.0,
                super::WindProfileArg::Sitl => 0.0,
            },
            turbulence_mps: args.turbulence as f32,
        }),
        gps_loss_height_m: args.gps_loss_height,
        no_gps: args.no_gps,
        vision_velocity,
        moving_pad: args.pad_motion.any_given(),
        signing: None,
        patience: gcs::Patience {
            connect: std::time::Duration::from_secs_f64(args.connect_timeout),
            param_try: std::time::Duration::from_secs_f64(args.param_timeout),
        },
    }
}

/// `touchdown sitl` against a running SITL: flies, prints the outcome (text or `--json`).
pub(super) fn run(
    args: &super::SitlArgs,
    endpoint: EndpointSpec,
    params: Vec<(String, f32)>,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<super::Outcome, CliError> {
    if args.seeds > 1 || args.record.is_some() {
        return Err(CliError::new(
            "--seeds and --record fly the model; a running SITL flies one landing",
        ));
    }
    let motion = args.pad_motion.motion(0.0)?;
    if !motion.is_at_rest() {
        if args.gcs.is_none() {
            return Err(CliError::new(
                "a moving pad against a running SITL needs --gcs: its motion starts with the LAND \
                 the ground station commands",
            ));
        }
        if args.pad_motion.deck_heave.is_some() || args.pad_motion.deck_roll.is_some() {
            return Err(CliError::new(
                "--deck-heave and --deck-roll are for the model: the SITL's ground is flat and \
                 still (give --pad-velocity alone, or fly the model without --tcp/--udp)",
            ));
        }
        if args.gps_loss_height.is_some() || args.no_gps {
            return Err(CliError::new(
                "--no-gps and --gps-loss-height navigate on the board's position against the pad, \
                 which means nothing on a moving pad (docs/setup-ardupilot.md, \"A moving pad\")",
            ));
        }
    }
    let gps_denied = args.gps_loss_height.is_some() || args.no_gps;
    let gps_flag = if args.no_gps {
        "--no-gps"
    } else {
        "--gps-loss-height"
    };
    if gps_denied && args.gcs.is_none() {
        return Err(CliError(format!(
            "{gps_flag} needs --gcs: the ground station sets the autopilot's sources"
        )));
    }
    let params = if gps_denied {
        gps_denied_board_params(params, gps_flag)?
    } else {
        params
    };
    let vpe_en = vpe_enable(&params);
    let landing = LandingConfig {
        effects: args.effect_terms.effects(args.ideal),
        params,
        fps: args.fps,
        qvga: args.qvga,
        // In wall-clock time the frames must keep pace: the fast image model unless asked.
        renderer: args
            .renderer
            .unwrap_or(crate::renderer::RendererArg::Warp)
            .renderer(),
        // A rehearsal starts with the vehicle resting on the pad: the pad it can see there.
        pad: Some(args.pad_name()),
        threads: args
            .threads
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        // Its clock starts with the LAND ([`fly`] sets it).
        pad_motion: motion,
        ..LandingConfig::issue_15(args.seed)
    };
    let signing = match args.signing_key.as_deref() {
        None => None,
        Some(_) if args.gcs.is_none() => {
            return Err(CliError::new(
                "--signing-key needs --gcs: the ground station sets the key on the autopilot",
            ))
        }
        Some(text) => Some((
            crate::signing_key::parse(text).map_err(|e| CliError(format!("--signing-key: {e}")))?,
            crate::signing_key::timestamp_now(),
        )),
    };
    let config = ConnectConfig {
        endpoint: endpoint.clone(),
        landing,
        pad_at: args.pad_at,
        max_time_s: args.max_time,
        signing,
    };
    let mut rehearsal = None;
    let mut prepared = gcs::Prepared::default();
    if let Some(spec) = &args.gcs {
        let extra =
            crate::parse_param_list("--autopilot-params", args.autopilot_params.as_deref())?;
        if let Some((name, _)) = extra.iter().find(|(n, _)| n.is_empty() || n.len() > 16) {
            return Err(CliError(format!(
                "--autopilot-params: `{name}` is not a parameter name (1-16 characters)"
            )));
        }
        let mut plan = plan(args, extra, vpe_en & 2 != 0);
        plan.signing = signing;
        let (link, p) = gcs::prepare(spec, &plan, err)?;
        prepared = p;
        rehearsal = Some(Rehearsal {
            link,
            flight: Flight::new(plan),
        });
    }
    let o = fly(&config, rehearsal.as_mut(), err)?;
    let td = o.touchdown;
    let horizontal = td.map(|t| 100.0 * t.north_m.hypot(t.east_m));
    let log = rehearsal.as_ref().map(|r| r.flight.log.clone());
    let landing_to_touchdown = log.as_ref().and_then(|l| Some(td?.t_s - l.landing_s?));
    if let Some((mean, _)) = o.lag_s.filter(|(mean, _)| *mean > LAG_WARNING_S) {
        let _ = writeln!(
            err,
            "warning: the frames do not keep pace: {:.0} ms from exposure to target on average \
             (over {:.0} ms), {} frames skipped; try --qvga or a lower --fps",
            1e3 * mean,
            1e3 * LAG_WARNING_S,
            o.frames_skipped
        );
    }
    let text = if args.json {
        let json = ConnectedJson {
            autopilot: "sitl",
            endpoint: endpoint.describe(),
            touched_down: td.is_some(),
            touchdown_s: td.map(|t| t.t_s),
            north_cm: td.map(|t| 100.0 * t.north_m),
            east_cm: td.map(|t| 100.0 * t.east_m),
            horizontal_cm: horizontal,
            first_target_s: o.first_target_s,
            truth_samples: o.truth_samples,
            frames: o.frames,
            frames_with_fix: o.frames_with_fix,
            frames_skipped: o.frames_skipped,
            lag_ms_mean: o.lag_s.map(|(m, _)| 1e3 * m),
            lag_ms_max: o.lag_s.map(|(_, m)| 1e3 * m),
            targets_sent: o.targets_sent,
            retakeoff_s: o.retakeoff_s,
            run_s: o.run_s,
            stopped: o.stopped.clone(),
            rehearsal: rehearsal
                .as_ref()
                .zip(log.as_ref())
                .map(|(r, l)| RehearsalJson {
                    autopilot: r.link.autopilot.name(),
                    params_changed: prepared.changed.clone(),
                    rebooted: prepared.rebooted,
                    armed_s: l.armed_s,
                    landing_command_s: l.landing_s,
                    landing_start_north_m: l.landing_start_ne.map(|p| p.0),
                    landing_start_east_m: l.landing_start_ne.map(|p| p.1),
                    landing_height_m: l.landing_height_m,
                    start_held: l.start_held,
                    landing_to_touchdown_s: landing_to_touchdown,
                    disarmed_s: l.disarmed_s,
                    origin_set_s: l.origin_set_s,
                    mount_ready_s: l.mount_ready_s,
                    autopilot_messages: r.link.texts.clone(),
                    gps_loss: args.gps_loss_height.map(|height_m| GpsLossJson {
                        height_m,
                        source_switched_s: l.source_switched_s,
                        source_switched_height_m: l.source_switched_height_m,
                        gps_off_s: l.gps_off_s,
                        gps_param: r.link.gps_switch.as_ref().map(|s| s.name.clone()),
                        board_fit_at_switch: l.board_fit_at_switch,
                        vision_estimates_sent: o.vision_estimates_sent,
                    }),
                }),
            vision_accuracy: o.vision_accuracy.clone(),
        };
        let mut line = serde_json::to_string(&json).map_err(CliError::new)?;
        line.push('\n');
        line
    } else {
        let mut t = format!(
            "{}: {} ground-truth samples; timeline, s from the start of the run:\n",
            endpoint.describe(),
            o.truth_samples
        );
        // The events in the order they happened (a rehearsal's board sends its first
        // target during the climb, long before the landing).
        let mut events: Vec<(f64, String)> = Vec::new();
        if let (Some(r), Some(l)) = (&rehearsal, &log) {
            if let Some(a) = l.armed_s {
                let reboot = if prepared.rebooted {
                    ", rebooted once for its parameters"
                } else {
                    ""
                };
                events.push((a, format!("armed ({}{reboot})", r.link.autopilot.name())));
            }
            if let Some(s) = l.landing_s {
                let from = match (l.landing_start_ne, l.landing_height_m) {
                    (Some((n, e)), Some(h)) => format!(
                        " at {h:.1} m, {:.2} m off the pad (north {n:+.2}, east {e:+.2} m)",
                        n.hypot(e)
                    ),
                    _ => String::new(),
                };
                events.push((s, format!("landing commanded{from}")));
            }
            if let Some(d) = l.disarmed_s {
                events.push((d, "disarmed".into()));
            }
            if let Some(s) = l.source_switched_s {
                let at = l
                    .source_switched_height_m
                    .map_or(String::new(), |h| format!(" at {h:.1} m"));
                events.push((s, format!("EKF source set 2 (the board's position){at}")));
            }
            if let Some(s) = l.gps_off_s {
                let switch = r
                    .link
                    .gps_switch
                    .as_ref()
                    .map_or(String::new(), |s| format!(" ({} {})", s.name, s.off));
                events.push((s, format!("GPS lost{switch}")));
            }
        }
        if let Some(f) = o.first_target_s {
            events.push((f, "first LANDING_TARGET sent".into()));
        }
        if let Some(td) = td {
            let after = landing_to_touchdown.map_or(String::new(), |d| {
                format!(" ({d:.1} s after the landing command)")
            });
            events.push((td.t_s, format!("touchdown{after}")));
        }
        if let Some(r) = o.retakeoff_s {
            events.push((r, "rose again after touchdown".into()));
        }
        events.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (s, what) in &events {
            t.push_str(&format!("  {s:>7.2}  {what}\n"));
        }
        match (td, horizontal) {
            (Some(td), Some(h)) => t.push_str(&format!(
                "touchdown: {h:.1} cm from the pad centre (north {:+.1}, east {:+.1} cm)\n",
                100.0 * td.north_m,
                100.0 * td.east_m
            )),
            _ => t.push_str(&format!(
                "no touchdown in {:.0} s{}\n",
                o.run_s,
                o.stopped
                    .as_deref()
                    .map_or(String::new(), |s| format!(" ({s})"))
            )),
        }
        t.push_str(&format!(
            "frames {} ({} with a pad fix, {} skipped), LANDING_TARGETs sent {}{}\n",
            o.frames,
            o.frames_with_fix,
            o.frames_skipped,
            o.targets_sent,
            o.lag_s.map_or(String::new(), |(mean, max)| format!(
                "; lag from exposure to target {:.0} ms mean, {:.0} ms max",
                1e3 * mean,
                1e3 * max
            ))
        ));
        if let Some(v) = &o.vision_accuracy {
            if let Some(holding) = &v.holding {
                t.push_str(&holding.line("while holding"));
                t.push('\n');
            }
            t.push_str(&v.airborne.line("while airborne"));
            t.push('\n');
        }
        if let (Some(loss_m), Some(l)) = (args.gps_loss_height, &log) {
            t.push_str(&match (l.gps_off_s, l.source_switched_height_m) {
                (Some(s), Some(h)) => format!(
                    "GPS lost at {s:.2} s, {h:.1} m up (asked: {loss_m:.1} m); \
                     VISION_POSITION_ESTIMATEs sent {}\n",
                    o.vision_estimates_sent
                ),
                _ => format!(
                    "GPS not lost (asked at {loss_m:.1} m); VISION_POSITION_ESTIMATEs sent {}\n",
                    o.vision_estimates_sent
                ),
            });
        }
        t
    };
    out.write_all(text.as_bytes())
        .map_err(|e| CliError(format!("cannot write to stdout: {e}")))?;
    let disarmed = log.as_ref().is_none_or(|l| l.disarmed_s.is_some());
    match (td, o.stopped) {
        (_, Some(reason)) => Err(CliError(reason)),
        (Some(_), None) if o.retakeoff_s.is_some() => Err(CliError::new(
            "the vehicle took off again after its touchdown",
        )),
        (Some(_), None) if !disarmed => Err(CliError(format!(
            "the autopilot did not disarm within --max-time {:.0} s of the landing command",
            args.max_time
        ))),
        (Some(_), None) => Ok(super::Outcome::Success),
        (None, None) => Err(CliError(format!(
            "no touchdown within --max-time {:.0} s{}",
            args.max_time,
            if rehearsal.is_some() {
                " of the landing command"
            } else {
                ""
            }
        ))),
    }
}

/// The board's parameters for a GPS-denied rehearsal (`flag` names it in errors): the user's
/// `params` as given, then TD_VPE_EN 1 (the VISION_POSITION_ESTIMATE it navigates on) and
/// TD_PAD_YAW (the frame held to the rehearsal pad, whose top edge faces north) where the user
/// set neither; an error when TD_VPE_EN, as set, sends no position.
fn gps_denied_board_params(
    mut params: Vec<(String, f32)>,
    flag: &str,
) -> Result<Vec<(String, f32)>, CliError> {
    let unset = |params: &[(String, f32)], param: &str| {
        params
            .iter()
            .all(|(name, _)| !name.eq_ignore_ascii_case(param))
    };
    if unset(&params, "TD_VPE_EN") {
        params.push(("TD_VPE_EN".to_string(), 1.0));
    }
    if unset(&params, "TD_PAD_YAW") {
        params.push(("TD_PAD_YAW".to_string(), rehearsal_pad_bearing_deg()));
    }
    let vpe_en = vpe_enable(&params);
    if vpe_en & 1 == 0 {
        return Err(CliError(format!(
            "{flag}: TD_VPE_EN = {vpe_en} sends no VISION_POSITION_ESTIMATE (bit 0)"
        )));
    }
    Ok(params)
}

/// TD_VPE_EN as `params` leave it (the last value given wins, as the board applies them; 0
/// when not given, the board's default).
fn vpe_enable(params: &[(String, f32)]) -> i32 {
    params
        .iter()
        .rev()
        .find(|(name, _)| name.eq_ignore_ascii_case("TD_VPE_EN"))
        .map_or(0, |(_, v)| *v as i32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use touchdown_core::companion::mavlink::dialects::common::SIM_STATE_DATA;

    #[test]
    fn a_gps_denied_rehearsal_fills_in_what_the_user_left_out_and_keeps_what_they_set() {
        let owned = |list: &[(&str, f32)]| -> Vec<(String, f32)> {
            list.iter().map(|(n, v)| (n.to_string(), *v)).collect()
        };
        // Nothing given: the position, held to the rehearsal pad's bearing.
        assert_eq!(
            gps_denied_board_params(Vec::new(), "--no-gps").unwrap(),
            owned(&[("TD_VPE_EN", 1.0), ("TD_PAD_YAW", 0.0)])
        );
        // The user's values, in any case, stay as given and first.
        let given = owned(&[
            ("td_vpe_en", 3.0),
            ("TD_PAD_YAW", -1.0),
            ("TD_CAM_ROLL", 1.2),
        ]);
        assert_eq!(
            gps_denied_board_params(given.clone(), "--no-gps").unwrap(),
            given
        );
        // A TD_VPE_EN without the position: refused, naming the flag.
        let e =
            gps_denied_board_params(owned(&[("TD_VPE_EN", 2.0)]), "--gps-loss-height").unwrap_err();
        assert_eq!(
            e.0,
            "--gps-loss-height: TD_VPE_EN = 2 sends no VISION_POSITION_ESTIMATE (bit 0)"
        );
    }

    #[test]
    fn sim_state_reads_the_integer_position_and_the_float_one_in_either_unit() {
        let pad = [-35.363_261_0, 149.165_230_0, 584.0];
        let base = SIM_STATE_DATA {
            q1: 1.0,
            alt: 594.0,
            ..SIM_STATE_DATA::DEFAULT
        };
        // 1e-5 degrees of latitude north of the pad: 1.113 m.
        let with_ints = SIM_STATE_DATA {
            lat_int: -353_632_510,
            lon_int: 1_491_652_300,
            lat: -353_632_510_i32 as f32,
            lon: 1_491_652_300_i32 as f32,
            ..base
        };
        let s = ground_truth(&MavMessage::SIM_STATE(with_ints.clone())).expect("truth");
        let state = in_pad_frame(&s, &pad);
        assert!((state.position.y - 1.113).abs() < 0.01, "{state:?}");
        assert!(state.position.x.abs() < 0.01, "{state:?}");
        assert!((state.position.z - 10.0).abs() < 1e-6, "{state:?}");
        // Without the integers: the float in 1e-7 degrees (ArduPilot) or in degrees.
        for (lat, lon) in [
            (-353_632_510_i32 as f32, 1_491_652_300_i32 as f32),
            (-35.363_25_f32, 149.165_23_f32),
        ] {
            let s = ground_truth(&MavMessage::SIM_STATE(SIM_STATE_DATA {
                lat,
                lon,
                ..base.clone()
            }))
            .expect("truth");
            let state = in_pad_frame(&s, &pad);
            // A float's rounding at these magnitudes: tens of centimetres.
            assert!((state.position.y - 1.113).abs() < 1.0, "{state:?}");
        }
        // No attitude: not a sample.
        let none = SIM_STATE_DATA {
            q1: 0.0,
            ..with_ints
        };
        assert_eq!(ground_truth(&MavMessage::SIM_STATE(none)), None);
    }

    #[test]
    fn the_truth_is_turned_into_the_pad_frame_east_north_up() {
        let pad = [47.0, 8.0, 400.0];
        let east_of_pad = GeoSample {
            lat_deg: 47.0,
            lon_deg: 8.0 + (2.0 / (EARTH_RADIUS_M * 47f64.to_radians().cos())).to_degrees(),
            alt_m: 405.0,
            body_to_ned: UnitQuaternion::identity(),
        };
        let state = in_pad_frame(&east_of_pad, &pad);
        assert!(
            (state.position - Vector3::new(2.0, 0.0, 5.0)).norm() < 1e-6,
            "{state:?}"
        );
    }
}
