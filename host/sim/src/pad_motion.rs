//! A pad that moves: a boat's deck, a truck's roof, a rover's dock.
//!
//! The simulator's world is the pad frame (x east, y north, z up from the pad's origin), and a
//! scenario's trajectory is the vehicle's in that frame *as the pad lay when its motion began*:
//! the world frame, fixed to the ground. A [`PadMotion`] says where the pad is at each time: a
//! horizontal velocity that turns at a constant rate (a vehicle driving a straight line or an
//! arc), and for a boat the deck's heave (up and down) and roll (about its keel, the direction
//! it travels in). The camera sees the vehicle *relative to the pad*
//! ([`PadMotion::relative`]), so everything rendered (the pad, its margin and the ground
//! texture around it, which is the deck or the roof and moves with the pad) follows the pad,
//! while the vehicle's attitude (what the autopilot reports) stays the world's.
//!
//! Time starts at [`PadMotion::start_s`]: before it the pad lies still where it starts
//! (a rehearsal starts it with the LAND, once the vehicle is over it).

use crate::math::{mul, mul_vec, rot_z, rotation_about, transpose, Mat3, Vec3};
use crate::trajectory::VehicleState;

/// How the pad moves (all zero: at rest).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PadMotion {
    /// Its velocity over the ground when it starts, north and east, m/s.
    pub velocity_ne_mps: [f64; 2],
    /// How fast its heading, and the velocity with it, turns, degrees per second (positive
    /// clockwise seen from above: north toward east).
    pub turn_rate_deg_s: f64,
    /// Heave: the deck's amplitude up and down, metres (a sine).
    pub heave_m: f64,
    /// The heave's period, seconds.
    pub heave_period_s: f64,
    /// Roll: the deck's amplitude about its keel, degrees (a sine).
    pub roll_deg: f64,
    /// The roll's period, seconds.
    pub roll_period_s: f64,
    /// When the motion begins, seconds on the scenario's clock.
    pub start_s: f64,
    /// When it ends (the pad then stays where it is), seconds on the same clock; infinite:
    /// never. A rehearsal against a SITL, whose ground stands still, stops the pad when the
    /// vehicle reaches the ground: a real deck carries the vehicle on with it.
    pub stop_s: f64,
}

/// Where the pad is at one time: its origin and its axes in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PadPose {
    /// The pad's origin from where it started, NED, metres.
    pub origin_ned: Vec3,
    /// The pad's own NED axes (its north the +y of its frame) to the world's NED.
    pub rotation: Mat3,
}

impl Default for PadMotion {
    fn default() -> Self {
        PadMotion::at_rest()
    }
}

/// The pad frame's (east, north, up) coordinates as NED.
fn pad_to_ned(p: Vec3) -> Vec3 {
    [p[1], p[0], -p[2]]
}

/// NED coordinates as the pad frame's (east, north, up).
fn ned_to_pad(p: Vec3) -> Vec3 {
    [p[1], p[0], -p[2]]
}

impl PadMotion {
    /// A pad lying still.
    pub const fn at_rest() -> Self {
        PadMotion {
            velocity_ne_mps: [0.0, 0.0],
            turn_rate_deg_s: 0.0,
            heave_m: 0.0,
            heave_period_s: 0.0,
            roll_deg: 0.0,
            roll_period_s: 0.0,
            start_s: 0.0,
            stop_s: f64::INFINITY,
        }
    }

    /// Whether the pad never moves.
    pub fn is_at_rest(&self) -> bool {
        self.velocity_ne_mps == [0.0, 0.0] && self.heave_m == 0.0 && self.roll_deg == 0.0
    }

    /// Every field finite, periods positive where there is an amplitude; the reason if not.
    pub fn validate(&self) -> Result<(), String> {
        let finite = self.velocity_ne_mps.iter().all(|v| v.is_finite())
            && [
                self.turn_rate_deg_s,
                self.heave_m,
                self.heave_period_s,
                self.roll_deg,
                self.roll_period_s,
                self.start_s,
            ]
            .iter()
            .all(|v| v.is_finite());
        if !finite || self.stop_s.is_nan() {
            return Err("the pad's motion has a value that is not a finite number".into());
        }
        if self.heave_m != 0.0 && self.heave_period_s <= 0.0 {
            return Err("the deck's heave needs a positive period".into());
        }
        if self.roll_deg != 0.0 && self.roll_period_s <= 0.0 {
            return Err("the deck's roll needs a positive period".into());
        }
        if self.roll_deg.abs() >= 45.0 {
            return Err(format!(
                "a deck rolling {} degrees is capsizing, not landing ground",
                self.roll_deg
            ));
        }
        Ok(())
    }

    /// Seconds the pad has moved by `t`.
    fn moved_s(&self, t: f64) -> f64 {
        (t.min(self.stop_s) - self.start_s).max(0.0)
    }

    /// The pad's heading at `t` from its heading at the start, radians.
    fn heading(&self, t: f64) -> f64 {
        self.turn_rate_deg_s.to_radians() * self.moved_s(t)
    }

    /// The axis the deck rolls about, NED, in the pad's own axes: the way it travels when it
    /// starts (north when it does not travel).
    fn keel(&self) -> Vec3 {
        let [n, e] = self.velocity_ne_mps;
        let speed = n.hypot(e);
        if speed > 0.0 {
            [n / speed, e / speed, 0.0]
        } else {
            [1.0, 0.0, 0.0]
        }
    }

    /// Where the pad is at `t`.
    pub fn pose(&self, t: f64) -> PadPose {
        let tau = self.moved_s(t);
        let [vn, ve] = self.velocity_ne_mps;
        let w = self.turn_rate_deg_s.to_radians();
        let (north, east) = if (w * tau).abs() < 1e-9 {
            (vn * tau, ve * tau)
        } else {
            // The velocity turned by `w s` at each time s, integrated from 0 to tau.
            let (s, c) = (w * tau).sin_cos();
            ((s * vn - (1.0 - c) * ve) / w, ((1.0 - c) * vn + s * ve) / w)
        };
        let wave = |amplitude: f64, period: f64| {
            if amplitude == 0.0 || period <= 0.0 {
                0.0
            } else {
                amplitude * (std::f64::consts::TAU * tau / period).sin()
            }
        };
        let up = wave(self.heave_m, self.heave_period_s);
        let roll = wave(self.roll_deg, self.roll_period_s).to_radians();
        PadPose {
            origin_ned: [north, east, -up],
            rotation: mul(&rot_z(self.heading(t)), &rotation_about(&self.keel(), roll)),
        }
    }

    /// The pad's velocity over the ground at `t` (its origin's), NED, m/s.
    pub fn velocity_ned(&self, t: f64) -> Vec3 {
        let h = 1e-3;
        let (a, b) = (self.pose(t - h).origin_ned, self.pose(t + h).origin_ned);
        [0, 1, 2].map(|k| (b[k] - a[k]) / (2.0 * h))
    }

    /// A point given in the world (the pad frame as the pad started) in the moving pad's
    /// frame at `t`.
    pub fn point_relative(&self, t: f64, world: Vec3) -> Vec3 {
        let pose = self.pose(t);
        let d = pad_to_ned(world);
        let d = [0, 1, 2].map(|k| d[k] - pose.origin_ned[k]);
        ned_to_pad(mul_vec(&transpose(&pose.rotation), d))
    }

    /// A flight given against the pad, carried along the pad's drive and turns (not its heave
    /// and roll, which a vehicle does not follow): the vehicle in the world. A scenario flown
    /// over a moving pad (`touchdown simulate --pad-velocity`, [`crate::Simulator::vehicle_state`])
    /// keeps its flight over the pad this way, while the autopilot's attitude and velocity are
    /// the world's.
    pub fn carry(&self, t: f64, flown: &VehicleState) -> VehicleState {
        if self.is_at_rest() {
            return *flown;
        }
        let pose = self.pose(t);
        let heading = rot_z(self.heading(t));
        let p = mul_vec(&heading, pad_to_ned(flown.position));
        let world = [p[0] + pose.origin_ned[0], p[1] + pose.origin_ned[1], p[2]];
        VehicleState {
            position: ned_to_pad(world),
            attitude: mul(&heading, &flown.attitude),
        }
    }

    /// The vehicle, given in the world (the pad frame as the pad started; attitude body FRD to
    /// the world's NED), relative to the moving pad at `t`: its position in the pad's frame,
    /// its attitude to the pad's NED.
    pub fn relative(&self, t: f64, world: &VehicleState) -> VehicleState {
        if self.is_at_rest() {
            return *world;
        }
        let pose = self.pose(t);
        VehicleState {
            position: self.point_relative(t, world.position),
            attitude: mul(&transpose(&pose.rotation), &world.attitude),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{from_euler, IDENTITY};

    fn close(a: Vec3, b: Vec3, tol: f64) -> bool {
        (0..3).all(|k| (a[k] - b[k]).abs() < tol)
    }

    #[test]
    fn a_pad_at_rest_changes_nothing() {
        let m = PadMotion::at_rest();
        let v = VehicleState {
            position: [1.0, 2.0, 3.0],
            attitude: from_euler(0.1, -0.2, 0.3),
        };
        assert_eq!(m.relative(5.0, &v), v);
        assert!(m.validate().is_ok());
    }

    #[test]
    fn a_driving_pad_leaves_the_vehicle_behind_by_its_path() {
        let m = PadMotion {
            velocity_ne_mps: [1.0, 2.0],
            start_s: 3.0,
            ..PadMotion::at_rest()
        };
        let hover = VehicleState {
            position: [0.0, 0.0, 10.0],
            attitude: IDENTITY,
        };
        // Before the start it lies where it started.
        assert!(close(
            m.relative(2.0, &hover).position,
            [0.0, 0.0, 10.0],
            1e-12
        ));
        // 2 s after: 2 m north and 4 m east, so the vehicle is 4 m west, 2 m south of it.
        let r = m.relative(5.0, &hover);
        assert!(
            close(r.position, [-4.0, -2.0, 10.0], 1e-9),
            "{:?}",
            r.position
        );
        assert!(close(m.velocity_ned(5.0), [1.0, 2.0, 0.0], 1e-6));
    }

    #[test]
    fn a_turning_pad_drives_an_arc_and_turns_its_axes() {
        // 1 m/s north, turning 90 degrees in 10 s: a quarter circle of radius 20/pi m.
        let m = PadMotion {
            velocity_ne_mps: [1.0, 0.0],
            turn_rate_deg_s: 9.0,
            ..PadMotion::at_rest()
        };
        let r = 20.0 / std::f64::consts::PI;
        let pose = m.pose(10.0);
        assert!(
            close(pose.origin_ned, [r, r, 0.0], 1e-9),
            "{:?}",
            pose.origin_ned
        );
        assert!(close(m.velocity_ned(10.0), [0.0, 1.0, 0.0], 1e-6));
        // The pad's north now points east: a vehicle 1 m east of its origin is 1 m along its
        // +y (north) axis.
        let east_of_it = [pose.origin_ned[1] + 1.0, pose.origin_ned[0], 0.0];
        assert!(close(
            m.point_relative(10.0, east_of_it),
            [0.0, 1.0, 0.0],
            1e-9
        ));
    }

    #[test]
    fn a_carried_flight_stays_over_the_pad_but_for_the_deck_s_heave() {
        let m = PadMotion {
            velocity_ne_mps: [1.0, 0.5],
            turn_rate_deg_s: 6.0,
            heave_m: 0.3,
            heave_period_s: 5.0,
            ..PadMotion::at_rest()
        };
        let flown = VehicleState {
            position: [1.0, -2.0, 8.0],
            attitude: from_euler(0.05, -0.1, 0.7),
        };
        for t in [0.0, 1.3, 7.0, 20.0] {
            let world = m.carry(t, &flown);
            let back = m.relative(t, &world);
            let up = 0.3 * (std::f64::consts::TAU * t / 5.0).sin();
            let want = [flown.position[0], flown.position[1], flown.position[2] - up];
            assert!(close(back.position, want, 1e-9), "{t}: {:?}", back.position);
            for (a, b) in back.attitude.iter().zip(&flown.attitude) {
                assert!(close(*a, *b, 1e-12));
            }
        }
        // The world velocity is the pad's: the vehicle hovers over it.
        let (a, b) = (m.carry(10.0, &flown), m.carry(10.001, &flown));
        let v = [0, 1, 2].map(|k| (b.position[k] - a.position[k]) / 0.001);
        let pad = m.velocity_ned(10.0);
        // Pad frame (east, north, up) against NED; the vehicle's own turn with the pad adds
        // its offset times the turn rate.
        assert!(
            (v[0].hypot(v[1]) - pad[0].hypot(pad[1])).abs() < 0.3,
            "{v:?} {pad:?}"
        );
    }

    #[test]
    fn a_deck_heaves_and_rolls_about_its_keel() {
        let m = PadMotion {
            velocity_ne_mps: [0.0, 2.0],
            heave_m: 0.5,
            heave_period_s: 8.0,
            roll_deg: 10.0,
            roll_period_s: 4.0,
            ..PadMotion::at_rest()
        };
        assert!(m.validate().is_ok());
        // A quarter of the roll's period and an eighth of the heave's.
        let pose = m.pose(1.0);
        let up = 0.5 * (std::f64::consts::TAU / 8.0).sin();
        assert!((pose.origin_ned[2] + up).abs() < 1e-12);
        // Rolling about its keel (east) by 10 degrees: east stays east, down tilts.
        let keel = mul_vec(&pose.rotation, [0.0, 1.0, 0.0]);
        assert!(close(keel, [0.0, 1.0, 0.0], 1e-12));
        let down = mul_vec(&pose.rotation, [0.0, 0.0, 1.0]);
        assert!((down[2] - 10f64.to_radians().cos()).abs() < 1e-12);
        let bad = PadMotion {
            roll_deg: 5.0,
            ..PadMotion::at_rest()
        };
        assert!(bad.validate().is_err());
        let nan = PadMotion {
            velocity_ne_mps: [f64::NAN, 0.0],
            ..PadMotion::at_rest()
        };
        assert!(nan.validate().is_err());
    }
}
