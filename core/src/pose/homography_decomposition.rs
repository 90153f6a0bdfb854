//! The paper's pose: decompose the plane-to-image homography as `H = K [r1 r2 t]`
//! (equations 5-7 of the fiducial-landing paper), without refinement.
//!
//! Kept, and selectable as [`PoseMethod::PaperHomography`](super::PoseMethod), only so the
//! paper's tables can be reproduced. It is a single linear estimate: `H` is fitted to the
//! four corners, the scale comes from the norms of its first two columns (their mean, since
//! with noise they differ), `r3 = r1 x r2`, and the resulting matrix is projected onto the
//! nearest rotation (SVD). It ignores which of the two planar solutions is right and does
//! not minimise any image error, which is why touchdown uses [`ippe`](super::ippe) and
//! [`levenberg_marquardt`](super::levenberg_marquardt) instead.
//!
//! The corners are taken in undistorted normalised coordinates, i.e. `K^-1 H` directly: for a
//! distortion-free camera, the paper's setup, that is exactly its equation.
//!
//! Only fixed-size arithmetic (no index comes from input data), so checked indexing is
//! relaxed here.
#![allow(clippy::indexing_slicing)]

use super::{marker_corners, Pose, PoseError};
use crate::geometry::{Homography, Point};
use nalgebra::{Matrix3, Vector3};

/// Iteration cap of the SVD that projects the estimate onto the rotations.
pub const SVD_MAX_ITERATIONS: usize = 100;

/// The paper's pose of a square marker of edge `size` from its corners in undistorted
/// normalised image coordinates (contract order).
pub fn paper_pose(normalized: &[Point; 4], size: f32) -> Result<Pose, PoseError> {
    if !(size.is_finite() && size > 0.0) {
        return Err(PoseError::BadMarkerSize);
    }
    let plane = marker_corners(size).map(|m| Point::new(m.x, m.y));
    let h = Homography::from_4_points(&plane, normalized).ok_or(PoseError::DegenerateCorners)?;
    let m = h.m;
    let h1 = Vector3::new(m[0], m[3], m[6]);
    let h2 = Vector3::new(m[1], m[4], m[7]);
    let h3 = Vector3::new(m[2], m[5], m[8]);
    let mean_norm = 0.5 * (h1.norm() + h2.norm());
    if !(mean_norm > 1e-12) {
        return Err(PoseError::DegenerateCorners);
    }
    // The sign is chosen so the marker is in front of the camera.
    let lambda = if h3.z >= 0.0 { 1.0 } else { -1.0 } / mean_norm;
    let r1 = h1 * lambda;
    let r2 = h2 * lambda;
    let translation = h3 * lambda;
    let estimate = Matrix3::from_columns(&[r1, r2, r1.cross(&r2)]);
    let svd = estimate
        .try_svd(true, true, 1e-7, SVD_MAX_ITERATIONS)
        .ok_or(PoseError::NoSolution)?;
    let (u, v_t) = (
        svd.u.ok_or(PoseError::NoSolution)?,
        svd.v_t.ok_or(PoseError::NoSolution)?,
    );
    let mut rotation = u * v_t;
    if rotation.determinant() < 0.0 {
        let flip = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
        rotation = u * flip * v_t;
    }
    let pose = Pose {
        rotation,
        translation,
    };
    if pose.is_valid() {
        Ok(pose)
    } else {
        Err(PoseError::NoSolution)
    }
}
