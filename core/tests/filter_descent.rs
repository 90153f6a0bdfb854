//! The filters on a simulated descent (`descent_sim`: 1 m/s down from 30 m to 1 m, 0.5 m/s
//! drift, 30 Hz, range-dependent pose noise, dropped frames, outliers) against their accuracy
//! targets: ours beats the raw pose without lag, the paper's filter trails (seed 1 here, seeds
//! 2-5 in the long suite, `cargo test -- --ignored`); and the printed comparison of the
//! three, an ignored report:
//! `cargo test -p touchdown-core --test filter_descent -- --ignored --nocapture`
//! (`TOUCHDOWN_DESCENT_WOBBLE_DEG`, `TOUCHDOWN_DESCENT_SEED`: see
//! [`descent_comparison_report`]).

mod descent_sim;

use descent_sim::{compare, SimConfig};

/// Seed 1 of the descent: ours beats the raw pose without lag, the paper's filter trails. The
/// same on seeds 2-5 is in the long suite ([`descent_ours_beats_raw_on_seeds_2_to_5`]).
#[test]
fn descent_ours_beats_raw_without_lag_and_paper_lags() {
    ours_beats_raw_and_paper_lags(1..=1);
}

/// [`descent_ours_beats_raw_without_lag_and_paper_lags`] on four more seeds: a seed sweep,
/// kept out of a newcomer's `cargo test`.
#[test]
#[ignore = "long: seeds 2-5 of the descent, in the long suite (`cargo test -- --ignored`, CI runs it)"]
fn descent_ours_beats_raw_on_seeds_2_to_5() {
    ours_beats_raw_and_paper_lags(2..=5);
}

fn ours_beats_raw_and_paper_lags(seeds: std::ops::RangeInclusive<u64>) {
    // The seeds are independent descents: simulated on threads, checked in seed order.
    let comparisons: Vec<_> = std::thread::scope(|scope| {
        let runs: Vec<_> = seeds
            .map(|seed| {
                scope.spawn(move || {
                    let cfg = SimConfig {
                        seed,
                        ..SimConfig::default()
                    };
                    (seed, compare(&cfg))
                })
            })
            .collect();
        runs.into_iter()
            .map(|run| run.join().expect("a seed's descent"))
            .collect()
    });
    for (seed, c) in comparisons {
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

/// The filter comparison of one descent, printed: the scenario, the pose noise, the table of
/// RMS and lag for the raw pose, the paper's filter and ours, and ours and the paper's RMS
/// against the raw inliers'; it fails if ours is not the best of the three on the chosen
/// descent. A report to read (the fixed checks are the tests above), hence ignored by
/// default. Run it with
///
/// ```text
/// cargo test -p touchdown-core --test filter_descent -- --ignored --nocapture
/// ```
///
/// and choose the descent with `TOUCHDOWN_DESCENT_WOBBLE_DEG` (roll/pitch wobble, degrees,
/// default 0) and `TOUCHDOWN_DESCENT_SEED` (default 3) in the environment.
#[test]
#[ignore = "a report: prints the filter comparison of one descent (see its doc)"]
fn descent_comparison_report() {
    let mut cfg = SimConfig::default();
    if let Some(v) = env_number("TOUCHDOWN_DESCENT_WOBBLE_DEG") {
        cfg.wobble_deg = v;
    }
    if let Some(v) = env_number("TOUCHDOWN_DESCENT_SEED") {
        cfg.seed = v as u64;
    }
    println!(
        "Descent {:.0} m -> {:.0} m at {} m/s, drift {} m/s, {} Hz, roll/pitch wobble {}°, seed {}",
        cfg.start_altitude,
        cfg.end_altitude,
        cfg.descent_speed,
        cfg.drift_speed,
        cfg.rate_hz,
        cfg.wobble_deg,
        cfg.seed
    );
    println!(
        "pose noise: range sigma = {} px * d^2 / ({} px * {} m), cross-range sigma = {} px * d / {} px; \
         {:.0} % frames dropped + a burst of {}, {:.0} % outliers (3-8 m)",
        cfg.k_range_px,
        cfg.focal_px,
        cfg.marker_size_m,
        cfg.k_centre_px,
        cfg.focal_px,
        cfg.drop_probability * 100.0,
        cfg.burst.1,
        cfg.outlier_probability * 100.0
    );
    let c = compare(&cfg);
    print!("{}", c.table());
    println!(
        "ours / raw inliers RMS: {:.2}; paper / raw inliers RMS: {:.2}",
        c.ours.rms_total / c.raw_inliers.rms_total,
        c.paper.rms_total / c.raw_inliers.rms_total
    );
    // On whatever descent was chosen, the claim the report illustrates must hold.
    assert!(
        c.ours.rms_total < c.paper.rms_total && c.ours.rms_total < c.raw_inliers.rms_total,
        "ours {} paper {} raw inliers {}",
        c.ours.rms_total,
        c.paper.rms_total,
        c.raw_inliers.rms_total
    );
}

/// The number in environment variable `name`, if set; a value that is not a number stops the
/// report (a typo must not silently print the default descent).
fn env_number(name: &str) -> Option<f64> {
    let value = std::env::var(name).ok()?;
    match value.parse::<f64>() {
        Ok(v) => Some(v),
        Err(_) => panic!("{name}={value}: not a number"),
    }
}
