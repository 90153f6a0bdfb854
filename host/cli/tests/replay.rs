//! `touchdown replay` as a user sees it: the tables for a small simulated recording, the
//! figures, the same results from a recording and from the scenario rendered in memory,
//! `--json` against the text of the same run, vision-only replay without truth, and one-line
//! errors (exit status 2) naming the file and line of a truncated or corrupt recording.
//!
//! One small recording (the first [`FRAMES`] frames of the paper scenario: its 5 m hover) is
//! written once with `touchdown simulate` and copied for the tests that damage it.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// Frames of the shared recording: the paper scenario's first set point, `z=5`, has 16.
const FRAMES: usize = 10;

fn touchdown(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_touchdown"))
        .args(args)
        .output()
        .expect("the touchdown binary runs")
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("replay-tests")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn path_str(path: &Path) -> &str {
    path.to_str().expect("scratch paths are UTF-8")
}

/// The shared recording, written on first use: without flight effects (a global shutter,
/// no vibration, the nominal mount), so that these tests are about the replay itself; the
/// flight effects have tests of their own.
fn recording() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = scratch("paper-recording");
        let frames = FRAMES.to_string();
        let output = touchdown(&[
            "simulate",
            "--scenario",
            "paper",
            "--ideal",
            "--frames",
            &frames,
            "--out",
            path_str(&dir),
        ]);
        assert!(output.status.success(), "{}", text(&output.stderr));
        dir
    })
}

/// A private copy of the shared recording.
fn copy_of_recording(name: &str) -> PathBuf {
    let dir = scratch(name);
    copy_dir(recording(), &dir);
    dir
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("create copy");
    for entry in std::fs::read_dir(from).expect("read recording") {
        let entry = entry.expect("entry");
        let target = to.join(entry.file_name());
        if entry.file_type().expect("file type").is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).expect("copy file");
        }
    }
}

/// Asserts exit status 2 and exactly one stderr line containing every `needle`.
fn assert_fails_with_one_line(output: &Output, needles: &[&str]) {
    let stderr = text(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "stderr: {stderr}");
    assert_eq!(stderr.lines().count(), 1, "expected one line: {stderr}");
    assert!(stderr.starts_with("error: "), "{stderr}");
    for needle in needles {
        assert!(stderr.contains(needle), "stderr lacks `{needle}`: {stderr}");
    }
}

/// The cells of the set-point row starting with `row` in the first table: the columns
/// between `|` separators, split on whitespace.
fn row_cells(stdout: &str, row: &str) -> Vec<Vec<String>> {
    let line = stdout
        .lines()
        .find(|l| l.starts_with(row))
        .unwrap_or_else(|| panic!("no row `{row}` in:\n{stdout}"));
    line.split('|')
        .map(|cell| cell.split_whitespace().map(str::to_string).collect())
        .collect()
}

fn number(cell: &str) -> f64 {
    cell.trim_end_matches('%')
        .parse()
        .unwrap_or_else(|_| panic!("not a number: {cell}"))
}

/// The output from the set-point table on, without the timing in the header.
fn tables(stdout: &str) -> String {
    stdout
        .lines()
        .skip_while(|l| !l.starts_with("Set points"))
        .filter(|l| !l.starts_with("Figures"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The set-point table alone.
fn set_point_table(stdout: &str) -> String {
    tables(stdout)
        .lines()
        .take_while(|l| !l.starts_with("Mean error on every axis"))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn replay_prints_the_set_point_table_and_writes_figures() {
    let plots = scratch("figures");
    let output = touchdown(&["replay", path_str(recording()), "--plots", path_str(&plots)]);
    let stdout = text(&output.stdout);
    assert!(output.status.success(), "{}", text(&output.stderr));
    assert!(
        stdout.contains(&format!(": {FRAMES} frames in 1 sequence (")),
        "{stdout}"
    );
    // Columns: row | published est err | paper's method x6 | ours x6.
    let cells = row_cells(&stdout, "Z   500");
    assert_eq!(cells[1], ["502", "-2.1"], "published values of Table 2");
    let ours = &cells[3];
    assert_eq!(ours.len(), 6, "{ours:?}");
    // The vehicle hovers at 5 m with a 2 cm wobble: estimate within 3 cm, error well under
    // the paper's, every frame detected, estimates once the track is confirmed.
    let (estimate, abs_error, detected, estimated) = (
        number(&ours[0]),
        number(&ours[2]),
        number(&ours[4]),
        number(&ours[5]),
    );
    assert!((estimate - 500.0).abs() < 3.0, "estimate {estimate} cm");
    assert!(abs_error < 1.0, "mean |error| {abs_error} cm");
    assert_eq!(detected, 100.0);
    assert!(estimated >= 70.0, "estimate rate {estimated} %");
    for needle in [
        "RMS error x / y / z, cm (filtered)",
        "longest gap without an estimate",
        "lag, frames",
    ] {
        assert!(stdout.contains(needle), "lacks `{needle}`:\n{stdout}");
    }
    for stem in [
        "position-x",
        "position-y",
        "position-z",
        "error-x",
        "error-y",
        "error-z",
    ] {
        let png = image::open(plots.join(format!("{stem}.png")))
            .unwrap_or_else(|e| panic!("{stem}.png: {e}"));
        // 1200 wide; the legend's band above the plot adds rows as the methods need.
        assert_eq!(png.width(), 1200);
        assert!(png.height() >= 520, "{stem}.png is {} high", png.height());
        // Not a blank canvas: lines, dots and text in several colours.
        let rgb = png.to_rgb8();
        let non_white = rgb.pixels().filter(|p| p.0 != [255, 255, 255]).count();
        assert!(non_white > 10_000, "{stem}.png is nearly blank");
        let svg = std::fs::read_to_string(plots.join(format!("{stem}.svg"))).expect("svg");
        assert!(
            svg.starts_with("<svg") && svg.contains("time (s)"),
            "{stem}.svg"
        );
    }
}

/// The set-point tables of the paper scenario's first [`FRAMES`] frames (ideal, no flight
/// effects) replayed three ways: in memory with the image-model options `image`, in memory
/// with `other` instead, and from its recording simulated with `image` into scratch `dir`;
/// `check_recording` looks at that recording first.
fn tables_in_memory_and_on_disk(
    dir: &str,
    image: &[&str],
    other: &[&str],
    check_recording: impl Fn(&Path),
) -> (String, String, String) {
    let frames = FRAMES.to_string();
    let dir = scratch(dir);
    let scenario = ["--scenario", "paper", "--ideal", "--frames", &frames];
    let output = touchdown(
        &[
            &["simulate"][..],
            &scenario,
            image,
            &["--out", path_str(&dir)],
        ]
        .concat(),
    );
    assert!(output.status.success(), "{}", text(&output.stderr));
    check_recording(&dir);
    let replay = |options: &[&str]| {
        let out = touchdown(&[&["replay"][..], &scenario, options, &["--no-plots"]].concat());
        assert!(out.status.success(), "{}", text(&out.stderr));
        set_point_table(&text(&out.stdout))
    };
    let from_disk = touchdown(&["replay", path_str(&dir), "--no-plots", "--ideal"]);
    assert!(from_disk.status.success(), "{}", text(&from_disk.stderr));
    (
        replay(image),
        replay(other),
        set_point_table(&text(&from_disk.stdout)),
    )
}

/// `--renderer warp` reaches the simulator both ways: a scenario replayed in memory with it
/// gives the tables of its recording simulated with it, and not the raster frames' tables.
#[test]
fn the_renderer_is_the_same_in_memory_and_on_disk() {
    let (warp, raster, from_disk) = tables_in_memory_and_on_disk(
        "paper-recording-warp",
        &["--renderer", "warp"],
        &["--renderer", "raster"],
        |_| {},
    );
    assert!(!warp.is_empty());
    assert_eq!(warp, from_disk);
    assert_ne!(warp, raster);
}

#[test]
fn scenario_in_memory_gives_the_same_tables_as_its_recording() {
    let frames = FRAMES.to_string();
    let from_memory = touchdown(&[
        "replay",
        "--scenario",
        "paper",
        "--frames",
        &frames,
        "--no-plots",
        "--ideal",
    ]);
    assert!(
        from_memory.status.success(),
        "{}",
        text(&from_memory.stderr)
    );
    let from_disk = touchdown(&["replay", path_str(recording()), "--no-plots", "--ideal"]);
    assert!(from_disk.status.success(), "{}", text(&from_disk.stderr));
    let (a, b) = (text(&from_memory.stdout), text(&from_disk.stdout));
    assert!(a.starts_with("touchdown replay: scenario paper, seed 1"));
    assert!(!tables(&a).is_empty());
    // The simulated autopilot samples the truth between frames: the simulator's for the
    // scenario, the frames' interpolated for the recording; they differ by hundredths of a
    // millimetre, which the other tables' last digits can show.
    assert_eq!(set_point_table(&a), set_point_table(&b));
    assert!(a.contains("(c) ideal sensor: RMS") && b.contains("(c) ideal sensor: RMS"));
    assert!(!a.contains("Figures"), "--no-plots wrote figures:\n{a}");
}

#[test]
fn recording_without_truth_replays_vision_only() {
    let dir = copy_of_recording("no-truth");
    let csv = std::fs::read_to_string(dir.join("frames.csv")).expect("frames.csv");
    let stripped: String = csv
        .lines()
        .map(|l| {
            let mut fields = l.split(',');
            format!(
                "{},{}\n",
                fields.next().unwrap_or(""),
                fields.next().unwrap_or("")
            )
        })
        .collect();
    std::fs::write(dir.join("frames.csv"), stripped).expect("write");
    let output = touchdown(&["replay", path_str(&dir), "--no-plots"]);
    let stdout = text(&output.stdout);
    assert!(output.status.success(), "{}", text(&output.stderr));
    assert!(stdout.contains("No truth"), "{stdout}");
    assert!(!stdout.contains("RMS error"), "{stdout}");
    // The set-point row gives the estimates: about 5 m up, over the pad.
    let cells = row_cells(&stdout, "z=5");
    let ours = &cells[2];
    let z = number(&ours[2]);
    assert!((z - 500.0).abs() < 10.0, "z {z} cm: {ours:?}");
    assert_eq!(number(&ours[3]), 100.0, "{ours:?}");
}

#[test]
fn corrupt_frames_csv_names_the_file_and_line() {
    let dir = copy_of_recording("corrupt-csv");
    let path = dir.join("frames.csv");
    let csv = std::fs::read_to_string(&path).expect("frames.csv");
    let mut lines: Vec<String> = csv.lines().map(str::to_string).collect();
    // Line 5 (frame 3) loses its last four columns, as a write cut short would.
    let cut: Vec<&str> = lines[4].split(',').take(5).collect();
    lines[4] = cut.join(",");
    std::fs::write(&path, lines.join("\n") + "\n").expect("write");
    let output = touchdown(&["replay", path_str(&dir), "--no-plots"]);
    assert_fails_with_one_line(&output, &["frames.csv: line 5", "columns"]);
    assert!(output.stdout.is_empty());
}

#[test]
fn missing_frame_file_is_named() {
    let dir = copy_of_recording("missing-pgm");
    std::fs::remove_file(dir.join("frames").join("000003.pgm")).expect("remove");
    let output = touchdown(&["replay", path_str(&dir), "--no-plots"]);
    assert_fails_with_one_line(&output, &["000003.pgm", "missing frame file", "line 5"]);
}

#[test]
fn truncated_frame_file_is_named() {
    let dir = copy_of_recording("truncated-pgm");
    let path = dir.join("frames").join("000002.pgm");
    let bytes = std::fs::read(&path).expect("pgm");
    std::fs::write(&path, &bytes[..bytes.len() / 2]).expect("truncate");
    let output = touchdown(&["replay", path_str(&dir), "--no-plots"]);
    assert_fails_with_one_line(&output, &["000002.pgm", "truncated"]);
    assert!(output.stdout.is_empty());
}

#[test]
fn bad_inputs_are_one_line_and_status_2() {
    let cases: [(&[&str], &[&str]); 14] = [
        (
            &["replay", "--scenario", "nosuch"],
            &["unknown scenario `nosuch`", "paper", "landing"],
        ),
        (&["replay"], &["nothing to replay"]),
        (
            &["replay", "some-dir", "--scenario", "paper"],
            &["not both"],
        ),
        (
            &["replay", "/nonexistent/recording"],
            &["/nonexistent/recording", "no such directory"],
        ),
        (
            &["replay", "--scenario", "paper", "--frames", "0"],
            &["--frames"],
        ),
        (&["replay", "some-dir", "--seed", "3"], &["--scenario only"]),
        (
            &["replay", "some-dir", "--psf", "disc:2"],
            &["--psf", "--scenario only"],
        ),
        (
            &["replay", "--scenario", "paper", "--psf", "box:2"],
            &["box:2", "gaussian:SIGMA"],
        ),
        (
            &["replay", "some-dir", "--response", "gamma:2.2"],
            &["--response", "--scenario only"],
        ),
        (
            &["replay", "--scenario", "paper", "--response", "gamma:2.2"],
            &["--response", "--renderer warp"],
        ),
        (
            &[
                "replay",
                "--scenario",
                "paper",
                "--renderer",
                "warp",
                "--response",
                "gamma:2.2,jpeg:101",
            ],
            &["jpeg:101", "whole 1 to 100"],
        ),
        (
            &["replay", "some-dir", "--pad-velocity", "1,0"],
            &["--pad-velocity", "--scenario only"],
        ),
        (
            &["replay", "--scenario", "paper", "--pad-velocity", "1"],
            &["`1`", "N,E"],
        ),
        (
            &["replay", "--scenario", "paper", "--deck-roll", "60@5"],
            &["capsizing"],
        ),
    ];
    for (args, needles) in cases {
        assert_fails_with_one_line(&touchdown(args), needles);
    }
}

/// The summary row starting with `row`: one cell per method.
fn summary_cells(stdout: &str, row: &str) -> Vec<String> {
    let line = stdout
        .lines()
        .find(|l| l.starts_with(row))
        .unwrap_or_else(|| panic!("no summary row `{row}` in:\n{stdout}"));
    line.split('|')
        .skip(1)
        .map(|c| c.trim().to_string())
        .collect()
}

/// `value` as the tables print it, with `decimals` decimals.
fn printed(value: &serde_json::Value, decimals: usize) -> String {
    let v = value
        .as_f64()
        .unwrap_or_else(|| panic!("not a number: {value}"));
    format!("{v:.decimals$}")
}

#[test]
fn json_has_every_table_and_the_numbers_of_the_text() {
    let frames = FRAMES.to_string();
    let args = [
        "replay",
        "--scenario",
        "paper",
        "--frames",
        &frames,
        "--pose-steps",
    ];
    let text_run = touchdown(&[&args[..], &["--no-plots"]].concat());
    assert!(text_run.status.success(), "{}", text(&text_run.stderr));
    let plots = scratch("json-figures");
    let json_run = touchdown(&[&args[..], &["--json", "--plots", path_str(&plots)]].concat());
    assert!(json_run.status.success(), "{}", text(&json_run.stderr));
    let (stdout, json_stdout) = (text(&text_run.stdout), text(&json_run.stdout));
    assert_eq!(
        json_stdout.lines().count(),
        1,
        "only the JSON: {json_stdout}"
    );
    let doc: serde_json::Value = serde_json::from_str(&json_stdout).expect("valid JSON");
    for key in ["setup", "set_points", "summary", "altitudes", "figures"] {
        assert!(doc.get(key).is_some(), "no `{key}` in {doc}");
    }

    let setup = &doc["setup"];
    assert_eq!(setup["input"]["kind"], "scenario");
    assert_eq!(setup["input"]["scenario"], "paper");
    assert_eq!(setup["input"]["seed"], 1);
    assert_eq!(setup["frames"], FRAMES);
    assert_eq!(setup["camera"]["width"], 640);
    assert_eq!(setup["pad"]["markers"][0]["family"], "aruco_6x6_250");
    // The variant columns keep their order; the pattern fit's is last.
    let methods = setup["methods"].as_array().expect("methods");
    let names: Vec<&str> = methods.iter().filter_map(|m| m["name"].as_str()).collect();
    assert_eq!(
        names,
        [
            "paper's method",
            "ours",
            "no level fix",
            "no flip choice",
            "neither step",
            "no pattern fit",
            "no shutter correction",
            "no second look"
        ]
    );
    assert!(methods.iter().all(|m| m["attitude_given"] == true));
    let fits: Vec<bool> = methods[1..]
        .iter()
        .map(|m| m["settings"]["detector"]["fit_small_markers"] == true)
        .collect();
    assert_eq!(fits, [true, true, true, true, false, true, true]);
    let shutter: Vec<bool> = methods[1..]
        .iter()
        .map(|m| m["settings"]["correct_rolling_shutter"] == true)
        .collect();
    assert_eq!(shutter, [true, true, true, true, true, false, true]);
    let second_look: Vec<bool> = methods[1..]
        .iter()
        .map(|m| m["settings"]["look_again"] == true)
        .collect();
    assert_eq!(second_look, [true, true, true, true, true, true, false]);

    // The summary: the same numbers as the text's, per method, in the same order.
    let summary = doc["summary"]["methods"].as_array().expect("summary");
    assert_eq!(summary.len(), names.len());
    let detected = summary_cells(&stdout, "frames with a pose");
    let rms = summary_cells(&stdout, "RMS error x / y / z, cm (filtered)");
    let raw = summary_cells(&stdout, "RMS error x / y / z, cm (raw pose)");
    for (k, m) in summary.iter().enumerate() {
        assert_eq!(m["name"], names[k]);
        let rate = 100.0 * m["detection_rate"].as_f64().expect("rate");
        assert_eq!(detected[k], format!("{} ({rate:.1} %)", m["detected"]));
        let xyz = |v: &serde_json::Value| {
            format!(
                "{} / {} / {}",
                printed(&v["x"], 2),
                printed(&v["y"], 2),
                printed(&v["z"], 2)
            )
        };
        assert_eq!(rms[k], xyz(&m["rms_error_cm"]), "{}", names[k]);
        assert_eq!(raw[k], xyz(&m["raw_rms_error_cm"]), "{}", names[k]);
    }

    // The set-point table's row for the 5 m hover, ours.
    let row = &doc["set_points"][0];
    assert_eq!((&row["label"], &row["axis"]), (&"z=5".into(), &"z".into()));
    assert_eq!(row["reference_cm"], 500.0);
    assert_eq!(row["published"]["estimate_cm"], 502.0);
    let ours = &row["methods"][1]["on_axis"];
    let cells = row_cells(&stdout, "Z   500");
    assert_eq!(cells[3][0], printed(&ours["mean_estimate_cm"], 1));
    assert_eq!(cells[3][3], printed(&ours["rms_error_cm"], 2));

    // --json with --plots still writes the figures, and says where.
    assert_eq!(doc["figures"]["files"], 12);
    assert!(plots.join("error-z.svg").is_file());
}

#[test]
fn json_alone_writes_no_figures() {
    let cwd = scratch("json-no-figures");
    std::fs::create_dir_all(&cwd).expect("scratch dir");
    let output = Command::new(env!("CARGO_BIN_EXE_touchdown"))
        .args(["replay", "--scenario", "paper", "--frames", "3", "--json"])
        .current_dir(&cwd)
        .output()
        .expect("the touchdown binary runs");
    assert!(output.status.success(), "{}", text(&output.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&output.stdout).expect("valid JSON");
    assert!(doc["figures"].is_null(), "{doc}");
    let entries = std::fs::read_dir(&cwd).expect("read scratch").count();
    assert_eq!(
        entries, 0,
        "--json without --plots wrote into the current directory"
    );
}

#[test]
fn help_explains_inputs_methods_tables_and_figures() {
    let output = touchdown(&["replay", "--help"]);
    assert_eq!(output.status.code(), Some(0));
    let help = text(&output.stdout);
    for needle in [
        "RECORDING",
        "--scenario",
        "setpoints.csv",
        "Table 1",
        "truth - estimate",
        "longest gap",
        "lag",
        "--plots",
        "--no-plots",
        "--json",
        "no pattern fit",
        "position-x",
        "Exit status",
    ] {
        assert!(help.contains(needle), "replay --help lacks `{needle}`");
    }
    let top = text(&touchdown(&["--help"]).stdout);
    assert!(top.contains("replay"), "{top}");
}

/// `summary.methods[m].flight[kind]` of a `--json` run.
fn flight_summary<'a>(doc: &'a serde_json::Value, m: usize, kind: &str) -> &'a serde_json::Value {
    &doc["summary"]["methods"][m]["flight"][kind]
}

fn json_run(args: &[&str]) -> serde_json::Value {
    let output = touchdown(&[&["replay", "--json"][..], args].concat());
    assert!(output.status.success(), "{}", text(&output.stderr));
    serde_json::from_slice(&output.stdout).expect("valid JSON")
}

fn horizontal(doc: &serde_json::Value, m: usize, kind: &str) -> f64 {
    flight_summary(doc, m, kind)["mean_horizontal_cm"]
        .as_f64()
        .unwrap_or_else(|| panic!("no {kind} of method {m}: {doc}"))
}

#[test]
fn in_flight_the_three_errors_are_side_by_side() {
    let frames = FRAMES.to_string();
    let base = ["--scenario", "paper", "--frames", &frames];
    let doc = json_run(&base);
    // The error model: every term with its value and unit, the flight effects, the mount.
    let model = &doc["error_model"];
    assert_eq!(model["autopilot"], "ardupilot");
    assert_eq!(model["terms"]["plnd_lag"]["value"], 0.02);
    assert_eq!(model["terms"]["plnd_lag"]["unit"], "s");
    assert_eq!(model["terms"]["baud"]["value"], 921600.0);
    assert_eq!(model["terms"].as_object().map(|t| t.len()), Some(13));
    assert_eq!(model["flight_effects"]["readout_ms"], 30.5);
    // The paper scenario's mount is known to the board (as the paper's was).
    assert_eq!(model["mount_known"], true);
    for m in [0, 1] {
        for kind in ["sent", "reconstructed", "ideal"] {
            let frames = flight_summary(&doc, m, kind)["frames"]
                .as_u64()
                .unwrap_or(0);
            assert!(frames >= 5, "method {m} {kind}: {frames} frames\n{doc}");
        }
    }
    // At 5 m the autopilot's own errors (0.3 deg of tilt bias, 0.5 deg of heading over a
    // small offset, the 20 ms of delay on a slow hover wobble) are a few centimetres; the
    // ideal sensor's reconstruction has exactly those.
    let (a, b, c) = (
        horizontal(&doc, 1, "sent"),
        horizontal(&doc, 1, "reconstructed"),
        horizontal(&doc, 1, "ideal"),
    );
    assert!(a < 1.0, "(a) {a} cm");
    assert!(c > 0.3 && c < 6.0, "(c) {c} cm");
    assert!((b - c).abs() < 1.5, "(b) {b} cm, (c) {c} cm");

    // The ideal autopilot: (b) is (a) and (c) is nothing.
    let ideal = json_run(&[&base[..], &["--ideal"]].concat());
    let (a, b, c) = (
        horizontal(&ideal, 1, "sent"),
        horizontal(&ideal, 1, "reconstructed"),
        horizontal(&ideal, 1, "ideal"),
    );
    assert!(c < 0.1, "ideal (c) {c} cm");
    assert!((b - a).abs() < 0.1, "ideal (a) {a} (b) {b} cm");
    assert_eq!(ideal["error_model"]["terms"]["tilt_bias"]["value"], 0.0);

    // One error source alone shows in (c): a 1 degree tilt bias at 5 m is about 9 cm.
    let tilt = json_run(&[&base[..], &["--ideal", "--tilt-bias-deg", "1"]].concat());
    let c = horizontal(&tilt, 1, "ideal");
    assert!(c > 1.0 && c < 20.0, "tilt bias alone: (c) {c} cm");
}

#[test]
fn px4_reconstructs_from_the_local_ned_point() {
    let frames = FRAMES.to_string();
    let doc = json_run(&[
        "--scenario",
        "paper",
        "--frames",
        &frames,
        "--autopilot",
        "px4",
        "--ideal",
    ]);
    assert_eq!(doc["error_model"]["autopilot"], "px4");
    let frames = flight_summary(&doc, 1, "reconstructed")["frames"]
        .as_u64()
        .unwrap_or(0);
    assert!(frames >= 5, "{doc}");
    let (a, b, c) = (
        horizontal(&doc, 1, "sent"),
        horizontal(&doc, 1, "reconstructed"),
        horizontal(&doc, 1, "ideal"),
    );
    assert!(c < 0.2, "PX4 ideal (c) {c} cm");
    assert!((b - a).abs() < 0.2, "PX4 (a) {a} (b) {b} cm");
    // With the position drift alone, what PX4 reconstructs relative to itself hardly moves:
    // the drift is in both its own position and the point we computed from it.
    let drift = json_run(&[
        "--scenario",
        "paper",
        "--frames",
        "6",
        "--autopilot",
        "px4",
        "--ideal",
        "--position-drift-m",
        "2",
    ]);
    let c = horizontal(&drift, 1, "ideal");
    assert!(c < 0.5, "PX4 drift alone: (c) {c} cm");
}

#[test]
fn flight_flags_are_checked() {
    let out = touchdown(&["replay", "--scenario", "paper", "--autopilot", "inav"]);
    assert_fails_with_one_line(&out, &["autopilot", "inav"]);
    let out = touchdown(&["replay", "--scenario", "paper", "--tilt-bias-deg", "-1"]);
    assert_fails_with_one_line(&out, &["--tilt-bias-deg", "negative"]);
    let out = touchdown(&["replay", path_str(recording()), "--readout-ms", "10"]);
    assert_fails_with_one_line(&out, &["--readout-ms", "--scenario"]);
    let help = text(&touchdown(&["replay", "--help"]).stdout);
    for needle in [
        "--autopilot",
        "PLND_LAG",
        "--ideal",
        "--mount-known",
        "--no-calibration",
        "(c) what it would reconstruct from an ideal sensor",
    ] {
        assert!(help.contains(needle), "replay --help lacks `{needle}`");
    }
}

/// `--calibration-hover` flies the set-up guide's hover through the board's companion first:
/// the mount it sets is what the next flight starts with, close to the scenario's true
/// misalignment (roll 1.2, pitch -1.6 deg) but measured, not copied (the hover's own attitude
/// bias is in it). A board that may not calibrate (`--no-calibration`) cannot be asked to.
#[test]
#[ignore = "long: in the long suite, `cargo test -- --ignored` (CI runs it)"]
fn calibration_hover_hands_the_mount_the_board_set_to_the_flight() {
    let out = touchdown(&[
        "replay",
        "--scenario",
        "landing",
        "--calibration-hover",
        "--frames",
        "2",
        "--json",
        "--no-plots",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let model = &doc["error_model"];
    let hover = &model["calibration_hover"];
    assert_eq!(hover["applied"], true, "{hover}");
    assert_eq!(hover["frames"], 300, "{hover}");
    let roll = hover["TD_CAM_ROLL"].as_f64().expect("roll");
    let pitch = hover["TD_CAM_PITCH"].as_f64().expect("pitch");
    assert!((roll - 1.2).abs() < 0.3, "roll {roll}");
    assert!((pitch + 1.6).abs() < 0.3, "pitch {pitch}");
    assert!(
        roll != 1.2 && pitch != -1.6,
        "copied from the truth: {roll} {pitch}"
    );
    let params = model["board_params"].as_array().expect("board_params");
    let value = |name: &str| {
        params
            .iter()
            .find(|p| p["name"] == name)
            .and_then(|p| p["value"].as_f64())
    };
    assert_eq!(value("TD_CAM_ROLL"), Some(roll));
    assert_eq!(value("TD_CAM_PITCH"), Some(pitch));

    let refused = touchdown(&[
        "replay",
        "--scenario",
        "landing",
        "--calibration-hover",
        "--no-calibration",
    ]);
    assert_fails_with_one_line(&refused, &["--calibration-hover", "--no-calibration"]);
}

/// `--psf` reaches either model both ways: the paper's hover replayed in memory through a
/// defocus disc gives the tables of its recording simulated through it, and not the tables
/// of the scenario's own lens.
#[test]
fn a_psf_is_the_same_in_memory_and_on_disk() {
    for renderer in ["raster", "warp"] {
        let (disc, own, from_disk) = tables_in_memory_and_on_disk(
            &format!("paper-recording-disc-{renderer}"),
            &["--renderer", renderer, "--psf", "disc:2.5"],
            &["--renderer", renderer],
            |dir| {
                let toml =
                    std::fs::read_to_string(dir.join("simulation.toml")).expect("simulation.toml");
                assert!(
                    toml.contains("psf = \"[Disc { diameter_px: 2.5 }]\"")
                        && toml.contains(&format!("renderer = \"{renderer}\"")),
                    "{toml}"
                );
            },
        );
        assert!(!disc.is_empty());
        assert_eq!(disc, from_disk, "{renderer}");
        assert_ne!(disc, own, "{renderer}");
    }
}

/// `--response` reaches the warp model both ways, as `--psf` does: the paper's hover replayed
/// in memory through a gamma-encoded camera with JPEG gives the tables of its recording
/// simulated through them, which records them, and not the tables of a linear response.
#[test]
fn a_response_is_the_same_in_memory_and_on_disk() {
    let (encoded, own, from_disk) = tables_in_memory_and_on_disk(
        "paper-recording-response",
        &["--renderer", "warp", "--response", "gamma:2.2,jpeg:90"],
        &["--renderer", "warp"],
        |dir| {
            let toml =
                std::fs::read_to_string(dir.join("simulation.toml")).expect("simulation.toml");
            assert!(
                toml.contains("gamma: Some(2.2)") && toml.contains("jpeg: Some(90)"),
                "{toml}"
            );
        },
    );
    assert!(!encoded.is_empty());
    assert_eq!(encoded, from_disk);
    assert_ne!(encoded, own);
}

/// The far range's scale on more than one image model (issue 39): the paper's hovers at 30,
/// 40 and 50 m replayed on the ray-casting model and on the warp model, each through three
/// lenses (the scenario's, a defocus disc, a motion line), the warp model through others and
/// other cameras' responses too, and over the same marker printed on a margin a cell wider
/// than the detector knows of (the `margin` scenario: the ground's edge within a far
/// marker's blur). Wherever a hover has estimates, their mean is within 0.3 % of the range,
/// on every row; at 30 and 40 m each row gives a pose in at least the share of frames it
/// states. Not held yet, so not asserted (docs/accuracy.md, "Through other lenses"): a
/// gamma-encoded camera gives no pose at 50 m and 69 % of the 40 m frames; at 50 m the
/// Gaussian of 0.8 px keeps a quarter of the frames, the motion line and the raster model's
/// disc about two thirds; the wider margin behind a 0.8 px Gaussian, a 2 px disc or motion
/// line or a lens sharp in the middle reads some heights 0.4-1.3 % near, through a gamma
/// curve 0.8 % far.
#[test]
#[ignore = "long: in the long suite, `cargo test -- --ignored` (CI runs it)"]
fn the_far_range_scale_holds_within_0_3_percent_through_several_lenses() {
    // (name, scenario, arguments, least share of the 30 and 40 m frames with a pose)
    let models: [(&str, &str, &[&str], f64); 13] = [
        (
            "raster, the scenario's lens",
            "paper",
            &["--renderer", "raster"],
            0.9,
        ),
        (
            "raster, defocus disc 2 px",
            "paper",
            &["--renderer", "raster", "--psf", "disc:2"],
            0.9,
        ),
        (
            "raster, motion line 2 px at 30 deg",
            "paper",
            &["--renderer", "raster", "--psf", "motion:2@30"],
            0.9,
        ),
        (
            "warp, the scenario's lens",
            "paper",
            &["--renderer", "warp"],
            0.9,
        ),
        (
            "warp, defocus disc 2 px",
            "paper",
            &["--renderer", "warp", "--psf", "disc:2"],
            0.9,
        ),
        (
            "warp, motion line 2 px at 30 deg",
            "paper",
            &["--renderer", "warp", "--psf", "motion:2@30"],
            0.9,
        ),
        (
            "warp, Gaussian 0.8 px",
            "paper",
            &["--renderer", "warp", "--psf", "gaussian:0.8"],
            0.9,
        ),
        (
            "warp, Gaussian 0.5 px, unsharpened",
            "paper",
            &[
                "--renderer",
                "warp",
                "--psf",
                "gaussian:0.5",
                "--response",
                "sharpen:0",
            ],
            0.9,
        ),
        (
            "warp, a gamma-encoded camera (2.2)",
            "paper",
            &["--renderer", "warp", "--response", "gamma:2.2"],
            0.6,
        ),
        (
            "warp, JPEG at quality 90",
            "paper",
            &["--renderer", "warp", "--response", "jpeg:90"],
            0.9,
        ),
        (
            "raster, a margin a cell wider",
            "margin",
            &["--renderer", "raster"],
            0.9,
        ),
        (
            "warp, a margin a cell wider",
            "margin",
            &["--renderer", "warp"],
            0.9,
        ),
        (
            "warp, a margin a cell wider, JPEG at quality 90",
            "margin",
            &["--renderer", "warp", "--response", "jpeg:90"],
            0.9,
        ),
    ];
    let mut failures = Vec::new();
    for (name, scenario, args, min_detection) in models {
        let out = touchdown(
            &[
                &["replay", "--scenario", scenario, "--no-plots", "--json"][..],
                args,
            ]
            .concat(),
        );
        assert!(out.status.success(), "{name}: {}", text(&out.stderr));
        let doc: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
        far_rows_off(
            &doc,
            name,
            &[30.0, 40.0, 50.0],
            min_detection,
            &mut failures,
        );
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

/// Checks ours in a replay's `--json` `doc` at each of `heights_m`: wherever the hover has
/// estimates, their mean within 0.3 % of the range, and below 45 m a pose in at least
/// `min_detection` of its frames; each row is printed, and what is off is pushed to
/// `failures`, named `name`.
fn far_rows_off(
    doc: &serde_json::Value,
    name: &str,
    heights_m: &[f64],
    min_detection: f64,
    failures: &mut Vec<String>,
) {
    const MAX_SCALE_ERROR: f64 = 0.003;
    for &height_m in heights_m {
        let label = format!("z={height_m}");
        let ours = doc["set_points"]
            .as_array()
            .and_then(|rows| rows.iter().find(|r| r["label"] == label.as_str()))
            .and_then(|row| row["methods"].as_array())
            .and_then(|m| m.iter().find(|m| m["name"] == "ours"))
            .unwrap_or_else(|| panic!("{name}: no {label} row for ours"));
        let detection = ours["detection_rate"].as_f64().expect("detection rate");
        let error_cm = ours["on_axis"]["mean_error_cm"].as_f64();
        println!(
            "{name}, {height_m} m: pose in {:.0} % of frames, mean error {}",
            100.0 * detection,
            error_cm.map_or("-".into(), |e| format!("{e:+.2} cm"))
        );
        if let Some(e) = error_cm {
            if e.abs() / 100.0 > MAX_SCALE_ERROR * height_m {
                failures.push(format!("{name}, {height_m} m: {e:+.2} cm, over 0.3 %"));
            }
        }
        if height_m < 45.0 && detection < min_detection {
            failures.push(format!(
                "{name}, {height_m} m: a pose in {:.0} % of frames",
                100.0 * detection
            ));
        }
    }
}

/// The far range on imagery of a third image model, one written from the file formats alone
/// (`scripts/independent_render.py`: its own sampling, PSF, cluttered ground, noise and a
/// marker on a white margin of two cells, or of one): the paper's hovers at 20 to 50 m read
/// within 0.3 % of the range wherever there are estimates, with a pose in 90 % of the
/// frames up to 40 m. Skipped (printed) without python3, numpy, OpenCV or the shared
/// families.
#[test]
#[ignore = "long: in the long suite, `cargo test -- --ignored` (CI runs it)"]
fn the_far_range_holds_on_an_independent_renderers_imagery() {
    // The camera and pad files the renderer takes: the paper scenario's.
    let ours = scratch("independent-camera");
    let out = touchdown(&[
        "simulate",
        "--scenario",
        "paper",
        "--frames",
        "1",
        "--out",
        path_str(&ours),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let script =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scripts/independent_render.py");
    let mut failures = Vec::new();
    for (name, margin) in [("margin of two cells", "2"), ("margin of one cell", "1")] {
        let dir = scratch(&format!("independent-margin-{margin}"));
        let rendered = Command::new("python3")
            .arg(&script)
            .args(["--camera-from", path_str(&ours), "--out", path_str(&dir)])
            .args(["--heights", "20,30,40,50", "--frames-per-height", "8"])
            .args(["--seed", "1", "--margin-cells", margin])
            .output();
        match rendered {
            Ok(o) if o.status.success() => {}
            Ok(o) if o.status.code() == Some(3) => {
                println!("skipping: {}", text(&o.stderr).trim());
                return;
            }
            Ok(o) => panic!("{name}: the renderer failed: {}", text(&o.stderr)),
            Err(e) => {
                println!("skipping: python3 does not run ({e})");
                return;
            }
        }
        let out = touchdown(&["replay", path_str(&dir), "--no-plots", "--json"]);
        assert!(out.status.success(), "{name}: {}", text(&out.stderr));
        let doc: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
        far_rows_off(&doc, name, &[20.0, 30.0, 40.0, 50.0], 0.9, &mut failures);
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

/// A pad driving at 1 m/s under the landing scenario's flight (flown against the pad, carried
/// along): the board sees what it sees over a pad at rest, sends the same targets, and takes
/// the pad as moving within seconds of its track, from the pad's place on the ground (the
/// autopilot's position plus the level estimate); over the pad at rest it never does.
#[test]
fn a_pad_driving_under_the_flight_is_taken_as_moving_and_lands_the_same() {
    let base = [
        "replay",
        "--scenario",
        "landing",
        "--frames",
        "66",
        "--json",
    ];
    let run = |extra: &[&str]| {
        let output = touchdown(&[&base[..], extra].concat());
        assert!(output.status.success(), "{}", text(&output.stderr));
        let doc: serde_json::Value = serde_json::from_str(&text(&output.stdout)).expect("JSON");
        let ours = doc["summary"]["methods"]
            .as_array()
            .and_then(|m| m.iter().find(|m| m["name"] == "ours"))
            .cloned()
            .expect("our method");
        (
            ours["flight"]["pad_moving_from_frame"].as_u64(),
            ours["flight"]["sent"]["rms_error_cm"].clone(),
        )
    };
    let (at_rest_from, at_rest_rms) = run(&[]);
    let (moving_from, moving_rms) = run(&["--pad-velocity", "0.7,0.7"]);
    assert_eq!(at_rest_from, None, "a pad at rest taken as moving");
    let from = moving_from.expect("the moving pad never taken as moving");
    // 15 frames a second: the filter and the two-second hold after the track is confirmed.
    assert!(from <= 60, "taken as moving only after frame {from}");
    for axis in ["x", "y", "z"] {
        let (a, b) = (
            at_rest_rms[axis].as_f64().expect("RMS"),
            moving_rms[axis].as_f64().expect("RMS"),
        );
        assert!(
            (a - b).abs() <= 0.05 * a.max(1.0),
            "{axis}: {a} cm at rest, {b} cm moving"
        );
    }
}
