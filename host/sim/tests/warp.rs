//! The warp renderer ([`Renderer::Warp`]): its frames are a pure function of the scenario and
//! the seed whatever the thread count; the core's detector finds the pad's markers in them
//! where the truth puts them; a flat ground renders to the grey level its albedo gives; the
//! pad's pre-rasterised texture agrees with the printed cells; each PSF blurs an edge by
//! its width.
//!
//! Print the figures with `cargo test -p touchdown-sim --test warp -- --nocapture`.

use touchdown_core::detect::{buffer_sizes, Buffers, Detection, Detector, DetectorConfig};
use touchdown_core::family::{tables, Family};
use touchdown_formats::image_io::GrayFrame;
use touchdown_sim::camera::SimCamera;
use touchdown_sim::effects::FlightEffects;
use touchdown_sim::math::apply_homography;
use touchdown_sim::scenario::{FramePlan, Scenario};
use touchdown_sim::sensor::{Optics, Sensor};
use touchdown_sim::texture::GroundKind;
use touchdown_sim::trajectory::{Profile, Segment, Trajectory, Wobble};
use touchdown_sim::warp::{Psf, Response};
use touchdown_sim::world::{INK_ALBEDO, PAPER_ALBEDO};
use touchdown_sim::{Renderer, Simulator, WarpOptics};

/// Largest distance of a detected corner of a marker wholly in view from the truth's, pixels
/// (the landing's vibration and rolling shutter bend the edges the detector fits straight
/// lines to: the raster renderer's frames give up to 0.6 px too).
const CORNER_TOLERANCE_PX: f64 = 0.75;
/// Largest RMS of the corner errors of every marker found in a frame, pixels.
const CORNER_RMS_PX: f64 = 0.4;
/// How much worse than the raster renderer's the worst corner may be, pixels.
const CORNER_PARITY_PX: f64 = 0.15;

/// The landing scenario (seed 3) with the typical flight effects: rolling shutter,
/// vibration, misaligned mount, board lens and sensor, grass.
fn landing() -> Scenario {
    landing_with(&FlightEffects::typical())
}

/// The landing scenario (seed 3) with `effects`.
fn landing_with(effects: &FlightEffects) -> Scenario {
    let mut s = Scenario::named("landing", 3).expect("landing");
    s.apply_effects(effects);
    s
}

/// When the landing's descent passes `height` metres.
fn time_at_height(scenario: &Scenario, height: f64) -> f64 {
    let trajectory = &scenario.trajectory;
    let (mut lo, mut hi) = (0.0, trajectory.end_time());
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if trajectory.state(mid).position[2] > height {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[test]
fn the_same_scenario_gives_the_same_bytes_on_any_thread_count() {
    let scenario = landing();
    let t_us = (time_at_height(&scenario, 5.0) * 1e6) as u64;
    let one = Simulator::new(scenario.clone())
        .with_threads(1)
        .with_renderer(Renderer::Warp);
    let two = Simulator::new(scenario)
        .with_threads(2)
        .with_renderer(Renderer::Warp);
    let a = one.render_at(t_us, 4);
    let b = one.render_at(t_us, 4);
    let c = two.render_at(t_us, 4);
    assert_eq!(a, b);
    assert_eq!(a, c);
    assert_eq!(a.subframes, 1);
    // Another frame index draws other noise; the raster renderer draws another image.
    assert_ne!(a.image, one.render_at(t_us, 5).image);
    let raster = Simulator::new(landing()).with_threads(2);
    let r = raster.render_at(t_us, 4);
    assert_eq!(r.truth, a.truth);
    assert_ne!(r.image, a.image);
    // Every scenario renders, at both sizes (`touchdown sitl --qvga`'s 320x240: the same
    // lens on half the pixels).
    for name in [
        "paper",
        "lateral",
        "descent",
        "sun",
        "shadow",
        "occlusion",
        "hover",
    ] {
        for (w, h) in [(640u32, 480u32), (320, 240)] {
            let mut s = Scenario::named(name, 1).expect("a named scenario");
            s.camera = SimCamera::with_fov(w, h, 60.0, s.camera.model.distortion);
            let sim = Simulator::new(s)
                .with_threads(2)
                .with_renderer(Renderer::Warp);
            let frame = sim.render(0).expect("frame 0");
            assert_eq!(
                (frame.image.width, frame.image.height),
                (w as usize, h as usize)
            );
            let mean = frame
                .image
                .pixels
                .iter()
                .map(|&p| f64::from(p))
                .sum::<f64>()
                / f64::from(w * h);
            assert!(
                mean > 10.0 && mean < 245.0,
                "{name} {w}x{h}: mean grey {mean}"
            );
        }
    }
}

fn detect(frame: &GrayFrame, families: &[&Family<'_>]) -> Vec<Detection> {
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
    let mut detector = Detector::new(DetectorConfig::default());
    detector
        .detect(&frame.view(), families, &mut buffers)
        .expect("the detector accepts the frame")
        .to_vec()
}

/// What the detector made of one frame.
struct Found {
    height: f64,
    /// Markers wholly in view: every corner 4 px inside the image, every side 16 px long.
    whole: usize,
    /// Of those, how many were found.
    whole_found: usize,
    /// The worst corner error of those, pixels.
    worst: f64,
    /// Every marker found (whole or not) and the RMS of all their corners' errors, pixels.
    found: usize,
    rms: f64,
}

/// The detector on frames of `scenario` at `heights`, against the rolling-shutter truth.
fn detector_on(scenario: Scenario, renderer: Renderer, heights: &[f64]) -> Vec<Found> {
    let family = tables::by_name("tag36h11").expect("shipped family");
    let simulator = Simulator::new(scenario).with_renderer(renderer);
    let pad = simulator.world.pad.clone();
    heights
        .iter()
        .enumerate()
        .map(|(k, &height)| {
            let t = time_at_height(&simulator.scenario, height);
            let frame = simulator.render_at((t * 1e6).round() as u64, k);
            let truth = simulator.marker_corners_rolling_shutter(frame.t_us as f64 * 1e-6);
            let (w, h) = (640.0, 480.0);
            let whole = |c: &[[f64; 2]; 4]| {
                c.iter()
                    .all(|p| p[0] >= 4.0 && p[1] >= 4.0 && p[0] <= w - 5.0 && p[1] <= h - 5.0)
                    && (0..4).all(|i| {
                        let (a, b) = (c[i], c[(i + 1) % 4]);
                        (a[0] - b[0]).hypot(a[1] - b[1]) >= 16.0
                    })
            };
            let detections = detect(&frame.image, &[family]);
            let mut result = Found {
                height,
                whole: truth.iter().flatten().filter(|c| whole(c)).count(),
                whole_found: 0,
                worst: 0.0,
                found: 0,
                rms: 0.0,
            };
            let mut sum2 = 0.0;
            for d in &detections {
                let Some(index) = pad.markers.iter().position(|m| m.id == d.id) else {
                    panic!("{height} m: id {} is not on the pad", d.id);
                };
                let Some(corners) = truth[index] else {
                    continue;
                };
                result.found += 1;
                let mut worst = 0.0f64;
                for (p, q) in d.corners.iter().zip(&corners) {
                    let e = (f64::from(p.x) - q[0]).hypot(f64::from(p.y) - q[1]);
                    worst = worst.max(e);
                    sum2 += e * e;
                }
                if whole(&corners) {
                    result.whole_found += 1;
                    result.worst = result.worst.max(worst);
                }
            }
            result.rms = (sum2 / (4 * result.found.max(1)) as f64).sqrt();
            result
        })
        .collect()
}

#[test]
fn the_detector_finds_the_markers_where_the_truth_puts_them() {
    let heights = [20.0, 10.0, 5.0, 3.0, 2.0, 1.0];
    let warp = detector_on(landing(), Renderer::Warp, &heights);
    let raster = detector_on(landing(), Renderer::Raster, &heights);
    for (w, r) in warp.iter().zip(&raster) {
        println!(
            "{} m: {} markers whole in view; warp finds {} of them (worst corner {:.3} px) and \
             {} in all (corner RMS {:.3} px); raster {} (worst {:.3} px), {} (RMS {:.3} px)",
            w.height,
            w.whole,
            w.whole_found,
            w.worst,
            w.found,
            w.rms,
            r.whole_found,
            r.worst,
            r.found,
            r.rms
        );
    }
    for (w, r) in warp.iter().zip(&raster) {
        assert_eq!(w.whole_found, w.whole, "{} m: markers missed", w.height);
        assert!(
            w.worst <= r.worst + CORNER_PARITY_PX,
            "{} m: worst corner {:.3} px, raster {:.3} px",
            w.height,
            w.worst,
            r.worst
        );
        assert!(
            w.worst <= CORNER_TOLERANCE_PX,
            "{} m: a corner {:.3} px from the truth",
            w.height,
            w.worst
        );
        assert!(
            w.rms <= CORNER_RMS_PX,
            "{} m: corner RMS {:.3} px",
            w.height,
            w.rms
        );
    }
}

/// Without the flight effects (a global shutter on a rigid, aligned mount; the board lens
/// and sensor, motion blur and all), the corners are within half a pixel.
#[test]
fn without_flight_effects_the_corners_are_within_half_a_pixel() {
    let heights = [20.0, 10.0, 5.0, 3.0, 2.0, 1.0];
    let warp = detector_on(
        landing_with(&FlightEffects::none()),
        Renderer::Warp,
        &heights,
    );
    for w in &warp {
        println!(
            "{} m, no effects: {} markers whole in view, {} found, worst corner {:.3} px, \
             RMS {:.3} px",
            w.height, w.whole, w.whole_found, w.worst, w.rms
        );
        assert_eq!(w.whole_found, w.whole, "{} m: markers missed", w.height);
        assert!(
            w.worst <= 0.5,
            "{} m: worst corner {:.3} px",
            w.height,
            w.worst
        );
    }
}

/// The paper's marker under an ideal camera hovering still at `height` over `ground`, an
/// ideal lens and sensor (radiance 1 = grey level 250), no exposure time.
fn still(height: f64, ground: GroundKind) -> Scenario {
    let mut s = Scenario::named("paper", 1).expect("paper scenario");
    s.ground = ground;
    s.optics = Optics::ideal();
    s.sensor = Sensor::ideal();
    s.exposure_time_s = 0.0;
    s.trajectory = Trajectory {
        segments: vec![Segment {
            t0: 0.0,
            t1: 1.0,
            from: [0.13, -0.21, height],
            to: [0.13, -0.21, height],
            profile: Profile::Hold,
        }],
        yaw: 0.3,
        wobble: Wobble::none(),
        tilt_with_acceleration: false,
        trim: (0.0, 0.0),
    };
    s.frames = vec![FramePlan {
        t_us: 0,
        label: None,
    }];
    s
}

/// Pixel `(u, v)`'s corners on the ground.
fn footprint(sim: &Simulator, u: usize, v: usize) -> Option<[(f64, f64); 4]> {
    let h = sim.camera_pose(0.0).ground_homography();
    let camera = &sim.scenario.camera;
    let corner = |du: f64, dv: f64| {
        let (x, y) = camera.undistort(u as f64 + du, v as f64 + dv)?;
        apply_homography(&h, x, y)
    };
    Some([
        corner(-0.5, -0.5)?,
        corner(0.5, -0.5)?,
        corner(0.5, 0.5)?,
        corner(-0.5, 0.5)?,
    ])
}

#[test]
fn a_flat_ground_renders_to_its_grey_level_and_through_the_gamma() {
    let scenario = still(6.0, GroundKind::Flat(0.5));
    let plain = Simulator::new(scenario.clone()).with_renderer(Renderer::Warp);
    let gamma = 2.2;
    let curved = Simulator::new(scenario)
        .with_renderer(Renderer::Warp)
        .with_warp_optics(WarpOptics {
            response: Response {
                gamma,
                ..Response::linear()
            },
            ..WarpOptics::ideal()
        });
    let (a, b) = (plain.render(0).unwrap(), curved.render(0).unwrap());
    let sheet = plain.world.pad.sheet;
    // 0.5 x 1.0 (daylight) x 250; through the gamma, 255 (125 / 255)^(1 / 2.2).
    let expected_curve = (255.0 * (125.0f64 / 255.0).powf(1.0 / gamma)).round() as u8;
    let mut ground_pixels = 0;
    for v in 0..480 {
        for u in 0..640 {
            let Some(corners) = footprint(&plain, u, v) else {
                continue;
            };
            // Well clear of the sheet (a pixel is 1 cm here).
            let clear = corners.iter().all(|&(x, y)| {
                x < sheet.x0 - 0.05
                    || x > sheet.x1 + 0.05
                    || y < sheet.y0 - 0.05
                    || y > sheet.y1 + 0.05
            });
            if clear {
                ground_pixels += 1;
                assert_eq!(a.image.pixels[v * 640 + u], 125, "({u}, {v})");
                assert_eq!(b.image.pixels[v * 640 + u], expected_curve, "({u}, {v})");
            }
        }
    }
    assert!(ground_pixels > 100_000, "{ground_pixels}");
}

#[test]
fn the_pad_texture_is_the_printed_cells() {
    // At 0.8 m a pixel is 1.4 mm, a cell 12.5 mm; at 3 m 5.4 mm.
    for height in [0.8, 3.0] {
        let sim =
            Simulator::new(still(height, GroundKind::Flat(0.3))).with_renderer(Renderer::Warp);
        let frame = sim.render(0).unwrap();
        let marker = &sim.world.pad.markers[0];
        let n = marker.grid() as f64;
        let margin = marker.margin_cells;
        let (mut white, mut black, mut wrong) = (0, 0, Vec::new());
        for v in 0..480 {
            for u in 0..640 {
                let Some(corners) = footprint(&sim, u, v) else {
                    continue;
                };
                let cells = corners.map(|(x, y)| {
                    let (c, r) = marker.grid_coords(x, y);
                    ((c + margin).floor(), (r + margin).floor())
                });
                if cells.iter().any(|&c| c != cells[0]) {
                    continue;
                }
                let (c, r) = (cells[0].0 - margin, cells[0].1 - margin);
                let albedo = if c < -margin || r < -margin || c >= n + margin || r >= n + margin {
                    continue;
                } else if c < 0.0
                    || r < 0.0
                    || c >= n
                    || r >= n
                    || marker.pattern.is_white(r as usize, c as usize)
                {
                    // The margin, or a white cell.
                    PAPER_ALBEDO
                } else {
                    INK_ALBEDO
                };
                let expected = (f64::from(albedo) * 250.0).round() as u8;
                if albedo == PAPER_ALBEDO {
                    white += 1;
                } else {
                    black += 1;
                }
                let got = frame.image.pixels[v * 640 + u];
                if got != expected {
                    wrong.push((u, v, got, expected));
                }
            }
        }
        println!("{height} m: {white} white and {black} black pixels within a cell");
        assert!(white > 1000 && black > 1000, "{white} {black}");
        assert!(
            wrong.is_empty(),
            "{height} m: {:?}",
            &wrong[..wrong.len().min(10)]
        );
    }
}

#[test]
fn block_compression_keeps_flat_blocks_and_block_means() {
    let render = |height: f64, quality: Option<u8>| {
        Simulator::new(still(height, GroundKind::Flat(0.5)))
            .with_renderer(Renderer::Warp)
            .with_warp_optics(WarpOptics {
                response: Response {
                    block_quality: quality,
                    ..Response::linear()
                },
                ..WarpOptics::ideal()
            })
            .render(0)
            .expect("frame 0")
            .image
    };
    // At the best quality the steps are half a grey level and up: a flat block comes back
    // as it was, an edge moves by a few grey levels at most.
    let plain = render(3.0, None);
    let best = render(3.0, Some(100));
    let block = |img: &GrayFrame, bx: usize, by: usize| -> Vec<u8> {
        (0..64)
            .map(|k| img.pixels[(by * 8 + k / 8) * 640 + bx * 8 + k % 8])
            .collect()
    };
    let mut flat_blocks = 0;
    for by in 0..480 / 8 {
        for bx in 0..640 / 8 {
            let before = block(&plain, bx, by);
            if before.iter().all(|&p| p == before[0]) {
                flat_blocks += 1;
                assert_eq!(before, block(&best, bx, by), "block ({bx}, {by})");
            }
        }
    }
    assert!(flat_blocks > 1000, "{flat_blocks}");
    let worst_change = plain
        .pixels
        .iter()
        .zip(&best.pixels)
        .map(|(&a, &b)| (i32::from(a) - i32::from(b)).abs())
        .max()
        .unwrap_or(0);
    assert!(worst_change <= 4, "{worst_change}");
    // At quality 30 the edges ring, but every block keeps its mean to within half the mean's
    // step (the transform's step 0.5 + 49.5 x 70 / 99 = 35.5, over 8 for the mean) plus
    // what the clipping of the ringing at black and white takes (3 grey levels).
    let rough = render(3.0, Some(30));
    assert_ne!(plain.pixels, rough.pixels);
    let mut worst_mean = 0.0f64;
    for by in 0..480 / 8 {
        for bx in 0..640 / 8 {
            let mean = |img: &GrayFrame| {
                block(img, bx, by)
                    .iter()
                    .map(|&p| f64::from(p))
                    .sum::<f64>()
                    / 64.0
            };
            worst_mean = worst_mean.max((mean(&plain) - mean(&rough)).abs());
        }
    }
    println!("quality 30: block means within {worst_mean:.2} grey levels");
    let half_step = 0.5 * (0.5 + 49.5 * 70.0 / 99.0) / 8.0;
    assert!(worst_mean <= half_step + 3.0, "{worst_mean}");
}

/// The variance, pixels squared, of the line-spread function of a vertical step edge in
/// row `row` of a `w x h` image blurred by `psf`.
fn edge_variance(psf: &Psf, w: usize, h: usize, row: usize) -> f64 {
    let edge = w / 2;
    let mut image: Vec<f32> = (0..w * h)
        .map(|k| if k % w < edge { 0.0 } else { 1.0 })
        .collect();
    psf.apply(&mut image, w, h);
    let line = &image[row * w..(row + 1) * w];
    let lsf: Vec<f64> = line.windows(2).map(|p| f64::from(p[1] - p[0])).collect();
    let total: f64 = lsf.iter().sum();
    let mean = lsf
        .iter()
        .enumerate()
        .map(|(i, d)| i as f64 * d)
        .sum::<f64>()
        / total;
    lsf.iter()
        .enumerate()
        .map(|(i, d)| (i as f64 - mean).powi(2) * d)
        .sum::<f64>()
        / total
}

#[test]
fn each_psf_blurs_an_edge_by_its_width() {
    let (w, h) = (64, 48);
    let middle = h / 2;
    let within = |got: f64, expected: f64, tolerance: f64, what: &str| {
        assert!(
            (got - expected).abs() <= tolerance * expected + 0.01,
            "{what}: variance {got:.4} px^2, expected {expected:.4}"
        );
    };
    let close = |got: f64, expected: f64, what: &str| within(got, expected, 0.06, what);
    for sigma in [0.6, 1.5, 3.0] {
        let v = edge_variance(&Psf::Gaussian { sigma_px: sigma }, w, h, middle);
        close(v, sigma * sigma, &format!("Gaussian {sigma}"));
    }
    // The disc and the line are their area (length) in each pixel: the edge's spread is the
    // variance of those weights summed over each column of pixels, from the disc's area
    // left of `x` (the line's length).
    let column_variance = |left_of: &dyn Fn(f64) -> f64, reach: i64| {
        let total = left_of(f64::from(reach as i32) + 1.0);
        (-reach..=reach)
            .map(|i| {
                let x = i as f64;
                x * x * (left_of(x + 0.5) - left_of(x - 0.5))
            })
            .sum::<f64>()
            / total
    };
    for d in [2.0, 3.0, 5.0, 9.0] {
        let r: f64 = 0.5 * d;
        let disc_left_of = |x: f64| {
            let x = x.clamp(-r, r);
            r * r * (std::f64::consts::PI - (x / r).acos()) + x * (r * r - x * x).sqrt()
        };
        let expected = column_variance(&disc_left_of, r.ceil() as i64 + 1);
        let v = edge_variance(&Psf::Disc { diameter_px: d }, w, h, middle);
        within(v, expected, 0.03, &format!("disc {d}"));
        // About the continuous disc's d^2 / 16 plus a pixel's 1 / 12.
        within(v, d * d / 16.0 + 1.0 / 12.0, 0.2, &format!("disc {d}"));
    }
    for l in [3.0, 8.0] {
        let half: f64 = 0.5 * l;
        let line_left_of = |x: f64| x.clamp(-half, half) + half;
        let expected = column_variance(&line_left_of, half.ceil() as i64 + 1);
        let across = edge_variance(
            &Psf::MotionLine {
                length_px: l,
                angle_deg: 0.0,
            },
            w,
            h,
            middle,
        );
        within(across, expected, 0.03, &format!("line {l} across"));
        // Along the edge: no spread at all.
        let along = edge_variance(
            &Psf::MotionLine {
                length_px: l,
                angle_deg: 90.0,
            },
            w,
            h,
            middle,
        );
        assert!(along < 0.01, "line {l} along the edge: {along}");
    }
    // The field blur: nothing at the centre, the corner's Gaussian at the corners (the
    // top row's edge is at a corner's distance from the centre, to within the half width).
    let field = Psf::Field {
        corner_sigma_px: 2.0,
    };
    let (cw, ch) = (64, 65);
    let centre = edge_variance(&field, cw, ch, ch / 2);
    assert!(centre < 0.02, "field blur at the centre: {centre}");
    let top = edge_variance(&field, cw, ch, 0);
    // The top row at the edge's column is (h - 1) / 2 from the centre, of a corner's
    // sqrt(((w - 1) / 2)^2 + ((h - 1) / 2)^2): the blend's weight is the square of that.
    let weight = (32.0f64 * 32.0) / (31.5f64 * 31.5 + 32.0 * 32.0);
    close(top, weight * 4.0, "field blur in the top row");
    // A narrow corner blur (three taps per axis): the same proportion of its variance.
    let narrow = Psf::Field {
        corner_sigma_px: 0.6,
    };
    let centre = edge_variance(&narrow, cw, ch, ch / 2);
    assert!(centre < 0.01, "narrow field blur at the centre: {centre}");
    let top = edge_variance(&narrow, cw, ch, 0);
    close(top, weight * 0.36, "narrow field blur in the top row");
}

/// Sum of squared differences between horizontal and vertical neighbours: how sharp a
/// frame's edges are.
fn gradient_energy(frame: &GrayFrame) -> f64 {
    let (w, p) = (frame.width, &frame.pixels);
    let mut sum = 0.0;
    for (k, &v) in p.iter().enumerate() {
        let v = f64::from(v);
        if k % w + 1 < w {
            sum += (f64::from(p[k + 1]) - v).powi(2);
        }
        if let Some(&below) = p.get(k + w) {
            sum += (f64::from(below) - v).powi(2);
        }
    }
    sum
}

#[test]
fn either_model_takes_the_lens_as_point_spread_functions() {
    let mut scenario = still(6.0, GroundKind::Flat(0.3));
    // The board's lens blur, no defocus (focused at the pad), no noise.
    scenario.optics = Optics {
        aperture_m: 0.0,
        ..Optics::board_camera()
    };
    let lens_sigma = scenario.optics.blur_sigma_px;
    assert!(lens_sigma > 0.3, "the board's lens blurs: {lens_sigma}");
    for renderer in [Renderer::Raster, Renderer::Warp] {
        let model = || {
            Simulator::new(scenario.clone())
                .with_threads(2)
                .with_renderer(renderer)
        };
        let own = model().render(0).expect("one frame").image;
        // The lens given as its own Gaussian: the scenario's frame, to the blur's rounding
        // (the warp model's softer corners are its lens's too; without them, near enough).
        let as_given = model()
            .with_lens_psfs(vec![Psf::Gaussian {
                sigma_px: lens_sigma,
            }])
            .render(0)
            .expect("one frame")
            .image;
        let (worst, mean) = own
            .pixels
            .iter()
            .zip(&as_given.pixels)
            .fold((0u8, 0.0), |(worst, sum), (a, b)| {
                (worst.max(a.abs_diff(*b)), sum + f64::from(a.abs_diff(*b)))
            });
        let mean = mean / own.pixels.len() as f64;
        println!("{renderer}: the lens as its Gaussian: worst {worst}, mean {mean:.3} grey levels");
        assert!(mean < 0.05 && worst <= 3, "{renderer}: {worst} / {mean}");
        // A defocus disc of 6 px in its place spreads every edge further.
        let defocused = model()
            .with_lens_psfs(vec![Psf::Disc { diameter_px: 6.0 }])
            .render(0)
            .expect("one frame")
            .image;
        let ratio = gradient_energy(&defocused) / gradient_energy(&own);
        println!("{renderer}: a 6 px disc leaves {ratio:.2} of the gradient energy");
        assert!(ratio < 0.6, "{renderer}: {ratio}");
    }
}
