//! The pad pose with the tilt taken from gravity.
//!
//! A flat pad's tilt relative to the camera is what a single small marker measures worst: at
//! 20 m a 1 m marker spans ~28 pixels, and the image barely tells a slight tilt from a
//! slightly smaller distance, so the six-parameter fit trades one for the other and the
//! altitude comes out biased low (by roughly `d * tilt^2 / 2`: centimetres at 20-25 m in the
//! paper geometry). The vehicle's attitude knows the camera's tilt to a
//! fraction of a degree. [`level_pad_fix`] keeps only the heading of the image fix (well
//! observed: it is the marker's in-image rotation), takes the tilt from the attitude, and
//! re-solves the translation by linear least squares over every corner of every layout
//! marker. The result is unbiased in altitude and its covariance no longer carries the
//! tilt-range coupling.
//!
//! # The row rate
//!
//! On a rolling-shutter camera each row is exposed at its own time. The pipeline moves the
//! corners for the body rates the autopilot reports, but the mount's vibration (50-200 Hz,
//! far above any attitude stream) is still turning the camera while the marker's rows are
//! read out. Over a small marker's few hundred microseconds of rows that turn is a constant
//! rate: the bottom corners are displaced against the top ones, in proportion to their row.
//! Vertically that stretches the marker and reads as a range error (at 20 m, 0.3 % of range
//! per tenth of a pixel on a 28-pixel marker); horizontally it shears it. The solve therefore
//! carries two nuisance unknowns, the image displacement per row (`a`, `b`, normalised units
//! per normalised row), beside the translation: the range then comes from what a rate cannot
//! change, the widths along each row. A prior ([`ROW_RATE_PRIOR_RAD_S`]) keeps them
//! defined when the corners span few rows; on a global-shutter camera
//! ([`CameraModel::line_time_us`] 0) they are held at zero.
//!
//! `camera_from_level` is the rotation from a level frame (z up against gravity, any
//! heading) to the camera frame; with the vehicle attitude `R_ned_from_body` and the mount
//! `R_body_from_camera`, it is `(R_ned_from_body R_body_from_camera)^T R_ned_from_level`,
//! where `R_ned_from_level` maps (x, y, z-up) to NED, e.g. x = north, y = west, z = up.
// Fixed 3x3/6x6 matrix indices and the two image axes only, never from data.
#![allow(clippy::indexing_slicing)]

use super::pad_pose::{layout_marker, PadFix, PIXEL_NOISE_FLOOR_PX};
use super::{marker_corners, Pose, PoseError};
use crate::camera::CameraModel;
use crate::detect::Detection;
use crate::family::Family;
use crate::pad::PadLayout;
use nalgebra::{Matrix3, Vector3};

/// The prior on the camera's residual turn rate over the readout (rad/s, one sigma per
/// axis): the mount's vibration, what the rolling-shutter correction from the autopilot's
/// rates cannot see. 25 deg/s RMS, the gyro noise a balanced small multicopter logs in
/// flight (0.03 degrees RMS at 50-200 Hz). The prior is the vibration's own size, not looser:
/// on markers of under ~35 pixels the shape tells a rate from the corners' own errors
/// poorly, and a looser prior (1 and 3 rad/s were measured) reads the far rows worse.
pub const ROW_RATE_PRIOR_RAD_S: f32 = 0.44;

/// One corner's equation along one image axis: `t_part . t + s * rate = b`, the rate being
/// the row rate along that axis (see the module docs).
#[derive(Clone, Copy)]
struct Equation {
    t_part: Vector3<f32>,
    /// The image axis: 0 = x (the rate that shears), 1 = y (rows: the rate that stretches).
    axis: usize,
    /// The corner's row against the corners' mean row, normalised units (0: no rates).
    s: f32,
    b: f32,
}

/// Re-solves `fix` with the pad's tilt from gravity (see the module docs). The covariance's
/// rotation part is the heading variance of `fix` about the vertical (the tilt is known); the
/// translation part comes from the linear solve; cross terms are dropped.
pub fn level_pad_fix(
    fix: &PadFix,
    detections: &[Detection],
    families: &[&Family<'_>],
    layout: &PadLayout<'_>,
    camera: &CameraModel,
    camera_from_level: &Matrix3<f32>,
) -> Result<PadFix, PoseError> {
    // Heading of the pad in the level frame, from the image fix: M = C^T R should be a
    // rotation about z; its first column gives the angle.
    let m = camera_from_level.transpose() * fix.pose.rotation;
    let (c, s) = (m[(0, 0)], m[(1, 0)]);
    let norm = libm::sqrtf(c * c + s * s);
    if !(norm > 1e-3) {
        return Err(PoseError::NoSolution);
    }
    let (c, s) = (c / norm, s / norm);
    let heading = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
    let rotation = camera_from_level * heading;

    // The row rates' column for each corner: its row against the corners' mean row, in
    // normalised units (so that the rates do not move the pad, only shape it), or nothing on
    // a global-shutter camera.
    let rolling = camera.line_time_us > 0.0 && camera.fy > 0.0;
    let mut row_sum = 0.0f32;
    let mut row_count = 0usize;
    for detection in detections {
        if layout_marker(layout, families, detection).is_some() {
            for corner in &detection.corners {
                row_sum += corner.y;
                row_count += 1;
            }
        }
    }
    let mean_row = if row_count > 0 {
        row_sum / row_count as f32
    } else {
        0.0
    };
    // The prior as two pseudo-observations, weighted against the pixel noise floor: a rate of
    // one prior sigma displaces a row by `ROW_RATE_PRIOR_RAD_S * line_time` radians (one
    // normalised unit of row is `fy` rows).
    let focal = 0.5 * (camera.fx + camera.fy);
    let noise_normalised = PIXEL_NOISE_FLOOR_PX / focal;
    let prior_sigma = ROW_RATE_PRIOR_RAD_S * camera.line_time_us * 1e-6 * camera.fy;
    let prior_weight = if rolling && prior_sigma > 0.0 {
        noise_normalised / prior_sigma
    } else {
        1.0
    };

    // Two passes: the first finds the depths, the second weights each corner's equations by
    // 1/depth so that the residuals are normalised image errors. Each equation is
    // `t_part . t + s * rate[axis] = b`, with one row rate per image axis. The rates are
    // eliminated in closed form (their normal block is diagonal): what is left is a 3x3 solve
    // for the translation, whose inverse is also the translation's covariance with the rates
    // free (the Schur complement), and which has no panic path (a general 5x5 inverse has).
    let mut translation = fix.pose.translation;
    let mut schur_inverse = Matrix3::<f32>::zeros();
    let mut residual_sq = 0.0f32;
    let mut equations = 0usize;
    for _ in 0..2 {
        let mut normal = Matrix3::<f32>::zeros();
        let mut rhs = Vector3::<f32>::zeros();
        // Per image axis: the rate's normal entry (the prior's included), its coupling with
        // the translation and its right-hand side.
        let mut rate_normal = [prior_weight * prior_weight; 2];
        let mut coupling = [Vector3::<f32>::zeros(); 2];
        let mut rate_rhs = [0.0f32; 2];
        let mut rows: heapless::Vec<Equation, { 2 * super::pad_pose::MAX_PAD_POINTS }> =
            heapless::Vec::new();
        for detection in detections {
            let Some(marker) = layout_marker(layout, families, detection) else {
                continue;
            };
            for (corner, model) in detection.corners.iter().zip(marker_corners(marker.size)) {
                let Some(n) = camera.undistort(*corner) else {
                    continue;
                };
                let p = rotation * marker.to_pad(&model);
                let depth = (p + translation).z;
                if !(depth > 1e-3) {
                    return Err(PoseError::NoSolution);
                }
                let w = 1.0 / depth;
                let s = if rolling {
                    (corner.y - mean_row) / camera.fy
                } else {
                    0.0
                };
                // n - rate * s is where the corner would be without the turn during readout.
                let pair = [
                    Equation {
                        t_part: Vector3::new(w, 0.0, -n.x * w),
                        axis: 0,
                        s,
                        b: (n.x * p.z - p.x) * w,
                    },
                    Equation {
                        t_part: Vector3::new(0.0, w, -n.y * w),
                        axis: 1,
                        s,
                        b: (n.y * p.z - p.y) * w,
                    },
                ];
                for equation in pair {
                    normal += equation.t_part * equation.t_part.transpose();
                    rhs += equation.t_part * equation.b;
                    let axis = equation.axis;
                    rate_normal[axis] += s * s;
                    coupling[axis] += equation.t_part * s;
                    rate_rhs[axis] += s * equation.b;
                    let _ = rows.push(equation);
                }
            }
        }
        equations = rows.len();
        // Eliminate the rates (each `rate_normal` is at least the prior's, > 0).
        let mut schur = normal;
        let mut reduced = rhs;
        for axis in 0..2 {
            let (d, c, r) = (rate_normal[axis], coupling[axis], rate_rhs[axis]);
            schur -= c * c.transpose() / d;
            reduced -= c * (r / d);
        }
        schur_inverse = schur.try_inverse().ok_or(PoseError::NoSolution)?;
        translation = schur_inverse * reduced;
        let rates = [0, 1]
            .map(|axis| (rate_rhs[axis] - coupling[axis].dot(&translation)) / rate_normal[axis]);
        residual_sq = rows
            .iter()
            .map(|equation| {
                let e = equation.t_part.dot(&translation)
                    + equation.s * rates.get(equation.axis).copied().unwrap_or(0.0)
                    - equation.b;
                e * e
            })
            .sum();
    }
    if equations < 6 || !translation.iter().all(|v| v.is_finite()) {
        return Err(PoseError::NoSolution);
    }
    let rms_normalised = libm::sqrtf(residual_sq / equations as f32);
    let sigma = rms_normalised.max(noise_normalised);
    let translation_cov = schur_inverse * (sigma * sigma);
    // Rotation: only the heading is still uncertain, a rotation about the vertical, which is
    // `up` in the camera frame (the covariance is over left increments in the camera frame).
    // Its variance is the image fix's along that axis; the tilt's is gone.
    let up = camera_from_level * Vector3::new(0.0, 0.0, 1.0);
    // Element by element: `fixed_view(..).into_owned()` keeps a panic path (see nopanic/).
    let rotation_cov = Matrix3::from_fn(|r, c| fix.covariance.get((r, c)).copied().unwrap_or(0.0));
    let heading_var = up.dot(&(rotation_cov * up)).max(0.0);
    let heading_cov = up * up.transpose() * heading_var;
    let mut covariance = nalgebra::Matrix6::<f32>::zeros();
    for r in 0..3 {
        for k in 0..3 {
            covariance[(r, k)] = heading_cov[(r, k)];
            covariance[(r + 3, k + 3)] = translation_cov[(r, k)];
        }
    }
    Ok(PadFix {
        pose: Pose {
            rotation,
            translation,
        },
        covariance,
        markers_used: fix.markers_used,
        reprojection_rms_px: rms_normalised * focal,
        alternative_rms_px: fix.alternative_rms_px,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::family::tables;
    use crate::geometry::Point;
    use crate::pad::designs;
    use crate::pose::pad_pose;

    /// The paper's camera (640x480, f = 554.3 px) with the OV7725's VGA readout, 30.5 ms.
    fn camera(line_time_us: f32) -> CameraModel {
        let mut camera = CameraModel::pinhole(640, 480, 554.3, 554.3, 319.5, 239.5);
        camera.line_time_us = line_time_us;
        camera
    }

    /// Straight down: the level frame's x (north) is the image's right, its y (west) the
    /// image's up, its z (up) against the optical axis.
    fn down() -> Matrix3<f32> {
        Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0)
    }

    /// The paper's 1 m marker seen from 20 m (about 28 pixels across), its rows displaced by
    /// a turn during readout: `(shear, stretch)` pixels per row, from the marker's mean row.
    fn detection_at_20_m(shear: f32, stretch: f32) -> Detection {
        let camera = camera(0.0);
        let translation = Vector3::new(0.3, -0.2, 20.0);
        let corners = marker_corners(1.0).map(|model| {
            camera
                .project(&(down() * model + translation))
                .unwrap_or(Point { x: 0.0, y: 0.0 })
        });
        let mean_row = corners.iter().map(|c| c.y).sum::<f32>() / 4.0;
        let corners = corners.map(|c| Point {
            x: c.x + shear * (c.y - mean_row),
            y: c.y + stretch * (c.y - mean_row),
        });
        Detection {
            family: 0,
            id: 0,
            hamming: 0,
            corners,
            center: Point {
                x: corners.iter().map(|c| c.x).sum::<f32>() / 4.0,
                y: mean_row,
            },
            decision_margin: 1.0,
            contrast: 100.0,
        }
    }

    /// The levelled fix's range (the camera's height above the pad), metres.
    fn levelled_range(detection: Detection, camera: &CameraModel) -> f32 {
        let families = [tables::by_name("aruco_6x6_250").unwrap()];
        let detections = [detection];
        let layout = designs::PAPER_SINGLE;
        let fix = pad_pose(&detections, &families, &layout, camera).unwrap();
        let level = level_pad_fix(&fix, &detections, &families, &layout, camera, &down()).unwrap();
        level.pose.translation.z
    }

    #[test]
    fn a_turn_during_readout_does_not_change_the_range() {
        // 0.2 pixels of stretch over the marker's 28 rows: 0.36 % of range if it were read
        // as scale (7 cm at 20 m), as a global-shutter solve does. The rate's prior keeps
        // about half of a stretch this large (over two prior sigmas) on a marker this small.
        let stretched = detection_at_20_m(0.0, 0.2 / 27.7);
        let global = levelled_range(stretched, &camera(0.0));
        let rolling = levelled_range(stretched, &camera(63.5));
        assert!((global - 20.0).abs() > 0.05, "global {global}");
        assert!(
            (rolling - 20.0).abs() < 0.55 * (global - 20.0).abs(),
            "rolling {rolling} global {global}"
        );
        // A shear alone costs the range nothing either way.
        let sheared = detection_at_20_m(0.3 / 27.7, 0.0);
        assert!((levelled_range(sheared, &camera(63.5)) - 20.0).abs() < 0.005);
    }

    #[test]
    fn without_a_turn_the_row_rates_change_nothing() {
        let still = detection_at_20_m(0.0, 0.0);
        let global = levelled_range(still, &camera(0.0));
        let rolling = levelled_range(still, &camera(63.5));
        assert!((global - 20.0).abs() < 1e-3, "global {global}");
        assert!((rolling - global).abs() < 1e-3, "rolling {rolling}");
    }
}
