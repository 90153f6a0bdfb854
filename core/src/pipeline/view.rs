//! How far the vehicle can move before the pad leaves the camera's view: the margin a pilot
//! or a ground station watches when the board is the vehicle's only source of position.
//!
//! The margin is that of the marker with the most room: the distance, on the ground at that
//! marker's depth, from its nearest corner to the nearest edge of the image, over the markers
//! fully in view and large enough to decode ([`DECODABLE_PX`]). It is the worst direction's
//! margin: a move of that much toward the nearest edge takes the last such marker out of the
//! view (or a turn or tilt that moves the image by as much), after which the board has no fix
//! and the autopilot's estimator coasts on its own.

use super::CameraModel;
use crate::geometry::Point;
use crate::pad::PadLayout;
use crate::pose::Pose;
use nalgebra::Vector3;

/// A marker is counted only from this many pixels across (its longest side): about what the
/// detector decodes (see [`crate::pad`] for the arithmetic of the shipped pads).
pub const DECODABLE_PX: f32 = 14.0;

/// The view margin of `pad` seen at `pose` (pad frame to camera frame) through `camera`,
/// metres; `None` when no marker of the pad is fully in view and decodable.
pub fn view_margin_m(pose: &Pose, pad: &PadLayout<'_>, camera: &CameraModel) -> Option<f32> {
    const SIGNS: [(f32, f32); 4] = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
    let (w, h) = (camera.width as f32, camera.height as f32);
    let focal = camera.fx.min(camera.fy);
    if !(focal > 0.0 && w > 0.0 && h > 0.0) {
        return None;
    }
    let mut best: Option<f32> = None;
    for marker in pad.markers() {
        let half = 0.5 * marker.size;
        let mut corners = [Point::new(0.0, 0.0); 4];
        let mut whole = true;
        for (slot, (sx, sy)) in corners.iter_mut().zip(SIGNS) {
            let on_pad = marker.to_pad(&Vector3::new(sx * half, sy * half, 0.0));
            match camera.project(&pose.transform(&on_pad)) {
                Some(p) => *slot = p,
                None => whole = false,
            }
        }
        if !whole {
            continue;
        }
        let side = |a: &Point, b: &Point| libm::hypotf(a.x - b.x, a.y - b.y);
        let longest = corners
            .iter()
            .zip(corners.iter().cycle().skip(1))
            .map(|(a, b)| side(a, b))
            .fold(0.0, f32::max);
        // Pixel centres span [0, w - 1]: a corner on the last pixel has no room left.
        let room_px = corners
            .iter()
            .map(|p| p.x.min(p.y).min(w - 1.0 - p.x).min(h - 1.0 - p.y))
            .fold(f32::INFINITY, f32::min);
        let depth = pose.transform(&marker.to_pad(&Vector3::zeros())).z;
        if !(longest >= DECODABLE_PX && room_px >= 0.0 && depth > 0.0) {
            continue;
        }
        let metres = room_px * depth / focal;
        best = Some(best.map_or(metres, |b| b.max(metres)));
    }
    best
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use crate::pad::designs;
    use nalgebra::Matrix3;

    /// A 320 x 240 camera with a 60 degree horizontal field of view, no distortion.
    fn qvga() -> CameraModel {
        let f = 160.0 / libm::tanf(30f32.to_radians());
        CameraModel::pinhole(320, 240, f, f, 159.5, 119.5)
    }

    /// The 70 degree 640x480 lens of the shipped pads' arithmetic.
    fn vga() -> CameraModel {
        let f = 320.0 / libm::tanf(35f32.to_radians());
        CameraModel::pinhole(640, 480, f, f, 319.5, 239.5)
    }

    /// The camera `height` m straight above the pad point (`x`, `y`), image top toward pad +y.
    fn above(x: f32, y: f32, height: f32) -> Pose {
        // Camera x right = pad x, camera y down = pad -y, camera z forward = pad -z.
        let rotation = Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0);
        Pose {
            rotation,
            translation: rotation * Vector3::new(-x, -y, -height),
        }
    }

    #[test]
    fn centred_over_one_marker_the_margin_is_the_room_around_it_on_the_ground() {
        let camera = qvga();
        // The paper's single 1 m marker from 10 m: the frame's short side covers 2 * 10 *
        // (120 / f) m; the marker takes 1 m of it, leaving half the rest each side.
        let margin = view_margin_m(&above(0.0, 0.0, 10.0), &designs::PAPER_SINGLE, &camera)
            .expect("in view");
        let short_side = 2.0 * 10.0 * 119.5 / camera.fy;
        let expected = 0.5 * (short_side - 1.0);
        assert!((margin - expected).abs() < 0.01, "{margin} vs {expected}");
        // Moved by less than the margin toward the nearest (top or bottom) edge: that much
        // less room; by more: gone.
        let moved = view_margin_m(&above(0.0, 1.0, 10.0), &designs::PAPER_SINGLE, &camera)
            .expect("still in view");
        assert!((moved - (expected - 1.0)).abs() < 0.01, "{moved}");
        assert_eq!(
            view_margin_m(
                &above(0.0, expected + 0.05, 10.0),
                &designs::PAPER_SINGLE,
                &camera
            ),
            None
        );
    }

    #[test]
    fn too_small_or_behind_counts_for_nothing() {
        let camera = qvga();
        // The 1 m marker from 20 km: a pixel wide.
        assert_eq!(
            view_margin_m(&above(0.0, 0.0, 20_000.0), &designs::PAPER_SINGLE, &camera),
            None
        );
        // The camera looking up, away from the pad.
        let mut away = above(0.0, 0.0, 10.0);
        away.rotation = -away.rotation;
        away.translation = -away.translation;
        assert_eq!(view_margin_m(&away, &designs::PAPER_SINGLE, &camera), None);
    }

    #[test]
    fn the_nested_pad_keeps_a_marker_in_view_from_its_top_height_down_to_its_smallest() {
        let camera = qvga();
        // Over the landing point: the marker with the most room changes with height.
        for height in [0.3f32, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0] {
            let margin = view_margin_m(&above(0.0, 0.0, height), &designs::NESTED, &camera);
            assert!(margin.is_some_and(|m| m > 0.0), "{height} m: {margin:?}");
        }
    }

    /// The camera `height` m above the pad point (`x`, `y`), its image top turned `yaw_deg`
    /// counter-clockwise from pad +y.
    fn above_turned(x: f32, y: f32, height: f32, yaw_deg: f32) -> Pose {
        let level = above(x, y, height);
        let (s, c) = libm::sincosf(yaw_deg.to_radians());
        // Turning the camera about its optical axis: camera-frame points turn the other way.
        let turn = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
        Pose {
            rotation: turn * level.rotation,
            translation: turn * level.translation,
        }
    }

    /// Whether some marker of `pad` is in view and decodable from every heading (every 5
    /// degrees of a half turn: the image is a rectangle) and from every point within `radius`
    /// m of the landing point (a grid of a twelfth of it), `height` m up; with `tilt_deg`,
    /// also tilted that much toward each of eight directions.
    fn covered(
        pad: &PadLayout<'_>,
        camera: &CameraModel,
        height: f32,
        radius: f32,
        tilt_deg: f32,
    ) -> bool {
        const STEPS: i32 = 6;
        let step = radius / STEPS as f32;
        // Level, then (with a tilt) a turn about each of eight level axes through the camera,
        // in its frame.
        let tilts = if tilt_deg > 0.0 { 9 } else { 1 };
        let turns: std::vec::Vec<Matrix3<f32>> = (0..tilts)
            .map(|t| {
                let toward = 45f32.to_radians() * t as f32;
                let tilt = if t == 0 { 0.0 } else { tilt_deg.to_radians() };
                let axis = nalgebra::Unit::new_normalize(Vector3::new(
                    libm::cosf(toward),
                    libm::sinf(toward),
                    0.0,
                ));
                *nalgebra::Rotation3::from_axis_angle(&axis, tilt).matrix()
            })
            .collect();
        (-STEPS..=STEPS).all(|i| {
            (-STEPS..=STEPS).all(|j| {
                let (x, y) = (i as f32 * step, j as f32 * step);
                x * x + y * y > radius * radius + 1e-6
                    || (0..36).all(|k| {
                        let pose = above_turned(x, y, height, 5.0 * k as f32);
                        turns.iter().all(|turn| {
                            let tilted = Pose {
                                rotation: turn * pose.rotation,
                                translation: turn * pose.translation,
                            };
                            view_margin_m(&tilted, pad, camera).is_some()
                        })
                    })
            })
        })
    }

    #[test]
    fn the_rest_pad_has_a_marker_in_view_from_the_ground_up() {
        let pad = &designs::NESTED_REST;
        // On the ground: the camera 0.1 m up (or higher landing gear), within 6 cm of the
        // landing point (a lever arm plus a landing's miss), facing anywhere.
        for camera in [qvga(), vga()] {
            for height in [0.1f32, 0.15, 0.2, 0.3] {
                assert!(covered(pad, &camera, height, 0.06, 0.0), "{height} m");
            }
        }
        // In the air: the camera within a tenth of its height of the landing point (a
        // precision landing's approach).
        for (camera, top) in [(qvga(), 20.0f32), (vga(), 30.0)] {
            for height in [0.5f32, 0.7, 1.0, 1.5, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0, 30.0] {
                if height <= top {
                    assert!(
                        covered(pad, &camera, height, (0.1 * height).min(1.0), 0.0),
                        "{height} m, {} px",
                        camera.width
                    );
                }
            }
        }
        // The earlier nested pad has nothing whole in view on the ground.
        assert!(!covered(&designs::NESTED, &qvga(), 0.1, 0.0, 0.0));
    }

    /// The wide lens of the coverage claims: 640x480 behind 100 degrees, with barrel
    /// distortion (the image's corners pulled in by about a tenth).
    fn wide() -> CameraModel {
        let f = 320.0 / libm::tanf(50f32.to_radians());
        let mut camera = CameraModel::pinhole(640, 480, f, f, 319.5, 239.5);
        camera.distortion = [-0.08, 0.01, 0.0, 0.0, 0.0];
        camera
    }

    #[test]
    fn the_field_pad_keeps_a_marker_in_view_30_cm_off_and_tilted() {
        let pad = &designs::NESTED_FIELD;
        // On the ground, as the rest pad.
        for camera in [qvga(), vga(), wide()] {
            for height in [0.1f32, 0.15] {
                assert!(covered(pad, &camera, height, 0.06, 0.0), "{height} m");
            }
        }
        // From 0.2 m up: a vehicle blown 30 cm off the landing point and tilted 10 degrees,
        // facing anywhere, up to where the altitude marker takes over; above, the approach
        // (within a tenth of the height, level).
        for (camera, top) in [(qvga(), 20.0f32), (vga(), 30.0), (wide(), 20.0)] {
            for height in [
                0.2f32, 0.25, 0.3, 0.4, 0.5, 0.7, 1.0, 1.5, 2.0, 3.0, 5.0, 8.0,
            ] {
                assert!(
                    covered(pad, &camera, height, 0.3, 10.0),
                    "{height} m, {} px",
                    camera.width
                );
            }
            for height in [12.0f32, 20.0, 30.0] {
                if height <= top {
                    assert!(
                        covered(pad, &camera, height, 0.1 * height, 0.0),
                        "{height} m"
                    );
                }
            }
        }
        // The rest pad loses its markers over its 0.40 m ones at 0.3 m.
        assert!(!covered(&designs::NESTED_REST, &qvga(), 0.3, 0.3, 0.0));
    }

    /// The envelope docs/setup-ardupilot.md quotes: the recommended pad's view margin with
    /// the camera straight above the landing point, for the 60 degree QVGA and the 70 degree
    /// VGA lens (`cargo test -p touchdown-core --lib envelope -- --nocapture` prints it).
    #[test]
    fn envelope_of_the_recommended_pad() {
        let heights = [
            0.1f32, 0.2, 0.3, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0, 30.0, 40.0,
        ];
        let pad = designs::RECOMMENDED;
        std::println!("| height | 320x240, 60 deg | 640x480, 70 deg |");
        std::println!("|---|---|---|");
        for h in heights {
            let cell = |camera: &CameraModel| match view_margin_m(&above(0.0, 0.0, h), pad, camera)
            {
                Some(m) => std::format!("{m:.2} m"),
                None => std::string::String::from("none"),
            };
            std::println!("| {h} m | {} | {} |", cell(&qvga()), cell(&vga()));
        }
        for h in heights {
            assert!(
                view_margin_m(&above(0.0, 0.0, h), pad, &vga()).is_some(),
                "{h}"
            );
        }
    }
}
