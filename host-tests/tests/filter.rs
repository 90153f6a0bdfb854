//! Filters and frames: the simulated descent against its accuracy
//! targets, the paper's filter equation by equation, the tracker's lifecycle, gating and
//! recovery, a randomised check that the covariance stays symmetric positive definite, and the
//! MAVLink frame conventions.

#[path = "filter_sim/mod.rs"]
mod filter_sim;

use filter_sim::{compare, SimConfig};
use nalgebra::{Matrix3, Matrix6, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use touchdown_core::filter::axes::{self, Attitude, CameraMount, RotationError};
use touchdown_core::filter::{
    ConfigError, Measurement, PaperConfig, PaperKalman, RejectReason, TrackState, Tracker,
    TrackerConfig, UpdateOutcome,
};

const FRAME_US: u64 = 33_333;

fn meas(t_us: u64, p: [f32; 3], sigma: f32) -> Measurement {
    Measurement {
        t_us,
        position: Vector3::from(p),
        covariance: Matrix3::identity() * (sigma * sigma),
    }
}

fn tracker() -> Tracker {
    Tracker::new(TrackerConfig::level()).unwrap()
}

/// A confirmed track on a static pad at `p`, last update at the returned time.
fn confirmed(tr: &mut Tracker, p: [f32; 3], frames: u64) -> u64 {
    let mut t = 0;
    for i in 0..frames {
        t = i * FRAME_US;
        tr.update(&meas(t, p, 0.05));
    }
    assert_eq!(tr.state(), TrackState::Tracking);
    t
}

// ---------------------------------------------------------------------------------------------
// The simulated descent (its accuracy targets).

#[test]
fn descent_ours_beats_raw_without_lag_and_paper_lags() {
    for seed in 1..=5 {
        let cfg = SimConfig {
            seed,
            ..SimConfig::default()
        };
        let c = compare(&cfg);
        println!("seed {seed}\n{}", c.table());
        let raw = &c.raw_inliers;
        for axis in 0..3 {
            assert!(
                c.ours.rms[axis] <= 0.6 * raw.rms[axis],
                "seed {seed} axis {axis}: ours {} raw {}",
                c.ours.rms[axis],
                raw.rms[axis]
            );
        }
        assert!(c.ours.rms_total <= 0.6 * raw.rms_total);
        assert!(c.ours.lag_frames.abs() <= 1.0, "lag {}", c.ours.lag_frames);
        // No injected outlier was fused; few good measurements were gated (the 99.9 % gate).
        assert_eq!(c.outliers_fused, 0, "seed {seed}");
        assert!(
            c.inliers_gated * 100 <= c.measured,
            "seed {seed}: {}",
            c.inliers_gated
        );
        assert_eq!(c.repairs, 0);
        // Ours reports on (nearly) every frame: dropped single frames are coasted over.
        assert!(
            c.ours.count + 10 >= c.frames,
            "{} of {}",
            c.ours.count,
            c.frames
        );
        // The paper's filter is a random walk with a steady-state gain of 0.159: it trails.
        assert!(c.paper.lag_frames > 4.0, "paper lag {}", c.paper.lag_frames);
        assert!(c.ours.rms_total < c.paper.rms_total);
    }
}

#[test]
fn descent_with_attitude_wobble() {
    let cfg = SimConfig {
        wobble_deg: 5.0,
        ..SimConfig::default()
    };
    let c = compare(&cfg);
    println!("{}", c.table());
    assert!(c.ours.rms_total <= 0.6 * c.raw_inliers.rms_total);
    assert!(c.ours.lag_frames.abs() <= 1.0);
    // Filtering in the level frame is at least as good as in the camera frame.
    assert!(c.ours.rms_total <= c.ours_camera_frame.rms_total);
}

// ---------------------------------------------------------------------------------------------
// The paper's filter.

#[test]
fn paper_first_steps_follow_equations_8_to_14() {
    let c = PaperConfig::TABLE_1;
    assert_eq!((c.x0, c.p0, c.r, c.q), (5.0, 1000.0, 3.0, 0.09));
    let mut f = PaperKalman::default();
    assert_eq!(f.estimate(), [5.0; 3]);
    // n = 1: no extrapolation; K = 1000 / 1003.
    let k1 = 1000.0f32 / 1003.0;
    let out = f.update([1.0, 2.0, 20.0], 0.0);
    let x1 = [
        5.0 + k1 * (1.0 - 5.0),
        5.0 + k1 * (2.0 - 5.0),
        5.0 + k1 * (20.0 - 5.0),
    ];
    for (a, b) in out.iter().zip(x1) {
        assert!((a - b).abs() < 1e-5);
    }
    let p1 = (1.0 - k1) * 1000.0;
    assert!((f.uncertainty()[0] - p1).abs() < 1e-4);
    // n = 2: p(2,1) = p(1,1) + q, x̂(2,1) = x̂(1,1) (zero velocity), then the update.
    let p21 = p1 + 0.09;
    let k2 = p21 / (p21 + 3.0);
    let out = f.update([1.5, 2.0, 19.0], 0.1);
    assert!((out[0] - (x1[0] + k2 * (1.5 - x1[0]))).abs() < 1e-5);
    assert!((out[2] - (x1[2] + k2 * (19.0 - x1[2]))).abs() < 1e-5);
    assert!((f.uncertainty()[0] - (1.0 - k2) * p21).abs() < 1e-5);
}

#[test]
fn paper_gain_converges_and_lags_a_ramp() {
    let mut f = PaperKalman::default();
    let dt = 1.0 / 30.0;
    let mut z = 30.0f32;
    let mut out = [0.0; 3];
    for _ in 0..600 {
        z -= dt;
        out = f.update([0.0, 0.0, z], dt);
    }
    // Steady state: p(n,n-1) solves p² - q p - q r = 0; K = p / (p + r) ≈ 0.159.
    let pp = (0.09 + (0.09f32 * 0.09 + 4.0 * 0.09 * 3.0).sqrt()) / 2.0;
    let k = pp / (pp + 3.0);
    assert!((f.uncertainty()[2] - (1.0 - k) * pp).abs() < 1e-4);
    // A ramp of v per step is trailed by v (1 - K) / K.
    let expected = dt * (1.0 - k) / k;
    assert!(
        ((out[2] - z) - expected).abs() < 1e-3,
        "{} vs {expected}",
        out[2] - z
    );
    // Non-finite input is skipped, not propagated.
    let before = f.estimate();
    let after = f.update([f32::NAN, 0.0, z], dt);
    assert!(after.iter().all(|v| v.is_finite()));
    assert_eq!(after[0], before[0]);
}

// ---------------------------------------------------------------------------------------------
// Tracker lifecycle.

#[test]
fn confirmation_then_tracking() {
    let mut tr = tracker();
    assert_eq!(tr.state(), TrackState::Searching);
    assert_eq!(
        tr.update(&meas(0, [1.0, 2.0, 10.0], 0.05)),
        UpdateOutcome::Reset
    );
    assert!(
        tr.estimate(0).is_none(),
        "a single sighting is not reported"
    );
    assert_eq!(
        tr.update(&meas(FRAME_US, [1.0, 2.0, 10.0], 0.05)),
        UpdateOutcome::Accepted
    );
    assert_eq!(tr.state(), TrackState::Searching);
    assert_eq!(
        tr.update(&meas(2 * FRAME_US, [1.0, 2.0, 10.0], 0.05)),
        UpdateOutcome::Accepted
    );
    assert_eq!(tr.state(), TrackState::Tracking);
    let e = tr.estimate(2 * FRAME_US).unwrap();
    assert!((e.position - Vector3::new(1.0, 2.0, 10.0)).norm() < 0.05);
    assert_eq!(e.since_update_us, 0);
}

#[test]
fn no_estimate_after_coast_and_lost_after_timeout() {
    let cfg = TrackerConfig::level();
    let mut tr = tracker();
    let t = confirmed(&mut tr, [0.5, -0.5, 8.0], 10);
    // Bridged: a couple of dropped frames.
    assert!(tr.estimate(t + 2 * FRAME_US).is_some());
    assert!(tr.estimate(t + cfg.max_coast_us).is_some());
    // Never stale: past the coast time there is no estimate, even while still "tracking".
    assert!(tr.estimate(t + cfg.max_coast_us + 1).is_none());
    assert_eq!(tr.predict_to(t + cfg.lost_timeout_us), TrackState::Tracking);
    assert!(tr.estimate(t + cfg.lost_timeout_us).is_none());
    assert_eq!(tr.predict_to(t + cfg.lost_timeout_us + 1), TrackState::Lost);
    assert!(tr.estimate(t + cfg.lost_timeout_us + 1).is_none());
    // Reacquisition starts a new track, reported once confirmed.
    let t2 = t + 2 * cfg.lost_timeout_us;
    assert_eq!(
        tr.update(&meas(t2, [3.0, 0.0, 6.0], 0.05)),
        UpdateOutcome::Reset
    );
    assert_eq!(tr.state(), TrackState::Lost);
    assert!(tr.estimate(t2).is_none());
    tr.update(&meas(t2 + FRAME_US, [3.0, 0.0, 6.0], 0.05));
    tr.update(&meas(t2 + 2 * FRAME_US, [3.0, 0.0, 6.0], 0.05));
    assert_eq!(tr.state(), TrackState::Tracking);
    let e = tr.estimate(t2 + 2 * FRAME_US).unwrap();
    assert!((e.position - Vector3::new(3.0, 0.0, 6.0)).norm() < 0.05);
    tr.reset();
    assert_eq!(tr.state(), TrackState::Searching);
    assert!(tr.estimate(t2 + 2 * FRAME_US).is_none());
}

#[test]
fn dropped_frames_are_a_longer_step() {
    // A pad moving at constant velocity, seen only every 4th frame: the prediction bridges the
    // gaps and the update at each measurement is still on the truth.
    let mut tr = tracker();
    let v = Vector3::new(0.5, 0.0, -1.0);
    for i in 0..120u64 {
        if i % 4 != 0 && i > 10 {
            tr.predict_to(i * FRAME_US);
            continue;
        }
        let t = i as f32 * FRAME_US as f32 * 1e-6;
        let p = Vector3::new(0.0, 1.0, 20.0) + v * t;
        tr.update(&meas(i * FRAME_US, p.into(), 0.02));
    }
    let t_last = 116 * FRAME_US;
    let e = tr.estimate(t_last).unwrap();
    let truth = Vector3::new(0.0, 1.0, 20.0) + v * (t_last as f32 * 1e-6);
    assert!(
        (e.position - truth).norm() < 0.03,
        "{}",
        (e.position - truth).norm()
    );
    assert!((e.velocity - v).norm() < 0.1);
}

#[test]
fn constant_velocity_target_has_no_lag() {
    // Noiseless constant-velocity target: at the time of each measurement the estimate sits on
    // the truth (no steady-state lag), and the predicted estimate between frames too.
    let mut tr = tracker();
    let p0 = Vector3::new(2.0, -1.0, 25.0);
    let v = Vector3::new(-0.5, 0.2, -1.0);
    let truth = |t_us: u64| p0 + v * (t_us as f32 * 1e-6);
    let mut worst = 0.0f32;
    for i in 0..300u64 {
        let t = i * FRAME_US;
        tr.update(&meas(t, truth(t).into(), 0.05));
        if i > 150 {
            let e = tr.estimate(t).unwrap();
            worst = worst.max((e.position - truth(t)).norm());
            let mid = t + FRAME_US / 2;
            let e = tr.estimate(mid).unwrap();
            worst = worst.max((e.position - truth(mid)).norm());
        }
    }
    assert!(worst < 2e-3, "worst {worst}");
}

#[test]
fn time_going_backwards() {
    let cfg = TrackerConfig::level();
    let mut tr = tracker();
    let t = confirmed(&mut tr, [0.0, 0.0, 5.0], 30);
    let before = tr.estimate(t).unwrap();
    // Slightly back: an out-of-order frame, ignored.
    assert_eq!(
        tr.update(&meas(t - FRAME_US, [0.3, 0.0, 5.0], 0.05)),
        UpdateOutcome::Rejected(RejectReason::OutOfOrder)
    );
    assert_eq!(tr.estimate(t).unwrap(), before);
    assert_eq!(tr.state(), TrackState::Tracking);
    // predict_to into the past is a no-op.
    assert_eq!(tr.predict_to(0), TrackState::Tracking);
    assert_eq!(tr.estimate(t).unwrap(), before);
    // An estimate before the last update is not given.
    assert!(tr.estimate(t - 1).is_none());
    // Far back: the clock was reset; start over from this measurement.
    let t_back = t - cfg.max_backwards_us - 1;
    assert!(t > cfg.max_backwards_us);
    assert_eq!(
        tr.update(&meas(t_back, [0.0, 0.0, 5.0], 0.05)),
        UpdateOutcome::Reset
    );
    assert_eq!(tr.state(), TrackState::Lost);
    assert!(tr.estimate(t_back).is_none());
    // And the new time line goes on normally.
    assert_eq!(
        tr.update(&meas(t_back + FRAME_US, [0.0, 0.0, 5.0], 0.05)),
        UpdateOutcome::Accepted
    );
}

#[test]
fn clock_reset_to_zero_restarts() {
    let mut tr = tracker();
    // Long flight on one clock...
    for i in 0..10u64 {
        tr.update(&meas(1_000_000_000 + i * FRAME_US, [0.0, 0.0, 5.0], 0.05));
    }
    assert_eq!(tr.state(), TrackState::Tracking);
    // ...then the time base restarts (time sync): a reset, not a 1000 s extrapolation.
    assert_eq!(
        tr.update(&meas(0, [0.0, 0.0, 5.0], 0.05)),
        UpdateOutcome::Reset
    );
}

#[test]
fn outlier_is_gated_and_does_not_move_the_track() {
    let mut tr = tracker();
    let t = confirmed(&mut tr, [1.0, 1.0, 10.0], 20);
    let before = tr.estimate(t + FRAME_US).unwrap();
    match tr.update(&meas(t + FRAME_US, [4.0, 1.0, 10.0], 0.05)) {
        UpdateOutcome::Gated(d2) => assert!(d2 > TrackerConfig::level().gate_d2),
        other => panic!("{other:?}"),
    }
    assert_eq!(tr.estimate(t + FRAME_US).unwrap(), before);
    assert_eq!(
        tr.update(&meas(t + 2 * FRAME_US, [1.0, 1.0, 10.0], 0.05)),
        UpdateOutcome::Accepted
    );
    // Outliers interleaved with good measurements never take over.
    for i in 3..40u64 {
        let p = if i % 2 == 0 {
            [1.0, 1.0, 10.0]
        } else {
            [4.0, 1.0 + (i as f32) * 0.01, 10.0]
        };
        let out = tr.update(&meas(t + i * FRAME_US, p, 0.05));
        assert_ne!(out, UpdateOutcome::Reset, "frame {i}");
    }
    let e = tr.estimate(t + 39 * FRAME_US).unwrap();
    assert!((e.position - Vector3::new(1.0, 1.0, 10.0)).norm() < 0.05);
}

#[test]
fn recovery_after_a_real_jump() {
    let cfg = TrackerConfig::level();
    let mut tr = tracker();
    let t = confirmed(&mut tr, [0.0, 0.0, 10.0], 20);
    // The pad really is 3 m further (a yaw reset, a wrong first track): consistent measurements.
    let mut outcomes = Vec::new();
    for i in 1..=u64::from(cfg.recovery_count) {
        outcomes.push(tr.update(&meas(t + i * FRAME_US, [3.0, 0.0, 10.0], 0.05)));
    }
    for o in &outcomes[..outcomes.len() - 1] {
        assert!(matches!(o, UpdateOutcome::Gated(_)), "{outcomes:?}");
    }
    assert_eq!(*outcomes.last().unwrap(), UpdateOutcome::Reset);
    assert_eq!(tr.state(), TrackState::Tracking);
    let t_end = t + u64::from(cfg.recovery_count) * FRAME_US;
    let e = tr.estimate(t_end).unwrap();
    assert!((e.position - Vector3::new(3.0, 0.0, 10.0)).norm() < 0.05);
    assert_eq!(
        tr.update(&meas(t_end + FRAME_US, [3.0, 0.0, 10.0], 0.05)),
        UpdateOutcome::Accepted
    );
}

#[test]
fn gated_measurements_that_disagree_do_not_recover() {
    let mut tr = tracker();
    let t = confirmed(&mut tr, [0.0, 0.0, 10.0], 20);
    // Far from the track and from each other: each restarts the candidate.
    for i in 1..=8u64 {
        let x = if i % 2 == 0 { 3.0 } else { -3.0 };
        assert!(matches!(
            tr.update(&meas(t + i * FRAME_US, [x, 0.0, 10.0], 0.05)),
            UpdateOutcome::Gated(_)
        ));
    }
}

#[test]
fn invalid_measurements_are_rejected() {
    let mut tr = tracker();
    confirmed(&mut tr, [0.0, 0.0, 10.0], 5);
    let t = 10 * FRAME_US;
    let bad_position = meas(t, [f32::NAN, 0.0, 1.0], 0.05);
    assert_eq!(
        tr.update(&bad_position),
        UpdateOutcome::Rejected(RejectReason::BadPosition)
    );
    assert_eq!(
        tr.update(&meas(t, [0.0, 1.0e9, 1.0], 0.05)),
        UpdateOutcome::Rejected(RejectReason::BadPosition)
    );
    let mut m = meas(t, [0.0, 0.0, 10.0], 0.05);
    m.covariance = -Matrix3::identity();
    assert_eq!(
        tr.update(&m),
        UpdateOutcome::Rejected(RejectReason::BadCovariance)
    );
    m.covariance = Matrix3::identity() * f32::INFINITY;
    assert_eq!(
        tr.update(&m),
        UpdateOutcome::Rejected(RejectReason::BadCovariance)
    );
    // A zero (over-confident) covariance is fine: the floor makes it positive definite.
    m.covariance = Matrix3::zeros();
    assert_eq!(tr.update(&m), UpdateOutcome::Accepted);
    assert_eq!(tr.state(), TrackState::Tracking);
}

#[test]
fn config_validation() {
    let ok = TrackerConfig::level();
    assert!(ok.validate().is_ok());
    assert!(TrackerConfig::camera_frame().validate().is_ok());
    let cases = [
        (
            TrackerConfig {
                accel_psd: 0.0,
                ..ok
            },
            ConfigError::ProcessNoise,
        ),
        (
            TrackerConfig {
                accel_psd: f32::NAN,
                ..ok
            },
            ConfigError::ProcessNoise,
        ),
        (
            TrackerConfig {
                gate_d2: -1.0,
                ..ok
            },
            ConfigError::Gate,
        ),
        (
            TrackerConfig {
                recovery_count: 1,
                ..ok
            },
            ConfigError::RecoveryCount,
        ),
        (
            TrackerConfig {
                confirm_count: 0,
                ..ok
            },
            ConfigError::ConfirmCount,
        ),
        (
            TrackerConfig {
                max_coast_us: 2_000_000,
                ..ok
            },
            ConfigError::Timeouts,
        ),
        (
            TrackerConfig {
                lost_timeout_us: 60_000_000,
                ..ok
            },
            ConfigError::Timeouts,
        ),
        (
            TrackerConfig {
                initial_velocity_sigma: 0.0,
                ..ok
            },
            ConfigError::InitialVelocity,
        ),
        (
            TrackerConfig {
                min_measurement_sigma: -0.1,
                ..ok
            },
            ConfigError::MeasurementFloor,
        ),
        (
            TrackerConfig {
                min_measurement_sigma: 0.0,
                ..ok
            },
            ConfigError::MeasurementFloor,
        ),
    ];
    for (cfg, err) in cases {
        assert_eq!(Tracker::new(cfg).unwrap_err(), err);
    }
}

// ---------------------------------------------------------------------------------------------
// Covariance stays symmetric positive definite through any sequence of operations.

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
                filter_sim::gauss(rng),
                filter_sim::gauss(rng),
                filter_sim::gauss(rng),
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
                            filter_sim::gauss(&mut rng) as f32,
                            filter_sim::gauss(&mut rng) as f32,
                            filter_sim::gauss(&mut rng) as f32,
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

// ---------------------------------------------------------------------------------------------
// Frames.

fn close(a: &Vector3<f32>, b: &Vector3<f32>) -> bool {
    (a - b).norm() < 1e-5
}

#[test]
fn downward_mount_axes() {
    let m = CameraMount::downward();
    assert!(
        close(&m.camera_to_body(&Vector3::x()), &Vector3::y()),
        "image right = body right"
    );
    assert!(
        close(&m.camera_to_body(&Vector3::y()), &-Vector3::x()),
        "image down = toward the tail"
    );
    assert!(
        close(&m.camera_to_body(&Vector3::z()), &Vector3::z()),
        "optical axis = body down"
    );
    assert!(
        close(&m.body_to_camera(&Vector3::x()), &-Vector3::y()),
        "nose = image top"
    );
    let q = m.quaternion_wxyz();
    assert!((q.iter().map(|v| v * v).sum::<f32>() - 1.0).abs() < 1e-6);
    // Turned 90° about the optical axis: image top toward the right wing.
    let r = CameraMount::downward_rotated(std::f32::consts::FRAC_PI_2).unwrap();
    assert!(close(&r.body_to_camera(&Vector3::y()), &-Vector3::y()));
}

#[test]
fn attitude_conventions() {
    let level = Attitude::level_north();
    assert!(close(
        &level.body_to_ned(&Vector3::new(1.0, 2.0, 3.0)),
        &Vector3::new(1.0, 2.0, 3.0)
    ));
    // Yaw 90°: nose east.
    let east = Attitude::from_euler(0.0, 0.0, std::f32::consts::FRAC_PI_2).unwrap();
    assert!(close(&east.body_to_ned(&Vector3::x()), &Vector3::y()));
    assert!((east.yaw() - std::f32::consts::FRAC_PI_2).abs() < 1e-6);
    // Pitch up 30°: the nose points up (negative down component).
    let up = Attitude::from_euler(0.0, 30f32.to_radians(), 0.0).unwrap();
    let nose = up.body_to_ned(&Vector3::x());
    assert!(nose.z < -0.49 && nose.x > 0.86);
    // Roll right 20°: the right wing goes down.
    let roll = Attitude::from_euler(20f32.to_radians(), 0.0, 0.0).unwrap();
    assert!(roll.body_to_ned(&Vector3::y()).z > 0.3);
    // The quaternion form (MAVLink ATTITUDE_QUATERNION q1..q4 = w, x, y, z) round-trips, and
    // equals Rz(yaw) Ry(pitch) Rx(roll).
    let (r, p, y) = (0.1f32, -0.2f32, 2.5f32);
    let a = Attitude::from_euler(r, p, y).unwrap();
    let b = Attitude::from_quaternion_wxyz(a.quaternion_wxyz()).unwrap();
    let rz = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), y);
    let ry = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), p);
    let rx = nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), r);
    let m = (rz * ry * rx).into_inner();
    assert!((a.matrix() - m).norm() < 1e-5);
    assert!((b.matrix() - m).norm() < 1e-5);
    assert!((a.yaw() - y).abs() < 1e-5);
    // Bad inputs.
    assert_eq!(
        Attitude::from_quaternion_wxyz([0.0; 4]).unwrap_err(),
        RotationError::NotUnit
    );
    assert_eq!(
        Attitude::from_quaternion_wxyz([f32::NAN, 0.0, 0.0, 0.0]).unwrap_err(),
        RotationError::NotFinite
    );
    assert_eq!(
        Attitude::from_euler(f32::INFINITY, 0.0, 0.0).unwrap_err(),
        RotationError::NotFinite
    );
    let reflection = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
    assert_eq!(
        CameraMount::from_matrix(&reflection).unwrap_err(),
        RotationError::NotRotation
    );
    assert_eq!(
        CameraMount::from_matrix(&Matrix3::identity())
            .unwrap()
            .quaternion_wxyz(),
        [1.0, 0.0, 0.0, 0.0]
    );
}

#[test]
fn level_frames() {
    // Tilted and yawed: LOCAL_FRD keeps the heading, drops the tilt.
    let yaw = 0.7f32;
    let a = Attitude::from_euler(0.15, -0.1, yaw).unwrap();
    let v_body = Vector3::new(1.0, -2.0, 5.0);
    let v_ned = a.body_to_ned(&v_body);
    let v_frd = a.body_to_local_frd(&v_body);
    assert!((v_frd.z - v_ned.z).abs() < 1e-5, "down is down");
    assert!((v_frd.norm() - v_body.norm()).abs() < 1e-4);
    let back = a.local_frd_to_ned(&v_frd);
    assert!(close(&back, &v_ned));
    // With no tilt, LOCAL_FRD is the body frame.
    let flat = Attitude::from_euler(0.0, 0.0, yaw).unwrap();
    assert!(close(&flat.body_to_local_frd(&v_body), &v_body));
    // PX4's absolute LOCAL_NED.
    let vehicle = Vector3::new(10.0, -4.0, -20.0);
    assert!(close(
        &axes::local_ned_position(&vehicle, &Vector3::new(1.0, 1.0, 20.0)),
        &Vector3::new(11.0, -3.0, 0.0)
    ));
}

#[test]
fn level_measurement_rotates_position_and_covariance() {
    let a = Attitude::from_euler(0.1, 0.05, -1.0).unwrap();
    let mount = CameraMount::downward();
    let m = Measurement {
        t_us: 42,
        position: Vector3::new(0.5, -0.3, 12.0),
        covariance: Matrix3::from_diagonal(&Vector3::new(0.01, 0.02, 0.5)),
    };
    let l = axes::level_measurement(&m, &a, &mount);
    assert_eq!(l.t_us, 42);
    assert!(close(
        &l.position,
        &a.body_to_ned(&mount.camera_to_body(&m.position))
    ));
    assert!(close(
        &axes::ned_to_camera(&l.position, &a, &mount),
        &m.position
    ));
    let mut e0: Vec<f32> = m
        .covariance
        .symmetric_eigenvalues()
        .iter()
        .copied()
        .collect();
    let mut e1: Vec<f32> = l
        .covariance
        .symmetric_eigenvalues()
        .iter()
        .copied()
        .collect();
    e0.sort_by(f32::total_cmp);
    e1.sort_by(f32::total_cmp);
    for (x, y) in e0.iter().zip(&e1) {
        assert!((x - y).abs() < 1e-5);
    }
    // Level, nose north: the pad straight below is straight below, image right = east.
    let n = axes::level_measurement(&m, &Attitude::level_north(), &mount);
    assert!(close(&n.position, &Vector3::new(0.3, 0.5, 12.0)));
}

#[test]
fn landing_angles_match_mavlink_and_ardupilot() {
    // Right of and below the image centre.
    let p = Vector3::new(1.0, 2.0, 10.0);
    let a = axes::landing_angles(&p).unwrap();
    assert!((a.angle_x - (0.1f32).atan()).abs() < 1e-6);
    assert!((a.angle_y - (0.2f32).atan()).abs() < 1e-6);
    // ArduPilot rebuilds the body-frame line of sight as (-tan(angle_y), tan(angle_x), 1).
    let los = Vector3::new(-a.angle_y.tan(), a.angle_x.tan(), 1.0).normalize();
    let body = CameraMount::downward().camera_to_body(&p).normalize();
    assert!(close(&los, &body));
    assert!((axes::distance(&p) - p.norm()).abs() < 1e-6);
    // Behind the camera or not finite: no angles.
    assert!(axes::landing_angles(&Vector3::new(0.0, 0.0, -1.0)).is_none());
    assert!(axes::landing_angles(&Vector3::new(f32::NAN, 0.0, 1.0)).is_none());
}
