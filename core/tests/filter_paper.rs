//! The paper's filter (equations 8-14, Table 1) equation by equation: its first steps, the
//! steady-state gain it converges to, the lag it has on a ramp, and non-finite input skipped.

use touchdown_core::filter::{PaperConfig, PaperKalman};

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
