//! The renderer's own checks: truth against the placed geometry, area-weighted edges, the
//! darkness and centroid of a rendered quad, determinism, noise spread and blur.

use super::*;

fn square(grid: usize) -> MarkerPattern {
    MarkerPattern::from_cells(&vec![false; grid * grid], grid, 0).unwrap()
}

fn white_ground(width: usize, height: usize) -> FrameOptions {
    FrameOptions {
        background: Background::Flat(255.0),
        black: 0.0,
        white: 255.0,
        ..FrameOptions::sized(width, height)
    }
}

fn close(a: Point, x: f32, y: f32, tol: f32) -> bool {
    (a.x - x).abs() <= tol && (a.y - y).abs() <= tol
}

#[test]
fn facing_marker_truth_is_the_placed_square() {
    let p = Placement::new(40.3, 31.7, 20.0);
    let (_, t) = render_cells(&[false; 16], 4, 0, &p, &white_ground(80, 60)).unwrap();
    let e = 10.0;
    assert!(
        close(t.corners[0], 40.3 - e, 31.7 - e, 1e-4),
        "{:?}",
        t.corners
    );
    assert!(close(t.corners[1], 40.3 + e, 31.7 - e, 1e-4));
    assert!(close(t.corners[2], 40.3 + e, 31.7 + e, 1e-4));
    assert!(close(t.corners[3], 40.3 - e, 31.7 + e, 1e-4));
    assert!(close(t.center, 40.3, 31.7, 1e-4));
}

#[test]
fn rotation_is_clockwise_in_the_image() {
    let p = Placement::new(40.0, 30.0, 20.0).rotated(90.0);
    let (_, t) = render_cells(&[false; 16], 4, 0, &p, &white_ground(80, 60)).unwrap();
    // The canonical top-left corner moves to the top-right of the image.
    assert!(close(t.corners[0], 50.0, 20.0, 1e-4), "{:?}", t.corners);
    assert!(close(t.corners[1], 50.0, 40.0, 1e-4), "{:?}", t.corners);
}

#[test]
fn border_ring_sets_the_edge_and_the_margin_is_paper() {
    // 4x4 grid, ring 1 is the edge: 2 cells span 20 px, so cells are 10 px; the white
    // quiet ring and one cell of margin extend 20 px beyond the edge.
    let mut cells = [true; 16];
    for k in [5, 6, 9, 10] {
        cells[k] = false;
    }
    let p = Placement::new(50.0, 50.0, 20.0);
    let (frame, t) = render_cells(&cells, 4, 1, &p, &FrameOptions::sized(101, 101)).unwrap();
    assert!(close(t.corners[0], 40.0, 40.0, 1e-4));
    assert_eq!(
        t.grid_point(0.0, 0.0).map(|q| close(q, 30.0, 30.0, 1e-4)),
        Some(true)
    );
    let at = |x: usize, y: usize| frame.pixels[y * 101 + x];
    assert_eq!(at(50, 50), 20); // black square
    assert_eq!(at(35, 50), 235); // quiet ring
    assert_eq!(at(22, 50), 235); // extra paper
    assert_eq!(at(15, 50), 128); // ground
}

#[test]
fn edge_pixels_are_area_weighted() {
    // Edges at x = 15.0 and 25.0 fall on pixel centres: those pixels are half covered.
    let p = Placement::new(20.0, 20.0, 10.0).with_margin(0.0);
    let (frame, _) = render_cells(&[false; 4], 2, 0, &p, &white_ground(41, 41)).unwrap();
    let at = |x: usize, y: usize| frame.pixels[y * 41 + x];
    assert_eq!(at(20, 20), 0);
    assert_eq!(at(14, 20), 255);
    assert_eq!(at(15, 20), 128);
    assert_eq!(at(25, 20), 128);
    assert_eq!(at(15, 15), 191); // a quarter covered: 255 * 3 / 4 = 191.25
                                 // Edge at x = 15.25: pixel 15 is 25 % covered.
    let p = Placement::new(20.25, 20.0, 10.0).with_margin(0.0);
    let (frame, _) = render_cells(&[false; 4], 2, 0, &p, &white_ground(41, 41)).unwrap();
    assert_eq!(frame.pixels[20 * 41 + 15], 191);
}

/// Total darkness and its centroid equal the area and centroid of the truth quad at any
/// rotation and tilt: the pixels and the truth come from the same mapping, and pixel
/// (0, 0) is the centre of the top-left pixel.
#[test]
fn darkness_matches_the_truth_quad_area_and_centroid() {
    for (rotation, tilt, axis) in [
        (0.0, 0.0, 0.0),
        (31.0, 0.0, 0.0),
        (12.0, 55.0, 70.0),
        (200.0, 40.0, -20.0),
    ] {
        let p = Placement::new(60.4, 55.9, 40.0)
            .rotated(rotation)
            .tilted(tilt, axis)
            .with_margin(0.0);
        let (frame, t) = render_cells(&[false; 9], 3, 0, &p, &white_ground(121, 111)).unwrap();
        let (mut dark, mut mx, mut my) = (0.0f64, 0.0f64, 0.0f64);
        for (k, &v) in frame.pixels.iter().enumerate() {
            let d = (255 - v) as f64 / 255.0;
            dark += d;
            mx += d * (k % 121) as f64;
            my += d * (k / 121) as f64;
        }
        // Shoelace area and centroid of the corner polygon.
        let c = t.corners.map(|q| (q.x as f64, q.y as f64));
        let (mut area, mut cx, mut cy) = (0.0, 0.0, 0.0);
        for k in 0..4 {
            let (a, b) = (c[k], c[(k + 1) % 4]);
            let cross = a.0 * b.1 - b.0 * a.1;
            area += 0.5 * cross;
            cx += (a.0 + b.0) * cross;
            cy += (a.1 + b.1) * cross;
        }
        let (cx, cy) = (cx / (6.0 * area), cy / (6.0 * area));
        let area = area.abs();
        assert!(
            (dark - area).abs() < 0.002 * area + 1.0,
            "rotation {rotation} tilt {tilt}: {dark} vs {area}"
        );
        let (ex, ey) = (mx / dark - cx, my / dark - cy);
        assert!(
            ex.abs() < 0.01 && ey.abs() < 0.01,
            "rotation {rotation} tilt {tilt}: centroid off by ({ex}, {ey})"
        );
    }
}

#[test]
fn tilt_foreshortens_and_keeps_the_centre() {
    let p = Placement::new(80.0, 60.0, 40.0).tilted(60.0, 0.0);
    let (_, t) = render_cells(&[false; 9], 3, 0, &p, &white_ground(160, 120)).unwrap();
    assert!(close(t.center, 80.0, 60.0, 1e-4));
    // Axis along x: the vertical extent shrinks to about cos(60) = half.
    let height = (t.corners[3].y + t.corners[2].y - t.corners[0].y - t.corners[1].y) * 0.5;
    assert!((height - 20.0).abs() < 2.0, "{height}");
    assert!(t.min_side_px() < 21.0);
}

#[test]
fn code_pattern_is_the_canonical_grid() {
    use touchdown_core::family::parse_family;
    const TWO: &str = "# family mini\n# cells 8\n\
        1111111110000001101011011001010110001101100010011000000111111111\n\
        1111111110000001101001011011010110101101101010011000000111111111\n";
    let mut codes = [0u64; 2];
    let mut ids = [0u16; 2];
    let family = parse_family(TWO, "mini", &mut codes)
        .unwrap()
        .into_family(&codes, &mut ids)
        .unwrap();
    let pattern = MarkerPattern::from_code(&family, 1).unwrap();
    let line = TWO.lines().nth(3).unwrap();
    for (k, ch) in line.chars().enumerate() {
        assert_eq!(pattern.is_white(k / 8, k % 8), ch == '1', "cell {k}");
    }
    assert_eq!(pattern.edge_cells(), 6);
    assert!(MarkerPattern::from_code(&family, 2).is_none());
}

#[test]
fn rendering_is_deterministic_and_seeded() {
    let mut options = FrameOptions {
        noise_sigma: 5.0,
        blur_sigma: 1.0,
        background: Background::Texture {
            mean: 120.0,
            amplitude: 60.0,
            scale_px: 32.0,
        },
        seed: 7,
        ..FrameOptions::sized(64, 48)
    };
    let p = Placement::new(30.0, 20.0, 16.0).rotated(10.0);
    let a = render_markers(&[(square(3), p)], &options);
    let b = render_markers(&[(square(3), p)], &options);
    assert_eq!(a, b);
    options.seed = 8;
    let c = render_markers(&[(square(3), p)], &options);
    assert_ne!(a.frame, c.frame);
}

#[test]
fn noise_has_the_requested_spread() {
    let options = FrameOptions {
        noise_sigma: 8.0,
        ..FrameOptions::sized(200, 200)
    };
    let frame = Scene::new(options).render().frame;
    let n = frame.pixels.len() as f64;
    let mean = frame.pixels.iter().map(|&v| v as f64).sum::<f64>() / n;
    let var = frame
        .pixels
        .iter()
        .map(|&v| (v as f64 - mean).powi(2))
        .sum::<f64>()
        / n;
    assert!((mean - 128.0).abs() < 0.2, "{mean}");
    // Rounding adds 1/12 of a level squared.
    assert!((var.sqrt() - 8.0).abs() < 0.15, "{}", var.sqrt());
}

#[test]
fn blur_keeps_the_total_light() {
    let p = Placement::new(40.0, 40.0, 20.0).rotated(20.0);
    let sharp = render_markers(&[(square(3), p)], &white_ground(81, 81));
    let blurred = render_markers(
        &[(square(3), p)],
        &FrameOptions {
            blur_sigma: 1.5,
            ..white_ground(81, 81)
        },
    );
    let total = |f: &GrayFrame| f.pixels.iter().map(|&v| v as f64).sum::<f64>();
    let (a, b) = (total(&sharp.frame), total(&blurred.frame));
    assert!((a - b).abs() < 0.001 * a, "{a} vs {b}");
    assert_ne!(sharp.frame, blurred.frame);
}

/// Every tap of a Gaussian of `sigma` out to 4 sigma, edges replicated, summed directly
/// (what the blur computes, however wide).
fn blurred_directly(image: &[f32], w: usize, h: usize, sigma: f64) -> Vec<f64> {
    let radius = (4.0 * sigma).ceil().max(1.0) as isize;
    let g = |j: isize| (-((j * j) as f64) / (2.0 * sigma * sigma)).exp();
    let total: f64 = (-radius..=radius).map(g).sum();
    let clamp = |v: isize, len: usize| v.clamp(0, len as isize - 1) as usize;
    let mut rows = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            rows[y * w + x] = (-radius..=radius)
                .map(|j| g(j) * f64::from(image[y * w + clamp(x as isize + j, w)]))
                .sum::<f64>()
                / total;
        }
    }
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            out[y * w + x] = (-radius..=radius)
                .map(|j| g(j) * rows[clamp(y as isize + j, h) * w + x])
                .sum::<f64>()
                / total;
        }
    }
    out
}

#[test]
fn a_blur_wider_than_the_image_is_the_direct_sum_and_stays_fast() {
    let (w, h) = (9, 6);
    let image: Vec<f32> = (0..w * h).map(|k| ((k * 37) % 101) as f32).collect();
    // 4 sigma reaches past the image: the wide path (the 1.0 one keeps the direct sum).
    for sigma in [1.0, 2.5, 7.0, 40.0] {
        let mut blurred = image.clone();
        raster::gaussian_blur(&mut blurred, w, h, sigma);
        let want = blurred_directly(&image, w, h, sigma);
        for (k, (&got, &want)) in blurred.iter().zip(&want).enumerate() {
            assert!(
                (f64::from(got) - want).abs() < 2e-3,
                "sigma {sigma}, pixel {k}: {got} against {want}"
            );
        }
    }
    // A pad a micrometre from the lens: a sigma of about a hundred thousand pixels (the
    // direct sum took minutes a frame). It flattens the image towards its edge-weighted mean
    // and takes a moment.
    let (w, h) = (320, 240);
    let mut image = vec![0.0f32; w * h];
    image[..w * h / 2].iter_mut().for_each(|v| *v = 200.0);
    let started = std::time::Instant::now();
    for sigma in [1.2e5, 1.0e9] {
        let mut blurred = image.clone();
        raster::gaussian_blur(&mut blurred, w, h, sigma);
        let (lo, hi) = blurred
            .iter()
            .fold((f32::MAX, f32::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        assert!(
            (99.0..=101.0).contains(&lo) && (99.0..=101.0).contains(&hi),
            "{sigma}: {lo}..{hi}"
        );
    }
    assert!(
        started.elapsed().as_secs_f64() < 5.0,
        "{:?}",
        started.elapsed()
    );
}
