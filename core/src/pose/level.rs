//! The pad pose with the tilt taken from gravity.
//!
//! A flat pad's tilt relative to the camera is what a single small marker measures worst: at
//! 20 m a 1 m marker spans ~28 pixels, and the image barely tells a slight tilt from a
//! slightly smaller distance, so the six-parameter fit trades one for the other and the
//! altitude comes out biased low (by roughly `d * tilt^2 / 2`; measured 4 cm at 20 m and 12
//! cm at 25 m in the paper geometry). The vehicle's attitude knows the camera's tilt to a
//! fraction of a degree. [`level_pad_fix`] keeps only the heading of the image fix (well
//! observed: it is the marker's in-image rotation), takes the tilt from the attitude, and
//! re-solves the translation by linear least squares over every corner of every layout
//! marker. The result is unbiased in altitude and its covariance no longer carries the
//! tilt-range coupling.
//!
//! `camera_from_level` is the rotation from a level frame (z up against gravity, any
//! heading) to the camera frame; with the vehicle attitude `R_ned_from_body` and the mount
//! `R_body_from_camera`, it is `(R_ned_from_body R_body_from_camera)^T R_ned_from_level`,
//! where `R_ned_from_level` maps (x, y, z-up) to NED, e.g. x = north, y = west, z = up.
// Fixed 3x3/6x6 matrix indices only, never from data.
#![allow(clippy::indexing_slicing)]

use super::pad_pose::{layout_marker, PadFix, PIXEL_NOISE_FLOOR_PX};
use super::{marker_corners, Pose, PoseError};
use crate::camera::CameraModel;
use crate::detect::Detection;
use crate::family::Family;
use crate::pad::PadLayout;
use nalgebra::{Matrix3, Vector3};

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

    // Two passes: the first finds the depths, the second weights each corner's equations by
    // 1/depth so that the residuals are normalised image errors.
    let mut translation = fix.pose.translation;
    let mut normal = Matrix3::<f32>::zeros();
    let mut residual_sq = 0.0f32;
    let mut equations = 0usize;
    for _ in 0..2 {
        normal = Matrix3::zeros();
        let mut rhs = Vector3::<f32>::zeros();
        let mut rows: heapless::Vec<(Vector3<f32>, f32), { 2 * super::pad_pose::MAX_PAD_POINTS }> =
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
                for (row, b) in [
                    (Vector3::new(w, 0.0, -n.x * w), (n.x * p.z - p.x) * w),
                    (Vector3::new(0.0, w, -n.y * w), (n.y * p.z - p.y) * w),
                ] {
                    normal += row * row.transpose();
                    rhs += row * b;
                    let _ = rows.push((row, b));
                }
            }
        }
        let inverse = normal.try_inverse().ok_or(PoseError::NoSolution)?;
        translation = inverse * rhs;
        residual_sq = rows
            .iter()
            .map(|(row, b)| {
                let e = row.dot(&translation) - b;
                e * e
            })
            .sum();
        equations = rows.len();
    }
    if equations < 6 || !translation.iter().all(|v| v.is_finite()) {
        return Err(PoseError::NoSolution);
    }
    let focal = 0.5 * (camera.fx + camera.fy);
    let rms_normalised = libm::sqrtf(residual_sq / equations as f32);
    let sigma = rms_normalised.max(PIXEL_NOISE_FLOOR_PX / focal);
    let translation_cov = normal.try_inverse().ok_or(PoseError::NoSolution)? * (sigma * sigma);
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
