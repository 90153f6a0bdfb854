//! The detector under strong barrel distortion, on stills rendered by our simulator
//! (`touchdown_sim::Simulator`, which runs the lens model backwards for every pixel): the
//! wide M12 lenses of the camera boards bend a marker's straight edges, most near the frame
//! border, where a marker is also cut short by the frame.
//!
//! The set: a 640x480 camera with a 70 degree (undistorted) horizontal field, radial
//! distortion k1 from -0.10 to -0.35 (k2 = -k1 / 3, which keeps the model invertible over the
//! whole frame, as a real calibration of such a lens is), one marker per frame on grass,
//! lying flat under a camera looking straight down from 1 m with a seeded tilt of up to 10
//! degrees, the board camera's blur and sensor noise. Markers from 15 to 300 pixels across
//! (as the lens shows them), each placed at the centre and at the border: the white
//! paper around it [`BORDER_GAP_PX`] inside one side (or a corner) of the frame, so its black
//! border is as close to the frame's edge as a marker that can be read gets. The families
//! alternate between aruco_6x6_250 and tag36h11.
//!
//! Asserted: with the camera model given to the detector, recall at least [`MIN_RECALL`]
//! over the set, and no detection that is not the rendered marker. Printed (run with
//! `--nocapture`): recall per k1 and size bin, with and without the camera.
//!
//! Also here, as the other end of "markers of every size": a marker 2,000 pixels across (a
//! pad's small marker filling a high-resolution frame at touchdown), which the contour
//! buffer of 4,096 points once missed silently ([`large_marker_is_found`]).
//!
//! Everything is seeded, so a failure reproduces with the case it prints.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use touchdown_core::camera::CameraModel;
use touchdown_core::detect::{Detection, Detector, DetectorConfig};
use touchdown_core::family::{tables, Family};
use touchdown_core::filter::VehicleState;
use touchdown_core::geometry::Point;
use touchdown_core::image::GrayImage;
use touchdown_core::params::PipelineSettings;
use touchdown_core::pipeline::{FramePipeline, PipelineConfig};
use touchdown_eval::workspace::HostWorkspace;
use touchdown_formats::pad::{MarkerConfig, PadConfig};
use touchdown_sim::camera::SimCamera;
use touchdown_sim::pad::PrintedPad;
use touchdown_sim::render::{render_markers, FrameOptions, MarkerPattern, Placement};
use touchdown_sim::scenario::{FramePlan, Scenario};
use touchdown_sim::sensor::{Optics, Sensor};
use touchdown_sim::texture::GroundKind;
use touchdown_sim::trajectory::{Profile, Segment, Trajectory, Wobble};
use touchdown_sim::Simulator;

/// The radial distortions of the set.
const K1: [f32; 5] = [-0.10, -0.18, -0.25, -0.30, -0.35];
/// Marker edges (black border, mean of the four sides as the lens shows them), pixels.
const SIZES_PX: [f64; 7] = [15.0, 25.0, 40.0, 70.0, 120.0, 200.0, 300.0];
/// Bins of the measured edge (mean of the four projected sides), pixels.
const BINS_PX: [f64; 6] = [0.0, 30.0, 60.0, 120.0, 200.0, f64::INFINITY];
/// Where a marker is placed: the centre, or against a side or corner of the frame (the
/// direction from the centre, image x right and y down).
const PLACES: [(&str, [f64; 2]); 5] = [
    ("centre", [0.0, 0.0]),
    ("left", [-1.0, 0.0]),
    ("right", [1.0, 0.0]),
    ("bottom", [0.0, 1.0]),
    ("corner", [1.0, 0.75]),
];
/// Gap between the marker's white paper and the frame's edge at the border, pixels.
const BORDER_GAP_PX: f64 = 1.0;
/// Rounds of scaling a marker's printed size to its nominal edge in the frame.
const SIZE_ITERATIONS: usize = 3;
/// Camera height above the pad, metres.
const ALTITUDE_M: f64 = 1.0;
/// Recall the set must reach with the camera given.
const MIN_RECALL: f64 = 0.98;
/// Frame size and field.
const WIDTH: u32 = 640;
const HEIGHT: u32 = 480;
const HFOV_DEG: f64 = 70.0;

/// One rendered case.
#[derive(Debug, Clone)]
struct Case {
    k1: f32,
    nominal_px: f64,
    place: &'static str,
    family: &'static str,
    id: u16,
    /// Mean projected edge, pixels.
    edge_px: f64,
    /// Projected outer corners of the black border (contract order).
    corners: [[f64; 2]; 4],
}

/// The outcome of one case for one detector.
#[derive(Debug, Clone, Copy, Default)]
struct Outcome {
    found: bool,
    wrong: usize,
    /// Largest distance of a found marker's corner from the truth, pixels.
    corner_error: Option<f64>,
}

fn lens(k1: f32) -> [f32; 5] {
    [k1, -k1 / 3.0, 0.0, 0.0, 0.0]
}

/// A still camera at [`ALTITUDE_M`] over the pad origin, tilted by `(roll, pitch)`.
fn hold(roll: f64, pitch: f64) -> Trajectory {
    Trajectory {
        segments: vec![Segment {
            t0: 0.0,
            t1: 1.0,
            from: [0.0, 0.0, ALTITUDE_M],
            to: [0.0, 0.0, ALTITUDE_M],
            profile: Profile::Hold,
        }],
        yaw: 0.0,
        wobble: Wobble::none(),
        tilt_with_acceleration: false,
        trim: (roll, pitch),
    }
}

fn scenario(k1: f32) -> Scenario {
    let mut s = Scenario::named("paper", 7).expect("the paper scenario");
    s.camera = SimCamera::with_fov(WIDTH, HEIGHT, HFOV_DEG, lens(k1));
    s.ground = GroundKind::Grass;
    s.optics = Optics {
        blur_sigma_px: 0.6,
        aperture_m: 0.0,
        ..Optics::board_camera()
    };
    s.sensor = Sensor::board_camera();
    s.exposure_time_s = 0.0;
    s.supersampling = 2;
    s.trajectory = hold(0.0, 0.0);
    s.frames = vec![FramePlan {
        t_us: 0,
        label: None,
    }];
    s
}

fn pad_of(family: &str, id: u16, size: f64, x: f64, y: f64, yaw_deg: f64) -> PrintedPad {
    PrintedPad::from_config(&PadConfig {
        name: "distortion".to_string(),
        markers: vec![MarkerConfig {
            family: family.to_string(),
            id,
            size,
            x,
            y,
            yaw_deg,
        }],
    })
    .expect("a one-marker pad")
}

/// Pixels of points along the outline of the marker's square at half-edge `half` (metres,
/// marker frame), `None` if one is behind the camera.
fn outline(sim: &Simulator, pad: &PrintedPad, half: f64) -> Option<Vec<[f64; 2]>> {
    let pose = sim.camera_pose(0.0);
    let m = &pad.markers[0];
    let mut out = Vec::new();
    const STEPS: usize = 24;
    for k in 0..4 {
        let (a, b) = [
            ((-half, half), (half, half)),
            ((half, half), (half, -half)),
            ((half, -half), (-half, -half)),
            ((-half, -half), (-half, half)),
        ][k];
        for j in 0..STEPS {
            let s = j as f64 / STEPS as f64;
            let [x, y] = m.to_pad(a.0 + s * (b.0 - a.0), a.1 + s * (b.1 - a.1));
            out.push(sim.scenario.camera.project(pose.to_camera([x, y, 0.0]))?);
        }
    }
    Some(out)
}

/// Smallest distance of an outline from the frame's edge (the frame spans -0.5 ..
/// width - 0.5), negative when it leaves the frame.
fn clearance(points: &[[f64; 2]]) -> f64 {
    let (w, h) = (f64::from(WIDTH) - 0.5, f64::from(HEIGHT) - 0.5);
    points
        .iter()
        .map(|[x, y]| (x + 0.5).min(y + 0.5).min(w - x).min(h - y))
        .fold(f64::INFINITY, f64::min)
}

/// The pad position (metres) of the marker's centre for a place: on the ray from the frame's
/// centre in direction `dir`, as far out as the white paper stays [`BORDER_GAP_PX`] inside
/// the frame (bisection), or `None` when the marker does not fit.
fn place_marker(
    sim: &Simulator,
    family: &str,
    id: u16,
    size: f64,
    yaw: f64,
    dir: [f64; 2],
) -> Option<(f64, f64)> {
    let at = |t: f64| (t * dir[0], -t * dir[1]);
    let fits = |t: f64| {
        let (x, y) = at(t);
        let pad = pad_of(family, id, size, x, y, yaw);
        let paper = pad.markers[0].paper_half();
        outline(sim, &pad, paper).map_or(-1.0, |o| clearance(&o))
    };
    if fits(0.0) < BORDER_GAP_PX {
        return None;
    }
    if dir == [0.0, 0.0] {
        return Some(at(0.0));
    }
    let (mut lo, mut hi) = (0.0, 0.0);
    let mut step = 0.02 * ALTITUDE_M;
    while fits(hi) >= BORDER_GAP_PX {
        lo = hi;
        hi += step;
        step *= 1.5;
        if hi > 5.0 * ALTITUDE_M {
            return None;
        }
    }
    for _ in 0..30 {
        let mid = 0.5 * (lo + hi);
        if fits(mid) >= BORDER_GAP_PX {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(at(lo))
}

/// The outer corners of the pad's marker in the frame and its mean edge, pixels.
fn project_corners(sim: &Simulator, pad: &PrintedPad) -> ([[f64; 2]; 4], f64) {
    let pose = sim.camera_pose(0.0);
    let c = pad.markers[0].corners();
    let corners = c.map(|p| {
        sim.scenario
            .camera
            .project(pose.to_camera(p))
            .expect("in front of the camera")
    });
    let edge_px = (0..4)
        .map(|k| {
            let (a, b) = (corners[k], corners[(k + 1) % 4]);
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
        })
        .sum::<f64>()
        / 4.0;
    (corners, edge_px)
}

fn families() -> [&'static Family<'static>; 2] {
    [
        tables::by_name("aruco_6x6_250").expect("aruco_6x6_250"),
        tables::by_name("tag36h11").expect("tag36h11"),
    ]
}

/// What the detections of `case`'s frame found.
fn score(detections: &[Detection], searched: &[&Family<'_>], case: &Case) -> Outcome {
    let mut outcome = Outcome::default();
    let centre = {
        let c = &case.corners;
        Point::new(
            (0.25 * (c[0][0] + c[1][0] + c[2][0] + c[3][0])) as f32,
            (0.25 * (c[0][1] + c[1][1] + c[2][1] + c[3][1])) as f32,
        )
    };
    for d in detections {
        let name = searched[d.family as usize].name;
        let near = d.center.distance(centre) <= (0.3 * case.edge_px).max(3.0) as f32;
        if name == case.family && d.id == case.id && near && !outcome.found {
            outcome.found = true;
            let error = d
                .corners
                .iter()
                .zip(&case.corners)
                .map(|(c, t)| (f64::from(c.x) - t[0]).hypot(f64::from(c.y) - t[1]))
                .fold(0.0, f64::max);
            outcome.corner_error = Some(error);
        } else {
            outcome.wrong += 1;
        }
    }
    outcome
}

/// The random draws of one case: the marker's id, its yaw (degrees) and the camera's tilt
/// (roll, pitch; radians).
type Draw = (u16, f64, (f64, f64));

/// Renders every case of the set and runs the detector with and without the camera. Each lens
/// on a thread of its own; the cases' random draws are made first, in the set's order, so the
/// set is the same on any number of threads.
fn run_set() -> Vec<(Case, Outcome, Outcome)> {
    let families = families();
    let mut rng = ChaCha8Rng::seed_from_u64(16);
    let draws: Vec<Vec<Draw>> = (0..K1.len())
        .map(|ki| {
            let mut lens_draws = Vec::new();
            for si in 0..SIZES_PX.len() {
                for pi in 0..PLACES.len() {
                    let family = families[(ki + si + pi) % families.len()];
                    let id = rng.random_range(0..family.codes.len().min(250)) as u16;
                    let yaw: f64 = rng.random_range(0.0..360.0);
                    let tilt = (
                        rng.random_range(-10.0f64..10.0).to_radians(),
                        rng.random_range(-10.0f64..10.0).to_radians(),
                    );
                    lens_draws.push((id, yaw, tilt));
                }
            }
            lens_draws
        })
        .collect();
    std::thread::scope(|scope| {
        let lenses: Vec<_> = draws
            .iter()
            .enumerate()
            .map(|(ki, lens_draws)| scope.spawn(move || run_lens(ki, lens_draws)))
            .collect();
        lenses
            .into_iter()
            .flat_map(|lens| lens.join().expect("a lens's cases"))
            .collect()
    })
}

/// The cases of lens `ki` of [`K1`], with their `draws` (see [`run_set`]).
fn run_lens(ki: usize, draws: &[Draw]) -> Vec<(Case, Outcome, Outcome)> {
    let families = families();
    let k1 = K1[ki];
    let mut workspace = HostWorkspace::new();
    let mut results = Vec::new();
    // One rendering thread: the lenses are the threads.
    let mut sim = Simulator::new(scenario(k1)).with_threads(1);
    let camera: CameraModel = sim.scenario.camera.model;
    let mut plain = Detector::new(DetectorConfig::default());
    let mut lensed = Detector::new(DetectorConfig::default());
    lensed.set_camera(Some(camera));
    let cases = SIZES_PX.iter().enumerate().flat_map(|(si, &nominal)| {
        PLACES
            .iter()
            .enumerate()
            .map(move |(pi, &p)| (si, nominal, pi, p))
    });
    for ((si, nominal, pi, (place, dir)), &(id, yaw, tilt)) in cases.zip(draws) {
        let family = families[(ki + si + pi) % families.len()];
        sim.scenario.trajectory = hold(tilt.0, tilt.1);
        // The lens shrinks a marker towards the border: its printed size is scaled
        // until its edge in the frame is the nominal one.
        let mut size = nominal / f64::from(camera.fx) * ALTITUDE_M;
        let mut placed = None;
        for _ in 0..SIZE_ITERATIONS {
            let Some((x, y)) = place_marker(&sim, family.name, id, size, yaw, dir) else {
                break;
            };
            let pad = pad_of(family.name, id, size, x, y, yaw);
            let (corners, edge_px) = project_corners(&sim, &pad);
            size *= nominal / edge_px;
            placed = Some((pad, corners, edge_px));
        }
        let Some((pad, corners, edge_px)) = placed else {
            continue;
        };
        sim.world.pad = pad;
        let frame = sim.render(0).expect("one frame").image;
        let image =
            GrayImage::new(&frame.pixels, frame.width, frame.height).expect("a valid frame");
        let case = Case {
            k1,
            nominal_px: nominal,
            place,
            family: family.name,
            id,
            edge_px,
            corners,
        };
        let searched = [family];
        let without = workspace
            .detect(&mut plain, &image, &searched)
            .expect("detects");
        let with = workspace
            .detect(&mut lensed, &image, &searched)
            .expect("detects");
        let a = score(&without, &searched, &case);
        let b = score(&with, &searched, &case);
        results.push((case, a, b));
    }
    results
}

fn bin_of(edge_px: f64) -> usize {
    BINS_PX
        .windows(2)
        .position(|w| edge_px >= w[0] && edge_px < w[1])
        .unwrap_or(0)
}

fn print_table(
    title: &str,
    results: &[(Case, Outcome, Outcome)],
    pick: fn(&(Case, Outcome, Outcome)) -> Outcome,
) {
    println!("{title}: found/markers per k1 (rows) and measured edge (columns)");
    let header: Vec<String> = BINS_PX
        .windows(2)
        .map(|w| {
            if w[1].is_finite() {
                format!("{}-{} px", w[0], w[1])
            } else {
                format!(">= {} px", w[0])
            }
        })
        .collect();
    println!(
        "  k1     | {} | all",
        header
            .iter()
            .map(|h| format!("{h:>11}"))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    for &k1 in &K1 {
        let mut cells = vec![(0usize, 0usize); BINS_PX.len() - 1];
        for r in results.iter().filter(|r| r.0.k1 == k1) {
            let cell = &mut cells[bin_of(r.0.edge_px)];
            cell.1 += 1;
            cell.0 += usize::from(pick(r).found);
        }
        let (f, n) = cells.iter().fold((0, 0), |a, c| (a.0 + c.0, a.1 + c.1));
        println!(
            "  {k1:>6.2} | {} | {f}/{n}",
            cells
                .iter()
                .map(|(f, n)| format!("{:>11}", format!("{f}/{n}")))
                .collect::<Vec<_>>()
                .join(" | ")
        );
    }
    let large: Vec<f64> = results
        .iter()
        .filter(|r| r.0.edge_px >= 60.0 && r.0.place != "centre")
        .filter_map(|r| pick(r).corner_error)
        .collect();
    let mean = large.iter().sum::<f64>() / large.len().max(1) as f64;
    let worst = large.iter().copied().fold(0.0, f64::max);
    println!(
        "  corner error of markers >= 60 px at the border: mean {mean:.2} px, max {worst:.2} px ({} markers)",
        large.len()
    );
    let by_bin: Vec<String> = BINS_PX
        .windows(2)
        .map(|w| {
            let errors: Vec<f64> = results
                .iter()
                .filter(|r| r.0.edge_px >= w[0] && r.0.edge_px < w[1] && r.0.place != "centre")
                .filter_map(|r| pick(r).corner_error)
                .collect();
            format!(
                "{:.2}",
                errors.iter().sum::<f64>() / errors.len().max(1) as f64
            )
        })
        .collect();
    println!(
        "  mean corner error at the border per measured edge (columns above), px: {}",
        by_bin.join(" | ")
    );
    for place in PLACES.iter().map(|p| p.0) {
        let of: Vec<_> = results.iter().filter(|r| r.0.place == place).collect();
        let found = of.iter().filter(|r| pick(r).found).count();
        println!("  {place:>7}: {found}/{}", of.len());
    }
}

#[test]
fn strong_barrel_distortion_recall() {
    let results = run_set();
    print_table("without the camera", &results, |r| r.1);
    print_table("with the camera", &results, |r| r.2);
    let total = results.len();
    let found = results.iter().filter(|r| r.2.found).count();
    let recall = found as f64 / total as f64;
    let missed: Vec<String> = results
        .iter()
        .filter(|r| !r.2.found)
        .map(|r| {
            format!(
                "  k1 {} {} {} id {} nominal {} px, edge {:.0} px, corners {:?}",
                r.0.k1, r.0.place, r.0.family, r.0.id, r.0.nominal_px, r.0.edge_px, r.0.corners
            )
        })
        .collect();
    println!("missed with the camera:\n{}", missed.join("\n"));
    let wrong: usize = results.iter().map(|r| r.1.wrong + r.2.wrong).sum();
    println!("recall with the camera {recall:.3} ({found}/{total}), wrong detections {wrong}");
    assert_eq!(wrong, 0, "wrong detections");
    assert!(total >= 140, "only {total} cases rendered");
    assert!(
        recall >= MIN_RECALL,
        "recall {recall:.3} below {MIN_RECALL}"
    );
}

/// A 2,000-pixel marker in a 2,600 x 2,600 frame (room for its white margin, a cell of 250
/// pixels), turned and tilted, through an ideal lens: found, corners within a pixel. Its boundary (about 8,000 steps) is twice the detector's
/// contour buffer, so it is fitted on every second pixel.
#[test]
fn large_marker_is_found() {
    let family = tables::by_name("aruco_6x6_250").expect("aruco_6x6_250");
    let pattern = MarkerPattern::from_code(family, 42).expect("id 42");
    let placement = Placement::new(1300.0, 1300.0, 2000.0)
        .rotated(8.0)
        .tilted(10.0, 30.0);
    let options = FrameOptions {
        supersampling: 2,
        ..FrameOptions::sized(2600, 2600)
    };
    let rendered = render_markers(&[(pattern, placement)], &options);
    let frame = &rendered.frame;
    let image = GrayImage::new(&frame.pixels, frame.width, frame.height).expect("a frame");
    let mut detector = Detector::new(DetectorConfig::default());
    let found = HostWorkspace::new()
        .detect(&mut detector, &image, &[family])
        .expect("detects");
    let truth = &rendered.truths[0];
    println!(
        "2,000 px marker: {} detection(s), shortest side {:.0} px, stats {:?}",
        found.len(),
        truth.min_side_px(),
        detector.stats()
    );
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0].id, 42);
    let error = truth.corner_error(&found[0].corners);
    println!("corner error {error:.3} px");
    assert!(error < 1.0, "corners off by {error} px");
}

/// The per-frame path knows the lens: a 250-pixel marker in the corner of a k1 = -0.35 frame
/// (the pad's small marker filling a wide-angle lens's view at touchdown), whose edges the
/// lens bows by several pixels, through [`FramePipeline`] as the board runs it. Its corners
/// come out within a fraction of a pixel of the truth, as from a detector given the camera,
/// where a detector without it (the pipeline before it handed its camera on) is pixels off;
/// and the pad fix puts the camera within a centimetre of where it is.
#[test]
fn the_pipeline_sees_through_its_lens() {
    let k1 = -0.35;
    let family = tables::by_name("aruco_6x6_250").expect("aruco_6x6_250");
    let (id, yaw, nominal) = (42, 17.0, 250.0);
    let mut sim = Simulator::new(scenario(k1)).with_threads(2);
    sim.scenario.trajectory = hold(0.05, -0.03);
    let camera: CameraModel = sim.scenario.camera.model;
    let mut size = nominal / f64::from(camera.fx) * ALTITUDE_M;
    let mut placed = None;
    for _ in 0..SIZE_ITERATIONS {
        let (x, y) =
            place_marker(&sim, family.name, id, size, yaw, [1.0, 0.75]).expect("the marker fits");
        let pad = pad_of(family.name, id, size, x, y, yaw);
        let (corners, edge_px) = project_corners(&sim, &pad);
        size *= nominal / edge_px;
        placed = Some((pad, corners));
    }
    let (pad, truth) = placed.expect("placed");
    let layout_config = pad.config.clone();
    let layout = layout_config.layout().expect("a one-marker layout");
    sim.world.pad = pad;
    let frame = sim.render(0).expect("one frame").image;
    let image = GrayImage::new(&frame.pixels, frame.width, frame.height).expect("a frame");
    let families: [&Family<'_>; 1] = [family];
    let error = |d: &Detection| {
        d.corners
            .iter()
            .zip(&truth)
            .map(|(c, t)| (f64::from(c.x) - t[0]).hypot(f64::from(c.y) - t[1]))
            .fold(0.0, f64::max)
    };

    let mut pipeline = FramePipeline::new(
        &families,
        &layout,
        camera,
        PipelineConfig::default(),
        PipelineSettings::default(),
    )
    .expect("the default trackers");
    let mut workspace = HostWorkspace::new();
    let report = pipeline.process(
        &image,
        0,
        &VehicleState::new(),
        &mut workspace.buffers(frame.width, frame.height),
    );
    assert_eq!(report.markers, 1, "{:?}", pipeline.detector().stats());
    let found = pipeline.detector().detections()[0];
    assert_eq!(found.id, id);
    let through_pipeline = error(&found);

    let mut lensed = Detector::new(DetectorConfig::default());
    lensed.set_camera(Some(camera));
    let with_camera = workspace
        .detect(&mut lensed, &image, &families)
        .expect("detects");
    let mut plain = Detector::new(DetectorConfig::default());
    let without = workspace
        .detect(&mut plain, &image, &families)
        .expect("detects");
    let without_camera = without.first().map(error);
    println!(
        "corner error: pipeline {through_pipeline:.3} px, detector with the camera {:.3} px, without {without_camera:?} px",
        with_camera.first().map_or(f64::NAN, error)
    );
    assert_eq!(with_camera.first().map(|d| d.corners), Some(found.corners));
    assert!(through_pipeline < 0.3, "corners {through_pipeline} px off");
    assert!(
        without_camera.is_none_or(|e| e > 1.5),
        "without the camera {without_camera:?} px"
    );

    let fix = report.fix.expect("a pad fix");
    let position = fix.camera_position();
    let true_position = sim.camera_pose(0.0).position;
    let miss = (0..3)
        .map(|k| (f64::from(position[k]) - true_position[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    println!("camera position {position:?}, truth {true_position:?}: {miss:.4} m off");
    assert!(miss < 0.01, "the fix is {miss} m off");
}
