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

/// Relative cost increase of a rejected step below which the cost is flat within rounding
/// (a sum of squares in f32 carries a few units of its last place, 1e-7 each): the
/// refinement has converged.
pub const FLAT_COST_TOLERANCE: f32 = 1e-5;
/// Absolute cost increase (squared pixels) below which a rejected step is flat, for fits
/// that are exact to rounding (noise-free points): 1e-8 px^2 is 1e-4 px of residual.
pub const FLAT_COST_FLOOR_PX2: f32 = 1e-8;

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
    let mut jtj = SymmetricAccumulator::default();
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
        jtj.add(&j);
        jtr += j.transpose() * r;
        cost += r.norm_squared();
    }
    let jtj = jtj.matrix();
    // Any infinite or NaN entry makes the sum infinite or NaN: one test instead of 36.
    (cost.is_finite() && jtj.sum().is_finite()).then_some((cost, jtj, jtr))
}

/// `J^T J` summed over points, its upper triangle only (21 of the 36 entries: the matrix is
/// symmetric). Each entry is summed as `J^T J` of nalgebra forms it, so the result is the
/// same to the bit.
#[derive(Default)]
struct SymmetricAccumulator {
    upper: [f32; 21],
}

impl SymmetricAccumulator {
    /// Adds `J^T J` of one point's 2x6 Jacobian.
    fn add(&mut self, j: &Matrix2x6<f32>) {
        let mut k = 0;
        for a in 0..6 {
            for b in a..6 {
                self.upper[k] += j[(0, a)] * j[(0, b)] + j[(1, a)] * j[(1, b)];
                k += 1;
            }
        }
    }

    /// The whole symmetric matrix.
    fn matrix(&self) -> Matrix6<f32> {
        let mut m = Matrix6::zeros();
        let mut k = 0;
        for a in 0..6 {
            for b in a..6 {
                m[(a, b)] = self.upper[k];
                m[(b, a)] = self.upper[k];
                k += 1;
            }
        }
        m
    }
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
        let tried = Cholesky::new(a).and_then(|chol| {
            let delta = chol.solve(&(-jtr));
            let candidate = step(&pose, &delta);
            let (c, j, r) = normal_equations(camera, &candidate, model, image)?;
            Some((candidate, c, j, r, delta))
        });
        match tried {
            Some((candidate, c, j, r, delta)) if c < cost => {
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
            // A step that leaves the cost where it is, within the rounding of its sum, was
            // taken at the minimum: more damping would only shorten it (at one more
            // evaluation each, up to seventeen from the smallest damping to the largest).
            Some((_, c, ..)) if c - cost <= FLAT_COST_TOLERANCE * cost + FLAT_COST_FLOOR_PX2 => {
                break;
            }
            _ => {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The triangle accumulator gives nalgebra's `J^T J` sum to the bit.
    #[test]
    fn symmetric_accumulator_matches_the_full_product() {
        let mut seed = 7u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 * 2000.0 - 1000.0
        };
        let mut full = Matrix6::<f32>::zeros();
        let mut triangle = SymmetricAccumulator::default();
        for _ in 0..50 {
            let j = Matrix2x6::from_fn(|_, _| next());
            full += j.transpose() * j;
            triangle.add(&j);
        }
        let got = triangle.matrix();
        for (a, b) in full.iter().zip(got.iter()) {
            assert_eq!(a.to_bits(), b.to_bits(), "{a} vs {b}");
        }
    }
}
