//! The closed loop: a landing in which the vehicle flies on the targets touchdown sends.
//!
//! Per camera frame ([`fly`]): the simulator renders the camera's view of the pad from the
//! vehicle's *true* pose (with its flight effects: rolling shutter, vibration, mount
//! misalignment), the board's per-frame path ([`touchdown_core::pipeline::FramePipeline`])
//! and its [`touchdown_core::companion::Companion`] run on it against the simulated autopilot
//! of [`crate::flight`] over MAVLink bytes ([`crate::Experiment::in_flight`], the very path
//! `touchdown replay` flies), and what that autopilot reconstructs from the LANDING_TARGET it
//! received steers the vehicle: an ArduPilot-like precision LAND ([`land`]) commands a
//! multicopter point mass ([`vehicle`]) in wind and gusts ([`wind`], the same at every
//! height or thinned toward the ground as ArduPilot SITL's default profile). The vehicle's true
//! state history is the [`crate::flight::TruthTable`] the simulated autopilot streams its
//! (erroneous) attitude and position estimates from, so the loop is closed through the
//! autopilot's own estimates, the link and the board, never through the truth.
//!
//! Touchdown is the moment the true height of the vehicle's body origin (the camera) over
//! the pad reaches zero; its error is the true horizontal position then against the pad's
//! origin (the landing point the pad's `pad.toml` defines, the point LANDING_TARGET aims at).
//! A moving pad ([`LandingConfig::pad_motion`]: a boat's deck, a truck's roof) is where it is
//! at each time: the height is over its plane straight below the camera (the deck heaving and
//! rolling under it; also the height the autopilot's LAND descends on, a rangefinder's), and
//! the error is the camera's position in the pad's own frame at the touchdown's time.
//!
//! # Timing
//! The vehicle runs on a 2.5 ms step (ArduPilot's 400 Hz loop) and is simulated
//! [`LOOKAHEAD_S`] ahead of each frame before the frame is rendered and processed: the
//! rolling shutter's rows are exposed up to 15 ms after the frame's time, and the autopilot
//! and link run on to the frame's delivery plus [`crate::flight::SETTLE_US`]. So a target
//! steers the vehicle from the end of that window on: at most [`LOOKAHEAD_S`] after its
//! exposure, some 20 ms after its receipt (the autopilot's own PLND_LAG handling is in the
//! reconstruction, as in the replay). The frame is rendered with the vehicle's motion
//! linearised about the frame's time (its position, velocity, attitude and attitude rates
//! then): over the 35 ms of a readout the neglected terms are below a millimetre and a
//! hundredth of a degree at these accelerations.

pub mod land;
mod landing;
pub mod px4;
pub mod vehicle;
pub mod wind;

pub use landing::{
    fly, local_trajectory, scene, Autopilot, LandingConfig, LandingOutcome, Touchdown, LOOKAHEAD_S,
    STEP_S,
};
