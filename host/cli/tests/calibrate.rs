//! `touchdown calibrate` as a user runs it: a simulated flight over the pad with a known mount
//! misalignment gives that misalignment back within the stated uncertainty; a recording
//! without the vehicle attitude, or without enough good frames, is a one-line error.
//!
//! The recording is rendered here with the simulator's library rather than `touchdown
//! simulate`: the descent scenario's last 15 s (16 m down to 1 m over the nested pad) at
//! 15 Hz (every second frame), without supersampling or rolling shutter, so the test renders
//! in minutes rather than many. The mount misalignment and the vibration are the simulator's own.

use std::path::{Path, PathBuf};
use std::process::Command;

use touchdown_formats::recording::RecordingWriter;
use touchdown_sim::effects::FlightEffects;
use touchdown_sim::scenario::Scenario;
use touchdown_sim::Simulator;

/// A fresh scratch directory path under the target directory (removed if it exists, not
/// created).
fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("calibrate")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn touchdown() -> Command {
    Command::new(env!("CARGO_BIN_EXE_touchdown"))
}

/// Renders the descent with the mount misaligned by (roll, pitch) into `dir`, every `step`th
/// frame, with or without the vehicle attitude columns.
fn render(dir: &Path, roll: f64, pitch: f64, step: usize, frames: usize, attitude: bool) {
    let mut scenario = Scenario::named("descent", 4).unwrap();
    // From 16 m down (the first 4 s, far away, give poor tilts the calibrator refuses).
    scenario.frames = scenario
        .frames
        .iter()
        .skip(120)
        .step_by(step)
        .take(frames)
        .cloned()
        .collect();
    scenario.apply_effects(&FlightEffects {
        readout_ms: 0.0,
        vibration_deg: 0.03,
        mount_roll_deg: roll,
        mount_pitch_deg: pitch,
    });
    scenario.supersampling = 1;
    let simulator = Simulator::new(scenario);
    let camera = simulator.scenario.camera.model;
    let pad = simulator.scenario.pad.config.clone();
    let mut writer =
        RecordingWriter::create_with_vehicle_attitude(dir, &camera, &pad, true, attitude).unwrap();
    for k in 0..simulator.frame_count() {
        let frame = simulator.render(k).unwrap();
        writer
            .push_with_vehicle_attitude(
                frame.t_us,
                Some(&frame.truth),
                attitude.then_some(&frame.vehicle_attitude),
                frame.label.as_deref(),
                &frame.image,
            )
            .unwrap();
    }
    writer.finish().unwrap();
}

#[test]
#[ignore = "long: in the long suite, `cargo test -- --ignored` (CI runs it)"]
fn calibrate_recovers_a_known_mount_misalignment() {
    let dir = scratch("known");
    render(&dir, 1.5, -1.0, 2, usize::MAX, true);
    let out = touchdown()
        .args(["calibrate", "--json"])
        .arg(&dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let f = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    let (roll, pitch) = (f("roll_deg"), f("pitch_deg"));
    let (roll_sigma, pitch_sigma) = (f("roll_sigma_deg"), f("pitch_sigma_deg"));
    eprintln!("{v}");
    assert!((roll - 1.5).abs() <= roll_sigma, "{v}");
    assert!((pitch + 1.0).abs() <= pitch_sigma, "{v}");
    assert!(
        (roll - 1.5).abs() <= 0.15 && (pitch + 1.0).abs() <= 0.15,
        "{v}"
    );
    // The attitude here is the simulator's truth: the sigma is the bias model's, the noise
    // part small.
    assert!(f("noise_sigma_deg") < 0.05, "{v}");
    assert!(f("frames") >= 100.0 && f("span_s") >= 10.0, "{v}");
    assert_eq!(
        v["params"]["TD_CAM_ROLL"].as_f64(),
        Some((roll * 100.0).round() / 100.0)
    );

    // The text form: the estimate and the lines to set.
    let out = touchdown().arg("calibrate").arg(&dir).output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("param set TD_CAM_ROLL "), "{text}");
    assert!(text.contains("param set TD_CAM_PITCH "), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn calibrate_refuses_a_recording_without_attitude_or_enough_frames() {
    let dir = scratch("no-attitude");
    render(&dir, 1.5, -1.0, 30, 3, false);
    let out = touchdown().arg("calibrate").arg(&dir).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains("no vehicle attitude"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);

    let dir = scratch("short");
    render(&dir, 1.5, -1.0, 30, 5, true);
    let out = touchdown().arg("calibrate").arg(&dir).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains("not enough good frames") && stderr.contains("it needs 100 frames"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);

    let out = touchdown()
        .args(["calibrate", "/nonexistent/recording"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(String::from_utf8_lossy(&out.stderr).lines().count(), 1);
}
