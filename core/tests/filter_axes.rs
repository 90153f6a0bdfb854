//! The frames the filters and the MAVLink messages are in: the camera mount, the attitude's
//! conventions (Euler angles, the MAVLink quaternion), the level frames (LOCAL_FRD, PX4's
//! absolute LOCAL_NED), a measurement turned into the level frame, and the landing angles as
//! MAVLink and ArduPilot read them.

use nalgebra::{Matrix3, Vector3};
use touchdown_core::filter::{
    distance, landing_angles, level_measurement, local_ned_position, ned_to_camera, Attitude,
    CameraMount, Measurement, RotationError,
};

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
        &local_ned_position(&vehicle, &Vector3::new(1.0, 1.0, 20.0)),
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
    let l = level_measurement(&m, &a, &mount);
    assert_eq!(l.t_us, 42);
    assert!(close(
        &l.position,
        &a.body_to_ned(&mount.camera_to_body(&m.position))
    ));
    assert!(close(&ned_to_camera(&l.position, &a, &mount), &m.position));
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
    let n = level_measurement(&m, &Attitude::level_north(), &mount);
    assert!(close(&n.position, &Vector3::new(0.3, 0.5, 12.0)));
}

#[test]
fn landing_angles_match_mavlink_and_ardupilot() {
    // Right of and below the image centre.
    let p = Vector3::new(1.0, 2.0, 10.0);
    let a = landing_angles(&p).unwrap();
    assert!((a.angle_x - (0.1f32).atan()).abs() < 1e-6);
    assert!((a.angle_y - (0.2f32).atan()).abs() < 1e-6);
    // ArduPilot rebuilds the body-frame line of sight as (-tan(angle_y), tan(angle_x), 1).
    let los = Vector3::new(-a.angle_y.tan(), a.angle_x.tan(), 1.0).normalize();
    let body = CameraMount::downward().camera_to_body(&p).normalize();
    assert!(close(&los, &body));
    assert!((distance(&p) - p.norm()).abs() < 1e-6);
    // Behind the camera or not finite: no angles.
    assert!(landing_angles(&Vector3::new(0.0, 0.0, -1.0)).is_none());
    assert!(landing_angles(&Vector3::new(f32::NAN, 0.0, 1.0)).is_none());
}
