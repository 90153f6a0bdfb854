//! Levenberg-Marquardt refinement of a pose on the pixel reprojection error.
//!
//! Why: closed-form starts (IPPE, homography) minimise an algebraic error in undistorted
//! coordinates; what the detector measured, with roughly equal noise per corner, is pixels
//! in the distorted image. Minimising the squared pixel distances (lens distortion inside the
//! model) is the maximum-likelihood pose under isotropic corner noise, and its Gauss-Newton
//! normal matrix `J^T J` is the information matrix the covariance of [`PadFix`] comes from.
//!
//! Parameters: a rotation increment `w` applied on the left (`R <- exp([w]x) R`, camera
//! frame) and a translation increment (`t <- t + dt`), in that order, six in all. Damping is
//! Marquardt's (scaled diagonal). The iteration count is capped at [`MAX_ITERATIONS`] and
//! the damping at [`MAX_DAMPING`]; the normal equations are accumulated point by point, so
//! any number of points costs no memory.
//!
//! [`PadFix`]: super::PadFix
//!
//! Only fixed-size arithmetic (no index comes from input data), so checked indexing is
//! relaxed here.
#![allow(clippy::indexing_slicing)]

use super::{Pose, PoseError};
use crate::camera::CameraModel;
use crate::geometry::Point;
use nalgebra::{Cholesky, Matrix2x3, Matrix2x6, Matrix3, Matrix6, Rotation3, Vector3, Vector6};

/// Most Levenberg-Marquardt iterations (accepted or rejected steps).
pub const MAX_ITERATIONS: usize = 30;
/// Damping beyond which the refinement gives up improving.
pub const MAX_DAMPING: f32 = 1e8;
/// Relative cost decrease below which the refinement has converged.
pub const RELATIVE_TOLERANCE: f32 = 1e-7;

/// A refined pose and the statistics of its fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refined {
    /// The pose.
    pub pose: Pose,
    /// Root-mean-square reprojection error, pixels.
    pub rms_px: f32,
    /// Sum of squared pixel residuals.
    pub sum_squared: f32,
    /// `J^T J` at the pose (parameters: left rotation increment, then translation).
    pub information: Matrix6<f32>,
    /// Number of points used.
    pub points: usize,
    /// Iterations run.
    pub iterations: usize,
}

impl Refined {
    /// Pose covariance (order: rotation increment in the camera frame, radians; then
    /// translation, metres) `(J^T J)^-1 sigma^2`, with the pixel noise `sigma` estimated from
    /// the residuals (`sum / (2n - 6)`) but not below `sigma_floor_px`; `None` when `J^T J` is
    /// singular (the pose is unobservable).
    pub fn covariance(&self, sigma_floor_px: f32) -> Option<Matrix6<f32>> {
        let dof = (2 * self.points).saturating_sub(6);
        let floor2 = sigma_floor_px * sigma_floor_px;
        let sigma2 = if dof > 0 {
            (self.sum_squared / dof as f32).max(floor2)
        } else {
            floor2
        };
        let inverse = Cholesky::new(self.information)?.inverse();
        // Symmetrise away rounding.
        let covariance = (inverse + inverse.transpose()) * (0.5 * sigma2);
        covariance
            .iter()
            .all(|v| v.is_finite())
            .then_some(covariance)
    }
}

/// Cost, `J^T J` and `J^T r` of `pose`; `None` when a point is behind the camera.
fn normal_equations(
    camera: &CameraModel,
    pose: &Pose,
    model: &[Vector3<f32>],
    image: &[Point],
) -> Option<(f32, Matrix6<f32>, Vector6<f32>)> {
    let mut cost = 0.0f32;
    let mut jtj = Matrix6::<f32>::zeros();
    let mut jtr = Vector6::<f32>::zeros();
    for (m, observed) in model.iter().zip(image) {
        let rotated = pose.rotation * m;
        let (pixel, d_pixel) = camera.project_with_jacobian(&(rotated + pose.translation))?;
        let r = nalgebra::Vector2::new(pixel.x - observed.x, pixel.y - observed.y);
        // d(point)/d(w) = -[R m]x ; d(point)/d(t) = I.
        let d_rot: Matrix2x3<f32> = d_pixel * (-rotated.cross_matrix());
        let mut j = Matrix2x6::<f32>::zeros();
        j.fixed_view_mut::<2, 3>(0, 0).copy_from(&d_rot);
        j.fixed_view_mut::<2, 3>(0, 3).copy_from(&d_pixel);
        jtj += j.transpose() * j;
        jtr += j.transpose() * r;
        cost += r.norm_squared();
    }
    (cost.is_finite() && jtj.iter().all(|v| v.is_finite())).then_some((cost, jtj, jtr))
}

/// Applies a parameter step to a pose.
fn step(pose: &Pose, delta: &Vector6<f32>) -> Pose {
    let w = Vector3::new(delta[0], delta[1], delta[2]);
    let dt = Vector3::new(delta[3], delta[4], delta[5]);
    Pose {
        rotation: Rotation3::new(w).into_inner() * pose.rotation,
        translation: pose.translation + dt,
    }
}

/// Re-orthonormalises a rotation that picked up rounding (Gram-Schmidt on its columns).
fn orthonormalise(r: &Matrix3<f32>) -> Matrix3<f32> {
    let c1 = r.column(0).into_owned();
    let c2 = r.column(1).into_owned();
    super::ippe::orthonormal_from_columns(&c1, &c2).unwrap_or(*r)
}

/// Refines `initial` on matching model points (pose frame, metres) and observed pixels.
pub fn refine(
    camera: &CameraModel,
    model: &[Vector3<f32>],
    image: &[Point],
    initial: &Pose,
) -> Result<Refined, PoseError> {
    if model.len() != image.len() || model.len() < 4 {
        return Err(PoseError::BadPointCount);
    }
    let mut pose = *initial;
    let (mut cost, mut jtj, mut jtr) =
        normal_equations(camera, &pose, model, image).ok_or(PoseError::NoSolution)?;
    let mut damping = 1e-3f32;
    let mut iterations = 0;
    while iterations < MAX_ITERATIONS {
        iterations += 1;
        let mut a = jtj;
        for i in 0..6 {
            a[(i, i)] += damping * (jtj[(i, i)] + 1e-9);
        }
        let accepted = Cholesky::new(a).and_then(|chol| {
            let delta = chol.solve(&(-jtr));
            let candidate = step(&pose, &delta);
            let (c, j, r) = normal_equations(camera, &candidate, model, image)?;
            (c < cost).then_some((candidate, c, j, r, delta))
        });
        match accepted {
            Some((candidate, c, j, r, delta)) => {
                let improvement = cost - c;
                pose = candidate;
                cost = c;
                jtj = j;
                jtr = r;
                damping = (damping * 0.1).max(1e-9);
                let small_step = delta.norm() < 1e-7 * (1.0 + pose.translation.norm());
                if improvement <= RELATIVE_TOLERANCE * cost || small_step {
                    break;
                }
            }
            None => {
                damping *= 10.0;
                if damping > MAX_DAMPING {
                    break;
                }
            }
        }
    }
    pose.rotation = orthonormalise(&pose.rotation);
    if !pose.is_valid() {
        return Err(PoseError::NoSolution);
    }
    let points = model.len();
    Ok(Refined {
        pose,
        rms_px: libm::sqrtf(cost / points as f32),
        sum_squared: cost,
        information: jtj,
        points,
        iterations,
    })
}
