//! The rolling-shutter correction end to end: rendered frames of a fast roll with a 30 ms
//! readout, run through the board's per-frame path (`FramePipeline`) fed the true attitude
//! at 50 Hz (as ATTITUDE_QUATERNION arrives) and the true velocity, with and without the
//! correction, against the same flight through a global shutter.
//!
//! The simulator renders each row at its own time (`touchdown_sim`'s rolling shutter), so
//! nothing here is built from the correction's own model: the frames are what a moving
//! OV7725 would see, the errors are against the simulator's truth at the frame's time.
//!
//! Print the figures with `cargo test -p touchdown-host-tests --test rolling_shutter --
//! --nocapture`.

use nalgebra::Vector3;
use touchdown_core::family::{tables, Family};
use touchdown_core::filter::{Attitude, PositionSample, VehicleState};
use touchdown_core::params::PipelineSettings;
use touchdown_core::pipeline::{FramePipeline, PipelineConfig};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_sim::effects::FlightEffects;
use touchdown_sim::scenario::{FramePlan, Scenario};
use touchdown_sim::sensor::{Optics, Sensor};
use touchdown_sim::texture::GroundKind;
use touchdown_sim::trajectory::{Profile, Segment, Trajectory, Wobble};
use touchdown_sim::Simulator;

/// Frames rendered: 0.6 s at 30 Hz.
const FRAMES: u64 = 18;
/// Frame interval, µs.
const FRAME_US: u64 = 33_333;
/// The first frame's time, µs: the attitude history starts at 0.
const FIRST_FRAME_US: u64 = 200_000;
/// Attitude (and position) samples every 20 ms: ATTITUDE_QUATERNION at 50 Hz.
const SAMPLE_US: u64 = 20_000;
/// Readout of the rolling-shutter frames, ms (the OV7725 at 30 fps: about 30 ms).
const READOUT_MS: f64 = 30.0;
/// Roll wobble: 10° at 0.8 Hz, so the vehicle rolls at up to 50 °/s (at t = 0, 0.625 s).
const ROLL_AMPLITUDE_DEG: f64 = 10.0;
const ROLL_HZ: f64 = 0.8;

/// 6 m up and 1.8 m south of the paper's 1 m marker (so it is seen in the upper rows, 11 ms
/// before the middle row), flying east at 3 m/s and rolling fast, on flat ground with ideal
/// optics and sensor and no exposure time (no motion blur: the skew alone).
fn scenario(readout_ms: f64) -> Scenario {
    let mut s = Scenario::named("paper", 1).expect("paper scenario");
    s.ground = GroundKind::Flat(0.3);
    s.optics = Optics::ideal();
    s.sensor = Sensor::ideal();
    s.exposure_time_s = 0.0;
    s.supersampling = 4;
    let mut terms = [[(0.0, 0.0, 0.0); 3]; 6];
    // A sine: the roll rate is largest where the roll is 0 (t = 0 and 0.625 s).
    terms[3][0] = (ROLL_AMPLITUDE_DEG.to_radians(), ROLL_HZ, 0.0);
    s.trajectory = Trajectory {
        segments: vec![Segment {
            t0: 0.0,
            t1: 1.0,
            from: [-1.5, -1.8, 6.0],
            to: [1.5, -1.8, 6.0],
            profile: Profile::Linear,
        }],
        yaw: 0.0,
        wobble: Wobble::from_terms(terms),
        tilt_with_acceleration: false,
        trim: (0.0, 0.0),
    };
    s.frames = (0..FRAMES)
        .map(|k| FramePlan {
            t_us: FIRST_FRAME_US + k * FRAME_US,
            label: None,
        })
        .collect();
    s.apply_effects(&FlightEffects {
        readout_ms,
        ..FlightEffects::none()
    });
    s
}

/// What the autopilot streams, from the simulator's truth: the body attitude and the NED
/// position and velocity every [`SAMPLE_US`], from `from_us` (exclusive) to `until_us`.
fn stream_vehicle(simulator: &Simulator, vehicle: &mut VehicleState, from_us: u64, until_us: u64) {
    // The simulator's NED: north = pad +y, east = pad +x, down = pad -z.
    let ned = |p: [f64; 3]| Vector3::new(p[1] as f32, p[0] as f32, -p[2] as f32);
    let position = |t: f64| ned(simulator.scenario.trajectory.state(t).position);
    for k in (from_us / SAMPLE_US + 1)..=until_us / SAMPLE_US {
        let t_us = k * SAMPLE_US;
        let t = t_us as f64 * 1e-6;
        let q = simulator.vehicle_attitude(t).map(|c| c as f32);
        let attitude = Attitude::from_quaternion_wxyz(q).expect("a unit quaternion");
        vehicle.push_attitude(t_us, &attitude, t_us);
        let h = 1e-3;
        let velocity = (position(t + h) - position(t - h)) / (2.0 * h) as f32;
        let sample = PositionSample {
            position: position(t),
            velocity,
        };
        vehicle.push_position(t_us, sample, t_us);
    }
}

/// Per frame, the error of the pad fix's camera position against the truth, metres (`None`
/// without a fix), with the correction on or off.
fn position_errors(simulator: &Simulator, correct: bool) -> Vec<Option<f64>> {
    let family = tables::by_name("aruco_6x6_250").expect("a shipped family");
    let families: [&Family<'_>; 1] = [family];
    let layout = simulator
        .scenario
        .pad
        .config
        .layout()
        .expect("the paper pad");
    let config = PipelineConfig {
        correct_rolling_shutter: correct,
        ..PipelineConfig::default()
    };
    let camera = simulator.scenario.camera.model;
    let mut pipeline = FramePipeline::new(
        &families,
        &layout,
        camera,
        config,
        PipelineSettings::default(),
    )
    .expect("the default trackers");
    let mut workspace = HostWorkspace::new();
    let (w, h) = (camera.width as usize, camera.height as usize);
    // The samples arrive as the flight goes: each frame is processed with those up to two
    // samples past its exposure (its processing delay), as the board would.
    let mut vehicle = VehicleState::new();
    let mut streamed_us = 0;
    stream_vehicle(simulator, &mut vehicle, 0, FIRST_FRAME_US);
    (0..FRAMES as usize)
        .map(|index| {
            let frame = simulator.render(index).expect("a planned frame");
            let until_us = frame.t_us + 2 * SAMPLE_US;
            stream_vehicle(simulator, &mut vehicle, streamed_us, until_us);
            streamed_us = until_us;
            let report = pipeline.process(
                &frame.image.view(),
                frame.t_us,
                &vehicle,
                &mut workspace.buffers(w, h),
            );
            report.fix.map(|fix| {
                let p = fix.camera_position().cast::<f64>();
                let t = frame.truth.position;
                (p - Vector3::new(t[0], t[1], t[2])).norm()
            })
        })
        .collect()
}

fn rms(errors: &[Option<f64>]) -> f64 {
    let found: Vec<f64> = errors.iter().flatten().copied().collect();
    assert_eq!(
        found.len(),
        errors.len(),
        "every frame has a fix: {errors:?}"
    );
    (found.iter().map(|e| e * e).sum::<f64>() / found.len() as f64).sqrt()
}

#[test]
fn the_correction_removes_the_skew_of_a_fast_roll() {
    let global = Simulator::new(scenario(0.0)).with_threads(2);
    let rolling = Simulator::new(scenario(READOUT_MS)).with_threads(2);
    assert_eq!(global.scenario.camera.model.line_time_us, 0.0);
    assert!(rolling.scenario.camera.model.line_time_us > 60.0);

    let cm = |errors: &[Option<f64>]| {
        let per_frame: Vec<String> = errors
            .iter()
            .map(|e| e.map_or("-".into(), |e| format!("{:.1}", e * 100.0)))
            .collect();
        per_frame.join(" ")
    };
    let (reference, without, with) = (
        position_errors(&global, true),
        position_errors(&rolling, false),
        position_errors(&rolling, true),
    );
    println!(
        "per frame, cm: global {}\nwithout {}\nwith {}",
        cm(&reference),
        cm(&without),
        cm(&with)
    );
    let (reference, without, with) = (rms(&reference), rms(&without), rms(&with));
    println!(
        "camera position RMS over {FRAMES} frames, 6 m, 3 m/s, roll up to {:.0} deg/s, \
         {READOUT_MS} ms readout: global shutter {:.1} cm; rolling shutter without the \
         correction {:.1} cm, with it {:.1} cm",
        ROLL_AMPLITUDE_DEG * std::f64::consts::TAU * ROLL_HZ,
        reference * 100.0,
        without * 100.0,
        with * 100.0
    );
    // The skew is a large error without the correction; with it, the error is within a
    // centimetre of the global shutter's.
    assert!(without > 4.0 * with, "without {without} m, with {with} m");
    assert!(
        with < reference + 0.01,
        "with {with} m, global {reference} m"
    );
}
