//! The error sources of a real flight that sit between the vehicle and its camera: the
//! rolling shutter's readout, the camera's vibration on its mount, and the mount's
//! misalignment. One struct, [`FlightEffects`], holds all three; a scenario takes them
//! ([`crate::scenario::Scenario::apply_effects`]). This module is the effects alone: it knows
//! no scenario.
//!
//! - **Rolling shutter**: the sensor exposes its rows one after another; row `v` is exposed
//!   `(v - (height - 1) / 2) * line_time_us` after the frame's time (the contract's
//!   `camera.toml` `line_time_us`), so a camera that moves or turns during the readout sees
//!   the pad skewed. The simulator renders every row at its own time ([`crate::Simulator`]).
//! - **Vibration** ([`Vibration`]): the camera turning on its mount relative to the body
//!   (mount flex driven by the motors), 50-200 Hz: the autopilot's attitude does not see it,
//!   the image does (and, with a rolling shutter, as a wobble of the rows).
//! - **Mount misalignment**: the camera is not screwed on exactly along the body axes. The
//!   true mount is the nominal downward one turned by `mount_roll_deg` about body x and
//!   `mount_pitch_deg` about body y: camera-to-body = `R_y(pitch) R_x(roll) nominal`
//!   ([`crate::camera::CameraMount::misaligned`]). The board believes the nominal mount
//!   unless calibrated.
//!
//! The named scenarios are built without any of these (so the tests that use them keep
//! their meaning); `apply_effects` adds them, as `touchdown simulate` and the replay do.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::math::{from_euler, Mat3, IDENTITY};

/// Lowest vibration frequency drawn, Hz.
pub const VIBRATION_MIN_HZ: f64 = 50.0;
/// Highest vibration frequency drawn, Hz.
pub const VIBRATION_MAX_HZ: f64 = 200.0;
/// Sinusoids per axis of the vibration.
pub const VIBRATION_TERMS: usize = 3;

/// The flight effects a scenario is rendered with; every term 0 turns it off.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlightEffects {
    /// Time from the first row's exposure to the last one's, milliseconds (0 = global
    /// shutter).
    pub readout_ms: f64,
    /// RMS of the camera's vibration on its mount, degrees, per body axis.
    pub vibration_deg: f64,
    /// Mount misalignment about body x (roll), degrees.
    pub mount_roll_deg: f64,
    /// Mount misalignment about body y (pitch), degrees.
    pub mount_pitch_deg: f64,
}

impl FlightEffects {
    /// A small multicopter with the board camera:
    /// - readout 30.5 ms: the OV7725 at 30 fps clocks 525 lines of 63.5 us per frame (its
    ///   datasheet's VGA timing), 480 of them active, so the active rows take 30.5 ms;
    /// - vibration 0.03 degrees RMS per axis: at 50-200 Hz that is an angular rate of about
    ///   25 deg/s RMS, the order of the gyro noise a balanced small multicopter logs in
    ///   flight, so about 1 px of jitter blur in a 4 ms exposure at VGA. (0.15 degrees would
    ///   be 120 deg/s: badly balanced props, images no user would fly with; the flag can
    ///   still ask for it.)
    /// - mount roll 1.2 and pitch -1.6 degrees (2.0 degrees in all): a mount printed and
    ///   screwed on by hand, with nothing aligning it to the flight controller's axes.
    pub fn typical() -> Self {
        FlightEffects {
            readout_ms: 30.5,
            vibration_deg: 0.03,
            mount_roll_deg: 1.2,
            mount_pitch_deg: -1.6,
        }
    }

    /// None of the effects: a global shutter on a rigid, exactly aligned mount.
    pub fn none() -> Self {
        FlightEffects {
            readout_ms: 0.0,
            vibration_deg: 0.0,
            mount_roll_deg: 0.0,
            mount_pitch_deg: 0.0,
        }
    }
}

impl Default for FlightEffects {
    fn default() -> Self {
        Self::typical()
    }
}

/// The camera's rotation on its mount: per body axis (x, y, z) a sum of
/// [`VIBRATION_TERMS`] sinusoids with seeded frequencies in
/// [`VIBRATION_MIN_HZ`]..[`VIBRATION_MAX_HZ`], seeded phases and amplitudes scaled so that
/// each axis's RMS (over a long time) is exactly the one asked.
#[derive(Debug, Clone, PartialEq)]
pub struct Vibration {
    /// Per body axis: (amplitude radians, frequency Hz, phase radians).
    terms: [[(f64, f64, f64); VIBRATION_TERMS]; 3],
}

impl Default for Vibration {
    fn default() -> Self {
        Self::none()
    }
}

impl Vibration {
    /// No vibration: the camera sits still on its mount.
    pub fn none() -> Self {
        Vibration {
            terms: [[(0.0, 0.0, 0.0); VIBRATION_TERMS]; 3],
        }
    }

    /// Vibration of `rms_deg` RMS per body axis (0 or less: none), drawn from `seed`.
    pub fn new(rms_deg: f64, seed: u64) -> Self {
        if !(rms_deg > 0.0 && rms_deg.is_finite()) {
            return Self::none();
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut terms = [[(0.0, 0.0, 0.0); VIBRATION_TERMS]; 3];
        for axis in terms.iter_mut() {
            for term in axis.iter_mut() {
                let weight = rng.random_range(0.5..1.5);
                let f = rng.random_range(VIBRATION_MIN_HZ..VIBRATION_MAX_HZ);
                let phase = rng.random_range(0.0..std::f64::consts::TAU);
                *term = (weight, f, phase);
            }
            // A sum of sines of distinct frequencies has mean square sum(a^2) / 2.
            let mean_square: f64 = axis.iter().map(|t| 0.5 * t.0 * t.0).sum();
            let k = rms_deg.to_radians() / mean_square.sqrt();
            for term in axis.iter_mut() {
                term.0 *= k;
            }
        }
        Vibration { terms }
    }

    /// Whether the camera moves on its mount at all.
    pub fn is_none(&self) -> bool {
        self.terms.iter().flatten().all(|t| t.0 == 0.0)
    }

    /// The frequencies of every term, Hz, per body axis.
    pub fn frequencies(&self) -> [[f64; VIBRATION_TERMS]; 3] {
        self.terms.map(|axis| axis.map(|t| t.1))
    }

    /// The rotation angles about body x, y, z at `t` seconds, radians.
    pub fn angles(&self, t: f64) -> [f64; 3] {
        self.terms.map(|axis| {
            axis.iter()
                .map(|&(a, f, p)| a * (std::f64::consts::TAU * f * t + p).sin())
                .sum()
        })
    }

    /// The camera's rotation on its mount at `t`, in body axes (applied before the mount:
    /// camera-to-body = `rotation(t) mount`); the identity without vibration.
    pub fn rotation(&self, t: f64) -> Mat3 {
        if self.is_none() {
            return IDENTITY;
        }
        let [x, y, z] = self.angles(t);
        from_euler(x, y, z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vibration_has_the_asked_rms_and_band() {
        let v = Vibration::new(0.15, 42);
        for axis in v.frequencies() {
            assert!(axis
                .iter()
                .all(|f| (VIBRATION_MIN_HZ..VIBRATION_MAX_HZ).contains(f)));
        }
        // 20 s at 10 kHz: the RMS of each axis.
        let n = 200_000;
        let mut sum = [0.0f64; 3];
        for k in 0..n {
            let a = v.angles(k as f64 * 1e-4);
            for (s, x) in sum.iter_mut().zip(a) {
                *s += x * x;
            }
        }
        for s in sum {
            let rms = (s / n as f64).sqrt().to_degrees();
            assert!((rms - 0.15).abs() < 0.005, "RMS {rms} deg");
        }
        assert_ne!(v, Vibration::new(0.15, 43));
        assert!(Vibration::new(0.0, 42).is_none());
    }
}
