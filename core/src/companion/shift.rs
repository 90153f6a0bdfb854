//! PX4 profile: the outer loop that shifts the LOCAL_NED point against the vehicle's measured
//! offset from the pad (TD_PX4_OL_ALT).
//!
//! # Why
//! PX4 flies precision landing on its own position estimate and never on our measurement: the
//! navigator turns the target's `x_abs, y_abs` into the position setpoint, and the multicopter
//! position controller (P on the position error, MPC_XY_P 0.95 /s, then a velocity PID,
//! MPC_XY_VEL_P/I/D_ACC 1.8 / 0.4 / 0.2) drives its *estimate* there. The velocity PID's
//! integrator removes any steady velocity error, so in a hover its estimated velocity settles
//! where `MPC_XY_P * (setpoint - estimate)` equals it: an estimated velocity that is off by
//! `b` while the vehicle stands still leaves the estimate `b / MPC_XY_P` from the setpoint
//! (0.3 m/s: 32 cm), and the vehicle with it. The absolute point we send is exact in PX4's
//! frame; the landing misses by that steady offset. The offset is slow (an estimator bias), so
//! one integral cancels it: the board measures where the vehicle is against the pad (the level
//! estimate plus TD_CAM_POS, independent of PX4's estimate) and moves the point it sends by
//! the integral of that offset until the vehicle, not the setpoint, is over the pad.
//!
//! # The loop
//! With the vehicle at `pad + shift + s` (`s` PX4's steady offset), the measured
//! vehicle-to-pad offset is `d = -(shift + s)`, and `shift' = gain * d` settles at
//! `shift = -s` with the time constant `1 / gain`. What the integral acts through is PX4's
//! path from the point we send to the vehicle: the trajectory generator (jerk- and
//! acceleration-limited, and slowed further while the vehicle lags behind it) and the closed
//! position loop (`w_n = sqrt(1.8 * 0.95) = 1.31 rad/s`, damping 0.69 at PX4's defaults). On
//! PX4 SIH (752ecd3d) a target moving at 0.3 m/s was followed 1.5 s late by the setpoint and
//! some 0.8 s later again by the estimate: about 2.5 s in all. An integrator behind a lag `T`
//! keeps a phase margin of `90 deg - gain * T`: [`ShiftConfig::gain_per_s`] = 0.15 /s keeps
//! 68 degrees at 2.5 s. (A first version at 0.3 /s, without the speed gate, integrating from
//! 8 m, ran to its bound on SIH: 1.2 and 1.7 m off where the same landing without it was
//! 0.7 m off.)
//!
//! It only integrates
//! - below TD_PX4_OL_ALT (the camera's height over the pad; 0 turns the loop off);
//! - above [`ShiftConfig::floor_m`]: in the last half metre PX4's position loop has no time
//!   left to follow (and on the ground the vehicle cannot move, so the integral would only
//!   wind up);
//! - within [`ShiftConfig::gate_m`] of the pad and slower than [`ShiftConfig::max_speed_mps`]
//!   against it (the estimator's relative velocity, which PX4's velocity error does not
//!   touch): farther off, or faster, the vehicle is still flying there, not sitting at a
//!   steady offset, and integrating the approach would wind the shift up;
//! - while PX4 says it is in an AUTO mode that lands on our target (PRECLAND, or RTL and
//!   MISSION, whose landings precision-land with RTL_PLD_MD / NAV_LAND param2): in Position
//!   mode or a Hold over the pad the vehicle does not fly to our point, and the integral would
//!   run to its bound. Any other mode resets it.
//!
//! The shift is bounded by [`ShiftConfig::bound_m`] (a wrong measurement can move the point by
//! no more), kept through gaps of the pad (PX4 keeps flying to the last point it received,
//! shifted), and reset when the pad has been lost for [`ShiftConfig::reset_after_us`] (PX4's
//! PLD_BTOUT default: by then PX4 has given the target up too), on an autopilot reboot and
//! when the parameter or the profile turns it off.

use nalgebra::Vector2;

/// The outer loop's fixed tuning (see the module docs for where each comes from).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShiftConfig {
    /// Integral gain, 1/s: 68 degrees of phase margin behind PX4's 2.5 s of lag.
    pub gain_per_s: f32,
    /// Largest shift, metres.
    pub bound_m: f32,
    /// No integration farther than this from the pad (horizontal), metres.
    pub gate_m: f32,
    /// No integration while the vehicle moves faster than this against the pad
    /// (horizontal), m/s.
    pub max_speed_mps: f32,
    /// No integration with the camera this close to the pad, metres.
    pub floor_m: f32,
    /// Longest step integrated at once, µs (a gap longer than this counts as this long).
    pub max_step_us: u64,
    /// The pad not seen for this long resets the shift, µs.
    pub reset_after_us: u64,
}

impl Default for ShiftConfig {
    fn default() -> Self {
        ShiftConfig {
            gain_per_s: 0.15,
            // SIH's offsets reached 0.8 m; twice PX4's 0.3 m/s velocity-estimate error over
            // MPC_XY_P, with room.
            bound_m: 1.0,
            gate_m: 1.0,
            // Above the gusts' few tenths, below PX4's approach speeds (MPC_XY_CRUISE 5 m/s,
            // braking at MPC_ACC_HOR 3 m/s^2: still 1.3 m/s at 0.3 m from its goal).
            max_speed_mps: 0.5,
            floor_m: 0.5,
            max_step_us: 200_000,
            reset_after_us: 5_000_000,
        }
    }
}

/// One frame's measurement of the vehicle against the pad.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShiftMeasurement {
    /// The frame's exposure, our clock, µs.
    pub exposure_us: u64,
    /// The pad minus the vehicle's origin, north and east, metres.
    pub offset_ne: Vector2<f32>,
    /// How fast that changes, north and east, m/s.
    pub rate_ne: Vector2<f32>,
    /// The camera's height over the pad, metres.
    pub height_m: f32,
}

/// The shift and the time of the last measurement it took.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PadShift {
    shift: Vector2<f32>,
    last_us: Option<u64>,
}

impl PadShift {
    /// No shift.
    pub fn new() -> Self {
        PadShift::default()
    }

    /// The shift in force, north and east, metres.
    pub fn shift(&self) -> Vector2<f32> {
        self.shift
    }

    /// Back to no shift.
    pub fn reset(&mut self) {
        *self = PadShift::default();
    }

    /// A frame without a usable estimate at `exposure_us`: the shift is kept through a gap
    /// and reset once the pad has been lost for `reset_after_us`.
    pub fn on_gap(&mut self, config: &ShiftConfig, exposure_us: u64) {
        if self
            .last_us
            .is_some_and(|last| exposure_us.saturating_sub(last) > config.reset_after_us)
        {
            self.reset();
        }
    }

    /// One frame's measurement `m`; `ceiling_m` is TD_PX4_OL_ALT and `active` whether PX4 is
    /// in a mode that flies to our point. Returns the shift to add to the point sent. Never
    /// panics; a non-finite input integrates nothing.
    pub fn update(
        &mut self,
        config: &ShiftConfig,
        ceiling_m: f32,
        active: bool,
        m: &ShiftMeasurement,
    ) -> Vector2<f32> {
        let ShiftMeasurement {
            exposure_us,
            offset_ne,
            rate_ne,
            height_m,
        } = *m;
        // Written so that NaN turns the loop off too.
        if !(ceiling_m > 0.0) || !active {
            self.reset();
            return self.shift;
        }
        self.on_gap(config, exposure_us);
        let dt_us = match self.last_us {
            // A repeat or an older frame adds nothing.
            Some(last) => exposure_us.saturating_sub(last).min(config.max_step_us),
            None => 0,
        };
        if self.last_us.is_none_or(|last| exposure_us > last) {
            self.last_us = Some(exposure_us);
        }
        let usable = offset_ne.iter().all(|v| v.is_finite())
            && rate_ne.iter().all(|v| v.is_finite())
            && height_m.is_finite();
        let inside = height_m < ceiling_m
            && height_m > config.floor_m
            && offset_ne.norm() < config.gate_m
            && rate_ne.norm() < config.max_speed_mps;
        if usable && inside {
            let dt = dt_us as f32 * 1e-6;
            let next = self.shift + offset_ne * (config.gain_per_s * dt);
            let n = next.norm();
            self.shift = if n > config.bound_m && n.is_finite() {
                next * (config.bound_m / n)
            } else {
                next
            };
            if !self.shift.iter().all(|v| v.is_finite()) {
                self.shift = Vector2::zeros();
            }
        }
        self.shift
    }
}

/// Whether a PX4 HEARTBEAT's mode lands on our target: custom mode enabled, main mode AUTO
/// (4), sub-mode MISSION (4), RTL (5) or PRECLAND (9) (PX4's `px4_custom_mode.h`: main mode
/// in bits 16-23, sub-mode in bits 24-31).
pub fn px4_mode_lands_on_target(base_mode_custom: bool, custom_mode: u32) -> bool {
    const MAIN_AUTO: u32 = 4;
    const SUB_MISSION: u32 = 4;
    const SUB_RTL: u32 = 5;
    const SUB_PRECLAND: u32 = 9;
    let main = (custom_mode >> 16) & 0xFF;
    let sub = (custom_mode >> 24) & 0xFF;
    base_mode_custom && main == MAIN_AUTO && matches!(sub, SUB_MISSION | SUB_RTL | SUB_PRECLAND)
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec;
    use std::vec::Vec;

    const PRECLAND: u32 = (9 << 24) | (4 << 16);

    fn meas(
        exposure_us: u64,
        offset_ne: Vector2<f32>,
        rate_ne: Vector2<f32>,
        height_m: f32,
    ) -> ShiftMeasurement {
        ShiftMeasurement {
            exposure_us,
            offset_ne,
            rate_ne,
            height_m,
        }
    }

    #[test]
    fn px4_modes() {
        assert!(px4_mode_lands_on_target(true, PRECLAND));
        assert!(px4_mode_lands_on_target(true, (5 << 24) | (4 << 16)));
        assert!(px4_mode_lands_on_target(true, (4 << 24) | (4 << 16)));
        // AUTO.LOITER (the SITL's 0x03040000), AUTO.LAND, POSCTL, no custom mode.
        assert!(!px4_mode_lands_on_target(true, 0x0304_0000));
        assert!(!px4_mode_lands_on_target(true, (6 << 24) | (4 << 16)));
        assert!(!px4_mode_lands_on_target(true, 3 << 16));
        assert!(!px4_mode_lands_on_target(false, PRECLAND));
    }

    /// PX4's loop around the shift, in one axis at 50 Hz: the target is the pad plus the
    /// shift; PX4's setpoint follows it 1.5 s late (its trajectory generator, as on SIH) and
    /// PX4 drives its estimate there with P on the position (0.95) and a velocity PI (1.8,
    /// 0.4) on an estimated velocity off by `bias`, so the vehicle stands `bias / 0.95` from
    /// its setpoint; the board measures the true offset with `delay` frames of lag.
    /// Returns the vehicle's true offset from the pad after each second.
    fn px4_axis(bias: f32, seconds: usize, delay: usize, config: &ShiftConfig) -> Vec<f32> {
        let dt = 0.02f32;
        let (mut p, mut v, mut integ, mut acc) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        let mut shift = PadShift::new();
        let mut seen = std::collections::VecDeque::from(vec![0.0f32; delay + 1]);
        let mut out = Vec::new();
        let mut sp = 0.0f32;
        let mut traj = 0.0f32;
        for k in 0..seconds * 50 {
            seen.push_back(p);
            let measured = seen.pop_front().unwrap_or(0.0);
            let t_us = k as u64 * 20_000;
            sp = shift
                .update(
                    config,
                    10.0,
                    true,
                    &meas(
                        t_us,
                        Vector2::new(-measured, 0.0),
                        Vector2::new(-v, 0.0),
                        5.0,
                    ),
                )
                .x;
            traj += (sp - traj) * (dt / 1.5);
            let v_est = v + bias;
            let v_sp = 0.95 * (traj - p);
            let e = v_sp - v_est;
            integ += 0.4 * e * dt;
            let a_sp = 1.8 * e + integ;
            // The attitude loop's lag.
            acc += (a_sp - acc) * (dt / 0.15);
            v += acc * dt;
            p += v * dt;
            if (k + 1) % 50 == 0 {
                out.push(p);
            }
        }
        let _ = sp;
        out
    }

    #[test]
    fn the_shift_cancels_a_steady_offset_without_overshoot() {
        let config = ShiftConfig::default();
        // Without the loop the vehicle settles 32 cm off.
        let off = px4_axis(
            0.3,
            40,
            3,
            &ShiftConfig {
                gain_per_s: 0.0,
                ..config
            },
        );
        let steady = *off.last().unwrap();
        assert!((steady + 0.3 / 0.95).abs() < 0.01, "{steady}");
        let on = px4_axis(0.3, 60, 3, &config);
        // Within 5 cm after 20 s, 1 cm after 35 s, and never beyond the pad by more than a
        // tenth of the offset (stable, well damped).
        assert!(on[19].abs() < 0.05, "{on:?}");
        assert!(on[34].abs() < 0.01, "{on:?}");
        assert!(on.iter().all(|p| *p < 0.1 * 0.3 / 0.95), "{on:?}");
        // A longer delay (0.3 s of frames) still converges.
        let slow = px4_axis(0.3, 60, 15, &config);
        assert!(slow[34].abs() < 0.015, "{slow:?}");
        // Twice the gain (0.3 /s) overshoots by more than a tenth behind the same lag.
        let fast = px4_axis(
            0.3,
            60,
            3,
            &ShiftConfig {
                gain_per_s: 0.3,
                ..config
            },
        );
        assert!(fast.iter().any(|p| *p > 0.1 * 0.3 / 0.95), "{fast:?}");
    }

    #[test]
    fn the_shift_is_bounded_and_resets() {
        let config = ShiftConfig::default();
        let mut s = PadShift::new();
        let far = Vector2::new(0.8, 0.6); // 1.0 m: outside the gate
        let near = Vector2::new(0.56, 0.42); // 0.7 m
        let mut t = 0u64;
        for _ in 0..10_000 {
            t += 33_333;
            s.update(&config, 8.0, true, &meas(t, near, Vector2::zeros(), 3.0));
        }
        assert!(
            (s.shift().norm() - config.bound_m).abs() < 1e-4,
            "{}",
            s.shift()
        );
        // Points along the measured offset.
        assert!((s.shift().normalize() - near.normalize()).norm() < 1e-4);
        let held = s.shift();
        // Outside the gate, moving, above the ceiling, below the floor: held.
        t += 33_333;
        let moving = Vector2::new(0.0, 0.6);
        assert_eq!(
            s.update(&config, 8.0, true, &meas(t, -near, moving, 3.0)),
            held
        );
        t += 33_333;
        assert_eq!(
            s.update(&config, 8.0, true, &meas(t, -far, Vector2::zeros(), 3.0)),
            held
        );
        t += 33_333;
        assert_eq!(
            s.update(&config, 8.0, true, &meas(t, -near, Vector2::zeros(), 9.0)),
            held
        );
        t += 33_333;
        assert_eq!(
            s.update(&config, 8.0, true, &meas(t, -near, Vector2::zeros(), 0.3)),
            held
        );
        // Bad input integrates nothing and keeps the shift finite.
        t += 33_333;
        let nan = Vector2::new(f32::NAN, 0.0);
        assert_eq!(
            s.update(&config, 8.0, true, &meas(t, nan, Vector2::zeros(), 3.0)),
            held
        );
        t += 33_333;
        assert_eq!(
            s.update(
                &config,
                8.0,
                true,
                &meas(t, -near, Vector2::zeros(), f32::INFINITY)
            ),
            held
        );
        // A gap shorter than the reset keeps it; a frame after it integrates one step only.
        t += 4_000_000;
        s.on_gap(&config, t);
        assert_eq!(s.shift(), held);
        let after = s.update(
            &config,
            8.0,
            true,
            &meas(t + 1, -near, Vector2::zeros(), 3.0),
        );
        assert!((after - held).norm() < 0.3 * 0.2 * 0.7 + 1e-4);
        // The pad lost for longer than the reset: gone.
        s.on_gap(&config, t + 1 + config.reset_after_us + 1);
        assert_eq!(s.shift(), Vector2::zeros());
        // Off (TD_PX4_OL_ALT 0, NaN) or not in a landing mode: reset at once.
        for (ceiling, active) in [(0.0, true), (f32::NAN, true), (8.0, false)] {
            let mut s = PadShift::new();
            s.update(&config, 8.0, true, &meas(0, near, Vector2::zeros(), 3.0));
            s.update(
                &config,
                8.0,
                true,
                &meas(100_000, near, Vector2::zeros(), 3.0),
            );
            assert!(s.shift().norm() > 0.0);
            assert_eq!(
                s.update(
                    &config,
                    ceiling,
                    active,
                    &meas(200_000, near, Vector2::zeros(), 3.0)
                ),
                Vector2::zeros()
            );
        }
        // Time going back, or u64 extremes: nothing integrated, no panic.
        let mut s = PadShift::new();
        s.update(
            &config,
            8.0,
            true,
            &meas(u64::MAX, near, Vector2::zeros(), 3.0),
        );
        assert_eq!(
            s.update(&config, 8.0, true, &meas(0, near, Vector2::zeros(), 3.0)),
            Vector2::zeros()
        );
        assert_eq!(
            s.update(
                &config,
                8.0,
                true,
                &meas(u64::MAX, near, Vector2::zeros(), 3.0)
            ),
            Vector2::zeros()
        );
    }
}
