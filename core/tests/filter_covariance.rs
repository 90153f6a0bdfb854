//! Our tracker's covariance stays symmetric positive definite through any sequence of
//! operations: a seeded random walk over updates near the track, outliers, dropped frames, real
//! jumps of the pad, time going backwards, garbage and resets, with random (anisotropic,
//! rank-deficient, zero) measurement covariances.

mod descent_sim;

use nalgebra::{Matrix3, Matrix6, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use touchdown_core::filter::{Measurement, Tracker, TrackerConfig, UpdateOutcome};

fn assert_spd6(p: &Matrix6<f32>, ctx: &str) {
    assert!(p.iter().all(|v| v.is_finite()), "{ctx}: not finite {p}");
    assert_eq!(*p, p.transpose(), "{ctx}: not symmetric");
    let p64 = p.cast::<f64>();
    assert!(p64.cholesky().is_some(), "{ctx}: not positive definite {p}");
    let min_eig = p64.symmetric_eigenvalues().min();
    assert!(min_eig > 0.0, "{ctx}: eigenvalue {min_eig}");
}

fn assert_spd3(p: &Matrix3<f32>, ctx: &str) {
    assert!(p.iter().all(|v| v.is_finite()), "{ctx}: not finite");
    let p64 = p.cast::<f64>();
    assert!(
        (p64 - p64.transpose()).norm() <= 1e-6 * p64.norm(),
        "{ctx}: not symmetric"
    );
    assert!(
        p64.symmetric_eigenvalues().min() > 0.0,
        "{ctx}: not positive definite {p}"
    );
}

fn random_covariance(rng: &mut ChaCha8Rng) -> Matrix3<f32> {
    // Random orientation, variances spread over 1e-8 .. 1e2 m² (very anisotropic allowed),
    // sometimes rank-deficient (a zero variance), sometimes exactly zero.
    match rng.random_range(0..10) {
        0 => Matrix3::zeros(),
        _ => {
            let axis = Vector3::new(
                descent_sim::gauss(rng),
                descent_sim::gauss(rng),
                descent_sim::gauss(rng),
            );
            let r = nalgebra::Rotation3::new(axis).into_inner().cast::<f32>();
            let mut d = Vector3::zeros();
            for v in d.iter_mut() {
                *v = if rng.random_bool(0.1) {
                    0.0
                } else {
                    10f32.powf(rng.random_range(-8.0..2.0))
                };
            }
            r * Matrix3::from_diagonal(&d) * r.transpose()
        }
    }
}

#[test]
fn covariance_stays_symmetric_positive_definite() {
    let mut rng = ChaCha8Rng::seed_from_u64(20240611);
    let mut checks = 0u64;
    let mut outcomes = [0u32; 4];
    for case in 0..400 {
        let mut cfg = TrackerConfig::level();
        cfg.accel_psd = 10f32.powf(rng.random_range(-3.0..2.0));
        cfg.min_measurement_sigma = if rng.random_bool(0.3) { 0.001 } else { 0.005 };
        cfg.confirm_count = rng.random_range(1..4);
        cfg.recovery_count = rng.random_range(2..6);
        let mut tr = Tracker::new(cfg).unwrap();
        let mut t: u64 = rng.random_range(0..1_000_000_000);
        let mut centre = Vector3::new(
            rng.random_range(-20.0..20.0),
            rng.random_range(-20.0..20.0),
            rng.random_range(0.5..40.0f32),
        );
        for step in 0..250 {
            let ctx = format!("case {case} step {step}");
            match rng.random_range(0..100) {
                // Update near the track (the common case).
                0..=59 => {
                    t += rng.random_range(0..70_000);
                    let noise = 10f32.powf(rng.random_range(-4.0..0.0));
                    let p = centre
                        + Vector3::new(
                            descent_sim::gauss(&mut rng) as f32,
                            descent_sim::gauss(&mut rng) as f32,
                            descent_sim::gauss(&mut rng) as f32,
                        ) * noise;
                    let m = Measurement {
                        t_us: t,
                        position: p,
                        covariance: random_covariance(&mut rng),
                    };
                    let o = tr.update(&m);
                    outcomes[match o {
                        UpdateOutcome::Accepted => 0,
                        UpdateOutcome::Gated(_) => 1,
                        UpdateOutcome::Reset => 2,
                        UpdateOutcome::Rejected(_) => 3,
                    }] += 1;
                }
                // Outlier.
                60..=69 => {
                    t += rng.random_range(0..70_000);
                    let p = centre + Vector3::new(rng.random_range(-50.0..50.0), 0.0, 1.0);
                    let m = Measurement {
                        t_us: t,
                        position: p,
                        covariance: random_covariance(&mut rng),
                    };
                    tr.update(&m);
                }
                // Dropped frames / pure prediction, up to beyond the lost timeout.
                70..=79 => {
                    t += rng.random_range(0..1_500_000);
                    tr.predict_to(t);
                }
                // The pad jumps for real.
                80..=84 => {
                    centre += Vector3::new(
                        rng.random_range(-5.0..5.0),
                        rng.random_range(-5.0..5.0),
                        0.0,
                    );
                }
                // Time going backwards, a little or a lot.
                85..=89 => {
                    let back = rng.random_range(0..2_000_000u64).min(t);
                    let m = Measurement {
                        t_us: t - back,
                        position: centre,
                        covariance: random_covariance(&mut rng),
                    };
                    tr.update(&m);
                    if back > cfg.max_backwards_us {
                        t -= back;
                    }
                }
                // Garbage.
                90..=94 => {
                    let m = Measurement {
                        t_us: t,
                        position: Vector3::new(f32::NAN, 0.0, 1.0),
                        covariance: Matrix3::identity() * -1.0,
                    };
                    assert!(matches!(tr.update(&m), UpdateOutcome::Rejected(_)));
                    outcomes[3] += 1;
                }
                // Reset.
                _ => tr.reset(),
            }
            if let Some(p) = tr.covariance() {
                assert_spd6(&p, &ctx);
                checks += 1;
            }
            if let Some(e) = tr.estimate(t) {
                assert_spd3(&e.position_covariance, &ctx);
                assert_spd3(&e.velocity_covariance, &ctx);
                assert!(e
                    .position
                    .iter()
                    .chain(e.velocity.iter())
                    .all(|v| v.is_finite()));
            }
        }
        assert_eq!(tr.repairs(), 0, "case {case}: covariance repaired");
    }
    println!("{checks} covariance checks; accepted/gated/reset/rejected: {outcomes:?}");
    assert!(checks > 50_000);
    assert!(outcomes.iter().all(|&n| n > 0), "{outcomes:?}");
}
