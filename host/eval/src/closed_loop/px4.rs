//! The closed loop's PX4: the navigator's Precision Land and the multicopter position
//! controller, flying on PX4's own (biased) estimates.
//!
//! What it does, and where PX4 does it (read in PX4's source, `main` of 2025 as stored in our
//! code index and the strings of the SITL build at 752ecd3d; our words, our code):
//! - **Target** (`mavlink_receiver.cpp`, `handle_message_landing_target`): a LOCAL_NED
//!   LANDING_TARGET is `landing_target_pose.x_abs, y_abs, z_abs` as is. The navigator's
//!   precision landing (`navigator/precland.cpp`) counts it valid for PLD_BTOUT (5 s) after
//!   its time stamp.
//! - **States** (`precland.cpp`): Start until a target is valid; *horizontal approach* at the
//!   height where it began, the position setpoint the target's `x_abs, y_abs`; once PX4's
//!   estimate is within PLD_HACC_RAD (0.2 m) of the target on **each** of north and east for
//!   2 s, *descend above target*: a LAND setpoint at the target's `x_abs, y_abs`, updated
//!   with every target. A target stale beyond PLD_BTOUT ends the descent: *final approach*
//!   (keep descending to the last point) when PX4's estimate is less than PLD_FAPPR_ALT
//!   (0.1 m) above the target's `z_abs`, else "Lost landing target while landing": search
//!   (climb to PLD_SRCH_ALT) or fall back to a normal landing. Near the ground (within
//!   PLD_FAPPR_ALT) a target older than 0.5 s already counts as lost for the descent. Landed
//!   ends it all. The model climbs away on "lost" (as the SITL did twice) and never lands then.
//! - **Setpoint shaping** (`FlightTaskAuto`, `_prepareLandSetpoints`, and
//!   `PositionSmoothing`): the land position follows the navigator's target each cycle; the
//!   trajectory generator moves the position setpoint toward it, limited to MPC_XY_CRUISE
//!   (5 m/s) and MPC_ACC_HOR (3 m/s^2) and braking in time (MPC_JERK_AUTO 4 m/s^3), and
//!   here also at most MPC_XY_TRAJ_P (0.5 /s) times its distance to the goal: the model's
//!   stand-in for how PX4 SIH followed a moving target (its setpoint 1.5 s behind a target
//!   moving at 0.3 m/s, POSITION_TARGET_LOCAL_NED on the ground station link); the
//!   descent is MPC_LAND_SPEED (0.7 m/s) below MPC_LAND_ALT2 (5 m), interpolated to
//!   MPC_Z_V_AUTO_DN (1.5 m/s) at MPC_LAND_ALT1 (10 m).
//! - **Position control** (`mc_pos_control`, `PositionControl`): velocity setpoint = the
//!   trajectory's velocity + MPC_XY_P (0.95 /s) times the position error of PX4's *estimate*;
//!   a velocity PID (MPC_XY_VEL_P_ACC 1.8 /s, MPC_XY_VEL_I_ACC 0.4 /s^2, MPC_XY_VEL_D_ACC 0.2
//!   on the estimated acceleration) on the *estimated* velocity gives the acceleration, tilt
//!   limited to MPC_TILTMAX_AIR (45 deg); its integrator stops while the output is cut.
//!   The defaults were read from the SITL with PARAM_REQUEST_READ (docs/setup-px4.md).
//! - **Estimates**: the local position with the error model's drift
//!   ([`crate::flight::Realisation::position_error`], the same the board sees in
//!   LOCAL_POSITION_NED), and a constant velocity-estimate error [`Px4Params::velocity_bias_ne`]
//!   that the position does not share. With the velocity PID's integrator the estimate then
//!   stands `bias / MPC_XY_P` from its setpoint in a hover, as PX4 SIH did (20-60 cm).
//!
//! Not modelled: the search pattern and the normal-landing fallback (the model reports the
//! loss and climbs), the land detector's delay (touchdown is the first ground contact), yaw.

use nalgebra::{Vector2, Vector3};
use touchdown_sim::trajectory::GRAVITY;

use super::vehicle::Command;

/// PX4's parameters (defaults of the SITL build; see the module docs) and the estimate bias.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Px4Params {
    /// MPC_XY_P, 1/s.
    pub xy_p: f64,
    /// MPC_XY_VEL_P_ACC, 1/s.
    pub vel_p: f64,
    /// MPC_XY_VEL_I_ACC, 1/s^2.
    pub vel_i: f64,
    /// MPC_XY_VEL_D_ACC, dimensionless.
    pub vel_d: f64,
    /// MPC_TILTMAX_AIR, degrees.
    pub tilt_max_deg: f64,
    /// MPC_XY_CRUISE, m/s.
    pub cruise_mps: f64,
    /// MPC_ACC_HOR, m/s^2.
    pub acc_hor: f64,
    /// MPC_JERK_AUTO, m/s^3.
    pub jerk: f64,
    /// MPC_XY_TRAJ_P, 1/s (see the module docs).
    pub traj_p: f64,
    /// MPC_LAND_SPEED, m/s.
    pub land_speed_mps: f64,
    /// MPC_Z_V_AUTO_DN, m/s.
    pub descent_high_mps: f64,
    /// MPC_LAND_ALT1, m.
    pub land_alt1_m: f64,
    /// MPC_LAND_ALT2, m.
    pub land_alt2_m: f64,
    /// MPC_Z_P, 1/s (holding the approach height).
    pub z_p: f64,
    /// PLD_HACC_RAD, m.
    pub hacc_rad_m: f64,
    /// How long within PLD_HACC_RAD before the descent, s.
    pub settle_s: f64,
    /// PLD_BTOUT, s.
    pub btout_s: f64,
    /// PLD_FAPPR_ALT, m.
    pub fappr_alt_m: f64,
    /// The velocity estimate's constant error, north and east, m/s.
    pub velocity_bias_ne: Vector2<f64>,
}

impl Px4Params {
    /// The SITL's defaults, no velocity bias.
    pub fn defaults() -> Self {
        Px4Params {
            xy_p: 0.95,
            vel_p: 1.8,
            vel_i: 0.4,
            vel_d: 0.2,
            tilt_max_deg: 45.0,
            cruise_mps: 5.0,
            acc_hor: 3.0,
            jerk: 4.0,
            traj_p: 0.5,
            land_speed_mps: 0.7,
            descent_high_mps: 1.5,
            land_alt1_m: 10.0,
            land_alt2_m: 5.0,
            z_p: 1.0,
            hacc_rad_m: 0.2,
            settle_s: 2.0,
            btout_s: 5.0,
            fappr_alt_m: 0.1,
            velocity_bias_ne: Vector2::zeros(),
        }
    }
}

/// Precision Land's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Px4State {
    /// No valid target yet: hold.
    Start,
    /// Fly to the target at the height where it began.
    HorizontalApproach,
    /// Descend on the target.
    Descend,
    /// Descend on the last target (lost within PLD_FAPPR_ALT).
    FinalApproach,
    /// "Lost landing target while landing": the model climbs away.
    Lost,
}

/// The navigator and the position controller (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Px4PrecLand {
    /// Its parameters.
    pub params: Px4Params,
    /// The state.
    pub state: Px4State,
    hold: Vector3<f64>,
    approach_z: f64,
    /// The newest target: when it was measured (its stamp), the pad's absolute point.
    target: Option<(f64, Vector3<f64>)>,
    settled_since: Option<f64>,
    traj: Vector2<f64>,
    traj_v: Vector2<f64>,
    integral: Vector2<f64>,
    last_vel: Option<Vector2<f64>>,
    accel_est: Vector2<f64>,
    /// When the horizontal approach began, s.
    pub approach_s: Option<f64>,
    /// When the descent began, s.
    pub descend_s: Option<f64>,
    /// When the final approach began, s.
    pub final_s: Option<f64>,
    /// When the target was lost, s.
    pub lost_s: Option<f64>,
    /// Targets used.
    pub targets_used: usize,
    /// Longest time between two targets' stamps, s.
    pub longest_gap_s: f64,
}

impl Px4PrecLand {
    /// Precision Land engaged with PX4's estimate at `own_ned`.
    pub fn new(params: Px4Params, own_ned: &Vector3<f64>) -> Self {
        Px4PrecLand {
            params,
            state: Px4State::Start,
            hold: *own_ned,
            approach_z: own_ned.z,
            target: None,
            settled_since: None,
            traj: own_ned.xy(),
            traj_v: Vector2::zeros(),
            integral: Vector2::zeros(),
            last_vel: None,
            accel_est: Vector2::zeros(),
            approach_s: None,
            descend_s: None,
            final_s: None,
            lost_s: None,
            targets_used: 0,
            longest_gap_s: 0.0,
        }
    }

    /// A target (`landing_target_pose`): the pad's absolute point, stamped `measured_s`.
    pub fn measure(&mut self, measured_s: f64, pad_ned: &Vector3<f64>) {
        if !pad_ned.iter().all(|v| v.is_finite()) || !measured_s.is_finite() {
            return;
        }
        if let Some((t, _)) = self.target {
            self.longest_gap_s = self.longest_gap_s.max(measured_s - t);
        }
        self.targets_used += 1;
        self.target = Some((measured_s, *pad_ned));
    }

    /// The position setpoint's goal now (north, east), before shaping.
    pub fn goal_ne(&self) -> Vector2<f64> {
        match (self.state, self.target) {
            (Px4State::Start | Px4State::Lost, _) | (_, None) => self.hold.xy(),
            (_, Some((_, p))) => p.xy(),
        }
    }

    /// Runs the state machine at `now_s` on PX4's position estimate `own`.
    fn update_state(&mut self, now_s: f64, own: &Vector3<f64>) {
        let p = &self.params;
        let age = self.target.map(|(t, _)| now_s - t);
        let valid = age.is_some_and(|a| a <= p.btout_s);
        match self.state {
            Px4State::Start if valid => {
                self.state = Px4State::HorizontalApproach;
                self.approach_z = own.z;
                self.approach_s = Some(now_s);
            }
            Px4State::HorizontalApproach => {
                if !valid {
                    self.lose(now_s, own);
                    return;
                }
                let Some((_, t)) = self.target else { return };
                let within =
                    (t.x - own.x).abs() < p.hacc_rad_m && (t.y - own.y).abs() < p.hacc_rad_m;
                if !within {
                    self.settled_since = None;
                } else if now_s - *self.settled_since.get_or_insert(now_s) > p.settle_s {
                    self.state = Px4State::Descend;
                    self.descend_s = Some(now_s);
                }
            }
            Px4State::Descend => {
                let Some((_, t)) = self.target else { return };
                let near = t.z - own.z < p.fappr_alt_m;
                let fresh = if near {
                    age.is_some_and(|a| a < 0.5)
                } else {
                    valid
                };
                if !fresh {
                    if valid && near {
                        self.state = Px4State::FinalApproach;
                        self.final_s = Some(now_s);
                    } else {
                        self.lose(now_s, own);
                    }
                }
            }
            _ => {}
        }
    }

    fn lose(&mut self, now_s: f64, own: &Vector3<f64>) {
        self.state = Px4State::Lost;
        self.lost_s = Some(now_s);
        self.hold = *own;
    }

    /// The command at `now_s` for a step of `dt_s`, from PX4's position and velocity
    /// estimates (local NED) and its height over the ground.
    pub fn command(
        &mut self,
        now_s: f64,
        dt_s: f64,
        own: &Vector3<f64>,
        own_velocity: &Vector3<f64>,
        height_m: f64,
    ) -> Command {
        self.update_state(now_s, own);
        let p = self.params;
        // The trajectory generator: toward the goal, braking in time, within the limits.
        let to_goal = self.goal_ne() - self.traj;
        let d = to_goal.norm();
        let brake = (2.0 * p.acc_hor * d)
            .sqrt()
            .min((p.jerk * d * d).cbrt())
            .min(p.traj_p * d);
        let want = if d > 1e-9 {
            to_goal / d * brake.min(p.cruise_mps)
        } else {
            Vector2::zeros()
        };
        let dv = want - self.traj_v;
        let max_dv = p.acc_hor * dt_s;
        self.traj_v += if dv.norm() > max_dv {
            dv * (max_dv / dv.norm())
        } else {
            dv
        };
        self.traj += self.traj_v * dt_s;
        // The position and velocity loops on the estimates.
        let v_est = own_velocity.xy() + p.velocity_bias_ne;
        if let Some(last) = self.last_vel {
            // The estimated acceleration, low-passed (PX4 filters its D term too).
            let a = (v_est - last) / dt_s.max(1e-6);
            self.accel_est += (a - self.accel_est) * (dt_s / 0.05).min(1.0);
        }
        self.last_vel = Some(v_est);
        let v_sp = self.traj_v + (self.traj - own.xy()) * p.xy_p;
        let error = v_sp - v_est;
        let raw = error * p.vel_p + self.integral - self.accel_est * p.vel_d;
        let max_acc = GRAVITY * p.tilt_max_deg.to_radians().tan();
        let accel = if raw.norm() > max_acc {
            raw * (max_acc / raw.norm())
        } else {
            // The integrator runs only while the output is not cut.
            self.integral += error * (p.vel_i * dt_s);
            raw
        };
        let down_mps = match self.state {
            Px4State::Start | Px4State::HorizontalApproach => {
                let z_sp = if self.state == Px4State::Start {
                    self.hold.z
                } else {
                    self.approach_z
                };
                ((z_sp - own.z) * p.z_p).clamp(-p.descent_high_mps, p.descent_high_mps)
            }
            Px4State::Descend | Px4State::FinalApproach => {
                let f =
                    ((height_m - p.land_alt2_m) / (p.land_alt1_m - p.land_alt2_m)).clamp(0.0, 1.0);
                p.land_speed_mps + f * (p.descent_high_mps - p.land_speed_mps)
            }
            Px4State::Lost => -1.0,
        };
        Command {
            accel_ne: accel,
            down_mps,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::closed_loop::vehicle::{Vehicle, VehicleParams};

    /// A hover on a fixed target: the vehicle stands `bias / MPC_XY_P` from it, toward minus
    /// the bias (its estimated velocity reads `bias` while it stands still).
    #[test]
    fn a_velocity_bias_leaves_the_vehicle_off_its_setpoint() {
        let bias = Vector2::new(0.3, 0.0);
        let params = Px4Params {
            velocity_bias_ne: bias,
            settle_s: 1e9,
            ..Px4Params::defaults()
        };
        let start = Vector3::new(0.0, 0.0, -10.0);
        let mut v = Vehicle::hovering(VehicleParams::typical(), start);
        let mut c = Px4PrecLand::new(params, &start);
        let dt = 0.0025;
        let mut t = 0.0;
        while t < 40.0 {
            c.measure(t, &Vector3::new(1.0, 0.0, 0.0));
            let cmd = c.command(t, dt, &v.position_ned, &v.velocity_ned, v.height_m());
            v.step(dt, &cmd, &Vector3::new(3.0, 1.0, 0.0));
            t += dt;
        }
        assert_eq!(c.state, Px4State::HorizontalApproach);
        let off = v.position_ned.xy() - Vector2::new(1.0, 0.0);
        assert!((off - (-bias / 0.95)).norm() < 0.01, "{off}");
    }
}
