//! The closed loop's vehicle: a multicopter as a point mass whose thrust tilts to the
//! commanded horizontal acceleration.
//!
//! - Horizontal: the thrust's horizontal part (the tilt, `g tan(tilt)`) follows the commanded
//!   acceleration with a first-order lag ([`VehicleParams::attitude_tau_s`], the attitude
//!   loop's response: ArduCopter's ATC_INPUT_TC, 0.15 s), limited to
//!   [`VehicleParams::max_tilt_deg`]; the air pushes on the airspeed `a = wind - velocity`
//!   as ArduPilot SITL's multicopter frame does (`SIM_Frame.cpp`, `SIM_Motor.cpp`): the
//!   rotors' momentum drag, linear in the airspeed (`drag_per_s * a`), and the body's
//!   drag, quadratic per axis (`body_drag_per_m * a |a|`, SITL's `areaCd * rho / 2` over
//!   the mass).
//! - Vertical: the climb rate follows the commanded one with its own first-order lag.
//! - Attitude: the body's thrust axis along the specific force the vehicle produces, nose at
//!   a fixed heading ([`touchdown_sim::trajectory::attitude_for`], the simulator's own rule,
//!   so the rendered camera and the autopilot's attitude agree with the motion).
//!
//! Positions are NED relative to the pad's origin (down = minus the height over the pad);
//! [`Vehicle::truth`] gives the [`TrueState`] of the rest of the crate (pad frame).

use nalgebra::{Matrix3, Vector2, Vector3};
use touchdown_sim::trajectory::{attitude_for, GRAVITY};

use crate::flight::{TrueState, NED_FROM_PAD};

/// How the vehicle responds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleParams {
    /// Time constant of the tilt following the commanded acceleration, seconds.
    pub attitude_tau_s: f64,
    /// Time constant of the climb rate following the commanded one, seconds.
    pub climb_tau_s: f64,
    /// The rotors' momentum drag, linear in the airspeed, 1/s (acceleration per m/s).
    pub drag_per_s: f64,
    /// The body's drag, quadratic in the airspeed, 1/m (acceleration per (m/s)^2).
    pub body_drag_per_m: f64,
    /// Largest tilt, degrees.
    pub max_tilt_deg: f64,
    /// Heading, radians from north toward east.
    pub yaw: f64,
}

impl VehicleParams {
    /// A small multicopter: attitude response 0.15 s, climb response 0.3 s, 30 degrees of
    /// tilt at most (ArduPilot's ANGLE_MAX default), nose north. Its drag is that of the
    /// frame ArduPilot SITL flies by default (`SIM_Frame.h`'s default model: 3 kg, 0.385 m^2
    /// of rotor disc, mdrag_coef 0.2, a reference of 15.08 m/s at 45 degrees of tilt), at sea
    /// level: momentum drag `mdrag_coef * sqrt(thrust * rho * disc) / mass` = 0.24 /s at
    /// hover; the body's areaCd is what the reference's drag force leaves over the rotors'
    /// part, 0.175 m^2, so `0.5 * rho * areaCd / mass` = 0.036 /m (at 5 m/s of airspeed the
    /// body adds 0.9 m/s^2 to the rotors' 1.2).
    pub fn typical() -> Self {
        VehicleParams {
            attitude_tau_s: 0.15,
            climb_tau_s: 0.3,
            drag_per_s: 0.24,
            body_drag_per_m: 0.036,
            max_tilt_deg: 30.0,
            yaw: 0.0,
        }
    }
}

/// What the autopilot asks of the vehicle.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Command {
    /// Horizontal acceleration, north and east, m/s^2.
    pub accel_ne: Vector2<f64>,
    /// Down velocity, m/s (positive: descending).
    pub down_mps: f64,
}

/// The vehicle's state (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vehicle {
    /// How it responds.
    pub params: VehicleParams,
    /// Position, NED from the pad's origin, metres.
    pub position_ned: Vector3<f64>,
    /// Velocity, NED, m/s.
    pub velocity_ned: Vector3<f64>,
    /// The thrust's horizontal acceleration (the tilt), north and east, m/s^2.
    pub tilt_accel_ne: Vector2<f64>,
    /// The vertical acceleration of the last step, down, m/s^2.
    pub down_accel: f64,
}

impl Vehicle {
    /// Hovering still at `position_ned`.
    pub fn hovering(params: VehicleParams, position_ned: Vector3<f64>) -> Self {
        Vehicle {
            params,
            position_ned,
            velocity_ned: Vector3::zeros(),
            tilt_accel_ne: Vector2::zeros(),
            down_accel: 0.0,
        }
    }

    /// Height of the body origin (the camera) over the pad, metres.
    pub fn height_m(&self) -> f64 {
        -self.position_ned.z
    }

    /// Flies `dt_s` on `command` in `wind_ned`.
    pub fn step(&mut self, dt_s: f64, command: &Command, wind_ned: &Vector3<f64>) {
        let p = self.params;
        let limit = GRAVITY * p.max_tilt_deg.to_radians().tan();
        let mut wanted = command.accel_ne;
        if wanted.norm() > limit {
            wanted *= limit / wanted.norm();
        }
        let k = 1.0 - (-dt_s / p.attitude_tau_s.max(1e-6)).exp();
        self.tilt_accel_ne += (wanted - self.tilt_accel_ne) * k;
        let kz = 1.0 - (-dt_s / p.climb_tau_s.max(1e-6)).exp();
        let down_velocity = self.velocity_ned.z + (command.down_mps - self.velocity_ned.z) * kz;
        self.down_accel = (down_velocity - self.velocity_ned.z) / dt_s;
        let air = wind_ned - self.velocity_ned;
        let drag = air * p.drag_per_s + air.map(|a| a * a.abs()) * p.body_drag_per_m;
        let accel = Vector3::new(
            self.tilt_accel_ne.x + drag.x,
            self.tilt_accel_ne.y + drag.y,
            self.down_accel,
        );
        self.position_ned += (self.velocity_ned + 0.5 * accel * dt_s) * dt_s;
        self.velocity_ned += accel * dt_s;
        self.velocity_ned.z = down_velocity;
    }

    /// Body FRD to NED: the thrust axis along the specific force of the tilt and the climb.
    pub fn body_to_ned(&self) -> Matrix3<f64> {
        // attitude_for takes the acceleration the thrust produces in the pad frame (east,
        // north, up).
        let thrust_pad = [self.tilt_accel_ne.y, self.tilt_accel_ne.x, -self.down_accel];
        let m = attitude_for(thrust_pad, self.params.yaw);
        Matrix3::from_fn(|i, j| m[i][j])
    }

    /// The truth of the rest of the crate: position in the pad frame and the attitude.
    pub fn truth(&self) -> TrueState {
        TrueState {
            position: NED_FROM_PAD * self.position_ned,
            body_to_ned: self.body_to_ned(),
        }
    }

    /// The velocity in the pad frame, m/s.
    pub fn velocity_pad(&self) -> Vector3<f64> {
        NED_FROM_PAD * self.velocity_ned
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    #[test]
    fn the_vehicle_tilts_toward_its_acceleration_and_drifts_with_the_wind() {
        let mut v = Vehicle::hovering(VehicleParams::typical(), Vector3::new(0.0, 0.0, -10.0));
        let east = Command {
            accel_ne: Vector2::new(0.0, 2.0),
            down_mps: 0.0,
        };
        for _ in 0..400 {
            v.step(0.0025, &east, &Vector3::zeros());
        }
        // After 1 s (almost 7 time constants) the tilt gives the commanded 2 m/s^2 east.
        assert!(
            (v.tilt_accel_ne.y - 2.0).abs() < 0.01,
            "{}",
            v.tilt_accel_ne
        );
        let thrust = v.body_to_ned() * Vector3::new(0.0, 0.0, -1.0);
        assert!(thrust.y > 0.19 && thrust.z < -0.97, "{thrust}");
        let tilt = (2.0f64 / GRAVITY).atan();
        let angle = Rotation3::from_matrix_unchecked(v.body_to_ned()).angle();
        assert!((angle - tilt).abs() < 2e-3, "{angle} {tilt}");
        // Level in a 3 m/s wind: the drag accelerates it toward 3 m/s downwind.
        let mut w = Vehicle::hovering(VehicleParams::typical(), Vector3::new(0.0, 0.0, -10.0));
        for _ in 0..40_000 {
            w.step(0.0025, &Command::default(), &Vector3::new(3.0, 0.0, 0.0));
        }
        assert!((w.velocity_ned.x - 3.0).abs() < 0.01, "{}", w.velocity_ned);
        // Never beyond 30 degrees.
        let mut hard = Vehicle::hovering(VehicleParams::typical(), Vector3::zeros());
        let far = Command {
            accel_ne: Vector2::new(100.0, 0.0),
            down_mps: 0.0,
        };
        for _ in 0..1000 {
            hard.step(0.0025, &far, &Vector3::zeros());
        }
        assert!((hard.tilt_accel_ne.norm() - GRAVITY * 30f64.to_radians().tan()).abs() < 1e-6);
    }

    #[test]
    fn the_climb_rate_follows_the_command() {
        let mut v = Vehicle::hovering(VehicleParams::typical(), Vector3::new(0.0, 0.0, -20.0));
        let down = Command {
            accel_ne: Vector2::zeros(),
            down_mps: 1.5,
        };
        for _ in 0..1200 {
            v.step(0.0025, &down, &Vector3::zeros());
        }
        assert!((v.velocity_ned.z - 1.5).abs() < 1e-3);
        // 3 s at 1.5 m/s less the 0.3 s lag.
        assert!(
            (v.height_m() - (20.0 - 1.5 * 2.7)).abs() < 0.02,
            "{}",
            v.height_m()
        );
        assert_eq!(v.truth().position.z, v.height_m());
    }
}
