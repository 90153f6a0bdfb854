//! Infinitesimal Plane-based Pose Estimation for a square marker (Collins and Bartoli, "
//! Infinitesimal Plane-Based Pose Estimation", IJCV 2014), written from the paper's math.
//!
//! Why IPPE: four coplanar corners determine the homography `H` from the marker plane to the
//! normalised image exactly, and at any plane point the first-order behaviour of `H` (its
//! 2x2 Jacobian) pins the rotation down up to one reflection. Those two rotations are the
//! two physically plausible poses of a planar target, which iterative PnP solvers only find
//! one of, depending on their start. Returning both lets the caller choose by reprojection
//! error or by a filter's prediction.
//!
//! Steps, at the marker centre (plane origin), which the homography maps to the normalised
//! image point `q0`:
//! 1. `J` = Jacobian of the homography at the origin: with `H` scaled so `h33 = 1`,
//!    `J = [h11 - h13 h31, h12 - h13 h32; h21 - h23 h31, h22 - h23 h32]`, `q0 = (h13, h23)`.
//! 2. Rotate the camera about its centre by `Rv` so the ray through `q0` becomes the optical
//!    axis. In that view the centre is at `(0, 0, d)` and the Jacobian becomes
//!    `A = Rv[0..2, 0..2] J / |(q0, 1)|`; it also equals `B / d` where `B` is the upper-left
//!    2x2 block of the rotated pose's rotation `R'`.
//! 3. The upper-left 2x2 block of the first two columns of a rotation has largest singular
//!    value 1, so `d = 1 / sigma_max(A)` and `B = A / sigma_max(A)`.
//! 4. The third entries `(a, b)` of those two columns satisfy `(a, b)^T (a, b) = I - B^T B`
//!    (orthonormality), a rank-one matrix: `(a, b)` is fixed up to its sign. The two signs
//!    are the two poses; the third column is the cross product of the first two.
//! 5. `R = Rv^T R'`; the translation follows by linear least squares over all four corners
//!    given `R`.
//!
//! Only fixed-size arithmetic (no index comes from input data), so checked indexing is
//! relaxed here.
#![allow(clippy::indexing_slicing)]

use super::{marker_corners, Pose, PoseError};
use crate::geometry::{Homography, Point};
use nalgebra::{Matrix2, Matrix3, Vector3};

/// The two IPPE poses of a square marker of edge `size` from its corners in undistorted
/// normalised image coordinates (contract order). Unrefined, in no particular order.
pub fn square_poses(normalized: &[Point; 4], size: f32) -> Result<[Pose; 2], PoseError> {
    if !(size.is_finite() && size > 0.0) {
        return Err(PoseError::BadMarkerSize);
    }
    let model = marker_corners(size);
    let plane = model.map(|m| Point::new(m.x, m.y));
    let h = Homography::from_4_points(&plane, normalized).ok_or(PoseError::DegenerateCorners)?;
    let m = h.m;
    if !(m[8].abs() > 1e-12) {
        return Err(PoseError::DegenerateCorners);
    }
    let hs = m.map(|v| v / m[8]);
    let q0 = Point::new(hs[2], hs[5]);
    let jacobian = Matrix2::new(
        hs[0] - hs[2] * hs[6],
        hs[1] - hs[2] * hs[7],
        hs[3] - hs[5] * hs[6],
        hs[4] - hs[5] * hs[7],
    );

    // Rv: rotation taking the unit ray through q0 onto the optical axis.
    let s = libm::sqrtf(q0.x * q0.x + q0.y * q0.y + 1.0);
    let ray = Vector3::new(q0.x / s, q0.y / s, 1.0 / s);
    let rv = rotation_onto_z(&ray);
    let a = rv.fixed_view::<2, 2>(0, 0) * jacobian / s;

    let sigma_max = largest_singular_value(&a);
    if !(sigma_max > 1e-12) || !sigma_max.is_finite() {
        return Err(PoseError::DegenerateCorners);
    }
    let b = a / sigma_max;
    let c = b.transpose() * b;
    // (a3, b3) with (a3, b3)^T (a3, b3) = I - C.
    let (e11, e22, e12) = (
        (1.0 - c[(0, 0)]).max(0.0),
        (1.0 - c[(1, 1)]).max(0.0),
        -c[(0, 1)],
    );
    let (third_a, third_b) = if e11 >= e22 {
        let x = libm::sqrtf(e11);
        (x, if x > 1e-12 { e12 / x } else { 0.0 })
    } else {
        let y = libm::sqrtf(e22);
        (if y > 1e-12 { e12 / y } else { 0.0 }, y)
    };

    let mut poses = [Pose::identity(); 2];
    for (pose, sign) in poses.iter_mut().zip([1.0f32, -1.0]) {
        let c1 = Vector3::new(b[(0, 0)], b[(1, 0)], sign * third_a);
        let c2 = Vector3::new(b[(0, 1)], b[(1, 1)], sign * third_b);
        let r_view = orthonormal_from_columns(&c1, &c2).ok_or(PoseError::NoSolution)?;
        let rotation = rv.transpose() * r_view;
        let translation = translation_given_rotation(&rotation, &model, normalized)
            .ok_or(PoseError::NoSolution)?;
        *pose = Pose {
            rotation,
            translation,
        };
    }
    if poses.iter().any(|p| !p.is_valid()) {
        return Err(PoseError::NoSolution);
    }
    Ok(poses)
}

/// The rotation that takes the unit vector `v` onto `(0, 0, 1)` (Rodrigues' formula for
/// aligning two vectors; `v.z > 0` here, so it is never the antiparallel case).
pub(crate) fn rotation_onto_z(v: &Vector3<f32>) -> Matrix3<f32> {
    let z = Vector3::z();
    let k = v.cross(&z);
    let cos = v.dot(&z);
    let kx = k.cross_matrix();
    let denominator = 1.0 + cos;
    if !(denominator > 1e-6) {
        return Matrix3::identity();
    }
    Matrix3::identity() + kx + kx * kx / denominator
}

/// Largest singular value of a 2x2 matrix, closed form.
fn largest_singular_value(a: &Matrix2<f32>) -> f32 {
    let frobenius2 = a.iter().map(|v| v * v).sum::<f32>();
    let det = a.determinant();
    let disc = (frobenius2 * frobenius2 - 4.0 * det * det).max(0.0);
    libm::sqrtf(0.5 * (frobenius2 + libm::sqrtf(disc)))
}

/// A rotation whose first two columns are (Gram-Schmidt orthonormalised) `c1`, `c2`.
pub(crate) fn orthonormal_from_columns(
    c1: &Vector3<f32>,
    c2: &Vector3<f32>,
) -> Option<Matrix3<f32>> {
    let n1 = c1.norm();
    if !(n1 > 1e-9) {
        return None;
    }
    let e1 = c1 / n1;
    let c2o = c2 - e1 * e1.dot(c2);
    let n2 = c2o.norm();
    if !(n2 > 1e-9) {
        return None;
    }
    let e2 = c2o / n2;
    let e3 = e1.cross(&e2);
    let r = Matrix3::from_columns(&[e1, e2, e3]);
    r.iter().all(|v| v.is_finite()).then_some(r)
}

/// Least-squares translation for a known rotation: each normalised point `q` of model point
/// `P` gives two linear equations `[1 0 -qx; 0 1 -qy] (R P + t) = 0`.
pub(crate) fn translation_given_rotation(
    rotation: &Matrix3<f32>,
    model: &[Vector3<f32>],
    normalized: &[Point],
) -> Option<Vector3<f32>> {
    let mut ata = Matrix3::<f32>::zeros();
    let mut atb = Vector3::<f32>::zeros();
    for (p, q) in model.iter().zip(normalized) {
        let rp = rotation * p;
        // Rows of A_i.
        let r1 = Vector3::new(1.0, 0.0, -q.x);
        let r2 = Vector3::new(0.0, 1.0, -q.y);
        ata += r1 * r1.transpose() + r2 * r2.transpose();
        atb -= r1 * r1.dot(&rp) + r2 * r2.dot(&rp);
    }
    let t = ata.try_inverse()? * atb;
    t.iter().all(|v| v.is_finite()).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn project(pose: &Pose, size: f32) -> [Point; 4] {
        marker_corners(size).map(|m| {
            let x = pose.transform(&m);
            Point::new(x.x / x.z, x.y / x.z)
        })
    }

    #[test]
    fn one_of_the_two_solutions_is_exact() {
        for k in 0..40 {
            let a = k as f32 * 0.61;
            let truth = Pose {
                rotation: Rotation3::from_euler_angles(
                    core::f32::consts::PI + 0.6 * libm::sinf(a),
                    0.5 * libm::cosf(1.7 * a),
                    a,
                )
                .into_inner(),
                translation: Vector3::new(0.3 * libm::sinf(a), -0.2, 1.5 + 0.5 * libm::cosf(a)),
            };
            let poses = square_poses(&project(&truth, 0.2), 0.2).unwrap();
            let best = poses
                .iter()
                .map(|p| {
                    (
                        p.rotation_angle_to(&truth),
                        (p.translation - truth.translation).norm(),
                    )
                })
                .fold(
                    (f32::MAX, f32::MAX),
                    |acc, v| if v.0 < acc.0 { v } else { acc },
                );
            assert!(best.0 < 2e-3 && best.1 < 2e-3, "{k}: {best:?}");
        }
    }
}
