//! Property tests (proptest) of the core's geometry, pose, decoding and filter.
//!
//! - Homography: four random points in general position map exactly onto four random image
//!   points, and the inverse homography maps any point back.
//! - Pose: a square marker projected with a random pose (distance, tilt, heading, offset,
//!   size) is solved back by IPPE + refinement: the true pose is among the two candidates
//!   and the best one reprojects to within 0.01 px.
//! - Decoding: a marker drawn axis-aligned and turned by each of the four quarter turns
//!   decodes to its id; its mirror image never decodes to an id (a marker seen from the back
//!   of a transparent print, or through a mirror, must not read as another marker).
//! - Filter: the tracker's covariance stays symmetric positive definite through random
//!   sequences of updates with extreme measurement covariances (eigenvalues over 18 decades,
//!   rank-deficient, slightly indefinite), predictions, drops and resets. This complements
//!   tests/filter_covariance.rs's seeded random test (variances 1e-8..1e2 m²) with the
//!   extreme covariances and shrinking to a minimal failing sequence.
//!
//! Case counts are set so the file runs in a few seconds in a debug `cargo test`.

use nalgebra::{Matrix3, Matrix6, Rotation3, Vector3};
use proptest::prelude::*;
use touchdown_core::camera::CameraModel;
use touchdown_core::detect::{Detector, DetectorConfig, QvgaWorkspace};
use touchdown_core::family::{tables, Family};
use touchdown_core::filter::{Measurement, Tracker, TrackerConfig};
use touchdown_core::geometry::{Homography, Point};
use touchdown_core::image::GrayImage;
use touchdown_core::pose::{marker_corners, marker_pose, PoseMethod};

// ---------------------------------------------------------------------------------------
// Homography

/// Twice the area of the triangle (a, b, c).
fn triangle_area2(a: Point, b: Point, c: Point) -> f32 {
    ((b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)).abs()
}

/// No three of the points nearly collinear (relative to the spread of the points).
fn general_position(p: &[Point; 4]) -> bool {
    let scale = p
        .iter()
        .flat_map(|a| p.iter().map(move |b| a.distance(*b)))
        .fold(0.0f32, f32::max);
    let triples = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)];
    scale > 0.01
        && triples
            .iter()
            .all(|&(i, j, k)| triangle_area2(p[i], p[j], p[k]) > 0.02 * scale * scale)
}

/// A quadrilateral around `centre` with corners near (±half, ±half), each moved by up to
/// 40 % of `half`: any shape from a square to a strongly skewed quad, rarely degenerate.
fn quad(
    centre: std::ops::Range<f32>,
    half: std::ops::Range<f32>,
) -> impl Strategy<Value = [Point; 4]> {
    let jitter = -0.4f32..0.4;
    (
        (centre.clone(), centre),
        half,
        prop::array::uniform8(jitter),
    )
        .prop_map(|((cx, cy), h, j)| {
            let signs = [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)];
            let mut q = [Point::default(); 4];
            for (k, (p, (sx, sy))) in q.iter_mut().zip(signs).enumerate() {
                *p = Point::new(cx + h * (sx + j[2 * k]), cy + h * (sy + j[2 * k + 1]));
            }
            q
        })
}

/// The proptest settings of this file: `cases` cases, no failure files in the source tree.
fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        failure_persistence: None,
        ..ProptestConfig::with_cases(cases)
    }
}

proptest! {
    #![proptest_config(config(512))]

    #[test]
    fn homography_maps_its_four_points_and_back(
        plane in quad(-2.0..2.0, 0.05..3.0),
        image in quad(100.0..540.0, 10.0..100.0),
        inside in (0.1f32..0.9, 0.1f32..0.9),
    ) {
        prop_assume!(general_position(&plane) && general_position(&image));
        let h = Homography::from_4_points(&plane, &image);
        prop_assert!(h.is_some(), "no homography for {plane:?} -> {image:?}");
        let h = h.unwrap();
        for (p, q) in plane.iter().zip(&image) {
            let m = h.map(p.x, p.y);
            prop_assert!(m.is_some());
            let m = m.unwrap();
            prop_assert!(m.distance(*q) < 0.02, "{p:?} -> {m:?}, expected {q:?}");
        }
        // The inverse maps a point between the first three corners back to itself.
        let inverse = Homography::from_4_points(&image, &plane).unwrap();
        let (s, t) = inside;
        let p = Point::new(
            plane[0].x + s * (plane[1].x - plane[0].x) + t * (plane[2].x - plane[0].x) * 0.5,
            plane[0].y + s * (plane[1].y - plane[0].y) + t * (plane[2].y - plane[0].y) * 0.5,
        );
        if let Some(q) = h.map(p.x, p.y) {
            if q.x.abs() < 1.0e4 && q.y.abs() < 1.0e4 {
                let back = inverse.map(q.x, q.y);
                prop_assert!(back.is_some());
                let back = back.unwrap();
                prop_assert!(back.distance(p) < 1.0e-3 * (1.0 + q.x.abs().max(q.y.abs()) / 640.0),
                    "{p:?} -> {q:?} -> {back:?}");
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Pose

proptest! {
    #![proptest_config(config(256))]

    #[test]
    fn ippe_recovers_a_projected_square(
        distance in 0.5f32..25.0,
        size in 0.1f32..1.25,
        tilt_deg in 0.0f32..60.0,
        tilt_axis_deg in 0.0f32..360.0,
        heading_deg in 0.0f32..360.0,
        offset in (-0.35f32..0.35, -0.25f32..0.25),
    ) {
        let camera = CameraModel::pinhole(640, 480, 600.0, 600.0, 319.5, 239.5);
        let axis = Vector3::new(tilt_axis_deg.to_radians().cos(), tilt_axis_deg.to_radians().sin(), 0.0);
        let rotation = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), tilt_deg.to_radians())
            * Rotation3::from_axis_angle(&Vector3::z_axis(), heading_deg.to_radians());
        let translation = Vector3::new(offset.0 * distance, offset.1 * distance, distance);
        let model = marker_corners(size);
        let mut corners = [Point::default(); 4];
        for (c, m) in corners.iter_mut().zip(&model) {
            let p = camera.project(&(rotation * m + translation));
            prop_assume!(p.is_some());
            *c = p.unwrap();
        }
        // In the image and large enough to be detected (14 px edges).
        prop_assume!(corners.iter().all(|c| c.x > 0.0 && c.x < 639.0 && c.y > 0.0 && c.y < 479.0));
        prop_assume!((0..4).all(|k| corners[k].distance(corners[(k + 1) % 4]) > 14.0));

        let solved = marker_pose(&corners, size, &camera, PoseMethod::Ippe);
        prop_assert!(solved.is_ok(), "{solved:?}");
        let solved = solved.unwrap();
        prop_assert!(solved.best.reprojection_rms_px < 0.01, "{solved:?}");
        let truth = rotation.matrix();
        let matches = |c: &touchdown_core::pose::PoseCandidate| {
            let r = c.pose.rotation.transpose() * truth;
            let angle = ((r.trace() - 1.0) * 0.5).clamp(-1.0, 1.0).acos();
            (c.pose.translation - translation).norm() < 2e-3 * distance && angle < 0.02
        };
        prop_assert!(
            matches(&solved.best) || solved.alternative.as_ref().is_some_and(matches),
            "truth R {truth} t {translation} not among {solved:?}"
        );
    }
}

// ---------------------------------------------------------------------------------------
// Decoding under rotation and mirroring

/// Families whose markers are drawn: normal and reversed layouts, 4x4 to 7x7 data.
fn families() -> [&'static Family<'static>; 5] {
    [
        &tables::TAG36H11,
        &tables::ARUCO_6X6_250,
        &tables::TAG_STANDARD41H12,
        &tables::ARUCO_4X4_50,
        &tables::ARUCO_7X7_250,
    ]
}

/// Marker `id` drawn axis-aligned, `cell` pixels per cell, one white cell of margin around
/// the family's grid, then turned `quarter_turns` times clockwise and mirrored left-right
/// when asked. Returns (side, pixels).
fn draw(
    family: &Family<'_>,
    id: usize,
    cell: usize,
    quarter_turns: u8,
    mirror: bool,
) -> (usize, Vec<u8>) {
    let grid = family.grid as usize;
    let side = (grid + 2) * cell;
    let mut canonical = vec![255u8; side * side];
    for row in 0..grid {
        for col in 0..grid {
            if family.cell_is_white(id, row, col) == Some(false) {
                for y in 0..cell {
                    let start = ((row + 1) * cell + y) * side + (col + 1) * cell;
                    canonical[start..start + cell].fill(0);
                }
            }
        }
    }
    let mut out = vec![0u8; side * side];
    for y in 0..side {
        for x in 0..side {
            // Source pixel of output (x, y).
            let (mut sx, mut sy) = (x, y);
            for _ in 0..quarter_turns % 4 {
                // Clockwise turn: out(x, y) = in(y, side - 1 - x).
                (sx, sy) = (sy, side - 1 - sx);
            }
            if mirror {
                sx = side - 1 - sx;
            }
            out[y * side + x] = canonical[sy * side + sx];
        }
    }
    (side, out)
}

proptest! {
    #![proptest_config(config(48))]

    #[test]
    fn decode_is_invariant_under_rotation_and_rejects_mirrors(
        which in 0usize..5,
        id_seed in any::<u16>(),
        cell in 4usize..8,
    ) {
        let family = families()[which];
        let id = usize::from(id_seed) % family.codes.len();
        let mut workspace = Box::new(QvgaWorkspace::new());
        let mut detector = Detector::new(DetectorConfig::default());
        for quarter_turns in 0..4u8 {
            for mirror in [false, true] {
                let (side, pixels) = draw(family, id, cell, quarter_turns, mirror);
                let image = GrayImage::new(&pixels, side, side).unwrap();
                let found = detector.detect(&image, &[family], &mut workspace.buffers()).unwrap();
                let ids: Vec<u16> = found.iter().map(|d| d.id).collect();
                if mirror {
                    // A mirror image may only be read as the marker itself (a code equal to
                    // its own mirror image), never as another id.
                    prop_assert!(ids.iter().all(|&d| usize::from(d) == id),
                        "{} id {id} mirrored, turned {quarter_turns}: read as {ids:?}", family.name);
                } else {
                    prop_assert_eq!(ids.len(), 1, "{} id {} turned {}: {:?}", family.name, id, quarter_turns, found);
                    prop_assert_eq!(usize::from(ids[0]), id);
                    let centre = (side as f32 - 1.0) * 0.5;
                    prop_assert!(found[0].center.distance(Point::new(centre, centre)) < 0.5);
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Filter covariance

/// What happens to the tracker at one step.
#[derive(Debug, Clone)]
enum Step {
    /// A measurement `dt_us` after the previous step: offset from the pad (m) and a
    /// covariance R diag(eigenvalues) Rᵀ; a negative eigenvalue makes it indefinite.
    Update {
        dt_us: u32,
        offset: [f32; 3],
        axis: [f32; 3],
        eigenvalues: [f32; 3],
    },
    /// Prediction only (dropped frames), possibly past the lost timeout.
    Predict {
        dt_us: u32,
    },
    /// A measurement stamped before the previous one.
    Backwards {
        back_us: u32,
    },
    Reset,
}

fn eigenvalue() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => (-12.0f32..6.0).prop_map(|e| 10f32.powf(e)),
        1 => Just(0.0f32),
        1 => -1.0e-6f32..0.0,
    ]
}

fn step() -> impl Strategy<Value = Step> {
    prop_oneof![
        6 => (
            0u32..70_000,
            [-0.5f32..0.5, -0.5f32..0.5, -0.5f32..0.5],
            [-3.2f32..3.2, -3.2f32..3.2, -3.2f32..3.2],
            [eigenvalue(), eigenvalue(), eigenvalue()],
        )
            .prop_map(|(dt_us, offset, axis, eigenvalues)| Step::Update { dt_us, offset, axis, eigenvalues }),
        2 => (0u32..3_000_000).prop_map(|dt_us| Step::Predict { dt_us }),
        1 => (0u32..2_000_000).prop_map(|back_us| Step::Backwards { back_us }),
        1 => Just(Step::Reset),
    ]
}

fn assert_spd(p: &Matrix6<f32>) -> Result<(), TestCaseError> {
    prop_assert!(p.iter().all(|v| v.is_finite()), "not finite: {p}");
    prop_assert_eq!(*p, p.transpose(), "not symmetric: {}", p);
    let p64 = p.cast::<f64>();
    prop_assert!(p64.cholesky().is_some(), "not positive definite: {p}");
    Ok(())
}

proptest! {
    #![proptest_config(config(64))]

    #[test]
    fn tracker_covariance_stays_symmetric_positive_definite(
        camera_frame in any::<bool>(),
        pad in [-10.0f32..10.0, -10.0f32..10.0, 0.5f32..40.0],
        steps in prop::collection::vec(step(), 1..120),
    ) {
        let config = if camera_frame { TrackerConfig::camera_frame() } else { TrackerConfig::level() };
        let mut tracker = Tracker::new(config).unwrap();
        let mut t: u64 = 1_000_000_000;
        let pad = Vector3::from(pad);
        for step in &steps {
            match *step {
                Step::Update { dt_us, offset, axis, eigenvalues } => {
                    t += u64::from(dt_us);
                    let r = Rotation3::new(Vector3::from(axis));
                    let covariance = r.matrix() * Matrix3::from_diagonal(&Vector3::from(eigenvalues)) * r.matrix().transpose();
                    let m = Measurement { t_us: t, position: pad + Vector3::from(offset), covariance };
                    let _ = tracker.update(&m);
                }
                Step::Predict { dt_us } => {
                    t += u64::from(dt_us);
                    let _ = tracker.predict_to(t);
                }
                Step::Backwards { back_us } => {
                    let m = Measurement {
                        t_us: t.saturating_sub(u64::from(back_us)),
                        position: pad,
                        covariance: Matrix3::identity() * 0.01,
                    };
                    let _ = tracker.update(&m);
                }
                Step::Reset => tracker.reset(),
            }
            if let Some(p) = tracker.covariance() {
                assert_spd(&p)?;
            }
            if let Some(e) = tracker.estimate(t) {
                prop_assert!(e.position.iter().chain(e.velocity.iter()).all(|v| v.is_finite()));
                let c = e.position_covariance.cast::<f64>();
                prop_assert!(c.cholesky().is_some(), "position covariance {}", e.position_covariance);
            }
        }
        prop_assert_eq!(tracker.repairs(), 0);
    }
}
