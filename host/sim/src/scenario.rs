//! The named scenarios: what is flown, over which pad, in which light, seen by which camera.
//!
//! | name | pad | what |
//! |---|---|---|
//! | `paper` | paper-single (1.0 m aruco_6x6_250) | the paper's set points: hover at Z = 5, 10, 15, 20, 25 m and on to 30, 40, 50 m; X and Y = 1.2 ... 6 m at 15 m |
//! | `margin` | paper-single on a white margin of two cells | the paper's Z hovers, 5 to 50 m |
//! | `lateral` | paper-single | fast 4 m dashes at 12 m (tilting up to ~30 degrees, motion blur) |
//! | `descent` | nested | 1 m/s down from 20 m to 1 m while drifting 0.5 m/s onto the pad |
//! | `landing` | nested | approach and landing from 40 m to 0.3 m |
//! | `hover` | nested | the set-up guide's mount-calibration hover: 3 m over the pad, holding still, 20 s |
//! | `sun` | nested | hover at 20 ... 1 m in strong sun; the sensor's own auto-exposure meters the grass and the pad clips; a replay closes the board's loop instead (it meters the decoded markers) |
//! | `shadow` | nested | hover at 20 ... 1 m with a hard shadow edge across the pad on concrete; the sensor's own auto-exposure on the frame's mean, a replay the board's loop |
//! | `occlusion` | nested | hover at 20 ... 1 m with a dark object lying across part of the pad |
//!
//! The camera is the one of the paper's experiments: 640x480 with a 60
//! degree horizontal field of view (f = 554.3 px), looking straight down, image top toward
//! the nose. `paper` keeps it ideal (the paper used Gazebo's distortion-free camera); the
//! others add a mild barrel distortion, defocus and vignetting of a board camera.
//!
//! `paper` flies the set points of the paper's Tables 2-4 ([`TABLE_ALTITUDES_M`],
//! [`TABLE_OFFSETS_M`] at [`OFFSET_ROWS_ALTITUDE_M`], and [`EXTRA_ALTITUDES_M`] above them),
//! Z rows first, then X, then Y, all at heading 0. These tables are the one definition of
//! where the paper's experiment hovers: the evaluation's in-memory paper geometry
//! (`touchdown_eval::paper_geometry`) hovers at the same points.
//!
//! Every named scenario is rendered without the flight effects of [`crate::effects`] (a
//! global shutter on a rigid, aligned mount), so tests built on them keep their meaning;
//! [`Scenario::apply_effects`] adds the rolling shutter, vibration and mount misalignment.
//!
//! Exposure: `sun` and `shadow` are rendered with the simulated sensor's own auto-exposure
//! (the frame's mean to a target, as a sensor's AEC does); the others with a fixed exposure.
//! `touchdown replay` closes the board's auto-exposure loop around `sun` and `shadow` instead
//! ([`Scenario::board_exposure`]): each frame then gets the exposure time and gain the
//! board chose, and its motion blur lasts that exposure time
//! ([`crate::Simulator::render_exposed`]); `--exposure` picks either for any scenario.
//!
//! Frames carry set-point labels where the scenario has set points (`z=5`, `x=1.2`,
//! `hover=3`); the paper's tables group frames by them.

use crate::camera::{CameraMount, SimCamera};
use crate::effects::{FlightEffects, Vibration};
use crate::math::Vec3;
use crate::pad::PrintedPad;
use crate::pad_motion::PadMotion;
use crate::sensor::{Exposure, Optics, Sensor};
use crate::texture::GroundKind;
use crate::trajectory::{Profile, Segment, Trajectory, Wobble};
use crate::world::{Lighting, Occluder, ShadowEdge};

/// Altitude of the paper's X and Y rows (Tables 3 and 4), metres.
pub const OFFSET_ROWS_ALTITUDE_M: f64 = 15.0;
/// The altitudes of the paper's Table 2 (the Z rows), metres.
pub const TABLE_ALTITUDES_M: [f64; 5] = [5.0, 10.0, 15.0, 20.0, 25.0];
/// The horizontal offsets of the paper's Tables 3 and 4 (the X and Y rows, at
/// [`OFFSET_ROWS_ALTITUDE_M`]), metres.
pub const TABLE_OFFSETS_M: [f64; 5] = [1.2, 2.4, 3.6, 4.8, 6.0];
/// The altitudes beyond Table 2 flown by default (Z rows without a published value), metres.
pub const EXTRA_ALTITUDES_M: [f64; 3] = [30.0, 40.0, 50.0];

/// Mild barrel distortion of a small M12 board lens at 60 degrees.
pub const BOARD_LENS_DISTORTION: [f32; 5] = [-0.12, 0.03, 0.0005, -0.0003, 0.0];

/// One frame to render.
#[derive(Debug, Clone, PartialEq)]
pub struct FramePlan {
    /// Middle of the exposure, microseconds from the start.
    pub t_us: u64,
    /// Set-point label, if the scenario has set points.
    pub label: Option<String>,
}

/// Everything needed to render a recording.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Name (`paper`, ...).
    pub name: String,
    /// One line about it.
    pub description: String,
    /// The seed everything random derives from.
    pub seed: u64,
    /// The camera.
    pub camera: SimCamera,
    /// How it is mounted: the true mount (misaligned by [`Scenario::apply_effects`]).
    pub mount: CameraMount,
    /// How the camera vibrates on its mount (none unless [`Scenario::apply_effects`]).
    pub vibration: Vibration,
    /// The pad.
    pub pad: PrintedPad,
    /// The ground around the pad.
    pub ground: GroundKind,
    /// Sun, sky, shadow.
    pub lighting: Lighting,
    /// Something lying on the pad.
    pub occluder: Option<Occluder>,
    /// The lens.
    pub optics: Optics,
    /// The sensor.
    pub sensor: Sensor,
    /// Exposure time, seconds (what motion blurs over).
    pub exposure_time_s: f64,
    /// Sub-samples per pixel side (without motion blur).
    pub supersampling: usize,
    /// The flight: the vehicle in the world (the pad frame as the pad lay when it started to
    /// move, if it moves).
    pub trajectory: Trajectory,
    /// How the pad moves (at rest unless a scenario or `--pad-velocity` and its kin say).
    pub pad_motion: PadMotion,
    /// Whether `trajectory` is flown against the pad and carried along its drive (a scenario
    /// flown over a moving pad), rather than the vehicle's own path in the world (a closed
    /// loop's, a SITL's).
    pub flight_follows_pad: bool,
    /// The frames.
    pub frames: Vec<FramePlan>,
    /// Whether a replay closes the board's auto-exposure loop around this scenario by default
    /// (`touchdown replay --exposure`): the scenarios about light, whose sensor's own AEC
    /// ([`Exposure::Auto`]) is what the board's loop replaces. The rendering alone
    /// (`touchdown simulate`, [`crate::Simulator::render`]) always uses the scenario's own.
    pub board_exposure: bool,
}

/// The scenario names and what they are, for `--help`.
pub const SCENARIOS: &[(&str, &str)] = &[
    (
        "paper",
        "the paper's set points over a 1.0 m aruco_6x6_250: Z = 5..50 m, X and Y = 1.2..6 m at 15 m (288 frames)",
    ),
    (
        "margin",
        "the paper's Z = 5..50 m hovers over its marker printed on a white margin of two cells, the ground beyond (128 frames)",
    ),
    (
        "lateral",
        "fast 4 m dashes at 12 m over the paper's marker, tilting ~30 deg, motion blur (330 frames)",
    ),
    (
        "descent",
        "1 m/s descent from 20 m to 1 m drifting 0.5 m/s onto the nested pad, 30 Hz (570 frames)",
    ),
    (
        "landing",
        "approach and landing from 40 m to 0.3 m over the nested pad, 15 Hz (630 frames)",
    ),
    (
        "hover",
        "the set-up guide's mount-calibration hover: 3 m over the nested pad, holding still, 20 s at 15 Hz (300 frames)",
    ),
    (
        "rest",
        "the vehicle resting on the recommended (nested-field) pad before take-off: the camera 0.1 m up, 2 cm from the landing point, still, 20 s at 15 Hz (300 frames)",
    ),
    (
        "sun",
        "hover at 20..1 m in strong sun with auto-exposure on grass: the white pad clips (60 frames)",
    ),
    (
        "shadow",
        "hover at 20..1 m with a hard shadow edge across the nested pad on concrete (60 frames)",
    ),
    (
        "occlusion",
        "hover at 20..1 m with a dark object lying across part of the nested pad (60 frames)",
    ),
];

/// Microseconds of a frame period at `rate_hz`.
fn period_us(rate_hz: f64) -> u64 {
    (1e6 / rate_hz).round() as u64
}

/// Hover set points: `frames_per_point` frames at `rate_hz` at each, `gap_s` between them.
/// Only the hovers are recorded: the vehicle jumps to the next set point in the middle of the
/// gap (a [`Profile::Jump`]), so every frame is exposed at its own set point alone.
fn set_points(
    points: &[(String, Vec3)],
    frames_per_point: usize,
    rate_hz: f64,
    gap_s: f64,
) -> (Vec<Segment>, Vec<FramePlan>) {
    let period = period_us(rate_hz);
    let mut segments = Vec::new();
    let mut frames = Vec::new();
    let mut t_us = 0u64;
    let gap_us = (gap_s * 1e6).round() as u64;
    for (label, position) in points {
        let t0 = t_us as f64 * 1e-6;
        if let Some(previous) = segments.last().map(|s: &Segment| s.to) {
            let jump = t0 - 0.5 * gap_us as f64 * 1e-6;
            segments.push(Segment {
                t0: jump,
                t1: jump,
                from: previous,
                to: *position,
                profile: Profile::Jump,
            });
        }
        for _ in 0..frames_per_point {
            frames.push(FramePlan {
                t_us,
                label: Some(label.clone()),
            });
            t_us += period;
        }
        let t1 = t_us as f64 * 1e-6;
        segments.push(Segment {
            t0,
            t1,
            from: *position,
            to: *position,
            profile: Profile::Hold,
        });
        t_us += gap_us;
    }
    (segments, frames)
}

/// Evenly spaced frames over `[0, duration_s]`.
fn uniform_frames(duration_s: f64, rate_hz: f64) -> Vec<FramePlan> {
    let period = period_us(rate_hz);
    let count = (duration_s * 1e6 / period as f64).floor() as u64 + 1;
    (0..count)
        .map(|k| FramePlan {
            t_us: k * period,
            label: None,
        })
        .collect()
}

fn label(axis: &str, value: f64) -> String {
    format!("{axis}={value}")
}

impl Scenario {
    /// The scenario called `name` with `seed`; `None` for an unknown name.
    pub fn named(name: &str, seed: u64) -> Option<Scenario> {
        let paper_pad = PrintedPad::design("paper-single")?;
        let nested = PrintedPad::design("nested")?;
        let ideal_camera = SimCamera::with_fov(640, 480, 60.0, [0.0; 5]);
        let board_camera = SimCamera::with_fov(640, 480, 60.0, BOARD_LENS_DISTORTION);
        let base = |name: &str, pad: PrintedPad, camera: SimCamera, trajectory, frames| Scenario {
            name: name.to_string(),
            description: SCENARIOS
                .iter()
                .find(|s| s.0 == name)
                .map_or(String::new(), |s| s.1.to_string()),
            seed,
            camera,
            mount: CameraMount::downward(),
            vibration: Vibration::none(),
            pad,
            ground: GroundKind::Grass,
            lighting: Lighting::daylight(),
            occluder: None,
            optics: Optics::board_camera(),
            sensor: Sensor::board_camera(),
            exposure_time_s: 0.004,
            supersampling: 4,
            trajectory,
            frames,
            board_exposure: false,
            pad_motion: PadMotion::at_rest(),
            flight_follows_pad: false,
        };
        let hover_wobble = Wobble::new(0.02, 0.5, 0.4, seed);
        let hover_set = |seed_salt: u64| {
            let points: Vec<(String, Vec3)> = [20.0, 10.0, 5.0, 3.0, 2.0, 1.0]
                .iter()
                .map(|&h| (label("hover", h), [0.0, 0.0, h]))
                .collect();
            let (segments, frames) = set_points(&points, 10, 30.0, 1.0);
            let trajectory = Trajectory {
                segments,
                yaw: 0.0,
                wobble: Wobble::new(0.01, 0.5, 0.4, seed ^ seed_salt),
                tilt_with_acceleration: false,
                trim: (0.0, 0.0),
            };
            (trajectory, frames)
        };
        // The paper's Z set points, 5 to 50 m over the pad's centre.
        let altitude_points = || -> Vec<(String, Vec3)> {
            TABLE_ALTITUDES_M
                .iter()
                .chain(&EXTRA_ALTITUDES_M)
                .map(|&z| (label("z", z), [0.0, 0.0, z]))
                .collect()
        };
        // The paper's set points flown as hovers of 16 frames at 30 Hz over `pad`, the lens
        // focused at infinity.
        let paper_hovers = |points: &[(String, Vec3)], pad: PrintedPad| {
            let (segments, frames) = set_points(points, 16, 30.0, 1.0);
            let trajectory = Trajectory {
                segments,
                yaw: 0.0,
                wobble: hover_wobble.clone(),
                tilt_with_acceleration: false,
                trim: (0.0, 0.0),
            };
            Scenario {
                optics: Optics {
                    focus_distance_m: f64::INFINITY,
                    ..Optics::board_camera()
                },
                ..base(name, pad, ideal_camera, trajectory, frames)
            }
        };
        let scenario = match name {
            "paper" => {
                let mut points = altitude_points();
                let h = OFFSET_ROWS_ALTITUDE_M;
                for x in TABLE_OFFSETS_M {
                    points.push((label("x", x), [x, 0.0, h]));
                }
                for y in TABLE_OFFSETS_M {
                    points.push((label("y", y), [0.0, y, h]));
                }
                paper_hovers(&points, paper_pad)
            }
            "margin" => {
                // The paper's altitude hovers over its marker printed on a white margin of
                // two cells, one more than the paper's: the ground's edge lies within a far
                // marker's blur, where the detector knows nothing of what is printed.
                paper_hovers(&altitude_points(), paper_pad.with_wider_margins(1.0).ok()?)
            }
            "lateral" => {
                let h = 12.0;
                let stops: [Vec3; 5] = [
                    [0.0, 0.0, h],
                    [4.0, 0.0, h],
                    [0.0, 0.0, h],
                    [0.0, 4.0, h],
                    [0.0, 0.0, h],
                ];
                let mut segments = vec![Segment {
                    t0: 0.0,
                    t1: 1.0,
                    from: stops[0],
                    to: stops[0],
                    profile: Profile::Hold,
                }];
                let mut t = 1.0;
                for pair in stops.windows(2) {
                    segments.push(Segment {
                        t0: t,
                        t1: t + 2.0,
                        from: pair[0],
                        to: pair[1],
                        profile: Profile::MinimumJerk,
                    });
                    segments.push(Segment {
                        t0: t + 2.0,
                        t1: t + 2.5,
                        from: pair[1],
                        to: pair[1],
                        profile: Profile::Hold,
                    });
                    t += 2.5;
                }
                let frames = uniform_frames(t - 1.0 / 30.0, 30.0);
                let trajectory = Trajectory {
                    segments,
                    yaw: 0.0,
                    wobble: Wobble::new(0.02, 0.7, 0.5, seed),
                    tilt_with_acceleration: true,
                    trim: (0.0, 0.0),
                };
                Scenario {
                    exposure_time_s: 0.008,
                    ..base(name, paper_pad, board_camera, trajectory, frames)
                }
            }
            "descent" => {
                let (top, bottom, speed, drift) = (20.0, 1.0, 1.0, 0.5);
                let duration = (top - bottom) / speed;
                // Drifting toward the pad from the south-west: over it at the bottom.
                let offset = drift * duration;
                let direction = 225f64.to_radians();
                let start = [offset * direction.cos(), offset * direction.sin(), top];
                let segments = vec![Segment {
                    t0: 0.0,
                    t1: duration,
                    from: start,
                    to: [0.0, 0.0, bottom],
                    profile: Profile::Linear,
                }];
                let frames = uniform_frames(duration - 1.0 / 30.0, 30.0);
                let trajectory = Trajectory {
                    segments,
                    yaw: 0.0,
                    wobble: Wobble::new(0.03, 2.0, 0.3, seed),
                    tilt_with_acceleration: true,
                    trim: (0.0, 0.0),
                };
                base(name, nested, board_camera, trajectory, frames)
            }
            "landing" => {
                let segments = vec![
                    Segment {
                        t0: 0.0,
                        t1: 20.0,
                        from: [-10.0, -6.0, 40.0],
                        to: [0.0, 0.0, 15.0],
                        profile: Profile::MinimumJerk,
                    },
                    Segment {
                        t0: 20.0,
                        t1: 32.0,
                        from: [0.0, 0.0, 15.0],
                        to: [0.0, 0.0, 3.0],
                        profile: Profile::Linear,
                    },
                    Segment {
                        t0: 32.0,
                        t1: 41.0,
                        from: [0.0, 0.0, 3.0],
                        to: [0.0, 0.0, 0.3],
                        profile: Profile::Linear,
                    },
                    Segment {
                        t0: 41.0,
                        t1: 42.0,
                        from: [0.0, 0.0, 0.3],
                        to: [0.0, 0.0, 0.3],
                        profile: Profile::Hold,
                    },
                ];
                let frames = uniform_frames(42.0, 15.0);
                let trajectory = Trajectory {
                    segments,
                    yaw: 0.0,
                    wobble: Wobble::new(0.015, 1.0, 0.3, seed),
                    tilt_with_acceleration: true,
                    trim: (0.0, 0.0),
                };
                base(name, nested, board_camera, trajectory, frames)
            }
            "hover" => {
                // What docs/setup-ardupilot.md asks of a user calibrating the mount: hover at
                // 2-5 m over the pad, holding still, for at least 20 s. A hovering multicopter
                // still sways: the landing's wobble, at the landing's frame rate.
                let h = 3.0;
                let duration = 20.0;
                let segments = vec![Segment {
                    t0: 0.0,
                    t1: duration,
                    from: [0.0, 0.0, h],
                    to: [0.0, 0.0, h],
                    profile: Profile::Hold,
                }];
                let trajectory = Trajectory {
                    segments,
                    yaw: 0.0,
                    wobble: Wobble::new(0.015, 1.0, 0.3, seed),
                    tilt_with_acceleration: true,
                    trim: (0.0, 0.0),
                };
                let frames = uniform_frames(duration - 0.5 / 15.0, 15.0);
                base(name, nested, board_camera, trajectory, frames)
            }
            "rest" => {
                // On the ground: the camera at a multicopter's gear height over the rest
                // field, a little off the landing point, the vehicle still (no sway).
                let at = [0.02, -0.01, 0.1];
                let duration = 20.0;
                let segments = vec![Segment {
                    t0: 0.0,
                    t1: duration,
                    from: at,
                    to: at,
                    profile: Profile::Hold,
                }];
                let trajectory = Trajectory {
                    segments,
                    yaw: 0.0,
                    wobble: Wobble::new(0.0, 1.0, 0.0, seed),
                    tilt_with_acceleration: false,
                    trim: (0.0, 0.0),
                };
                let frames = uniform_frames(duration - 0.5 / 15.0, 15.0);
                let rest_pad =
                    PrintedPad::from_layout(touchdown_core::pad::designs::RECOMMENDED).ok()?;
                base(name, rest_pad, board_camera, trajectory, frames)
            }
            "sun" => {
                let (trajectory, frames) = hover_set(1);
                Scenario {
                    lighting: Lighting {
                        direct: 2.8,
                        sky: 0.4,
                        shadow: None,
                    },
                    sensor: Sensor {
                        bloom: 0.8,
                        bloom_sigma_px: 2.0,
                        flare: 0.05,
                        exposure: Exposure::Auto {
                            target_mean: 140.0,
                            limits: (50.0, 1e6),
                        },
                        ..Sensor::board_camera()
                    },
                    exposure_time_s: 0.001,
                    board_exposure: true,
                    pad_motion: PadMotion::at_rest(),
                    flight_follows_pad: false,
                    ..base(name, nested, board_camera, trajectory, frames)
                }
            }
            "shadow" => {
                let (trajectory, frames) = hover_set(2);
                Scenario {
                    ground: GroundKind::Concrete,
                    lighting: Lighting {
                        shadow: Some(ShadowEdge::new([0.1, 0.3], 30.0, 0.02)),
                        ..Lighting::daylight()
                    },
                    sensor: Sensor {
                        exposure: Exposure::Auto {
                            target_mean: 110.0,
                            limits: (50.0, 1e6),
                        },
                        ..Sensor::board_camera()
                    },
                    board_exposure: true,
                    pad_motion: PadMotion::at_rest(),
                    flight_follows_pad: false,
                    ..base(name, nested, board_camera, trajectory, frames)
                }
            }
            "occlusion" => {
                let (trajectory, frames) = hover_set(3);
                Scenario {
                    ground: GroundKind::Asphalt,
                    occluder: Some(Occluder {
                        center: [0.3, 0.85],
                        radii: [0.35, 0.14],
                        angle_deg: 25.0,
                        albedo: 0.06,
                    }),
                    ..base(name, nested, board_camera, trajectory, frames)
                }
            }
            _ => return None,
        };
        Some(scenario)
    }

    /// Keeps only the first `count` frames.
    pub fn truncate(&mut self, count: usize) {
        self.frames.truncate(count);
    }
}

impl Scenario {
    /// Renders this scenario with `effects`: the camera's `line_time_us` is the readout over
    /// its rows (`readout_ms * 1000 / height`), the vibration is seeded from the scenario's
    /// seed, and the mount is the nominal downward one misaligned by the effects' angles.
    /// Applying [`FlightEffects::none`] leaves a scenario of [`Scenario::named`] unchanged.
    pub fn apply_effects(&mut self, effects: &FlightEffects) {
        let height = self.camera.height().max(1) as f64;
        let readout_us = effects.readout_ms.max(0.0) * 1000.0;
        self.camera.model.line_time_us = (readout_us / height) as f32;
        self.vibration = Vibration::new(
            effects.vibration_deg,
            self.seed ^ 0x7669_6272_6174_696f, // "vibratio"
        );
        self.mount = CameraMount::misaligned(effects.mount_roll_deg, effects.mount_pitch_deg);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{from_euler, max_difference, mul};

    #[test]
    fn none_changes_nothing() {
        let mut scenario = Scenario::named("landing", 3).expect("landing");
        let before = (scenario.camera, scenario.mount, scenario.vibration.clone());
        scenario.apply_effects(&FlightEffects::none());
        assert_eq!(
            before,
            (scenario.camera, scenario.mount, scenario.vibration.clone())
        );
    }

    #[test]
    fn typical_sets_the_readout_and_the_mount() {
        let mut scenario = Scenario::named("landing", 3).expect("landing");
        scenario.apply_effects(&FlightEffects::typical());
        let readout = scenario.camera.model.line_time_us as f64 * 480.0;
        assert!((readout - 30_500.0).abs() < 0.1, "{readout} us");
        assert!(scenario.camera.model.validate().is_ok());
        assert!(!scenario.vibration.is_none());
        // R_y(pitch) R_x(roll) nominal.
        let expected = mul(
            &from_euler(0.0, (-1.6f64).to_radians(), 0.0),
            &mul(
                &from_euler(1.2f64.to_radians(), 0.0, 0.0),
                &CameraMount::downward().rotation,
            ),
        );
        assert!(max_difference(&scenario.mount.rotation, &expected) < 1e-15);
    }

    #[test]
    fn every_scenario_exists_with_the_frame_count_its_help_gives() {
        for (name, help) in SCENARIOS {
            let scenario = Scenario::named(name, 1).unwrap();
            let count = help
                .rsplit('(')
                .next()
                .and_then(|s| s.split(' ').next())
                .and_then(|n| n.parse::<usize>().ok())
                .unwrap();
            assert_eq!(scenario.frames.len(), count, "{name}");
            assert!(scenario.frames.windows(2).all(|w| w[0].t_us < w[1].t_us));
        }
        assert!(Scenario::named("moon", 1).is_none());
    }
}
