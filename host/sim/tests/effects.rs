//! The flight effects in rendered frames: the rolling shutter's skew where the
//! rolling-shutter corner function says (found by the core's detector), the vibration's
//! wobble and blur, the misaligned mount, the vehicle attitude of a frame, and that without
//! effects nothing changed.

use touchdown_core::detect::{buffer_sizes, Buffers, Detection, Detector, DetectorConfig};
use touchdown_core::family::tables;
use touchdown_formats::image_io::GrayFrame;
use touchdown_sim::camera::{CameraMount, CameraPose};
use touchdown_sim::effects::{FlightEffects, Vibration};
use touchdown_sim::math::{from_euler, matrix_to_quat, mul, transpose, Mat3};
use touchdown_sim::scenario::{FramePlan, Scenario};
use touchdown_sim::sensor::{Optics, Sensor};
use touchdown_sim::texture::GroundKind;
use touchdown_sim::trajectory::{Profile, Segment, Trajectory, Wobble};
use touchdown_sim::Simulator;

/// 30 degrees per second, radians per second.
const RATE: f64 = 30.0 * std::f64::consts::PI / 180.0;
/// The rolling shutter's readout of the tests, seconds (the typical one).
const READOUT_S: f64 = 0.0305;

/// Hovering at `altitude` over the pad, turning at `rates` (roll, pitch, yaw rad/s) through
/// t = 0: a slow sine (0.05 Hz) through zero whose slope there is the rate.
fn turning(altitude: f64, rates: [f64; 3]) -> Trajectory {
    let f = 0.05;
    let mut terms = [[(0.0, 0.0, 0.0); 3]; 6];
    for (k, rate) in rates.iter().enumerate() {
        terms[3 + k][0] = (rate / (std::f64::consts::TAU * f), f, 0.0);
    }
    Trajectory {
        segments: vec![Segment {
            t0: -1.0,
            t1: 1.0,
            from: [0.0, 0.0, altitude],
            to: [0.0, 0.0, altitude],
            profile: Profile::Hold,
        }],
        yaw: 0.0,
        wobble: Wobble::from_terms(terms),
        tilt_with_acceleration: false,
        trim: (0.0, 0.0),
    }
}

/// The paper's marker and ideal camera, a flat ground, an ideal lens and sensor, no
/// exposure time (each row an instant), one frame at t = 0.
fn sharp(trajectory: Trajectory) -> Scenario {
    let mut s = Scenario::named("paper", 1).expect("paper scenario");
    s.ground = GroundKind::Flat(0.3);
    s.optics = Optics::ideal();
    s.sensor = Sensor::ideal();
    s.exposure_time_s = 0.0;
    s.trajectory = trajectory;
    s.frames = vec![FramePlan {
        t_us: 0,
        label: None,
    }];
    s
}

fn rolling_shutter_only() -> FlightEffects {
    FlightEffects {
        readout_ms: READOUT_S * 1e3,
        ..FlightEffects::none()
    }
}

fn detect(frame: &GrayFrame) -> Vec<Detection> {
    let sizes = buffer_sizes(frame.width, frame.height);
    let (mut bitmap, mut visited) = (
        vec![0u32; sizes.bitmap_words],
        vec![0u32; sizes.bitmap_words],
    );
    let mut tiles = vec![0u8; sizes.tile_bytes];
    let mut buffers = Buffers {
        bitmap: &mut bitmap,
        visited: &mut visited,
        tiles: &mut tiles,
    };
    let family = tables::by_name("aruco_6x6_250").expect("shipped family");
    let mut detector = Detector::new(DetectorConfig::default());
    detector
        .detect(&frame.view(), &[family], &mut buffers)
        .expect("the detector accepts the frame")
        .to_vec()
}

/// Largest distance between corresponding corners.
fn worst(a: &[[f64; 2]; 4], b: &[[f64; 2]; 4]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt())
        .fold(0.0, f64::max)
}

/// The rolling shutter at 30 deg/s: the detector finds the corners where
/// `marker_corners_rolling_shutter` puts them, pixels away from the global shutter's, and
/// the difference is the readout's skew.
#[test]
fn rolling_shutter_skews_the_marker_where_the_corner_function_says() {
    for (what, rates) in [
        ("roll", [RATE, 0.0, 0.0]),
        ("pitch", [0.0, RATE, 0.0]),
        ("yaw", [0.0, 0.0, RATE]),
    ] {
        let mut scenario = sharp(turning(2.5, rates));
        scenario.apply_effects(&rolling_shutter_only());
        let simulator = Simulator::new(scenario);
        let frame = simulator.render(0).expect("frame 0");
        let rolling = simulator.marker_corners_rolling_shutter(0.0)[0].expect("in view");
        let global = simulator.marker_corners(&simulator.camera_pose(0.0))[0].expect("in view");
        let found = detect(&frame.image);
        assert_eq!(found.len(), 1, "{what}: {found:?}");
        let detected = found[0].corners.map(|p| [f64::from(p.x), f64::from(p.y)]);
        let to_rolling = worst(&detected, &rolling);
        let to_global = worst(&detected, &global);
        let shift = worst(&rolling, &global);
        // The skew: how far the corners move relative to each other (the marker's shape
        // changing, not the whole marker moving).
        let moved =
            [0, 1, 2, 3].map(|k| [rolling[k][0] - global[k][0], rolling[k][1] - global[k][1]]);
        let mut skew = 0.0f64;
        for a in &moved {
            for b in &moved {
                skew = skew.max(((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt());
            }
        }
        let rows = rolling.iter().map(|p| p[1]).fold(0.0, f64::max)
            - rolling.iter().map(|p| p[1]).fold(f64::MAX, f64::min);
        println!(
            "{what} 30 deg/s, readout {:.1} ms, marker {rows:.0} rows tall: RS corners up to \
             {shift:.2} px from the global-shutter ones, skew {skew:.2} px; detected \
             {to_rolling:.3} px from the RS corners, {to_global:.2} px from the global ones",
            READOUT_S * 1e3
        );
        if what == "yaw" {
            // Turning about the optical axis during the readout bends the marker's edges
            // (each row turned by its own angle: a shift growing with the square of the
            // row's distance from the middle, 0.4 px at the marker's top and bottom here);
            // the detector fits straight edges, so its corners sit a few tenths off.
            assert!(to_rolling < 0.5, "{what}: {to_rolling} px");
        } else {
            // Roll and pitch shear the marker, its edges stay straight.
            assert!(to_rolling < 0.25, "{what}: {to_rolling} px");
        }
        if what == "yaw" {
            // About the optical axis: the corners move by the rate times their row time
            // times their distance from the image centre: under a pixel for a centred marker.
            assert!(skew > 0.5, "{what}: skew {skew} px");
        } else {
            assert!(skew > 3.0 && to_global > 1.5, "{what}: skew {skew} px");
        }
        // The skew a row's time predicts: a turn about body x (the image's up axis) moves
        // the image sideways by f * rate * dt, about body y up and down.
        let f = simulator.scenario.camera.fx();
        let middle = 0.5 * (simulator.scenario.camera.height() as f64 - 1.0);
        let line = READOUT_S / simulator.scenario.camera.height() as f64;
        for (r, g) in rolling.iter().zip(&global) {
            let dt = (r[1] - middle) * line;
            let (along, across) = match what {
                "roll" => (r[0] - g[0], r[1] - g[1]),
                "pitch" => (r[1] - g[1], r[0] - g[0]),
                _ => continue,
            };
            let expected = f * RATE * dt;
            assert!(
                (along.abs() - expected.abs()).abs() < 0.08 * expected.abs() + 0.05
                    && across.abs() < 0.1 * expected.abs() + 0.05,
                "{what}: corner moved ({along:.3}, {across:.3}) px, expected {expected:.3} px"
            );
        }
    }
}

/// A global shutter: the rolling-shutter corners are the frame-time corners.
#[test]
fn without_a_readout_the_corner_functions_agree() {
    let simulator = Simulator::new(sharp(turning(2.5, [RATE, 0.0, RATE])));
    let rolling = simulator.marker_corners_rolling_shutter(0.0);
    let global = simulator.marker_corners(&simulator.camera_pose(0.0));
    assert_eq!(rolling, global);
}

/// FNV-1a of a frame's pixels.
fn fnv(pixels: &[u8]) -> u64 {
    pixels.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// Without effects a frame is the one the renderer drew before the effects existed: the
/// hashes of landing frames 0 and 29 (board lens, defocus, vignetting, noise) and of lateral
/// frame 51 (mid-dash, motion-blurred over several sub-frames) as rendered by commit
/// 93d3383, before rolling shutter, vibration and mount misalignment were added. A
/// deliberate change of the renderer updates them.
#[test]
fn without_effects_the_frames_are_the_old_ones() {
    for (name, frames, expected) in [
        ("landing", &[0usize, 29][..], &OLD_LANDING_HASHES[..]),
        ("lateral", &[51][..], &[OLD_LATERAL_51_HASH][..]),
    ] {
        let mut scenario = Scenario::named(name, 1).expect("scenario");
        let plain = Simulator::new(scenario.clone());
        scenario.apply_effects(&FlightEffects::none());
        let none = Simulator::new(scenario);
        for (&k, &hash) in frames.iter().zip(expected) {
            let a = plain.render(k).expect("frame");
            let b = none.render(k).expect("frame");
            assert_eq!(a, b, "{name} frame {k}");
            println!("{name} frame {k}: {} sub-frames", a.subframes);
            assert_eq!(fnv(&a.image.pixels), hash, "{name} frame {k}");
        }
    }
}

/// `fnv` of landing frames 0 and 29 (seed 1) from `touchdown simulate --scenario landing
/// --frames 30` at commit 93d3383.
const OLD_LANDING_HASHES: [u64; 2] = [0xf2f1_5542_f44b_c8e8, 0x3600_3c24_776f_0df3];
/// `fnv` of lateral frame 51 (seed 1, t = 1.7 s) from `touchdown simulate --scenario
/// lateral --frames 52` at commit 93d3383.
const OLD_LATERAL_51_HASH: u64 = 0x180c_b187_1226_b8b6;

/// The camera turns on its mount at 50-200 Hz with the asked RMS per axis; the vehicle's
/// attitude does not move with it.
#[test]
fn vibration_wobbles_the_camera_not_the_vehicle() {
    let still = sharp(turning(5.0, [0.0; 3]));
    let mut shaken = still.clone();
    shaken.apply_effects(&FlightEffects {
        vibration_deg: 0.15,
        ..FlightEffects::none()
    });
    let (a, b) = (Simulator::new(still), Simulator::new(shaken));
    // 2 s at 2 kHz: the camera's rotation on its mount, about each body axis.
    let rate = 2000.0;
    let n = 4000;
    let mount = CameraMount::downward().rotation;
    let mut series = [vec![0.0f64; n], vec![0.0; n], vec![0.0; n]];
    for k in 0..n {
        let t = k as f64 / rate;
        assert_eq!(a.vehicle_attitude(t), b.vehicle_attitude(t), "at {t} s");
        assert_eq!(a.camera_pose(t).position, b.camera_pose(t).position);
        // camera-to-pad = N B V M: V = B^T N^T C M^T, with B, N from the still camera.
        let still_camera = a.camera_pose(t).rotation;
        let nb = mul(&still_camera, &transpose(&mount));
        let v: Mat3 = mul(
            &transpose(&nb),
            &mul(&b.camera_pose(t).rotation, &transpose(&mount)),
        );
        // Small angles: the skew part.
        let angles = [
            0.5 * (v[2][1] - v[1][2]),
            0.5 * (v[0][2] - v[2][0]),
            0.5 * (v[1][0] - v[0][1]),
        ];
        for (s, x) in series.iter_mut().zip(angles) {
            s[k] = x;
        }
    }
    for (axis, s) in series.iter().enumerate() {
        let rms = (s.iter().map(|x| x * x).sum::<f64>() / n as f64)
            .sqrt()
            .to_degrees();
        assert!((rms - 0.15).abs() < 0.01, "axis {axis}: RMS {rms:.4} deg");
        // Power by frequency (0.5 Hz bins): all of it between 45 and 205 Hz.
        let (mut inside, mut total) = (0.0, 0.0);
        for bin in 1..1000 {
            let f = bin as f64 * 0.5;
            let (mut re, mut im) = (0.0, 0.0);
            for (k, x) in s.iter().enumerate() {
                let phase = std::f64::consts::TAU * f * k as f64 / rate;
                re += x * phase.cos();
                im += x * phase.sin();
            }
            let power = re * re + im * im;
            total += power;
            if (45.0..=205.0).contains(&f) {
                inside += power;
            }
        }
        assert!(
            inside > 0.97 * total,
            "axis {axis}: {:.1} % of the power in 45-205 Hz",
            100.0 * inside / total
        );
    }
}

/// A vibrating camera blurs a 4 ms exposure of a hovering vehicle (the image moves), a
/// still one does not.
#[test]
fn vibration_blurs_the_exposure() {
    let mut still = sharp(turning(5.0, [0.0; 3]));
    still.exposure_time_s = 0.004;
    let mut shaken = still.clone();
    shaken.apply_effects(&FlightEffects {
        vibration_deg: 0.15,
        ..FlightEffects::none()
    });
    let still = Simulator::new(still);
    let shaken = Simulator::new(shaken);
    assert_eq!(still.subframe_count(0.0, still.scenario.exposure_time_s), 1);
    let counts: Vec<usize> = (0..10)
        .map(|k| shaken.subframe_count(k as f64 * 0.0123, shaken.scenario.exposure_time_s))
        .collect();
    println!("sub-frames of a 4 ms exposure with 0.15 deg RMS vibration: {counts:?}");
    assert!(counts.iter().all(|&n| n >= 2), "{counts:?}");
    assert!(counts.iter().any(|&n| n >= 4), "{counts:?}");
}

/// The misaligned mount turns the camera by R_y(pitch) R_x(roll) in body axes; the frame's
/// truth is the camera pose at its time and its vehicle attitude the body's.
#[test]
fn the_mount_turns_the_camera_and_the_frame_carries_the_vehicle_attitude() {
    let mut scenario = Scenario::named("landing", 2).expect("landing");
    scenario.camera = touchdown_sim::camera::SimCamera::with_fov(160, 120, 60.0, [0.0; 5]);
    scenario.frames = vec![FramePlan {
        t_us: 5_000_000,
        label: None,
    }];
    let nominal = Simulator::new(scenario.clone());
    scenario.apply_effects(&FlightEffects {
        mount_roll_deg: 1.2,
        mount_pitch_deg: -1.6,
        ..FlightEffects::none()
    });
    let misaligned = Simulator::new(scenario);
    let t = 5.0;
    let body_to_ned = touchdown_sim::math::quat_to_matrix(misaligned.vehicle_attitude(t));
    let expected = CameraPose::of_vehicle(
        nominal.camera_pose(t).position,
        &body_to_ned,
        &CameraMount {
            rotation: mul(
                &mul(
                    &from_euler(0.0, (-1.6f64).to_radians(), 0.0),
                    &from_euler(1.2f64.to_radians(), 0.0, 0.0),
                ),
                &CameraMount::downward().rotation,
            ),
        },
    );
    let pose = misaligned.camera_pose(t);
    let difference = touchdown_sim::math::max_difference(&pose.rotation, &expected.rotation);
    assert!(difference < 1e-12, "{difference}");
    // 2 degrees off the nominal camera.
    let relative = mul(&transpose(&nominal.camera_pose(t).rotation), &pose.rotation);
    let angle = ((relative[0][0] + relative[1][1] + relative[2][2] - 1.0) * 0.5)
        .acos()
        .to_degrees();
    assert!((angle - 2.0).abs() < 0.01, "{angle} deg");
    let frame = misaligned.render(0).expect("frame");
    assert_eq!(frame.truth, touchdown_sim::truth_of_pose(&pose));
    assert_eq!(frame.vehicle_attitude, misaligned.vehicle_attitude(t));
    let round_trip = matrix_to_quat(&body_to_ned);
    assert!(frame
        .vehicle_attitude
        .iter()
        .zip(round_trip)
        .all(|(a, b)| (a - b).abs() < 1e-15));
    assert!(frame.vehicle_attitude[0] >= 0.0);
    assert_eq!(frame.vehicle_attitude, nominal.vehicle_attitude(t));
}

/// All effects on: the same bytes with one thread and with two.
#[test]
fn effects_render_the_same_with_any_thread_count() {
    let mut scenario = Scenario::named("lateral", 4).expect("lateral");
    scenario.camera = touchdown_sim::camera::SimCamera::with_fov(160, 120, 60.0, [0.0; 5]);
    scenario.frames = vec![FramePlan {
        t_us: 1_700_000,
        label: None,
    }];
    scenario.apply_effects(&FlightEffects::typical());
    let one = Simulator::new(scenario.clone()).with_threads(1).render(0);
    let two = Simulator::new(scenario).with_threads(2).render(0);
    assert_eq!(one, two);
    assert!(one.is_some_and(|f| f.subframes > 1));
}

/// The vibration is the scenario seed's: another seed, another vibration.
#[test]
fn vibration_follows_the_seed() {
    let mut a = Scenario::named("landing", 1).expect("landing");
    let mut b = Scenario::named("landing", 2).expect("landing");
    a.apply_effects(&FlightEffects::typical());
    b.apply_effects(&FlightEffects::typical());
    assert_ne!(a.vibration, b.vibration);
    assert_ne!(a.vibration, Vibration::none());
}
