//! The tracker's Kalman filter: a constant-velocity model of the pad's position and velocity
//! (state `[position, velocity]`, position measured), its prediction, its gated correction
//! (Joseph form) and the covariance repair.
//!
//! Separate from the track management in the parent module: this is the filter arithmetic on
//! one state, which knows nothing of candidates, confirmation or timeouts.

use super::{Measurement, REPAIR_FLOOR};
use nalgebra::{Matrix3, Matrix3x6, Matrix6, Vector3, Vector6};

/// The Kalman state at one time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Kf {
    pub(super) x: Vector6<f32>,
    pub(super) p: Matrix6<f32>,
    pub(super) t_us: u64,
}

/// `[I 0]`: the position part of the state.
fn h() -> Matrix3x6<f32> {
    Matrix3x6::identity()
}

fn symmetrised6(p: &Matrix6<f32>) -> Matrix6<f32> {
    (p + p.transpose()) * 0.5
}

pub(super) fn symmetrised3(p: &Matrix3<f32>) -> Matrix3<f32> {
    (p + p.transpose()) * 0.5
}

/// The 3x3 diagonal block of `p` starting at row and column `at` (0 or 3). Built element by
/// element: `fixed_view(..).into_owned()` goes through nalgebra's iterator constructor, whose
/// "iterator too short" panic the optimiser keeps (see nopanic/).
pub(super) fn block3(p: &Matrix6<f32>, at: usize) -> Matrix3<f32> {
    Matrix3::from_fn(|r, c| p.get((at + r, at + c)).copied().unwrap_or(0.0))
}

/// Seconds between two time stamps (`t1 >= t0`, else 0).
fn seconds(t0: u64, t1: u64) -> f32 {
    t1.saturating_sub(t0) as f32 * 1.0e-6
}

impl Kf {
    pub(super) fn new(m: &Measurement, r: &Matrix3<f32>, velocity_sigma: f32) -> Self {
        let mut x = Vector6::zeros();
        x.fixed_rows_mut::<3>(0).copy_from(&m.position);
        let mut p = Matrix6::zeros();
        p.fixed_view_mut::<3, 3>(0, 0).copy_from(r);
        p.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(Matrix3::identity() * (velocity_sigma * velocity_sigma)));
        Kf { x, p, t_us: m.t_us }
    }

    /// The state predicted to `t_us` (itself when `t_us` is not later).
    pub(super) fn predicted(&self, t_us: u64, q: f32) -> Kf {
        if t_us <= self.t_us {
            return *self;
        }
        let dt = seconds(self.t_us, t_us);
        let mut f = Matrix6::identity();
        f.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(Matrix3::identity() * dt));
        let i3 = Matrix3::<f32>::identity();
        let mut qm = Matrix6::zeros();
        qm.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(i3 * (q * dt * dt * dt / 3.0)));
        qm.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(i3 * (q * dt * dt / 2.0)));
        qm.fixed_view_mut::<3, 3>(3, 0)
            .copy_from(&(i3 * (q * dt * dt / 2.0)));
        qm.fixed_view_mut::<3, 3>(3, 3).copy_from(&(i3 * (q * dt)));
        Kf {
            x: f * self.x,
            p: symmetrised6(&(f * self.p * f.transpose() + qm)),
            t_us,
        }
    }

    pub(super) fn position(&self) -> Vector3<f32> {
        h() * self.x
    }

    /// Innovation `y`, its covariance's Cholesky factor and `y^T S^-1 y`.
    pub(super) fn innovation(
        &self,
        z: &Vector3<f32>,
        r: &Matrix3<f32>,
    ) -> Option<(Vector3<f32>, nalgebra::Cholesky<f32, nalgebra::U3>, f32)> {
        let y = z - self.position();
        let hm = h();
        let s = symmetrised3(&(hm * self.p * hm.transpose() + r));
        let chol = s.cholesky()?;
        let d2 = y.dot(&chol.solve(&y));
        if d2.is_finite() {
            Some((y, chol, d2))
        } else {
            None
        }
    }

    /// The Kalman update (Joseph form). Returns whether the covariance had to be repaired.
    pub(super) fn correct(
        &mut self,
        y: &Vector3<f32>,
        chol: &nalgebra::Cholesky<f32, nalgebra::U3>,
        r: &Matrix3<f32>,
    ) -> bool {
        let hm = h();
        // K = P H^T S^-1, and since S is symmetric K^T = S^-1 (P H^T)^T = S^-1 H P.
        let kt: Matrix3x6<f32> = chol.solve(&(hm * self.p));
        let k = kt.transpose();
        self.x += k * y;
        let i_kh = Matrix6::identity() - k * hm;
        let p = i_kh * self.p * i_kh.transpose() + k * r * k.transpose();
        self.p = symmetrised6(&p);
        self.repair()
    }

    /// Keeps `P` positive definite should rounding ever break it: drops the correlations and
    /// floors the variances. Returns whether that was needed.
    pub(super) fn repair(&mut self) -> bool {
        if self.p.iter().all(|v| v.is_finite()) && self.p.cholesky().is_some() {
            return false;
        }
        let d = self.p.diagonal().map(|v| {
            if v.is_finite() && v > REPAIR_FLOOR {
                v
            } else {
                REPAIR_FLOOR
            }
        });
        self.p = Matrix6::from_diagonal(&d);
        if !self.x.iter().all(|v| v.is_finite()) {
            self.x = Vector6::zeros();
        }
        true
    }
}
