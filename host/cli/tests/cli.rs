//! `touchdown detect` as users and scripts see it: the built binary, its exit status, its
//! stderr lines and its JSON (the contract in `docs/interfaces.md`).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;
use touchdown_core::family::{tables, Family};
use touchdown_formats::image_io::{save_png, GrayFrame};
use touchdown_formats::pgm::save_pgm;

fn touchdown(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_touchdown"))
        .args(args)
        .output()
        .expect("the touchdown binary runs")
}

/// A fresh file path for one test (tests run in parallel, so names are per test).
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli-tests");
    std::fs::create_dir_all(&dir).expect("scratch directory");
    dir.join(name)
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn exit_code(output: &Output) -> Option<i32> {
    output.status.code()
}

/// Asserts exit status 2 and exactly one stderr line containing every `needle`.
fn assert_fails_with_one_line(output: &Output, needles: &[&str]) {
    let stderr = text(&output.stderr);
    assert_eq!(exit_code(output), Some(2), "stderr: {stderr}");
    assert_eq!(
        stderr.lines().count(),
        1,
        "expected one stderr line, got: {stderr}"
    );
    for needle in needles {
        assert!(stderr.contains(needle), "stderr lacks `{needle}`: {stderr}");
    }
}

fn path_str(path: &Path) -> &str {
    path.to_str().expect("scratch paths are UTF-8")
}

/// Parses stdout as JSON lines.
fn json_lines(output: &Output) -> Vec<Value> {
    text(&output.stdout)
        .lines()
        .map(|line| serde_json::from_str(line).unwrap_or_else(|e| panic!("not JSON ({e}): {line}")))
        .collect()
}

/// Checks the contract's keys (no more, no fewer) and value types of one image record.
fn assert_contract_shape(record: &Value) {
    let object = record.as_object().expect("a JSON object per image");
    let mut keys: Vec<&str> = object.keys().map(String::as_str).collect();
    keys.sort_unstable();
    assert_eq!(keys, ["detections", "height", "image", "time_ms", "width"]);
    assert!(record["image"].is_string());
    assert!(record["width"].is_u64() && record["height"].is_u64());
    assert!(record["time_ms"].as_f64().is_some_and(|t| t >= 0.0));
    for detection in record["detections"]
        .as_array()
        .expect("detections is an array")
    {
        let object = detection.as_object().expect("a detection is an object");
        let mut keys: Vec<&str> = object.keys().map(String::as_str).collect();
        keys.sort_unstable();
        assert_eq!(keys, ["corners", "family", "hamming", "id"]);
        assert!(detection["family"].is_string());
        assert!(detection["id"].is_u64() && detection["hamming"].is_u64());
        let corners = detection["corners"]
            .as_array()
            .expect("corners is an array");
        assert_eq!(corners.len(), 4);
        for corner in corners {
            let xy = corner.as_array().expect("a corner is [x, y]");
            assert!(xy.len() == 2 && xy.iter().all(Value::is_number));
        }
    }
}

#[test]
fn help_describes_defaults_corners_and_json() {
    let output = touchdown(&["--help"]);
    assert_eq!(exit_code(&output), Some(0));
    assert!(text(&output.stdout).contains("detect"));

    let output = touchdown(&["detect", "--help"]);
    assert_eq!(exit_code(&output), Some(0));
    let help = text(&output.stdout);
    for needle in [
        "tag36h11 and aruco_6x6_250",
        "top-left, top-right, bottom-right,",
        "centre of the top-left pixel",
        "--json",
        "\"time_ms\"",
        "\"corners\"",
        "--camera",
        "--tag-size",
        "--method",
    ] {
        assert!(
            help.contains(needle),
            "detect --help lacks `{needle}`:\n{help}"
        );
    }
}

#[test]
fn corrupt_image_exits_2_naming_the_file() {
    let path = scratch("corrupt.png");
    std::fs::write(&path, b"\x89PNG\r\n\x1a\n this is not really a PNG").expect("write");
    let output = touchdown(&["detect", path_str(&path)]);
    assert_fails_with_one_line(&output, &["corrupt.png"]);

    let path = scratch("garbage.jpg");
    std::fs::write(&path, b"garbage").expect("write");
    let output = touchdown(&["detect", "--json", path_str(&path)]);
    assert_fails_with_one_line(&output, &["garbage.jpg"]);
    assert!(output.stdout.is_empty());
}

#[test]
fn truncated_jpeg_exits_2_instead_of_reading_as_no_markers() {
    // Textured, so that most of the file is scan data and a third of it ends inside it.
    let (width, height) = (320u32, 240u32);
    let pixels: Vec<u8> = (0..width * height)
        .map(|i| ((i % width) * 7 + (i / width) * 13 + i.wrapping_mul(2_654_435_761) % 31) as u8)
        .collect();
    let whole = scratch("whole.jpg");
    image::save_buffer(&whole, &pixels, width, height, image::ExtendedColorType::L8)
        .expect("write");
    let bytes = std::fs::read(&whole).expect("read");
    assert_eq!(
        exit_code(&touchdown(&["detect", path_str(&whole)])),
        Some(0)
    );
    let cut = scratch("first-third.jpg");
    std::fs::write(&cut, &bytes[..bytes.len() / 3]).expect("write");
    let output = touchdown(&["detect", path_str(&cut)]);
    assert_fails_with_one_line(&output, &["first-third.jpg", "truncated JPEG"]);
}

#[test]
fn oversized_image_exits_2_stating_the_limit() {
    let path = scratch("too-wide.png");
    image::save_buffer(&path, &[0u8; 9000], 9000, 1, image::ExtendedColorType::L8).expect("write");
    let output = touchdown(&["detect", path_str(&path)]);
    assert_fails_with_one_line(&output, &["too-wide.png", "9000x1", "8192x8192"]);
}

#[test]
fn usage_errors_are_one_line() {
    let output = touchdown(&["detect", "--tag-size", "-1", "a.png"]);
    assert_fails_with_one_line(&output, &["--tag-size", "positive"]);
    assert!(!text(&output.stderr).contains("-- -1"));
    let output = touchdown(&["detect", "--bogus", "a.png"]);
    assert_fails_with_one_line(&output, &["--bogus"]);
    let output = touchdown(&["frobnicate"]);
    assert_fails_with_one_line(&output, &["frobnicate"]);
}

#[test]
fn camera_file_without_fy_names_the_key_not_line_1() {
    let camera = scratch("no-fy.toml");
    std::fs::write(
        &camera,
        "width = 640\nheight = 480\nfx = 554.3\ncx = 319.5\ncy = 239.5\n",
    )
    .expect("write");
    let image = scratch("no-fy.pgm");
    save_pgm(&image, &GrayFrame::filled(16, 16, 255)).expect("write");
    let output = touchdown(&[
        "detect",
        "--camera",
        path_str(&camera),
        "--tag-size",
        "0.2",
        path_str(&image),
    ]);
    assert_fails_with_one_line(&output, &["no-fy.toml", "missing key `fy`"]);
    assert!(!text(&output.stderr).contains("line 1"));
}

#[test]
fn missing_image_exits_2() {
    let path = scratch("does-not-exist.png");
    let output = touchdown(&["detect", path_str(&path)]);
    assert_fails_with_one_line(&output, &["does-not-exist.png"]);
}

#[test]
fn readable_images_are_still_reported_when_one_fails() {
    let good = scratch("partly-good.pgm");
    save_pgm(&good, &GrayFrame::filled(32, 24, 200)).expect("write");
    let bad = scratch("partly-bad.pgm");
    std::fs::write(&bad, b"P5\n32 24\n255\n short").expect("write");
    let output = touchdown(&["detect", "--json", path_str(&good), path_str(&bad)]);
    assert_fails_with_one_line(&output, &["partly-bad.pgm"]);
    let records = json_lines(&output);
    assert_eq!(records.len(), 1);
    assert_eq!(records[0]["image"], path_str(&good));
}

#[test]
fn unknown_family_exits_2_listing_the_names() {
    let output = touchdown(&["detect", "--family", "tag99h99", "whatever.png"]);
    let mut needles = vec!["tag99h99"];
    needles.extend(tables::names());
    assert_fails_with_one_line(&output, &needles);
}

#[test]
fn bad_family_file_exits_2_with_its_line() {
    let family = scratch("bad-family.txt");
    std::fs::write(&family, "# family broken\n# cells 8\n\n1111111110000001\n").expect("write");
    let image = scratch("bad-family.pgm");
    save_pgm(&image, &GrayFrame::filled(16, 16, 255)).expect("write");
    let output = touchdown(&["detect", "--family", path_str(&family), path_str(&image)]);
    assert_fails_with_one_line(&output, &["bad-family.txt", "line 4"]);

    std::fs::write(&family, "00000000\n0x000000\n").expect("write");
    let output = touchdown(&["detect", "--family", path_str(&family), path_str(&image)]);
    assert_fails_with_one_line(&output, &["bad-family.txt: line 1"]);

    // One all-black 8x8 code: not "two codes are equal" (there is one), but why it can't work.
    std::fs::write(&family, format!("# cells 8\n{}\n", "0".repeat(64))).expect("write");
    let output = touchdown(&["detect", "--family", path_str(&family), path_str(&image)]);
    assert_fails_with_one_line(&output, &["bad-family.txt: line 2", "orientation"]);
    assert!(!text(&output.stderr).contains("two codes"));
}

#[test]
fn too_many_families_exit_2() {
    let names = [
        "tag16h5",
        "tag25h9",
        "tag36h10",
        "tag36h11",
        "aruco_4x4_50",
        "aruco_5x5_50",
        "aruco_6x6_50",
        "aruco_7x7_50",
        "aruco_original",
    ];
    let mut args = vec!["detect"];
    for name in &names {
        args.extend(["--family", name]);
    }
    args.push("whatever.png");
    assert_fails_with_one_line(&touchdown(&args), &["at most 8"]);
}

#[test]
fn blank_pgm_gives_an_empty_json_record() {
    let path = scratch("blank.pgm");
    save_pgm(&path, &GrayFrame::filled(97, 61, 255)).expect("write");
    let output = touchdown(&["detect", "--json", path_str(&path)]);
    assert_eq!(exit_code(&output), Some(0), "{}", text(&output.stderr));
    let records = json_lines(&output);
    assert_eq!(records.len(), 1);
    assert_contract_shape(&records[0]);
    assert_eq!(records[0]["image"], path_str(&path));
    assert_eq!(
        (records[0]["width"].as_u64(), records[0]["height"].as_u64()),
        (Some(97), Some(61))
    );
    assert_eq!(records[0]["detections"].as_array().map(Vec::len), Some(0));

    // Text mode: a line for the image and the summary.
    let output = touchdown(&["detect", path_str(&path), path_str(&path)]);
    assert_eq!(exit_code(&output), Some(0));
    let stdout = text(&output.stdout);
    assert!(stdout.contains("blank.pgm: no markers (97x61"), "{stdout}");
    assert!(
        stdout
            .lines()
            .last()
            .is_some_and(|l| l.starts_with("2 images, 0 markers found")),
        "{stdout}"
    );
}

/// `--draw` writes the image with the marker outlined: green on the outline, the first corner
/// red, the rest the image's grey; `--draw-scale 2` halves it; two images are refused.
#[test]
fn draw_outlines_the_markers_found() {
    let (frame, corners) = draw_marker(&tables::TAG36H11, 7);
    let image = scratch("draw-marker.png");
    save_png(&image, &frame).expect("write");
    let out = scratch("draw-marker-outlined.png");
    let output = touchdown(&["detect", "--draw", path_str(&out), path_str(&image)]);
    assert_eq!(exit_code(&output), Some(0), "{}", text(&output.stderr));
    let drawn = image::open(&out).expect("a PNG").to_rgb8();
    assert_eq!(
        (drawn.width() as usize, drawn.height() as usize),
        (frame.width, frame.height)
    );
    let [first, second, ..] = corners;
    let middle_of_top = [(first[0] + second[0]) / 2.0, first[1]];
    let at = |p: [f32; 2]| drawn.get_pixel(p[0].round() as u32, p[1].round() as u32).0;
    assert_eq!(at(middle_of_top), [0, 220, 0]);
    assert_eq!(at(first), [230, 0, 0]);
    assert_eq!(drawn.get_pixel(2, 2).0, [255, 255, 255]);

    let half = scratch("draw-marker-half.png");
    let output = touchdown(&[
        "detect",
        "--draw",
        path_str(&half),
        "--draw-scale",
        "2",
        path_str(&image),
    ]);
    assert_eq!(exit_code(&output), Some(0), "{}", text(&output.stderr));
    let (w, h) = image::image_dimensions(&half).expect("a PNG");
    assert_eq!(
        (w as usize, h as usize),
        (frame.width / 2, frame.height / 2)
    );

    let output = touchdown(&[
        "detect",
        "--draw",
        path_str(&out),
        path_str(&image),
        path_str(&image),
    ]);
    assert_fails_with_one_line(&output, &["--draw", "one IMAGE"]);
}

#[test]
fn family_file_is_accepted() {
    let family = scratch("one_marker.txt");
    std::fs::write(&family, format!("{CUSTOM_8X8}\n")).expect("write");
    let image = scratch("family-file-blank.png");
    save_png(&image, &GrayFrame::filled(40, 30, 128)).expect("write");
    let output = touchdown(&[
        "detect",
        "--json",
        "--family",
        path_str(&family),
        "--family",
        "TAG36H11",
        path_str(&image),
    ]);
    assert_eq!(exit_code(&output), Some(0), "{}", text(&output.stderr));
    assert_contract_shape(&json_lines(&output)[0]);
}

/// `detect --camera` hands the camera to the detector, as the board's per-frame path does: a
/// 250-pixel marker under a wide-angle lens (k1 = -0.35), whose edges the lens bows by
/// pixels, rendered by the simulator. Its corners come out within a fraction of a pixel of
/// the truth with the camera, pixels off without it.
#[test]
fn detect_with_a_distorting_camera_fits_through_the_lens() {
    use touchdown_formats::pad::{MarkerConfig, PadConfig};
    use touchdown_sim::camera::SimCamera;
    use touchdown_sim::pad::PrintedPad;
    use touchdown_sim::scenario::{FramePlan, Scenario};
    use touchdown_sim::trajectory::{Profile, Segment, Trajectory, Wobble};
    use touchdown_sim::Simulator;

    let mut scenario = Scenario::named("paper", 7).expect("the paper scenario");
    scenario.camera = SimCamera::with_fov(640, 480, 70.0, [-0.35, 0.35 / 3.0, 0.0, 0.0, 0.0]);
    scenario.trajectory = Trajectory {
        segments: vec![Segment {
            t0: 0.0,
            t1: 1.0,
            from: [0.0, 0.0, 1.0],
            to: [0.0, 0.0, 1.0],
            profile: Profile::Hold,
        }],
        yaw: 0.0,
        wobble: Wobble::none(),
        tilt_with_acceleration: false,
        trim: (0.05, -0.03),
    };
    scenario.exposure_time_s = 0.0;
    scenario.frames = vec![FramePlan {
        t_us: 0,
        label: None,
    }];
    let mut sim = Simulator::new(scenario);
    let model = sim.scenario.camera.model;
    let pose = sim.camera_pose(0.0);
    let pad_of = |size: f64| {
        PrintedPad::from_config(&PadConfig {
            name: "lens".to_string(),
            markers: vec![MarkerConfig {
                family: "aruco_6x6_250".to_string(),
                id: 42,
                size,
                x: 0.0,
                y: 0.0,
                yaw_deg: 17.0,
            }],
        })
        .expect("a one-marker pad")
    };
    let corners_of = |pad: &PrintedPad| {
        pad.markers[0].corners().map(|p| {
            sim.scenario
                .camera
                .project(pose.to_camera(p))
                .expect("in front of the camera")
        })
    };
    // The lens shrinks the marker: its printed size is scaled until it is 250 px across.
    let mut size = 250.0 / f64::from(model.fx);
    for _ in 0..3 {
        let c = corners_of(&pad_of(size));
        let edge = (0..4)
            .map(|k| {
                let (a, b) = (c[k], c[(k + 1) % 4]);
                (a[0] - b[0]).hypot(a[1] - b[1])
            })
            .sum::<f64>()
            / 4.0;
        size *= 250.0 / edge;
    }
    let pad = pad_of(size);
    let truth = corners_of(&pad);
    sim.world.pad = pad;
    let frame = sim.render(0).expect("one frame").image;
    let image = scratch("lens-marker.png");
    save_png(&image, &frame).expect("write");
    let camera = scratch("lens-camera.toml");
    let d = model.distortion;
    std::fs::write(
        &camera,
        format!(
            "width = 640\nheight = 480\nfx = {}\nfy = {}\ncx = {}\ncy = {}\ndistortion = [{}, {}, {}, {}, {}]\n",
            model.fx, model.fy, model.cx, model.cy, d[0], d[1], d[2], d[3], d[4]
        ),
    )
    .expect("write");
    let corner_error = |extra: &[&str]| -> f64 {
        let mut args = vec!["detect", "--json", "--family", "aruco_6x6_250"];
        args.extend_from_slice(extra);
        args.push(path_str(&image));
        let output = touchdown(&args);
        assert_eq!(exit_code(&output), Some(0), "{}", text(&output.stderr));
        let json = &json_lines(&output)[0];
        let detections = json["detections"].as_array().expect("detections");
        assert_eq!(detections.len(), 1, "{json}");
        assert_eq!(detections[0]["id"], 42);
        // No size was given, so no pose: the camera alone is the detector's lens.
        assert!(detections[0].get("pose").is_none(), "{json}");
        let corners = detections[0]["corners"].as_array().expect("corners");
        corners
            .iter()
            .zip(&truth)
            .map(|(c, t)| {
                let (x, y) = (c[0].as_f64().expect("x"), c[1].as_f64().expect("y"));
                (x - t[0]).hypot(y - t[1])
            })
            .fold(0.0, f64::max)
    };
    let with_camera = corner_error(&["--camera", path_str(&camera)]);
    let without = corner_error(&[]);
    println!("corner error with the camera {with_camera:.3} px, without {without:.3} px");
    assert!(
        with_camera < 0.3,
        "with the camera: corners {with_camera} px off"
    );
    assert!(
        without > 1.5,
        "without the camera: corners {without} px off"
    );
}

#[test]
fn camera_options_are_checked_and_give_the_pose() {
    let image = scratch("camera-blank.pgm");
    save_pgm(&image, &GrayFrame::filled(16, 16, 255)).expect("write");
    let camera = scratch("CAMERA.toml");
    std::fs::write(
        &camera,
        "width = 640\nheight = 480\nfx = 554.3\nfy = \"x\"\ncx = 319.5\ncy = 239.5\n",
    )
    .expect("write");
    let output = touchdown(&[
        "detect",
        "--camera",
        path_str(&camera),
        "--tag-size",
        "0.2",
        path_str(&image),
    ]);
    assert_fails_with_one_line(&output, &["CAMERA.toml: line 4"]);

    std::fs::write(&camera, "width = 640\nheight = 480\nfx = 554.3\nfy = 554.3\ncx = 319.5\ncy = 239.5\ndistortion = [0.1, 0.0, 0.0, 0.0, 0.0]\n")
        .expect("write");
    let output = touchdown(&[
        "detect",
        "--camera",
        path_str(&camera),
        "--tag-size",
        "0.2",
        path_str(&image),
    ]);
    assert_eq!(
        exit_code(&output),
        Some(0),
        "a valid camera file is accepted"
    );

    // A marker seen straight on: 100 px across at focal length 640 px, so a 0.2 m marker is
    // 1.28 m away along the optical axis, in front of the image centre.
    let rendered = touchdown_sim::render::render_marker(
        tables::by_name("tag36h11").expect("shipped"),
        3,
        &touchdown_sim::render::Placement::new(319.5, 239.5, 100.0),
        &touchdown_sim::render::FrameOptions::sized(640, 480),
    )
    .expect("render");
    let marker = scratch("camera-marker.png");
    save_png(&marker, &rendered.0).expect("write");
    std::fs::write(
        &camera,
        "width = 640\nheight = 480\nfx = 640.0\nfy = 640.0\ncx = 319.5\ncy = 239.5\n",
    )
    .expect("write");
    let output = touchdown(&[
        "detect",
        "--json",
        "--family",
        "tag36h11",
        "--camera",
        path_str(&camera),
        "--tag-size",
        "0.2",
        path_str(&marker),
    ]);
    assert_eq!(exit_code(&output), Some(0));
    let json: Value = serde_json::from_slice(&output.stdout).expect("one JSON line");
    let pose = &json["detections"][0]["pose"];
    let t: Vec<f64> = pose["t"]
        .as_array()
        .expect("t")
        .iter()
        .filter_map(Value::as_f64)
        .collect();
    assert_eq!(t.len(), 3);
    assert!(t[0].abs() < 0.01 && t[1].abs() < 0.01, "centred: {t:?}");
    assert!((t[2] - 1.28).abs() < 0.01, "distance: {t:?}");
    assert_eq!(pose["R"].as_array().map(Vec::len), Some(9));
    assert!(
        pose["reprojection_px"].as_f64().is_some_and(|e| e < 0.5),
        "{pose}"
    );

    // The camera alone: the lens for the detector, no size, so no pose and no warning.
    let output = touchdown(&[
        "detect",
        "--json",
        "--camera",
        path_str(&camera),
        path_str(&marker),
    ]);
    assert_eq!(exit_code(&output), Some(0), "{}", text(&output.stderr));
    let json: Value = serde_json::from_slice(&output.stdout).expect("one JSON line");
    assert_eq!(json["detections"][0]["id"], 3, "{json}");
    assert!(json["detections"][0].get("pose").is_none(), "{json}");
    assert!(output.stderr.is_empty(), "{}", text(&output.stderr));

    // --pad: each marker at its own size, the pad's families searched without --family
    // (aruco_4x4_50 is not among the defaults; tag36h11 is found only because the pad has
    // it). Marker 3 is 0.4 m on this pad, so twice as far as at 0.2 m; a marker not on the
    // pad gets no pose unless --tag-size sizes it.
    let pad = scratch("camera-pad.toml");
    let pad_with = |id: u16| {
        std::fs::write(
            &pad,
            format!(
                "name = \"p\"\n[[marker]]\nfamily = \"aruco_4x4_50\"\nid = 1\nsize = 0.1\nx = 1.0\ny = 0.0\n[[marker]]\nfamily = \"TAG36H11\"\nid = {id}\nsize = 0.4\nx = 0.0\ny = 0.0\n"
            ),
        )
        .expect("write");
    };
    let distance = |extra: &[&str]| -> Option<f64> {
        let mut args = vec!["detect", "--json", "--camera", path_str(&camera), "--pad"];
        args.push(path_str(&pad));
        args.extend_from_slice(extra);
        args.push(path_str(&marker));
        let output = touchdown(&args);
        assert_eq!(exit_code(&output), Some(0), "{}", text(&output.stderr));
        assert!(output.stderr.is_empty(), "{}", text(&output.stderr));
        let json: Value = serde_json::from_slice(&output.stdout).expect("one JSON line");
        assert_eq!(json["detections"][0]["id"], 3, "{json}");
        json["detections"][0]["pose"]["t"][2].as_f64()
    };
    pad_with(3);
    let on_pad = distance(&[]).expect("a pose at the pad's size");
    assert!((on_pad - 2.56).abs() < 0.02, "distance {on_pad}");
    pad_with(4);
    assert_eq!(distance(&[]), None, "a marker the pad does not size");
    let sized = distance(&["--tag-size", "0.2"]).expect("a pose at --tag-size");
    assert!((sized - 1.28).abs() < 0.01, "distance {sized}");
    let output = touchdown(&[
        "detect",
        "--family",
        "aruco_4x4_50",
        "--camera",
        path_str(&camera),
        "--pad",
        path_str(&pad),
        path_str(&marker),
    ]);
    assert_eq!(exit_code(&output), Some(0));
    assert!(
        text(&output.stdout).contains("0 markers"),
        "--family wins over the pad's"
    );

    let output = touchdown(&["detect", "--tag-size", "0.2", path_str(&image)]);
    assert_fails_with_one_line(&output, &["--camera"]);
    let output = touchdown(&["detect", "--pad", path_str(&pad), path_str(&image)]);
    assert_fails_with_one_line(&output, &["--pad", "--camera"]);
    std::fs::write(
        &pad,
        "name = \"p\"\n[[marker]]\nfamily = \"tag36h11\"\nid = 1\nx = 0.0\ny = 0.0\n",
    )
    .expect("write");
    let output = touchdown(&[
        "detect",
        "--camera",
        path_str(&camera),
        "--pad",
        path_str(&pad),
        path_str(&image),
    ]);
    assert_fails_with_one_line(&output, &["size"]);
    // clap's own usage errors exit 2 as well.
    assert_eq!(
        exit_code(&touchdown(&[
            "detect",
            "--tag-size",
            "-3",
            path_str(&image)
        ])),
        Some(2)
    );
    assert_eq!(exit_code(&touchdown(&["detect"])), Some(2));
}

// --- Markers drawn cell by cell: need the detector. ---

/// A paper-style custom 8x8 marker: black ring 0 around 6x6 data cells, no quiet ring.
const CUSTOM_8X8: &str = "0000000001100110011111100100001001011010011001100100001000000000";

/// Pixels per cell of the drawn markers, and the white margin around the grid.
const CELL: usize = 10;
const MARGIN: usize = 60;

/// Draws code `id` of `family` axis-aligned, `CELL` pixels per cell, on a white canvas with
/// `MARGIN` pixels around the grid; returns the frame and the expected corners (outer black
/// border; the border edge between pixels `i - 1` and `i` lies at `i - 0.5`).
fn draw_marker(family: &Family<'_>, id: usize) -> (GrayFrame, [[f32; 2]; 4]) {
    let n = usize::from(family.grid);
    let side = n * CELL + 2 * MARGIN;
    let mut frame = GrayFrame::filled(side, side, 255);
    for row in 0..n {
        for col in 0..n {
            let white = family
                .cell_is_white(id, row, col)
                .expect("cell inside the grid");
            let level = if white { 255 } else { 0 };
            for y in MARGIN + row * CELL..MARGIN + (row + 1) * CELL {
                for x in MARGIN + col * CELL..MARGIN + (col + 1) * CELL {
                    frame.pixels[y * side + x] = level;
                }
            }
        }
    }
    let ring = usize::from(family.border_ring);
    let near = (MARGIN + ring * CELL) as f32 - 0.5;
    let far = (MARGIN + (n - ring) * CELL) as f32 - 0.5;
    (frame, [[near, near], [far, near], [far, far], [near, far]])
}

/// The frame turned a quarter clockwise, and where a point of the old frame lands.
fn rotate_clockwise(frame: &GrayFrame) -> GrayFrame {
    let (w, h) = (frame.width, frame.height);
    let mut out = GrayFrame::filled(h, w, 0);
    for y in 0..h {
        for x in 0..w {
            // (x, y) -> (h - 1 - y, x)
            out.pixels[x * h + (h - 1 - y)] = frame.pixels[y * w + x];
        }
    }
    out
}

fn rotate_point_clockwise(height: usize, [x, y]: [f32; 2]) -> [f32; 2] {
    [(height - 1) as f32 - y, x]
}

fn corners_of(detection: &Value) -> [[f32; 2]; 4] {
    let mut out = [[0.0f32; 2]; 4];
    for (k, slot) in out.iter_mut().enumerate() {
        for (axis, value) in slot.iter_mut().enumerate() {
            *value = detection["corners"][k][axis]
                .as_f64()
                .expect("corner coordinate") as f32;
        }
    }
    out
}

fn assert_corners_near(got: [[f32; 2]; 4], want: [[f32; 2]; 4], tolerance: f32) {
    for k in 0..4 {
        let error = ((got[k][0] - want[k][0]).powi(2) + (got[k][1] - want[k][1]).powi(2)).sqrt();
        assert!(
            error <= tolerance,
            "corner {k}: got {:?}, want {:?} (all: {got:?})",
            got[k],
            want[k]
        );
    }
}

/// Runs `touchdown detect --json` on one frame and returns its only detection.
fn detect_one(frame: &GrayFrame, file: &str, families: &[&str]) -> Value {
    let path = scratch(file);
    save_png(&path, frame).expect("write");
    let mut args = vec!["detect", "--json"];
    for family in families {
        args.extend(["--family", family]);
    }
    args.push(path_str(&path));
    let output = touchdown(&args);
    assert_eq!(exit_code(&output), Some(0), "{}", text(&output.stderr));
    let records = json_lines(&output);
    assert_eq!(records.len(), 1);
    assert_contract_shape(&records[0]);
    let detections = records[0]["detections"].as_array().expect("detections");
    assert_eq!(
        detections.len(),
        1,
        "expected one marker in {file}: {detections:?}"
    );
    detections[0].clone()
}

#[test]
fn drawn_markers_are_found_with_their_ids_and_corners() {
    for (family, id) in [(&tables::TAG36H11, 7usize), (&tables::ARUCO_6X6_250, 23)] {
        let (frame, corners) = draw_marker(family, id);
        let detection = detect_one(&frame, &format!("drawn-{}-{id}.png", family.name), &[]);
        assert_eq!(detection["family"], family.name);
        assert_eq!(detection["id"].as_u64(), Some(id as u64));
        assert_eq!(detection["hamming"].as_u64(), Some(0));
        assert_corners_near(corners_of(&detection), corners, 0.25);

        // Turned a quarter: the same id, and the corners follow the marker, not the image.
        let turned = rotate_clockwise(&frame);
        let detection = detect_one(
            &turned,
            &format!("drawn-{}-{id}-turned.png", family.name),
            &[],
        );
        assert_eq!(detection["id"].as_u64(), Some(id as u64));
        let want = corners.map(|p| rotate_point_clockwise(frame.height, p));
        assert_corners_near(corners_of(&detection), want, 0.25);
    }
}

#[test]
fn drawn_custom_marker_is_found_through_its_family_file() {
    let family_path = scratch("my_pad_marker.txt");
    std::fs::write(&family_path, format!("{CUSTOM_8X8}\n")).expect("write");
    let selected =
        touchdown_formats::families::resolve(path_str(&family_path)).expect("valid family file");
    let family = selected.family();
    let (frame, corners) = draw_marker(&family, 0);
    let detection = detect_one(&frame, "drawn-custom.png", &[path_str(&family_path)]);
    assert_eq!(detection["family"], "my_pad_marker");
    assert_eq!(detection["id"].as_u64(), Some(0));
    assert_corners_near(corners_of(&detection), corners, 0.25);
}
