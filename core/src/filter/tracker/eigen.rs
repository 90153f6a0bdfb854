//! Eigen-decomposition of a symmetric 3x3 matrix (cyclic Jacobi), with which the tracker
//! floors a measurement covariance's eigenvalues.
//!
//! Separate because it is general linear algebra, kept here instead of nalgebra's for the
//! no-panic guarantee (see [`symmetric_eigen3`]), with a test against nalgebra's.

use nalgebra::{Matrix3, Vector3};

/// Iteration bound of the 3x3 symmetric eigen-decomposition (converges in a handful).
const EIGEN_MAX_ITERATIONS: usize = 64;

/// Eigen-decomposition of a symmetric 3x3 matrix.
pub(super) struct Eigen3 {
    pub(super) eigenvalues: Vector3<f32>,
    /// Unit eigenvectors, as columns, in the order of the eigenvalues.
    pub(super) eigenvectors: Matrix3<f32>,
}

/// Cyclic Jacobi eigen-decomposition of a symmetric 3x3 matrix: `None` when it is not finite.
///
/// Used instead of `nalgebra::SymmetricEigen`, whose bounds-checked indexing inside its QR
/// iterations leaves panic paths in the firmware (the no-panic link check, nopanic/, needs
/// none); for a 3x3 covariance this is as accurate (both to f32 rounding) and as fast. Each
/// rotation zeroes one off-diagonal pair; the off-diagonal mass falls quadratically, so a
/// handful of sweeps reach rounding level and [`EIGEN_MAX_ITERATIONS`] is never the limit for
/// finite input.
pub(super) fn symmetric_eigen3(a: &Matrix3<f32>) -> Option<Eigen3> {
    if !a.iter().all(|v| v.is_finite()) {
        return None;
    }
    let mut a = *a;
    let mut v = Matrix3::<f32>::identity();
    for _ in 0..EIGEN_MAX_ITERATIONS {
        let off = a.m12 * a.m12 + a.m13 * a.m13 + a.m23 * a.m23;
        let diag = a.m11 * a.m11 + a.m22 * a.m22 + a.m33 * a.m33;
        if !(off > f32::EPSILON * f32::EPSILON * diag) {
            break; // also ends on an all-zero matrix
        }
        jacobi_rotate(&mut a, &mut v, 0, 1);
        jacobi_rotate(&mut a, &mut v, 0, 2);
        jacobi_rotate(&mut a, &mut v, 1, 2);
    }
    let eigenvalues = Vector3::new(a.m11, a.m22, a.m33);
    if !(eigenvalues.iter().chain(v.iter()).all(|x| x.is_finite())) {
        return None;
    }
    Some(Eigen3 {
        eigenvalues,
        eigenvectors: v,
    })
}

/// One Jacobi rotation in the (p, q) plane (p < q < 3): `a <- Jᵀ a J` with `a[p][q]` zeroed,
/// `v <- v J` accumulating the eigenvectors.
#[inline(always)]
fn jacobi_rotate(a: &mut Matrix3<f32>, v: &mut Matrix3<f32>, p: usize, q: usize) {
    let (Some(&apq), Some(&app), Some(&aqq)) = (a.get((p, q)), a.get((p, p)), a.get((q, q))) else {
        return;
    };
    if apq == 0.0 {
        return;
    }
    // tan of the rotation angle, the smaller root of t² + 2θt - 1 = 0 (stable form).
    let theta = (aqq - app) / (2.0 * apq);
    let t = if theta.abs() > 1.0e18 {
        0.5 / theta // θ² would overflow; t ≈ 1/(2θ)
    } else {
        let root = libm::sqrtf(theta * theta + 1.0);
        if theta >= 0.0 {
            1.0 / (theta + root)
        } else {
            -1.0 / (-theta + root)
        }
    };
    let c = 1.0 / libm::sqrtf(t * t + 1.0);
    let s = t * c;
    let mut j = Matrix3::<f32>::identity();
    for (index, value) in [((p, p), c), ((q, q), c), ((p, q), s), ((q, p), -s)] {
        if let Some(slot) = j.get_mut(index) {
            *slot = value;
        }
    }
    *a = j.transpose() * *a * j;
    for index in [(p, q), (q, p)] {
        if let Some(slot) = a.get_mut(index) {
            *slot = 0.0;
        }
    }
    *v *= j;
}

#[cfg(test)]
mod tests {
    use super::super::kf::symmetrised3;
    use super::*;

    /// The Jacobi decomposition agrees with nalgebra's: same eigenvalues, and it rebuilds
    /// the matrix (covariances of every shape: isotropic, flat, needle, rotated, singular).
    #[test]
    fn jacobi_eigen_matches_nalgebra() {
        let rotation = nalgebra::Rotation3::from_euler_angles(0.3, -1.1, 2.0);
        let cases = [
            Matrix3::identity() * 0.01,
            Matrix3::from_diagonal(&Vector3::new(1.0e-4, 2.0e-4, 5.0)),
            Matrix3::from_diagonal(&Vector3::new(3.0, 1.0e-6, 1.0e-6)),
            rotation.matrix()
                * Matrix3::from_diagonal(&Vector3::new(0.5, 2.0e-3, 1.0e-5))
                * rotation.matrix().transpose(),
            rotation.matrix()
                * Matrix3::from_diagonal(&Vector3::new(0.0, 1.0, 1.0))
                * rotation.matrix().transpose(),
            Matrix3::new(4.0, 1.0, 0.5, 1.0, 3.0, -0.25, 0.5, -0.25, 2.0),
            Matrix3::zeros(),
        ];
        for m in cases {
            let m = symmetrised3(&m);
            let ours = symmetric_eigen3(&m).unwrap();
            let theirs = nalgebra::SymmetricEigen::try_new(m, f32::EPSILON, 64).unwrap();
            let mut a: [f32; 3] = ours.eigenvalues.into();
            let mut b: [f32; 3] = theirs.eigenvalues.into();
            a.sort_by(f32::total_cmp);
            b.sort_by(f32::total_cmp);
            let scale = m.norm().max(1e-12);
            for (x, y) in a.iter().zip(&b) {
                assert!((x - y).abs() <= 1e-5 * scale, "{m}: {a:?} vs {b:?}");
            }
            let v = ours.eigenvectors;
            let rebuilt = v * Matrix3::from_diagonal(&ours.eigenvalues) * v.transpose();
            assert!(
                (rebuilt - m).norm() <= 1e-5 * scale,
                "{m} rebuilt as {rebuilt}"
            );
            assert!((v.transpose() * v - Matrix3::identity()).norm() < 1e-5);
        }
        assert!(symmetric_eigen3(&Matrix3::from_element(f32::NAN)).is_none());
    }
}
