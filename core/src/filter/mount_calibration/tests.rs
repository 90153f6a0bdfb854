use super::*;
use crate::pose::Pose;
use nalgebra::{Matrix6, Rotation3, UnitQuaternion};

const PERIOD_US: u64 = 33_333;

/// A deterministic generator (xorshift), uniform in [-1, 1) and roughly normal.
struct Noise(u64);
impl Noise {
    fn uniform(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        ((self.0 >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }
    fn normal(&mut self) -> f32 {
        // Sum of 3 uniforms, scaled to unit variance.
        (self.uniform() + self.uniform() + self.uniform()) * 1.0
    }
}

/// The fix a camera on `true_mount` sees of a level pad under `attitude`, with its tilt
/// sigma `tilt_sigma_deg` (isotropic) and the tilt itself perturbed by `tilt_error`
/// (radians, camera axes).
fn fix_seen(
    true_mount: &CameraMount,
    attitude: &Attitude,
    tilt_sigma_deg: f32,
    tilt_error: Vector3<f32>,
) -> PadFix {
    // Pad to NED: pad x east, y north, z up.
    let ned_from_pad = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0);
    let camera_from_ned = (attitude.matrix() * true_mount.matrix()).transpose();
    let error = Rotation3::new(tilt_error).into_inner();
    let rotation = error * camera_from_ned * ned_from_pad;
    let var = tilt_sigma_deg.to_radians().powi(2);
    let mut covariance = Matrix6::identity() * 1e-6;
    for k in 0..3 {
        covariance[(k, k)] = var;
    }
    PadFix {
        pose: Pose {
            rotation,
            translation: Vector3::new(0.1, 0.2, 3.0),
        },
        covariance,
        markers_used: 3,
        reprojection_rms_px: 0.1,
        alternative_rms_px: f32::INFINITY,
    }
}

fn hover_attitude(k: u64) -> Attitude {
    // A hover rocking by a few degrees, heading wandering.
    let t = k as f32 * 0.0333;
    Attitude::from_euler(
        (3.0 * libm::sinf(0.7 * t)).to_radians(),
        (2.0 * libm::sinf(0.45 * t + 1.0)).to_radians(),
        0.3 + 0.1 * libm::sinf(0.1 * t),
    )
    .unwrap()
}

#[test]
fn the_aligning_roll_and_pitch_invert_the_tilted_mount() {
    let base = CameraMount::downward().turned_about_optical_axis(25.0);
    for (roll, pitch) in [(1.5f32, -1.0f32), (-8.0, 6.0), (0.0, 0.0), (0.3, 9.5)] {
        let tilted = base.tilted(roll, pitch);
        for k in [0u64, 40, 95] {
            let att = hover_attitude(k);
            let d = att.ned_to_body(&Vector3::z());
            // The camera's down through the true mount, then through the base.
            let down_camera = tilted.body_to_camera(&d);
            let u = base.camera_to_body(&down_camera);
            let (r, p) = roll_pitch_aligning(&u, &d).unwrap();
            assert!((r.to_degrees() - roll).abs() < 2e-3, "{r} vs {roll}");
            assert!((p.to_degrees() - pitch).abs() < 2e-3, "{p} vs {pitch}");
        }
    }
    assert_eq!(
        roll_pitch_aligning(&Vector3::new(f32::NAN, 0.0, 1.0), &Vector3::z()),
        None
    );
    assert_eq!(roll_pitch_aligning(&Vector3::x(), &Vector3::y()), None);
}

/// Feeds `frames` frames of a hover with the true mount at (1.5, -1.0) deg, fix noise
/// `fix_sigma` and a slow attitude bias of `bias_deg` (a sine of period 40 s); returns the
/// calibrator and the reports.
fn hover(
    frames: u64,
    fix_sigma_deg: f32,
    bias_deg: f32,
    config: MountCalibrationConfig,
) -> (MountCalibrator, heapless::Vec<(u64, MountCorrection), 8>) {
    let base = CameraMount::downward();
    let truth = base.tilted(1.5, -1.0);
    let mut cal = MountCalibrator::new(config);
    let mut noise = Noise(0x1234_5678_9abc_def1);
    let mut reports = heapless::Vec::new();
    for k in 0..frames {
        let t = k * PERIOD_US;
        let true_att = hover_attitude(k);
        let fix = fix_seen(
            &truth,
            &true_att,
            fix_sigma_deg,
            Vector3::new(noise.normal(), noise.normal(), noise.normal())
                * fix_sigma_deg.to_radians(),
        );
        // What the autopilot believes: the truth with a slow roll and pitch bias and a
        // little white noise.
        let phase = t as f32 * 1e-6 * core::f32::consts::TAU / 40.0;
        let bias = UnitQuaternion::from_euler_angles(
            (bias_deg * libm::sinf(phase) + 0.02 * noise.normal()).to_radians(),
            (bias_deg * libm::cosf(phase) + 0.02 * noise.normal()).to_radians(),
            0.0,
        );
        let believed = Attitude::from_quaternion_wxyz({
            let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                true_att.quaternion_wxyz()[0],
                true_att.quaternion_wxyz()[1],
                true_att.quaternion_wxyz()[2],
                true_att.quaternion_wxyz()[3],
            )) * bias;
            [q.w, q.i, q.j, q.k]
        })
        .unwrap();
        if let Ok(Some(c)) = cal.observe(&fix, &believed, &base, t, (0.0, 0.0)) {
            let _ = reports.push((k, c));
        }
    }
    (cal, reports)
}

#[test]
fn converges_within_its_sigma_without_bias() {
    let config = MountCalibrationConfig {
        attitude_bias_deg: 0.0,
        ..MountCalibrationConfig::default()
    };
    let (cal, reports) = hover(900, 0.1, 0.0, config);
    let e = cal.estimate().unwrap();
    assert!(e.confident);
    assert!((e.roll_deg - 1.5).abs() <= 2.0 * e.roll_sigma_deg, "{e:?}");
    assert!(
        (e.pitch_deg + 1.0).abs() <= 2.0 * e.pitch_sigma_deg,
        "{e:?}"
    );
    assert!(e.sigma_deg() < 0.05, "{e:?}");
    // Reported once, when it first became confident (after 10 s: 300 frames).
    assert_eq!(reports.len(), 1, "{reports:?}");
    let (k, c) = reports[0];
    assert!((300..320).contains(&k), "{k}");
    assert!((c.roll_deg - 1.5).abs() < 0.1 && (c.pitch_deg + 1.0).abs() < 0.1);
    assert_eq!((c.mount_roll_deg, c.roll_deg), (c.roll_deg, c.roll_deg));
}

#[test]
fn a_slow_attitude_bias_is_inside_the_stated_sigma() {
    // 0.25 degree bias over 20 s (half its 40 s period): the estimate carries part of it,
    // and the sigma, from the bias model, says so.
    let (cal, reports) = hover(600, 0.1, 0.25, MountCalibrationConfig::default());
    let e = cal.estimate().unwrap();
    assert!(e.confident, "{e:?}");
    assert!(e.bias_sigma_deg > 0.15 && e.noise_sigma_deg < 0.05, "{e:?}");
    assert!((e.roll_deg - 1.5).abs() <= e.roll_sigma_deg, "{e:?}");
    assert!((e.pitch_deg + 1.0).abs() <= e.pitch_sigma_deg, "{e:?}");
    assert_eq!(reports.len(), 1, "{reports:?}");
    // Not averaged away: the error is well above what the noise alone would allow.
    let noise_only = MountCalibrationConfig {
        attitude_bias_deg: 0.0,
        ..MountCalibrationConfig::default()
    };
    let (cal, _) = hover(600, 0.1, 0.25, noise_only);
    let e = cal.estimate().unwrap();
    let error = (e.roll_deg - 1.5).abs().max((e.pitch_deg + 1.0).abs());
    assert!(error > 2.0 * e.sigma_deg(), "{error} vs {e:?}");
}

#[test]
fn refuses_poor_and_levelled_fixes() {
    let base = CameraMount::downward();
    let truth = base.tilted(1.5, -1.0);
    let att = hover_attitude(10);
    let mut cal = MountCalibrator::new(MountCalibrationConfig::default());
    // A far single marker: a 2 degree tilt sigma.
    let poor = fix_seen(&truth, &att, 2.0, Vector3::zeros());
    assert_eq!(
        cal.observe(&poor, &att, &base, 0, (0.0, 0.0)),
        Err(MountRefusal::PoorTilt)
    );
    // A levelled fix: only the heading uncertain (its tilt is the attitude's).
    let mut levelled = fix_seen(&truth, &att, 0.1, Vector3::zeros());
    let up = levelled.pose.rotation * Vector3::z();
    let heading = up * up.transpose() * 1e-4;
    for r in 0..3 {
        for c in 0..3 {
            levelled.covariance[(r, c)] = heading[(r, c)];
        }
    }
    assert_eq!(
        cal.observe(&levelled, &att, &base, 0, (0.0, 0.0)),
        Err(MountRefusal::TiltNotMeasured)
    );
    // A flip-ambiguous single marker (with three markers the same errors are one pose).
    let mut ambiguous = fix_seen(&truth, &att, 0.1, Vector3::zeros());
    ambiguous.alternative_rms_px = 0.15;
    ambiguous.markers_used = 1;
    assert_eq!(
        cal.observe(&ambiguous, &att, &base, 0, (0.0, 0.0)),
        Err(MountRefusal::Ambiguous)
    );
    ambiguous.markers_used = 3;
    let mut probe = cal.clone();
    assert_eq!(
        probe.observe(&ambiguous, &att, &base, 0, (0.0, 0.0)),
        Ok(None)
    );
    // A pad tilted by 20 degrees.
    let tilted = fix_seen(&truth, &att, 0.1, Vector3::new(0.35, 0.0, 0.0));
    assert_eq!(
        cal.observe(&tilted, &att, &base, 0, (0.0, 0.0)),
        Err(MountRefusal::NotLevel)
    );
    // NaN covariance (counted as a poor tilt).
    let mut nan = fix_seen(&truth, &att, 0.1, Vector3::zeros());
    nan.covariance[(0, 0)] = f32::NAN;
    assert!(cal.observe(&nan, &att, &base, 0, (0.0, 0.0)).is_err());
    let s = cal.stats();
    assert_eq!(
        (
            s.accepted,
            s.poor_tilt,
            s.tilt_not_measured,
            s.ambiguous,
            s.not_level
        ),
        (0, 2, 1, 1, 1)
    );
    assert_eq!(cal.estimate(), None);
    // A good one is taken; after the gate closes a 1 degree outlier is refused.
    for k in 0..40u64 {
        let good = fix_seen(&truth, &att, 0.05, Vector3::zeros());
        assert_eq!(
            cal.observe(&good, &att, &base, k * PERIOD_US, (0.0, 0.0)),
            Ok(None)
        );
    }
    let outlier = fix_seen(&truth, &att, 0.05, Vector3::new(0.02, 0.0, 0.0));
    assert_eq!(
        cal.observe(&outlier, &att, &base, 41 * PERIOD_US, (0.0, 0.0)),
        Err(MountRefusal::Outlier)
    );
}

#[test]
fn not_confident_on_a_short_or_noisy_hover() {
    // 5 s only: never confident, never reported.
    let (cal, reports) = hover(150, 0.1, 0.0, MountCalibrationConfig::default());
    assert!(!cal.estimate().unwrap().confident && reports.is_empty());
}

#[test]
fn a_later_report_only_when_the_estimate_moves_significantly() {
    let config = MountCalibrationConfig {
        attitude_bias_deg: 0.0,
        ..MountCalibrationConfig::default()
    };
    let base = CameraMount::downward();
    let att = Attitude::level_north();
    let mut cal = MountCalibrator::new(config);
    let mut reports = 0;
    let mut noise = Noise(7);
    let mut last = None;
    // 20 s at (1.5, -1.0), then the mount is knocked to (3.5, -1.0) for 40 s.
    for k in 0..1800u64 {
        let truth = if k < 600 {
            base.tilted(1.5, -1.0)
        } else {
            base.tilted(3.5, -1.0)
        };
        let e = Vector3::new(noise.normal(), noise.normal(), 0.0) * 0.1f32.to_radians();
        let fix = fix_seen(&truth, &att, 0.1, e);
        if let Ok(Some(c)) = cal.observe(&fix, &att, &base, k * PERIOD_US, (0.0, 0.0)) {
            reports += 1;
            last = Some(c);
        }
    }
    // One report for the first mount; the knocked mount's frames are outliers (2 degrees
    // is far outside a 0.1 degree scatter) until 90 in a row restart the accumulation,
    // which reports the new mount once, 10 s later: two reports, not a stream.
    assert_eq!(reports, 2);
    assert!(
        (last.unwrap().mount_roll_deg - 3.5).abs() < 0.05,
        "{last:?}"
    );
    let s = cal.stats();
    assert_eq!((s.outliers, s.restarts, s.reports), (90, 1, 2));
}
