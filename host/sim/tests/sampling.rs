//! The renderer's adaptive sampling against the exhaustive one: a pixel whose footprint the
//! world calls uniform is shaded from one look-up, every other pixel from sub-samples
//! (`raster::Sampling`); sub-sampling every pixel must give the same frame. Frames of the
//! nested pad seen as `touchdown sitl` and the replay see it (board lens, the typical flight
//! effects: rolling shutter, vibration, a misaligned mount; motion blur over several
//! sub-frames) at several heights and tilts, and of the shadow and occlusion scenarios,
//! whose shadow edge and occluder are footprint tests of their own.
//!
//! A footprint taken for uniform while an edge crosses it gets a single albedo where the
//! exhaustive sampling mixes paper and ink: tens of grey levels. The test also checks that
//! one sample per pixel (an edge missed in every pixel it crosses) is caught by the same
//! bound, so the frames do hold edges where it matters.

use touchdown_sim::camera::RayMap;
use touchdown_sim::effects::FlightEffects;
use touchdown_sim::raster::{render_radiance_sampled, Sampling};
use touchdown_sim::scenario::Scenario;
use touchdown_sim::sensor;
use touchdown_sim::trajectory::{Profile, Segment, Trajectory, Wobble};
use touchdown_sim::Simulator;

/// Hovering over `[x, y, height]`, descending at 0.5 m/s, tilted by `roll_deg` and
/// `pitch_deg`, heading `yaw_deg`, and turning at 20 deg/s about every axis (motion blur).
fn flight(at: [f64; 3], roll_deg: f64, pitch_deg: f64, yaw_deg: f64) -> Trajectory {
    let f = 0.05;
    let rate = 20f64.to_radians();
    let mut terms = [[(0.0, 0.0, 0.0); 3]; 6];
    for term in terms.iter_mut().skip(3) {
        term[0] = (rate / (std::f64::consts::TAU * f), f, 0.0);
    }
    Trajectory {
        segments: vec![Segment {
            t0: -1.0,
            t1: 1.0,
            from: [at[0], at[1], at[2] + 0.5],
            to: [at[0], at[1], at[2] - 0.5],
            profile: Profile::Linear,
        }],
        yaw: yaw_deg.to_radians(),
        wobble: Wobble::from_terms(terms),
        tilt_with_acceleration: false,
        trim: (roll_deg.to_radians(), pitch_deg.to_radians()),
    }
}

/// The grey levels of the frame at t = 0 with `sampling` and `supersampling` sub-samples per
/// pixel side, and its sub-frame count. The sensor's noise is drawn from the same seed
/// whatever the sampling, so only the radiance differs.
fn frame(simulator: &Simulator, sampling: Sampling, supersampling: usize) -> (Vec<u8>, usize) {
    let s = &simulator.scenario;
    let (w, h) = (s.camera.width(), s.camera.height());
    let rays = RayMap::new(&s.camera);
    let poses = simulator.row_poses(0.0, s.exposure_time_s);
    let radiance = render_radiance_sampled(
        &simulator.world,
        &rays,
        w,
        h,
        &poses,
        supersampling,
        2,
        sampling,
    );
    let blur = s.optics.blur_sigma(
        s.camera.fx(),
        simulator.camera_pose(0.0).axis_distance_to_ground(),
    );
    let pixels = sensor::expose(
        radiance,
        w,
        h,
        &rays.cos_off_axis,
        &s.optics,
        &s.sensor,
        blur,
        &[],
        7,
    );
    (pixels, poses.subframes())
}

/// Largest and mean absolute difference, grey levels.
fn difference(a: &[u8], b: &[u8]) -> (u8, f64) {
    let max = a
        .iter()
        .zip(b)
        .map(|(p, q)| p.abs_diff(*q))
        .max()
        .unwrap_or(0);
    let mean = a
        .iter()
        .zip(b)
        .map(|(p, q)| f64::from(p.abs_diff(*q)))
        .sum::<f64>()
        / a.len().max(1) as f64;
    (max, mean)
}

#[test]
#[ignore = "long: in the long suite, `cargo test -- --ignored` (CI runs it)"]
fn adaptive_sampling_is_the_exhaustive_one() {
    // (scenario, where, roll, pitch, yaw): heights of the landing from the pad small in the
    // image to the pad filling it, level and tilted.
    let cases: [(&str, [f64; 3], f64, f64, f64); 7] = [
        ("landing", [0.3, 0.2, 20.0], 0.0, 0.0, 0.0),
        ("landing", [1.5, -1.0, 20.0], 15.0, -10.0, 30.0),
        ("landing", [0.1, 0.5, 5.0], 0.0, 0.0, 10.0),
        ("landing", [0.4, 0.3, 5.0], -20.0, 12.0, 45.0),
        ("landing", [0.05, 0.02, 1.0], 8.0, 5.0, 20.0),
        ("shadow", [0.0, 0.3, 5.0], 5.0, -5.0, 0.0),
        ("occlusion", [0.2, 0.6, 3.0], 0.0, 6.0, -15.0),
    ];
    for (name, at, roll, pitch, yaw) in cases {
        let mut scenario = Scenario::named(name, 1).expect("scenario");
        scenario.apply_effects(&FlightEffects::typical());
        scenario.trajectory = flight(at, roll, pitch, yaw);
        let s = scenario.supersampling;
        let simulator = Simulator::new(scenario);
        let (adaptive, subframes) = frame(&simulator, Sampling::Adaptive, s);
        let (exhaustive, _) = frame(&simulator, Sampling::Exhaustive, s);
        let (max, mean) = difference(&adaptive, &exhaustive);
        println!(
            "{name} at {at:?} roll {roll} pitch {pitch} yaw {yaw}: {subframes} sub-frames, \
             adaptive - exhaustive max {max}, mean {mean:.5} grey levels"
        );
        assert!(
            subframes > 1,
            "{name} {at:?}: the frames are motion-blurred"
        );
        // Rounding: a radiance a few ulps apart can round to the next grey level.
        assert!(max <= 1, "{name} {at:?}: max |difference| {max}");
        assert!(mean < 0.001, "{name} {at:?}: mean |difference| {mean}");
        // One sample per pixel, as if every edge had been missed, is caught by the bound.
        let (point, _) = frame(&simulator, Sampling::Adaptive, 1);
        let (max, _) = difference(&point, &exhaustive);
        assert!(max > 10, "{name} {at:?}: no edge to miss ({max})");
    }
}
