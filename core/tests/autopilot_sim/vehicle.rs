//! The vehicle's flight and what the camera sees of it: a path in LOCAL_NED (drifting north,
//! descending, swaying east, rolling, pitching and turning), the truth of one frame exposed on
//! it (the pad relative to the vehicle and in the camera frame, the pad's axes), the pad fix a
//! detector would report for it, and the camera's timing (a frame every
//! [`FRAME_PERIOD_US`], processed [`PROCESS_DELAY_US`] later).

use std::collections::VecDeque;

use nalgebra::{Matrix3, Rotation3, Vector3};
use touchdown_core::filter::{camera_to_ned_matrix, Attitude, CameraMount};
use touchdown_core::pose::PadFix;

use super::{pad_fix, pad_ned, Rng, FRAME_PERIOD_US, PROCESS_DELAY_US, SIGMA_LATERAL, SIGMA_RANGE};

/// The vehicle's path: from (2, -1, -12) m LOCAL_NED it drifts north and descends at constant
/// speeds, sways east and west (0.3 m at 0.5 rad/s), rolls (0.1 rad) and pitches (0.08 rad),
/// and turns from a heading of 0.5 rad at a constant rate.
#[derive(Debug, Clone, Copy)]
pub struct VehiclePath {
    /// North speed, m/s.
    pub north_mps: f32,
    /// Descent speed, m/s.
    pub down_mps: f32,
    /// Turn rate, rad/s.
    pub yaw_rate: f32,
}

impl VehiclePath {
    /// The companion tests' flight (8-18 s): 0.2 m/s north, 0.3 m/s down, 0.05 rad/s turn.
    pub const APPROACH: VehiclePath = VehiclePath {
        north_mps: 0.2,
        down_mps: 0.3,
        yaw_rate: 0.05,
    };
    /// The clock-drift tests' flight (up to 60 s, so slower: the vehicle is still 6 m up at
    /// the end): 0.02 m/s north, 0.1 m/s down, 0.01 rad/s turn.
    pub const SLOW_APPROACH: VehiclePath = VehiclePath {
        north_mps: 0.02,
        down_mps: 0.1,
        yaw_rate: 0.01,
    };

    /// LOCAL_NED position at `t` seconds, m.
    pub fn position(&self, t: f32) -> Vector3<f32> {
        Vector3::new(
            2.0 + self.north_mps * t,
            -1.0 + 0.3 * (0.5 * t).sin(),
            -12.0 + self.down_mps * t,
        )
    }

    /// LOCAL_NED velocity at `t` seconds, m/s.
    pub fn velocity(&self, t: f32) -> Vector3<f32> {
        Vector3::new(self.north_mps, 0.15 * (0.5 * t).cos(), self.down_mps)
    }

    /// Attitude at `t` seconds.
    pub fn attitude(&self, t: f32) -> Attitude {
        Attitude::from_euler(
            0.1 * (1.3 * t).sin(),
            0.08 * (0.9 * t).cos(),
            0.5 + self.yaw_rate * t,
        )
        .unwrap()
    }
}

/// The truth of one frame.
#[derive(Debug, Clone, Copy)]
pub struct Exposure {
    pub attitude: Attitude,
    /// The pad relative to the vehicle, NED axes.
    pub rel_ned: Vector3<f32>,
    /// NED to camera.
    pub r_cam_ned: Matrix3<f32>,
    /// The pad in the camera frame.
    pub t_cam: Vector3<f32>,
    /// The pad's distance from the camera.
    pub distance: f32,
    /// The pad's axes in NED: x east, y north, z up, turned about z by the pad's yaw.
    pub r_ned_pad: Matrix3<f32>,
}

impl Exposure {
    /// The frame exposed at `exposure_us` by a camera on `mount` flying `path`, over a pad at
    /// [`pad_ned`] turned by `pad_yaw` radians.
    pub fn new(path: &VehiclePath, exposure_us: u64, mount: &CameraMount, pad_yaw: f32) -> Self {
        let t = exposure_us as f32 * 1e-6;
        let attitude = path.attitude(t);
        let rel_ned = pad_ned() - path.position(t);
        let r_cam_ned = camera_to_ned_matrix(&attitude, mount).transpose();
        let t_cam = r_cam_ned * rel_ned;
        let r_ned_pad = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0)
            * Rotation3::from_axis_angle(&Vector3::z_axis(), pad_yaw).into_inner();
        Exposure {
            attitude,
            rel_ned,
            r_cam_ned,
            t_cam,
            distance: t_cam.norm(),
            r_ned_pad,
        }
    }

    /// The fix of a perfect detector: the true pose.
    pub fn exact_fix(&self) -> PadFix {
        pad_fix(self.r_cam_ned * self.r_ned_pad, self.t_cam, self.distance)
    }

    /// The true pose with Gaussian noise on the position, [`SIGMA_LATERAL`] of the distance
    /// across the line of sight and [`SIGMA_RANGE`] along it: what the fix's covariance says.
    pub fn noisy_fix(&self, rng: &mut Rng) -> PadFix {
        let (sl, sr) = (SIGMA_LATERAL * self.distance, SIGMA_RANGE * self.distance);
        let noisy = self.t_cam + Vector3::new(sl * rng.gauss(), sl * rng.gauss(), sr * rng.gauss());
        pad_fix(self.r_cam_ned * self.r_ned_pad, noisy, self.distance)
    }
}

/// The camera's timing: a frame exposed every [`FRAME_PERIOD_US`] from 100 ms on, its fix
/// (or none: no pad in view) reaching the estimator stage [`PROCESS_DELAY_US`] after the
/// exposure.
pub struct CameraFrames {
    next_exposure_us: u64,
    /// (delivery time, exposure time, fix), in delivery order.
    processing: VecDeque<(u64, u64, Option<PadFix>)>,
}

impl CameraFrames {
    pub fn new() -> Self {
        CameraFrames {
            next_exposure_us: 100_000,
            processing: VecDeque::new(),
        }
    }

    /// The exposure time of the frame exposed by `now`, if one is due.
    pub fn exposure_due(&mut self, now: u64) -> Option<u64> {
        if now < self.next_exposure_us {
            return None;
        }
        let exposure_us = self.next_exposure_us;
        self.next_exposure_us += FRAME_PERIOD_US;
        Some(exposure_us)
    }

    /// Starts processing the frame exposed at `exposure_us`, whose fix is `fix`.
    pub fn process(&mut self, exposure_us: u64, fix: Option<PadFix>) {
        self.processing
            .push_back((exposure_us + PROCESS_DELAY_US, exposure_us, fix));
    }

    /// The next frame processed by `now`: (exposure time, fix).
    pub fn processed(&mut self, now: u64) -> Option<(u64, Option<PadFix>)> {
        if self.processing.front().is_some_and(|(t, _, _)| *t <= now) {
            self.processing.pop_front().map(|(_, te, fix)| (te, fix))
        } else {
            None
        }
    }
}
