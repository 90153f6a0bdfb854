//! Vehicle motion: position and attitude as smooth functions of time, deterministic from a
//! seed.
//!
//! A multicopter tilts to accelerate, so the attitude follows the path: the body's thrust
//! axis (-z) points along the specific force `a - g` it must produce, the nose keeps the
//! commanded heading, and a seeded wobble (sums of sines, like gusts and a hovering
//! controller's hunting) turns roll, pitch and yaw a little more. The acceleration is taken
//! from the path by a central difference over [`ACCELERATION_SPAN_S`], which smooths the
//! corners between path segments the way the vehicle's own response would.
//!
//! A path can also jump: a [`Profile::Jump`] segment moves the vehicle without flying, as a
//! recording that keeps only the hovers of a set-point experiment does (the vehicle is
//! elsewhere at the next hover). The path is continuous between jumps
//! ([`Trajectory::continuous_span`]); the simulator exposes no frame across one, and the
//! acceleration is taken within the span, so a jump neither ghosts an image nor tilts the
//! vehicle.
//!
//! Positions are in the pad frame (x east, y north, z up, metres); attitudes are body FRD to
//! NED (see [`super::camera`]).

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::math::{cross, from_columns, from_euler, mul, normalize, scale, Mat3, Vec3};

/// Standard gravity, m/s^2.
pub const GRAVITY: f64 = 9.80665;
/// Half-width of the central difference that gives the acceleration, seconds.
pub const ACCELERATION_SPAN_S: f64 = 0.15;
/// How far before a jump the path is still read as the span's end, seconds: the path at the
/// jump's own time is already past it.
pub const JUMP_GUARD_S: f64 = 1e-7;

/// Where the vehicle is and how it is turned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleState {
    /// Position in the pad frame, metres.
    pub position: Vec3,
    /// Body FRD to NED rotation.
    pub attitude: Mat3,
}

/// Smooth seeded wobble: three sines per channel with random phases and frequencies.
#[derive(Debug, Clone, PartialEq)]
pub struct Wobble {
    /// Per channel (x, y, z position; roll, pitch, yaw): (amplitude, frequency Hz, phase).
    terms: [[(f64, f64, f64); 3]; 6],
}

impl Wobble {
    /// No wobble.
    pub fn none() -> Self {
        Wobble {
            terms: [[(0.0, 0.0, 0.0); 3]; 6],
        }
    }

    /// Position wobble of about `position_m` (RMS per axis) and attitude wobble of about
    /// `attitude_deg`, with frequencies around `frequency_hz`.
    pub fn new(position_m: f64, attitude_deg: f64, frequency_hz: f64, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x776f_6262_6c65); // "wobble"
        let mut terms = [[(0.0, 0.0, 0.0); 3]; 6];
        for (channel, row) in terms.iter_mut().enumerate() {
            let amplitude = if channel < 3 {
                position_m
            } else {
                attitude_deg.to_radians()
            };
            for term in row.iter_mut() {
                // Three sines of amplitude a/sqrt(1.5) have an RMS of a.
                let a = amplitude / 1.5f64.sqrt() * rng.random_range(0.6..1.4);
                let f = frequency_hz * rng.random_range(0.4..1.6);
                let phase = rng.random_range(0.0..std::f64::consts::TAU);
                *term = (a, f, phase);
            }
        }
        Wobble { terms }
    }

    /// A wobble of given sines: per channel (x, y, z position in metres; roll, pitch, yaw
    /// in radians), three `(amplitude, frequency Hz, phase radians)` terms. A test's exact
    /// motion: a slow sine through zero turns the vehicle at `amplitude * 2 pi frequency`
    /// rad/s there.
    pub fn from_terms(terms: [[(f64, f64, f64); 3]; 6]) -> Self {
        Wobble { terms }
    }

    fn channel(&self, channel: usize, t: f64) -> f64 {
        self.terms.get(channel).map_or(0.0, |row| {
            row.iter()
                .map(|&(a, f, p)| a * (std::f64::consts::TAU * f * t + p).sin())
                .sum()
        })
    }

    /// Position offset at `t`.
    pub fn position(&self, t: f64) -> Vec3 {
        [self.channel(0, t), self.channel(1, t), self.channel(2, t)]
    }

    /// Roll, pitch, yaw offsets at `t`, radians.
    pub fn attitude(&self, t: f64) -> (f64, f64, f64) {
        (self.channel(3, t), self.channel(4, t), self.channel(5, t))
    }
}

/// How a segment gets from its start to its end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Profile {
    /// Constant velocity.
    Linear,
    /// Minimum jerk (rest to rest, smooth): `10 s^3 - 15 s^4 + 6 s^5`.
    MinimumJerk,
    /// Stay at the start (a hover set point; `to` is ignored).
    Hold,
    /// Be at `to` from `t0` on without having flown there from `from` (where the previous
    /// segment left the vehicle): a discontinuity of the path, not a motion. `t1` is
    /// ignored (a jump takes no time).
    Jump,
}

/// A piece of the path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Start time, seconds.
    pub t0: f64,
    /// End time, seconds.
    pub t1: f64,
    /// Start position.
    pub from: Vec3,
    /// End position.
    pub to: Vec3,
    /// How it moves.
    pub profile: Profile,
}

/// A path through segments, the heading, and the wobble.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// Consecutive segments (times increasing). Before the first and after the last the
    /// vehicle holds the nearest end.
    pub segments: Vec<Segment>,
    /// Heading, radians from north toward east.
    pub yaw: f64,
    /// Gusts and hunting.
    pub wobble: Wobble,
    /// Whether the vehicle tilts with its acceleration (off: level set points, as the paper's
    /// tables assume).
    pub tilt_with_acceleration: bool,
    /// Constant roll and pitch, radians (holding against a steady wind).
    pub trim: (f64, f64),
}

impl Trajectory {
    /// The path position at `t` (without wobble).
    pub fn path(&self, t: f64) -> Vec3 {
        let Some(first) = self.segments.first() else {
            return [0.0; 3];
        };
        let segment = self
            .segments
            .iter()
            .rev()
            .find(|s| t >= s.t0)
            .unwrap_or(first);
        let span = (segment.t1 - segment.t0).max(1e-9);
        let u = ((t - segment.t0) / span).clamp(0.0, 1.0);
        let k = match segment.profile {
            Profile::Linear => u,
            Profile::MinimumJerk => u * u * u * (10.0 - 15.0 * u + 6.0 * u * u),
            Profile::Hold => 0.0,
            // Before the jump the previous segment holds the vehicle; from it on, `to`.
            Profile::Jump => 1.0,
        };
        let (a, b) = (segment.from, segment.to);
        [
            a[0] + k * (b[0] - a[0]),
            a[1] + k * (b[1] - a[1]),
            a[2] + k * (b[2] - a[2]),
        ]
    }

    /// The times `[start, end)` around `t` within which the path is continuous: from the
    /// last jump at or before `t` to the next one after it (infinite without one).
    pub fn continuous_span(&self, t: f64) -> (f64, f64) {
        let jumps = self
            .segments
            .iter()
            .filter(|s| s.profile == Profile::Jump)
            .map(|s| s.t0);
        let mut span = (f64::NEG_INFINITY, f64::INFINITY);
        for jump in jumps {
            if jump <= t {
                span.0 = span.0.max(jump);
            } else {
                span.1 = span.1.min(jump);
            }
        }
        span
    }

    /// Position and attitude at `t`.
    pub fn state(&self, t: f64) -> VehicleState {
        let jitter = self.wobble.position(t);
        let p = self.path(t);
        let position = [p[0] + jitter[0], p[1] + jitter[1], p[2] + jitter[2]];
        let level = if self.tilt_with_acceleration {
            let h = ACCELERATION_SPAN_S;
            // Across a jump the vehicle did not accelerate: the difference stays on this
            // side of it (holding the span's ends, as the path holds its own ends).
            let (start, end) = self.continuous_span(t);
            let last_before_end = end - JUMP_GUARD_S;
            let (a, b) = (
                self.path((t - h).max(start)),
                self.path((t + h).min(last_before_end)),
            );
            let accel_pad = [0, 1, 2].map(|k| (a[k] - 2.0 * p[k] + b[k]) / (h * h));
            attitude_for(accel_pad, self.yaw)
        } else {
            from_euler(0.0, 0.0, self.yaw)
        };
        let (roll, pitch, yaw) = self.wobble.attitude(t);
        let (roll, pitch) = (roll + self.trim.0, pitch + self.trim.1);
        VehicleState {
            position,
            attitude: mul(&level, &from_euler(roll, pitch, yaw)),
        }
    }

    /// The last segment's end time.
    pub fn end_time(&self) -> f64 {
        self.segments.last().map_or(0.0, |s| s.t1)
    }
}

/// The attitude (body FRD to NED) of a multicopter accelerating at `accel_pad` (pad frame)
/// with heading `yaw`.
pub fn attitude_for(accel_pad: Vec3, yaw: f64) -> Mat3 {
    // Pad (east, north, up) to NED, then the specific force f = a - g (g = +z in NED).
    let a_ned = [accel_pad[1], accel_pad[0], -accel_pad[2]];
    let f = [a_ned[0], a_ned[1], a_ned[2] - GRAVITY];
    // Thrust is along -z_body: z_body = -f / |f|.
    let z_b = normalize(scale(f, -1.0));
    let heading = [yaw.cos(), yaw.sin(), 0.0];
    let mut y_b = normalize(cross(z_b, heading));
    if y_b == [0.0; 3] {
        y_b = [-yaw.sin(), yaw.cos(), 0.0];
    }
    let x_b = cross(y_b, z_b);
    from_columns(x_b, y_b, z_b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{max_difference, mul_vec};

    #[test]
    fn hover_is_level_and_acceleration_tilts() {
        let level = attitude_for([0.0; 3], 0.3);
        assert!(max_difference(&level, &from_euler(0.0, 0.0, 0.3)) < 1e-12);
        // Accelerating east with the nose north: roll right, thrust tilted east.
        let m = attitude_for([GRAVITY, 0.0, 0.0], 0.0);
        let thrust_ned = mul_vec(&m, [0.0, 0.0, -1.0]);
        assert!(
            thrust_ned[1] > 0.7 && thrust_ned[2] < -0.7,
            "{thrust_ned:?}"
        );
    }

    #[test]
    fn minimum_jerk_reaches_its_ends() {
        let t = Trajectory {
            segments: vec![Segment {
                t0: 1.0,
                t1: 3.0,
                from: [0.0, 0.0, 10.0],
                to: [4.0, 0.0, 10.0],
                profile: Profile::MinimumJerk,
            }],
            yaw: 0.0,
            wobble: Wobble::none(),
            tilt_with_acceleration: true,
            trim: (0.0, 0.0),
        };
        assert_eq!(t.path(0.0), [0.0, 0.0, 10.0]);
        assert_eq!(t.path(3.5), [4.0, 0.0, 10.0]);
        assert!((t.path(2.0)[0] - 2.0).abs() < 1e-12);
        assert!(max_difference(&t.state(0.0).attitude, &from_euler(0.0, 0.0, 0.0)) < 1e-12);
    }

    /// Two hovers 5 m apart with a jump between them, tilting with acceleration.
    fn hovers_with_a_jump() -> Trajectory {
        let (a, b) = ([0.0, 0.0, 10.0], [0.0, 0.0, 15.0]);
        let hold = |t0, t1, p| Segment {
            t0,
            t1,
            from: p,
            to: p,
            profile: Profile::Hold,
        };
        Trajectory {
            segments: vec![
                hold(0.0, 1.0, a),
                Segment {
                    t0: 1.5,
                    t1: 1.5,
                    from: a,
                    to: b,
                    profile: Profile::Jump,
                },
                hold(2.0, 3.0, b),
            ],
            yaw: 0.0,
            wobble: Wobble::none(),
            tilt_with_acceleration: true,
            trim: (0.0, 0.0),
        }
    }

    #[test]
    fn a_jump_splits_the_path_without_tilting_the_vehicle() {
        let t = hovers_with_a_jump();
        assert_eq!(t.path(1.4), [0.0, 0.0, 10.0]);
        assert_eq!(t.path(1.5), [0.0, 0.0, 15.0]);
        assert_eq!(t.path(2.5), [0.0, 0.0, 15.0]);
        assert_eq!(t.continuous_span(0.5), (f64::NEG_INFINITY, 1.5));
        assert_eq!(t.continuous_span(1.5), (1.5, f64::INFINITY));
        // A central difference across the jump would read 5 m in 0.15 s as a climb of
        // hundreds of m/s^2; the vehicle hovers, level, on both sides.
        for time in [1.45, 1.5, 1.55] {
            let level = from_euler(0.0, 0.0, 0.0);
            assert!(
                max_difference(&t.state(time).attitude, &level) < 1e-12,
                "tilted at {time} s"
            );
        }
    }
}
