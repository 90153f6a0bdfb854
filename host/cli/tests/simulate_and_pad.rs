//! `touchdown simulate` and `touchdown pad` as a user runs them: a simulated recording that
//! reads back (and renders again to the same bytes), a printable pad whose pad.toml gives the
//! same layout back, page tiling, and one-line errors with status 2.

use std::path::{Path, PathBuf};
use std::process::Command;

use touchdown_formats::recording::Recording;
use touchdown_sim::effects::FlightEffects;
use touchdown_sim::scenario::Scenario;
use touchdown_sim::{Renderer, Simulator};

/// A fresh scratch directory path under the target directory (removed if it exists, not
/// created).
fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("simulate_and_pad")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn touchdown() -> Command {
    Command::new(env!("CARGO_BIN_EXE_touchdown"))
}

/// Runs `touchdown simulate ARGS --out DIR`, which must succeed, and reads the recording.
fn simulate(args: &[&str], dir: &Path) -> Recording {
    let out = touchdown()
        .arg("simulate")
        .args(args)
        .arg("--out")
        .arg(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    Recording::read(dir).unwrap()
}

#[test]
fn simulate_writes_a_readable_recording() {
    let dir = scratch("simulate");
    let recording = simulate(&["--scenario", "sun", "--frames", "2", "--seed", "3"], &dir);
    assert_eq!(recording.frames.len(), 2);
    assert_eq!(recording.frames[0].label.as_deref(), Some("hover=20"));
    let truth = recording.frames[1].truth.unwrap();
    assert!((truth.position[2] - 20.0).abs() < 0.2);
    // Rendering again from the same seed, with the typical flight effects (the default),
    // gives the same bytes, and the vehicle's attitude of the frame.
    let mut scenario = Scenario::named("sun", 3).unwrap();
    scenario.truncate(2);
    scenario.apply_effects(&FlightEffects::typical());
    let again = Simulator::new(scenario).render(1).unwrap();
    assert_eq!(again.image, recording.frames[1].image);
    assert_eq!(again.truth, truth);
    assert_eq!(
        recording.frames[1].vehicle_attitude,
        Some(again.vehicle_attitude)
    );
    // The rolling shutter's line time is in camera.toml: 30.5 ms over 480 rows.
    let line = f64::from(recording.camera.line_time_us);
    assert!((line * 480.0 - 30_500.0).abs() < 0.1, "{line} us");
    let csv = std::fs::read_to_string(dir.join("frames.csv")).unwrap();
    assert!(
        csv.lines()
            .next()
            .unwrap()
            .ends_with(",cam_qz,veh_qw,veh_qx,veh_qy,veh_qz"),
        "{csv}"
    );
    let toml = std::fs::read_to_string(dir.join("simulation.toml")).unwrap();
    assert!(toml.contains("readout_ms = 30.5\n"), "{toml}");
    // A non-empty directory is refused with one line and status 2.
    let out = touchdown()
        .args(["simulate", "--scenario", "sun", "--frames", "1", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    assert!(stderr.contains("not empty"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn simulate_effect_flags_override_the_typical_ones() {
    let run = |name: &str, flags: &[&str]| {
        let dir = scratch(name);
        let mut args = vec!["--scenario", "occlusion", "--frames", "1"];
        args.extend_from_slice(flags);
        let recording = simulate(&args, &dir);
        let _ = std::fs::remove_dir_all(&dir);
        recording
    };
    // --ideal: the frames of the scenario without effects, a global shutter.
    let ideal = run("ideal", &["--ideal"]);
    let mut scenario = Scenario::named("occlusion", 1).unwrap();
    scenario.truncate(1);
    let plain = Simulator::new(scenario.clone()).render(0).unwrap();
    assert_eq!(ideal.frames[0].image, plain.image);
    assert_eq!(ideal.camera.line_time_us, 0.0);
    // Each flag sets its own term: a readout of 10 ms, the rest as --ideal.
    let readout = run("readout", &["--ideal", "--readout-ms", "10"]);
    let mut effects = FlightEffects::none();
    effects.readout_ms = 10.0;
    scenario.apply_effects(&effects);
    let expected = Simulator::new(scenario.clone()).render(0).unwrap();
    assert_eq!(readout.frames[0].image, expected.image);
    assert!((f64::from(readout.camera.line_time_us) * 480.0 - 10_000.0).abs() < 0.1);
    // Typical but a global shutter and an aligned mount: only the vibration left.
    let shaken = run(
        "shaken",
        &[
            "--readout-ms",
            "0",
            "--mount-roll-deg",
            "0",
            "--mount-pitch-deg",
            "-0",
        ],
    );
    let mut scenario = Scenario::named("occlusion", 1).unwrap();
    scenario.truncate(1);
    scenario.apply_effects(&FlightEffects {
        vibration_deg: FlightEffects::typical().vibration_deg,
        ..FlightEffects::none()
    });
    let expected = Simulator::new(scenario).render(0).unwrap();
    assert_eq!(shaken.frames[0].image, expected.image);
    assert_eq!(shaken.camera.line_time_us, 0.0);
    assert_ne!(shaken.frames[0].image, plain.image);
}

#[test]
fn simulate_renders_with_the_renderer_asked_for() {
    let dir = scratch("simulate-warp");
    let recording = simulate(
        &[
            "--scenario",
            "landing",
            "--frames",
            "2",
            "--seed",
            "5",
            "--threads",
            "2",
            "--renderer",
            "warp",
        ],
        &dir,
    );
    let mut scenario = Scenario::named("landing", 5).unwrap();
    scenario.truncate(2);
    scenario.apply_effects(&FlightEffects::typical());
    let warp = Simulator::new(scenario.clone())
        .with_renderer(Renderer::Warp)
        .render(1)
        .unwrap();
    assert_eq!(warp.image, recording.frames[1].image);
    assert_ne!(
        Simulator::new(scenario).render(1).unwrap().image,
        recording.frames[1].image
    );
    let toml = std::fs::read_to_string(dir.join("simulation.toml")).unwrap();
    assert!(toml.contains("renderer = \"warp\""), "{toml}");
}

#[test]
fn simulate_draws_the_pad_asked_for_over_the_same_flight() {
    let dir = scratch("simulate-pad");
    let args = ["--scenario", "landing", "--frames", "1", "--threads", "2"];
    let field = simulate(&[&args[..], &["--pad", "nested-field"]].concat(), &dir);
    let toml = std::fs::read_to_string(dir.join("pad.toml")).unwrap();
    assert!(toml.contains("name = \"nested-field\""), "{toml}");
    let nested = simulate(&args, &scratch("simulate-pad-default"));
    assert_eq!(field.frames[0].t_us, nested.frames[0].t_us);
    assert_eq!(field.frames[0].truth, nested.frames[0].truth);
    assert_ne!(field.frames[0].image, nested.frames[0].image);
}

#[test]
fn bad_options_are_one_line_and_status_2() {
    for args in [
        vec!["simulate", "--scenario", "moon"],
        vec!["simulate", "--scenario", "paper", "--frames", "0"],
        vec!["simulate", "--scenario", "paper", "--vibration-deg", "x"],
        vec!["simulate", "--scenario", "paper", "--readout-ms", "-1"],
        vec!["simulate", "--scenario", "paper", "--mount-roll-deg", "90"],
        vec!["simulate", "--scenario", "paper", "--renderer", "gpu"],
        vec!["simulate", "--scenario", "paper", "--pad", "round"],
        vec!["sitl", "--renderer", "ray"],
        vec!["replay", "--scenario", "paper", "--renderer", ""],
        vec!["replay", "/nonexistent", "--renderer", "warp"],
        vec!["pad", "--design", "nested"],
        vec!["pad", "--layout", "/nonexistent/pad.toml", "--out", "/tmp"],
    ] {
        let out = touchdown().args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.starts_with("error:"), "{args:?}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{args:?}: {stderr}");
    }
}

#[test]
fn pad_refuses_overlapping_markers() {
    let dir = scratch("pad-overlap");
    std::fs::create_dir_all(&dir).unwrap();
    let layout = dir.join("overlap.toml");
    std::fs::write(
        &layout,
        "name = \"overlap\"\n\
         [[marker]]\nfamily = \"tag36h11\"\nid = 0\nsize = 1.0\nx = 0.0\ny = 0.0\n\
         [[marker]]\nfamily = \"tag36h11\"\nid = 1\nsize = 0.2\nx = 0.1\ny = 0.1\n",
    )
    .unwrap();
    let out = touchdown()
        .args(["pad", "--layout"])
        .arg(&layout)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains("overlap.toml") && stderr.contains("overlap") && stderr.contains("#1"),
        "{stderr}"
    );
    assert!(!dir.join("out").join("pad.svg").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn pad_tiles_into_pages_and_counts_markers_in_words() {
    let dir = scratch("pad-tiles");
    let out = touchdown()
        .args([
            "pad",
            "--design",
            "paper-single",
            "--tile",
            "letter",
            "--out",
        ])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("1 marker;"), "{stdout}");
    // A 1300 x 1340 mm drawing (1.25 m sheet, 25 mm borders, 40 mm footer) on letter paper
    // (195.9 x 259.4 mm inside the margins, stepping 185.9 x 249.4): 7 columns, 6 rows.
    assert!(
        stdout.contains("wrote 42 letter pages (6 rows x 7 columns"),
        "{stdout}"
    );
    let pages: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|name| name.starts_with("pad-page-"))
        .collect();
    assert_eq!(pages.len(), 42);
    assert!(pages.contains(&"pad-page-1-1.svg".to_string()));
    assert!(pages.contains(&"pad-page-6-7.svg".to_string()));
    let page = std::fs::read_to_string(dir.join("pad-page-2-3.svg")).unwrap();
    assert!(
        page.contains("width=\"215.9mm\" height=\"279.4mm\""),
        "{}",
        &page[..300]
    );
    assert!(page.contains("page row 2 column 3 of 6 x 7"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn pad_writes_svg_and_the_same_layout() {
    let dir = scratch("pad");
    let out = touchdown()
        .args(["pad", "--design", "nested", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let svg = std::fs::read_to_string(dir.join("pad.svg")).unwrap();
    assert!(svg.contains("mm\" height=\"") && svg.contains("viewBox"));
    assert!(svg.contains("100 mm"));
    let config = touchdown_formats::pad::load_pad(&dir.join("pad.toml")).unwrap();
    assert_eq!(
        config.layout().unwrap(),
        touchdown_core::pad::designs::NESTED
    );
    // And a layout file gives the same pad back.
    let again = scratch("pad-again");
    let out = touchdown()
        .args(["pad", "--layout"])
        .arg(dir.join("pad.toml"))
        .arg("--out")
        .arg(&again)
        .output()
        .unwrap();
    assert!(out.status.success());
    assert_eq!(std::fs::read_to_string(again.join("pad.svg")).unwrap(), svg);
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&again);
}
