//! Our tracker's lifecycle (confirmation, coasting, loss, reacquisition), its timing (dropped
//! frames, no lag on a constant velocity, time going backwards, a clock reset), gating and
//! recovery, invalid measurements and its configuration's validation.

use nalgebra::{Matrix3, Vector3};
use touchdown_core::filter::{
    ConfigError, Measurement, RejectReason, TrackState, Tracker, TrackerConfig, UpdateOutcome,
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
